"""The package's layers: storage at the bottom, the stage libraries on it, the orchestrator on top.

Read from the source with :mod:`ast` (every ``import`` statement, function-local ones
included), so an upward import fails here before it can hide behind import order.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LIBRARIES = ("hydro", "handoff", "nbody", "analysis")
#: The top-level packages each package may import (besides itself).
ALLOWED = {
    "storage": set(),
    "hydro": {"storage"},
    "handoff": {"storage", "hydro"},
    "nbody": {"storage", "handoff"},
    "analysis": {"storage"},
    "pipeline": {"storage", "hydro", "handoff", "nbody", "analysis"},
}


def module_name(path: Path, root: Path = ROOT) -> str:
    """``impactpipe.<folder>.<sub>...`` of a source file under ``root``."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(["impactpipe", *parts])


def imported_modules(path: Path, root: Path = ROOT) -> set[str]:
    """The absolute names of the impactpipe modules a source file imports."""
    name = module_name(path, root)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module or ""
            found.add(stem)
            found.update(f"{stem}.{alias.name}" for alias in node.names)
    return {m for m in found if m.startswith("impactpipe.")}


def sources(folder: str, root: Path = ROOT) -> list[Path]:
    return sorted((root / folder).rglob("*.py"))


def top_package(module: str) -> str:
    return module.split(".")[1]


def upward_imports(folder: str, root: Path = ROOT) -> list[str]:
    """``file imports module`` for every import of ``folder`` that :data:`ALLOWED` forbids."""
    return [f"{path.relative_to(root)} imports {module}"
            for path in sources(folder, root) for module in sorted(imported_modules(path, root))
            if top_package(module) not in ALLOWED[folder] | {folder}]


@pytest.mark.parametrize("folder", sorted(ALLOWED))
def test_a_package_imports_only_the_layers_below_it(folder):
    upward = upward_imports(folder)
    assert not upward, "\n".join(upward)


def test_the_nbody_adapter_imports_nothing_from_hydro():
    path = ROOT / "pipeline" / "adapters" / "nbody.py"
    assert not [m for m in imported_modules(path) if top_package(m) == "hydro"]


def test_no_import_cycle_between_modules():
    modules = {module_name(p): p for folder in ALLOWED for p in sources(folder)}
    graph = {name: {m for m in imported_modules(path) if m in modules and m != name}
             for name, path in modules.items()}
    # A package's __init__ re-exporting its modules is not a cycle of the code's layers.
    for name in graph:
        graph[name] = {m for m in graph[name] if not name.startswith(m + ".")}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            pytest.fail("import cycle: " + " -> ".join(cycle))


@pytest.mark.parametrize("line", ["from impactpipe.pipeline import derived",
                                  "import impactpipe.pipeline.runstore",
                                  "from ...pipeline.stages import StageContext"])
def test_the_check_finds_an_upward_import(tmp_path, line):
    (tmp_path / "hydro" / "amr").mkdir(parents=True)
    (tmp_path / "hydro" / "amr" / "probe.py").write_text(f"def f():\n    {line}\n")
    assert upward_imports("hydro", tmp_path)
    assert not upward_imports("pipeline", tmp_path)
