"""Which rank advances which blocks, and which cells the ranks exchange before a ghost fill.

Rank r owns the blocks ``cuts[r] .. cuts[r + 1] - 1`` of the mesh's block order (a Morton
curve, :func:`impactpipe.hydro.mesh.blocks.morton_keys`).  The cuts balance an estimated cost
per block (:func:`block_costs`), weights measured by ``benchmarks/block_costs.py`` on the 2D
impact (docs/performance.md, "Several MPI ranks"): a void cell costs about a third of a cell
holding material (the sweep skips the Riemann solver and the EOS in void, but still moves
through it), and a block holding both, where the interfaces and free surfaces are, costs
about as much again per cell.

Exchange plan: a ghost slab of block b along axis d copies the ``GHOST`` interior cells of
its neighbour next to the shared face (:mod:`impactpipe.hydro.mesh.boundary`).  Where the
neighbour belongs to another rank, its owner sends that strip (the neighbour's interior
cells within ``GHOST`` of the face, over the interior of the other axes) before the fill.
The plan lists, per axis and per peer rank, the strips in one deterministic order (by block,
then low face before high face), computed with numpy from the mesh alone, the same on every
rank.  A derived field's fills along every axis (the stress step's work arrays) send the
strips of every axis to a peer in one message (:func:`every_axis_routes`): the strips are
interior cells, which no ghost fill writes, so the axes' fills do not wait for each other.

Tracers' neighbourhood: a tracer's velocity and peak-pressure stencil around a point in block
b reads interior cells of b and of the blocks beside it across faces, edges and corners, at
most :data:`TRACER_REACH` cells from b (the multilinear stencil's corner cells lie within one
cell of the point, docs/hydro.md "Tracers").  :func:`neighbourhood_routes` lists, per peer
rank, the interior cells of the peer's blocks within that reach of this rank's blocks, and
of this rank's blocks within the reach of the peer's, in one order (by block, then cell).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from impactpipe.hydro.amr.plans import axis_plans
from impactpipe.hydro.scheme.timestep import PHI_VOID

#: Cells beyond a block's faces, edges and corners that the stencil of a tracer in the block reads.
TRACER_REACH = 1
#: Cost of a step of a cell holding material / of a void cell / added per cell of a block that
#: holds both (units of 10 ns: benchmarks/block_costs.py measured 200, 70 and 330 ns per
#: cell-update of full, void and mixed blocks of the 2D impact on one core, 510, 171 and 544
#: with strength).
MATERIAL_CELL_COST = 20
VOID_CELL_COST = 7
MIXED_BLOCK_CELL_COST = 20


def block_costs(mesh, alpha: np.ndarray) -> np.ndarray:
    """(B,) int64 estimated cost per block from the volume fractions ``alpha`` (B, M, NX, NY, NZ) of
    B blocks of ``mesh`` (all of them, or a range):
    :data:`MATERIAL_CELL_COST` per interior cell whose summed volume fraction is >= PHI_VOID,
    :data:`VOID_CELL_COST` per other interior cell, and :data:`MIXED_BLOCK_CELL_COST` per cell
    of a block that has both."""
    phi = mesh.interior(alpha).sum(axis=1).reshape(alpha.shape[0], -1)
    cells = phi.shape[1]
    material = (phi >= PHI_VOID).sum(axis=1).astype(np.int64)
    mixed = (material > 0) & (material < cells)
    return MATERIAL_CELL_COST * material + VOID_CELL_COST * (cells - material) + MIXED_BLOCK_CELL_COST * cells * mixed


def owned_ranges(costs: np.ndarray, nranks: int) -> np.ndarray:
    """(nranks + 1,) cut points: rank r owns blocks ``cuts[r] .. cuts[r + 1] - 1``.

    Each cut is the block boundary whose summed cost lies nearest to r / nranks of the total
    (exact integer arithmetic, ties to the lower boundary), so every range's cost is within
    one block's cost of the mean; every rank owns at least one block.  Raises ValueError
    when there are more ranks than blocks.
    """
    costs = np.asarray(costs, dtype=np.int64)
    nblocks = len(costs)
    if nranks > nblocks:
        raise ValueError(f"{nranks} MPI ranks but the mesh has only {nblocks} blocks: every rank needs at "
                         f"least one block (fewer ranks, or smaller hydro.block_cells)")
    scaled = np.concatenate([[0], np.cumsum(costs)]) * nranks
    total = int(scaled[-1]) // nranks
    cuts = [0]
    for r in range(1, nranks):
        target = total * r
        i = int(np.searchsorted(scaled, target, side="left"))
        if i > 0 and target - scaled[i - 1] <= scaled[i] - target:
            i -= 1
        cuts.append(min(max(i, cuts[-1] + 1), nblocks - (nranks - r)))
    cuts.append(nblocks)
    return np.array(cuts, dtype=np.int64)


@dataclass(frozen=True)
class Strips:
    """Interior strips of blocks as cells: ``blocks[i]`` and the flat padded cell index
    ``cells[i]`` (ix * NY * NZ + iy * NZ + iz), in exchange order."""

    blocks: np.ndarray
    cells: np.ndarray

    def indices(self, values: np.ndarray, runs: tuple[slice, ...] = (slice(None),)) -> np.ndarray:
        """Flat indices into ``values.reshape(-1)`` (a field (NB, C, NX, NY, NZ)) of every cell of
        the strips, for each component of the ``runs`` (slices of C, one after another) in turn:
        (ncomponents, ncells) raveled.  Computed anew on each call: an exchange plan
        (:class:`~impactpipe.hydro.parallel.exchange.StripPlan`) takes them once per call site."""
        ncomp = values.shape[1]
        per_block = int(np.prod(values.shape[2:]))
        base = self.blocks * (ncomp * per_block) + self.cells
        chosen = np.concatenate([np.arange(*bounds) for bounds in run_bounds(runs, ncomp)])
        return (base[None, :] + (chosen * per_block)[:, None]).ravel()

    def values(self, values: np.ndarray, runs: tuple[slice, ...] = (slice(None),)) -> int:
        """Number of values of the components of the ``runs`` of the field ``values`` the strips hold."""
        return sum(len(range(*bounds)) for bounds in run_bounds(runs, values.shape[1])) * len(self.cells)


def run_bounds(runs: tuple[slice, ...], ncomponents: int) -> tuple[tuple[int, int, int], ...]:
    """(start, stop, step) of each slice of ``runs`` over ``ncomponents`` components (a hashable key)."""
    return tuple(run.indices(ncomponents) for run in runs)


@dataclass(frozen=True)
class Route:
    """What one rank exchanges with one peer before a ghost fill along one axis."""

    peer: int
    send: Strips
    receive: Strips


def owners(cuts: np.ndarray) -> np.ndarray:
    """(NB,) the rank that owns each block."""
    return np.repeat(np.arange(len(cuts) - 1), np.diff(cuts))


def exchange_routes(mesh, cuts: np.ndarray, rank: int) -> list[list[Route]]:
    """Per axis (0, 1, 2) the routes of ``rank``, by peer rank (empty on unused axes)."""
    owner = owners(cuts)
    routes: list[list[Route]] = []
    for axis in range(3):
        if mesh.ghost[axis] == 0:
            routes.append([])
            continue
        strips = _face_strips(mesh, axis, owner)
        peers = sorted({q for (s, q) in strips if s == rank} | {s for (s, q) in strips if q == rank})
        routes.append([Route(q, _strips(mesh, axis, strips.get((rank, q), [])),
                             _strips(mesh, axis, strips.get((q, rank), []))) for q in peers])
    return routes


def every_axis_routes(routes: list[list[Route]]) -> list[Route]:
    """Lists of routes by peer (those of :func:`exchange_routes`, per axis, or of other exchanges
    before a fill) joined into one route per peer rank: its cells of every list, list after
    list (each list's in its own order).  A fill of a field along every axis whose strips are
    interior cells (none a ghost that another axis's fill writes) sends them in one message per
    peer; a cell beside faces along two axes is sent once per face, a cell in two lists once
    per list."""
    peers = sorted({route.peer for axis_routes in routes for route in axis_routes})
    joined = []
    for peer in peers:
        mine = [route for axis_routes in routes for route in axis_routes if route.peer == peer]
        joined.append(Route(peer, joined_strips([route.send for route in mine]),
                            joined_strips([route.receive for route in mine])))
    return joined


def joined_strips(parts: list[Strips]) -> Strips:
    """The cells of the strips ``parts``, one after another."""
    return Strips(np.concatenate([part.blocks for part in parts]), np.concatenate([part.cells for part in parts]))


def overlap_groups(mesh, cuts: np.ndarray, rank: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per axis (0, 1, 2): ``(inner, edge)``, the indices within ``rank``'s range of its blocks
    whose ghost slabs along the axis need no other rank's strips (inner), and of the rest (edge).

    While the strips of a ghost fill travel, the sweep can advance the inner blocks; the edge
    blocks wait for them (:meth:`~impactpipe.hydro.parallel.distributed.BlockRanges.start_ghosts`).
    On an adaptive mesh an edge block has another rank's block beside a face between blocks of
    one level, or it is the destination of a row of the axis's coarse/fine plans
    (:func:`impactpipe.hydro.amr.plans.axis_plans`: restriction, prolongation) whose source
    block another rank owns: those rows are applied after the strips arrive, and they read
    only the cells received and the edge blocks' own (the rows whose source this rank owns are
    applied before the inner blocks are swept).
    """
    lo, hi = int(cuts[rank]), int(cuts[rank + 1])
    local = np.arange(hi - lo, dtype=np.int64)
    groups = []
    for axis in range(3):
        if mesh.ghost[axis] == 0:
            groups.append((local[:0], local))
            continue
        remote = _filled_from_ranks(mesh, cuts, rank, [axis])
        groups.append((local[~remote], local[remote]))
    return groups


def _filled_from_ranks(mesh, cuts: np.ndarray, rank: int, axes: list[int]) -> np.ndarray:
    """(hi - lo,) bool for the blocks ``lo .. hi - 1`` of ``rank``: whether a ghost fill along one
    of the ``axes`` copies into block lo + i the cells of another rank's block: beside a face
    (between blocks of one level on an adaptive mesh), or by a row of the axis's restriction or
    prolongation (:func:`impactpipe.hydro.amr.plans.axis_plans`) whose source block another rank
    owns."""
    lo, hi = int(cuts[rank]), int(cuts[rank + 1])
    nbr = mesh.neighbor[lo:hi][:, axes, :]
    across = (nbr >= 0) & ((nbr < lo) | (nbr >= hi))
    if not mesh.adaptive:
        return across.any(axis=(1, 2))
    remote = (across & (mesh.neighbor_level[lo:hi][:, axes, :] == 0)).any(axis=(1, 2))
    owner = owners(cuts)
    for axis in axes:
        plans = axis_plans(mesh, axis)
        for name in ("restrict", "prolong"):
            rows = plans[name][(owner[plans[name][:, 0]] == rank) & (owner[plans[name][:, 4]] != rank)]
            remote[rows[:, 0] - lo] = True
    return remote


def field_overlap_groups(mesh, cuts: np.ndarray, rank: int) -> tuple[np.ndarray, np.ndarray]:
    """``(inner, edge)``: the blocks of ``rank`` (block numbers, int64) whose ghosts along every
    used axis a fill of a derived field completes from this rank's cells alone (inner), and the
    rest (edge).

    The stress step's kernels read the ghosts along every axis at once, filled by one ghost fill
    per axis: while the strips of those fills travel they can advance the inner blocks, the
    edge blocks after (:meth:`~impactpipe.hydro.strength.model.MaterialStrength.kick`).  On a
    uniform mesh an edge block has another rank's block beside one of its faces; on an adaptive
    mesh, beside a face between blocks of one level, or it is the destination of a row of a
    coarse/fine plan (:func:`impactpipe.hydro.amr.plans.axis_plans`: restriction, prolongation)
    whose source block another rank owns."""
    owned = np.arange(int(cuts[rank]), int(cuts[rank + 1]), dtype=np.int64)
    remote = _filled_from_ranks(mesh, cuts, rank, [axis for axis in range(3) if mesh.ghost[axis] > 0])
    return owned[~remote], owned[remote]


def _face_strips(mesh, axis: int, owner: np.ndarray) -> dict[tuple[int, int], list[tuple[int, int]]]:
    """(sender, receiver) -> [(block, side)]: the faces along ``axis`` whose neighbour another rank owns."""
    out: dict[tuple[int, int], list[tuple[int, int]]] = {}
    for block in range(mesh.nblocks):
        for side in range(2):
            nbr = int(mesh.neighbor[block, axis, side])
            if nbr >= 0 and owner[nbr] != owner[block]:
                out.setdefault((int(owner[block]), int(owner[nbr])), []).append((block, side))
    return out


def _strips(mesh, axis: int, faces: list[tuple[int, int]]) -> Strips:
    """The interior cells within GHOST of each (block, side) face along ``axis``."""
    g = mesh.ghost
    n = mesh.interior_shape
    padded = mesh.padded_shape
    blocks, cells = [], []
    for block, side in faces:
        ranges = [np.arange(g[d], g[d] + n[d]) for d in range(3)]
        start = g[axis] if side == 0 else n[axis]
        ranges[axis] = np.arange(start, start + g[axis])
        ix, iy, iz = np.meshgrid(*ranges, indexing="ij")
        flat = ((ix * padded[1] + iy) * padded[2] + iz).ravel()
        cells.append(flat)
        blocks.append(np.full(flat.size, block, dtype=np.int64))
    if not faces:
        return Strips(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    return Strips(np.concatenate(blocks), np.concatenate(cells).astype(np.int64))


def neighbourhood_routes(mesh, cuts: np.ndarray, rank: int, reach: int = TRACER_REACH) -> list[Route]:
    """The routes of ``rank``, by peer rank, that bring the interior cells of other ranks' blocks
    within ``reach`` cells of this rank's blocks (across faces, edges and corners, periodic
    faces included) up to date; a cell is listed once per route, in (block, flat cell) order.
    On an adaptive mesh, whole blocks: every block that touches one of this rank's blocks
    (:func:`touching_blocks`), since a stencil across a level face reads up to two finer cells
    deep."""
    owner = owners(cuts)
    per_block = int(np.prod(mesh.padded_shape))
    if mesh.adaptive:
        receiver, sender = touching_blocks(mesh)
        cells = _interior_cells(mesh)
        keys = (sender[:, None] * per_block + cells[None, :]).ravel()
        return _routes(keys, np.repeat(owner[sender], cells.size), np.repeat(owner[receiver], cells.size), rank,
                       per_block)
    senders, receivers, keys = [], [], []
    for offset in itertools.product((-1, 0, 1), repeat=mesh.ndim):
        if not any(offset):
            continue
        near = _block_at_offset(mesh, offset)
        blocks = np.flatnonzero(near >= 0)
        blocks = blocks[owner[near[blocks]] != owner[blocks]]
        cells = _facing_cells(mesh, offset, reach)
        keys.append((near[blocks][:, None] * per_block + cells[None, :]).ravel())
        senders.append(np.repeat(owner[near[blocks]], cells.size))
        receivers.append(np.repeat(owner[blocks], cells.size))
    return _routes(*(np.concatenate(a) for a in (keys, senders, receivers)), rank, per_block)


def restriction_stencil(mesh) -> np.ndarray:
    """(S, 3) offsets from the lowest of the 2^ndim fine cells of a restriction to each of them
    (0 or 1 along every used axis)."""
    used = [d for d in range(3) if mesh.ghost[d] > 0]
    return np.array([[a, j, k] for a in (0, 1) for j in (0, 1) for k in (0, 1)
                     if (a == 0 or 0 in used) and (j == 0 or 1 in used) and (k == 0 or 2 in used)])


def prolongation_stencil(mesh) -> np.ndarray:
    """(S, 3) offsets from the coarse cell of a state's prolongation to the cells it reads: itself
    and its neighbours along every used axis (the limited slopes)."""
    used = [d for d in range(3) if mesh.ghost[d] > 0]
    return np.array([np.zeros(3, int)] + [sign * np.eye(3, dtype=int)[d] for d in used for sign in (-1, 1)])


#: The offsets of a derived field's prolongation, which copies the coarse cell alone.
COPY_STENCIL = np.zeros((1, 3), dtype=np.int64)


def plan_routes(mesh, cuts: np.ndarray, rank: int, plan: np.ndarray, stencil: np.ndarray,
                interior_along: int | None = None) -> list[Route]:
    """The routes of ``rank`` that bring to the owner of each row's destination block
    (``plan[:, 0]``) the cells its kernel reads in the row's source block (``plan[:, 4]``):
    the source cell ``plan[:, 5:8]`` plus each offset of ``stencil`` (S, 3), where another rank
    owns the source (the coarse/fine plans of :mod:`impactpipe.hydro.amr.plans`).  With
    ``interior_along`` (an axis), only the cells in the interior along that axis: a state's
    prolongation along it also reads the coarse block's ghost cell toward the finer block,
    which the restriction sets from the finer block's cells, and the owner of the finer block
    restricts it itself (:meth:`~impactpipe.hydro.parallel.distributed.BlockRanges.plans`)."""
    owner = owners(cuts)
    padded = np.array(mesh.padded_shape)
    per_block = int(padded.prod())
    cells = plan[:, None, 5:8] + stencil[None, :, :]
    flat = (cells[..., 0] * padded[1] + cells[..., 1]) * padded[2] + cells[..., 2]
    keys = (plan[:, 4:5] * per_block + flat).ravel()
    senders = np.repeat(owner[plan[:, 4]], len(stencil))
    receivers = np.repeat(owner[plan[:, 0]], len(stencil))
    if interior_along is not None:
        along = cells[..., interior_along].ravel()
        inside = (along >= mesh.ghost[interior_along]) & (along < padded[interior_along] - mesh.ghost[interior_along])
        keys, senders, receivers = keys[inside], senders[inside], receivers[inside]
    return _routes(keys, senders, receivers, rank, per_block)


def level_field_routes(mesh, cuts: np.ndarray, rank: int, routes: list[list[Route]]) -> list[Route]:
    """The routes of ``rank``, one per peer rank, of a derived field's ghost fills along every
    used axis of an adaptive mesh: for each axis in turn, the strips of ``routes`` (those of
    :func:`exchange_routes`), the fine cells of the restrictions and the coarse cells that the
    prolongations copy (:func:`plan_routes` of the axis's coarse/fine plans).  All are interior
    cells, which none of these fills writes, so every axis's cells travel in one message per
    peer (:func:`every_axis_routes`)."""
    parts = []
    for axis in range(3):
        if mesh.ghost[axis] == 0:
            continue
        plans = axis_plans(mesh, axis)
        parts += [routes[axis], plan_routes(mesh, cuts, rank, plans["restrict"], restriction_stencil(mesh)),
                  plan_routes(mesh, cuts, rank, plans["prolong"], COPY_STENCIL)]
    return every_axis_routes(parts)


def level_state_routes(mesh, cuts: np.ndarray, rank: int, routes: list[list[Route]], axis: int) -> list[Route]:
    """The routes of ``rank``, one per peer rank, of the state's ghost fill along ``axis`` of an
    adaptive mesh: the strips of ``routes`` (those of :func:`exchange_routes`), the fine cells of
    the restrictions and the coarse cells that the prolongations read, but for the coarse
    ghosts toward the finer block (``interior_along`` of :func:`plan_routes`).  None of them is
    a ghost cell that this fill writes, so they all travel before it, in one message per peer."""
    plans = axis_plans(mesh, axis)
    return every_axis_routes([routes[axis], plan_routes(mesh, cuts, rank, plans["restrict"], restriction_stencil(mesh)),
                              plan_routes(mesh, cuts, rank, plans["prolong"], prolongation_stencil(mesh), axis)])


def block_routes(cuts: np.ndarray, rank: int, receiver_blocks: np.ndarray, sender_blocks: np.ndarray,
                 per_block: int) -> list[Route]:
    """The routes of ``rank`` that bring whole rows of per-block arrays (``per_block`` values
    after the first two axes, e.g. the coarse/fine face fluxes) from the owner of each
    ``sender_blocks[i]`` to the owner of ``receiver_blocks[i]``."""
    owner = owners(cuts)
    cells = np.arange(per_block, dtype=np.int64)
    keys = (np.asarray(sender_blocks, dtype=np.int64)[:, None] * per_block + cells[None, :]).ravel()
    return _routes(keys, np.repeat(owner[sender_blocks], per_block), np.repeat(owner[receiver_blocks], per_block),
                   rank, per_block)


def _routes(keys: np.ndarray, senders: np.ndarray, receivers: np.ndarray, rank: int, per_block: int) -> list[Route]:
    """Routes of ``rank`` from cells ``keys`` (block * per_block + flat cell) that ``senders[i]``
    sends to ``receivers[i]`` (pairs on one rank dropped); each cell once per route, in key order."""
    apart = senders != receivers
    keys, senders, receivers = keys[apart], senders[apart], receivers[apart]
    peers = np.unique(np.concatenate([receivers[senders == rank], senders[receivers == rank]]))

    def strips(sender: int, receiver: int) -> Strips:
        cells = np.unique(keys[(senders == sender) & (receivers == receiver)])
        return Strips(cells // per_block, cells % per_block)

    return [Route(int(q), strips(rank, q), strips(q, rank)) for q in peers]


def touching_blocks(mesh) -> tuple[np.ndarray, np.ndarray]:
    """(a, b): every ordered pair of distinct blocks whose closed boxes touch (faces, edges,
    corners; across periodic faces too): |c_a - c_b| <= (w_a + w_b) / 2 along every used axis
    (c the centres, w the widths, periodic axes by the nearest image), candidates from a k-d
    tree in the max norm (scipy.spatial.cKDTree)."""
    from scipy.spatial import cKDTree

    nd = mesh.ndim
    lo = np.asarray(mesh.domain_lo[:nd], float)
    extent = np.asarray(mesh.domain_hi[:nd], float) - lo
    width = mesh.block_dx[:, :nd] * np.array(mesh.interior_shape[:nd])
    centre = mesh.block_lo[:, :nd] + width / 2 - lo
    periodic = np.array([mesh.boundaries[d][0] == "periodic" for d in range(nd)])
    slack = 1e-9 * extent.max()
    tree = cKDTree(np.clip(centre, 0.0, None), boxsize=np.where(periodic, extent, 4.0 * extent))
    pairs = tree.query_pairs(width.max() + slack, p=np.inf, output_type="ndarray")
    a, b = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
    gap = np.abs(centre[a] - centre[b])
    gap = np.where(periodic, np.minimum(gap, extent - gap), gap)
    keep = (gap <= (width[a] + width[b]) / 2 + slack).all(axis=1)
    a, b = a[keep], b[keep]
    return np.concatenate([a, b]), np.concatenate([b, a])


def _interior_cells(mesh) -> np.ndarray:
    """Flat padded indices of a block's interior cells."""
    g = mesh.ghost
    n = mesh.interior_shape
    padded = mesh.padded_shape
    ix, iy, iz = np.meshgrid(*[np.arange(g[d], g[d] + n[d]) for d in range(3)], indexing="ij")
    return ((ix * padded[1] + iy) * padded[2] + iz).ravel().astype(np.int64)


def _block_at_offset(mesh, offset: tuple[int, ...]) -> np.ndarray:
    """(NB,) the block ``offset`` (-1, 0 or +1 per used axis) blocks away from each block through
    the neighbour table (a single-level mesh), < 0 where a domain face is crossed."""
    near = np.arange(mesh.nblocks)
    for axis, step in enumerate(offset):
        if step:
            near = np.where(near >= 0, mesh.neighbor[np.maximum(near, 0), axis, (step + 1) // 2], -1)
    return near


def _facing_cells(mesh, offset: tuple[int, ...], reach: int) -> np.ndarray:
    """Flat padded indices of a block's interior cells within ``reach`` of its face, edge or corner
    that faces the block at -``offset`` (along axis d: the low cells when offset_d = +1, the high
    cells when -1, every interior cell when 0)."""
    g = mesh.ghost
    n = mesh.interior_shape
    padded = mesh.padded_shape
    ranges = [np.arange(g[d], g[d] + n[d]) for d in range(3)]
    for axis, step in enumerate(offset):
        if step:
            ranges[axis] = ranges[axis][:reach] if step > 0 else ranges[axis][-reach:]
    ix, iy, iz = np.meshgrid(*ranges, indexing="ij")
    return ((ix * padded[1] + iy) * padded[2] + iz).ravel().astype(np.int64)
