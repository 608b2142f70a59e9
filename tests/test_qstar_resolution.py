"""Q*_D with two errors: the runs' scatter and the resolution error of a ladder."""

from __future__ import annotations

import concurrent.futures as cf
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from impactpipe.analysis.resolution_error import qstar_resolution_error, write_resolution_table
from impactpipe.analysis.richardson import richardson
from impactpipe.pipeline.cli import main
from impactpipe.pipeline.sweep import SweepError, load_sweep, run_sweep

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
import sweep_stand_ins  # noqa: E402
from test_sweep import write_sweep as sweep_file  # noqa: E402

LADDER = [10.0, 20.0, 40.0]


def expected_qstar(n: float) -> float:
    return sweep_stand_ins.QSTAR * (1.0 + sweep_stand_ins.RESOLUTION_C / n ** 2)


def test_a_second_order_ladder_extrapolates_to_its_limit():
    exact = [expected_qstar(n) for n in LADDER]
    distance = expected_qstar(40.0) - sweep_stand_ins.QSTAR
    sharp = qstar_resolution_error(LADDER, exact, [1e-6, 1e-6, 1e-6])
    assert sharp.ok and sharp.refused == 0.0
    assert sharp.order == pytest.approx(2.0, abs=1e-9)
    assert sharp.extrapolated == pytest.approx(sweep_stand_ins.QSTAR, rel=1e-12)
    assert sharp.error == pytest.approx(distance, rel=1e-5)
    assert sharp.extrapolated_range == pytest.approx((sweep_stand_ins.QSTAR,) * 2, rel=1e-6)
    ladder = qstar_resolution_error(LADDER, exact, [10.0, 11.0, 12.0])
    assert ladder.ok and ladder.extrapolated == sharp.extrapolated and ladder.order == sharp.order
    low, high = ladder.extrapolated_range
    assert low < sweep_stand_ins.QSTAR < high and 0.0 < ladder.refused < 0.5  # seed errors near the last change
    assert ladder.error > distance, "the rungs' seed errors widen the resolution error"
    assert list(ladder.resolutions) == [40.0, 20.0, 10.0] and ladder.seed_error[0] == 12.0
    text = ladder.describe()
    assert "(seeds) +-" in text and "observed order 2.00" in text and "68 % of the extrapolations in" in text


def test_the_resolution_error_covers_the_limit_of_noisy_ladders_about_68_percent_of_the_time():
    """Verification against a known limit: ladders Q*_D(n) = 700 + 2e4 / n^2 J/kg at 5/10/20
    cells, each rung drawn with its seed error (400, 60, 25 J/kg: a coarse rung as uncertain as
    case 9's).  The converged value lies within the resolution error of the finest rung in about
    68 % of the extrapolated ladders (measured 0.72 over these 80); the distance to the means'
    Richardson value alone covers it in only 0.57."""
    n = np.array([5.0, 10.0, 20.0])
    limit = 700.0
    sigma = np.array([400.0, 60.0, 25.0])
    rng = np.random.default_rng(1)
    covered = covered_by_means = extrapolated = 0
    for _ in range(80):
        q = limit + 2.0e4 / n ** 2 + sigma * rng.standard_normal(3)
        ladder = qstar_resolution_error(n, q, sigma)
        if not ladder.ok:
            continue
        extrapolated += 1
        distance = abs(q[2] - limit)
        covered += distance <= ladder.error
        covered_by_means += distance <= abs(q[2] - ladder.extrapolated)
    assert extrapolated >= 50
    assert 0.6 <= covered / extrapolated <= 0.85
    assert covered_by_means / extrapolated < covered / extrapolated - 0.1


def test_case9_ladder_in_numbers():
    """The documented case 9 statement (docs/validation.md): the 5-cell rung's Q*_D is a line
    extrapolated beyond its runs (+-640 J/kg), so the extrapolation's uncertainty, not the
    means' Richardson distance (17 J/kg), sets the resolution error."""
    ladder = qstar_resolution_error([5, 10, 20], [1382.3, 831.5, 741.8], [640.0, 88.0, 27.0])
    assert ladder.ok and ladder.order == pytest.approx(2.62, abs=0.01)
    assert abs(ladder.qstar[0] - ladder.extrapolated) == pytest.approx(17.4, abs=0.1)
    assert ladder.error == pytest.approx(49.8, abs=0.1)
    assert ladder.refused == pytest.approx(0.39, abs=0.01)
    assert ladder.extrapolated_range == pytest.approx((656.6, 755.5), abs=0.1)


def test_a_ladder_whose_draws_mostly_refuse_gets_no_error():
    ladder = qstar_resolution_error([5, 10, 20], [1382.3, 831.5, 741.8], [640.0, 300.0, 27.0])
    assert richardson_ok([5, 10, 20], [1382.3, 831.5, 741.8])
    assert not ladder.ok and "resamplings of the rungs within their seed errors cannot be extrapolated" in ladder.status
    assert ladder.refused > 0.5 and math.isnan(ladder.error) and math.isnan(ladder.extrapolated)
    assert "resolution error not estimated" in ladder.describe()


def richardson_ok(resolutions, qstar):
    return richardson(1.0 / np.asarray(resolutions, dtype=float), np.asarray(qstar, dtype=float)).ok


@pytest.mark.parametrize(("qstar", "why"), [
    ([1395.0, 1239.0, 1120.0], "observed order 0.39 below 0.5"),  # case 8's measured ladder
    ([1395.0, 1239.0, 1300.0], "non-monotone"),
    ([1395.0, 1300.0, 1200.0], "not converging"),
])
def test_a_ladder_outside_the_asymptotic_range_gets_no_invented_error(qstar, why):
    ladder = qstar_resolution_error(LADDER, qstar, [11.0, 14.0, 12.0])
    assert not ladder.ok and why in ladder.status
    assert math.isnan(ladder.error) and math.isnan(ladder.extrapolated)
    assert ladder.last_change == pytest.approx(qstar[2] - qstar[1])
    assert "resolution error not estimated" in ladder.describe()


def test_two_rungs_give_the_last_change_only(tmp_path):
    ladder = qstar_resolution_error([20.0, 40.0], [1239.0, 1120.0], [14.0, 12.0])
    assert "needs 3" in ladder.status and ladder.last_change == pytest.approx(-119.0)
    text = write_resolution_table(tmp_path / "r.csv", ladder).read_text().splitlines()
    assert text[0].startswith("# Q*_D = 1120") and text[2] == "cells_per_projectile_radius,Qstar_D_J_per_kg,seed_error_J_per_kg"
    assert text[3].startswith("40.0,1120.0,12.0")


def test_bad_ladders_are_refused():
    with pytest.raises(ValueError, match="distinct"):
        qstar_resolution_error([10, 10, 20], [1.0, 2.0, 3.0], [0.1, 0.1, 0.1])
    with pytest.raises(ValueError, match="same"):
        qstar_resolution_error([10, 20], [1.0], [0.1])


def write_sweep(tmp_path, **fields):
    """test_sweep's sweep file, with stages whose Q*_D depends on the resolution."""
    return sweep_file(tmp_path, stage_functions=sweep_stand_ins.RESOLVED_STAGES, **fields)


def test_a_sweep_with_a_resolution_ladder_reports_both_errors(tmp_path):
    path = write_sweep(tmp_path, mode="qstar", resolution=LADDER,
                       qstar={"variable": "scene.impact.velocity", "bracket": [1000.0, 8000.0], "tolerance": 0.05})
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    assert sorted(r["hydro.cells_per_projectile_radius"] for r in result["qstar"]) == LADDER
    (ladder,) = result["resolution"]
    assert ladder["Qstar_D"] == pytest.approx(expected_qstar(40.0), rel=1e-6)
    assert ladder["observed_order"] == pytest.approx(2.0, rel=1e-4)
    assert ladder["richardson"] == pytest.approx(sweep_stand_ins.QSTAR, rel=1e-5)
    assert ladder["resolution_error"] == pytest.approx(expected_qstar(40.0) - sweep_stand_ins.QSTAR, rel=1e-3)
    assert (tmp_path / "sweep" / "qstar_resolution.csv").is_file()
    # impactpipe qstar over the finished sweep groups its runs by resolution the same way
    out = CliRunner().invoke(main, ["qstar", str(tmp_path / "sweep"), "--out", str(tmp_path / "fit")])
    assert out.exit_code == 0, out.output
    assert "(resolution: Richardson" in out.output and "observed order 2.00" in out.output
    assert (tmp_path / "fit" / "qstar_resolution.csv").is_file()
    assert sorted(p.name for p in (tmp_path / "fit").glob("qstar_n*.csv")) == \
        ["qstar_n10.csv", "qstar_n20.csv", "qstar_n40.csv"]


@pytest.mark.parametrize(("fields", "message"), [
    ({"resolution": [10.0]}, "at least two distinct"),
    ({"resolution": [10.0, 20.0], "axes": {"hydro.cells_per_projectile_radius": [5, 10]}}, "also in axes"),
])
def test_a_bad_resolution_ladder_is_a_sweep_file_error(tmp_path, fields, message):
    with pytest.raises(SweepError, match=message):
        load_sweep(write_sweep(tmp_path, **fields))


def test_case8_ladder_in_numbers():
    """The documented case 8 statement (docs/accuracy.md, "Q*_D against resolution", measured on
    0.1.0) is what the function gives for that Q*_D ladder (five seeds x four speeds per rung)."""
    ladder = qstar_resolution_error([5, 10, 20, 40], [1643.0, 1395.0, 1239.0, 1120.0], [76.0, 11.0, 14.0, 12.0])
    assert not ladder.ok and ladder.order == pytest.approx(0.39, abs=0.01)
    assert np.isclose(ladder.last_change, -119.0)


def test_a_grid_sweep_with_a_resolution_ladder_fits_each_rung(tmp_path):
    velocities = [2000.0, 2400.0, 2800.0, 3200.0]
    path = write_sweep(tmp_path, resolution=LADDER, axes={"scene.impact.velocity": velocities})
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_sweep(load_sweep(path), executor=pool, show_progress=False)
    assert len(result["points"]) == len(velocities) * len(LADDER)
    (ladder,) = result["resolution"]
    assert ladder["Qstar_D_n10"] == pytest.approx(expected_qstar(10.0), rel=1e-9)
    assert ladder["richardson"] == pytest.approx(sweep_stand_ins.QSTAR, rel=1e-9)


def test_a_rung_whose_runs_do_not_bracket_half_is_named():
    ladder = qstar_resolution_error(LADDER, [expected_qstar(n) for n in LADDER], [10.0, 11.0, 12.0],
                                    brackets=[False, True, True])
    assert ladder.ok and ladder.unbracketed == (10.0,)
    assert "caution: the runs at 10 cells per projectile radius do not bracket" in ladder.describe()
