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
weighted like the stress) as its cumulative law per unit mass at J = FLAW_NODES node strains
eps_0 < ... < eps_(J-1) (:func:`flaw_nodes`, :func:`flaw_law_per_mass`):

    C_j = (number of the cell's flaws with eps <= eps_j) / M         (flaws per kg)

M = rho0 v f the cell's material mass.  Between nodes the law is linear in eps^m (the Weibull
law's own variable: given that a flaw lies between two nodes, it lies anywhere in eps^m with
equal probability), from 0 at zero strain to C_0 at eps_0, and C_(J-1) (every flaw) beyond the
last node (:func:`impactpipe.hydro.strength.fracture.cumulative_flaws`).  The C_j are amounts
per unit mass, and the law is linear in them: transport, mixing, AMR restriction and
prolongation conserve sum(M C_j), the body's number of flaws below each node, exactly; a part
of a cell gets its share of the cell's law and a mixture of two cells' material the sum of their
laws, at every strain.  (A law kept as each cell's weakest and strongest flaw is not additive:
an averaged weakest strain loses the weak flaws a mixture holds.)  The nodes are geometric in
eps^m from the body's weakest flaw eps_1 = (1 / (k V))^(1/m) to its strongest
eps_n = (n_tot / (k V))^(1/m), J of them: (n_tot)^(1/(J - 1)) flaws per node interval of the
whole body's law, and a cell's flaw is placed within a factor (n_tot)^(1/(m (J - 1))) in strain
(1.21 for 1e5 flaws, m = 8.5, J = 8).

The flaws are drawn in chunks of :data:`CHUNK` with numpy (no Python loop per flaw or per cell).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from impactpipe.hydro.strength.parameters import FLAW_NODES

#: Flaws drawn per chunk (bounds the memory of the draw, not its result).
CHUNK = 1 << 22


class CellFlaws(NamedTuple):
    """The flaws of each cell of a body: smallest and largest activation strain (-, 0 where the
    cell has none), the number of flaws (int64) and, when node strains were given, the number of
    flaws at or below each node (N, J) int64 (else None)."""

    eps_min: np.ndarray
    eps_max: np.ndarray
    count: np.ndarray
    below: np.ndarray | None = None


def default_flaw_count(n_cells: int) -> int:
    """n_tot = ceil(N ln N), at least N: about the draws that leave no one of N equal cells empty."""
    return max(int(np.ceil(n_cells * np.log(max(n_cells, 1)))), n_cells)


def activation_strain(j: np.ndarray, body_volume: float, weibull_m: float, weibull_k: float) -> np.ndarray:
    """Activation strain eps_j = (j / (k V))^(1/m) (-) of the body's j-th weakest flaw (j >= 1)."""
    return (np.asarray(j, dtype=float) / (weibull_k * body_volume)) ** (1.0 / weibull_m)


def flaw_nodes(body_volume: float, n_flaws: int, weibull_m: float, weibull_k: float,
               nodes: int = FLAW_NODES) -> np.ndarray:
    """Node strains (-) of the cumulative law: geometric in eps^m from the body's weakest flaw
    (j = 1) to its strongest (j = n_tot) of :func:`activation_strain`."""
    j = np.asarray(n_flaws, dtype=float) ** (np.arange(nodes) / (nodes - 1))
    return activation_strain(j, body_volume, weibull_m, weibull_k)


class BodyShare(NamedTuple):
    """The cells of a body that one of several processes holds, the body's cells being numbered
    in the processes' order: ``before``, the running sum of the cells' weights (m^3) up to its
    first cell, ``total``, the whole body's running sum (its last value), and ``ends``, whether
    its cells end the body.  Each process draws every flaw (one random sequence) and keeps those
    that fall in its cells, so the flaws do not depend on how the body is shared."""

    before: float
    total: float
    ends: bool


def running_sum(weights: np.ndarray, before: float = 0.0) -> np.ndarray:
    """before + w_0, before + w_0 + w_1, ...: the running sum of ``weights`` continued from
    ``before``, added one weight at a time (the same bits however the weights are split)."""
    return np.cumsum(np.concatenate(([before], weights)))[1:]


def assign_flaws(cell_volume: np.ndarray, body_volume: float, weibull_m: float, weibull_k: float,
                 rng: np.random.Generator, fill: np.ndarray | None = None,
                 n_flaws: int | None = None, node_strains: np.ndarray | None = None,
                 share: BodyShare | None = None) -> CellFlaws:
    """Draw the body's flaws and assign each to a cell weighted by its material volume.

    Args:
        cell_volume: (N,) volumes v_i of the cells the body fills (m^3).
        body_volume: the body's volume V (m^3) that sets the strains eps_j = (j / (k V))^(1/m).
        weibull_m: Weibull exponent m (-).
        weibull_k: Weibull coefficient k (m^-3).
        rng: the random generator (seeded by the caller).
        fill: optional (N,) fraction of each cell the body fills (0 .. 1); 1 when omitted.
        n_flaws: number of flaws n_tot; :func:`default_flaw_count` (N ln N) when omitted.
        node_strains: optional (J,) increasing strains; each cell's flaws at or below each are counted.
        share: where these cells are one process's part of the body (:class:`BodyShare`), that
            part; ``n_flaws`` must then be given.  None: the whole body.

    Returns:
        :class:`CellFlaws` with each cell's eps_min, eps_max, flaw count (and counts below the nodes).
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
    if share is None:
        cumulative = running_sum(weight)
        share = BodyShare(0.0, float(cumulative[-1]), True)
    else:
        cumulative = running_sum(weight, share.before)
    cumulative /= share.total
    lowest = share.before / share.total
    first = np.full(n_cells, n_tot + 1, dtype=np.int64)
    last = np.zeros(n_cells, dtype=np.int64)
    count = np.zeros(n_cells, dtype=np.int64)
    # the rank of the last flaw at or below each node: eps_j <= eps_node <=> j <= k V eps_node^m
    node_rank = None if node_strains is None else np.floor(
        weibull_k * body_volume * np.asarray(node_strains, dtype=float) ** weibull_m * (1.0 + 1e-12)).astype(np.int64)
    below = None if node_rank is None else np.zeros((n_cells, node_rank.size), dtype=np.int64)
    for start in range(1, n_tot + 1, CHUNK):
        j = np.arange(start, min(start + CHUNK, n_tot + 1), dtype=np.int64)
        u = rng.random(j.size)
        cell = np.searchsorted(cumulative, u, side="right")
        if share.before > 0.0 or not share.ends:  # the draws that fall in these cells
            kept = ((cell > 0) | (u >= lowest)) & ((cell < n_cells) | share.ends)
            cell, j = cell[kept], j[kept]
        np.minimum(cell, n_cells - 1, out=cell)
        count += np.bincount(cell, minlength=n_cells)
        np.minimum.at(first, cell, j)
        np.maximum.at(last, cell, j)
        if below is not None:
            for node, rank in enumerate(node_rank):
                below[:, node] += np.bincount(cell[j <= rank], minlength=n_cells)
    has = count > 0
    eps_min = np.where(has, activation_strain(np.where(has, first, 1), body_volume, weibull_m, weibull_k), 0.0)
    eps_max = np.where(has, activation_strain(np.where(has, last, 1), body_volume, weibull_m, weibull_k), 0.0)
    return CellFlaws(eps_min, eps_max, count, below)


def flaw_law_per_mass(flaws: CellFlaws, material_mass: np.ndarray) -> np.ndarray:
    """The cells' cumulative laws per unit mass C_j = below_j / M (flaws per kg; (N, J), module
    docstring) from flaws drawn with node strains; ``material_mass`` (N,) the body's mass in each
    cell M = rho0 v f (kg), positive where a cell holds flaws."""
    if flaws.below is None:
        raise ValueError("the flaws were drawn without node strains")
    mass = np.asarray(material_mass, dtype=float).ravel()
    has = flaws.count > 0
    if (mass[has] <= 0.0).any():
        raise ValueError("a cell with flaws needs a positive material mass")
    return np.where(has[:, None], flaws.below / np.where(has, mass, 1.0)[:, None], 0.0)
