"""Q*_D's hand-off-time error: Q*_D fitted at each hand-off time, their spread and slope."""

from __future__ import annotations

import concurrent.futures as cf
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from impactpipe.analysis.handoff_error import fit_by_handoff_time, qstar_handoff_error, write_handoff_table
from impactpipe.pipeline.cli import main
from impactpipe.pipeline.sweep import load_sweep, run_sweep

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
import sweep_stand_ins  # noqa: E402
from test_sweep import write_sweep  # noqa: E402

TIMES = [4.0, 6.0, 8.0]


def timed_qstar(t: float) -> float:
    return sweep_stand_ins.QSTAR * (1.0 + sweep_stand_ins.HANDOFF_TIME_C * t)


def test_a_linear_trend_is_measured_exactly():
    q = [timed_qstar(t) for t in TIMES]
    result = qstar_handoff_error(TIMES[::-1], q[::-1], [10.0, 10.0, 10.0])
    assert list(result.times) == TIMES
    assert result.slope == pytest.approx(sweep_stand_ins.QSTAR * sweep_stand_ins.HANDOFF_TIME_C, rel=1e-12)
    assert result.slope_err == pytest.approx(0.0, abs=1e-9)
    assert result.mean == pytest.approx(timed_qstar(6.0), rel=1e-12)
    assert result.error == pytest.approx(2.0 * result.slope, rel=1e-12)  # std of 4, 6, 8 s is 2 s
    assert result.status == "trend"


def test_the_slope_test_rejects_a_true_plateau_about_five_percent_of_the_time():
    """Verification against a known answer: Q*_D constant over four hand-off times with normal
    scatter; the slope test calls 'trend' in about 5 % of the draws (its confidence), and finds
    a slope of three scatter widths per time step in most."""
    rng = np.random.default_rng(3)
    times = np.array([14.0, 16.0, 18.0, 20.0])
    flat = [qstar_handoff_error(times, 1000.0 + 30.0 * rng.standard_normal(4), np.full(4, 30.0)).status
            for _ in range(1000)]
    assert 0.03 <= flat.count("trend") / len(flat) <= 0.07
    steep = [qstar_handoff_error(times, 1000.0 + 45.0 * times + 30.0 * rng.standard_normal(4),
                                 np.full(4, 30.0)).status for _ in range(200)]
    assert steep.count("trend") / len(steep) > 0.8


def test_two_times_give_the_spread_without_a_slope_test(tmp_path):
    result = qstar_handoff_error([10.0, 12.0], [900.0, 960.0], [20.0, 25.0])
    assert result.status == "two times" and np.isnan(result.slope_err)
    assert result.slope == pytest.approx(30.0) and result.error == pytest.approx(60.0 / np.sqrt(2.0))
    assert "untested" in result.describe()
    lines = write_handoff_table(tmp_path / "h.csv", result).read_text().splitlines()
    assert lines[0].startswith("# hand-off at 10/12 s") and lines[1].startswith("handoff_time_s")
    assert lines[2:] == ["10.0,900.0,20.0", "12.0,960.0,25.0"]


def test_bad_hand_off_times_are_refused():
    with pytest.raises(ValueError, match="distinct"):
        qstar_handoff_error([10.0, 10.0], [1.0, 2.0], [0.1, 0.1])
    with pytest.raises(ValueError, match="at least two"):
        qstar_handoff_error([10.0], [1.0], [0.1])
    with pytest.raises(ValueError, match="fitted"):
        qstar_handoff_error([10.0, 12.0], [1.0, np.nan], [0.1, 0.1])


def test_fit_by_handoff_time_fits_each_time_and_names_the_unfittable():
    q = np.array([500.0, 1500.0, 2500.0] * 3)
    t = np.repeat([14.0, 16.0, 18.0], 3)
    qstar = np.array([timed_qstar(x) for x in t])
    mlr = 1.0 - 0.5 * q / qstar
    result, problems = fit_by_handoff_time(t, q, mlr, np.full(q.size, 5000))
    assert problems == []
    assert result.qstar == pytest.approx([timed_qstar(x) for x in (14.0, 16.0, 18.0)], rel=1e-9)
    one_run = np.append(t[:6], 20.0)
    result, problems = fit_by_handoff_time(one_run, q[:7], mlr[:7], np.full(7, 5000))
    assert list(result.times) == [14.0, 16.0] and len(problems) == 1 and problems[0].startswith("hand-off at 20 s")
    assert fit_by_handoff_time(t[:3], q[:3], mlr[:3], np.full(3, 5000)) == (None, [])
    unfinished = mlr.copy()
    unfinished[[0, 4]] = np.nan
    result, problems = fit_by_handoff_time(t, q, unfinished, np.full(q.size, 5000))
    assert problems == [] and result.qstar == pytest.approx([timed_qstar(x) for x in (14.0, 16.0, 18.0)], rel=1e-9)


def test_a_sweep_with_handoff_time_replicates_reports_the_handoff_time_error(tmp_path):
    path = write_sweep(tmp_path, stage_functions=sweep_stand_ins.TIMED_STAGES, mode="qstar",
                       replicates={"handoff.time": TIMES},
                       qstar={"variable": "scene.impact.velocity", "bracket": [1000.0, 8000.0], "tolerance": 0.05})
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    (record,) = result["qstar"]
    for t in TIMES:
        assert record[f"Qstar_D_t{t:g}"] == pytest.approx(timed_qstar(t), rel=1e-9)
    slope = sweep_stand_ins.QSTAR * sweep_stand_ins.HANDOFF_TIME_C
    assert record["Qstar_D_handoff_slope"] == pytest.approx(slope, rel=1e-9)
    assert record["Qstar_D_handoff_error"] == pytest.approx(2.0 * slope, rel=1e-9)
    assert record["handoff_status"] == "trend"
    out = CliRunner().invoke(main, ["qstar", str(tmp_path / "sweep"), "--out", str(tmp_path / "fit")])
    assert out.exit_code == 0, out.output
    assert "hand-off at 4/6/8 s: Q*_D = " in out.output and "(trend)" in out.output
    rows = (tmp_path / "fit" / "qstar_handoff.csv").read_text().splitlines()[2:]
    assert [float(r.split(",")[1]) for r in rows] == pytest.approx([timed_qstar(t) for t in TIMES], rel=1e-9)


def test_runs_of_one_handoff_time_get_no_handoff_time_error(tmp_path):
    path = write_sweep(tmp_path, stage_functions=sweep_stand_ins.TIMED_STAGES, mode="qstar",
                       overrides={"hydro.end_time": 6.0, "handoff.time": 6.0},
                       qstar={"variable": "scene.impact.velocity", "bracket": [1000.0, 8000.0], "tolerance": 0.05})
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    (record,) = result["qstar"]
    assert not any(k.startswith("Qstar_D_handoff") or k == "handoff_status" for k in record)
    out = CliRunner().invoke(main, ["qstar", str(tmp_path / "sweep"), "--out", str(tmp_path / "fit")])
    assert out.exit_code == 0, out.output
    assert "hand-off at" not in out.output and not (tmp_path / "fit" / "qstar_handoff.csv").exists()


def test_handoff_time_replicates_on_the_points_own_snapshots_share_its_hydro_run(tmp_path):
    """Hand-off times that the point's hydro run writes anyway set no hydro keys, so every
    replicate has the hydro settings of the point itself and a finished run of it serves them."""
    from impactpipe.pipeline.stages import stage_hashes

    snapshots = load_sweep(write_sweep(tmp_path)).snapshots({})
    times = [snapshots[6], snapshots[-1]]
    assert all(type(t) is float for t in snapshots)
    sweep = load_sweep(write_sweep(tmp_path, replicates={"handoff.time": times, "handoff.seed": [1, 2]}))
    point = {"scene.impact.velocity": 2000.0}
    runs = sweep.replicate_runs(point)
    assert sorted((r["handoff.time"], r["handoff.seed"]) for r in runs) == [(t, s) for t in times for s in (1, 2)]
    assert all("hydro.end_time" not in r and "hydro.output_times" not in r for r in runs)
    hydro = stage_hashes(sweep.config_for(point))["hydro"]
    assert {stage_hashes(sweep.config_for(r))["hydro"] for r in runs} == {hydro}
    later = load_sweep(write_sweep(tmp_path, replicates={"handoff.time": [times[0], times[1] + 1.0]}))
    assert all(r["hydro.end_time"] == times[1] + 1.0 for r in later.replicate_runs(point))


def test_case9_handoff_times_in_numbers():
    """The documented case 9 statement (docs/validation.md, "Q*_D of case 9 with three errors"):
    at 20 cells Q*_D falls with the hand-off time by more than the slope test allows."""
    result = qstar_handoff_error([14.0, 16.0, 18.0, 20.0], [811.8, 795.5, 759.1, 741.8], [20.0, 20.0, 20.0, 20.0])
    assert result.status == "trend"
    assert result.slope == pytest.approx(-12.3, abs=0.05) and result.slope_err == pytest.approx(1.4, abs=0.05)
    assert result.error == pytest.approx(32.2, abs=0.05) and result.mean == pytest.approx(777.05, abs=0.01)
