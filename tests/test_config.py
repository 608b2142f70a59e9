"""Config validation: every broken config fails with one located line, before any output."""

from pathlib import Path

import pytest
from click.testing import CliRunner

from impactpipe.pipeline.cli import main
from impactpipe.pipeline.config import ConfigError, load_config, load_yaml, parse_config

HERE = Path(__file__).parent
BROKEN = sorted((HERE / "configs" / "broken").glob("*.yaml"))
SWEEPS = sorted((HERE.parent / "configs" / "sweeps").glob("*.yaml"))
EXAMPLES = sorted(set((HERE.parent / "configs").rglob("*.yaml")) - set(SWEEPS))


def _expected(path: Path) -> str:
    first = path.read_text().splitlines()[0]
    assert first.startswith("# expect: ")
    return first[len("# expect: "):]


@pytest.mark.parametrize("path", BROKEN, ids=[p.stem for p in BROKEN])
def test_broken_config_names_key_value_and_allowed(path, tmp_path):
    text = path.read_text().replace("OUTDIR", str(tmp_path / "run"))
    cfg = tmp_path / path.name
    cfg.write_text(text)
    result = CliRunner().invoke(main, ["validate", str(cfg)])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1, lines
    assert _expected(path) in lines[0]
    assert lines[0].startswith(f"{cfg}:"), "message must start with file:line"
    result = CliRunner().invoke(main, ["run", str(cfg)])
    assert result.exit_code == 2
    assert not (tmp_path / "run").exists(), "a rejected config must not create its run directory"


def test_all_errors_reported_together(tmp_path):
    text = (HERE / "configs" / "broken" / "cfl_large.yaml").read_text()
    text = text.replace("angle: 90", "angle: 95").replace("preset: weak", "preset: weakk")
    with pytest.raises(ConfigError) as info:
        parse_config(text, source=tmp_path / "c.yaml")
    joined = "\n".join(info.value.messages)
    assert len(info.value.messages) == 3
    assert "hydro.cfl" in joined and "scene.impact.angle" in joined and "strength.preset" in joined


def test_line_numbers_point_at_the_key(tmp_path):
    text = "name: x\nscene:\n  problem: impact\n  target: {material: b, radius: 1.0}\n" \
           "  projectile: {material: b, radius: 0.1}\n  impact: {velocity: 1.0}\n" \
           "materials:\n  b: {eos: {model: tillotson, preset: basalt}}\nhydro:\n  cfl: 2\n"
    with pytest.raises(ConfigError) as info:
        parse_config(text, source="c.yaml")
    assert info.value.messages == ["c.yaml:10: hydro.cfl: must be <= 1 (got 2)"]


def test_yaml_floats_without_exponent_sign_are_numbers():
    assert load_yaml("a: 10.0e3\nb: 1e-3\nc: 4.0e-7\nd: 5") == {"a": 10000.0, "b": 0.001, "c": 4.0e-7, "d": 5}


def test_unquoted_off_is_the_interfaces_mode_off(tmp_path):
    """YAML 1.1 reads `interfaces: off` as false; it means the mode, and true is still refused."""
    text = (HERE.parent / "configs" / "reference" / "case8c.yaml").read_text()
    cfg = tmp_path / "off.yaml"
    cfg.write_text(text.replace("  self_gravity: false\n", "  self_gravity: false\n  refinement: {interfaces: off}\n"))
    assert load_config(cfg).hydro.refinement.interfaces == "off"
    cfg.write_text(text.replace("  self_gravity: false\n", "  self_gravity: false\n  refinement: {interfaces: on}\n"))
    with pytest.raises(ConfigError, match="hydro.refinement.interfaces: must be one of 'all', 'active' or 'off'"):
        load_config(cfg)


def test_presets_resolve_and_overrides_win(tmp_path):
    text = "name: x\nscene:\n  problem: impact\n  target: {material: b, radius: 1.0e4}\n" \
           "  projectile: {material: b, radius: 830}\n  impact: {velocity: 1900}\n" \
           "materials:\n  b:\n    eos: {model: tillotson, preset: basalt, A: 30.0e9}\n" \
           "    strength: {model: geo, preset: weak, Y0: 2.0e6}\n"
    mats = parse_config(text, source=tmp_path / "c.yaml").resolved_materials()
    assert mats["b"]["eos"]["A"] == 30.0e9 and mats["b"]["eos"]["B"] == 26.7e9
    assert mats["b"]["strength"]["Y0"] == 2.0e6 and mats["b"]["strength"]["Y_M"] == 1.0e7
    assert mats["b"]["strength"]["mu_i"] == 1.0 and mats["b"]["strength"]["T_melt"] == 1474.0


@pytest.mark.parametrize("path", EXAMPLES, ids=[str(p.relative_to(HERE.parent)) for p in EXAMPLES])
def test_example_configs_validate(path):
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 0, result.output
    assert "derived:" in result.output


@pytest.mark.parametrize("path", SWEEPS, ids=[p.stem for p in SWEEPS])
def test_committed_sweep_files_load(path, tmp_path):
    from impactpipe.pipeline.sweep import load_sweep

    sweep = load_sweep(path, output=tmp_path)  # validates the sweep file and every point's config
    assert sweep.base_path.is_file()


def test_every_config_key_is_documented():
    import re

    from impactpipe.pipeline.config import key_paths

    doc = re.sub(r"```.*?```", "", (HERE.parent / "docs" / "config.md").read_text(), flags=re.S)
    tokens = set(re.findall(r"`([^`]+)`", doc))
    words = {w for t in tokens for w in re.split(r"[,\s{}:]+", t)}
    missing = [p for p in key_paths()
               if p not in doc and p.split(".")[-1] not in words and not any(t.startswith(p + ".") for t in tokens)]
    assert not missing, f"undocumented config keys: {missing}"


def test_nbody_time_step_keys_default_to_the_driver_rule_and_are_bounded():
    import inspect

    from impactpipe.nbody.driver import reaccumulate

    text = "name: x\nscene:\n  problem: impact\n  target: {material: b, radius: 1.0e3}\n" \
           "  projectile: {material: b, radius: 100}\n  impact: {velocity: 1.0e3}\n" \
           "materials:\n  b: {eos: {model: tillotson, preset: basalt}}\n"
    nbody = parse_config(text, source="c.yaml").nbody
    rule = inspect.signature(reaccumulate).parameters
    for key in ("steps_per_dynamical_time", "collision_step_fraction"):
        assert getattr(nbody, key) == rule[key].default, key
    bad = text + "nbody:\n  steps_per_dynamical_time: 0\n  collision_step_fraction: 1.5\n"
    with pytest.raises(ConfigError) as info:
        parse_config(bad, source="c.yaml")
    assert info.value.messages == ["c.yaml:10: nbody.steps_per_dynamical_time: must be > 0 (got 0)",
                                   "c.yaml:11: nbody.collision_step_fraction: must be <= 1 (got 1.5)"]
