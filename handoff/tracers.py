"""Tracer bookkeeping for the hand-off: which leaf block holds each tracer, and per-block records.

A tracer belongs to the leaf block whose closed bounds ``lo <= x <= hi`` (on the mesh axes
in use) contain its current position; tracers flagged ``exited`` belong to none.  A tracer
on a face shared by two blocks is given to exactly one of them: blocks of the smallest
extents are searched first, then the nearest centre in the max-norm wins (deterministic
for given inputs).

Per block the hand-off needs the tracer count, the mean and the maximum peak pressure, and
the pre-impact position of the block's material.  Tracers are massless, so the origin is a
weighted mean in which each tracer of material k stands for an equal share of the mass of
material k in the block:

    w_t = m_{b,k(t)} / N_{b,k(t)},    x0_b = sum_t w_t x0_t / sum_t w_t,

with m_{b,k} the mass of material k in block b (kg) and N_{b,k} the number of its tracers
there.  Materials present without tracers are not represented; if every tracer in the
block is of a material with no mass in it, the tracers are weighted equally.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from impactpipe.hydro.output.snapshot import TracerSet

# Relative slack on the max-norm distance (in units of the block half-width) below which a
# point counts as inside a block: absorbs round-off for points on a block face.
_FACE_TOLERANCE = 1e-9


def locate_in_blocks(points: np.ndarray, block_lo: np.ndarray, block_hi: np.ndarray, ndim: int) -> np.ndarray:
    """Index of the leaf block containing each point, -1 where none does.

    Blocks are grouped by their extents (every block of one refinement level has the same
    edge lengths); within a group a point lies in the block whose centre c is nearest in
    the scaled max-norm max_i |x_i - c_i| / h_i <= 1 (h = half the block extents), found
    with a k-d tree, so the cost is O((N_points + N_blocks) log N_blocks) per group.

    Args:
        points: (N, 3) positions in mesh coordinates (m); rows with non-finite entries
            on the axes in use are located nowhere.
        block_lo, block_hi: (NB, 3) block corners (m).
        ndim: number of mesh axes in use (the leading ones).

    Returns:
        (N,) int64 block indices into the block arrays, -1 for points in no block.
    """
    points = np.asarray(points, dtype=float)[:, :ndim]
    lo = np.asarray(block_lo, dtype=float)[:, :ndim]
    hi = np.asarray(block_hi, dtype=float)[:, :ndim]
    extent = hi - lo
    if np.any(extent <= 0.0):
        raise ValueError("every leaf block must have a positive extent on the axes in use")
    owner = np.full(points.shape[0], -1, dtype=np.int64)
    if points.shape[0] == 0 or lo.shape[0] == 0:
        return owner
    finite = np.all(np.isfinite(points), axis=1)

    # Size classes: extents equal to 1e-9 of the largest block edge, smallest extents first
    # (np.unique sorts the rows).
    quantum = extent.max() * 1e-9
    size_keys = np.round(extent / quantum).astype(np.int64)
    _, size_class = np.unique(size_keys, axis=0, return_inverse=True)
    size_class = size_class.reshape(-1)
    centre = 0.5 * (lo + hi)
    for cls in range(int(size_class.max()) + 1):
        members = np.flatnonzero(size_class == cls)
        todo = np.flatnonzero((owner < 0) & finite)
        if todo.size == 0:
            break
        half = 0.5 * extent[members].mean(axis=0)
        tree = cKDTree(centre[members] / half)
        dist, nearest = tree.query(points[todo] / half, k=1, p=np.inf,
                                   distance_upper_bound=1.0 + _FACE_TOLERANCE)
        hit = np.isfinite(dist)
        owner[todo[hit]] = members[nearest[hit]]
    return owner


@dataclass
class BlockTracerRecords:
    """Tracer summaries per leaf block (NB blocks).

    Attributes:
        count: (NB,) tracers in the block.
        peak_pressure_mean: (NB,) arithmetic mean of their peak pressures (Pa), NaN if none.
        peak_pressure_max: (NB,) largest peak pressure (Pa), NaN if none.
        origin_position: (NB, 3) material-mass-weighted mean initial position (m, mesh
            coordinates; see the module docstring), NaN if none.
        owner: (N_tracers,) block index of each tracer, -1 for exited tracers and tracers
            in no leaf block.
        exited: number of tracers flagged exited.
        outside: number of tracers not flagged exited that lie in no leaf block.
    """

    count: np.ndarray
    peak_pressure_mean: np.ndarray
    peak_pressure_max: np.ndarray
    origin_position: np.ndarray
    owner: np.ndarray
    exited: int
    outside: int


def block_tracer_records(
    tracers: TracerSet | None,
    block_lo: np.ndarray,
    block_hi: np.ndarray,
    ndim: int,
    block_material_mass: np.ndarray,
) -> BlockTracerRecords:
    """Associate tracers with leaf blocks and summarise them per block.

    Args:
        tracers: the tracer set at hand-off, or None (every block then has no tracer).
        block_lo, block_hi: (NB, 3) block corners (m).
        ndim: number of mesh axes in use.
        block_material_mass: (NB, M) mass of each material in each block (kg), for the
            origin weights w_t = m_{b,k} / N_{b,k}.

    Returns:
        The per-block records.
    """
    nb, n_materials = block_material_mass.shape
    count = np.zeros(nb, dtype=np.int64)
    mean = np.full(nb, np.nan)
    peak = np.full(nb, np.nan)
    origin = np.full((nb, 3), np.nan)
    if tracers is None or len(tracers) == 0:
        return BlockTracerRecords(count, mean, peak, origin, np.zeros(0, dtype=np.int64), 0, 0)

    material = np.asarray(tracers.material, dtype=np.int64)
    if material.size and (material.min() < 0 or material.max() >= n_materials):
        raise ValueError(f"tracer material indices must lie in [0, {n_materials - 1}]")
    exited = np.asarray(tracers.exited, dtype=bool)
    owner = np.full(len(tracers), -1, dtype=np.int64)
    inside = ~exited
    owner[inside] = locate_in_blocks(np.asarray(tracers.position)[inside], block_lo, block_hi, ndim)
    outside = int(np.count_nonzero(inside & (owner < 0)))

    sel = np.flatnonzero(owner >= 0)
    b = owner[sel]
    pressure = np.asarray(tracers.peak_pressure, dtype=float)[sel]
    count = np.bincount(b, minlength=nb).astype(np.int64)
    has = count > 0
    mean[has] = np.bincount(b, weights=pressure, minlength=nb)[has] / count[has]
    peak_all = np.full(nb, -np.inf)
    np.maximum.at(peak_all, b, pressure)
    peak[has] = peak_all[has]

    k = material[sel]
    per_material = np.bincount(b * n_materials + k, minlength=nb * n_materials).reshape(nb, n_materials)
    weight = block_material_mass[b, k] / per_material[b, k]
    weight_sum = np.bincount(b, weights=weight, minlength=nb)
    equal = weight_sum[b] <= 0.0
    weight = np.where(equal, 1.0, weight)
    weight_sum = np.bincount(b, weights=weight, minlength=nb)
    x0 = np.asarray(tracers.initial_position, dtype=float)[sel]
    for axis in range(3):
        origin[has, axis] = np.bincount(b, weights=weight * x0[:, axis], minlength=nb)[has] / weight_sum[has]
    return BlockTracerRecords(count, mean, peak, origin, owner, int(np.count_nonzero(exited)), outside)


def fill_from_nearest(position: np.ndarray, value: np.ndarray, has_value: np.ndarray,
                      neighbours: int = 2) -> np.ndarray:
    """Give points without a value the mean value of their nearest points that have one.

    Args:
        position: (N, 3) point positions (m).
        value: (N,) values; entries where ``has_value`` is False are replaced.
        has_value: (N,) bool.
        neighbours: how many nearest points with a value to average (fewer if fewer exist).

    Returns:
        (N,) a copy of ``value`` with the gaps filled (NaN where no point has a value).
    """
    out = np.array(value, dtype=float, copy=True)
    donors = np.flatnonzero(has_value)
    gaps = np.flatnonzero(~has_value)
    if gaps.size == 0:
        return out
    if donors.size == 0:
        out[gaps] = np.nan
        return out
    k = min(neighbours, donors.size)
    _, nearest = cKDTree(position[donors]).query(position[gaps], k=k)
    nearest = np.asarray(nearest).reshape(gaps.size, k)
    out[gaps] = value[donors][nearest].mean(axis=1)
    return out
