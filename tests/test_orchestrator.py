"""Stage orchestration: resume, invalidation by config hash, interruption, atomic writes."""

import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from impactpipe.pipeline import stages
from impactpipe.pipeline.config import parse_config
from impactpipe.storage import atomic_path

CONFIG = """
name: orchestration
scene:
  problem: impact
  target: {material: basalt, radius: 1.0e4}
  projectile: {material: basalt, radius: 830.0}
  impact: {velocity: 1900.0}
materials:
  basalt: {eos: {model: tillotson, preset: basalt}}
hydro: {cfl: 0.4}
nbody: {collision_model: merge}
"""


def config(**overrides):
    return parse_config(CONFIG, source="orchestration.yaml", overrides=overrides)


@pytest.fixture
def calls(monkeypatch):
    """Replace the stage functions by stand-ins that record their calls and write their file."""
    log = []
    behaviour = {}

    def make(stage, overrides=None):
        def stage_function(ctx):
            log.append(stage)
            action = behaviour.get(stage)
            if action == "interrupt":
                raise stages.StageInterrupted("test interrupt")
            if action == "fail":
                raise RuntimeError("stage broke")
            with atomic_path(ctx.path(stage)) as tmp:
                tmp.write_text(stage)
            return {f"{stage}_value": len(log)}
        return stage_function

    monkeypatch.setattr(stages, "load_stage_function", make)
    return log, behaviour


def test_resume_skips_finished_stages(tmp_path, calls):
    log, _ = calls
    stages.run(config(), tmp_path, show_progress=False)
    assert log == ["hydro", "handoff", "nbody", "analysis"]
    stages.run(config(), tmp_path, show_progress=False)
    assert log == ["hydro", "handoff", "nbody", "analysis"], "a second run must do no work"
    summary = stages.read_summary(tmp_path)
    assert summary["analysis_value"] == 4 and set(summary["stages"]) == set(stages.STAGES)
    assert "numpy" in summary["versions"]


def test_adopted_stages_bring_only_their_own_summary_entries(tmp_path, calls):
    """A run adopting a donor's hydro and hand-off stages must not show the donor's N-body and
    analysis answers before (or instead of) its own."""
    log, behaviour = calls
    donor, run = tmp_path / "donor", tmp_path / "run"
    stages.run(config(), donor, show_progress=False)
    other = config(**{"nbody.opening_angle": 0.25})
    assert stages.adopt_stages(run, donor, other) == ["hydro", "handoff"]
    summary = stages.read_summary(run)
    assert (summary["hydro_value"], summary["handoff_value"]) == (1, 2)
    assert "nbody_value" not in summary and "analysis_value" not in summary
    assert set(summary["stages"]) == {"hydro", "handoff"} and summary["run_dir"] == str(run.resolve())
    behaviour["nbody"] = "fail"
    with pytest.raises(RuntimeError, match="stage broke"):
        stages.run(other, run, show_progress=False)
    assert "analysis_value" not in stages.read_summary(run)
    behaviour.clear()
    stages.run(other, run, show_progress=False)
    assert stages.read_summary(run)["analysis_value"] == 7 and log[-3:] == ["nbody", "nbody", "analysis"]


def test_changed_hydro_key_reruns_hydro_and_everything_after(tmp_path, calls):
    log, _ = calls
    stages.run(config(), tmp_path, show_progress=False)
    log.clear()
    stages.run(config(**{"hydro.cfl": 0.3}), tmp_path, show_progress=False)
    assert log == ["hydro", "handoff", "nbody", "analysis"]


def test_changed_nbody_key_reruns_only_nbody_and_analysis(tmp_path, calls):
    log, _ = calls
    stages.run(config(), tmp_path, show_progress=False)
    log.clear()
    stages.run(config(**{"nbody.collision_model": "bounce"}), tmp_path, show_progress=False)
    assert log == ["nbody", "analysis"]


def test_changed_preset_parameter_reruns_hydro(tmp_path, calls):
    log, _ = calls
    stages.run(config(), tmp_path, show_progress=False)
    log.clear()
    stages.run(config(**{"materials.basalt.eos.A": 30.0e9}), tmp_path, show_progress=False)
    assert log[0] == "hydro"


def test_interrupted_stage_is_rerun(tmp_path, calls):
    log, behaviour = calls
    behaviour["nbody"] = "interrupt"
    with pytest.raises(stages.StageInterrupted):
        stages.run(config(), tmp_path, show_progress=False)
    assert not (tmp_path / "nbody.h5").exists()
    assert stages.read_records(tmp_path)["nbody"]["status"] == "interrupted"
    behaviour.clear()
    log.clear()
    stages.run(config(), tmp_path, show_progress=False)
    assert log == ["nbody", "analysis"]


def test_stages_of_another_version_are_kept_but_named(tmp_path, calls, caplog):
    """A finished stage written by another impactpipe version is not rerun silently or
    unasked: it is kept, and the plan and a warning name the version and the way to refresh it;
    an interrupted stage's checkpoint from another version is named the same way."""
    log, behaviour = calls
    behaviour["nbody"] = "interrupt"
    with pytest.raises(stages.StageInterrupted):
        stages.run(config(), tmp_path, show_progress=False)
    records = stages.read_records(tmp_path)
    version = stages.storage.package_versions()["impactpipe"]
    assert {rec["version"] for rec in records.values()} == {version}
    del records["hydro"]["version"]
    records["nbody"]["version"] = "0.0.1"
    (tmp_path / stages.RECORD_FILE).write_text(json.dumps(records))
    reasons = dict(stages.plan(config(), tmp_path))
    assert reasons["hydro"] == (f"skip: up to date, but written by impactpipe {stages.UNRECORDED_VERSION} "
                                f"(this is {version}); `--from hydro` reruns it with this version")
    assert reasons["handoff"] == "skip: up to date"
    assert reasons["nbody"].startswith("run: previous attempt interrupted; its checkpoint was written by "
                                       f"impactpipe 0.0.1 (this is {version})")
    behaviour.clear()
    log.clear()
    with caplog.at_level("INFO", logger="impactpipe.pipeline.stages"):
        stages.run(config(), tmp_path, show_progress=False)
    assert log == ["nbody", "analysis"]
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert len(warned) == 2 and warned[0].startswith("hydro: up to date, but written by") and \
        warned[1].startswith("nbody: previous attempt interrupted; its checkpoint")
    assert stages.read_records(tmp_path)["nbody"]["version"] == version


def test_failed_stage_is_recorded_and_rerun(tmp_path, calls):
    log, behaviour = calls
    behaviour["handoff"] = "fail"
    with pytest.raises(RuntimeError, match="stage broke"):
        stages.run(config(), tmp_path, show_progress=False)
    record = stages.read_records(tmp_path)["handoff"]
    assert record["status"] == "failed" and "stage broke" in record["error"]
    behaviour.clear()
    log.clear()
    stages.run(config(), tmp_path, show_progress=False)
    assert log == ["handoff", "nbody", "analysis"]


def test_from_and_force(tmp_path, calls):
    log, _ = calls
    stages.run(config(), tmp_path, show_progress=False)
    log.clear()
    stages.run(config(), tmp_path, from_stage="nbody", show_progress=False)
    assert log == ["nbody", "analysis"]
    log.clear()
    stages.run(config(), tmp_path, force=True, show_progress=False)
    assert log == ["hydro", "handoff", "nbody", "analysis"]


def test_deleted_output_is_rerun(tmp_path, calls):
    log, _ = calls
    stages.run(config(), tmp_path, show_progress=False)
    (tmp_path / "handoff.h5").unlink()
    log.clear()
    stages.run(config(), tmp_path, show_progress=False)
    assert log == ["handoff", "nbody", "analysis"]


def test_sigterm_stops_stage_cleanly(tmp_path, monkeypatch):
    def slow_stage(ctx):
        with atomic_path(ctx.path("hydro")) as tmp:
            tmp.write_text("partial")
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)
        return {}

    monkeypatch.setattr(stages, "load_stage_function", lambda stage, overrides=None: slow_stage)
    with pytest.raises(stages.StageInterrupted, match="SIGTERM"):
        stages.run(config(), tmp_path, stages=["hydro"], show_progress=False)
    assert not (tmp_path / "hydro.h5").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".tmp-")]
    assert stages.read_records(tmp_path)["hydro"]["status"] == "interrupted"


def test_second_signal_while_stopping_does_not_lose_the_interrupted_record(tmp_path, monkeypatch):
    """A sweep's pool SIGTERMs a worker again once another worker has exited: a signal that
    arrives while the first one's stop writes the record must not abort that write."""
    def stage(ctx):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)

    write = stages.storage.write_json_atomic
    def write_with_second_signal(path, data):
        if data.get("hydro", {}).get("status") == "interrupted":
            os.kill(os.getpid(), signal.SIGTERM)
        write(path, data)

    monkeypatch.setattr(stages, "load_stage_function", lambda stage_name, overrides=None: stage)
    monkeypatch.setattr(stages.storage, "write_json_atomic", write_with_second_signal)
    with pytest.raises(stages.StageInterrupted, match="SIGTERM"):
        stages.run(config(), tmp_path, stages=["hydro"], show_progress=False)
    assert stages.read_records(tmp_path)["hydro"]["status"] == "interrupted"


def test_progress_eta_of_a_resumed_stage_counts_from_where_it_resumed(monkeypatch):
    """A stage resumed at t = 9 of 15 s that then advances 1 s per 100 wall seconds has 500 s
    left at t = 10 (the old estimate, from t = 0 and the reporter's creation, said 150 s)."""
    from impactpipe.pipeline import progress

    clock = [1000.0]
    monkeypatch.setattr(progress.time, "monotonic", lambda: clock[0])
    reporter = progress.StageProgress("hydro", 15.0, bar=False)
    reporter(9.0)
    clock[0] += 100.0
    reporter(10.0)
    assert reporter.eta(10.0, clock[0]) == pytest.approx(500.0)
    clock[0] += 100.0
    assert reporter.eta(11.0, clock[0]) == pytest.approx(400.0)
    fresh = progress.StageProgress("hydro", 15.0, bar=False)
    fresh(9.0)
    assert math.isnan(fresh.eta(9.0, clock[0] + 50.0)), "no progress since the first call: no rate yet"


def test_killed_writer_leaves_no_complete_looking_file(tmp_path):
    target = tmp_path / "out.h5"
    script = textwrap.dedent(f"""
        import time, h5py, numpy as np
        from impactpipe.storage import atomic_path
        with atomic_path({str(target)!r}) as tmp:
            with h5py.File(tmp, "w") as f:
                f["x"] = np.zeros(1000)
                print("writing", flush=True)
                time.sleep(30)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "writing"
    proc.kill()
    proc.wait()
    assert not target.exists()


def test_atomic_path_replaces_only_on_success(tmp_path):
    target = tmp_path / "summary.json"
    target.write_text(json.dumps({"old": True}))
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("writer failed")
    assert json.loads(target.read_text()) == {"old": True}
    assert [p.name for p in tmp_path.iterdir()] == ["summary.json"]


def test_atomic_path_gives_new_files_the_umask_mode_and_keeps_a_replaced_files_mode(tmp_path):
    """The temporary file starts at mode 0600 (mkstemp); outputs must not stay private."""
    fresh = tmp_path / "hydro.h5"
    with atomic_path(fresh) as tmp:
        tmp.write_text("new")
    mask = os.umask(0o022)
    os.umask(mask)
    assert fresh.stat().st_mode & 0o777 == 0o666 & ~mask
    plain = tmp_path / "plain.txt"
    plain.write_text("as open() makes it")
    assert fresh.stat().st_mode & 0o777 == plain.stat().st_mode & 0o777
    kept = tmp_path / "summary.json"
    kept.write_text("old")
    kept.chmod(0o640)
    with atomic_path(kept) as tmp:
        tmp.write_text("new")
    assert kept.stat().st_mode & 0o777 == 0o640
    assert kept.read_text() == "new"


def test_provenance_records_the_commit_of_the_imported_source(monkeypatch):
    """A sweep worker keeps running the code it imported; a commit made meanwhile must not
    appear in the provenance of its later outputs."""
    from impactpipe import storage

    imported = storage.SOURCE_COMMIT
    monkeypatch.setattr(storage, "git_commit", lambda: "0123456789abcdef-made-after-import")
    attrs = storage.provenance("name: x\n", storage.utc_now(), 1.0)
    assert attrs["git_commit"] == (imported or "unknown")


def test_cli_run_keeps_a_run_log_while_the_console_stays_quiet(tmp_path, calls):
    from click.testing import CliRunner

    from impactpipe.pipeline.cli import main

    path = tmp_path / "orchestration.yaml"
    path.write_text(CONFIG)
    result = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "run"), "-q"])
    assert result.exit_code == 0, result.output
    text = (tmp_path / "run" / "run.log").read_text()
    for stage in stages.STAGES:
        assert f"INFO impactpipe.pipeline.stages: {stage}: done in" in text
    assert " INFO " not in result.output
    again = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "run"), "-q"])
    assert again.exit_code == 0
    appended = (tmp_path / "run" / "run.log").read_text()
    assert appended.startswith(text) and "hydro: up to date" in appended[len(text):]


def test_run_logs_of_runs_in_threads_stay_apart(tmp_path):
    """Two runs in threads of one process (a Dask worker with threads): each run.log holds its
    own run's records only, and a nested run_log for the same directory adds no second copy."""
    import logging
    import threading

    from impactpipe.pipeline.runstore import run_log

    logger = logging.getLogger("impactpipe.test")
    barrier = threading.Barrier(2)

    def work(name):
        with run_log(tmp_path / name), run_log(tmp_path / name):
            for i in range(20):
                barrier.wait()
                logger.info("%s line %d", name, i)

    threads = [threading.Thread(target=work, args=(name,)) for name in ("a", "b")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for name, other in (("a", "b"), ("b", "a")):
        lines = (tmp_path / name / "run.log").read_text().splitlines()
        assert len(lines) == 20 and all(f"{name} line" in line for line in lines)
        assert not any(f"{other} line" in line for line in lines)
