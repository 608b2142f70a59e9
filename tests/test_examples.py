"""The examples in the public API's docstrings run and print what they say.

They run in a scratch directory that sees the repository's configs/.  The run() example
makes ``runs/quickstart`` there first (the fixture runs it), and the readers' examples open
its files.
"""

from __future__ import annotations

import doctest
import importlib
import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
RUN_EXAMPLE = ("impactpipe.pipeline.stages", "run")
#: (module, function) of each documented entry point besides run().
EXAMPLES = [
    ("impactpipe.pipeline.config", "load_config"),
    ("impactpipe.hydro.output.io", "read_snapshot"),
    ("impactpipe.handoff.store", "read_particles"),
    ("impactpipe.nbody.result", "read_result"),
    ("impactpipe.analysis.io", "read_analysis"),
    ("impactpipe.analysis.qstar", "fit_qstar"),
    ("impactpipe.analysis.resolution_error", "qstar_resolution_error"),
    ("impactpipe.analysis.handoff_error", "qstar_handoff_error"),
]


def run_example(module: str, name: str) -> int:
    """Run the docstring example of ``module.name`` in the current directory; its failure count."""
    function = getattr(importlib.import_module(module), name)
    (test,) = doctest.DocTestFinder().find(function, name, globs={})
    assert test.examples, f"{module}.{name} has no example"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    runner.run(test)
    return runner.failures


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A scratch directory with configs/ and the quickstart run of the run() example."""
    directory = tmp_path_factory.mktemp("examples")
    (directory / "configs").symlink_to(ROOT / "configs")
    cwd = os.getcwd()
    os.chdir(directory)
    try:
        failures = run_example(*RUN_EXAMPLE)
    finally:
        os.chdir(cwd)
    return directory, failures


def test_run_example(workdir):
    assert workdir[1] == 0, "the run() example failed (output above)"


@pytest.mark.parametrize(("module", "name"), EXAMPLES, ids=[name for _, name in EXAMPLES])
def test_docstring_example(module, name, workdir, monkeypatch):
    monkeypatch.chdir(workdir[0])
    assert run_example(module, name) == 0, f"{module}.{name}: example failed (output above)"
