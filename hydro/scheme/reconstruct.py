"""Slope limiters and the compressive face value used for volume fractions.

Cell ``i`` with neighbours ``i - 1`` and ``i + 1`` has the one-sided differences
``dl = q_i - q_{i-1}`` and ``dr = q_{i+1} - q_i``:

- :func:`mc_slope`, monotonised central (van Leer 1977):
  ``dq = sign * min(2 |dl|, 2 |dr|, |dl + dr| / 2)`` if ``dl dr > 0``, else 0.
- :func:`minmod_slope`: ``sign * min(|dl|, |dr|)`` if ``dl dr > 0``, else 0 (the most
  diffusive TVD slope; used to prolong coarse cells onto finer ones, where the value at an
  offset of at most a quarter cell per axis then stays between the neighbours' values).
- :func:`ultrabee_face`, the compressive limited face value for an advected bounded quantity
  (Roe's ultrabee, the TVD bound of the time-dependent flux limiter): with Courant number
  ``nu = |u*| dt / dx`` at the face, donor cell ``D``, its upwind neighbour ``U`` and the
  downwind cell ``W``,
  ``r = (q_D - q_U) / (q_W - q_D)``, ``phi = max(0, min(2 r / nu, 2 / (1 - nu)))``,
  ``q_face = q_D + phi (1 - nu) (q_W - q_D) / 2``.
  It keeps a material interface within 2-3 cells while staying TVD in one dimension.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True, inline="always")
def minmod_slope(qm, q0, qp):
    """Minmod limited slope (difference per cell) from three cell values."""
    dl = q0 - qm
    dr = qp - q0
    if dl * dr <= 0.0:
        return 0.0
    return dl if abs(dl) < abs(dr) else dr


@njit(cache=True, inline="always")
def mc_slope(qm, q0, qp):
    """Monotonised-central limited slope (difference per cell) from three cell values."""
    dl = q0 - qm
    dr = qp - q0
    if dl * dr <= 0.0:
        return 0.0
    adl = abs(dl)
    adr = abs(dr)
    s = 0.5 * abs(dl + dr)
    m = 2.0 * adl if adl < adr else 2.0 * adr
    if s < m:
        m = s
    return m if dl > 0.0 else -m


@njit(cache=True, inline="always")
def ultrabee_face(q_up, q_donor, q_down, nu):
    """Compressive (ultrabee) face value between ``q_donor`` and ``q_down`` at Courant number ``nu``."""
    dr = q_down - q_donor
    if dr == 0.0:
        return q_donor
    r = (q_donor - q_up) / dr
    if r <= 0.0:
        return q_donor
    if nu >= 1.0:
        return q_down
    phi = 2.0 / (1.0 - nu)
    if nu > 0.0 and 2.0 * r / nu < phi:
        phi = 2.0 * r / nu
    return q_donor + 0.5 * phi * (1.0 - nu) * dr
