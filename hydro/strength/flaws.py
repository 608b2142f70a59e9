"""Weibull flaws of one material body, assigned to the cells it fills (Benz & Asphaug 1994).

A brittle body holds incipient flaws whose number per unit volume that activate at tensile
strain eps or below follows the Weibull law (Grady & Kipp 1980; Jaeger & Cook 1969)

    n(eps) = k eps^m              (k in m^-3, m dimensionless; basalt: m = 8.5, k = 3e39 m^-3)

Assignment (Benz & Asphaug 1994, Icarus 107, 98): the body of volume V (m^3) gets n_tot flaws
with the activation strains

    eps_j = (j / (k V))^(1/m),        j = 1 .. n_tot,

so that exactly j flaws of the body activate at strain eps_j or below, whatever the mesh.  Each
flaw goes to a cell drawn at random with probability w_i / sum(w), w_i = v_i f_i the material
volume of cell i (its volume v_i times the body's fill f_i), so a region of volume V_r
receives on average k V_r eps^m of the flaws below eps: the statistics of any part of the body
do not depend on the cell size.  A cell keeps its smallest and largest activation strain and
its flaw count; :func:`impactpipe.hydro.strength.fracture.active_flaws` turns them back into
the cell's number of active flaws at a strain.

Number of flaws: n_tot = ceil(N ln N) for N cells (at least N) unless given.  N ln N is the
expected number of draws until every one of N equal cells holds a flaw (the coupon collector;
Benz & Asphaug 1994 draw until every particle has one); it is fixed here instead, so the body's
law is not extended by a random number of extra flaws.  With equal cells about one cell in N
ln N draws stays empty (N (1 - 1/N)^(N ln N) -> 1); cells with a small weight w_i (partly
filled surface cells) stay empty more often: they have count 0 and no tensile flaw.

In the hydro stage a cell's flaws travel with the material (the state's ``arhoq``, mass
weighted like the stress) as a local Weibull law per unit mass (:func:`flaw_law_per_mass`):

    n_act,m(eps) = min(max(a eps^m - b, 0), n_m)        (flaws per kg active at strain eps)

the straight line in eps^m through the cell's first flaw (1 active at eps_min) and its last
(n at eps_max), a = (n - 1) / (M (eps_max^m - eps_min^m)), b = max(a M eps_min^m - 1, 0) / M,
n_m = n / M, M = rho0 v f the cell's material mass (a cell with one flaw takes the body's slope,
a = k / rho0; a cell without flaws has a = b = n_m = 0).  b >= 0 keeps every flaw inactive
without strain: a cell whose first flaw lies within one flaw spacing of zero strain takes the
line through the origin instead (below its first flaw, at most one flaw early).  The three are amounts per unit mass,
so transport, mixing, AMR restriction and prolongation conserve sum(M a), sum(M b) and the
flaw count sum(M n_m): a part of a cell gets its share of the cell's law (1/8 of the law to
each of 8 children), and a mixture of two cells gets the sum of their laws wherever neither is
cut off (below its first flaw or above its last); only those cut-offs are not additive.
The discrete steps of the cell's law at eps_min and eps_max become ramps one flaw spacing
wide (below eps_min and above eps_max, the partial flaw of the continuum law).

The flaws are drawn in chunks of :data:`CHUNK` with numpy (no Python loop per flaw or per cell).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

#: Flaws drawn per chunk (bounds the memory of the draw, not its result).
CHUNK = 1 << 22


class CellFlaws(NamedTuple):
    """The flaws of each cell of a body: smallest and largest activation strain (-, 0 where the
    cell has none) and the number of flaws (int64)."""

    eps_min: np.ndarray
    eps_max: np.ndarray
    count: np.ndarray


def default_flaw_count(n_cells: int) -> int:
    """n_tot = ceil(N ln N), at least N: about the draws that leave no one of N equal cells empty."""
    return max(int(np.ceil(n_cells * np.log(max(n_cells, 1)))), n_cells)


def activation_strain(j: np.ndarray, body_volume: float, weibull_m: float, weibull_k: float) -> np.ndarray:
    """Activation strain eps_j = (j / (k V))^(1/m) (-) of the body's j-th weakest flaw (j >= 1)."""
    return (np.asarray(j, dtype=float) / (weibull_k * body_volume)) ** (1.0 / weibull_m)


def assign_flaws(cell_volume: np.ndarray, body_volume: float, weibull_m: float, weibull_k: float,
                 rng: np.random.Generator, fill: np.ndarray | None = None,
                 n_flaws: int | None = None) -> CellFlaws:
    """Draw the body's flaws and assign each to a cell weighted by its material volume.

    Args:
        cell_volume: (N,) volumes v_i of the cells the body fills (m^3).
        body_volume: the body's volume V (m^3) that sets the strains eps_j = (j / (k V))^(1/m).
        weibull_m: Weibull exponent m (-).
        weibull_k: Weibull coefficient k (m^-3).
        rng: the random generator (seeded by the caller).
        fill: optional (N,) fraction of each cell the body fills (0 .. 1); 1 when omitted.
        n_flaws: number of flaws n_tot; :func:`default_flaw_count` (N ln N) when omitted.

    Returns:
        :class:`CellFlaws` with each cell's eps_min, eps_max and flaw count.
    """
    weight = np.asarray(cell_volume, dtype=float).ravel()
    if fill is not None:
        weight = weight * np.asarray(fill, dtype=float).ravel()
    n_cells = weight.size
    if n_cells == 0 or not (weight >= 0.0).all() or weight.sum() <= 0.0:
        raise ValueError("the body needs at least one cell with a positive volume and fill")
    if body_volume <= 0.0 or weibull_m <= 0.0 or weibull_k <= 0.0:
        raise ValueError(f"body volume, Weibull m and k must be > 0 (got {body_volume:g}, {weibull_m:g}, {weibull_k:g})")
    n_tot = default_flaw_count(n_cells) if n_flaws is None else int(n_flaws)
    if n_tot < 1:
        raise ValueError(f"a body needs at least one flaw (got {n_tot})")
    cumulative = np.cumsum(weight)
    cumulative /= cumulative[-1]
    first = np.full(n_cells, n_tot + 1, dtype=np.int64)
    last = np.zeros(n_cells, dtype=np.int64)
    count = np.zeros(n_cells, dtype=np.int64)
    for start in range(1, n_tot + 1, CHUNK):
        j = np.arange(start, min(start + CHUNK, n_tot + 1), dtype=np.int64)
        cell = np.searchsorted(cumulative, rng.random(j.size), side="right")
        np.minimum(cell, n_cells - 1, out=cell)
        count += np.bincount(cell, minlength=n_cells)
        np.minimum.at(first, cell, j)
        np.maximum.at(last, cell, j)
    has = count > 0
    eps_min = np.where(has, activation_strain(np.where(has, first, 1), body_volume, weibull_m, weibull_k), 0.0)
    eps_max = np.where(has, activation_strain(np.where(has, last, 1), body_volume, weibull_m, weibull_k), 0.0)
    return CellFlaws(eps_min, eps_max, count)


class FlawLaw(NamedTuple):
    """The local Weibull law per unit mass of each cell (module docstring): slope a, offset b and
    flaw count n_m, all in flaws per kg (a per unit eps^m)."""

    slope: np.ndarray
    offset: np.ndarray
    count: np.ndarray


def flaw_law_per_mass(flaws: CellFlaws, material_mass: np.ndarray, weibull_m: float, weibull_k: float,
                      reference_density: float) -> FlawLaw:
    """The cells' local Weibull laws per unit mass from their drawn flaws (module docstring).

    Args:
        flaws: each cell's eps_min, eps_max and count (:func:`assign_flaws`).
        material_mass: (N,) the body's mass in each cell M = rho0 v f (kg); cells with flaws need M > 0.
        weibull_m, weibull_k: the body's Weibull law (-, m^-3).
        reference_density: rho0 (kg/m^3), for the body's slope k / rho0 of cells with one flaw.
    """
    mass = np.asarray(material_mass, dtype=float).ravel()
    count = np.asarray(flaws.count, dtype=float)
    has = count > 0
    if (mass[has] <= 0.0).any():
        raise ValueError("a cell with flaws needs a positive material mass")
    lo = np.asarray(flaws.eps_min, dtype=float) ** weibull_m
    hi = np.asarray(flaws.eps_max, dtype=float) ** weibull_m
    safe_mass = np.where(has, mass, 1.0)
    several = count > 1
    slope = np.where(several, (count - 1.0) / np.where(several, hi - lo, 1.0) / safe_mass,
                     weibull_k / reference_density)
    slope = np.where(has, slope, 0.0)
    offset = np.where(has, np.maximum(slope * lo - 1.0 / safe_mass, 0.0), 0.0)
    return FlawLaw(slope, offset, np.where(has, count / safe_mass, 0.0))
