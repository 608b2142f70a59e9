"""The resolution error of Q*_D: Q*_D fitted at several mesh resolutions, extrapolated.

A Q*_D measured at one resolution carries two errors: the scatter of its runs (the
bootstrap error of :func:`impactpipe.analysis.qstar.fit_qstar`, which holds the hand-off
seeds' scatter when the runs have replicates) and the discretisation error of the hydro
stage.  Given Q*_D at three or more resolutions n (cells per projectile radius, step size
h = 1/n), :func:`qstar_resolution_error` extrapolates Q*_D to h -> 0 with
:func:`impactpipe.analysis.richardson.richardson` and reports the observed order p and the
Richardson value Q*_D(inf) of the rungs' Q*_D.

The rungs' own errors enter the extrapolation: each of 4000 draws (fixed seed,
:func:`~impactpipe.analysis.richardson.resampled_richardson`) replaces every rung's Q*_D by
Q*_D + seed_error x N(0, 1) and extrapolates again.  Then

    resolution error = the 68th percentile over the draws of |Q*_D(finest) - Q*_D(inf, draw)|,

at least |Q*_D(finest) - Q*_D(inf)|, and the 16th-84th percentiles of Q*_D(inf, draw) are
reported beside it with the share of draws that could not be extrapolated.  A coarse rung
whose Q*_D is uncertain (its runs do not bracket M_lr/M_T = 0.5) widens the error instead of
fixing the order by accident.

No error is invented where Richardson refuses (fewer than three rungs, answers that do not
change monotonically, changes that do not shrink, or p below
:data:`~impactpipe.analysis.richardson.MIN_ORDER`), nor where more than ``MAX_REFUSED`` of
the draws refuse: the error is NaN, ``status`` says why, and ``last_change`` (Q*_D of the
finest rung minus the next) is the only measured bound it leaves, a lower one.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from impactpipe.analysis.qstar import plus_minus
from impactpipe.analysis.richardson import RESAMPLING_DRAWS, resampled_richardson, richardson
from impactpipe.storage import atomic_path

#: Largest share of resamplings that may refuse Richardson for an error to be given.
MAX_REFUSED = 0.5


@dataclass
class ResolutionError:
    """Q*_D over a resolution ladder (J/kg) and its resolution error.

    Attributes:
        resolutions: rungs, cells per projectile radius, finest first.
        qstar: Q*_D of each rung (J/kg).
        seed_error: the fit's error of each rung (J/kg; its runs' scatter).
        status: "extrapolated", or why Richardson refused.
        order: observed order p (NaN unless extrapolated).
        extrapolated: Q*_D at h -> 0 (J/kg, NaN unless extrapolated).
        error: the resolution error (J/kg, module docstring; NaN unless extrapolated).
        last_change: Q*_D(finest) - Q*_D(next finest) (J/kg, NaN with one rung).
        extrapolated_range: 16th and 84th percentiles of the extrapolated Q*_D over the
            resamplings of the rungs within their seed errors (J/kg; NaN if none extrapolates).
        refused: share of those resamplings that Richardson refused.
        unbracketed: the rungs whose runs do not bracket M_lr/M_T = 0.5 (their Q*_D
            extrapolates the fitted line beyond the runs), finest first.
    """

    resolutions: np.ndarray
    qstar: np.ndarray
    seed_error: np.ndarray
    status: str
    order: float
    extrapolated: float
    error: float
    last_change: float
    extrapolated_range: tuple[float, float] = (float("nan"), float("nan"))
    refused: float = float("nan")
    unbracketed: tuple[float, ...] = ()

    @property
    def ok(self) -> bool:
        return self.status == "extrapolated"

    def describe(self, fmt: str = ".4g") -> str:
        """One line: the finest rung's Q*_D with its seed error and resolution error (or why none)."""
        rungs = "/".join(f"{n:g}" for n in self.resolutions[:3][::-1])
        head = f"Q*_D = {plus_minus(self.qstar[0], self.seed_error[0], fmt)} J/kg (seeds)"
        caution = ""
        if self.unbracketed:
            which = ", ".join(f"{n:g}" for n in self.unbracketed)
            caution = (f"; caution: the runs at {which} cells per projectile radius do not bracket "
                       f"M_lr/M_T = 0.5, so that Q*_D extrapolates its fitted line")
        low, high = self.extrapolated_range
        spread = (f"; under the seed errors 68 % of the extrapolations in {low:{fmt}}-{high:{fmt}} J/kg, "
                  f"{self.refused:.0%} refused" if math.isfinite(low) else "")
        if self.ok:
            return (f"{head} +- {self.error:{fmt}} J/kg (resolution: Richardson {self.extrapolated:{fmt}} J/kg at "
                    f"observed order {self.order:.2f} over {rungs} cells per projectile radius{spread}){caution}")
        change = f"; the last refinement moved it by {self.last_change:+{fmt}} J/kg" \
            if math.isfinite(self.last_change) else ""
        return (f"{head}; resolution error not estimated over {rungs} cells per projectile radius: "
                f"{self.status}{change}{spread}{caution}")


def qstar_resolution_error(resolutions, qstar, seed_error, brackets=None) -> ResolutionError:
    """Resolution error of Q*_D from its values at several resolutions (module docstring).

    Args:
        resolutions: (k,) cells per projectile radius of each rung (any order, distinct).
        qstar: (k,) Q*_D of each rung (J/kg).
        seed_error: (k,) the fit's error of each rung (J/kg).
        brackets: (k,) whether each rung's runs bracket M_lr/M_T = 0.5 (``QStarFit.brackets``);
            the rungs that do not are named in the description.  None: not known.

    Example: Q*_D converging at second order towards 1000 J/kg; with seed errors of about 1 %
    the extrapolation's own uncertainty more than doubles the distance to the limit::

        >>> from impactpipe.analysis.resolution_error import qstar_resolution_error
        >>> ladder = qstar_resolution_error([10, 20, 40], [1160.0, 1040.0, 1010.0], [12.0, 10.0, 11.0])
        >>> round(ladder.extrapolated, 6), round(ladder.order, 6), round(ladder.error, 1)
        (1000.0, 2.0, 23.9)
        >>> [round(v, 1) for v in ladder.extrapolated_range], round(ladder.refused, 3)
        ([970.6, 1016.3], 0.029)
    """
    n = np.asarray(resolutions, dtype=float)
    q = np.asarray(qstar, dtype=float)
    e = np.asarray(seed_error, dtype=float)
    if not (n.shape == q.shape == e.shape) or n.ndim != 1 or n.size == 0:
        raise ValueError("resolutions, qstar and seed_error must be 1-D arrays of the same, non-zero length")
    if np.unique(n).size != n.size or (n <= 0).any():
        raise ValueError(f"resolutions must be distinct and positive (got {n.tolist()})")
    order = np.argsort(-n)
    n, q, e = n[order], q[order], e[order]
    unbracketed = () if brackets is None else tuple(float(n_i) for n_i, ok in
                                                    zip(n, np.asarray(brackets, dtype=bool)[order]) if not ok)
    ext = richardson(1.0 / n, q)
    last = float(q[0] - q[1]) if n.size >= 2 else float("nan")
    if not ext.ok:
        return ResolutionError(resolutions=n, qstar=q, seed_error=e, status=ext.status, order=ext.order,
                               extrapolated=ext.value, error=float("nan"), last_change=last,
                               unbracketed=unbracketed)
    values = np.array([draw.value for _, draw in resampled_richardson(1.0 / n, q, e) if draw.ok])
    refused = 1.0 - values.size / RESAMPLING_DRAWS
    low, high = (float(v) for v in np.percentile(values, (16, 84))) if values.size else (float("nan"),) * 2
    if refused > MAX_REFUSED:
        status = (f"{refused:.0%} of {RESAMPLING_DRAWS} resamplings of the rungs within their seed errors cannot be "
                  f"extrapolated (more than {MAX_REFUSED:.0%})")
        return ResolutionError(resolutions=n, qstar=q, seed_error=e, status=status, order=float("nan"),
                               extrapolated=float("nan"), error=float("nan"), last_change=last,
                               extrapolated_range=(low, high), refused=refused, unbracketed=unbracketed)
    error = max(abs(float(q[0]) - ext.value), float(np.percentile(np.abs(q[0] - values), 68)))
    return ResolutionError(resolutions=n, qstar=q, seed_error=e, status=ext.status, order=ext.order,
                           extrapolated=ext.value, error=error, last_change=last,
                           extrapolated_range=(low, high), refused=refused, unbracketed=unbracketed)


def write_resolution_table(path: str | os.PathLike, ladder: ResolutionError) -> Path:
    """Write the ladder as CSV (atomically): ``#`` lines with :meth:`ResolutionError.describe` and
    the Richardson result, then one row per rung (``cells_per_projectile_radius,
    Qstar_D_J_per_kg, seed_error_J_per_kg``), finest first."""
    header = [
        f"# {ladder.describe()}",
        f"# richardson: status = {ladder.status}; order = {ladder.order:.6g}; extrapolated = "
        f"{ladder.extrapolated:.6g} J/kg; resolution error = {ladder.error:.6g} J/kg; last change = "
        f"{ladder.last_change:.6g} J/kg; 16th-84th percentiles of the resampled extrapolations = "
        f"{ladder.extrapolated_range[0]:.6g}-{ladder.extrapolated_range[1]:.6g} J/kg ({ladder.refused:.3g} refused)",
    ]
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            fh.write("\n".join(header) + "\n")
            writer = csv.writer(fh)
            writer.writerow(["cells_per_projectile_radius", "Qstar_D_J_per_kg", "seed_error_J_per_kg"])
            for n, q, e in zip(ladder.resolutions, ladder.qstar, ladder.seed_error):
                writer.writerow([repr(float(n)), repr(float(q)), repr(float(e))])
    return Path(path)
