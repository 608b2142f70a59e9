"""Shock history of the material: cumulative peak-pressure distributions and provenance.

Convention: the cumulative distribution is the *fraction of mass shocked to at
least P*,

    F(P) = sum_{i : P_i >= P} m_i / sum_i m_i,

evaluated at the distinct peak pressures in ascending order, so F is
non-increasing, F = 1 at the lowest pressure and F = (mass at the highest
pressure) / total at the highest.  Particles whose peak pressure is not finite
(no tracer information) are left out of numerator and denominator; their mass
fraction is logged.

Provenance: the N-body stage stores, for each final particle k, the hand-off
particle ids it contains as CSR arrays (``members[members_offset[k]:
members_offset[k + 1]]``).  :func:`provenance_owner` inverts that into the final
particle that holds each hand-off particle (-1 for hand-off particles in no final
particle, e.g. removed as escaped).  Selections of final particles (a remnant's
members) become selections of hand-off particles with ``np.isin(owner,
members)``.

Interior / exterior of a remnant: hand-off material whose final particle lies
within ``interior_fraction`` (default 0.75) of the remnant's bulk radius from the
remnant's centre of mass is interior, the rest exterior.  With merging collision
models all the material of a merged particle sits at that particle's centre, so
the split only resolves structure down to the size of the final particles.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from .remnants import RemnantResult

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class MassFractionCurve:
    """F(P): fraction of the selected mass shocked to at least P.

    Attributes:
        pressure: (n,) distinct peak pressures, ascending (Pa).
        fraction: (n,) F at each pressure, non-increasing, fraction[0] = 1.
        mass: selected mass with a finite peak pressure (kg).
    """

    pressure: np.ndarray
    fraction: np.ndarray
    mass: float

    def as_datasets(self) -> dict[str, Any]:
        """The curve as a ``write_analysis`` group."""
        return {
            "pressure": (self.pressure, "Pa", "distinct peak pressures, ascending"),
            "fraction": (self.fraction, "dimensionless", "mass fraction shocked to >= pressure"),
            "mass": (self.mass, "kg", "selected mass with a finite peak pressure"),
        }


def cumulative_mass_fraction(peak_pressure, mass) -> tuple[np.ndarray, np.ndarray]:
    """Fraction of mass shocked to at least P, at each distinct peak pressure.

    Args:
        peak_pressure: (N,) peak pressures (Pa); non-finite entries are left out.
        mass: (N,) masses (kg).

    Returns:
        (pressure, fraction): distinct finite pressures ascending (Pa) and
        F(P) = sum_{P_i >= P} m_i / sum m_i (non-increasing, F[0] = 1).  Empty arrays
        when no particle has a finite pressure.
    """
    p = np.asarray(peak_pressure, dtype=float)
    m = np.asarray(mass, dtype=float)
    if p.shape != m.shape or p.ndim != 1:
        raise ValueError("peak_pressure and mass must be 1-D arrays of the same length")
    finite = np.isfinite(p)
    if not finite.all() and m.sum() > 0:
        logger.warning("%d particles (%.3g of the mass) have no finite peak pressure and are left out",
                       int((~finite).sum()), m[~finite].sum() / m.sum())
    p, m = p[finite], m[finite]
    if p.size == 0:
        return np.zeros(0), np.zeros(0)
    levels, inverse = np.unique(p, return_inverse=True)
    mass_at = np.bincount(inverse, weights=m, minlength=levels.size)
    above = np.cumsum(mass_at[::-1])[::-1]
    return levels, above / above[0]


def _curve(peak_pressure, mass, select) -> MassFractionCurve:
    p, f = cumulative_mass_fraction(peak_pressure[select], mass[select])
    finite = np.isfinite(peak_pressure[select])
    return MassFractionCurve(pressure=p, fraction=f, mass=float(mass[select][finite].sum()))


def provenance_owner(members_offset, members, handoff_ids) -> np.ndarray:
    """The final particle that contains each hand-off particle.

    Args:
        members_offset: (N_final + 1,) CSR offsets.
        members: hand-off ids contained in the final particles.
        handoff_ids: (N_handoff,) ids of the hand-off particles (unique).

    Returns:
        (N_handoff,) int64 index of the final particle holding each hand-off
        particle, -1 where none does.

    Raises:
        ValueError: malformed offsets, a member id that is not a hand-off id, or a
        hand-off id listed in more than one final particle.
    """
    offset = np.asarray(members_offset, dtype=np.int64)
    ids_in = np.asarray(members, dtype=np.int64)
    ids = np.asarray(handoff_ids, dtype=np.int64)
    malformed = offset.ndim != 1 or offset.size < 1 or offset[0] != 0 or offset[-1] != ids_in.size
    if malformed or np.any(np.diff(offset) < 0):
        raise ValueError("members_offset must start at 0, not decrease, and end at len(members)")
    owner = np.full(ids.size, -1, dtype=np.int64)
    if ids_in.size == 0:
        return owner
    if ids.size == 0:
        raise ValueError("members lists ids but there are no hand-off ids")
    sorter = np.argsort(ids, kind="stable")
    where = sorter[np.minimum(np.searchsorted(ids, ids_in, sorter=sorter), ids.size - 1)]
    unknown = ids[where] != ids_in
    if np.any(unknown):
        raise ValueError(f"{int(unknown.sum())} member ids are not hand-off ids (first: {ids_in[unknown][0]})")
    if np.unique(where).size != where.size:
        raise ValueError("a hand-off id appears in more than one final particle")
    final_index = np.repeat(np.arange(offset.size - 1, dtype=np.int64), np.diff(offset))
    owner[where] = final_index
    return owner


def shock_history(
    peak_pressure,
    mass,
    owner,
    remnants: RemnantResult,
    final_position,
    *,
    interior_fraction: float = 0.75,
) -> dict[str, MassFractionCurve]:
    """Cumulative peak-pressure distributions for the standard splits of the material.

    Args:
        peak_pressure: (N_handoff,) peak pressure of each hand-off particle (Pa).
        mass: (N_handoff,) hand-off particle masses (kg).
        owner: (N_handoff,) final particle holding each hand-off particle
            (:func:`provenance_owner`), -1 for none.
        remnants: remnants found on the final particles.
        final_position: (N_final, 3) final particle positions (m).
        interior_fraction: interior means closer than this times the largest
            remnant's bulk radius to its centre of mass.

    Returns:
        Curves keyed "all", and when the remnants exist "largest",
        "largest_interior", "largest_exterior", "second_largest".
    """
    p = np.asarray(peak_pressure, dtype=float)
    m = np.asarray(mass, dtype=float)
    owner = np.asarray(owner, dtype=np.int64)
    xf = np.asarray(final_position, dtype=float)
    curves = {"all": _curve(p, m, np.ones(p.size, dtype=bool))}
    lr = remnants.largest
    if lr is not None:
        in_lr = np.isin(owner, lr.members)
        dist = np.full(p.size, np.inf)
        held = owner >= 0
        dist[held] = np.linalg.norm(xf[owner[held]] - lr.com, axis=1)
        interior = dist < interior_fraction * lr.bulk_radius
        curves["largest"] = _curve(p, m, in_lr)
        curves["largest_interior"] = _curve(p, m, in_lr & interior)
        curves["largest_exterior"] = _curve(p, m, in_lr & ~interior)
    slr = remnants.second_largest
    if slr is not None:
        curves["second_largest"] = _curve(p, m, np.isin(owner, slr.members))
    return curves
