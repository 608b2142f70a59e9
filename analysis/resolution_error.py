"""The resolution error of Q*_D: Q*_D fitted at several mesh resolutions, extrapolated.

A Q*_D measured at one resolution carries two errors: the scatter of its runs (the
bootstrap error of :func:`impactpipe.analysis.qstar.fit_qstar`, which holds the hand-off
seeds' scatter when the runs have replicates) and the discretisation error of the hydro
stage.  Given Q*_D at three or more resolutions n (cells per projectile radius, step size
h = 1/n), :func:`qstar_resolution_error` extrapolates Q*_D to h -> 0 with
:func:`impactpipe.analysis.richardson.richardson` and reports

    resolution error = |Q*_D(finest) - Q*_D(extrapolated)|,

with the observed order p.  Where Richardson refuses (fewer than three rungs, answers that
do not change monotonically, changes that do not shrink, or p below
:data:`~impactpipe.analysis.richardson.MIN_ORDER`) no error is invented: the error is NaN,
``status`` says why, and ``last_change`` (Q*_D of the finest rung minus the next) is the
only measured bound it leaves, a lower one.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from impactpipe.analysis.qstar import plus_minus
from impactpipe.analysis.richardson import richardson
from impactpipe.storage import atomic_path


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
        error: |Q*_D(finest) - extrapolated| (J/kg, NaN unless extrapolated).
        last_change: Q*_D(finest) - Q*_D(next finest) (J/kg, NaN with one rung).
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
        if self.ok:
            return (f"{head} +- {self.error:{fmt}} J/kg (resolution: Richardson {self.extrapolated:{fmt}} J/kg at "
                    f"observed order {self.order:.2f} over {rungs} cells per projectile radius){caution}")
        change = f"; the last refinement moved it by {self.last_change:+{fmt}} J/kg" \
            if math.isfinite(self.last_change) else ""
        return (f"{head}; resolution error not estimated over {rungs} cells per projectile radius: "
                f"{self.status}{change}{caution}")


def qstar_resolution_error(resolutions, qstar, seed_error, brackets=None) -> ResolutionError:
    """Resolution error of Q*_D from its values at several resolutions (module docstring).

    Args:
        resolutions: (k,) cells per projectile radius of each rung (any order, distinct).
        qstar: (k,) Q*_D of each rung (J/kg).
        seed_error: (k,) the fit's error of each rung (J/kg).
        brackets: (k,) whether each rung's runs bracket M_lr/M_T = 0.5 (``QStarFit.brackets``);
            the rungs that do not are named in the description.  None: not known.

    Example: Q*_D converging at second order towards 1000 J/kg::

        >>> from impactpipe.analysis.resolution_error import qstar_resolution_error
        >>> ladder = qstar_resolution_error([10, 20, 40], [1160.0, 1040.0, 1010.0], [12.0, 10.0, 11.0])
        >>> round(ladder.extrapolated, 6), round(ladder.order, 6), round(ladder.error, 6)
        (1000.0, 2.0, 10.0)
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
    error = abs(float(q[0]) - ext.value) if ext.ok else float("nan")
    return ResolutionError(resolutions=n, qstar=q, seed_error=e, status=ext.status, order=ext.order,
                           extrapolated=ext.value, error=error, last_change=last, unbracketed=unbracketed)


def write_resolution_table(path: str | os.PathLike, ladder: ResolutionError) -> Path:
    """Write the ladder as CSV (atomically): ``#`` lines with :meth:`ResolutionError.describe` and
    the Richardson result, then one row per rung (``cells_per_projectile_radius,
    Qstar_D_J_per_kg, seed_error_J_per_kg``), finest first."""
    header = [
        f"# {ladder.describe()}",
        f"# richardson: status = {ladder.status}; order = {ladder.order:.6g}; extrapolated = "
        f"{ladder.extrapolated:.6g} J/kg; resolution error = {ladder.error:.6g} J/kg; last change = "
        f"{ladder.last_change:.6g} J/kg",
    ]
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            fh.write("\n".join(header) + "\n")
            writer = csv.writer(fh)
            writer.writerow(["cells_per_projectile_radius", "Qstar_D_J_per_kg", "seed_error_J_per_kg"])
            for n, q, e in zip(ladder.resolutions, ladder.qstar, ladder.seed_error):
                writer.writerow([repr(float(n)), repr(float(q)), repr(float(e))])
    return Path(path)
