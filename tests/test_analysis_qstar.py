"""Q*_D fit on synthetic runs drawn from a known line."""

import csv
import logging

import numpy as np
import pytest

from impactpipe.analysis import fit_qstar, write_qstar_table
from impactpipe.analysis.qstar import plus_minus, pooled_replicate_std

QSTAR = 1790.0  # J/kg, case 8 of method.md section 6
GAMMA = 0.083**3  # (R_P/R_T)^3, equal densities


def synthetic_runs(seed, n_runs=10, noise=0.03):
    """M_lr/M_T = 1 - 0.5 Q/Q*_D plus Gaussian noise, Q spanning 0.3-1.6 Q*_D."""
    rng = np.random.default_rng(seed)
    q = np.linspace(0.3, 1.6, n_runs) * QSTAR
    y = 1.0 - 0.5 * q / QSTAR + rng.normal(0.0, noise, n_runs)
    n_lr = np.where(y > 0.35, 1500, 150)
    return q, y, n_lr


def test_recovers_qstar_within_reported_uncertainty():
    q, y, n_lr = synthetic_runs(seed=11)
    fit = fit_qstar(q, y, n_lr, n_bootstrap=2000, seed=0)
    assert fit.brackets
    assert fit.used.all()
    assert 0.0 < fit.qstar_err < 0.1 * QSTAR
    assert abs(fit.qstar - QSTAR) < 2.0 * fit.qstar_err
    assert fit.qstar_interval[0] < fit.qstar < fit.qstar_interval[1]
    assert fit.normalized_slope == pytest.approx(-0.5, abs=3 * fit.normalized_slope_err)
    np.testing.assert_allclose(fit.weights, np.where(n_lr >= 200, 1.0, 0.25))


def test_bootstrap_coverage_over_seeds():
    hits = 0
    n_seeds = 20
    for seed in range(n_seeds):
        q, y, n_lr = synthetic_runs(seed=100 + seed)
        fit = fit_qstar(q, y, n_lr, n_bootstrap=400, seed=seed)
        hits += abs(fit.qstar - QSTAR) < 2.0 * fit.qstar_err
    # ~95% expected for a 2-sigma interval; the bootstrap of 10 runs is somewhat narrow
    assert hits >= 16


def test_weighted_line_matches_numpy_polyfit():
    q = np.array([800.0, 1200.0, 1600.0, 2100.0, 2600.0])
    y = np.array([0.80, 0.62, 0.57, 0.41, 0.30])
    n_lr = np.array([900, 800, 600, 150, 120])
    fit = fit_qstar(q, y, n_lr, n_bootstrap=10)
    w = np.where(n_lr >= 200, 1.0, 0.25)
    slope, intercept = np.polyfit(q, y, 1, w=np.sqrt(w))  # polyfit weights multiply residuals
    assert fit.slope == pytest.approx(slope, rel=1e-10)
    assert fit.intercept == pytest.approx(intercept, rel=1e-10)
    assert fit.qstar == pytest.approx((0.5 - intercept) / slope, rel=1e-10)


def test_unresolved_runs_are_excluded_and_critical_velocity():
    # exact line, case-8 geometry: Q = 0.5 gamma v^2; v* = sqrt(2 Q*_D / gamma) = 2.502 km/s
    v = np.array([1.0e3, 1.9e3, 2.8e3, 3.7e3])
    q = 0.5 * GAMMA * v**2
    y = 1.0 - 0.5 * q / QSTAR
    y[-1] = 0.05  # like run 8a: an unresolved remnant, left out of the fit
    n_lr = np.array([1350, 1350, 228, 140])
    fit = fit_qstar(q, y, n_lr, velocity=v, n_bootstrap=200)
    np.testing.assert_array_equal(fit.used, [True, True, True, False])
    assert fit.weights[-1] == 0.0
    assert fit.qstar == pytest.approx(QSTAR, rel=1e-10)
    assert fit.critical_velocity == pytest.approx(np.sqrt(2 * QSTAR / GAMMA), rel=1e-10)
    assert abs(fit.critical_velocity - 2500.0) < 40.0  # reference: 2.50 +- 0.04 km/s
    assert fit.qstar_err == pytest.approx(0.0, abs=1e-6)  # no scatter about an exact line


def test_critical_projectile_radius_at_fixed_speed():
    r_p = np.array([400.0, 600.0, 800.0, 1000.0])
    q = 0.5 * (r_p / 1e4) ** 3 * 3000.0**2
    y = 1.0 - 0.5 * q / QSTAR
    fit = fit_qstar(q, y, np.full(4, 1000), projectile_radius=r_p, n_bootstrap=50)
    assert fit.critical_radius == pytest.approx(1e4 * (2 * QSTAR / 3000.0**2) ** (1 / 3), rel=1e-10)
    with pytest.raises(ValueError, match="swept"):
        fit_qstar(q, y, np.full(4, 1000), velocity=np.array([1.0e3, 2.0e3, 3.0e3, 3.5e3]))


def test_flags_runs_that_do_not_bracket_half(caplog):
    q = np.array([200.0, 400.0, 600.0, 800.0])
    y = 1.0 - 0.5 * q / QSTAR  # all above 0.5
    with caplog.at_level(logging.WARNING, logger="impactpipe.analysis.qstar"):
        fit = fit_qstar(q, y, np.full(4, 1000), n_bootstrap=100)
    assert not fit.brackets
    assert fit.qstar == pytest.approx(QSTAR)
    assert "bracket" in caplog.text


def test_two_runs_give_no_uncertainty():
    """A line through two runs fits them exactly: Q*_D without an error bar, not with a zero one."""
    fit = fit_qstar([1000.0, 2000.0], [0.7, 0.3], [1500, 1500], velocity=[1900.0, 1900.0 * np.sqrt(2.0)])
    assert fit.qstar == pytest.approx(1500.0)
    assert np.isnan(fit.qstar_err) and np.isnan(fit.normalized_slope_err) and np.isnan(fit.critical_velocity_err)
    assert all(np.isnan(fit.qstar_interval))
    assert plus_minus(fit.qstar, fit.qstar_err) == "1.5e+03 (no error bar)"
    assert plus_minus(1790.0, 60.0, ".4g") == "1790 +- 60"


def test_degenerate_sets_raise():
    with pytest.raises(ValueError, match="two runs"):
        fit_qstar([1000.0, 2000.0], [0.6, 0.05], [500, 500])
    with pytest.raises(ValueError, match="decrease"):
        fit_qstar([1000.0, 2000.0], [0.4, 0.6], [500, 500])


def test_table_round_trip(tmp_path):
    q, y, n_lr = synthetic_runs(seed=5, n_runs=6)
    v = np.sqrt(2 * q / GAMMA)
    fit = fit_qstar(q, y, n_lr, velocity=v, n_bootstrap=200)
    path = write_qstar_table(tmp_path / "qstar.csv", q, y, n_lr, fit, velocity=v,
                             labels=[f"run{i}" for i in range(6)])
    text = path.read_text()
    assert text.startswith("# Q*_D = ")
    assert "critical velocity" in text
    rows = list(csv.DictReader(line for line in text.splitlines() if not line.startswith("#")))
    assert [r["run"] for r in rows] == [f"run{i}" for i in range(6)]
    np.testing.assert_allclose([float(r["Q_J_per_kg"]) for r in rows], q, rtol=1e-15)
    np.testing.assert_allclose([float(r["Q_over_QstarD"]) for r in rows], q / fit.qstar, rtol=1e-15)
    np.testing.assert_allclose([float(r["weight"]) for r in rows], fit.weights)
    np.testing.assert_allclose([float(r["velocity_m_per_s"]) for r in rows], v)
    assert [int(r["used"]) for r in rows] == [1] * 6


def test_pooled_replicate_std_by_hand():
    # Q 1: values 0.6, 0.8 (squares 0.01 + 0.01); Q 2: 0.3, 0.4, 0.5 (0.01 + 0 + 0.01); Q 3 single
    q = [1.0, 2.0, 1.0, 2.0, 3.0, 2.0]
    y = [0.6, 0.3, 0.8, 0.4, 0.9, 0.5]
    s, groups = pooled_replicate_std(q, y)
    assert groups == 2
    assert s == pytest.approx(np.sqrt(0.04 / 3), rel=1e-12)
    s, groups = pooled_replicate_std([1.0, 2.0], [0.6, 0.3])
    assert groups == 0 and np.isnan(s)


def replicated_runs(seed, values_of_q, replicates, noise):
    """``replicates`` runs at each Q of an exact line plus Gaussian scatter ``noise``."""
    rng = np.random.default_rng(seed)
    q = np.repeat(np.asarray(values_of_q, dtype=float) * QSTAR, replicates)
    y = 1.0 - 0.5 * q / QSTAR + rng.normal(0.0, noise, q.size)
    return q, y, np.full(q.size, 1500)


def test_replicates_put_the_scatter_into_the_error_bar():
    """One run per Q hides the method's scatter; replicates measure it and the bootstrap carries it."""
    noise = 0.05
    q, y, n_lr = replicated_runs(1, [0.6, 1.0, 1.4], 40, noise)
    fit = fit_qstar(q, y, n_lr, n_bootstrap=1000)
    assert fit.replicated_q == 3
    assert fit.replicate_std == pytest.approx(noise, rel=0.15)
    # at Q*_D the line's error is that of the mean of all n runs, s / sqrt(n), and
    # Q*_D's is that over the slope |b| = 0.5 / Q*_D: 2 s Q*_D / sqrt(n) (about 0.8 % here)
    expected = 2.0 * fit.replicate_std * QSTAR / np.sqrt(q.size)
    assert fit.qstar_err == pytest.approx(expected, rel=0.25)
    hits = 0
    for seed in range(20):
        q, y, n_lr = replicated_runs(200 + seed, [0.7, 1.3], 4, noise)
        fit = fit_qstar(q, y, n_lr, n_bootstrap=400, seed=seed)
        assert np.isfinite(fit.qstar_err)  # two distinct Q, each replicated: an error bar
        hits += abs(fit.qstar - QSTAR) < 2.0 * fit.qstar_err
    assert hits >= 16
    one_each = fit_qstar([0.7 * QSTAR, 1.0 * QSTAR, 1.3 * QSTAR], [0.65, 0.5, 0.35], [1500] * 3, n_bootstrap=200)
    assert one_each.replicated_q == 0 and np.isnan(one_each.replicate_std)
    assert one_each.qstar_err == pytest.approx(0.0, abs=1e-6)  # exact line: the bootstrap sees no scatter
