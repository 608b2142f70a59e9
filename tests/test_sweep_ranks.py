"""Sweeps whose points run on several MPI ranks (``execution.ranks_per_run``, docs/sweeps.md,
"Points on several MPI ranks"): the local example (tests/configs/sweep_two_ranks.yaml, two points
of a small r-z impact through every stage, each on 2 ranks) gives every point's single-process
answer bit for bit; a sweep stopped by SIGTERM stops its ranks, which keep their checkpoint, and
the next sweep resumes them to the same answer; a point whose launch fails is a failed point with
the end of its output; what cannot run on ranks is refused before anything is written.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest
import yaml
from click.testing import CliRunner

pytest.importorskip("mpi4py")

import sweep_stand_ins  # noqa: E402
from impactpipe.pipeline import cli, ranks, stages  # noqa: E402
from impactpipe.pipeline.lock import process_alive  # noqa: E402
from impactpipe.pipeline.sweep import Execution, load_sweep, run_sweep, sweep_status  # noqa: E402

HERE = Path(__file__).resolve().parent
EXAMPLE = HERE / "configs" / "sweep_two_ranks.yaml"
#: The stand-in stages are imported by the ranks too.
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
#: Output files of the stages whose datasets must agree bit for bit.
STAGE_FILES = ("hydro.h5", "handoff.h5", "nbody.h5", "analysis.h5")
#: Summary entries that differ between any two runs (where and how long).
VOLATILE = ("run_dir", "stages", "git_commit")


def impactpipe_sweep(path: Path, out: Path, *options: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "impactpipe.pipeline.cli", "sweep", str(path), "--out", str(out),
                             "-q", *options], env=ENV, start_new_session=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def finished(process: subprocess.Popen, timeout: float = 240) -> tuple[int, str]:
    """Exit status and standard error of a sweep run to its end."""
    _, err = process.communicate(timeout=timeout)
    return process.returncode, err


def answer(run_dir: Path) -> dict:
    """Every dataset of the stages' files and the summary without its volatile entries."""
    out = {}
    for name in STAGE_FILES:
        with h5py.File(run_dir / name, "r") as f:
            f.visititems(lambda key, obj: out.__setitem__(f"{name}/{key}", obj[()].tobytes())
                         if isinstance(obj, h5py.Dataset) else None)
    summary = json.loads((run_dir / "summary.json").read_text())
    out["summary"] = json.dumps({k: v for k, v in summary.items() if k not in VOLATILE}, sort_keys=True)
    return out


def point_results(sweep_dir: Path) -> dict:
    """Each point's row of points.json without wall times."""
    points = json.loads((sweep_dir / "points.json").read_text())
    return {name: {k: v for k, v in p["summary"].items() if k != "wall_seconds"} for name, p in points.items()}


@pytest.fixture(scope="module")
def single(tmp_path_factory):
    """The example sweep with one process per point (``--ranks-per-run 1``): the answers."""
    out = tmp_path_factory.mktemp("single") / "sweep"
    status, err = finished(impactpipe_sweep(EXAMPLE, out, "--ranks-per-run", "1"))
    assert status == 0, err
    return out


def test_points_on_two_ranks_give_the_single_process_answers_bit_for_bit(single, tmp_path):
    status, err = finished(impactpipe_sweep(EXAMPLE, tmp_path / "sweep"))
    assert status == 0, err
    assert point_results(tmp_path / "sweep") == point_results(single)
    assert len(point_results(single)) == 2
    for run_dir in sorted((single / "runs").iterdir()):
        shared = tmp_path / "sweep" / "runs" / run_dir.name
        assert "hydro on 2 MPI ranks" in (shared / "run.log").read_text()
        assert "MPI ranks" not in (run_dir / "run.log").read_text()
        assert answer(shared) == answer(run_dir), run_dir.name


def write_sweep(tmp_path: Path, **fields) -> Path:
    """The example sweep with ``fields`` changed, in ``tmp_path``."""
    spec = yaml.safe_load(EXAMPLE.read_text())
    spec.update({"base": str(EXAMPLE.parent / spec["base"]), **fields})
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def test_a_sweep_stopped_by_sigterm_stops_its_ranks_and_the_next_resumes_them(single, tmp_path):
    """SIGTERM to the sweep process alone: the worker passes it on to mpiexec, rank 0 ends its step,
    keeps the checkpoint and stops every rank; the next sweep resumes the point from it."""
    path = write_sweep(tmp_path, axes={"scene.impact.velocity": [250.0]}, stage_functions=sweep_stand_ins.PACED_STAGES)
    sweep = impactpipe_sweep(path, tmp_path / "sweep")
    runs = tmp_path / "sweep" / "runs"
    deadline = time.time() + 120
    while time.time() < deadline and not list(runs.glob("*.pid")):
        time.sleep(0.05)
    (pid_file,) = runs.glob("*.pid")
    rank_zero = int(pid_file.read_text())
    os.kill(sweep.pid, signal.SIGTERM)
    try:
        status, err = finished(sweep, timeout=60)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(sweep.pid, signal.SIGKILL)
    assert status != 0
    assert "SIGTERM passed on to its ranks, which stopped (exit status 130)" in err
    deadline = time.time() + 30
    while time.time() < deadline and process_alive(None, rank_zero):
        time.sleep(0.05)
    assert not process_alive(None, rank_zero), "rank 0 must stop with the sweep"
    run_dir = runs / pid_file.stem
    assert stages.read_records(run_dir)["hydro"]["status"] == "interrupted"
    with h5py.File(run_dir / "hydro.checkpoint.h5", "r") as f:
        assert 1 <= f.attrs["step_count"] < 10
    assert sweep_status(tmp_path / "sweep")["counts"] == {"interrupted": 1}
    result = run_sweep(load_sweep(write_sweep(tmp_path, axes={"scene.impact.velocity": [250.0]}),
                                  output=tmp_path / "sweep"), show_progress=False)
    assert [p["status"] for p in result["points"].values()] == ["complete"]
    assert "resuming from checkpoint at" in (run_dir / "run.log").read_text()
    assert answer(run_dir) == answer(single / "runs" / run_dir.name)


def test_a_failed_launch_is_a_failed_point_with_the_end_of_its_output(tmp_path, monkeypatch):
    """On a worker thread (as on Dask): the ranks' exit status and rank 0's error in the record."""
    monkeypatch.setenv("PYTHONPATH", ENV["PYTHONPATH"])
    path = write_sweep(tmp_path, axes={"scene.impact.velocity": [sweep_stand_ins.FAILING_VELOCITY]},
                       stage_functions=sweep_stand_ins.STAGES, execution={"ranks_per_run": 2, "retries": 0})
    with cf.ThreadPoolExecutor(1) as pool:
        result = run_sweep(load_sweep(path, output=tmp_path / "sweep"), executor=pool, show_progress=False)
    (point,) = result["points"].values()
    assert point["status"] == "failed" and point["attempts"] == 1
    assert "mpiexec -n 2 ended with exit status 1" in point["error"]
    assert "synthetic failure at 666" in point["error"]
    assert "synthetic failure at 666" in Path(point["run_dir"], "error.log").read_text()


@pytest.mark.parametrize(("change", "message"), [
    ("no mpi4py", 'execution.ranks_per_run: 2 ranks per run need mpi4py and an MPI library: '
                  'pip install "impactpipe[mpi]"'),
    ("no srun", "execution.launcher: no srun on PATH"),
])
def test_what_cannot_run_on_ranks_is_refused_before_anything_is_written(change, message, tmp_path, monkeypatch):
    fields = {}
    if change == "no mpi4py":
        monkeypatch.setattr(ranks, "mpi_installed", lambda: False)
    else:
        monkeypatch.setenv("PATH", str(tmp_path))
        fields["execution"] = {"ranks_per_run": 2, "launcher": "srun"}
    path = write_sweep(tmp_path, **fields)
    result = CliRunner().invoke(cli.main, ["sweep", str(path), "--out", str(tmp_path / "sweep")])
    assert result.exit_code == 2
    line = next(line for line in result.output.splitlines() if message in line)
    assert line.startswith(f"{path}:") and line.split(":")[1].isdigit()
    assert not (tmp_path / "sweep").exists()


def test_the_command_line_sets_the_ranks_per_run_and_is_checked_the_same_way(tmp_path, monkeypatch):
    monkeypatch.setattr(ranks, "mpi_installed", lambda: False)
    path = write_sweep(tmp_path, execution={"ranks_per_run": 1})
    result = CliRunner().invoke(cli.main, ["sweep", str(path), "--out", str(tmp_path / "sweep"),
                                           "--ranks-per-run", "3"])
    assert result.exit_code == 2
    assert "execution.ranks_per_run: 3 ranks per run need mpi4py" in result.output
    assert not (tmp_path / "sweep").exists()


def test_the_default_workers_leave_a_core_to_each_thread_of_each_rank(monkeypatch):
    monkeypatch.setattr(os, "cpu_count", lambda: 16)
    assert Execution(threads_per_run=2, ranks_per_run=4).default_workers() == 2
    assert Execution(ranks_per_run=4).default_workers() == 4
    assert Execution(threads_per_run=4, ranks_per_run=8).default_workers() == 1
