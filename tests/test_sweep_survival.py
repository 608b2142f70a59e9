"""Sweeps that survive their stops: pool workers die with the sweep, a killed pool worker is replaced,
a point is never run twice at once, points.json and sweep-status stay true after a stop, and a log
gets a line per point.

The stages are the stand-ins of tests/sweep_stand_ins.py.
"""

import collections
import concurrent.futures as cf
import contextlib
import json
import logging
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest
import yaml

import sweep_stand_ins
from impactpipe.pipeline import stages
from impactpipe.pipeline.sweep import grid_points, load_sweep, point_name, run_sweep, sweep_status

HERE = Path(__file__).parent
BASE = HERE / "configs" / "sweep_base.yaml"
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
SWEEP = [sys.executable, "-c", "from impactpipe.pipeline.cli import main; main()", "sweep"]


def write_sweep(tmp_path, stage_functions, velocities, workers=2):
    spec = {"name": "survive", "base": str(BASE), "output": str(tmp_path / "sweep"), "stage_functions": stage_functions,
            "axes": {"scene.impact.velocity": velocities}, "execution": {"backend": "local", "workers": workers}}
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@contextlib.contextmanager
def hanging_sweep(tmp_path):
    """A sweep process whose two workers sit inside hanging hydro stages; yields (process, worker pids)."""
    path = write_sweep(tmp_path, sweep_stand_ins.HANGING_STAGES, [1000.0, 1100.0, 1200.0])
    proc = subprocess.Popen([*SWEEP, str(path), "-q"], env=ENV, start_new_session=True)
    runs = tmp_path / "sweep" / "runs"
    try:
        deadline = time.time() + 90
        while time.time() < deadline and len(list(runs.glob("*.pid"))) < 2:
            time.sleep(0.05)
        pids = [int(p.read_text()) for p in runs.glob("*.pid")]
        assert len(pids) == 2, "both workers must be inside a hydro stage"
        yield proc, pids
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def interrupted_points(tmp_path):
    runs = tmp_path / "sweep" / "runs"
    return [stages.read_records(d)["hydro"]["status"] for d in runs.iterdir()
            if d.is_dir() and (runs / f"{d.name}.pid").exists()]


def test_workers_stop_when_the_sweep_is_killed_with_sigkill(tmp_path):
    """``kill -9`` of the sweep process alone: its workers notice within a second or so, stop their
    stages cleanly (recorded interrupted) and exit; sweep-status reports no point running."""
    with hanging_sweep(tmp_path) as (proc, pids):
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        deadline = time.time() + 20
        while time.time() < deadline and any(alive(pid) for pid in pids):
            time.sleep(0.1)
        assert not any(alive(pid) for pid in pids), "orphaned workers must stop"
    assert interrupted_points(tmp_path) == ["interrupted", "interrupted"]
    points = json.loads((tmp_path / "sweep" / "points.json").read_text())
    assert [p["status"] for p in points.values()].count("running") == 2, "SIGKILL left no chance to record it"
    status = sweep_status(tmp_path / "sweep")
    assert "running" not in status["counts"] and status["counts"]["interrupted"] == 2, status


def test_sigterm_leaves_points_json_and_sweep_status_true(tmp_path):
    with hanging_sweep(tmp_path) as (proc, pids):
        os.kill(proc.pid, signal.SIGTERM)
        assert proc.wait(timeout=30) != 0
    points = json.loads((tmp_path / "sweep" / "points.json").read_text())
    statuses = collections.Counter(p["status"] for p in points.values())
    assert statuses == {"interrupted": 2, "pending": 1}, statuses
    result = subprocess.run([sys.executable, "-c", "from impactpipe.pipeline.cli import main; main()",
                             "sweep-status", str(tmp_path / "sweep")], capture_output=True, text=True, env=ENV)
    assert result.returncode == 0 and "running" not in result.stdout, result.stdout
    assert "2 interrupted" in result.stdout


def test_a_point_held_by_another_process_is_waited_for_and_run_once(tmp_path, caplog):
    """An orphan of an earlier sweep still holds a point's run directory: the restarted sweep waits
    for it (and says so) instead of running the same point at the same time."""
    velocities = [1000.0, 1100.0]
    path = write_sweep(tmp_path, sweep_stand_ins.STAGES, velocities)
    sweep = load_sweep(path)
    params = grid_points(sweep)[0]
    run_dir = sweep.directory / "runs" / point_name(params, sweep.config_for(params))
    code = textwrap.dedent(f"""
        import time
        from impactpipe.pipeline.lock import run_lock
        with run_lock({str(run_dir)!r}):
            print("held", flush=True)
            time.sleep(2.0)
    """)
    orphan = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert orphan.stdout.readline().strip() == "held"
    caplog.set_level(logging.WARNING, logger="impactpipe")
    try:
        with cf.ThreadPoolExecutor(2) as pool:
            result = run_sweep(sweep, executor=pool, show_progress=False)
        released = orphan.wait(timeout=10)
    finally:
        orphan.kill()
    assert released == 0, "the orphan released the lock itself: the sweep waited for it"
    assert any(f"{run_dir} is in use by process {orphan.pid}" in r.getMessage() for r in caplog.records)
    assert [p["status"] for p in result["points"].values()] == ["complete", "complete"]
    log = (tmp_path / "sweep" / "runs" / "calls.log").read_text().split("\n")
    assert collections.Counter(line.split()[0] for line in log if line) == {
        name: 4 for name in result["points"]}, "every stage of every point ran exactly once"


def test_a_second_sweep_on_the_same_directory_exits_2(tmp_path):
    with hanging_sweep(tmp_path) as (proc, _):
        path = write_sweep(tmp_path, sweep_stand_ins.STAGES, [1000.0, 1100.0, 1200.0])
        second = subprocess.run([*SWEEP, str(path), "-q"], env=ENV, capture_output=True, text=True, timeout=60)
    assert second.returncode == 2 and f"is in use by process {proc.pid}" in second.stderr, second.stderr


def test_sweep_to_a_file_logs_a_line_per_point_start_and_end(tmp_path):
    velocities = [1000.0, 1100.0, 1200.0]
    path = write_sweep(tmp_path, sweep_stand_ins.STAGES, velocities)
    with open(tmp_path / "sweep.log", "w") as out:
        subprocess.run([*SWEEP, str(path)], env=ENV, stdout=out, stderr=subprocess.DEVNULL, check=True, timeout=120)
    lines = (tmp_path / "sweep.log").read_text().splitlines()
    names = json.loads((tmp_path / "sweep" / "points.json").read_text())
    assert len(names) == len(velocities)
    for name in names:
        assert len([line for line in lines if f"point {name}: started (attempt 1)" in line]) == 1, lines
        assert len([line for line in lines if f"point {name}: complete in" in line]) == 1, lines


def test_a_killed_pool_worker_is_replaced_and_every_point_runs_once(tmp_path, caplog):
    """``kill -9`` of a pool worker inside a point's hydro stage: the pool is replaced, the two points
    in flight run again on the new one (spending no retry), and every stage of every point
    finishes exactly once.  The killed point alone is counted a death of its worker."""
    path = write_sweep(tmp_path, sweep_stand_ins.HELD_STAGES, [1000.0, 1100.0, 1200.0, 1300.0])
    runs = tmp_path / "sweep" / "runs"
    killed = {}

    def kill_one_worker():
        deadline = time.time() + 120
        while time.time() < deadline and len(list(runs.glob("*.pid"))) < 2:
            time.sleep(0.05)
        first, second = sorted(runs.glob("*.pid"))  # both workers wait inside their hydro stages
        killed[first.stem] = int(first.read_text())
        os.kill(killed[first.stem], signal.SIGKILL)
        while time.time() < deadline and alive(int(second.read_text())):
            time.sleep(0.05)  # until the broken pool has stopped the other worker
        (runs / "release").touch()

    killer = threading.Thread(target=kill_one_worker)
    killer.start()
    caplog.set_level(logging.WARNING, logger="impactpipe")
    try:
        result = run_sweep(load_sweep(path), show_progress=False)
    finally:
        killer.join()
    [(name, pid)] = killed.items()
    points = result["points"]
    assert [p["status"] for p in points.values()] == ["complete"] * 4, points
    assert [p["attempts"] for p in points.values()] == [1] * 4, "a worker's death spends no retry"
    assert {n: p.get("worker_deaths", 0) for n, p in points.items()} == {n: int(n == name) for n in points}
    log = (runs / "calls.log").read_text().split()
    assert collections.Counter(zip(log[::2], log[1::2])) == {(n, s): 1 for n in points for s in stages.STAGES}
    assert any(f"process {pid} (killed by SIGKILL), running point {name}" in r.getMessage() for r in caplog.records)


def test_a_point_that_kills_its_worker_fails_after_three_deaths(tmp_path):
    """A point whose stage kills its own process (a crash) fails once its worker has died three times,
    with a message saying so; the points beside it finish and are not counted deaths."""
    velocities = [1000.0, sweep_stand_ins.FATAL_VELOCITY, 1200.0]
    result = run_sweep(load_sweep(write_sweep(tmp_path, sweep_stand_ins.FATAL_STAGES, velocities)),
                       show_progress=False)
    by_speed = {p["params"]["scene.impact.velocity"]: p for p in result["points"].values()}
    fatal = by_speed.pop(sweep_stand_ins.FATAL_VELOCITY)
    assert fatal["status"] == "failed" and fatal["worker_deaths"] == 3 and fatal["attempts"] == 1, fatal
    assert "its pool worker died 3 times while running it (the last: killed by SIGKILL)" in fatal["error"]
    assert [(p["status"], p.get("worker_deaths", 0)) for p in by_speed.values()] == [("complete", 0)] * 2
