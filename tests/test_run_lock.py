"""One writer per run directory (pipeline/lock.py), and the stages of a dead process read interrupted."""

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from impactpipe.pipeline import stages
from impactpipe.pipeline.cli import main
from impactpipe.pipeline.config import parse_config
from impactpipe.pipeline.lock import LOCK_FILE, RunLocked
from impactpipe.storage import atomic_path

HERE = Path(__file__).parent
CONFIG = (HERE / "configs" / "sweep_base.yaml").read_text()


def config():
    return parse_config(CONFIG, source="lock.yaml")


@pytest.fixture
def instant_stages(monkeypatch):
    """Stage functions that only write their file."""
    def make(stage, overrides=None):
        def stage_function(ctx):
            with atomic_path(ctx.path(stage)) as tmp:
                tmp.write_text(stage)
            return {}
        return stage_function

    monkeypatch.setattr(stages, "load_stage_function", make)


@contextlib.contextmanager
def holder(run_dir: Path):
    """Another process holding ``run_dir``'s lock; yields its pid; SIGKILLed on exit."""
    code = textwrap.dedent(f"""
        import time
        from impactpipe.pipeline.lock import run_lock
        with run_lock({str(run_dir)!r}):
            print("held", flush=True)
            time.sleep(120)
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "held"
        yield proc
    finally:
        proc.kill()
        proc.wait()


def test_second_run_on_a_held_directory_exits_2_at_once_naming_the_holder(tmp_path, instant_stages):
    path = tmp_path / "lock.yaml"
    path.write_text(CONFIG)
    run_dir = tmp_path / "run"
    with holder(run_dir) as proc:
        t0 = time.monotonic()
        result = CliRunner().invoke(main, ["run", str(path), "--out", str(run_dir), "-q"])
        assert time.monotonic() - t0 < 10.0
        assert result.exit_code == 2, result.output
        assert f"process {proc.pid} on {socket.gethostname()} since 20" in result.output
        assert "Traceback" not in result.output
        assert sorted(p.name for p in run_dir.iterdir()) == [LOCK_FILE], "the second run writes nothing"
        with pytest.raises(RunLocked, match=f"in use by process {proc.pid} on "):
            stages.run(config(), run_dir, show_progress=False)


def test_lock_of_a_killed_holder_is_taken_over_with_a_notice(tmp_path, instant_stages):
    path = tmp_path / "lock.yaml"
    path.write_text(CONFIG)
    run_dir = tmp_path / "run"
    with holder(run_dir) as proc:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert json.loads((run_dir / LOCK_FILE).read_text())["pid"] == proc.pid, "the dead holder's record is left"
    result = CliRunner().invoke(main, ["run", str(path), "--out", str(run_dir)])
    assert result.exit_code == 0, result.output
    assert f"taking over the lock of process {proc.pid} on {socket.gethostname()}" in result.output
    assert (run_dir / LOCK_FILE).read_text() == "", "a clean release empties the record"
    assert stages.read_records(run_dir)["analysis"]["status"] == "complete"


def test_two_threads_cannot_write_one_directory(tmp_path):
    """flock is per open file, so a second thread of the same process is refused too."""
    import threading

    from impactpipe.pipeline.lock import run_lock

    errors = []
    with run_lock(tmp_path):
        def other():
            try:
                with run_lock(tmp_path):
                    pass
            except RunLocked as exc:
                errors.append(exc)
        thread = threading.Thread(target=other)
        thread.start()
        thread.join()
        with run_lock(tmp_path):  # the same thread re-enters
            pass
    assert len(errors) == 1 and f"process {os.getpid()}" in str(errors[0])


HANGING = textwrap.dedent("""
    import sys
    from impactpipe.pipeline import stages
    from impactpipe.pipeline.config import parse_config
    config = parse_config(open(sys.argv[1]).read(), source=sys.argv[1])
    stages.run(config, sys.argv[2], show_progress=False,
               stage_functions={"hydro": "sweep_stand_ins:hanging_hydro"})
""")


def test_stage_left_by_a_killed_process_reads_interrupted_not_running(tmp_path, instant_stages):
    path = tmp_path / "lock.yaml"
    path.write_text(CONFIG)
    run_dir = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", HANGING, str(path), str(run_dir)], env=env)
    pid_file = tmp_path / "run.pid"
    deadline = time.time() + 60
    while time.time() < deadline and not pid_file.exists():
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    record = stages.read_records(run_dir)["hydro"]
    assert record["status"] == "running" and record["pid"] == proc.pid and record["host"] == socket.gethostname()
    assert stages.attempt_status(record) == "interrupted"
    assert stages.plan(config(), run_dir)[0] == ("hydro", "run: previous attempt interrupted")
    result = CliRunner().invoke(main, ["run", str(path), "--out", str(run_dir)])
    assert result.exit_code == 0, result.output
    assert "hydro: previous attempt interrupted" in result.output
    assert "running" not in result.output
