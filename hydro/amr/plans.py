"""Index plans for the coarse/fine faces of an adaptive mesh, built once per mesh and cached.

For a sweep axis d a plan lists, for every ghost cell on a coarse/fine face, the cell(s) it
takes its value from, and, for every coarse cell beside finer blocks, the fine face cells
whose fluxes replace its own (:mod:`impactpipe.hydro.amr.transfer` applies them):

- ``restrict``: ghost cells of a coarse block across from finer blocks: (coarse block, ghost
  cell, fine block, lowest of its 2^ndim fine cells) and the axis-0 weights of the two fine
  columns (1/2 each, annulus volume shares in 2d-cylindrical);
- ``prolong``: ghost cells of a fine block across from a coarser one: (fine block, ghost
  cell, coarse block, the coarse cell that contains it);
- ``reflux``: coarse cells on a coarse/fine face: (coarse block, side, cell, fine block, first
  of the fine face cells in the sweep's transverse indices) and the coarse cell volume.

Cells are found from global cell indices: cell ``c`` (padded) of block b at level L along axis
a has the global index G = block_index[b, a] block_cells + c - GHOST on that level's grid; its
parent cell is G >> 1 and its children 2 G, 2 G + 1.
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.mesh.blocks import GHOST, BlockMesh


def _face_cells(mesh: BlockMesh, blocks: np.ndarray, sides: np.ndarray, axis: int, depth_cells) -> tuple:
    """All cells of given faces: ``depth_cells(side)`` lists their padded indices along ``axis``.

    Returns (block (N,), padded cell (N, 3), side (N,)): every transverse interior cell of each
    face, for every listed index along ``axis``.
    """
    ndim = mesh.ndim
    n = mesh.block_cells
    ranges = []
    for a in range(3):
        if a >= ndim:
            ranges.append(np.zeros(1, dtype=np.int64))
        elif a == axis:
            ranges.append(None)
        else:
            ranges.append(np.arange(GHOST, GHOST + n, dtype=np.int64))
    out_b, out_c, out_s = [], [], []
    for side in (0, 1):
        sel = blocks[sides == side]
        if sel.size == 0:
            continue
        axes = list(ranges)
        axes[axis] = np.asarray(depth_cells(side), dtype=np.int64)
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        out_b.append(np.repeat(sel, len(grid)))
        out_c.append(np.tile(grid, (sel.size, 1)))
        out_s.append(np.full(sel.size * len(grid), side, dtype=np.int64))
    if not out_b:
        return np.zeros(0, np.int64), np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    return np.concatenate(out_b), np.concatenate(out_c), np.concatenate(out_s)


def _global_index(mesh: BlockMesh, blocks: np.ndarray, cells: np.ndarray, axis: int) -> np.ndarray:
    """(N, 3) global cell indices on each block's level, wrapped across periodic faces of ``axis``."""
    used = np.arange(3) < mesh.ndim
    glob = np.where(used, mesh.block_index[blocks] * mesh.block_cells + cells - GHOST, 0)
    if mesh.boundaries[axis][0] == "periodic":
        extent = mesh.blocks_at_level(mesh.block_level[blocks])[:, axis] * mesh.block_cells
        glob[:, axis] %= extent
    return glob


def _block_and_cell(mesh: BlockMesh, level: np.ndarray, glob: np.ndarray) -> tuple:
    """The leaf block at ``level`` holding global cells ``glob`` and the padded cell in it."""
    used = np.arange(3) < mesh.ndim
    blocks = mesh.lookup(level, glob // mesh.block_cells)
    if (blocks < 0).any():
        raise RuntimeError("coarse/fine plan: a cell across a coarse/fine face is not in a leaf block "
                           "(the mesh is not 2:1 balanced)")
    return blocks, np.where(used, glob % mesh.block_cells + GHOST, 0)


def axis0_weights(mesh: BlockMesh, level: np.ndarray, fine_glob0: np.ndarray) -> np.ndarray:
    """(N, 2) shares of the two axis-0 fine cells from global index ``fine_glob0`` at ``level``."""
    weights = np.full((len(level), 2), 0.5)
    if mesh.geometry == "2d-cylindrical" and len(level):
        dx = mesh.root_cell_size[0] / 2.0 ** level
        r0, r1, r2 = fine_glob0 * dx, (fine_glob0 + 1) * dx, (fine_glob0 + 2) * dx
        inner, outer = r1 ** 2 - r0 ** 2, r2 ** 2 - r1 ** 2
        weights[:, 0] = inner / (inner + outer)
        weights[:, 1] = outer / (inner + outer)
    return weights


def axis_plans(mesh: BlockMesh, axis: int) -> dict:
    """The restrict / prolong / reflux plans of ``axis`` (module docstring), cached on the mesh."""
    key = ("coarse_fine_plans", axis)
    if key in mesh.cache:
        return mesh.cache[key]
    n = mesh.block_cells
    lower = list(range(GHOST))
    upper = list(range(GHOST + n, GHOST + n + GHOST))
    ghosts = lambda side: lower if side == 0 else upper  # noqa: E731
    plans = {}
    # prolong: ghost cells of fine blocks beside coarser ones
    b_idx, s_idx = np.nonzero(mesh.neighbor_level[:, axis, :] == -1)
    blocks, cells, _ = _face_cells(mesh, b_idx, s_idx, axis, ghosts)
    glob = _global_index(mesh, blocks, cells, axis)
    src, src_cell = _block_and_cell(mesh, mesh.block_level[blocks] - 1, glob >> 1)
    plans["prolong"] = np.ascontiguousarray(np.column_stack([blocks, cells, src, src_cell]).astype(np.int64))
    # restrict: ghost cells of coarse blocks beside finer ones
    b_idx, s_idx = np.nonzero(mesh.neighbor_level[:, axis, :] == 1)
    blocks, cells, _ = _face_cells(mesh, b_idx, s_idx, axis, ghosts)
    glob = _global_index(mesh, blocks, cells, axis)
    used = np.arange(3) < mesh.ndim
    fine = np.where(used, 2 * glob, 0)
    level = mesh.block_level[blocks] + 1
    src, src_cell = _block_and_cell(mesh, level, fine)
    plans["restrict"] = np.ascontiguousarray(np.column_stack([blocks, cells, src, src_cell]).astype(np.int64))
    plans["restrict_weight"] = axis0_weights(mesh, level, fine[:, 0])
    # reflux: coarse interior cells on the faces towards finer blocks
    blocks, cells, sides = _face_cells(mesh, b_idx, s_idx, axis, lambda side: [GHOST] if side == 0 else [GHOST + n - 1])
    glob = _global_index(mesh, blocks, cells, axis)
    across = glob.copy()
    across[:, axis] += np.where(sides == 0, -1, 1)
    if mesh.boundaries[axis][0] == "periodic":
        extent = mesh.blocks_at_level(mesh.block_level[blocks])[:, axis] * n
        across[:, axis] %= extent
    fine = np.where(used, 2 * across, 0)
    fine[:, axis] += np.where(sides == 0, 1, 0)
    fblock, fcell = _block_and_cell(mesh, mesh.block_level[blocks] + 1, fine)
    t1 = 1 if axis == 0 else 0
    t2 = 1 if axis == 2 else 2
    plans["reflux"] = np.ascontiguousarray(
        np.column_stack([blocks, sides, cells, fblock, fcell[:, t1], fcell[:, t2]]).astype(np.int64))
    volumes = mesh.cell_volumes()
    interior = np.where(used, cells - GHOST, 0)
    plans["reflux_volume"] = volumes[blocks, interior[:, 0], interior[:, 1], interior[:, 2]] if len(blocks) \
        else np.zeros(0)
    mesh.cache[key] = plans
    return plans


def first_layer_plans(mesh: BlockMesh, axis: int) -> dict:
    """The rows of the restrict and prolong plans of ``axis`` (:func:`axis_plans`) whose ghost
    cell lies in the first ghost layer, next to the interior, cached on the mesh: ``restrict``,
    ``restrict_weight`` and ``prolong`` as there.  A row of either reads interior cells and
    first-layer ghosts only (the restriction fine interior cells; the prolongation a coarse
    interior cell and its face neighbours), so these rows alone give that layer the values the
    whole plans give it."""
    key = ("first_layer_plans", axis)
    if key in mesh.cache:
        return mesh.cache[key]
    plans = axis_plans(mesh, axis)
    n = mesh.block_cells
    out = {}
    for name in ("restrict", "prolong"):
        cell = plans[name][:, 1 + axis]  # the ghost cell's padded index along the axis (columns: block, cell)
        rows = (cell == GHOST - 1) | (cell == GHOST + n)
        out[name] = np.ascontiguousarray(plans[name][rows])
        if name == "restrict":
            out["restrict_weight"] = np.ascontiguousarray(plans["restrict_weight"][rows])
    mesh.cache[key] = out
    return out
