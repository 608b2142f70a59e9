"""How a :class:`~impactpipe.hydro.solver.Simulation` shares its blocks between processes.

The Simulation asks its ``partition`` which blocks to advance (``blocks``, a slice of the
block order), to fill their ghosts, to combine the time step and the failure checks over
every process, to regrid its blocks, and to bring every block to the process that writes an
output, or to open the output with the other processes where they write it together
(``writes_together``), and to give every process every block's rows of small per-block
arrays (the totals' sums, the refinement indicators).
:class:`WholeMesh` is the single process (every block, nothing to combine); :class:`BlockRanges` the MPI ranks
of one run (:func:`shared_simulation`, :meth:`~impactpipe.hydro.solver.Simulation.from_checkpoint`
with a communicator, :func:`distribute_from_root` or :func:`distribute` attaches it;
:func:`collect_counters` ends a run without moving its state, :func:`collect` gathers the
state on rank 0 for a script that compares it).

Tracers (:class:`~impactpipe.hydro.tracers.motion.Tracers`) are held by the process that owns
the block holding them: they ask the partition which process that is
(:meth:`WholeMesh.block_owners`), to hand a tracer's records to it when the tracer moves into
another process's blocks (:meth:`WholeMesh.hand_over`), to bring the cells around its blocks
up to date before they sample (:meth:`WholeMesh.share_neighbourhood`), and to gather every
tracer for an output (:meth:`WholeMesh.gather_items`).

The last-good copy of a step (:meth:`Simulation.restore_last_good`) is kept by each rank
over its own blocks only: only those are advanced, and a restore on every rank followed by
the exchange before the next ghost fill rebuilds exactly the serial state.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import h5py
import numpy as np

from impactpipe.hydro.amr.plans import axis_plans, first_layer_plans
from impactpipe.hydro.amr.regrid import moved_state, plan_sources, planned_costs, planned_mesh, summed_rows
from impactpipe.hydro.amr.transfer import (prolong_field_ghosts, prolong_state_ghosts, restrict_ghosts,
                                           restrict_state_ghosts)
from impactpipe.hydro.mesh.boundary import (
    NO_RECORD, every_layer, fill_field_ghosts, fill_first_ghost_layer, fill_ghosts, fill_ghosts_from_ranks_where,
    fill_ghosts_where, fill_state_ghost_layer, fill_state_ghost_layer_from_ranks, fill_state_ghost_slabs,
    fill_state_ghosts, fill_state_ghosts_from_ranks,
)
from impactpipe.hydro.mesh.scalar_stamps import NO_STAMPS
from impactpipe.hydro.mesh.state import FIELDS, HydroState
from impactpipe.storage import atomic_path, atomic_path_together

from .decomposition import (block_costs, block_routes, every_axis_routes, exchange_routes, field_overlap_groups,
                            level_field_routes, level_state_routes, neighbourhood_routes, overlap_groups,
                            owned_ranges, owners)
from .exchange import (CARRY_TAG, FIELD_TAG, FLUX_TAG, NEIGHBOURHOOD_TAG, STRIP_TAG, PendingStrips, StripExchange,
                       Traffic, broadcast_arrays, finish_strips, gather_item_rows, gather_owned_blocks, hand_over_rows,
                       move_rows, share_owned_blocks)
from .owned_memory import from_outline, lazy_zeros, outline, placed_rows, receive_halos, receive_owned_blocks

log = logging.getLogger(__name__)


@dataclass
class GhostFill:
    """A ghost fill along one axis in two parts (:meth:`WholeMesh.start_ghosts`): the blocks
    ``early`` (indices within the partition's ``blocks``) may be swept before
    :meth:`WholeMesh.finish_ghosts`, the blocks ``late`` only after it; ``pending``: the
    strips still travelling, or None."""

    early: np.ndarray
    late: np.ndarray
    pending: PendingStrips | None = None


@dataclass
class FieldFill:
    """A ghost fill of the components of a derived field that the ``runs`` (slices of its
    component axis) select, along each of the ``axes``, in two parts
    (:meth:`WholeMesh.start_field_ghosts`): of the blocks where ``wanted[b]`` is not 0, their
    ``layers`` ghost layers next to the interior; ``pending``: the strips of every axis and run
    still travelling (one message per peer rank), or None (the fill is complete)."""

    axes: tuple[int, ...]
    runs: tuple[slice, ...]
    wanted: np.ndarray
    layers: int | None
    pending: PendingStrips | None = None


@dataclass
class FirstLayerFill:
    """The fill of the state's first ghost layer along one axis, in two parts
    (:meth:`WholeMesh.start_first_ghost_layer`): ``late`` (int64 block numbers), the blocks
    whose layer waits for :meth:`WholeMesh.finish_first_ghost_layer`; ``pending``: the strips
    still travelling, or None (the fill is complete)."""

    late: np.ndarray
    pending: PendingStrips | None = None


def used_axes(mesh) -> tuple[int, ...]:
    """The axes of ``mesh`` with ghost cells."""
    return tuple(axis for axis in range(3) if mesh.ghost[axis] > 0)


class WholeMesh:
    """One process advances every block; ``traffic`` (:class:`~.exchange.Traffic`) stays zero."""

    blocks = slice(None)
    is_root = True
    rank = 0
    #: Whether a step may keep the record of the blocks whose transported scalars are +0.0
    #: (:meth:`start_ghosts`, :meth:`impactpipe.hydro.solver.Simulation.step`).
    keeps_scalar_record = True
    #: Whether this process advances every block (no strips travel between ranks).
    whole = True
    #: Whether the processes write each snapshot and checkpoint together into one file, each its
    #: own blocks' rows (parallel HDF5, :func:`parallel_hdf5`), instead of the process that writes
    #: receiving every block first (:meth:`gather_to_root`, :meth:`rows_at_root`).
    writes_together = False

    def __init__(self):
        self.traffic = Traffic()
        self._field_groups = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))

    def fill_ghosts(self, state, mesh, axis: int, q_layers: np.ndarray | None = None) -> None:
        """Fill the ghosts of every block along ``axis``; ``q_layers``: the ghost layers of each
        column of ``state.arhoq`` (None: every layer; :func:`~impactpipe.hydro.mesh.boundary.fill_state_ghosts`)."""
        fill_state_ghosts(state, mesh, axis, q_layers)

    def start_ghosts(self, state, mesh, axis: int, q_layers: np.ndarray | None = None,
                     scalars_clear: np.ndarray | None = None, stamps=None) -> GhostFill:
        """Fill the ghosts along ``axis`` (``q_layers`` as in :meth:`fill_ghosts`) as far as this
        process can without waiting for another's strips; a sweep may then advance the returned
        fill's ``early`` blocks before :meth:`finish_ghosts` completes the rest.  One process
        fills every ghost here, and every block is ``late`` (swept after :meth:`finish_ghosts`,
        as before the split).  ``scalars_clear``: the blocks whose scalars are +0.0, whose
        slabs from clear blocks need no copy of them, and ``stamps``: the blocks' scalar stamps,
        whose slabs holding their sources' scalars need none either
        (:func:`~impactpipe.hydro.mesh.boundary.fill_state_ghosts`), or None."""
        fill_state_ghosts(state, mesh, axis, q_layers, scalars_clear, stamps)
        return GhostFill(np.zeros(0, dtype=np.int64), np.arange(mesh.nblocks, dtype=np.int64))

    def finish_ghosts(self, fill: GhostFill, state, mesh, axis: int) -> None:
        """Complete the ghost fill :meth:`start_ghosts` began (nothing left for one process)."""

    def start_field_ghosts(self, field: np.ndarray, mesh, runs: tuple[slice, ...], wanted: np.ndarray,
                           layers: int | None = None) -> FieldFill:
        """Fill the ghosts of the components of a derived field (velocities, stresses) that the
        ``runs`` (slices of its component axis) select, along every used axis, without sign flips
        (:func:`~impactpipe.hydro.mesh.boundary.fill_field_ghosts`, run by run): on a uniform mesh
        only of the blocks where ``wanted[b]`` is not 0 and of those only the ``layers`` ghost
        layers next to the interior; on an adaptive mesh every layer of every block, the
        coarse/fine faces by restriction and copies of the coarse cells.  Across MPI ranks this
        fills what the process can without waiting for another's strips; the blocks ``early``
        of :meth:`field_groups` may then be advanced before :meth:`finish_field_ghosts`
        completes the rest.  Every cell these fills read is an interior cell (a same-level
        neighbour's, a restriction's fine cells, the coarse cell a fine ghost copies) and each
        axis's fill writes its own ghost slabs, so their order does not matter.  One process
        fills every ghost here."""
        axes = used_axes(mesh)
        for axis in axes:
            for run in runs:
                fill_field_ghosts(field[:, run], mesh, axis, wanted=wanted, layers=layers)
        return FieldFill(axes, runs, wanted, layers)

    def finish_field_ghosts(self, fill: FieldFill, field: np.ndarray, mesh) -> None:
        """Complete the ghost fill :meth:`start_field_ghosts` began (nothing left for one process)."""

    def field_groups(self, mesh) -> tuple[np.ndarray, np.ndarray]:
        """(early, late): the blocks (int64 block numbers) a kernel reading the ghosts along every
        axis may advance between :meth:`start_field_ghosts` and :meth:`finish_field_ghosts`,
        and the rest.  One process: none early, every block late (kept until the mesh's block
        count changes)."""
        if self._field_groups[1].size != mesh.nblocks:
            self._field_groups = (np.zeros(0, dtype=np.int64), np.arange(mesh.nblocks, dtype=np.int64))
        return self._field_groups

    def combine_rate(self, rate: float, first_bad: int) -> tuple[float, int]:
        """(largest signal rate (1/s), first block with a non-finite rate or -1) over every process."""
        return rate, first_bad

    def any(self, flag: bool) -> bool:
        """Whether ``flag`` holds on some process."""
        return flag

    def largest(self, value: float) -> float:
        """The largest of ``value`` over the processes."""
        return value

    def sum_integers(self, array: np.ndarray) -> None:
        """Sum the int64 ``array`` over the processes, in place (integer sums do not depend
        on the order, so the result is the same on any number of processes)."""

    def plans(self, mesh, axis: int) -> dict:
        """The coarse/fine plans of ``axis`` whose destination blocks this process advances
        (:func:`~impactpipe.hydro.amr.plans.axis_plans`)."""
        return axis_plans(mesh, axis)

    def share_face_flux(self, face_flux: np.ndarray, axis: int) -> None:
        """Bring the coarse/fine face fluxes ``face_flux`` (NB, 2, NQ, N1, N2) of the finer
        blocks this process refluxes from up to date (they are)."""

    def fill_first_ghost_layer(self, state, mesh, axis: int) -> None:
        """The first ghost layer along ``axis`` of every block
        (:func:`~impactpipe.hydro.mesh.boundary.fill_first_ghost_layer`: what the regrid reads)."""
        fill_first_ghost_layer(state, mesh, axis)

    def start_first_ghost_layer(self, state, mesh, axis: int) -> FirstLayerFill:
        """:meth:`fill_first_ghost_layer` as far as this process can go without another's strips;
        the blocks ``late`` of the fill it returns wait for :meth:`finish_first_ghost_layer`.
        One process fills the whole layer here."""
        self.fill_first_ghost_layer(state, mesh, axis)
        return FirstLayerFill(np.zeros(0, dtype=np.int64))

    def finish_first_ghost_layer(self, fill: FirstLayerFill, state, mesh, axis: int) -> None:
        """Complete the fill :meth:`start_first_ghost_layer` began (nothing left for one process)."""

    def regrid(self, sim, plan: dict, new_mesh=None) -> tuple:
        """(new mesh, new state, new partition) of ``sim`` after the regrid ``plan``
        (:func:`~impactpipe.hydro.amr.regrid.plan_leaves`; onto ``new_mesh`` where given, else the
        mesh of the plan's leaves): every block moved (:func:`~impactpipe.hydro.amr.regrid.moved_state`),
        the first ghost layer filled on every axis, and this partition (every block again)."""
        if new_mesh is None:
            new_mesh = planned_mesh(sim.mesh, plan)
        new_state = moved_state(sim.mesh, new_mesh, sim.state, plan, 0, new_mesh.nblocks, np.zeros)
        for axis in range(new_mesh.ndim):
            fill_first_ghost_layer(new_state, new_mesh, axis)
        return new_mesh, new_state, self

    def summed_rows(self, counters: np.ndarray, nblocks: int) -> np.ndarray:
        """Per-block ``counters`` (NB, ...) for a new mesh of ``nblocks`` blocks: their totals in
        row 0 (:func:`~impactpipe.hydro.amr.regrid.summed_rows`)."""
        return summed_rows(counters, nblocks)

    def first_failure(self, failure: np.ndarray) -> int:
        """The first block whose sweep failed (``failure[:, 0]`` != 0), or -1."""
        return int(np.argmax(failure[:, 0] != 0)) if failure[:, 0].any() else -1

    def from_owner(self, block: int, make: Callable[[], Any]) -> Any:
        """``make()`` evaluated by the process that owns ``block``, returned on every process."""
        return make()

    def carry_through(self, first: Any, step: Callable[[Any], Any]) -> tuple[Any, Any]:
        """Run ``step`` on every process in the order of their blocks, each on what the step of
        the process before returned (the first process on ``first``): a running sum over the
        blocks.  Returns (what this process's step was given, what the last process's returned)."""
        return first, step(first)

    def agree(self, value: Any) -> Any:
        """Rank 0's ``value`` on every process."""
        return value

    def gather_to_root(self, arrays: list[np.ndarray]) -> None:
        """Bring every block's rows of ``arrays`` (each (NB, ...)) to the process that writes
        (this one has them)."""

    def output_file(self, path, mode: str) -> h5py.File:
        """The h5py File of an output as this process opens it (with ``writes_together``, every
        process opens it together, with the mpio driver)."""
        return h5py.File(path, mode)

    def atomic_output(self, path):
        """The context of :func:`~impactpipe.storage.atomic_path` (every process together with
        ``writes_together``: :func:`~impactpipe.storage.atomic_path_together`)."""
        return atomic_path(path)

    def rows_at_root(self, array: np.ndarray) -> np.ndarray | None:
        """Every block's rows of ``array`` (NB, ...) on the process that writes, in an array of their
        own there, None elsewhere (this process has them: ``array`` itself)."""
        return array

    def zeros(self, shape: tuple[int, ...]) -> np.ndarray:
        """A float64 per-block array (NB, ...) of zeros of which this process writes the rows of
        ``blocks``: here every row, so numpy's own array."""
        return np.zeros(shape)

    def share_rows(self, array: np.ndarray) -> None:
        """Bring every block's row of ``array`` ((NB, ...), computed by each block's owner) to
        every process (this one has them)."""

    def block_owners(self, blocks: np.ndarray, out: np.ndarray) -> None:
        """``out[t]``: the process that owns block ``blocks[t]`` (this one), -1 where ``blocks[t]`` is -1."""
        np.minimum(blocks, 0, out=out)

    def share_neighbourhood(self, state) -> None:
        """Bring the cells within :data:`~.decomposition.TRACER_REACH` of this process's blocks up
        to date (they are)."""

    def hand_over(self, destination: np.ndarray, arrays: list[np.ndarray]) -> list[np.ndarray] | None:
        """The rows of per-item arrays (tracers, each (N, ...)) this process holds after row t
        went to process ``destination[t]``, None where none came or went
        (:func:`~.exchange.hand_over_rows`): here none moves."""
        return None

    def gather_items(self, arrays: list[np.ndarray], everywhere: bool = False) -> list[np.ndarray] | None:
        """Every process's rows of per-item arrays side by side, by process, on the process that
        writes (every process with ``everywhere``), None elsewhere (:func:`~.exchange.gather_item_rows`):
        here this process's."""
        return arrays


class BlockRanges(WholeMesh):
    """This rank advances the blocks ``cuts[rank] .. cuts[rank + 1] - 1`` (see :mod:`.decomposition`)."""

    keeps_scalar_record = False
    whole = False

    def __init__(self, comm, mesh, cuts: np.ndarray):
        super().__init__()
        self.comm = comm
        self.cuts = cuts
        self.lo, self.hi = int(cuts[comm.rank]), int(cuts[comm.rank + 1])
        self.blocks = slice(self.lo, self.hi)
        self.is_root = comm.rank == 0
        self.rank = comm.rank
        self.writes_together = parallel_hdf5()
        self.nblocks = mesh.nblocks
        self.routes = exchange_routes(mesh, cuts, comm.rank)
        self.neighbourhood = neighbourhood_routes(mesh, cuts, comm.rank)
        #: Per axis: (inner, edge) owned blocks, by index within ``blocks``
        #: (:func:`~.decomposition.overlap_groups`).
        self.overlap = overlap_groups(mesh, cuts, comm.rank)
        #: (inner, edge) owned blocks over every axis, by block number
        #: (:func:`~.decomposition.field_overlap_groups`).
        self.field_overlap = field_overlap_groups(mesh, cuts, comm.rank)
        #: The strips along every axis by peer, one message each (:func:`~.decomposition.every_axis_routes`).
        self.field_routes = every_axis_routes(self.routes)
        #: The exchanges (:class:`~.exchange.StripExchange`) of the strips before a ghost fill
        #: along each axis, of the strips along every axis, of the tracers' neighbourhood.
        self.strips = [StripExchange(comm, routes, STRIP_TAG + axis) for axis, routes in enumerate(self.routes)]
        self.field_strips = StripExchange(comm, self.field_routes, FIELD_TAG)
        self.neighbourhood_strips = StripExchange(comm, self.neighbourhood, NEIGHBOURHOOD_TAG)
        #: Per axis on an adaptive mesh: this rank's rows of the coarse/fine plans and their exchanges.
        self._plans: dict[int, dict] = {}
        #: On an adaptive mesh, the exchange before a derived field's fills along every axis
        #: (:func:`~.decomposition.level_field_routes`), built on first use.
        self._level_field_strips: StripExchange | None = None
        #: The ``wanted`` of a derived field's fill of every block (an adaptive mesh's).
        self.every_block = np.ones(mesh.nblocks, dtype=np.uint8)
        #: The exchanges of the face fluxes per (axis, row length), built on first use.
        self._flux_strips: dict[tuple[int, int], StripExchange] = {}

    def fill_ghosts(self, state, mesh, axis: int, q_layers: np.ndarray | None = None) -> None:
        """Receive the neighbours' strips along ``axis`` from their owners, then fill the owned
        blocks' ghosts (:func:`~impactpipe.hydro.mesh.boundary.fill_state_ghost_slabs`; ``q_layers``
        the ghost layers of each column of ``state.arhoq``, None or on an adaptive mesh every layer)."""
        g = int(mesh.ghost[axis])
        if g == 0:
            return
        if q_layers is None or mesh.adaptive:
            q_layers = every_layer(state.arhoq, g)
        fields = (state.alpha, state.arho, state.arhoe, state.momentum, state.energy, state.arhoq)
        self._state_strips(mesh, axis).exchange(fields, self.traffic)
        fill_state_ghost_slabs(*fields, mesh.neighbor, mesh.neighbor_level, axis, g, self.lo, self.hi, q_layers,
                               NO_RECORD, *NO_STAMPS)
        if mesh.adaptive:
            self._fill_level_ghosts(fields, mesh, axis, "here")
            self._fill_level_ghosts(fields, mesh, axis, "away")

    def _state_strips(self, mesh, axis: int) -> StripExchange:
        """The exchange before the state's ghost fill along ``axis``: the strips on a uniform mesh;
        on an adaptive mesh, with them in one message per peer, the fine cells the restriction
        reads and the coarse cells the prolongation reads (``level_strips`` of :meth:`plans`)."""
        return self.plans(mesh, axis)["level_strips"] if mesh.adaptive else self.strips[axis]

    def start_ghosts(self, state, mesh, axis: int, q_layers: np.ndarray | None = None,
                     scalars_clear: np.ndarray | None = None, stamps=None) -> GhostFill:
        """Post the strips along ``axis`` (:meth:`~.exchange.StripExchange.post`) and fill every owned
        block's ghosts from what this rank holds, then return while the strips travel: the
        fill's ``early`` blocks (the inner blocks of :func:`~.decomposition.overlap_groups`,
        whose ghosts along ``axis`` are now complete) can be swept meanwhile.  The slabs of the
        ``late`` blocks that face another rank's block are filled again by
        :meth:`finish_ghosts` (every layer).  On an adaptive mesh the fine cells that the
        restriction reads and the coarse cells that the prolongation reads from other ranks'
        blocks travel with the strips (:meth:`_state_strips`), every layer is filled, and the
        coarse/fine ghosts whose source block this rank owns are filled here
        (:meth:`_fill_level_ghosts`), the others by :meth:`finish_ghosts`; the blocks those
        others write are late.  ``q_layers`` as in
        :meth:`fill_ghosts`.  ``scalars_clear`` and ``stamps`` must be None: the ranks keep no
        record of the blocks whose scalars are +0.0, and every slab is copied."""
        if scalars_clear is not None or stamps is not None:
            raise ValueError("several MPI ranks keep no record of the blocks whose scalars are +0.0")
        inner, edge = self.overlap[axis]
        g = int(mesh.ghost[axis])
        if g == 0:
            return GhostFill(inner, edge)
        if q_layers is None or mesh.adaptive:
            q_layers = every_layer(state.arhoq, g)
        fields = (state.alpha, state.arho, state.arhoe, state.momentum, state.energy, state.arhoq)
        pending = self._state_strips(mesh, axis).post(fields, self.traffic)
        fill_state_ghost_slabs(*fields, mesh.neighbor, mesh.neighbor_level, axis, g, self.lo, self.hi, q_layers,
                               NO_RECORD, *NO_STAMPS)
        if mesh.adaptive:
            self._fill_level_ghosts(fields, mesh, axis, "here")
        return GhostFill(inner, edge, pending)

    def finish_ghosts(self, fill: GhostFill, state, mesh, axis: int) -> None:
        """Wait for the strips of :meth:`start_ghosts` and fill the edge blocks' slabs that face
        another rank's block (:func:`~impactpipe.hydro.mesh.boundary.fill_state_ghosts_from_ranks`);
        their other slabs keep what :meth:`start_ghosts` gave them, from the blocks as they were
        before the early sweep.  On an adaptive mesh the coarse/fine ghosts whose source block
        another rank owns follow (:meth:`_fill_level_ghosts`): they read only the cells received
        and those of late blocks."""
        if fill.pending is None:
            return
        finish_strips(fill.pending)
        fields = (state.alpha, state.arho, state.arhoe, state.momentum, state.energy, state.arhoq)
        g = int(mesh.ghost[axis])
        fill_state_ghosts_from_ranks(*fields, mesh.neighbor, mesh.neighbor_level, axis, g, fill.late + self.lo,
                                     self.lo, self.hi, every_layer(state.arhoq, g))
        if mesh.adaptive:
            self._fill_level_ghosts(fields, mesh, axis, "away")

    def _fill_level_ghosts(self, fields: tuple, mesh, axis: int, part: str) -> None:
        """The coarse/fine ghosts of the state's ``fields`` along ``axis`` of this rank's rows of
        the plans (:meth:`plans`) whose source block this rank owns (``part`` "here": no cell of
        another rank's block is read, so they are filled before the strips arrive) or another
        rank owns ("away": after, from the cells received, :meth:`_state_strips`): restriction,
        then prolongation.  A prolongation reads its coarse cell's ghost toward the finer block,
        which the restriction sets from the finer block's cells: with the rows "here" those of
        this rank's finer blocks; with the rows "away" this rank also restricts those ghosts of
        the other ranks' coarse blocks itself (``restrict_borrowed``)."""
        plans = self.plans(mesh, axis)
        restrictions = [(plans[f"restrict_{part}"], plans[f"restrict_{part}_weight"])]
        if part == "away":
            restrictions.append((plans["restrict_borrowed"], plans["restrict_borrowed_weight"]))
        for arr in fields:
            for rows, weights in restrictions:
                restrict_ghosts(arr, rows, weights)
        prolong_state_ghosts(fields, plans[f"prolong_{part}"], mesh.block_lo, mesh.block_dx, mesh.geometry_code,
                             mesh.ndim)

    def start_field_ghosts(self, field: np.ndarray, mesh, runs: tuple[slice, ...], wanted: np.ndarray,
                           layers: int | None = None) -> FieldFill:
        """Post the strips of the components of ``field`` that the ``runs`` (slices of its
        component axis) select along every used axis, every axis and run in one message per peer
        (:meth:`~.exchange.StripExchange.post`), and fill the ghosts of those components of the
        owned blocks from what this rank holds, axis by axis, then return while the strips
        travel: the inner blocks of :meth:`field_groups` have their ghosts complete.  The strips
        are interior cells and each axis's fill writes its own ghost slabs only, so one axis's
        strips need nothing from another's fill.  The slabs of the edge blocks that face another
        rank's block are filled again by :meth:`finish_field_ghosts`.

        On a uniform mesh (:attr:`field_routes`) the blocks where ``wanted[b]`` is not 0 get their
        ``layers`` layers next to the interior.  On an adaptive mesh every owned block gets every
        layer, and the message also carries the fine cells of other ranks' blocks that a
        restriction reads and the coarse cells that a fine ghost copies
        (:func:`~.decomposition.level_field_routes`, interior cells too); the rows of the
        coarse/fine plans whose source block this rank owns are applied here, the others by
        :meth:`finish_field_ghosts`."""
        axes = used_axes(mesh)
        if not mesh.adaptive:
            pending = self.field_strips.post((field,), self.traffic, runs)
            for axis in axes:
                g = int(mesh.ghost[axis])
                for run in runs:
                    fill_ghosts_where(field[:, run], mesh.neighbor, mesh.neighbor_level, axis, g, self.lo, self.hi,
                                      wanted, g if layers is None else layers)
            return FieldFill(axes, runs, wanted, layers, pending)
        if self._level_field_strips is None:
            self._level_field_strips = StripExchange(
                self.comm, level_field_routes(mesh, self.cuts, self.rank, self.routes), FIELD_TAG)
        pending = self._level_field_strips.post((field,), self.traffic, runs)
        for axis in axes:
            g = int(mesh.ghost[axis])
            plans = self.plans(mesh, axis)
            for run in runs:
                fill_ghosts(field[:, run], mesh.neighbor, mesh.neighbor_level, axis, g, -1, self.lo, self.hi)
                restrict_ghosts(field[:, run], plans["restrict_here"], plans["restrict_here_weight"])
                prolong_field_ghosts(field[:, run], plans["prolong_here"])
        return FieldFill(axes, runs, self.every_block, None, pending)

    def finish_field_ghosts(self, fill: FieldFill, field: np.ndarray, mesh) -> None:
        """Wait for the strips of :meth:`start_field_ghosts` and fill the edge blocks' slabs that
        face another rank's block, axis by axis and run by run
        (:func:`~impactpipe.hydro.mesh.boundary.fill_ghosts_from_ranks_where`); their other slabs
        keep what :meth:`start_field_ghosts` gave them.  On an adaptive mesh the rows of the
        coarse/fine plans whose source block another rank owns follow (``restrict_away`` and
        ``prolong_away`` of :meth:`plans`)."""
        if fill.pending is None:
            return
        finish_strips(fill.pending)
        for axis in fill.axes:
            g = int(mesh.ghost[axis])
            for run in fill.runs:
                fill_ghosts_from_ranks_where(field[:, run], mesh.neighbor, mesh.neighbor_level, axis, g,
                                             self.field_overlap[1], self.lo, self.hi, fill.wanted,
                                             g if fill.layers is None else fill.layers)
            if mesh.adaptive:
                plans = self.plans(mesh, axis)
                for run in fill.runs:
                    restrict_ghosts(field[:, run], plans["restrict_away"], plans["restrict_away_weight"])
                    prolong_field_ghosts(field[:, run], plans["prolong_away"])

    def field_groups(self, mesh) -> tuple[np.ndarray, np.ndarray]:
        """(early, late): the owned blocks whose ghosts a derived field's fill completes from this
        rank's cells alone, and the rest (:func:`~.decomposition.field_overlap_groups`)."""
        return self.field_overlap

    def plans(self, mesh, axis: int) -> dict:
        """This rank's rows of the coarse/fine plans of ``axis`` (destination blocks it owns) and
        the exchanges that bring the cells they read from other ranks' blocks.

        ``restrict`` (with ``restrict_weight``), ``prolong``, ``reflux`` (with ``reflux_volume``):
        the rows; ``restrict_here`` / ``restrict_away`` and ``prolong_here`` / ``prolong_away``
        (with their weights): those whose source block this rank owns / another rank owns (a
        fill applies the first before its strips arrive).  ``restrict_borrowed``
        (with its weights): rows of other ranks, the coarse ghosts of their blocks toward this
        rank's finer blocks that this rank's prolongation reads (:meth:`_borrowed_restriction`).
        ``level_strips``: before the state's fill (and the fill of its first ghost layer,
        :meth:`fill_first_ghost_layer`), the strips with the fine cells of the restriction and
        the coarse cells of the prolongation, in one message per peer
        (:func:`~.decomposition.level_state_routes`)."""
        if axis not in self._plans:
            whole = axis_plans(mesh, axis)
            owner = owners(self.cuts)
            mine = {}
            for name, weight in (("restrict", "restrict_weight"), ("prolong", None), ("reflux", "reflux_volume")):
                keep = owner[whole[name][:, 0]] == self.rank
                mine[name] = np.ascontiguousarray(whole[name][keep])
                if weight is not None:
                    mine[weight] = np.ascontiguousarray(whole[weight][keep])
            for name, weight in (("restrict", "restrict_weight"), ("prolong", None)):
                here = owner[mine[name][:, 4]] == self.rank
                for part, rows in (("here", here), ("away", ~here)):
                    mine[f"{name}_{part}"] = np.ascontiguousarray(mine[name][rows])
                    if weight is not None:
                        mine[f"{name}_{part}_weight"] = np.ascontiguousarray(mine[weight][rows])
            mine["restrict_borrowed"], mine["restrict_borrowed_weight"] = self._borrowed_restriction(
                mesh, axis, whole, mine["prolong_away"])
            mine["level_strips"] = StripExchange(
                self.comm, level_state_routes(mesh, self.cuts, self.rank, self.routes, axis), STRIP_TAG + axis)
            mine["reflux_pairs"] = (whole["reflux"][:, 0], whole["reflux"][:, 5])
            self._plans[axis] = mine
        return self._plans[axis]

    def _borrowed_restriction(self, mesh, axis: int, whole: dict, prolong_away: np.ndarray
                              ) -> tuple[np.ndarray, np.ndarray]:
        """(rows, weights) of the whole restriction plan of ``axis`` (``whole``) that set the coarse
        ghost cells which the rows ``prolong_away`` of this rank's prolongation read in other
        ranks' blocks: each coarse cell's neighbour along ``axis`` outside the interior, toward
        the finer block.  The coarse cell of a fine ghost lies next to the coarse/fine face, so
        that neighbour is restricted from the fine cells of the same finer block, this rank's:
        this rank restricts it itself, as its owner does, instead of receiving it after the
        owner's restriction, and the prolongation's cells can travel with the strips
        (:func:`~.decomposition.level_state_routes`).  A RuntimeError says if a row reads another
        rank's cells."""
        padded = np.array(mesh.padded_shape)
        per_block = int(padded.prod())
        g = int(mesh.ghost[axis])
        cells = prolong_away[:, 5:8].copy()
        cells[:, axis] += np.where(cells[:, axis] == g, -1, 1)
        outside = (cells[:, axis] < g) | (cells[:, axis] >= padded[axis] - g)

        def keys(blocks: np.ndarray, cells: np.ndarray) -> np.ndarray:
            """Flat indices of the padded ``cells`` (N, 3) of ``blocks`` (N,) in a field of one component."""
            return blocks * per_block + (cells[:, 0] * padded[1] + cells[:, 1]) * padded[2] + cells[:, 2]

        rows = np.isin(keys(whole["restrict"][:, 0], whole["restrict"][:, 1:4]),
                       keys(prolong_away[outside, 4], cells[outside]))
        borrowed = np.ascontiguousarray(whole["restrict"][rows])
        if (owners(self.cuts)[borrowed[:, 4]] != self.rank).any():
            raise RuntimeError("a coarse ghost that this rank's prolongation reads is restricted from another "
                               "rank's fine cells")
        return borrowed, np.ascontiguousarray(whole["restrict_weight"][rows])

    def share_face_flux(self, face_flux: np.ndarray, axis: int) -> None:
        """Receive, from their owners, the face-flux rows of the finer blocks beside this rank's
        coarse blocks (whole rows of ``face_flux`` (NB, 2, NQ, N1, N2))."""
        row = int(np.prod(face_flux.shape[2:]))
        key = (axis, row)
        if key not in self._flux_strips:
            coarse, fine = self._plans[axis]["reflux_pairs"]
            self._flux_strips[key] = StripExchange(self.comm, block_routes(self.cuts, self.rank, coarse, fine, row),
                                                   FLUX_TAG + axis)
        self._flux_strips[key].exchange((face_flux,), self.traffic)

    def fill_first_ghost_layer(self, state, mesh, axis: int) -> None:
        """The first ghost layer along ``axis`` of the owned blocks, the values
        :func:`~impactpipe.hydro.mesh.boundary.fill_first_ghost_layer` gives it: the strips along
        ``axis`` received from their owners (on an adaptive mesh in one message per peer with
        the fine cells of the restriction and the coarse cells of the prolongation,
        :meth:`_state_strips`), the same-level layer, then this rank's rows of the first-layer
        restriction and those of other ranks that its prolongation reads (``restrict_borrowed``
        of :meth:`_first_layer_plans`), and its rows of the first-layer prolongation.  The
        prolongation along ``axis`` reads no first-layer ghost that this fill writes but those
        restrictions: the ghosts along the other axes come from their fills before."""
        self.finish_first_ghost_layer(self.start_first_ghost_layer(state, mesh, axis), state, mesh, axis)

    def start_first_ghost_layer(self, state, mesh, axis: int) -> FirstLayerFill:
        """Post the strips of :meth:`fill_first_ghost_layer` and fill the owned blocks' same-level
        layer from what this rank holds, then return while the strips travel: the blocks of
        the fill's ``late`` (:meth:`_first_layer_late`: beside another rank's block along
        ``axis``, or written by a coarse/fine row) wait for :meth:`finish_first_ghost_layer`,
        the others' layer along ``axis`` is complete."""
        g = int(mesh.ghost[axis])
        if g == 0:
            return FirstLayerFill(np.zeros(0, dtype=np.int64))
        fields = (state.alpha, state.arho, state.arhoe, state.momentum, state.energy, state.arhoq)
        pending = self._state_strips(mesh, axis).post(fields, self.traffic)
        fill_state_ghost_layer(*fields, mesh.neighbor, mesh.neighbor_level, axis, g, self.lo, self.hi)
        return FirstLayerFill(self._first_layer_late(mesh, axis), pending)

    def finish_first_ghost_layer(self, fill: FirstLayerFill, state, mesh, axis: int) -> None:
        """Wait for the strips of :meth:`start_first_ghost_layer`, fill the late blocks' slabs of
        the same-level layer beside other ranks' blocks from them
        (:func:`~impactpipe.hydro.mesh.boundary.fill_state_ghost_layer_from_ranks`), then the
        coarse/fine rows of :meth:`fill_first_ghost_layer`."""
        if fill.pending is None:
            return
        finish_strips(fill.pending)
        g = int(mesh.ghost[axis])
        fields = (state.alpha, state.arho, state.arhoe, state.momentum, state.energy, state.arhoq)
        fill_state_ghost_layer_from_ranks(*fields, mesh.neighbor, mesh.neighbor_level, axis, g, fill.late, self.lo,
                                          self.hi)
        if not mesh.adaptive:
            return
        first = self._first_layer_plans(mesh, axis)
        restrict_state_ghosts(fields, first["restrict"], first["restrict_weight"])
        restrict_state_ghosts(fields, first["restrict_borrowed"], first["restrict_borrowed_weight"])
        prolong_state_ghosts(fields, first["prolong"], mesh.block_lo, mesh.block_dx, mesh.geometry_code, mesh.ndim)

    def _first_layer_late(self, mesh, axis: int) -> np.ndarray:
        """The owned blocks (int64 block numbers) whose first ghost layer along ``axis`` a fill
        completes only with other ranks' strips: beside another rank's block along ``axis``, or,
        on an adaptive mesh, the destination of a row of this rank's first-layer plans (kept)."""
        key = ("first_layer_late", axis)
        if key not in self._plans:
            neighbours = mesh.neighbor[self.lo:self.hi, axis, :]
            late = ((neighbours >= 0) & ((neighbours < self.lo) | (neighbours >= self.hi))).any(axis=1)
            if mesh.adaptive:
                first = self._first_layer_plans(mesh, axis)
                late[first["restrict"][:, 0] - self.lo] = True
                late[first["prolong"][:, 0] - self.lo] = True
            self._plans[key] = np.flatnonzero(late).astype(np.int64) + self.lo
        return self._plans[key]

    def _first_layer_plans(self, mesh, axis: int) -> dict:
        """This rank's rows (destination blocks it owns) of the first-layer plans of ``axis``
        (:func:`~impactpipe.hydro.amr.plans.first_layer_plans`), and ``restrict_borrowed`` (with
        its weights): the rows that set the other ranks' coarse ghosts which this rank's
        first-layer prolongation reads (:meth:`_borrowed_restriction`), kept."""
        key = ("first_layer", axis)
        if key not in self._plans:
            whole = first_layer_plans(mesh, axis)
            owner = owners(self.cuts)
            mine = {}
            for name, weight in (("restrict", "restrict_weight"), ("prolong", None)):
                keep = owner[whole[name][:, 0]] == self.rank
                mine[name] = np.ascontiguousarray(whole[name][keep])
                if weight is not None:
                    mine[weight] = np.ascontiguousarray(whole[weight][keep])
            away = mine["prolong"][owner[mine["prolong"][:, 4]] != self.rank]
            mine["restrict_borrowed"], mine["restrict_borrowed_weight"] = self._borrowed_restriction(
                mesh, axis, whole, away)
            self._plans[key] = mine
        return self._plans[key]

    def regrid(self, sim, plan: dict, new_mesh=None) -> tuple:
        """(new mesh, new state, new partition) of ``sim`` after the regrid ``plan`` (the same on
        every rank; onto ``new_mesh`` where given, else the mesh of the plan's leaves), no rank
        holding more than its own blocks and halo before and after.

        The new blocks are cut by their estimated cost (:func:`~.decomposition.owned_ranges` of
        :func:`~impactpipe.hydro.amr.regrid.planned_costs`: the old blocks' costs,
        :func:`~.decomposition.block_costs`, each computed by its owner and shared, carried over
        to the new blocks made from them).  Each rank receives from their old owners the old
        blocks, ghosts included, that its new blocks are made from
        (:func:`~impactpipe.hydro.amr.regrid.plan_sources`; one Alltoallv per field,
        :func:`~.exchange.move_rows`, into the old arrays' rows), builds its own new blocks in
        arrays of :meth:`zeros` of the new partition
        (:func:`~impactpipe.hydro.amr.regrid.moved_state`) and fills their first ghost layer on
        every axis through the new partition's exchanges (:meth:`fill_first_ghost_layer`)."""
        mesh, state = sim.mesh, sim.state
        if new_mesh is None:
            new_mesh = planned_mesh(mesh, plan)
        costs = np.zeros(mesh.nblocks, dtype=np.int64)
        costs[self.blocks] = block_costs(mesh, state.alpha[self.blocks])
        self.share_rows(costs)
        cuts = owned_ranges(planned_costs(plan, costs, mesh.ndim), self.comm.size)
        new = BlockRanges(self.comm, new_mesh, cuts)
        new.traffic = self.traffic
        owner = owners(self.cuts)
        needed = [plan_sources(plan, int(cuts[r]), int(cuts[r + 1])) for r in range(self.comm.size)]
        sent = [blocks[owner[blocks] == self.rank] if r != self.rank else blocks[:0] for r, blocks in
                enumerate(needed)]
        mine = needed[self.rank]
        received = [mine[owner[mine] == r] if r != self.rank else mine[:0] for r in range(self.comm.size)]
        started = time.perf_counter()
        move_rows(self.comm, [getattr(state, name) for name in FIELDS], sent, received)
        self.traffic.gathers += 1
        self.traffic.gather_seconds += time.perf_counter() - started
        new_state = moved_state(mesh, new_mesh, state, plan, new.lo, new.hi, new.zeros)
        for axis in range(new_mesh.ndim):
            new.fill_first_ghost_layer(new_state, new_mesh, axis)
        return new_mesh, new_state, new

    def summed_rows(self, counters: np.ndarray, nblocks: int) -> np.ndarray:
        """Per-block ``counters`` (NB, ...) for a new mesh of ``nblocks`` blocks, their totals in
        row 0 on every rank, the single process's bit for bit: rank 0 receives every rank's rows
        (:meth:`rows_at_root`) and sums them in block order
        (:func:`~impactpipe.hydro.amr.regrid.summed_rows`), then broadcasts the totals."""
        whole = self.rows_at_root(counters)
        total = self.comm.bcast(summed_rows(whole, 1)[0] if self.is_root else None, root=0)
        out = np.zeros((nblocks,) + counters.shape[1:], dtype=counters.dtype)
        out[0] = total
        return out

    def any(self, flag: bool) -> bool:
        """Whether ``flag`` holds on some rank (one allreduce, LOR)."""
        from mpi4py import MPI

        started = time.perf_counter()
        found = bool(self.comm.allreduce(bool(flag), op=MPI.LOR))
        self._count_allreduce(started)
        return found

    def largest(self, value: float) -> float:
        """The largest of ``value`` over the ranks (one allreduce, MAX)."""
        from mpi4py import MPI

        started = time.perf_counter()
        largest = float(self.comm.allreduce(value, op=MPI.MAX))
        self._count_allreduce(started)
        return largest

    def sum_integers(self, array: np.ndarray) -> None:
        """Sum the int64 ``array`` over the ranks, in place (one allreduce, SUM)."""
        from mpi4py import MPI

        started = time.perf_counter()
        self.comm.Allreduce(MPI.IN_PLACE, array, op=MPI.SUM)
        self._count_allreduce(started)

    def combine_rate(self, rate: float, first_bad: int) -> tuple[float, int]:
        """One Allreduce (MAX) of (rate, -first bad block): the serial run's values exactly."""
        from mpi4py import MPI

        values = np.array([rate if first_bad < 0 else 0.0, -float(first_bad if first_bad >= 0 else self.nblocks)])
        started = time.perf_counter()
        self.comm.Allreduce(MPI.IN_PLACE, values, op=MPI.MAX)
        self._count_allreduce(started)
        bad = int(-values[1])
        return float(values[0]), bad if bad < self.nblocks else -1

    def first_failure(self, failure: np.ndarray) -> int:
        """The first failed block over every rank (one allreduce, MIN), or -1."""
        from mpi4py import MPI

        local = super().first_failure(failure[self.blocks])
        started = time.perf_counter()
        first = self.comm.allreduce(self.lo + local if local >= 0 else self.nblocks, op=MPI.MIN)
        self._count_allreduce(started)
        return first if first < self.nblocks else -1

    def _count_allreduce(self, started: float) -> None:
        """Count one allreduce that began at ``started`` (``time.perf_counter()``, s) in ``traffic``."""
        self.traffic.allreduces += 1
        self.traffic.allreduce_seconds += time.perf_counter() - started

    def from_owner(self, block: int, make: Callable[[], Any]) -> Any:
        owner = int(np.searchsorted(self.cuts, block, side="right")) - 1
        return self.comm.bcast(make() if self.comm.rank == owner else None, root=owner)

    def carry_through(self, first: Any, step: Callable[[Any], Any]) -> tuple[Any, Any]:
        """Rank r receives rank r - 1's result, runs ``step`` and sends its own to rank r + 1; the
        last rank's is broadcast."""
        given = first if self.rank == 0 else self.comm.recv(source=self.rank - 1, tag=CARRY_TAG)
        result = step(given)
        if self.rank + 1 < self.comm.size:
            self.comm.send(result, dest=self.rank + 1, tag=CARRY_TAG)
        return given, self.comm.bcast(result, root=self.comm.size - 1)

    def agree(self, value: Any) -> Any:
        return self.comm.bcast(value, root=0)

    def share_rows(self, array: np.ndarray) -> None:
        """Every rank receives every rank's rows of ``array`` (one Allgatherv)."""
        share_owned_blocks(self.comm, [array], self.cuts, self.traffic)

    def gather_to_root(self, arrays: list[np.ndarray]) -> None:
        """Rank 0 receives every rank's rows of ``arrays`` (one Gatherv each,
        :func:`~.exchange.gather_owned_blocks`)."""
        gather_owned_blocks(self.comm, arrays, self.cuts, self.traffic)

    def output_file(self, path, mode: str) -> h5py.File:
        if self.writes_together:
            return h5py.File(path, mode, driver="mpio", comm=self.comm)
        return h5py.File(path, mode)

    def atomic_output(self, path):
        return atomic_path_together(path, self.comm) if self.writes_together else atomic_path(path)

    def zeros(self, shape: tuple[int, ...]) -> np.ndarray:
        """Zeros in :func:`~.owned_memory.lazy_zeros`, whose pages outside this rank's rows are
        committed only if written."""
        return lazy_zeros(shape, dense_rows=(self.lo, self.hi))

    def rows_at_root(self, array: np.ndarray) -> np.ndarray | None:
        """Rank 0: a new array (:func:`~.owned_memory.lazy_zeros`) holding every rank's rows of
        ``array`` (NB, ...), received in one Gatherv (:func:`~.exchange.gather_owned_blocks`);
        ``array`` itself is unchanged.  The other ranks send their rows and get None."""
        whole = lazy_zeros(array.shape, array.dtype, (0, self.nblocks)) if self.is_root else array
        if self.is_root:
            whole[self.blocks] = array[self.blocks]
        gather_owned_blocks(self.comm, [whole], self.cuts, self.traffic)
        return whole if self.is_root else None

    def block_owners(self, blocks: np.ndarray, out: np.ndarray) -> None:
        """``out[t]``: the rank whose range holds block ``blocks[t]``, -1 where ``blocks[t]`` is -1."""
        np.subtract(np.searchsorted(self.cuts, blocks, side="right"), 1, out=out)

    def share_neighbourhood(self, state) -> None:
        """Receive the interior cells of other ranks' blocks within TRACER_REACH of this rank's
        blocks (faces, edges, corners; :func:`~.decomposition.neighbourhood_routes`): the fields
        the tracers read (volume fractions, partial densities and internal energies, momentum)."""
        self.neighbourhood_strips.exchange((state.alpha, state.arho, state.arhoe, state.momentum), self.traffic)

    def hand_over(self, destination: np.ndarray, arrays: list[np.ndarray]) -> list[np.ndarray] | None:
        """Row t of each of ``arrays`` to rank ``destination[t]``; returns the rows this rank holds
        afterwards, None where none came or went (collective; one Alltoall of the counts and a
        message to and from each rank rows go to or come from, :func:`~.exchange.hand_over_rows`,
        counted in :attr:`traffic`)."""
        started = time.perf_counter()
        held = hand_over_rows(self.comm, destination, arrays)
        self.traffic.handovers += 1
        self.traffic.items_handed_over += int(np.count_nonzero(destination != self.rank))
        self.traffic.handover_seconds += time.perf_counter() - started
        return held

    def gather_items(self, arrays: list[np.ndarray], everywhere: bool = False) -> list[np.ndarray] | None:
        """Every rank's rows of per-item arrays side by side, by rank, on rank 0 (on every rank
        with ``everywhere``), None elsewhere (collective, :func:`~.exchange.gather_item_rows`)."""
        return gather_item_rows(self.comm, arrays, everywhere)


#: Set to "0" to have the ranks gather each snapshot and checkpoint on rank 0 even where h5py
#: has parallel HDF5 (:func:`parallel_hdf5`).
PARALLEL_HDF5_VARIABLE = "IMPACTPIPE_PARALLEL_HDF5"


def parallel_hdf5() -> bool:
    """Whether the ranks of a run write its snapshots and checkpoints together, each its own
    blocks' rows into the one file (h5py's mpio driver): where h5py was built with parallel
    HDF5, unless the environment sets PARALLEL_HDF5_VARIABLE to "0".  Then rank 0 never holds
    the whole state for an output; otherwise it receives every block for each one."""
    return bool(h5py.get_config().mpi) and os.environ.get(PARALLEL_HDF5_VARIABLE, "1") != "0"


def unsupported(mesh, nranks: int) -> list[str]:
    """Why a run on ``mesh`` cannot share it between ``nranks`` ranks in this version (empty when it can)."""
    reasons = []
    if nranks > mesh.nblocks:
        reasons.append(f"more ranks ({nranks}) than blocks ({mesh.nblocks})")
    return reasons


def refuse(reasons: list[str]) -> None:
    """Raise ValueError with the ``reasons`` of :func:`unsupported`, if any."""
    if reasons:
        raise ValueError(f"several MPI ranks: not supported in this version: {'; '.join(reasons)} "
                         f"(run with one rank)")


def distribute_from_root(sim, comm):
    """Share rank 0's ``sim`` between the ranks of ``comm`` (collective) and return this rank's
    Simulation; ``sim`` is None on the other ranks: only rank 0 builds the run.

    Rank 0 broadcasts the :func:`~.owned_memory.outline` of ``sim`` (everything but its arrays
    of cells), from which each other rank builds its Simulation with arrays of zeros that hold
    no memory yet; then :func:`distribute`.  A rank other than 0 thus never holds the whole
    state: its memory at the start is its own blocks, its halo and the mesh's per-block
    tables.  Raises ValueError on every rank, before anything else moves, for what
    this version does not distribute (:func:`unsupported`)."""
    refuse(comm.bcast(unsupported(sim.mesh, comm.size) if comm.rank == 0 else None, root=0))
    described = comm.bcast(outline(sim) if comm.rank == 0 else None, root=0)
    if comm.rank != 0:
        sim = from_outline(described)
    del described
    distribute(sim, comm)
    return sim


def distribute(sim, comm) -> None:
    """Share ``sim`` between the ranks of ``comm`` (collective; every rank holds the same run:
    built there too, or from rank 0's outline, :func:`distribute_from_root`).

    Rank 0's counters and tracers are broadcast, the blocks cut by the estimated cost of rank
    0's state (:func:`~.decomposition.owned_ranges`) and ``sim.partition`` set.  Each rank then
    holds only its own blocks of rank 0's state and the cells its exchanges write
    (:func:`~.owned_memory.receive_owned_blocks`), uniform or adaptive mesh (whose regrids keep
    it so, :meth:`BlockRanges.regrid`); what it built of the state is dropped unread.  Raises
    ValueError for what this version does not distribute (:func:`unsupported`) before anything
    moves.
    """
    refuse(unsupported(sim.mesh, comm.size))
    broadcast_arrays(comm, list(sim._counter_arrays()))
    sim.tracers = comm.bcast(sim.tracers, root=0)
    if sim.tracers is not None:
        sim.tracers.held_by_every_process()
    cuts = comm.bcast(owned_ranges(block_costs(sim.mesh, sim.state.alpha), comm.size) if comm.rank == 0 else None,
                      root=0)
    sim.partition = BlockRanges(comm, sim.mesh, cuts)
    receive_owned_blocks(sim, sim.partition)
    sim._keep_good()
    log_cuts(comm, cuts)


def shared_simulation(comm, mesh, initial_state: Callable, build: Callable):
    """A new run built by the ranks of ``comm`` together (collective), each setting its own
    blocks only, so that no rank ever holds the whole state; returns this rank's Simulation.

    ``initial_state(mesh, blocks)`` sets the problem's :class:`~impactpipe.hydro.mesh.state.HydroState`
    on the blocks ``blocks`` (a slice) of ``mesh`` alone (an array of those blocks' rows, for
    instance on :meth:`~impactpipe.hydro.mesh.blocks.BlockMesh.some_blocks`, whatever the
    other blocks hold); ``build(state, partition)`` makes the Simulation over ``mesh``
    (collective: :class:`~impactpipe.hydro.solver.Simulation` with ``partition``).  The blocks
    are cut as :func:`distribute` cuts a whole state, by the costs of the volume fractions
    (:func:`~.decomposition.owned_ranges`), which each rank first computes on an equal share of
    the blocks; each rank then sets its own blocks and keeps them in :func:`~.owned_memory.lazy_zeros`
    arrays of the whole mesh's shape, builds the Simulation and receives its halo.  Raises
    ValueError on every rank for what this version does not distribute (:func:`unsupported`)."""
    refuse(unsupported(mesh, comm.size))
    even = np.arange(comm.size + 1) * mesh.nblocks // comm.size
    costs = block_costs(mesh, initial_state(mesh, slice(even[comm.rank], even[comm.rank + 1])).alpha)
    cuts = owned_ranges(np.concatenate(comm.allgather(costs)), comm.size)
    partition = BlockRanges(comm, mesh, cuts)
    own = initial_state(mesh, partition.blocks)
    state = HydroState(**{name: placed_rows(array, partition) for name, array in own.arrays().items()})
    del own
    sim = build(state, partition)
    receive_halos(sim, partition)
    log_cuts(comm, cuts)
    return sim


def log_cuts(comm, cuts: np.ndarray) -> None:
    """Rank 0 logs each rank's blocks."""
    if comm.rank == 0:
        log.info("hydro on %d MPI ranks: blocks %s", comm.size,
                 ", ".join(f"{lo}-{hi - 1}" for lo, hi in zip(cuts[:-1], cuts[1:])))


#: Blocks whose volume fractions rank 0 reads at a time for the costs of :func:`checkpoint_partition`.
COST_CHUNK_BLOCKS = 256


def checkpoint_partition(comm, mesh, alpha) -> BlockRanges:
    """The ranks' :class:`BlockRanges` of a checkpoint's ``mesh`` (collective): the blocks cut as
    :func:`distribute` cuts them, by the costs of the saved volume fractions (the HDF5 dataset
    ``alpha``, (NB, M, NX, NY, NZ)), which rank 0 reads :data:`COST_CHUNK_BLOCKS` blocks at a time
    and broadcasts.  Raises ValueError on every rank for what this version does not distribute
    (:func:`unsupported`)."""
    refuse(unsupported(mesh, comm.size))
    cuts = None
    if comm.rank == 0:
        costs = np.concatenate([block_costs(mesh, alpha[lo : lo + COST_CHUNK_BLOCKS])
                                for lo in range(0, mesh.nblocks, COST_CHUNK_BLOCKS)])
        cuts = owned_ranges(costs, comm.size)
    cuts = comm.bcast(cuts, root=0)
    log_cuts(comm, cuts)
    return BlockRanges(comm, mesh, cuts)


def collect_counters(sim) -> None:
    """End a shared run without gathering its state (collective): rank 0 receives every block's
    counters (boundary, floors, amounts, porosity and strength counts), from which it reports
    the floors; the state stays with its owners.  With :meth:`~impactpipe.hydro.solver.Simulation.totals`
    (collective too, before this) it is what the end of a pipeline run needs, so rank 0 never
    gathers the whole state.  Rank 0 receives the tracers too (in their order), and the other
    ranks drop theirs.  Nothing to do on one process."""
    sim.partition.gather_to_root(list(sim._counter_arrays()))
    if sim.tracers is not None:
        sim.tracers = sim.tracers.assembled(sim.partition)


def collect(sim) -> None:
    """End the sharing (collective): rank 0 receives every block (state, ghosts included, and
    counters) and runs as a single process again.  The other ranks send their blocks and are
    done with ``sim``: it holds only their own blocks (so that no rank but the one that writes
    ever holds the whole state), and its partition is None."""
    partition = sim.partition
    partition.gather_to_root(list(sim.state.arrays().values()) + list(sim._counter_arrays()))
    if sim.tracers is not None:
        sim.tracers = sim.tracers.assembled(partition)
    sim.partition = WholeMesh() if partition.is_root else None
