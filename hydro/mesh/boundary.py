"""Ghost-layer filling along one axis, driven by the block neighbour table.

For a sweep along axis ``d`` only the ghost slabs on the two ``d`` faces of each block are
needed (the split scheme never reads corner ghosts).  With ``n`` interior and ``g`` ghost
cells per axis (padded index ``i``, interior ``g <= i < g + n``) the ghost cell ``g - 1 - j``
(low side, ``j = 0..g-1``) receives:

- neighbour block (interior or periodic): the neighbour's cell ``g + n - 1 - j``;
- reflecting: the mirror cell ``g + j`` of the same block, normal momentum negated;
- outflow: the first interior cell ``g`` (zero gradient).

and symmetrically on the high side.  Faces between blocks of different refinement levels
(``mesh.neighbor_level`` != 0) are skipped here and filled by restriction (coarse ghosts
from the fine interior) and then prolongation (fine ghosts from the coarse interior and its
just-restricted ghosts) by :func:`fill_field_ghosts` / :func:`fill_state_ghosts`, using the
plans of :mod:`impactpipe.hydro.amr.plans`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from impactpipe.hydro.amr.plans import axis_plans, first_layer_plans
from impactpipe.hydro.amr.transfer import (prolong_field_ghosts, prolong_state_ghosts, restrict_ghosts,
                                           restrict_state_ghosts)
from impactpipe.hydro.mesh.blocks import REFLECTING
from impactpipe.hydro.mesh.last_good import RECORD_VOID
from impactpipe.hydro.mesh.scalar_stamps import NO_STAMPS, ScalarStamps


@njit(cache=True, parallel=True)
def fill_ghosts(field, neighbor, neighbor_level, axis, ghost, flip_component, lo, hi):
    """Fill the same-level and domain-face ghost slabs of ``field[NB, C, NX, NY, NZ]`` along
    ``axis`` for the blocks ``lo .. hi - 1`` (every block, or one MPI rank's owned range).

    ``flip_component`` is the component index whose sign flips at a reflecting boundary
    (the normal momentum, ``axis``) or -1 for scalar fields.  Coarse/fine faces are left
    alone.  Blocks in parallel: a block writes only its own ghosts and reads only interior
    cells.
    """
    for b in prange(lo, hi):
        _fill_block_ghosts(field, b, neighbor, neighbor_level, axis, ghost, flip_component, ghost)


@njit(cache=True, parallel=True)
def fill_ghosts_where(field, neighbor, neighbor_level, axis, ghost, lo, hi, wanted, layers):
    """:func:`fill_ghosts` of a field without sign flips for the blocks ``b`` of ``lo .. hi - 1``
    with ``wanted[b]`` != 0 only (the strength step's work arrays: a block without material
    reads none of its ghosts), and of the ``layers`` (1 .. ``ghost``) ghost layers next to the
    interior only (the others keep what they held: the stress step's kernels read one layer,
    its hourglass viscosity two)."""
    for b in prange(lo, hi):
        if wanted[b] != 0:
            _fill_block_ghosts(field, b, neighbor, neighbor_level, axis, ghost, -1, layers)


@njit(cache=True, parallel=True)
def fill_state_ghost_slabs(alpha, arho, arhoe, mom, energy, arhoq, neighbor, neighbor_level, axis, ghost, lo,
                           hi, q_layers, scalars_clear, scalar_stamp, ghost_stamp):
    """:func:`fill_ghosts` for every conserved field of a state in one parallel pass over the
    blocks ``lo .. hi - 1`` (every block, or one MPI rank's owned range,
    :mod:`impactpipe.hydro.parallel`); they read any block's interior cells.  Column c of
    ``arhoq`` gets its ``q_layers[c]`` (int64, 1 .. ``ghost``) ghost layers next to the
    interior only (:func:`every_layer`: all of them), the other fields every layer.

    ``scalars_clear`` (uint8, (NB,), or empty: no record): the blocks whose scalars are +0.0
    in their interior and in those ghost layers
    (:func:`impactpipe.hydro.mesh.last_good.scalar_clear_blocks`), and among them the void
    ones (:data:`impactpipe.hydro.mesh.last_good.RECORD_VOID`).  A slab of a clear block
    whose source block is clear too already holds the +0.0 the copy would write, and its
    scalars are not copied; a slab of a void block from a void neighbour (not a domain face,
    where a reflecting face would write -0.0) is not copied at all: it holds +0.0 since the
    step began, and the neighbour's interior still does.

    ``scalar_stamp`` (int64, (NB,), or empty: no stamps), ``ghost_stamp`` (int64, (NB, 3, 2)):
    the stamps of :mod:`impactpipe.hydro.mesh.scalar_stamps`.  A slab whose scalars were last
    copied from its source block at the stamp the source holds now already holds what the copy
    would write, and its scalars are not copied; a slab whose scalars are copied records the
    source's stamp."""
    tracked = scalars_clear.shape[0] > 0
    stamped = scalar_stamp.shape[0] > 0
    for b in prange(lo, hi):
        for side in range(2):
            nbr = neighbor[b, axis, side]
            if nbr < 0 or neighbor_level[b, axis, side] == 0:
                src = nbr if nbr >= 0 else b
                if tracked and nbr >= 0 and scalars_clear[b] == RECORD_VOID and scalars_clear[src] == RECORD_VOID:
                    continue
                copy_scalars = not (tracked and scalars_clear[b] != 0 and scalars_clear[src] != 0)
                if stamped and copy_scalars:
                    copy_scalars = ghost_stamp[b, axis, side] != scalar_stamp[src]
                    ghost_stamp[b, axis, side] = scalar_stamp[src]
                _fill_state_side(alpha, arho, arhoe, mom, energy, arhoq, b, side, nbr, axis, ghost, q_layers,
                                 copy_scalars)


@njit(cache=True, parallel=True)
def fill_state_ghost_slabs_of(alpha, arho, arhoe, mom, energy, arhoq, neighbor, neighbor_level, axis, ghost, blocks,
                              q_layers):
    """:func:`fill_state_ghost_slabs` for the blocks listed in ``blocks`` (int64) only: one
    refinement level's blocks before its substep's sweep (:mod:`impactpipe.hydro.amr.subcycle`)."""
    for e in prange(blocks.shape[0]):
        b = blocks[e]
        for side in range(2):
            nbr = neighbor[b, axis, side]
            if nbr < 0 or neighbor_level[b, axis, side] == 0:
                _fill_state_side(alpha, arho, arhoe, mom, energy, arhoq, b, side, nbr, axis, ghost, q_layers, True)


@njit(cache=True, parallel=True)
def fill_state_ghost_layer(alpha, arho, arhoe, mom, energy, arhoq, neighbor, neighbor_level, axis, ghost, lo, hi):
    """The first ghost layer (next to the interior) of the same-level and domain-face slabs of
    the blocks ``lo .. hi - 1`` (every block, or one MPI rank's owned range) along ``axis``,
    every conserved field: what :func:`fill_state_ghost_slabs` writes there.  The other layers
    keep what they held."""
    for b in prange(lo, hi):
        for side in range(2):
            nbr = neighbor[b, axis, side]
            if nbr < 0 or neighbor_level[b, axis, side] == 0:
                _fill_state_layer_side(alpha, arho, arhoe, mom, energy, arhoq, b, side, nbr, axis, ghost)


@njit(cache=True, parallel=True)
def fill_state_ghost_layer_from_ranks(alpha, arho, arhoe, mom, energy, arhoq, neighbor, neighbor_level, axis, ghost,
                                      blocks, lo, hi):
    """For the blocks listed in ``blocks`` (int64), the first ghost layer of the slabs along
    ``axis`` whose same-level neighbour lies outside ``lo .. hi - 1`` (another MPI rank's block,
    its strips just received), every conserved field: what :func:`fill_state_ghost_layer`
    writes there.  The other slabs and layers are left as they are."""
    for e in prange(blocks.shape[0]):
        b = blocks[e]
        for side in range(2):
            nbr = neighbor[b, axis, side]
            if nbr >= 0 and neighbor_level[b, axis, side] == 0 and not (lo <= nbr < hi):
                _fill_state_layer_side(alpha, arho, arhoe, mom, energy, arhoq, b, side, nbr, axis, ghost)


@njit(cache=True, parallel=True)
def fill_state_ghosts_from_ranks(alpha, arho, arhoe, mom, energy, arhoq, neighbor, neighbor_level, axis, ghost,
                                 blocks, lo, hi, q_layers):
    """For the blocks listed in ``blocks`` (int64), the ghost slabs along ``axis`` whose same-level
    neighbour lies outside ``lo .. hi - 1`` (another MPI rank's block, its strips just received),
    every conserved field (the layers of :func:`fill_state_ghost_slabs`); the other slabs are
    left as they are (filled before, from blocks that may have been advanced since:
    :meth:`impactpipe.hydro.parallel.distributed.BlockRanges.start_ghosts`)."""
    for e in prange(blocks.shape[0]):
        b = blocks[e]
        for side in range(2):
            nbr = neighbor[b, axis, side]
            if nbr >= 0 and neighbor_level[b, axis, side] == 0 and not (lo <= nbr < hi):
                _fill_state_side(alpha, arho, arhoe, mom, energy, arhoq, b, side, nbr, axis, ghost, q_layers, True)


@njit(cache=True, parallel=True)
def fill_ghosts_from_ranks_where(field, neighbor, neighbor_level, axis, ghost, blocks, lo, hi, wanted, layers):
    """For the blocks listed in ``blocks`` (int64) with ``wanted[b]`` != 0, the ghost slabs of
    ``field`` along ``axis`` whose same-level neighbour lies outside ``lo .. hi - 1`` (another
    MPI rank's block, its strips just received), their ``layers`` layers next to the interior,
    without sign flips: what :func:`fill_ghosts_where` writes there.  The other slabs are left
    as they are (filled before the strips arrived,
    :meth:`impactpipe.hydro.parallel.distributed.BlockRanges.start_field_ghosts`)."""
    for e in prange(blocks.shape[0]):
        b = blocks[e]
        if wanted[b] == 0:
            continue
        for side in range(2):
            nbr = neighbor[b, axis, side]
            if nbr >= 0 and neighbor_level[b, axis, side] == 0 and not (lo <= nbr < hi):
                _fill_block_side(field, b, side, nbr, axis, ghost, -1, layers)


def every_layer(arhoq: np.ndarray, ghost: int) -> np.ndarray:
    """``q_layers`` of :func:`fill_state_ghost_slabs` that fills every ghost layer of every column of ``arhoq``."""
    return np.full(arhoq.shape[1], ghost, dtype=np.int64)


@njit(cache=True)
def _fill_state_side(alpha, arho, arhoe, mom, energy, arhoq, b, side, nbr, axis, ghost, q_layers, copy_scalars):
    """:func:`_fill_block_side` for every conserved field, the normal momentum flipped at a
    reflecting face, column c of ``arhoq`` ``q_layers[c]`` layers deep (none without ``copy_scalars``)."""
    _fill_block_side(alpha, b, side, nbr, axis, ghost, -1, ghost)
    _fill_block_side(arho, b, side, nbr, axis, ghost, -1, ghost)
    _fill_block_side(arhoe, b, side, nbr, axis, ghost, -1, ghost)
    _fill_block_side(mom, b, side, nbr, axis, ghost, axis, ghost)
    _fill_block_side(energy, b, side, nbr, axis, ghost, -1, ghost)
    if not copy_scalars:
        return
    n = (arhoq.shape[2], arhoq.shape[3], arhoq.shape[4])[axis] - 2 * ghost
    for j in range(ghost):
        dst, src = _slab_cells(side, nbr, ghost, n, j)
        blk = nbr if nbr >= 0 else np.int64(b)
        for c in range(arhoq.shape[1]):
            if j < q_layers[c]:
                _copy_slab(arhoq, b, blk, c, axis, dst, src, 1.0, ghost)


@njit(cache=True, inline="always")
def _fill_state_layer_side(alpha, arho, arhoe, mom, energy, arhoq, b, side, nbr, axis, ghost):
    """The first ghost layer of block b's slab on ``side`` along ``axis``, every conserved field
    (the normal momentum's sign flipped at a reflecting face)."""
    _fill_block_side(alpha, b, side, nbr, axis, ghost, -1, 1)
    _fill_block_side(arho, b, side, nbr, axis, ghost, -1, 1)
    _fill_block_side(arhoe, b, side, nbr, axis, ghost, -1, 1)
    _fill_block_side(mom, b, side, nbr, axis, ghost, axis, 1)
    _fill_block_side(energy, b, side, nbr, axis, ghost, -1, 1)
    _fill_block_side(arhoq, b, side, nbr, axis, ghost, -1, 1)


@njit(cache=True)
def _fill_block_ghosts(field, b, neighbor, neighbor_level, axis, ghost, flip_component, layers):
    """The ghost slabs of block ``b`` along ``axis`` (rules in the module docstring), their
    ``layers`` layers next to the interior."""
    for side in range(2):
        nbr = neighbor[b, axis, side]
        if nbr >= 0 and neighbor_level[b, axis, side] != 0:
            continue
        _fill_block_side(field, b, side, nbr, axis, ghost, flip_component, layers)


@njit(cache=True)
def _fill_block_side(field, b, side, nbr, axis, ghost, flip_component, layers):
    """The ghost slab of block ``b`` on ``side`` (0 low, 1 high) along ``axis`` from its same-level
    neighbour ``nbr``, or by the domain-face rule ``nbr`` < 0 names (module docstring): its
    ``layers`` (1 .. ``ghost``) layers next to the interior, j = 0 .. layers - 1."""
    n = (field.shape[2], field.shape[3], field.shape[4])[axis] - 2 * ghost
    for j in range(layers):
        dst, src = _slab_cells(side, nbr, ghost, n, j)
        blk = nbr if nbr >= 0 else np.int64(b)
        flip = nbr == REFLECTING
        for c in range(field.shape[1]):
            sign = -1.0 if (flip and c == flip_component) else 1.0
            _copy_slab(field, b, blk, c, axis, dst, src, sign, ghost)


@njit(cache=True, inline="always")
def _slab_cells(side, nbr, ghost, n, j):
    """(ghost index, source index) along the axis of ghost layer j (0 next to the interior) on
    ``side`` of a block with ``n`` interior cells, by the rules of the module docstring."""
    if side == 0:
        dst = ghost - 1 - j
        if nbr >= 0:
            src = ghost + n - 1 - j
        elif nbr == REFLECTING:
            src = ghost + j
        else:
            src = ghost
    else:
        dst = ghost + n + j
        if nbr >= 0:
            src = ghost + j
        elif nbr == REFLECTING:
            src = ghost + n - 1 - j
        else:
            src = ghost + n - 1
    return dst, src


@njit(cache=True, inline="always")
def _copy_slab(field, b, blk, c, axis, dst, src, sign, ghost):
    """``field[b, c]`` at index ``dst`` along ``axis`` = ``sign`` times ``field[blk, c]`` at ``src``
    (the interior range of the other axes)."""
    _, _, nx, ny, nz = field.shape
    if axis == 0 and nz == 1:
        # 2D: one loop over the contiguous row, without the loop of one z cell inside it,
        # copies it 1.5-2x faster
        for iy in range(_lo(ny, ghost), _hi(ny, ghost)):
            field[b, c, dst, iy, 0] = sign * field[blk, c, src, iy, 0]
    elif axis == 0:
        for iy in range(_lo(ny, ghost), _hi(ny, ghost)):
            for iz in range(_lo(nz, ghost), _hi(nz, ghost)):
                field[b, c, dst, iy, iz] = sign * field[blk, c, src, iy, iz]
    elif axis == 1:
        for ix in range(_lo(nx, ghost), _hi(nx, ghost)):
            for iz in range(_lo(nz, ghost), _hi(nz, ghost)):
                field[b, c, ix, dst, iz] = sign * field[blk, c, ix, src, iz]
    else:
        for ix in range(_lo(nx, ghost), _hi(nx, ghost)):
            for iy in range(_lo(ny, ghost), _hi(ny, ghost)):
                field[b, c, ix, iy, dst] = sign * field[blk, c, ix, iy, src]


@njit(cache=True, inline="always")
def _lo(npad, ghost):
    """First interior index of an axis with ``npad`` padded cells (0 for an unused axis)."""
    return ghost if npad > 1 else 0


@njit(cache=True, inline="always")
def _hi(npad, ghost):
    """One past the last interior index of an axis with ``npad`` padded cells."""
    return npad - ghost if npad > 1 else 1


def fill_field_ghosts(field: np.ndarray, mesh, axis: int, flip_component: int = -1,
                      wanted: np.ndarray | None = None, layers: int | None = None) -> None:
    """Fill the ghosts of one field along ``axis``; coarse/fine faces by restriction and copies.

    For fields that are not conserved amounts (velocities, stresses of the strength step):
    coarse ghosts get the volume-weighted fine means, fine ghosts a copy of the coarse cell.
    ``wanted[NB]``: on a uniform mesh, fill only the same-level ghosts of the blocks where it
    is not 0 (without sign flips; :func:`fill_ghosts_where`), and there only the ``layers``
    ghost layers next to the interior (all by default); an adaptive mesh fills every block's
    ghosts, every layer (its restriction reads interior fine cells and its prolongation copies
    the interior coarse cell).
    """
    g = int(mesh.ghost[axis])
    if g == 0:
        return
    if wanted is not None and not mesh.adaptive:
        fill_ghosts_where(field, mesh.neighbor, mesh.neighbor_level, axis, g, 0, mesh.nblocks, wanted,
                          g if layers is None else layers)
        return
    fill_ghosts(field, mesh.neighbor, mesh.neighbor_level, axis, g, flip_component, 0, mesh.nblocks)
    if mesh.adaptive:
        plans = axis_plans(mesh, axis)
        restrict_ghosts(field, plans["restrict"], plans["restrict_weight"])
        prolong_field_ghosts(field, plans["prolong"])


#: ``scalars_clear`` of :func:`fill_state_ghost_slabs` without a record: every slab is copied.
NO_RECORD = np.zeros(0, dtype=np.uint8)


def fill_state_ghosts(state, mesh, axis: int, q_layers: np.ndarray | None = None,
                      scalars_clear: np.ndarray | None = None, stamps: ScalarStamps | None = None) -> None:
    """Fill the ghosts of every conserved field of ``state`` along ``axis``; ``q_layers``:
    the ghost layers of each column of ``state.arhoq`` (:func:`fill_state_ghost_slabs`; None:
    every layer, which an adaptive mesh needs, since its prolongation reads the coarse ghosts);
    ``scalars_clear``: the blocks whose scalars are +0.0 (:func:`fill_state_ghost_slabs`; a
    uniform mesh's only, with ``q_layers``), or None; ``stamps``: the blocks' scalar stamps
    (:class:`~impactpipe.hydro.mesh.scalar_stamps.ScalarStamps`; a uniform mesh's only, with a
    record), or None.

    Coarse/fine faces: restriction, then the conservative limited prolongation of
    :func:`impactpipe.hydro.amr.transfer.prolong_state_ghosts`.
    """
    g = int(mesh.ghost[axis])
    if g == 0:
        return
    fields = (state.alpha, state.arho, state.arhoe, state.momentum, state.energy, state.arhoq)
    if q_layers is None or mesh.adaptive:
        q_layers = every_layer(state.arhoq, g)
        scalars_clear = None
    if scalars_clear is None or stamps is None:
        block_stamp, ghost_stamp = NO_STAMPS
    else:
        block_stamp, ghost_stamp = stamps.block, stamps.ghost
    fill_state_ghost_slabs(*fields, mesh.neighbor, mesh.neighbor_level, axis, g, 0, mesh.nblocks, q_layers,
                           NO_RECORD if scalars_clear is None else scalars_clear, block_stamp, ghost_stamp)
    if not mesh.adaptive:
        return
    plans = axis_plans(mesh, axis)
    for arr in fields:
        restrict_ghosts(arr, plans["restrict"], plans["restrict_weight"])
    prolong_state_ghosts(fields, plans["prolong"], mesh.block_lo, mesh.block_dx, mesh.geometry_code, mesh.ndim)


def fill_first_ghost_layer(state, mesh, axis: int) -> None:
    """The first ghost layer along ``axis`` (next to the interior) of every conserved field of
    ``state``, the values :func:`fill_state_ghosts` gives it; the other layers keep what they
    held.

    Same-level and domain faces by :func:`fill_state_ghost_layer`; coarse/fine faces by the
    rows of the restriction and then the prolongation that write the layer
    (:func:`~impactpipe.hydro.amr.plans.first_layer_plans`), which read no other ghost layer.
    The regrid fills this layer before its indicators and on the new mesh after a remesh
    (:meth:`impactpipe.hydro.solver.Simulation.regrid`), where the full fill did: the
    indicators look one cell beyond a block, a new child's prolongation
    (:func:`~impactpipe.hydro.amr.transfer.prolong_blocks`) reads its parent cells' face
    neighbours, and until the step's own fills every other reader of a ghost reads the first
    layer only (the prolongation of a later fill, a restore's included, reads a coarse
    block's first layer of the other axes at its edges); a sweep fills every layer along its
    axis first, so the second layer is read only after that.
    """
    g = int(mesh.ghost[axis])
    if g == 0:
        return
    fields = (state.alpha, state.arho, state.arhoe, state.momentum, state.energy, state.arhoq)
    fill_state_ghost_layer(*fields, mesh.neighbor, mesh.neighbor_level, axis, g, 0, mesh.nblocks)
    if not mesh.adaptive:
        return
    plans = first_layer_plans(mesh, axis)
    restrict_state_ghosts(fields, plans["restrict"], plans["restrict_weight"])
    prolong_state_ghosts(fields, plans["prolong"], mesh.block_lo, mesh.block_dx, mesh.geometry_code, mesh.ndim)
