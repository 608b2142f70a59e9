"""Which leaf block holds a point of the block mesh.

:class:`BlockLocator` finds the owning leaf block of a point on any
:class:`~impactpipe.hydro.mesh.blocks.BlockMesh` (:func:`locate`): the root block from the root
block grid, then one step down the block tree per level.  A regrid builds a new mesh with
renumbered blocks; the Simulation then calls :meth:`Tracers.mesh_changed`, which rebuilds
the locator and re-finds every tracer's block.  Positions and records are untouched by a
regrid (a tracer is a point, not a cell quantity).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from impactpipe.hydro.mesh.blocks import BlockMesh, block_keys

#: Boundary code for a periodic face in the fold / wrap kernels (the mesh neighbour table
#: holds a block index there; OUTFLOW and REFLECTING are the mesh's codes).
PERIODIC = 1


def as_positions(positions) -> np.ndarray:
    """(N, 3) float64 copy of (N, ndim) positions, unused components 0."""
    pos = np.asarray(positions, dtype=float)
    if pos.ndim != 2 or not 1 <= pos.shape[1] <= 3:
        raise ValueError(f"positions must have shape (N, 1..3), got {pos.shape}")
    out = np.zeros((pos.shape[0], 3))
    out[:, : pos.shape[1]] = pos
    return out


#: Entry of a block tree under construction that no block has filled (the leaves leave a hole).
_UNSET = np.iinfo(np.int64).min


def block_tree(mesh: BlockMesh) -> tuple[np.ndarray, np.ndarray]:
    """The leaf blocks of ``mesh`` as a tree of refined blocks over the root block grid.

    Returns ``root`` (``blocks_per_axis`` shape) coding each level-0 block and ``children``
    (nodes, 2^ndim) coding child c of each refined block (bit d of c set: the upper half
    along axis d, i.e. child index 2 i_d + 1 on the next level).  A code >= 0 is the index
    of a leaf block, a code < 0 the refined block (tree node) -1 - code.  A single-level
    mesh has no nodes and ``root`` maps the block grid to the block indices.
    """
    ndim = mesh.ndim
    level, index = mesh.block_level, mesh.block_index
    top = int(level.max(initial=0))
    node_keys, node_index = [], []
    for lev in range(top):
        deeper = level > lev
        ancestors = index[deeper] >> (level[deeper] - lev)[:, None]
        keys, first = np.unique(block_keys(np.full(len(ancestors), lev), ancestors), return_index=True)
        node_keys.append(keys)
        node_index.append(ancestors[first])
    offset = np.cumsum([0] + [len(k) for k in node_keys])
    root = np.full(tuple(int(n) for n in mesh.blocks_per_axis), _UNSET, dtype=np.int64)
    children = np.full((int(offset[-1]), 1 << ndim), _UNSET, dtype=np.int64)
    for lev in range(top + 1):
        leaf = np.flatnonzero(level == lev)
        items = index[leaf]
        codes = leaf
        if lev < top:
            items = np.concatenate([items, node_index[lev]])
            codes = np.concatenate([codes, -1 - (offset[lev] + np.arange(len(node_keys[lev])))])
        if lev == 0:
            root[items[:, 0], items[:, 1], items[:, 2]] = codes
            continue
        parent = offset[lev - 1] + np.searchsorted(node_keys[lev - 1],
                                                   block_keys(np.full(len(items), lev - 1), items >> 1))
        bit = ((items[:, :ndim] & 1) << np.arange(ndim)).sum(axis=1)
        children[parent, bit] = codes
    if (root == _UNSET).any() or (children == _UNSET).any():
        raise ValueError("the leaf blocks do not tile the domain")
    return root, children


@njit(cache=True)
def _grid_index(s, lev, n):
    """Index floor(2^lev s) on the level-``lev`` block grid of an axis with ``n`` root blocks,
    clamped to [0, n 2^lev - 1] (s = position / root block width)."""
    return min(max(int(math.floor(s * (1 << lev))), 0), (n << lev) - 1)


@njit(cache=True, parallel=True)
def _locate(position, skip, domain_lo, domain_hi, block_width, root, children, ndim, out):
    """Owning leaf block of each point, into ``out[N]``.

    With s_d = (x_d - lo_d) / w_d (w_d the root block width) the block holding the point on
    level L has grid index floor(2^L s_d) (clamped, so that x_d = hi_d belongs to the last
    block); the walk starts at the root block and descends into the child holding the point
    until it reaches a leaf.  Multiplying by 2^L is exact, so the indices of successive
    levels nest.  ``out`` is -1 for skipped points and points outside [lo, hi].
    """
    nblk = root.shape
    for t in prange(position.shape[0]):
        if skip[t]:
            out[t] = -1
            continue
        inside = True
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for d in range(ndim):
            x = position[t, d]
            if not (domain_lo[d] <= x <= domain_hi[d]):
                inside = False
                break
            s = (x - domain_lo[d]) / block_width[d]
            if d == 0:
                s0 = s
            elif d == 1:
                s1 = s
            else:
                s2 = s
        if not inside:
            out[t] = -1
            continue
        i0 = _grid_index(s0, 0, nblk[0])
        i1 = _grid_index(s1, 0, nblk[1])
        i2 = _grid_index(s2, 0, nblk[2])
        code = root[i0, i1, i2]
        lev = 0
        while code < 0:
            lev += 1
            j0 = _grid_index(s0, lev, nblk[0])
            j1 = _grid_index(s1, lev, nblk[1]) if ndim > 1 else 0
            j2 = _grid_index(s2, lev, nblk[2]) if ndim > 2 else 0
            code = children[-1 - code, (j0 - 2 * i0) + 2 * (j1 - 2 * i1) + 4 * (j2 - 2 * i2)]
            i0, i1, i2 = j0, j1, j2
        out[t] = code


class BlockLocator:
    """Owning-block lookup on a :class:`BlockMesh` of any leaf set (single-level or adaptive).

    Holds the block tree of :func:`block_tree`; the walk per point costs one step per
    level (:func:`_locate`).  Call ``locator(positions, skip, out)``: ``positions`` (N, 3) m,
    ``skip`` (N,) bool, ``out`` (N,) int64 receives the block index, -1 for skipped points
    and points outside the domain.  Build a new one for every new mesh (every regrid).
    """

    def __init__(self, mesh: BlockMesh):
        ndim = mesh.ndim
        width = np.ones(3)
        width[:ndim] = (mesh.domain_hi[:ndim] - mesh.domain_lo[:ndim]) / mesh.blocks_per_axis[:ndim]
        self.ndim = ndim
        self.domain_lo = mesh.domain_lo.copy()
        self.domain_hi = mesh.domain_hi.copy()
        self.block_width = width
        self.root, self.children = block_tree(mesh)

    def __call__(self, positions: np.ndarray, skip: np.ndarray, out: np.ndarray) -> np.ndarray:
        _locate(positions, skip, self.domain_lo, self.domain_hi, self.block_width, self.root, self.children,
                self.ndim, out)
        return out


def locate(mesh: BlockMesh, positions) -> np.ndarray:
    """(N,) index of the block containing each point of ``positions`` (N, 3) m, -1 outside the domain."""
    pos = as_positions(positions)
    out = np.empty(pos.shape[0], dtype=np.int64)
    return BlockLocator(mesh)(pos, np.zeros(pos.shape[0], dtype=np.bool_), out)


# ---------------------------------------------------------------------------- stencil
#
# Cells are addressed by global indices on the cell grid of a level L: cell g_d along axis d
# covers [lo_d + g_d dx_L, lo_d + (g_d + 1) dx_L], dx_L = dx_0 / 2^L; block b holds the cells
# block_index[b] * block_cells + [0, block_cells) of its own level.
