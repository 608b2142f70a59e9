"""Richardson extrapolation of an answer over a ladder of step sizes, and when to refuse it.

With the three finest rungs h1 < h2 < h3 and answers f1, f2, f3, the model
f(h) = f* + C h^p gives

    (f3 - f2) / (f2 - f1) = r21^p (r32^p - 1) / (r21^p - 1),   r21 = h2/h1, r32 = h3/h2,

solved for the observed order p, then f* = f1 + (f1 - f2) / (r21^p - 1) (Roache 1998,
*Verification and Validation in Computational Science and Engineering*).  Where the
answers do not change monotonically, their changes do not shrink, or p is below
:data:`MIN_ORDER`, no value is extrapolated and the status says why.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize


@dataclass
class Extrapolation:
    """Richardson estimate of one answer over one ladder.

    Attributes:
        status: "extrapolated", or why no value was extrapolated.
        order: observed order p (NaN unless extrapolated).
        ratios: (r21, r32), the step-size ratios of the three finest rungs (NaN if fewer).
        value: extrapolated answer f* (NaN unless extrapolated).
        errors: f_i - f* per rung, in the order of the input (NaN unless extrapolated).
    """

    status: str
    order: float = float("nan")
    ratios: tuple[float, float] = (float("nan"), float("nan"))
    value: float = float("nan")
    errors: np.ndarray = field(default_factory=lambda: np.array([]))

    @property
    def ok(self) -> bool:
        return self.status == "extrapolated"


#: Observed orders below this are not extrapolated: the estimate would lie more than 2.4 times
#: the last change beyond the finest rung (1 / (2^0.5 - 1) at a refinement ratio of 2).
MIN_ORDER = 0.5


def richardson(h: np.ndarray, f: np.ndarray, max_order: float = 20.0, min_order: float = MIN_ORDER) -> Extrapolation:
    """Richardson extrapolation of answers ``f`` at step sizes ``h`` from the three finest rungs.

    Model f(h) = f* + C h^p.  With h1 < h2 < h3 the three smallest step sizes (finite
    answers only), e21 = f2 - f1, e32 = f3 - f2, the observed order p solves
    e32 / e21 = r21^p (r32^p - 1) / (r21^p - 1) (r21 = h2/h1, r32 = h3/h2; for
    r21 = r32 = r, p = ln(e32/e21) / ln r), and f* = f1 + (f1 - f2) / (r21^p - 1).
    Needs e32 / e21 > 1 (the answers change monotonically and the change shrinks with
    refinement) and ``min_order`` <= p <= ``max_order``; otherwise the status says which
    failed and nothing is extrapolated.
    """
    h = np.asarray(h, dtype=float)
    f = np.asarray(f, dtype=float)
    nan_errors = np.full(h.shape, np.nan)
    good = np.flatnonzero(np.isfinite(f) & np.isfinite(h))
    if good.size < 3:
        return Extrapolation(f"{good.size} rung(s) with an answer: Richardson needs 3", errors=nan_errors)
    finest = good[np.argsort(h[good])[:3]]
    (h1, h2, h3), (f1, f2, f3) = h[finest], f[finest]
    if not 0 < h1 < h2 < h3:
        return Extrapolation("step sizes of the three finest rungs are not distinct and positive", errors=nan_errors)
    r21, r32 = h2 / h1, h3 / h2
    e21, e32 = f2 - f1, f3 - f2
    if e21 == 0.0 and e32 == 0.0:
        return Extrapolation("the three finest rungs agree exactly: no order to estimate", ratios=(r21, r32),
                             errors=nan_errors)
    if e21 == 0.0 or e32 / e21 < 0.0:
        return Extrapolation("non-monotone: the answers of the three finest rungs do not change in one direction",
                             ratios=(r21, r32), errors=nan_errors)
    ratio = e32 / e21
    if ratio <= 1.0:
        return Extrapolation(f"not converging: the change does not shrink with refinement "
                             f"((f3 - f2)/(f2 - f1) = {ratio:.3g})", ratios=(r21, r32), errors=nan_errors)

    def mismatch(p: float) -> float:
        return math.log(r21 ** p * (r32 ** p - 1.0) / (r21 ** p - 1.0)) - math.log(ratio)

    low = 1e-6
    if mismatch(low) > 0.0:
        return Extrapolation(f"no positive order fits (f3 - f2)/(f2 - f1) = {ratio:.3g} with ratios "
                             f"{r21:.3g}, {r32:.3g}", ratios=(r21, r32), errors=nan_errors)
    if mismatch(max_order) < 0.0:
        return Extrapolation(f"observed order above {max_order:g}: not in the asymptotic range",
                             ratios=(r21, r32), errors=nan_errors)
    p = float(optimize.brentq(mismatch, low, max_order, xtol=1e-12))
    if p < min_order:
        return Extrapolation(f"observed order {p:.2g} below {min_order:g}: not in the asymptotic range",
                             order=p, ratios=(r21, r32), errors=nan_errors)
    value = float(f1 + (f1 - f2) / (r21 ** p - 1.0))
    return Extrapolation("extrapolated", order=p, ratios=(r21, r32), value=value, errors=f - value)


#: Resamplings of a ladder within its rungs' errors (:func:`resampled_richardson`).
RESAMPLING_DRAWS = 4000


def resampled_richardson(h: np.ndarray, f: np.ndarray, sigma: np.ndarray, draws: int = RESAMPLING_DRAWS,
                         seed: int = 0) -> Iterator[tuple[np.ndarray, Extrapolation]]:
    """The ladder resampled within its rungs' errors: ``draws`` times (``numpy.random.
    default_rng(seed)``, so deterministic) f_i + sigma_i x N(0, 1) for every rung (a NaN
    sigma counts as 0, a NaN answer stays NaN), each draw with its :func:`richardson`.

    Yields (the drawn answers, their extrapolation).
    """
    h = np.asarray(h, dtype=float)
    f = np.asarray(f, dtype=float)
    spread = np.nan_to_num(np.abs(np.asarray(sigma, dtype=float)))
    rng = np.random.default_rng(seed)
    for _ in range(draws):
        sample = f + spread * rng.standard_normal(h.size)
        yield sample, richardson(h, sample)
