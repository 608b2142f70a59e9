"""Catastrophic disruption threshold Q*_D from a set of runs.

Method (method reference, section 5): for runs at a fixed size ratio and varying
speed (or fixed speed and varying projectile size), fit the straight line

    M_lr/M_T = a + b Q

by weighted least squares over the resolved runs (M_lr/M_T > ``min_mlr``, default
0.1; below that the largest remnant is a handful of particles and the linear
shape no longer holds).  Runs whose largest remnant has fewer than
``n_lr_resolved`` particles (default 200) get weight ``underresolved_weight``
(default 0.25, i.e. the residual of such a run counts a quarter as much, as if its
M_lr/M_T scatter were twice as large); the others weight 1.
Q*_D is where the line crosses 0.5:

    Q*_D = (0.5 - a) / b.

Uncertainty: bootstrap over runs.  ``n_bootstrap`` samples of the used runs are
drawn with replacement (numpy Generator seeded with ``seed``), refitted with
their weights, and samples with fewer than two distinct Q or a non-negative slope
are discarded.  ``qstar_err`` is the standard deviation of the valid samples and
``qstar_interval`` their 16th-84th percentiles.  With few runs the bootstrap
underestimates the error; a line through two runs has no scatter to resample, so with
fewer than three distinct Q the errors and the interval are NaN (not the zero the
bootstrap would give), unless every Q was run more than once.

Replicates: runs at the same Q that differ only in the hand-off (``handoff.seed`` or
``handoff.time``; a sweep's ``replicates``, docs/sweeps.md) sample the method's own
scatter of M_lr/M_T (N-body reaccumulation amplifies the hand-off's 1 % velocity noise into a
standard deviation of about 0.05 for case 8c, docs/accuracy.md).  They enter the fit as
separate runs, so the bootstrap over runs carries that scatter into ``qstar_err``; a
fit of one run per Q does not contain it.  ``replicate_std`` is the pooled standard
deviation of M_lr/M_T within Q,

    s^2 = sum_g sum_i (y_gi - mean_g)^2 / sum_g (n_g - 1),

over the fitted Q values g with n_g >= 2 runs (NaN when no Q was repeated), and
``replicated_q`` the number of such Q values.

The slope against the normalised energy, d(M_lr/M_T)/d(Q/Q*_D) = b Q*_D, is
reported with its bootstrap error (about -0.5 in the reference study).

``brackets`` is True when the fitted runs include M_lr/M_T values on both sides of
0.5; otherwise Q*_D is an extrapolation and a warning is logged.

Critical speed / projectile radius: the fit is made in Q, and Q*_D is converted.
With per-run speeds v_i at a fixed size ratio, Q_i / v_i^2 = m_p / (2 M_T) is
the same for every run and v* = sqrt(Q*_D / (Q_i / v_i^2)).  With per-run
projectile radii R_i at a fixed speed and equal densities, Q_i / R_i^3 is
constant and R* = (Q*_D / (Q_i / R_i^3))^(1/3).  A set where that ratio varies
(speed and size both swept) raises ValueError.  The bootstrap samples of Q*_D
are converted the same way to give the errors.
"""

from __future__ import annotations

import csv
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from impactpipe.storage import atomic_path

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class QStarFit:
    """Result of :func:`fit_qstar` (SI units; see the module docstring).

    Attributes:
        qstar: Q*_D (J/kg).
        qstar_err: bootstrap standard deviation of Q*_D (J/kg).
        qstar_interval: (16th, 84th) bootstrap percentiles of Q*_D (J/kg).
        intercept: a in M_lr/M_T = a + b Q (dimensionless).
        slope: b (kg/J).
        normalized_slope: b Q*_D, slope against Q/Q*_D (dimensionless).
        normalized_slope_err: its bootstrap standard deviation.
        brackets: True when fitted runs lie on both sides of M_lr/M_T = 0.5.
        used: (n_runs,) bool, runs in the fit.
        weights: (n_runs,) weight of each run (0 for runs not used).
        n_bootstrap_valid: bootstrap samples kept.
        min_mlr, n_lr_resolved, underresolved_weight: the settings used.
        critical_velocity, critical_velocity_err: v* and its bootstrap error (m/s), NaN if not asked.
        critical_radius, critical_radius_err: R* and its bootstrap error (m), NaN if not asked.
        replicate_std: pooled standard deviation of M_lr/M_T between runs at the same Q (NaN if none).
        replicated_q: fitted Q values with two or more runs.
    """

    qstar: float
    qstar_err: float
    qstar_interval: tuple[float, float]
    intercept: float
    slope: float
    normalized_slope: float
    normalized_slope_err: float
    brackets: bool
    used: np.ndarray
    weights: np.ndarray
    n_bootstrap_valid: int
    min_mlr: float
    n_lr_resolved: int
    underresolved_weight: float
    critical_velocity: float = float("nan")
    critical_velocity_err: float = float("nan")
    critical_radius: float = float("nan")
    critical_radius_err: float = float("nan")
    replicate_std: float = float("nan")
    replicated_q: int = 0

    def predict(self, q):
        """M_lr/M_T on the fitted line at specific energy ``q`` (J/kg)."""
        return self.intercept + self.slope * np.asarray(q, dtype=float)

    def as_datasets(self) -> dict[str, Any]:
        """The fit as a ``write_analysis`` group: (value, units, description) leaves."""
        return {
            "qstar": (self.qstar, "J/kg", "Q*_D: Q where the fitted M_lr/M_T crosses 0.5"),
            "qstar_err": (self.qstar_err, "J/kg", "bootstrap standard deviation of Q*_D"),
            "qstar_interval": (np.array(self.qstar_interval), "J/kg", "16th and 84th bootstrap percentiles"),
            "intercept": (self.intercept, "dimensionless", "a in M_lr/M_T = a + b Q"),
            "slope": (self.slope, "kg/J", "b in M_lr/M_T = a + b Q"),
            "normalized_slope": (self.normalized_slope, "dimensionless", "b Q*_D"),
            "normalized_slope_err": (self.normalized_slope_err, "dimensionless", "bootstrap std of b Q*_D"),
            "brackets": (np.int8(self.brackets), "dimensionless", "1 if fitted runs bracket 0.5"),
            "used": (self.used.astype(np.int8), "dimensionless", "1 for runs in the fit"),
            "weights": (self.weights, "dimensionless", "least-squares weight per run"),
            "n_bootstrap_valid": (self.n_bootstrap_valid, "dimensionless", "bootstrap samples kept"),
            "min_mlr": (self.min_mlr, "dimensionless", "runs with M_lr/M_T <= this are not fitted"),
            "n_lr_resolved": (self.n_lr_resolved, "dimensionless", "N_lr below this is down-weighted"),
            "underresolved_weight": (self.underresolved_weight, "dimensionless", "weight of under-resolved runs"),
            "critical_velocity": (self.critical_velocity, "m/s", "impact speed at Q*_D"),
            "critical_velocity_err": (self.critical_velocity_err, "m/s", "bootstrap std"),
            "critical_radius": (self.critical_radius, "m", "projectile radius at Q*_D"),
            "critical_radius_err": (self.critical_radius_err, "m", "bootstrap std"),
            "replicate_std": (self.replicate_std, "dimensionless",
                              "pooled standard deviation of M_lr/M_T between runs at the same Q"),
            "replicated_q": (self.replicated_q, "dimensionless", "fitted Q values with two or more runs"),
        }


def _weighted_lines(x, y, w):
    """Weighted least-squares lines y = a + b x along the last axis; returns (a, b, ok)."""
    sw = w.sum(axis=-1)
    mx = (w * x).sum(axis=-1) / sw
    my = (w * y).sum(axis=-1) / sw
    dx = x - mx[..., None]
    sxx = (w * dx * dx).sum(axis=-1)
    sxy = (w * dx * (y - my[..., None])).sum(axis=-1)
    scale = (w * x * x).sum(axis=-1) / sw
    ok = sxx > 1e-12 * scale
    b = np.where(ok, sxy / np.where(ok, sxx, 1.0), np.nan)
    return my - b * mx, b, ok


def _swept_constant(q, swept, power, name):
    """The constant k = Q_i / swept_i^power of a single-parameter sweep."""
    k = q / np.asarray(swept, dtype=float) ** power
    if not np.allclose(k, k[0], rtol=1e-6):
        raise ValueError(f"Q / {name}^{power} differs between runs: {name} is not the only swept variable")
    return float(k[0])


def fit_qstar(
    Q,
    mlr_over_mt,
    n_lr,
    *,
    min_mlr: float = 0.1,
    n_lr_resolved: int = 200,
    underresolved_weight: float = 0.25,
    n_bootstrap: int = 2000,
    seed: int = 0,
    velocity=None,
    projectile_radius=None,
) -> QStarFit:
    """Fit Q*_D to runs (see the module docstring for the method).

    Args:
        Q: (n,) specific impact energy per run (J/kg).
        mlr_over_mt: (n,) M_lr/M_T per run.
        n_lr: (n,) particles in the largest remnant per run.
        min_mlr: runs with M_lr/M_T <= min_mlr are left out of the fit.
        n_lr_resolved: runs with N_lr below this get ``underresolved_weight``.
        underresolved_weight: least-squares weight of under-resolved runs (others 1).
        n_bootstrap: bootstrap samples.
        seed: seed of the bootstrap generator.
        velocity: (n,) impact speed per run (m/s), for the critical speed.
        projectile_radius: (n,) projectile radius per run (m), for the critical radius.

    Raises:
        ValueError: fewer than two fitted runs with distinct Q, or a non-negative slope.

    Example: five runs on the line M_lr/M_T = 1 - Q / 2000 J/kg cross 0.5 at 1000 J/kg::

        >>> from impactpipe.analysis import fit_qstar
        >>> Q = [400.0, 700.0, 1000.0, 1300.0, 1600.0]
        >>> fit = fit_qstar(Q, [1.0 - q / 2000.0 for q in Q], n_lr=[500] * 5)
        >>> round(fit.qstar, 6), fit.brackets
        (1000.0, True)
    """
    q = np.asarray(Q, dtype=float)
    y = np.asarray(mlr_over_mt, dtype=float)
    n = np.asarray(n_lr)
    if not (q.shape == y.shape == n.shape) or q.ndim != 1:
        raise ValueError("Q, mlr_over_mt and n_lr must be 1-D arrays of the same length")
    used = (y > min_mlr) & np.isfinite(q) & np.isfinite(y)
    weights = np.where(n >= n_lr_resolved, 1.0, underresolved_weight) * used
    xu, yu, wu = q[used], y[used], weights[used]
    if np.unique(xu).size < 2:
        raise ValueError(f"need at least two runs with distinct Q and M_lr/M_T > {min_mlr}")
    a, b, _ = _weighted_lines(xu, yu, wu)
    if not b < 0.0:
        raise ValueError(f"M_lr/M_T does not decrease with Q over the fitted runs (slope {b:.3e} kg/J)")
    qstar = float((0.5 - a) / b)
    brackets = bool(np.any(yu > 0.5) and np.any(yu < 0.5))
    if not brackets:
        logger.warning("fitted runs do not bracket M_lr/M_T = 0.5 (range %.3f-%.3f): Q*_D = %.4g J/kg is an "
                       "extrapolation", yu.min(), yu.max(), qstar)

    rng = np.random.default_rng(seed)
    idx = rng.integers(0, xu.size, size=(n_bootstrap, xu.size))
    ab, bb, ok = _weighted_lines(xu[idx], yu[idx], wu[idx])
    ok &= bb < 0.0
    q_boot = (0.5 - ab[ok]) / bb[ok]
    s_boot = bb[ok] * q_boot
    n_valid = int(ok.sum())
    if n_valid < n_bootstrap // 2:
        logger.warning("only %d of %d bootstrap samples were usable (%d fitted runs)", n_valid, n_bootstrap,
                       xu.size)

    distinct, runs_per_q = np.unique(xu, return_counts=True)
    resamplable = distinct.size >= 3 or bool(np.all(runs_per_q >= 2))
    replicate_std, replicated_q = pooled_replicate_std(xu, yu)

    def spread(samples):
        return float(np.std(samples, ddof=1)) if resamplable and samples.size > 1 else float("nan")

    extra: dict[str, float] = {}
    if velocity is not None:
        k = _swept_constant(xu, np.asarray(velocity, dtype=float)[used], 2, "velocity")
        extra["critical_velocity"] = float(np.sqrt(qstar / k))
        extra["critical_velocity_err"] = spread(np.sqrt(q_boot / k))
    if projectile_radius is not None:
        k = _swept_constant(xu, np.asarray(projectile_radius, dtype=float)[used], 3, "projectile_radius")
        extra["critical_radius"] = float(np.cbrt(qstar / k))
        extra["critical_radius_err"] = spread(np.cbrt(q_boot / k))

    interval = (tuple(np.percentile(q_boot, [16.0, 84.0])) if resamplable and q_boot.size
                else (float("nan"), float("nan")))
    return QStarFit(
        qstar=qstar,
        qstar_err=spread(q_boot),
        qstar_interval=(float(interval[0]), float(interval[1])),
        intercept=float(a),
        slope=float(b),
        normalized_slope=float(b * qstar),
        normalized_slope_err=spread(s_boot),
        brackets=brackets,
        used=used,
        weights=weights,
        n_bootstrap_valid=n_valid,
        min_mlr=float(min_mlr),
        n_lr_resolved=int(n_lr_resolved),
        underresolved_weight=float(underresolved_weight),
        replicate_std=replicate_std,
        replicated_q=replicated_q,
        **extra,
    )


def pooled_replicate_std(q, y) -> tuple[float, int]:
    """(s, g): pooled standard deviation of ``y`` between entries with equal ``q`` and the
    number g of ``q`` values with two or more entries (equation in the module docstring);
    s is NaN when g is 0."""
    q = np.asarray(q, dtype=float)
    y = np.asarray(y, dtype=float)
    _, group, counts = np.unique(q, return_inverse=True, return_counts=True)
    means = np.bincount(group, weights=y) / counts
    squares = float(np.sum((y - means[group]) ** 2))
    dof = int(np.sum(counts - 1))
    replicated = int(np.sum(counts >= 2))
    return (float(np.sqrt(squares / dof)) if dof > 0 else float("nan")), replicated


def plus_minus(value: float, error: float, fmt: str = ".3g") -> str:
    """``value +- error`` for reports, or the value marked "(no error bar)" when the error is
    not finite (a fit through fewer than three distinct Q, :func:`fit_qstar`)."""
    if np.isfinite(error):
        return f"{value:{fmt}} +- {error:.2g}"
    return f"{value:{fmt}} (no error bar)"


def write_qstar_table(
    path: str | os.PathLike,
    Q,
    mlr_over_mt,
    n_lr,
    fit: QStarFit,
    *,
    labels=None,
    velocity=None,
    projectile_radius=None,
) -> Path:
    """Write the runs and the fit as CSV (atomically).

    Leading ``#`` lines state the fit (Q*_D, error, slope, bracketing, weights);
    then one row per run with columns ``run, Q_J_per_kg, Q_over_QstarD,
    mlr_over_mt, n_lr, used, weight`` and, when given, ``velocity_m_per_s``,
    ``projectile_radius_m``.  Read with pandas ``read_csv(path, comment="#")`` or
    ``csv.DictReader`` over the lines not starting with ``#``.
    """
    q = np.asarray(Q, dtype=float)
    labels = [str(i) for i in range(q.size)] if labels is None else [str(s) for s in labels]
    columns = {
        "run": labels,
        "Q_J_per_kg": q,
        "Q_over_QstarD": q / fit.qstar,
        "mlr_over_mt": np.asarray(mlr_over_mt, dtype=float),
        "n_lr": np.asarray(n_lr, dtype=np.int64),
        "used": fit.used.astype(int),
        "weight": fit.weights,
    }
    if velocity is not None:
        columns["velocity_m_per_s"] = np.asarray(velocity, dtype=float)
    if projectile_radius is not None:
        columns["projectile_radius_m"] = np.asarray(projectile_radius, dtype=float)
    header = [
        f"# Q*_D = {fit.qstar:.6g} J/kg +- {fit.qstar_err:.3g} (bootstrap std, {fit.n_bootstrap_valid} samples; "
        f"16-84%: {fit.qstar_interval[0]:.6g}-{fit.qstar_interval[1]:.6g})",
        f"# fit: M_lr/M_T = {fit.intercept:.6g} + ({fit.slope:.6g} kg/J) Q; slope vs Q/Q*_D = "
        f"{fit.normalized_slope:.4g} +- {fit.normalized_slope_err:.3g}",
        f"# runs fitted: M_lr/M_T > {fit.min_mlr:g}; weight {fit.underresolved_weight:g} for N_lr < "
        f"{fit.n_lr_resolved}, else 1; brackets 0.5: {fit.brackets}",
    ]
    if fit.replicated_q:
        header.append(f"# replicates: {fit.replicated_q} Q values run more than once; pooled standard deviation "
                      f"of M_lr/M_T at the same Q = {fit.replicate_std:.3g}")
    if np.isfinite(fit.critical_velocity):
        header.append(f"# critical velocity = {fit.critical_velocity:.6g} m/s +- {fit.critical_velocity_err:.3g}")
    if np.isfinite(fit.critical_radius):
        header.append(f"# critical projectile radius = {fit.critical_radius:.6g} m +- {fit.critical_radius_err:.3g}")
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            fh.write("\n".join(header) + "\n")
            writer = csv.writer(fh)
            writer.writerow(list(columns))
            for i in range(q.size):
                writer.writerow([_fmt(columns[name][i]) for name in columns])
    return Path(path)


def _fmt(value) -> str:
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    return str(value)
