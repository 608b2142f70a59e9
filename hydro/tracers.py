"""Massless Lagrangian tracers carried with the material velocity of the hydro mesh.

A tracer is a point x(t) (m, mesh coordinates: (x, 0, 0), (x, y, 0), (r, z, 0) in
2d-cylindrical, (x, y, z)) attached to one material k.  It moves with the interpolated cell
velocity and records the peak pressure, its time and the peak temperature of its material.

**Velocity.**  Cell velocity u_c = m_c / rho_c (momentum over mixture density).  At a
point x the tracer of material k sees

    v(x) = sum_c W_c(x) a_c u_c / sum_c W_c(x) a_c,        a_c = alpha_k rho_k in cell c

over the 2^ndim cells c of the (bi/tri)linear cell-centred stencil around x, with W_c the
multilinear weights.  Weighting by the tracer's own partial density means void and other
materials (a_c = 0) do not drag it: a tracer in a slab next to void moves with the slab.
In a single material of uniform density v is plain multilinear interpolation (exact for a
linear velocity field).  When every a_c vanishes the tracer takes the velocity of the cell
that contains it (0 in a void cell).

**Stencil on an adaptive mesh.**  The stencil lives on the cell grid of one level, addressed
by global cell indices; the leaf holding any cell is found by walking the block tree
(:func:`block_tree`).  It starts on the owning block's level L.  A stencil cell in a leaf
of that level is read directly; one in a finer leaf (L + 1) stands for the 2^ndim cells
covering it, each with W_c / 2^ndim (their mean); when a cell of positive weight lies in a
coarser leaf, the whole stencil is taken on the grid of level L - 1 instead (the owning
block's cells then enter by 2^ndim as well).  Every stencil is thus multilinear
interpolation on one level with exact point values of a linear field, so a linear field is
interpolated exactly across coarse/fine faces, edges and corners; the price is the coarser
stencil within about one cell of a coarser leaf.  On a single-level mesh this is the plain
stencil of the owning block.  At a domain face a reflecting boundary mirrors the cell and
negates the normal velocity (the symmetry axis r = 0 is one), outflow repeats the edge cell
(zero gradient), periodic wraps.  Interior cells only are read: ghost layers are stale
between sweeps (the solver fills each axis's ghosts just before its sweep) and are never
read, so the tracers do not touch the hydro state.

**Time integration** (Heun, second order): with v_n the field at t_n (sampled in
:meth:`Tracers.before_step`, before the sweeps) and v_{n+1} the field after the step,

    x* = x_n + dt v_n(x_n),    x_{n+1} = x_n + dt/2 [v_n(x_n) + v_{n+1}(x*)].

The recorded velocity is the step mean (x_{n+1} - x_n) / dt = [v_n(x_n) + v_{n+1}(x*)] / 2.
A predictor x* outside the domain is folded back for sampling (periodic wrap, mirror with
the normal velocity negated at a reflecting face, clamp at an outflow face).  After the
corrector, a position past a periodic face wraps, past a reflecting face (the axis in
2d-cylindrical: r < 0) is mirrored with its normal velocity negated, and past an outflow
face the tracer **exits**: it is flagged, its exit time is interpolated linearly in the
step, t_exit = t_n + dt (x_face - x_n) / (x_{n+1} - x_n), its velocity is kept, and from
then on it moves **ballistically** (x += dt v, no gravity; in 2d-cylindrical r < 0 is
mirrored, which is exact for a straight line without swirl).  Exited tracers record no
more peaks.

**Peaks.**  After every step (and at the first step's start for a tracer without a record)
the tracer's cell is the containing cell if it holds material k (alpha_k > ALPHA_MIN), else
the stencil cell with the largest W_c a_c; there p_k = P_k(rho_k, e_k) and
T_k = T_k(rho_k, e_k) with rho_k = arho_k / alpha_k and e_k = arhoe_k / arho_k
(:func:`impactpipe.hydro.eos.pressure_sound_speed`, :func:`impactpipe.hydro.eos.temperature`).
The peak pressure (Pa), its time (s) and the peak temperature (K) are the running maxima
(NaN until the first record).

**History** (optional): every ``history_interval`` seconds of simulated time the first step
that reaches k * history_interval appends (time, all positions) to arrays preallocated for
``end_time`` and doubled when full; 24 bytes per tracer and sample.

**Block lookup.**  :class:`BlockLocator` finds the owning leaf block of a point on any
:class:`~impactpipe.hydro.mesh.BlockMesh` (:func:`locate`): the root block from the root
block grid, then one step down the block tree per level.  A regrid builds a new mesh with
renumbered blocks; the Simulation then calls :meth:`Tracers.mesh_changed`, which rebuilds
the locator and re-finds every tracer's block.  Positions and records are untouched by a
regrid (a tracer is a point, not a cell quantity).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from impactpipe.hydro.eos import pressure_sound_speed, temperature
from impactpipe.hydro.mesh import GHOST, OUTFLOW, REFLECTING, BlockMesh, block_keys
from impactpipe.hydro.snapshot import TracerSet
from impactpipe.hydro.timestep import ALPHA_MIN
from impactpipe.storage import write_dataset

#: Boundary code for a periodic face in the fold / wrap kernels (the mesh neighbour table
#: holds a block index there; OUTFLOW and REFLECTING are the mesh's codes).
PERIODIC = 1

#: Tracer record arrays (the :class:`~impactpipe.hydro.snapshot.TracerSet` fields) with their
#: units and descriptions.
TRACER_UNITS = {
    "id": ("dimensionless", "tracer id"),
    "material": ("dimensionless", "material index into the snapshot's material_names"),
    "initial_position": ("m", "position at t = 0, mesh coordinates"),
    "position": ("m", "current position, mesh coordinates"),
    "velocity": ("m/s", "velocity over the last step (last velocity once exited)"),
    "peak_pressure": ("Pa", "highest pressure of the tracer's material in its cell"),
    "peak_pressure_time": ("s", "time of the peak pressure"),
    "peak_temperature": ("K", "highest temperature of the tracer's material in its cell"),
    "exited": ("dimensionless", "True once the tracer left the mesh through an outflow face"),
    "exit_time": ("s", "time the tracer left the mesh, NaN if it did not"),
}
#: Optional down-sampled trajectory.
HISTORY_UNITS = {
    "history_time": ("s", "times of the trajectory samples"),
    "history_position": ("m", "(samples, tracers, 3) positions at the sample times"),
}
#: History samples allocated when no end time is given (the arrays double when full).
HISTORY_CHUNK = 64


# ---------------------------------------------------------------------------- block lookup

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
    pos = _as_positions(positions)
    out = np.empty(pos.shape[0], dtype=np.int64)
    return BlockLocator(mesh)(pos, np.zeros(pos.shape[0], dtype=np.bool_), out)


# ---------------------------------------------------------------------------- stencil
#
# Cells are addressed by global indices on the cell grid of a level L: cell g_d along axis d
# covers [lo_d + g_d dx_L, lo_d + (g_d + 1) dx_L], dx_L = dx_0 / 2^L; block b holds the cells
# block_index[b] * block_cells + [0, block_cells) of its own level.


@njit(cache=True, inline="always")
def _cell_block(g, lev, m, block_cells):
    """Index on the level-``m`` block grid of the block covering cell ``g`` of level ``lev``."""
    if m <= lev:
        return (g >> (lev - m)) // block_cells
    return (g << (m - lev)) // block_cells


@njit(cache=True, inline="always")
def _leaf_of_cell(g0, g1, g2, lev, block_cells, root, children):
    """(leaf block, its level m) covering cell (g0, g1, g2) of level ``lev`` (unused axes 0).

    m < lev: the leaf is coarser than the cell; m >= lev: the cell is the 2^(m - lev) cells
    per used axis from g 2^(m - lev) of that leaf (all in it: a stencil spans levels L - 1 to
    L + 1 around a block of level L by the 2:1 balance, so m - lev <= 2, and block_cells is
    a multiple of 4 on a refined mesh, :meth:`Tracers.mesh_changed`).
    """
    i0 = _cell_block(g0, lev, 0, block_cells)
    i1 = _cell_block(g1, lev, 0, block_cells)
    i2 = _cell_block(g2, lev, 0, block_cells)
    code = root[i0, i1, i2]
    m = 0
    while code < 0:
        m += 1
        j0 = _cell_block(g0, lev, m, block_cells)
        j1 = _cell_block(g1, lev, m, block_cells)
        j2 = _cell_block(g2, lev, m, block_cells)
        code = children[-1 - code, (j0 - 2 * i0) + 2 * (j1 - 2 * i1) + 4 * (j2 - 2 * i2)]
        i0, i1, i2 = j0, j1, j2
    return code, m


@njit(cache=True, inline="always")
def _wrap(g, n, low, high):
    """(cell index in [0, n), velocity sign) for cell ``g`` of an axis of ``n`` cells with the
    domain-face codes ``low`` and ``high`` (|g| or g - n at most one cell outside).

    Periodic wraps, reflecting mirrors (g -> -1 - g or 2 n - 1 - g, sign -1), outflow
    repeats the edge cell.
    """
    if g < 0:
        if low == PERIODIC:
            return g + n, 1.0
        if low == REFLECTING:
            return -1 - g, -1.0
        return 0, 1.0
    if g >= n:
        if high == PERIODIC:
            return g - n, 1.0
        if high == REFLECTING:
            return 2 * n - 1 - g, -1.0
        return n - 1, 1.0
    return g, 1.0


@njit(cache=True, inline="always")
def _base(x, b, lev, d, ndim, block_lo, block_dx, block_index, block_level, block_cells):
    """Lower stencil cell and the weight of the upper cell along axis ``d`` on the level-``lev``
    cell grid (lev <= the level of block ``b``), for the point x inside block ``b``.

    The cell index i counts from cell q, the level-lev cell holding the block's first cell
    f = block_index[b, d] block_cells; with r = 2^(level_b - lev) and f = r q + p,
    s = ((x - block_lo) / dx_b + p) / r - 0.5 is the point's position in level-lev cells
    from the centre of cell q: i = floor(s), weight s - i.  On the block's own level
    (r = 1, q = f) this is s = (x - block_lo) / dx_b - 0.5.
    """
    if d >= ndim:
        return 0, 0.0
    shift = block_level[b] - lev
    if shift == 0:
        s = (x - block_lo[b, d]) / block_dx[b, d] - 0.5
    else:
        first = block_index[b, d] * block_cells
        s = ((x - block_lo[b, d]) / block_dx[b, d] + (first - ((first >> shift) << shift))) / (1 << shift) - 0.5
    i = int(math.floor(s))
    return i, s - i


@njit(cache=True)
def _stencil_base(x, y, z, b, lev, ndim, block_lo, block_dx, block_index, block_level, block_cells):
    """(i0, fx, j0, fy, k0, fz): :func:`_base` along the three axes for the point (x, y, z)."""
    i0, fx = _base(x, b, lev, 0, ndim, block_lo, block_dx, block_index, block_level, block_cells)
    j0, fy = _base(y, b, lev, 1, ndim, block_lo, block_dx, block_index, block_level, block_cells)
    k0, fz = _base(z, b, lev, 2, ndim, block_lo, block_dx, block_index, block_level, block_cells)
    return i0, fx, j0, fy, k0, fz


@njit(cache=True, inline="always")
def _global_cell(i, b, lev, d, block_index, block_level, block_cells):
    """Global index on the level-``lev`` cell grid of cell ``i`` counted as in :func:`_base`."""
    return ((block_index[b, d] * block_cells) >> (block_level[b] - lev)) + i


@njit(cache=True, inline="always")
def _corner(c, b, lev, i0, j0, k0, fx, fy, fz, ndim, codes, cells, block_index, block_level, block_cells,
            root, children):
    """Corner ``c`` (bit d set: upper cell along axis d) of the level-``lev`` stencil with lower
    cell (i0, j0, k0) (counted as in :func:`_base`) around a point in block ``b``.

    Returns (block, padded ix, iy, iz, n, multilinear weight, velocity signs sx, sy, sz): the
    corner cell is the n cells per used axis from (ix, iy, iz) of that leaf block (n = 1 on
    the leaf's own level, 2^(m - lev) on a finer leaf of level m), after the domain faces
    (:func:`_wrap`, on the level's ``cells << lev`` cells per axis).  Block -1 when the leaf
    is coarser than ``lev`` (the stencil must drop a level).
    """
    ix, iy, iz = i0, j0, k0
    w = 1.0
    if c & 1:
        ix += 1
        w *= fx
    else:
        w *= 1.0 - fx
    if ndim > 1:
        if c & 2:
            iy += 1
            w *= fy
        else:
            w *= 1.0 - fy
    if ndim > 2:
        if c & 4:
            iz += 1
            w *= fz
        else:
            w *= 1.0 - fz
    gy = GHOST if ndim > 1 else 0
    gz = GHOST if ndim > 2 else 0
    if lev == block_level[b] and 0 <= ix < block_cells and 0 <= iy < block_cells and 0 <= iz < block_cells:
        return b, ix + GHOST, iy + gy, iz + gz, 1, w, 1.0, 1.0, 1.0
    g0, sx = _wrap(_global_cell(ix, b, lev, 0, block_index, block_level, block_cells), cells[0] << lev,
                   codes[0, 0], codes[0, 1])
    g1, sy = 0, 1.0
    g2, sz = 0, 1.0
    if ndim > 1:
        g1, sy = _wrap(_global_cell(iy, b, lev, 1, block_index, block_level, block_cells), cells[1] << lev,
                       codes[1, 0], codes[1, 1])
    if ndim > 2:
        g2, sz = _wrap(_global_cell(iz, b, lev, 2, block_index, block_level, block_cells), cells[2] << lev,
                       codes[2, 0], codes[2, 1])
    blk, m = _leaf_of_cell(g0, g1, g2, lev, block_cells, root, children)
    if m < lev:
        return -1, 0, 0, 0, 0, w, sx, sy, sz
    shift = m - lev
    ix = (g0 << shift) - block_index[blk, 0] * block_cells + GHOST
    iy = (g1 << shift) - block_index[blk, 1] * block_cells + gy if ndim > 1 else 0
    iz = (g2 << shift) - block_index[blk, 2] * block_cells + gz if ndim > 2 else 0
    return blk, ix, iy, iz, 1 << shift, w, sx, sy, sz


@njit(cache=True, inline="always")
def _containing_cell(x, y, z, b, block_lo, block_dx, ncell, ndim):
    """Padded indices of the interior cell of block ``b`` containing (x, y, z)."""
    ix = min(max(int(math.floor((x - block_lo[b, 0]) / block_dx[b, 0])), 0), ncell[0] - 1) + GHOST
    iy = 0
    iz = 0
    if ndim > 1:
        iy = min(max(int(math.floor((y - block_lo[b, 1]) / block_dx[b, 1])), 0), ncell[1] - 1) + GHOST
    if ndim > 2:
        iz = min(max(int(math.floor((z - block_lo[b, 2]) / block_dx[b, 2])), 0), ncell[2] - 1) + GHOST
    return ix, iy, iz


# ---------------------------------------------------------------------------- kernels


@njit(cache=True, inline="always")
def _velocity_terms(arho, momentum, blk, k, ix, iy, iz, w, sx, sy, sz, ndim):
    """(W a u_x, W a u_y, W a u_z, W a) of cell (blk, ix, iy, iz) for material ``k``, u = m / rho
    with the velocity signs applied; zeros where a = arho_k <= 0."""
    a = arho[blk, k, ix, iy, iz]
    if a <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    rho = 0.0
    for j in range(arho.shape[1]):
        rho += arho[blk, j, ix, iy, iz]
    f = w * a / rho
    t0 = f * sx * momentum[blk, 0, ix, iy, iz]
    t1 = f * sy * momentum[blk, 1, ix, iy, iz] if ndim > 1 else 0.0
    t2 = f * sz * momentum[blk, 2, ix, iy, iz] if ndim > 2 else 0.0
    return t0, t1, t2, w * a


@njit(cache=True)
def _adaptive_velocity_sums(x, y, z, b, k, ndim, block_lo, block_dx, block_index, block_level, block_cells, codes,
                            cells, root, children, arho, momentum):
    """(sum W a u_x, sum W a u_y, sum W a u_z, sum W a) over the level-aware stencil of a point
    in block ``b``: the stencil of the block's level, dropped one level at a time while a corner
    of positive weight lies in a coarser leaf (a stencil of one level keeps multilinear
    interpolation exact for linear fields); a corner on a finer leaf adds its n^ndim cells,
    each with W / n^ndim (their mean stands for the coarser cell)."""
    lev = block_level[b]
    while True:
        i0, fx, j0, fy, k0, fz = _stencil_base(x, y, z, b, lev, ndim, block_lo, block_dx, block_index,
                                                block_level, block_cells)
        num0 = 0.0
        num1 = 0.0
        num2 = 0.0
        den = 0.0
        complete = True
        for c in range(1 << ndim):
            blk, ix, iy, iz, n, w, sx, sy, sz = _corner(c, b, lev, i0, j0, k0, fx, fy, fz, ndim, codes, cells,
                                                        block_index, block_level, block_cells, root, children)
            if w <= 0.0:
                continue
            if blk < 0:
                complete = False
                break
            share = w / n**ndim
            for p in range(n):
                for q in range(n if ndim > 1 else 1):
                    for r in range(n if ndim > 2 else 1):
                        t0, t1, t2, td = _velocity_terms(arho, momentum, blk, k, ix + p, iy + q, iz + r, share, sx,
                                                         sy, sz, ndim)
                        num0 += t0
                        num1 += t1
                        num2 += t2
                        den += td
        if complete:
            return num0, num1, num2, den
        lev -= 1


@njit(cache=True, parallel=True)
def _sample_velocity(position, sign, material, skip, block, block_lo, block_dx, block_index, block_level,
                     block_cells, ncell, ndim, codes, cells, root, children, arho, momentum, out):
    """Partial-density-weighted multilinear velocity (m/s) at each point, into ``out[N, 3]``.

    v = sum_c W_c a_c (m_c / rho_c) / sum_c W_c a_c with a_c the partial density of the
    point's material, over the cell-centred stencil of the owning block's level.  When a
    corner of positive weight is not a single cell of that level (it lies in a finer or a
    coarser leaf) the sums come from :func:`_adaptive_velocity_sums`.  The containing cell's
    velocity when the denominator vanishes.  Momentum components beyond ``ndim`` are zero by
    the state's contract and not read.  Component d is multiplied by ``sign[t, d]`` (-1 for
    a point folded through a reflecting face).  Skipped points are left unchanged.
    """
    nmat = arho.shape[1]
    for t in prange(position.shape[0]):
        if skip[t]:
            continue
        b = block[t]
        k = material[t]
        x, y, z = position[t, 0], position[t, 1], position[t, 2]
        lev = block_level[b]
        i0, fx, j0, fy, k0, fz = _stencil_base(x, y, z, b, lev, ndim, block_lo, block_dx, block_index,
                                                block_level, block_cells)
        num0 = 0.0
        num1 = 0.0
        num2 = 0.0
        den = 0.0
        for c in range(1 << ndim):
            blk, ix, iy, iz, n, w, sx, sy, sz = _corner(c, b, lev, i0, j0, k0, fx, fy, fz, ndim, codes, cells,
                                                        block_index, block_level, block_cells, root, children)
            if w <= 0.0:
                continue
            if n != 1:
                num0, num1, num2, den = _adaptive_velocity_sums(x, y, z, b, k, ndim, block_lo, block_dx, block_index,
                                                                block_level, block_cells, codes, cells, root, children,
                                                                arho, momentum)
                break
            t0, t1, t2, td = _velocity_terms(arho, momentum, blk, k, ix, iy, iz, w, sx, sy, sz, ndim)
            num0 += t0
            num1 += t1
            num2 += t2
            den += td
        if den > 0.0:
            v0, v1, v2 = num0 / den, num1 / den, num2 / den
        else:
            ix, iy, iz = _containing_cell(x, y, z, b, block_lo, block_dx, ncell, ndim)
            rho = 0.0
            for j in range(nmat):
                rho += arho[b, j, ix, iy, iz]
            if rho > 0.0:
                v0 = momentum[b, 0, ix, iy, iz] / rho
                v1 = momentum[b, 1, ix, iy, iz] / rho if ndim > 1 else 0.0
                v2 = momentum[b, 2, ix, iy, iz] / rho if ndim > 2 else 0.0
            else:
                v0 = v1 = v2 = 0.0
        out[t, 0] = sign[t, 0] * v0
        out[t, 1] = sign[t, 1] * v1
        out[t, 2] = sign[t, 2] * v2


@njit(cache=True)
def _adaptive_best_cell(x, y, z, b, k, ndim, block_lo, block_dx, block_index, block_level, block_cells, codes, cells,
                        root, children, alpha, arho):
    """(block, padded ix, iy, iz) of the cell with the largest W alpha_k rho_k (alpha_k > ALPHA_MIN)
    over the level-aware stencil of :func:`_adaptive_velocity_sums` (block -1: none)."""
    lev = block_level[b]
    while True:
        i0, fx, j0, fy, k0, fz = _stencil_base(x, y, z, b, lev, ndim, block_lo, block_dx, block_index,
                                                block_level, block_cells)
        best = 0.0
        cb, cx, cy, cz = -1, 0, 0, 0
        complete = True
        for c in range(1 << ndim):
            blk, ix, iy, iz, n, w, _, _, _ = _corner(c, b, lev, i0, j0, k0, fx, fy, fz, ndim, codes, cells,
                                                     block_index, block_level, block_cells, root, children)
            if w <= 0.0:
                continue
            if blk < 0:
                complete = False
                break
            share = w / n**ndim
            for p in range(n):
                for q in range(n if ndim > 1 else 1):
                    for r in range(n if ndim > 2 else 1):
                        score = share * arho[blk, k, ix + p, iy + q, iz + r]
                        if alpha[blk, k, ix + p, iy + q, iz + r] > ALPHA_MIN and score > best:
                            best = score
                            cb, cx, cy, cz = blk, ix + p, iy + q, iz + r
        if complete:
            return cb, cx, cy, cz
        lev -= 1


@njit(cache=True, parallel=True)
def _record_peaks(position, material, skip, block, unrecorded_only, time, block_lo, block_dx, block_index,
                  block_level, block_cells, ncell, ndim, codes, cells, root, children, alpha, arho, arhoe, eos_kind,
                  eos_params, eos_table, peak_pressure, peak_pressure_time, peak_temperature):
    """Update the running peak pressure (Pa, with its time in s) and peak temperature (K).

    The tracer's cell is the containing cell when it holds the tracer's material
    (alpha_k > ALPHA_MIN), else the stencil cell with the largest W_c alpha_k rho_k (the
    stencil of :func:`_sample_velocity`; :func:`_adaptive_best_cell` where it spans levels);
    none (material absent from the stencil) means no record this time.  There
    rho_k = arho_k / alpha_k, e_k = arhoe_k / arho_k, p_k = P_k(rho_k, e_k), T_k = T_k(rho_k, e_k).
    With ``unrecorded_only`` only tracers without a record yet (NaN peak time) are sampled.
    Returns the number of tracers on the mesh still without a record.
    """
    missing = 0
    for t in prange(position.shape[0]):
        if skip[t] or (unrecorded_only and not math.isnan(peak_pressure_time[t])):
            continue
        b = block[t]
        k = material[t]
        x, y, z = position[t, 0], position[t, 1], position[t, 2]
        cb = b
        cx, cy, cz = _containing_cell(x, y, z, b, block_lo, block_dx, ncell, ndim)
        if not (alpha[cb, k, cx, cy, cz] > ALPHA_MIN and arho[cb, k, cx, cy, cz] > 0.0):
            lev = block_level[b]
            i0, fx, j0, fy, k0, fz = _stencil_base(x, y, z, b, lev, ndim, block_lo, block_dx, block_index,
                                                    block_level, block_cells)
            best = 0.0
            cb = -1
            for c in range(1 << ndim):
                blk, ix, iy, iz, n, w, _, _, _ = _corner(c, b, lev, i0, j0, k0, fx, fy, fz, ndim, codes, cells,
                                                         block_index, block_level, block_cells, root, children)
                if w <= 0.0:
                    continue
                if n != 1:
                    cb, cx, cy, cz = _adaptive_best_cell(x, y, z, b, k, ndim, block_lo, block_dx, block_index,
                                                         block_level, block_cells, codes, cells, root, children,
                                                         alpha, arho)
                    break
                score = w * arho[blk, k, ix, iy, iz]
                if alpha[blk, k, ix, iy, iz] > ALPHA_MIN and score > best:
                    best = score
                    cb, cx, cy, cz = blk, ix, iy, iz
            if cb < 0:
                if math.isnan(peak_pressure_time[t]):
                    missing += 1
                continue
        a = alpha[cb, k, cx, cy, cz]
        ar = arho[cb, k, cx, cy, cz]
        rho = ar / a
        e = arhoe[cb, k, cx, cy, cz] / ar
        p, c2, flag = pressure_sound_speed(eos_kind[k], eos_params[k], eos_table, rho, e)
        temp = temperature(eos_kind[k], eos_params[k], eos_table, rho, e)
        if math.isfinite(p) and not p <= peak_pressure[t]:
            peak_pressure[t] = p
            peak_pressure_time[t] = time
        if math.isfinite(temp) and not temp <= peak_temperature[t]:
            peak_temperature[t] = temp
        if math.isnan(peak_pressure_time[t]):
            missing += 1
    return missing


@njit(cache=True, parallel=True)
def _fold(position, velocity, dt, skip, domain_lo, domain_hi, codes, ndim, out, sign):
    """Points x = position + dt velocity (m) mapped into the domain for sampling, into ``out[N, 3]``
    with velocity signs ``sign[N, 3]``.

    dt > 0 gives the Heun predictor x* = x_n + dt v_n(x_n); dt = 0 the positions themselves.
    Per used axis: periodic wraps, reflecting mirrors (x -> 2 x_face - x, sign -1),
    outflow clamps to the face.  Points inside are copied with sign +1.
    """
    for t in prange(position.shape[0]):
        if skip[t]:
            continue
        for d in range(3):
            x = position[t, d] + dt * velocity[t, d]
            s = 1.0
            if d < ndim:
                lo = domain_lo[d]
                hi = domain_hi[d]
                if x < lo or x > hi:
                    side = 0 if x < lo else 1
                    code = codes[d, side]
                    if code == PERIODIC:
                        length = hi - lo
                        x = x - length * math.floor((x - lo) / length)
                        if x >= hi:
                            x = lo
                    elif code == REFLECTING:
                        x = 2.0 * (lo if side == 0 else hi) - x
                        s = -1.0
                    if x < lo:
                        x = lo
                    elif x > hi:
                        x = hi
            out[t, d] = x
            sign[t, d] = s


@njit(cache=True, parallel=True)
def _correct(position, v_start, v_end, exited, dt, t_start, domain_lo, domain_hi, codes, ndim, cylindrical,
             velocity, exit_time):
    """Heun corrector and domain faces, in place.

    Tracers on the mesh: x_{n+1} = x_n + dt (v_start + v_end) / 2, velocity = (v_start +
    v_end) / 2; then periodic wrap, reflecting mirror (normal velocity negated) or, past an
    outflow face, exit at t_start + dt (x_face - x_n) / (x_{n+1} - x_n) (earliest face).
    Exited tracers move ballistically, x += dt velocity; in 2d-cylindrical r < 0 is mirrored.
    """
    for t in prange(position.shape[0]):
        if exited[t]:
            for d in range(3):
                position[t, d] += dt * velocity[t, d]
            if cylindrical and position[t, 0] < 0.0:
                position[t, 0] = -position[t, 0]
                velocity[t, 0] = -velocity[t, 0]
            continue
        frac = 2.0
        for d in range(3):
            x0 = position[t, d]
            v = 0.5 * (v_start[t, d] + v_end[t, d])
            x = x0 + dt * v
            if d < ndim:
                lo = domain_lo[d]
                hi = domain_hi[d]
                if x < lo or x > hi:
                    side = 0 if x < lo else 1
                    face = lo if side == 0 else hi
                    code = codes[d, side]
                    if code == PERIODIC:
                        x += (hi - lo) if side == 0 else lo - hi
                    elif code == REFLECTING:
                        x = min(max(2.0 * face - x, lo), hi)
                        v = -v
                    else:
                        frac = min(frac, (face - x0) / (x - x0))
                elif x == hi and codes[d, 1] == PERIODIC:
                    x = lo
            position[t, d] = x
            velocity[t, d] = v
        if frac <= 1.0:
            exited[t] = True
            exit_time[t] = t_start + frac * dt


# ---------------------------------------------------------------------------- tracers


def _as_positions(positions) -> np.ndarray:
    """(N, 3) float64 copy of (N, ndim) positions, unused components 0."""
    pos = np.asarray(positions, dtype=float)
    if pos.ndim != 2 or not 1 <= pos.shape[1] <= 3:
        raise ValueError(f"positions must have shape (N, 1..3), got {pos.shape}")
    out = np.zeros((pos.shape[0], 3))
    out[:, : pos.shape[1]] = pos
    return out


class Tracers:
    """Massless Lagrangian tracers driven by a :class:`~impactpipe.hydro.solver.Simulation`.

    Pass to the Simulation (``Simulation(..., tracers=tracers)`` or ``sim.tracers = tracers``
    before the first step); it calls :meth:`before_step`, :meth:`after_step`,
    :meth:`restore_good` and :meth:`save`.  Method and equations: module docstring.

    Args:
        positions: (N, 3) (or (N, ndim)) initial positions (m), mesh coordinates.
        materials: (N,) material index of each tracer.
        ids: (N,) int64 ids (default 1..N).
        history_interval: simulated seconds between trajectory samples, or None (no history).
        end_time: expected end time (s), used to preallocate the history.

    Attributes: the :class:`~impactpipe.hydro.snapshot.TracerSet` fields (``id``,
    ``material``, ``initial_position``, ``position``, ``velocity``, ``peak_pressure``,
    ``peak_pressure_time``, ``peak_temperature``, ``exited``, ``exit_time``), updated in place.
    """

    def __init__(self, positions, materials, ids=None, history_interval: float | None = None,
                 end_time: float | None = None):
        pos = _as_positions(positions)
        n = pos.shape[0]
        if not np.isfinite(pos).all():
            raise ValueError("tracer positions must be finite")
        mat = np.asarray(materials, dtype=np.int64).reshape(-1)
        if mat.shape != (n,) or (mat < 0).any():
            raise ValueError("materials must be N non-negative material indices")
        self.id = np.arange(1, n + 1, dtype=np.int64) if ids is None else np.asarray(ids, dtype=np.int64).copy()
        if self.id.shape != (n,) or np.unique(self.id).size != n:
            raise ValueError("ids must be N unique integers")
        self.material = mat.copy()
        self.initial_position = pos.copy()
        self.position = pos.copy()
        self.velocity = np.zeros((n, 3))
        self.peak_pressure = np.full(n, np.nan)
        self.peak_pressure_time = np.full(n, np.nan)
        self.peak_temperature = np.full(n, np.nan)
        self.exited = np.zeros(n, dtype=np.bool_)
        self.exit_time = np.full(n, np.nan)
        if history_interval is not None and not history_interval > 0.0:
            raise ValueError(f"history_interval must be > 0 s, got {history_interval}")
        self.history_interval = None if history_interval is None else float(history_interval)
        self.history_count = 0
        self.history_next = 0.0
        capacity = HISTORY_CHUNK
        if self.history_interval is not None and end_time is not None:
            capacity = int(end_time // self.history_interval) + 2
        self._allocate_history(capacity if self.history_interval is not None else 0)
        # scratch (no allocation per step)
        self._v_start = np.zeros((n, 3))
        self._v_end = np.zeros((n, 3))
        self._trial = np.zeros((n, 3))
        self._sign = np.ones((n, 3))
        self._block = np.full(n, -1, dtype=np.int64)
        self._t_start = 0.0
        self._missing = n  # tracers on the mesh without a peak record (a hint: recounted by each record)
        self._good = {name: getattr(self, name).copy() for name in self._MUTABLE}
        self._good_counts = (0, 0.0, n)
        self._mesh = None
        self._nmat = None

    #: Arrays that a step changes (kept at the start of each step for :meth:`restore_good`).
    _MUTABLE = ("position", "velocity", "peak_pressure", "peak_pressure_time", "peak_temperature", "exited",
                "exit_time")

    def __len__(self) -> int:
        return int(self.id.shape[0])

    def _allocate_history(self, capacity: int) -> None:
        self.history_time = np.zeros(capacity)
        self.history_position = np.zeros((capacity, len(self), 3))

    # ------------------------------------------------------------------ mesh binding

    def _bind(self, mesh: BlockMesh, nmat: int) -> None:
        """Follow ``mesh`` unless it is the bound one; check the material indices against ``nmat``."""
        if mesh is not self._mesh:
            self.mesh_changed(mesh)
        if nmat != self._nmat:
            if (self.material >= nmat).any():
                raise ValueError(f"tracer material index >= number of materials ({nmat})")
            self._nmat = nmat

    def mesh_changed(self, mesh: BlockMesh) -> None:
        """Bind to a new mesh (the Simulation calls this after every regrid, which renumbers the
        blocks): check the positions against it, rebuild the block lookup (:class:`BlockLocator`)
        and re-find the owning block of every tracer on the mesh.  Positions and records stay."""
        ndim = mesh.ndim
        if mesh.block_level.max(initial=0) > 0 and mesh.block_cells % 4:
            raise ValueError(f"tracers on a refined mesh need block_cells divisible by 4, got {mesh.block_cells}")
        on = ~self.exited
        if np.any(self.position[on, ndim:] != 0.0):
            raise ValueError(f"{mesh.geometry}: tracer position components beyond axis {ndim} must be 0")
        lo, hi = mesh.domain_lo[:ndim], mesh.domain_hi[:ndim]
        outside = on & ((self.position[:, :ndim] < lo) | (self.position[:, :ndim] > hi)).any(axis=1)
        if outside.any():
            raise ValueError(f"{int(outside.sum())} tracers on the mesh lie outside the domain")
        codes = np.full((3, 2), REFLECTING, dtype=np.int64)
        kinds = {"periodic": PERIODIC, "reflecting": REFLECTING, "outflow": OUTFLOW}
        for d, pair in enumerate(mesh.boundaries):
            codes[d] = [kinds[pair[0]], kinds[pair[1]]]
        self._codes = codes
        self._ncell = np.asarray(mesh.interior_shape, dtype=np.int64)
        self._cells = np.asarray(mesh.blocks_per_axis, dtype=np.int64) * mesh.block_cells
        self._locate = BlockLocator(mesh)
        self._mesh = mesh
        self._locate(self.position, self.exited, self._block)

    @property
    def owning_block(self) -> np.ndarray:
        """(N,) index of the block holding each tracer on the bound mesh (-1 once exited), as found
        by the last step or :meth:`mesh_changed` (a copy)."""
        return self._block.copy()

    def _sample(self, sim, dt: float, out: np.ndarray) -> None:
        """Sample the velocity at x_n + dt v_n (folded into the domain, into ``self._trial``; blocks
        into ``self._block``) into ``out``."""
        mesh = sim.mesh
        loc = self._locate
        _fold(self.position, self._v_start, dt, self.exited, mesh.domain_lo, mesh.domain_hi, self._codes,
              mesh.ndim, self._trial, self._sign)
        loc(self._trial, self.exited, self._block)
        _sample_velocity(self._trial, self._sign, self.material, self.exited, self._block, mesh.block_lo,
                         mesh.block_dx, mesh.block_index, mesh.block_level, mesh.block_cells, self._ncell, mesh.ndim,
                         self._codes, self._cells, loc.root, loc.children, sim.state.arho, sim.state.momentum, out)

    def _record(self, sim, unrecorded_only: bool) -> None:
        """Peak pressure / temperature at the current positions (``self._block`` must be current)."""
        mesh = sim.mesh
        st = sim.state
        eos = sim.eos
        loc = self._locate
        self._missing = _record_peaks(self.position, self.material, self.exited, self._block, unrecorded_only,
                                      sim.time, mesh.block_lo, mesh.block_dx, mesh.block_index, mesh.block_level,
                                      mesh.block_cells, self._ncell, mesh.ndim, self._codes, self._cells, loc.root,
                                      loc.children, st.alpha, st.arho, st.arhoe, eos.kind, eos.params, eos.table,
                                      self.peak_pressure, self.peak_pressure_time, self.peak_temperature)

    def _sample_history(self, time: float) -> None:
        if self.history_count == self.history_time.shape[0]:
            old_t, old_x = self.history_time, self.history_position
            self._allocate_history(max(2 * old_t.shape[0], HISTORY_CHUNK))
            self.history_time[: old_t.shape[0]] = old_t
            self.history_position[: old_t.shape[0]] = old_x
        self.history_time[self.history_count] = time
        self.history_position[self.history_count] = self.position
        self.history_count += 1
        self.history_next = (math.floor(time / self.history_interval) + 1.0) * self.history_interval

    # ------------------------------------------------------------------ Simulation hooks

    def before_step(self, sim) -> None:
        """Keep the records for :meth:`restore_good` and sample v_n(x_n) from ``sim.state`` at t_n."""
        self._bind(sim.mesh, sim.state.nmat)
        for name in self._MUTABLE:
            np.copyto(self._good[name], getattr(self, name))
        self._good_counts = (self.history_count, self.history_next, self._missing)
        self._t_start = sim.time
        self._sample(sim, 0.0, self._v_start)
        if self._missing:
            self._record(sim, unrecorded_only=True)  # self._block holds the blocks of the positions
        if self.history_interval is not None and self.history_count == 0:
            self._sample_history(sim.time)

    def after_step(self, sim, dt: float) -> None:
        """Heun step over ``dt`` (s) with the field after the sweeps; faces, exits and peak records."""
        mesh = sim.mesh
        self._sample(sim, dt, self._v_end)
        _correct(self.position, self._v_start, self._v_end, self.exited, dt, self._t_start, mesh.domain_lo,
                 mesh.domain_hi, self._codes, mesh.ndim, mesh.geometry == "2d-cylindrical", self.velocity,
                 self.exit_time)
        self._locate(self.position, self.exited, self._block)
        self._record(sim, unrecorded_only=False)
        if self.history_interval is not None and sim.time >= self.history_next * (1.0 - 1e-12):
            self._sample_history(sim.time)

    def restore_good(self) -> None:
        """Put back the records from the start of the last step (after a failed step)."""
        for name in self._MUTABLE:
            np.copyto(getattr(self, name), self._good[name])
        self.history_count, self.history_next, self._missing = self._good_counts

    # ------------------------------------------------------------------ output and checkpoints

    @property
    def history(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(times (K,) s, positions (K, N, 3) m) of the trajectory samples, or None without history."""
        if self.history_interval is None:
            return None
        k = self.history_count
        return self.history_time[:k].copy(), self.history_position[:k].copy()

    def to_tracer_set(self) -> TracerSet:
        """The records as a :class:`~impactpipe.hydro.snapshot.TracerSet` (copies)."""
        return TracerSet(**{name: getattr(self, name).copy() for name in TRACER_UNITS})

    def save(self, group) -> None:
        """Write everything needed to continue bit for bit into an (empty) h5py group."""
        for name, (units, description) in TRACER_UNITS.items():
            write_dataset(group, name, getattr(self, name), units, description)
        group.attrs["history_interval"] = np.nan if self.history_interval is None else self.history_interval
        group.attrs["history_count"] = self.history_count
        group.attrs["history_next"] = self.history_next
        group.attrs["history_capacity"] = self.history_time.shape[0]
        if self.history_interval is not None:
            k = self.history_count
            write_dataset(group, "history_time", self.history_time[:k], *HISTORY_UNITS["history_time"])
            write_dataset(group, "history_position", self.history_position[:k], *HISTORY_UNITS["history_position"])

    @classmethod
    def load(cls, group) -> "Tracers":
        """Rebuild the tracers written by :meth:`save`."""
        interval = float(group.attrs["history_interval"])
        tracers = cls(group["initial_position"][()], group["material"][()], ids=group["id"][()],
                      history_interval=None if math.isnan(interval) else interval)
        for name in Tracers._MUTABLE:
            np.copyto(getattr(tracers, name), group[name][()])
        if tracers.history_interval is not None:
            k = int(group.attrs["history_count"])
            tracers._allocate_history(int(group.attrs["history_capacity"]))
            tracers.history_time[:k] = group["history_time"][()]
            tracers.history_position[:k] = group["history_position"][()]
            tracers.history_count = k
            tracers.history_next = float(group.attrs["history_next"])
        return tracers


def interpolate_velocity(sim, positions, materials) -> np.ndarray:
    """(N, 3) tracer velocity (m/s) at ``positions`` (inside the domain) for tracers of ``materials``,
    from the current state of ``sim`` (the field a tracer sees; module docstring)."""
    probe = Tracers(positions, materials)
    probe._bind(sim.mesh, sim.state.nmat)
    out = np.zeros((len(probe), 3))
    probe._sample(sim, 0.0, out)
    return out


# ---------------------------------------------------------------------------- placement


def place_on_rays(impact_point, target_radius: float, target_center_z: float, n_rays: int = 30,
                  count: int = 900, projectile_radius: float | None = None,
                  projectile_center_z: float | None = None, projectile_cells: int = 4):
    """Tracers for a head-on 2d-cylindrical impact: rays through the target plus a projectile grid.

    Target (material 0): ``n_rays`` rays leave the impact point (r = 0, z_i) on the axis,
    at angles theta_i = (i + 1/2) pi / (2 n_rays), i = 0..n_rays-1, from the direction
    pointing at the target centre (0, z_c) towards +r.  Ray i carries m = count / n_rays
    tracers at distances s_j = (j + 1/2) L_i / m, j = 0..m-1, with L_i the chord to the far
    surface, L = |h| cos theta + sqrt(R^2 - h^2 sin^2 theta), h = z_i - z_c (2 R cos theta
    for an impact point on the surface).  Positions (s sin theta, z_i - sign(h) s cos theta, 0);
    equal numbers per ray put more tracers near the impact point, where the peak pressure
    falls fastest.  The impact point must lie on the axis inside or on the target (|h| <= R);
    with z_i = z_c the rays point to -z.

    Projectile (material 1, when ``projectile_radius`` is given): cell-centred points of a
    square grid of spacing R_p / ``projectile_cells`` in the half-disk r > 0 of the projectile
    centred at (0, ``projectile_center_z``).

    Returns (positions (N, 3) m, materials (N,) int64).
    """
    r_i, z_i = (float(v) for v in impact_point)
    radius = float(target_radius)
    h = z_i - float(target_center_z)
    if r_i != 0.0:
        raise ValueError("place_on_rays: the impact point must be on the symmetry axis (r = 0)")
    if abs(h) > radius:
        raise ValueError("place_on_rays: the impact point lies outside the target")
    if n_rays < 1 or count < n_rays or count % n_rays:
        raise ValueError(f"count ({count}) must be a positive multiple of n_rays ({n_rays})")
    per_ray = count // n_rays
    toward = -1.0 if h >= 0.0 else 1.0
    theta = (np.arange(n_rays) + 0.5) * (0.5 * np.pi / n_rays)
    chord = abs(h) * np.cos(theta) + np.sqrt(radius**2 - h**2 * np.sin(theta) ** 2)
    s = (np.arange(per_ray) + 0.5)[None, :] / per_ray * chord[:, None]
    pos = np.zeros((count, 3))
    pos[:, 0] = (s * np.sin(theta)[:, None]).ravel()
    pos[:, 1] = (z_i + toward * s * np.cos(theta)[:, None]).ravel()
    mats = np.zeros(count, dtype=np.int64)
    if projectile_radius is None:
        return pos, mats
    if projectile_center_z is None:
        raise ValueError("place_on_rays: projectile_center_z is needed with projectile_radius")
    n = int(projectile_cells)
    step = float(projectile_radius) / n
    r = (np.arange(n) + 0.5) * step
    z = float(projectile_center_z) + (np.arange(2 * n) + 0.5 - n) * step
    rr, zz = np.meshgrid(r, z, indexing="ij")
    keep = rr**2 + (zz - float(projectile_center_z)) ** 2 < float(projectile_radius) ** 2
    proj = np.zeros((int(keep.sum()), 3))
    proj[:, 0] = rr[keep]
    proj[:, 1] = zz[keep]
    return np.concatenate([pos, proj]), np.concatenate([mats, np.ones(proj.shape[0], dtype=np.int64)])


def _ball_lattice(center, radius: float, spacing: float) -> np.ndarray:
    """Cell-centred lattice points of ``spacing`` (m) strictly inside the ball (disk) of ``radius``."""
    center = np.asarray(center, dtype=float)
    n = int(math.ceil(radius / spacing))
    axis = (np.arange(2 * n) + 0.5 - n) * spacing
    grid = np.stack(np.meshgrid(*([axis] * center.size), indexing="ij"), axis=-1).reshape(-1, center.size)
    return center + grid[(grid**2).sum(axis=1) < radius**2]


def place_on_grid(target_center, target_radius: float, projectile_center, projectile_radius: float,
                  spacing: float, projectile_spacing: float | None = None):
    """Tracers on uniform grids filling the target (material 0) and the projectile (material 1).

    For 3d (centres with 3 components; 2 components give a 2d-planar layout).  Each body
    gets the cell-centred points c + (i + 1/2 - n) h (per axis, n = ceil(R / h)) inside its
    sphere, h = ``spacing`` for the target and ``projectile_spacing`` (default
    min(spacing, R_p / 4)) for the projectile, so a small projectile still carries tracers.

    Returns (positions (N, 3) m, materials (N,) int64).
    """
    if spacing <= 0.0:
        raise ValueError("spacing must be > 0")
    h_p = min(spacing, projectile_radius / 4.0) if projectile_spacing is None else float(projectile_spacing)
    target = _ball_lattice(target_center, float(target_radius), float(spacing))
    proj = _ball_lattice(projectile_center, float(projectile_radius), h_p)
    pos = _as_positions(np.concatenate([target, proj]))
    mats = np.concatenate([np.zeros(len(target), dtype=np.int64), np.ones(len(proj), dtype=np.int64)])
    return pos, mats
