"""Each problem's parameters are declared once, in its module; the config schema and docs follow them.

The scene models of :mod:`impactpipe.pipeline.config` are built from the ``PARAMETERS`` of
the modules in :mod:`impactpipe.hydro.problems`: these tests check that every declared
parameter reaches the schema with its default, type and bounds, that the tables of
docs/config.md state the same defaults, and that a scene passes to its ``setup`` unchanged.
"""

from __future__ import annotations

import ast
import pickle
import re
from pathlib import Path

import pytest
from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from impactpipe.hydro.problems import PROBLEMS
from impactpipe.hydro.problems.parameters import REQUIRED, Parameter, Record, violations
from impactpipe.pipeline.config import SCENES, ConfigError, parse_config

ROOT = Path(__file__).resolve().parent.parent
BOUNDS = ("gt", "ge", "lt", "le")


def declared(parameters: dict, prefix: str = ""):
    """(dotted key, Parameter or Record) of every declared parameter, records' fields included."""
    for key, param in parameters.items():
        yield prefix + key, param
        if isinstance(param, Record):
            yield from declared(param.fields, f"{prefix}{key}.")


def schema_field(model: type[BaseModel], dotted: str):
    """The pydantic field of ``dotted`` (``left.density``) in ``model``."""
    *parents, leaf = dotted.split(".")
    for key in parents:
        annotation = model.model_fields[key].annotation
        model = next(a for a in getattr(annotation, "__args__", (annotation,)) if isinstance(a, type))
    return model.model_fields[leaf]


def field_bounds(field) -> dict[str, float]:
    return {op: getattr(meta, op) for meta in field.metadata for op in BOUNDS if getattr(meta, op, None) is not None}


@pytest.mark.parametrize("problem", list(PROBLEMS))
def test_every_declared_parameter_is_in_the_schema_with_its_default_and_bounds(problem):
    model = SCENES[problem]
    parameters = PROBLEMS[problem].PARAMETERS
    assert list(model.model_fields) == ["problem", "geometry", *parameters]
    for dotted, param in declared(parameters):
        field = schema_field(model, dotted)
        expected = PydanticUndefined if param.default is REQUIRED else param.default
        assert field.default == expected, dotted
        assert field.is_required() == param.required, dotted
        if isinstance(param, Parameter):
            assert field.annotation is param.kind, dotted
            assert field_bounds(field) == param.bounds(), dotted


def test_a_declared_bound_is_what_the_config_enforces():
    """column_collapse's cells_per_height: the module's bound (MIN_CELLS_PER_HEIGHT) is the config's message."""
    from impactpipe.hydro.problems import column_collapse

    bound = column_collapse.PARAMETERS["cells_per_height"].ge
    assert bound == column_collapse.MIN_CELLS_PER_HEIGHT
    text = ("name: x\nscene:\n  problem: column_collapse\n  material: sand\n"
            f"  cells_per_height: {bound - 1}\nhydro: {{cfl: 0.2}}\n"
            "materials:\n  sand: {eos: {model: ideal_gas}}\n")
    with pytest.raises(ConfigError) as info:
        parse_config(text, source="c.yaml")
    assert info.value.messages == [f"c.yaml:5: scene.cells_per_height: must be >= {bound} (got {bound - 1})"]
    config = parse_config(text.replace(f"cells_per_height: {bound - 1}", f"cells_per_height: {bound}"),
                          source="c.yaml")
    assert config.scene.end_time == column_collapse.PARAMETERS["end_time"].default


def test_a_module_cross_check_is_a_config_error():
    from impactpipe.hydro.problems import shock_tube

    state = "{material: gas, density: 1, pressure: 1}"
    text = (f"name: x\nscene:\n  problem: shock_tube\n  interface: 2.0\n  left: {state}\n  right: {state}\n"
            "  end_time: 0.2\nmaterials:\n  gas: {eos: {model: ideal_gas}}\n")
    message = shock_tube.check_parameters({"interface": 2.0, "length": shock_tube.PARAMETERS["length"].default})
    assert message == ["interface must lie inside (0, length=1) (got 2)"]
    with pytest.raises(ConfigError) as info:
        parse_config(text, source="c.yaml")
    assert info.value.messages == [f"c.yaml:2: scene: {message[0]}"]


@pytest.mark.parametrize("problem", [name for name in PROBLEMS if name != "impact"])
def test_setup_takes_the_scene_and_its_textbook_case_obeys_the_bounds(problem):
    """A verification scene's keys are its setup's keys (the adapter passes the scene as it is)."""
    module = PROBLEMS[problem]
    assert set(module.PARAMETERS) <= set(module.DEFAULTS)
    assert violations(module.PARAMETERS, module.DEFAULTS) == []
    for key, param in module.PARAMETERS.items():
        if not param.required:
            assert module.DEFAULTS[key] == (param.default if param.example is REQUIRED else param.example), key


def test_parsed_scenes_pickle():
    """Sweep workers receive configs pickled: the built scene models must be importable by name."""
    text = ("name: x\nscene:\n  problem: interface_advection\n  inner: {material: gas, density: 1}\n"
            "materials:\n  gas: {eos: {model: ideal_gas}}\n")
    config = parse_config(text, source="c.yaml")
    assert pickle.loads(pickle.dumps(config)).model_dump() == config.model_dump()


def _doc_default(text: str):
    text = text.strip()
    if text == "required":
        return REQUIRED
    if text.startswith("none"):
        return None
    if text in ("true", "false"):
        return text == "true"
    return float(text)


def doc_tables() -> dict[str, dict[str, object]]:
    """{problem: {dotted key: documented default}} from the scene tables of docs/config.md."""
    tables: dict[str, dict[str, object]] = {}
    problem = None
    for line in (ROOT / "docs" / "config.md").read_text().splitlines():
        heading = re.match(r"### problem: (\w+)", line)
        if heading:
            problem = heading.group(1)
            tables[problem] = {}
        elif line.startswith("## "):
            problem = None
        elif problem and line.startswith("| `scene."):
            keys_cell, default_cell = line.split("|")[1:3]
            keys = re.findall(r"`scene\.([\w.]+)`", keys_cell)
            defaults = [_doc_default(d) for d in default_cell.split(",")]
            for key, default in zip(keys, defaults * len(keys) if len(defaults) == 1 else defaults):
                tables[problem][key] = default
    return tables


def test_docs_scene_tables_state_the_declared_defaults():
    tables = doc_tables()
    assert set(tables) == set(PROBLEMS)
    for problem, table in tables.items():
        parameters = PROBLEMS[problem].PARAMETERS
        expected = {}
        for key, param in parameters.items():
            if isinstance(param, Record) and f"{key}.{next(iter(param.fields))}" in table:
                expected.update({f"{key}.{k}": p.default for k, p in param.fields.items()})
            else:
                expected[key] = param.default
        assert table == expected, problem


def test_problem_modules_do_not_import_pydantic():
    for path in sorted((ROOT / "hydro").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n.split(".")[0] == "pydantic" for n in names), path
