"""Sweeps: grids on Dask, resume after a kill, failure isolation, shared hydro work, Q*_D bisection.

The stages are replaced by the instant stand-ins of tests/sweep_stand_ins.py, which log
every stage they finish, so the tests count work exactly.
"""

import collections
import concurrent.futures as cf
import contextlib
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

import sweep_stand_ins
from impactpipe.pipeline import stages
from impactpipe.pipeline.sweep import SweepError, load_sweep, run_sweep, sweep_status

HERE = Path(__file__).parent
BASE = HERE / "configs" / "sweep_base.yaml"


def write_sweep(tmp_path, **fields):
    spec = {"name": "test", "base": str(BASE), "output": str(tmp_path / "sweep"),
            "stage_functions": sweep_stand_ins.STAGES, **fields}
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def calls(tmp_path):
    log = tmp_path / "sweep" / "runs" / "calls.log"
    lines = log.read_text().split("\n") if log.is_file() else []
    return collections.Counter(tuple(line.split()) for line in lines if line)


def test_grid_on_dask_local_cluster_then_rerun_does_nothing(tmp_path):
    from distributed import Client, LocalCluster

    path = write_sweep(tmp_path, axes={"scene.impact.velocity": [1500.0, 2500.0],
                                       "scene.projectile.radius": [700.0, 900.0]})
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        result = run_sweep(load_sweep(path), executor=client.get_executor(pure=False), show_progress=False)
        assert len(result["points"]) == 4
        assert all(p["status"] == "complete" for p in result["points"].values())
        first = calls(tmp_path)
        assert sum(first.values()) == 16 and set(first.values()) == {1}
        run_sweep(load_sweep(path), executor=client.get_executor(pure=False), show_progress=False)
    assert calls(tmp_path) == first, "a second run of a finished sweep must do no work"
    rows = (tmp_path / "sweep" / "results.csv").read_text().strip().splitlines()
    assert len(rows) == 5 and "M_lr_over_M_T" in rows[0]
    q = 0.5 * (700.0 / 1.0e4) ** 3 * 1500.0 ** 2
    assert any(f"{1 - 0.5 * q / sweep_stand_ins.QSTAR:.6g}"[:6] in row for row in rows[1:])
    assert (tmp_path / "sweep" / "results.h5").is_file()


def test_failed_point_is_isolated_retried_and_reported(tmp_path):
    path = write_sweep(tmp_path, axes={"scene.impact.velocity": [1500.0, sweep_stand_ins.FAILING_VELOCITY, 2500.0]},
                       execution={"retries": 2})
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    status = {p["params"]["scene.impact.velocity"]: p for p in result["points"].values()}
    assert status[1500.0]["status"] == status[2500.0]["status"] == "complete"
    failed = status[sweep_stand_ins.FAILING_VELOCITY]
    assert failed["status"] == "failed" and failed["attempts"] == 3
    assert "synthetic failure at 666" in failed["error"]
    assert Path(failed["run_dir"], "error.log").is_file()
    report = sweep_status(tmp_path / "sweep")
    assert report["counts"] == {"complete": 2, "failed": 1}


def test_merge_and_bounce_share_one_hydro_run(tmp_path):
    path = write_sweep(tmp_path, axes={"nbody.collision_model": ["merge", "conditional_merge", "bounce"]})
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    assert all(p["status"] == "complete" for p in result["points"].values())
    done = calls(tmp_path)
    assert sum(n for (run, stage), n in done.items() if stage == "hydro") == 1
    assert sum(n for (run, stage), n in done.items() if stage == "handoff") == 1
    assert sum(n for (run, stage), n in done.items() if stage == "nbody") == 3
    for p in result["points"].values():
        assert Path(p["run_dir"], "hydro.h5").is_file()


def test_killed_sweep_resumes_and_runs_each_point_once(tmp_path):
    velocities = [1000.0 + 100.0 * i for i in range(8)]
    path = write_sweep(tmp_path, axes={"scene.impact.velocity": velocities},
                       execution={"backend": "local", "workers": 2}, stage_functions=sweep_stand_ins.SLOW_STAGES)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", "from impactpipe.pipeline.cli import main; main()", "sweep", str(path), "-q"],
                            env=env, start_new_session=True)
    deadline = time.time() + 90
    while time.time() < deadline:
        if sum(1 for (_, stage) in calls(tmp_path) if stage == "analysis") >= 2:
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    finished_before = sum(1 for (_, stage) in calls(tmp_path) if stage == "analysis")
    assert 2 <= finished_before < len(velocities), "the kill must land mid-sweep"
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    assert all(p["status"] == "complete" for p in result["points"].values())
    done = calls(tmp_path)
    assert len(done) == 4 * len(velocities), done
    # A kill can land after a stage's work (and its call-log line) but before the orchestrator
    # records it finished; that stage rightly runs again.  Only the stages in flight, at most
    # one per worker, may run twice; nothing finished is redone.
    rerun = [key for key, count in done.items() if count > 1]
    assert max(done.values()) <= 2 and len(rerun) <= 2, done


def test_sweep_stopped_by_sigterm_stops_its_workers_and_resumes(tmp_path):
    """SIGTERM to the sweep process alone (``kill PID``): its pool workers stop too, the hydro
    stages in flight record themselves as interrupted, and a rerun finishes every point."""
    velocities = [1000.0, 1100.0, 1200.0]
    path = write_sweep(tmp_path, axes={"scene.impact.velocity": velocities},
                       execution={"backend": "local", "workers": 2}, stage_functions=sweep_stand_ins.HANGING_STAGES)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", "from impactpipe.pipeline.cli import main; main()", "sweep", str(path), "-q"],
                            env=env, start_new_session=True)
    runs = tmp_path / "sweep" / "runs"
    deadline = time.time() + 90
    while time.time() < deadline and len(list(runs.glob("*.pid"))) < 2:
        time.sleep(0.05)
    pids = [int(p.read_text()) for p in runs.glob("*.pid")]
    assert len(pids) == 2, "both workers must be inside a hydro stage"
    os.kill(proc.pid, signal.SIGTERM)
    try:
        assert proc.wait(timeout=30) != 0
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    interrupted = [stages.read_records(d)["hydro"]["status"] for d in runs.iterdir()
                   if d.is_dir() and (runs / f"{d.name}.pid").exists()]
    assert interrupted == ["interrupted", "interrupted"]
    path = write_sweep(tmp_path, axes={"scene.impact.velocity": velocities},
                       execution={"backend": "local", "workers": 2}, stage_functions=sweep_stand_ins.STAGES)
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    assert [p["status"] for p in result["points"].values()] == ["complete"] * len(velocities)


def test_bisection_converges_on_synthetic_model(tmp_path):
    tolerance = 0.02
    low, high = 1000.0, 8000.0
    path = write_sweep(tmp_path, mode="qstar",
                       qstar={"variable": "scene.impact.velocity", "bracket": [low, high], "tolerance": tolerance})
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    (record,) = result["qstar"]
    v_crit = sweep_stand_ins.critical_velocity(1.0e4, 830.0)
    assert record["status"] == "converged"
    assert record["low"] <= v_crit <= record["high"]
    assert abs(record["bisection_estimate"] - v_crit) / v_crit < tolerance
    # each round halves the bracket: rounds until (high - low) / mid <= tolerance, plus the bracket round
    width, expected = high - low, 1
    while width / v_crit > tolerance:
        width /= 2.0
        expected += 1
    assert abs(record["rounds"] - expected) <= 1
    assert math.isclose(record["Qstar_D"], sweep_stand_ins.QSTAR, rel_tol=0.02)
    assert (tmp_path / "sweep" / "qstar.csv").is_file()


def test_bisection_widens_a_bracket_that_does_not_bracket(tmp_path):
    v_crit = sweep_stand_ins.critical_velocity(1.0e4, 830.0)
    path = write_sweep(tmp_path, mode="qstar", qstar={"bracket": [v_crit * 1.2, v_crit * 1.5], "tolerance": 0.05})
    with cf.ThreadPoolExecutor(2) as pool:
        (record,) = run_sweep(load_sweep(path), executor=pool, show_progress=False)["qstar"]
    assert record["status"] == "converged" and record["low"] <= v_crit <= record["high"]


def test_sweep_with_bad_axis_is_rejected_before_work(tmp_path):
    path = write_sweep(tmp_path, axes={"scene.impact.velocity": [1000.0, -5.0]})
    with pytest.raises(SweepError, match="scene.impact.velocity: must be > 0"):
        load_sweep(path)
    path = write_sweep(tmp_path, axes={"scene.impact.speed": [1000.0]})
    with pytest.raises(SweepError, match="not a config key"):
        load_sweep(path)
    assert not (tmp_path / "sweep").exists()


def test_real_stages_share_one_hydro_run_between_collision_models(tmp_path):
    """A tiny real impact: merge and conditional merge reuse one hydro and hand-off run."""
    base = tmp_path / "tiny.yaml"
    base.write_text((HERE.parent / "configs" / "quickstart.yaml").read_text()
                    .replace("cells_per_projectile_radius: 4", "cells_per_projectile_radius: 2")
                    .replace("velocity: 250.0", "velocity: 1.0e2"))
    spec = {"name": "real", "base": str(base), "output": str(tmp_path / "sweep"),
            "axes": {"nbody.collision_model": ["merge", "conditional_merge"]}}
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(spec))
    with cf.ThreadPoolExecutor(1) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    points = list(result["points"].values())
    assert [p["status"] for p in points] == ["complete", "complete"]
    records = [yaml.safe_load(Path(p["run_dir"], "stages.json").read_text()) for p in points]
    reused = [r["hydro"].get("reused_from") for r in records]
    assert sum(x is not None for x in reused) == 1, "exactly one point reuses the other's hydro run"
    hydro_files = [Path(p["run_dir"], "hydro.h5").stat().st_ino for p in points]
    assert hydro_files[0] == hydro_files[1], "the shared hydro.h5 is one file (hard link)"
    assert all(0.0 < p["summary"]["M_lr_over_M_T"] <= (1 + 0.1 ** 3) * (1 + 1e-3) for p in points)


SEEDS = [1, 2, 3, 4, 5]


def mlr_law(velocity, projectile_radius=830.0, target_radius=1.0e4):
    q = 0.5 * (projectile_radius / target_radius) ** 3 * velocity ** 2
    return 1.0 - 0.5 * q / sweep_stand_ins.QSTAR


def test_replicates_share_one_hydro_run_and_are_averaged(tmp_path):
    """Five hand-off seeds per point: one hydro run per point, the mean removes the seed offsets."""
    import csv

    import h5py

    velocities = [1500.0, 2500.0]
    path = write_sweep(tmp_path, axes={"scene.impact.velocity": velocities}, replicates={"handoff.seed": SEEDS},
                       stage_functions=sweep_stand_ins.NOISY_STAGES)
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    assert len(result["points"]) == 10
    done = calls(tmp_path)
    per_stage = collections.Counter(stage for (run, stage), n in done.items() for _ in range(n))
    assert per_stage == {"hydro": 2, "handoff": 10, "nbody": 10, "analysis": 10}
    rows = list(csv.DictReader(open(tmp_path / "sweep" / "replicates.csv")))
    assert [float(r["scene.impact.velocity"]) for r in rows] == velocities
    std = sweep_stand_ins.REPLICATE_NOISE * math.sqrt(2.5)
    for row, v in zip(rows, velocities):
        assert (row["runs"], row["complete"]) == ("5", "5")
        assert float(row["M_lr_over_M_T"]) == pytest.approx(mlr_law(v), abs=1e-12)
        assert float(row["M_lr_over_M_T_std"]) == pytest.approx(std, rel=1e-9)
        assert float(row["M_lr_over_M_T_sem"]) == pytest.approx(std / math.sqrt(5), rel=1e-9)
    with h5py.File(tmp_path / "sweep" / "results.h5") as f:
        assert f["replicates/M_lr_over_M_T"].attrs["units"] == "dimensionless"
        assert f["replicates/M_lr_over_M_T"][:] == pytest.approx([mlr_law(v) for v in velocities], abs=1e-12)


@pytest.mark.parametrize("noise_sigmas", [0.0, 2.0])
def test_qstar_search_bisects_the_mean_over_replicates(tmp_path, noise_sigmas):
    """Each bisection value is judged by its replicates' mean (here the exact law), and the fit's
    error bar carries their scatter.  With ``noise_sigmas`` the search stops at the first midpoint
    whose mean lies within that many standard errors of 0.5 (the seed offsets give a standard
    error of 0.03 sqrt(2.5) / sqrt(5) = 0.021): bisecting further would bisect the scatter."""
    tolerance = 0.02
    path = write_sweep(tmp_path, mode="qstar", replicates={"handoff.seed": SEEDS},
                       qstar={"variable": "scene.impact.velocity", "bracket": [1000.0, 8000.0], "tolerance": tolerance,
                              "noise_sigmas": noise_sigmas},
                       stage_functions=sweep_stand_ins.NOISY_STAGES)
    with cf.ThreadPoolExecutor(2) as pool:
        (record,) = run_sweep(load_sweep(path), executor=pool, show_progress=False)["qstar"]
    v_crit = sweep_stand_ins.critical_velocity(1.0e4, 830.0)
    assert record["low"] <= v_crit <= record["high"]
    assert record["replicates_per_value"] == 5
    assert record["replicate_std"] == pytest.approx(sweep_stand_ins.REPLICATE_NOISE * math.sqrt(2.5), rel=1e-9)
    assert 0.0 < record["Qstar_D_uncertainty"] < 0.1 * sweep_stand_ins.QSTAR
    assert abs(record["Qstar_D"] - sweep_stand_ins.QSTAR) < 2.0 * record["Qstar_D_uncertainty"]
    if noise_sigmas == 0.0:
        assert record["status"] == "converged"
        assert abs(record["bisection_estimate"] - v_crit) / v_crit < tolerance
        return
    sem = sweep_stand_ins.REPLICATE_NOISE * math.sqrt(2.5) / math.sqrt(5)
    assert record["status"] == "noise_limited"
    # the midpoints 4500, 2750, 1875, 2312.5 are resolved; 2531.25 (mean 0.488) is within 2 sem of 0.5
    assert (record["low"], record["high"]) == (2312.5, 2531.25)
    assert abs(mlr_law(2531.25) - 0.5) <= 2 * sem < abs(mlr_law(2312.5) - 0.5)
    assert record["rounds"] == 6  # the bracket's round and five midpoints


def test_handoff_time_replicates_share_one_hydro_run_to_the_latest_time(tmp_path):
    path = write_sweep(tmp_path, replicates={"handoff.time": [6.0, 4.0]})
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    done = calls(tmp_path)
    assert sum(n for (run, stage), n in done.items() if stage == "hydro") == 1
    assert sum(n for (run, stage), n in done.items() if stage == "handoff") == 2
    params = sorted((p["params"] for p in result["points"].values()), key=lambda p: p["handoff.time"])
    assert [p["handoff.time"] for p in params] == [4.0, 6.0]
    assert all(p["hydro.end_time"] == 6.0 and p["hydro.output_times"] == [4.0, 6.0] for p in params)


@pytest.mark.parametrize("fields, message", [
    ({"replicates": {"scene.impact.velocity": [1.0e3, 2.0e3]}}, "scene.impact.velocity cannot be replicated"),
    ({"replicates": {"handoff.seed": [1, 1]}}, "distinct values"),
    ({"replicates": {"handoff.seed": [1, 2]}, "axes": {"handoff.seed": [3]}}, "handoff.seed is also in axes"),
    ({"replicates": {"handoff.time": [4.0, 6.0]}, "overrides": {"hydro.end_time": 8.0}},
     "hydro.end_time cannot be set"),
    ({"replicates": {"handoff.time": [-4.0, 6.0]}}, "handoff.time: must be > 0"),
])
def test_bad_replicates_are_rejected_before_work(tmp_path, fields, message):
    path = write_sweep(tmp_path, **fields)
    with pytest.raises(SweepError, match=message):
        load_sweep(path)
    assert not (tmp_path / "sweep").exists()


def test_reuse_hydro_adds_seeds_to_an_earlier_run_without_rerunning_its_hydro(tmp_path):
    from click.testing import CliRunner

    from impactpipe.pipeline.cli import main

    first = write_sweep(tmp_path, axes={"scene.impact.velocity": [1500.0]})
    with cf.ThreadPoolExecutor(2) as pool:
        (donor,) = [p["run_dir"] for p in run_sweep(load_sweep(first), executor=pool, show_progress=False)["points"].values()]
    spec = {"name": "seeds", "base": str(BASE), "output": str(tmp_path / "seeds"), "replicates": {"handoff.seed": SEEDS},
            "axes": {"scene.impact.velocity": [1500.0]}, "stage_functions": sweep_stand_ins.NOISY_STAGES,
            "execution": {"workers": 1}}
    path = tmp_path / "seeds.yaml"
    path.write_text(yaml.safe_dump(spec))
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False, reuse_runs=[donor])
    assert [p["status"] for p in result["points"].values()] == ["complete"] * 5
    lines = (tmp_path / "seeds" / "runs" / "calls.log").read_text().split()
    # seed 1 is the donor's own hand-off: it adopts that too, and its N-body run
    assert (lines.count("hydro"), lines.count("handoff"), lines.count("nbody")) == (0, 4, 4)
    other = tmp_path / "other.yaml"
    other.write_text(yaml.safe_dump({**spec, "axes": {"scene.impact.velocity": [2500.0]}}))
    bad = CliRunner().invoke(main, ["sweep", str(other), "--reuse-hydro", donor, "--out", str(tmp_path / "o")])
    assert bad.exit_code == 2 and "its hydro settings match no point's" in bad.output
    assert not (tmp_path / "o").exists()


def test_real_stages_replicate_the_handoff_over_seeds(tmp_path):
    """The tiny real impact with two hand-off seeds: one hydro run, two hand-offs that differ only in
    what the seed draws (ring azimuths and velocity noise), and a replicates row averaging the runs."""
    import csv

    from impactpipe.handoff import read_particles

    base = tmp_path / "tiny.yaml"
    base.write_text((HERE.parent / "configs" / "quickstart.yaml").read_text()
                    .replace("cells_per_projectile_radius: 4", "cells_per_projectile_radius: 2")
                    .replace("velocity: 250.0", "velocity: 1.0e2"))
    spec = {"name": "real", "base": str(base), "output": str(tmp_path / "sweep"),
            "replicates": {"handoff.seed": [1, 2]}}
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(spec))
    with cf.ThreadPoolExecutor(1) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    points = sorted(result["points"].values(), key=lambda p: p["params"]["handoff.seed"])
    assert [p["status"] for p in points] == ["complete", "complete"]
    assert Path(points[0]["run_dir"], "hydro.h5").stat().st_ino == Path(points[1]["run_dir"], "hydro.h5").stat().st_ino
    one, two = (read_particles(Path(p["run_dir"], "handoff.h5")) for p in points)
    np.testing.assert_array_equal(one.mass, two.mass)
    np.testing.assert_allclose(np.hypot(one.position[:, 0], one.position[:, 1]),
                               np.hypot(two.position[:, 0], two.position[:, 1]), rtol=1e-12)
    np.testing.assert_array_equal(one.position[:, 2], two.position[:, 2])
    assert np.abs(one.velocity - two.velocity).max() > 0.0
    (row,) = csv.DictReader(open(tmp_path / "sweep" / "replicates.csv"))
    mlr = [p["summary"]["M_lr_over_M_T"] for p in points]
    assert (row["runs"], row["complete"]) == ("2", "2")
    assert float(row["M_lr_over_M_T"]) == pytest.approx(np.mean(mlr), rel=1e-12)


def test_a_rerun_with_other_downstream_settings_adopts_the_earlier_hydro_runs(tmp_path):
    """Point names hash the whole config, so a changed N-body setting (or a config key added
    by a new version) gives every point a new directory; the hydro runs already in runs/ are
    adopted all the same, and only the downstream stages run again."""
    velocities = [1500.0, 2500.0]
    path = write_sweep(tmp_path, axes={"scene.impact.velocity": velocities})
    with cf.ThreadPoolExecutor(2) as pool:
        run_sweep(load_sweep(path), executor=pool, show_progress=False)
    path = write_sweep(tmp_path, axes={"scene.impact.velocity": velocities}, overrides={"nbody.opening_angle": 0.3})
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    assert [p["status"] for p in result["points"].values()] == ["complete"] * 2
    done = collections.Counter(stage for (run, stage), n in calls(tmp_path).items() for _ in range(n))
    assert done == {"hydro": 2, "handoff": 2, "nbody": 4, "analysis": 4}
    # runs/ now holds both versions' points; `impactpipe qstar SWEEP_DIR` fits the current ones only
    from click.testing import CliRunner

    from impactpipe.pipeline.cli import main

    assert len([d for d in (tmp_path / "sweep" / "runs").iterdir() if d.is_dir()]) == 4
    fit = CliRunner().invoke(main, ["qstar", str(tmp_path / "sweep"), "--out", str(tmp_path / "fit")])
    assert fit.exit_code == 0, fit.output
    assert "2 finished points of the sweep" in fit.output and "from 2 of 2 runs" in fit.output


def test_replicates_run_as_soon_as_their_hydro_run_is_done(tmp_path):
    """One worker, two speeds with three seeds: the second and third seed of the first speed (a
    hand-off and N-body away) run before the second speed's hydro, not queued behind it."""
    path = write_sweep(tmp_path, axes={"scene.impact.velocity": [1500.0, 2500.0]},
                       replicates={"handoff.seed": [1, 2, 3]}, execution={"workers": 1})
    with cf.ThreadPoolExecutor(1) as pool:
        run_sweep(load_sweep(path), executor=pool, show_progress=False)
    lines = [line.split() for line in (tmp_path / "sweep" / "runs" / "calls.log").read_text().splitlines()]
    order = [(run.split("_")[0], stage) for run, stage in lines]
    second_hydro = order.index(("velocity=2500", "hydro"))
    assert [stage for run, stage in order[:second_hydro]].count("handoff") == 3
