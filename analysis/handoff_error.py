"""The hand-off-time error of Q*_D: Q*_D fitted at each of several hand-off times.

The hybrid method hands the hydro state to the N-body stage at one time, chosen after the
shock and rarefaction have crossed the target (method reference, section 3): the largest
remnant should then level off, a least-squares slope of it against the hand-off time be
consistent with zero, and the scatter about that slope is the method's own error (about
+-0.1 in M_lr/M_T in the reference study).  The same holds for Q*_D: fitted separately over
the runs handed off at each time t_j (the same hydro runs, handed off at several of their
snapshots), it gives Q*_D,j with the fit's own error e_j (the seeds' scatter,
:func:`impactpipe.analysis.qstar.fit_qstar`), and

    mean      = sum_j Q*_D,j / J
    error     = sqrt( sum_j (Q*_D,j - mean)^2 / (J - 1) )      (the hand-off-time error)
    slope b   = least-squares slope of Q*_D,j against t_j (J/kg/s),
    slope_err = its standard error from the residuals, sqrt( s^2 / sum_j (t_j - t_mean)^2 ),
                s^2 = sum_j residual_j^2 / (J - 2)   (NaN with two times).

``status`` is "plateau" when the slope is consistent with zero, as the method assumes
(|b| / slope_err within the two-sided 95 % quantile of Student's t with J - 2 degrees of
freedom), "trend" when it is not (Q*_D depends on the hand-off time: the error then measures
how much over the times given, and the times are not on a plateau), and "two times" when no
slope can be tested.  The hand-off-time error is reported beside the seeds'
error, not folded into it.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from impactpipe.analysis.qstar import plus_minus
from impactpipe.storage import atomic_path

#: Two-sided confidence of the slope test: a slope inside it counts as a plateau.
PLATEAU_CONFIDENCE = 0.95


@dataclass
class HandoffTimeError:
    """Q*_D at several hand-off times (J/kg) and its hand-off-time error.

    Attributes:
        times: hand-off times (s), ascending.
        qstar: Q*_D fitted over the runs handed off at each time (J/kg).
        seed_error: the fit's error at each time (J/kg; its runs' scatter).
        mean: mean of ``qstar`` over the times (J/kg).
        error: standard deviation of ``qstar`` over the times (ddof 1, J/kg).
        slope: least-squares slope of ``qstar`` against the time (J/kg/s).
        slope_err: its standard error (J/kg/s; NaN with two times).
        status: "plateau", "trend" or "two times" (module docstring).
    """

    times: np.ndarray
    qstar: np.ndarray
    seed_error: np.ndarray
    mean: float
    error: float
    slope: float
    slope_err: float
    status: str

    def describe(self, fmt: str = ".4g") -> str:
        """One line: Q*_D at each time, the mean, the hand-off-time error and the slope test."""
        each = ", ".join(f"{q:{fmt}}" for q in self.qstar)
        times = "/".join(f"{t:g}" for t in self.times)
        slope = f"slope {plus_minus(self.slope, self.slope_err, fmt)} J/kg per s" if math.isfinite(self.slope_err) \
            else f"slope {self.slope:{fmt}} J/kg per s, untested"
        return (f"hand-off at {times} s: Q*_D = {each} J/kg; mean {self.mean:{fmt}} +- {self.error:{fmt}} J/kg "
                f"(hand-off time: standard deviation over the times); {slope} ({self.status})")


def qstar_handoff_error(times, qstar, seed_error) -> HandoffTimeError:
    """Hand-off-time error of Q*_D from its values at several hand-off times (module docstring).

    Args:
        times: (J,) hand-off times (s), distinct, J >= 2.
        qstar: (J,) Q*_D fitted at each time (J/kg).
        seed_error: (J,) the fit's error at each time (J/kg).

    Example: three times on a plateau, Q*_D within 20 J/kg::

        >>> from impactpipe.analysis.handoff_error import qstar_handoff_error
        >>> h = qstar_handoff_error([14.0, 16.0, 18.0], [1000.0, 1020.0, 990.0], [30.0, 30.0, 30.0])
        >>> round(h.mean, 3), round(h.error, 3), round(h.slope, 3), round(h.slope_err, 3), h.status
        (1003.333, 15.275, -2.5, 7.217, 'plateau')
    """
    t = np.asarray(times, dtype=float)
    q = np.asarray(qstar, dtype=float)
    e = np.asarray(seed_error, dtype=float)
    if not (t.shape == q.shape == e.shape) or t.ndim != 1 or t.size < 2:
        raise ValueError("times, qstar and seed_error must be 1-D arrays of the same length, at least two")
    if np.unique(t).size != t.size:
        raise ValueError(f"hand-off times must be distinct (got {t.tolist()})")
    if not np.isfinite(q).all():
        raise ValueError(f"every hand-off time needs a fitted Q*_D (got {q.tolist()})")
    order = np.argsort(t)
    t, q, e = t[order], q[order], e[order]
    dt = t - t.mean()
    slope = float((dt * (q - q.mean())).sum() / (dt * dt).sum())
    if t.size > 2:
        residual = q - q.mean() - slope * dt
        slope_err = math.sqrt(float((residual * residual).sum()) / (t.size - 2) / float((dt * dt).sum()))
        limit = stats.t.ppf(0.5 + PLATEAU_CONFIDENCE / 2.0, t.size - 2) * slope_err
        status = "plateau" if abs(slope) <= limit else "trend"
    else:
        slope_err = float("nan")
        status = "two times"
    return HandoffTimeError(times=t, qstar=q, seed_error=e, mean=float(q.mean()), error=float(q.std(ddof=1)),
                            slope=slope, slope_err=slope_err, status=status)


def fit_by_handoff_time(handoff_times, q, mlr, n_lr) -> tuple[HandoffTimeError | None, list[str]]:
    """Q*_D fitted separately over the runs of each hand-off time, and their hand-off-time error.

    Args (one entry per run): ``handoff_times`` (s), ``q`` specific impact energy (J/kg),
    ``mlr`` M_lr/M_T, ``n_lr`` particles in the largest remnant; each time's runs go to
    :func:`impactpipe.analysis.qstar.fit_qstar` with its defaults.  Runs with a NaN time, Q or
    M_lr/M_T (unfinished) are left out.

    Returns (result, problems): the :class:`HandoffTimeError` over the times whose runs could
    be fitted (None with fewer than two such times, or when the runs share one time), and one
    line per time that could not be fitted.
    """
    from impactpipe.analysis.qstar import fit_qstar

    t, q, mlr, n_lr = (np.asarray(a, dtype=float) for a in (handoff_times, q, mlr, n_lr))
    finished = np.isfinite(t) & np.isfinite(q) & np.isfinite(mlr)
    t, q, mlr, n_lr = t[finished], q[finished], mlr[finished], n_lr[finished]
    times, values, errors, problems = [], [], [], []
    for time in np.unique(t):
        at = t == time
        try:
            fit = fit_qstar(q[at], mlr[at], n_lr[at])
        except (ValueError, np.linalg.LinAlgError) as exc:
            problems.append(f"hand-off at {time:g} s: no Q*_D ({exc})")
            continue
        times.append(float(time))
        values.append(fit.qstar)
        errors.append(fit.qstar_err)
    if len(times) < 2:
        return None, problems
    return qstar_handoff_error(times, values, errors), problems


def write_handoff_table(path: str | os.PathLike, result: HandoffTimeError) -> Path:
    """Write the hand-off times as CSV (atomically): a ``#`` line with
    :meth:`HandoffTimeError.describe`, then one row per time (``handoff_time_s,
    Qstar_D_J_per_kg, seed_error_J_per_kg``)."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            fh.write(f"# {result.describe()}\n")
            writer = csv.writer(fh)
            writer.writerow(["handoff_time_s", "Qstar_D_J_per_kg", "seed_error_J_per_kg"])
            for t, q, e in zip(result.times, result.qstar, result.seed_error):
                writer.writerow([repr(float(t)), repr(float(q)), repr(float(e))])
    return Path(path)
