"""Local time stepping per refinement level (subcycling, Berger & Colella 1989) on the leaf-block mesh.

With ``time_stepping = "per_level"`` a :class:`~impactpipe.hydro.solver.Simulation` step is one
step dt_0 of the root level, and level l advances in 2^l substeps of

    dt_l = dt_0 / 2^l,   dt_0 = min over the levels holding blocks of 2^l cfl / rate_l

(rate_l the largest (|u_d| + c) / dx_d of level l's cells, 1/s), so every level meets its own
CFL condition and a coarse cell is updated once where the global step updates it 2^l times.
The levels advance recursively, coarse first (refinement ratio 2):

    advance(l, dt, theta):  sweep level l's blocks by dt (ghosts filled for level l, the coarser
                            level l - 1 at the fraction theta of its own step), then their
                            strength step by dt when the scene has strength;
                            advance(l + 1, dt / 2, 0); advance(l + 1, dt / 2, 1/2);
                            reflux the level-l cells beside level l + 1 (flux registers).

The mesh holds leaves only (no covered coarse cells), so nothing is restricted onto level l
after its finer level's substeps; the finer level's amounts enter the coarse cells beside it
through the flux registers (:func:`~impactpipe.hydro.amr.transfer.register_fluxes`,
:func:`~impactpipe.hydro.amr.transfer.reflux_register`): per coarse face cell and sweep axis the
fine amounts dt_f A_f F_f of both substeps less the coarse dt_c A_c F_c, so what crossed every
coarse/fine face is the same amount on both sides and the totals are kept to round-off: the
fine amount, or, where that would drive a material of the coarse cell below zero, the share of
it that does not (the fine cells beside the face, then the cells around the coarse cell,
taking the rest as far as they hold it).  A root step whose end state allows a step more
than LEVEL_STEP_GROWTH shorter is taken again (:meth:`~impactpipe.hydro.solver.Simulation._level_step`).

Ghosts of level l along the sweep axis (:meth:`LevelStepper.fill_level_ghosts`): copies from the
same level's blocks, restriction from level l + 1 (which is at level l's time when level l
sweeps), and prolongation from level l - 1 at the time t_l of the substep, the coarse cells the
prolongation reads taken linearly in time between their values before (U_old) and after
(U_new) level l - 1's step:

    U(t_l) = U_old + theta (U_new - U_old),   theta = (t_l - t_(l-1)) / dt_(l-1) in {0, 1/2}

(one theta per substep, for all its sweeps).  Only those coarse cells are kept and
interpolated (:func:`level_plans`, ``interpolated``): the coarse cells holding a ghost of level l
and their face neighbours inside the same block.  A convex combination of two states keeps the
densities, volume fractions and internal energy (concave in the conserved amounts) positive.

With material strength each substep of level l is followed by the strength step of level l's
blocks (:meth:`LevelStepper._strength_step`): kick dt_l / 2, stress update dt_l, kick dt_l / 2
(:mod:`impactpipe.hydro.strength.model`), the work arrays' ghosts filled from the same level,
from level l + 1 (its state at the substep's start) and from level l - 1 (its interpolated cells
at theta); the kicks' momentum and energy amounts through coarse/fine faces enter the same flux
registers as the sweeps', so the stress impulse through a level face is kept exactly too.

The split sweeps alternate their order per substep: the n-th substep of level l (n counted from
the start of the run, 2^l per root step) sweeps x y z for even n and z y x for odd n, so a
level's pair of substeps is Strang-symmetric and the order follows from the step count alone
(a restart continues bit for bit).  On one level this is the global step, bit for bit.

Tracers (:mod:`impactpipe.hydro.tracers.motion`) move once per root step, by Heun with the
velocity field at the root step's start and end (second order in dt_0, as the global step's
Heun is in its dt).  Their peak pressure and temperature are recorded at the root step's end
and, in between, after each substep of level l >= 1 (once its finer levels and its reflux
are done, so level l and the finer levels are at the substep's end time t_n + s) for the
tracers whose point x_n + s v_n(x_n) on the predicted path lies in a level-l block: a tracer
in fine blocks is sampled as often as the global step samples it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from impactpipe.hydro.amr.plans import axis_plans
from impactpipe.hydro.amr.transfer import (P_DST, P_SRC, P_SX, P_SY, P_SZ, R_COARSE, R_CX, R_CY, R_CZ, R_FINE, R_F1,
                                           R_F2, R_SIDE, prolong_state_ghosts, register_fluxes, reflux_register,
                                           restrict_state_ghosts)
from impactpipe.hydro.mesh.blocks import GHOST, REFLECTING, BlockMesh
from impactpipe.hydro.mesh.boundary import NO_RECORD, every_layer, fill_state_ghost_slabs_of
from impactpipe.hydro.mesh.scalar_stamps import NO_STAMPS
from impactpipe.hydro.scheme.directional import sweep
from impactpipe.hydro.strength.model import LevelBlocks

#: Half width (cells) of the box around a register row's coarse cell whose cells take what
#: neither side of the face holds of its correction (:func:`_near_cells`).
NEAR_RADIUS = 2

#: The ``time_stepping`` modes: one step for all levels, or a step per level.
GLOBAL = "global"
PER_LEVEL = "per_level"
TIME_STEPPING = (GLOBAL, PER_LEVEL)


def level_plans(mesh: BlockMesh) -> dict:
    """Each level's blocks and ghost plans, cached on the mesh.

    ``blocks[l]``: the blocks of level l (int64); for each sweep axis a and level l,
    ``restrict[a, l]`` / ``restrict_weight[a, l]``: the rows of the axis's restrict plan
    (:func:`~impactpipe.hydro.amr.plans.axis_plans`) that fill level l's ghosts from level l + 1
    or level (l - 1)'s ghosts from level l (the prolongation into level l reads them);
    ``prolong[a, l]``: its prolong rows into level l's ghosts; ``interpolated[l]``: (N, 4) rows
    (block, padded cell) of the level-(l - 1) interior cells that any axis's prolongation into
    level l reads (a source cell and its face neighbours), the cells taken at the substep's time;
    ``fine_faces[a]``: the fine cells beside each coarse face cell of the reflux plan
    (:func:`_fine_face_cells`), which take what the coarse cell cannot of a register correction,
    and ``near[a]`` the cells around the coarse cell in its block (:func:`_near_cells`), which
    take what neither holds.
    """
    key = "level_plans"
    if key in mesh.cache:
        return mesh.cache[key]
    levels = mesh.max_level + 1
    level = mesh.block_level
    out = {"blocks": [np.flatnonzero(level == lv).astype(np.int64) for lv in range(levels)],
           "restrict": {}, "restrict_weight": {}, "prolong": {}}
    sources = [[] for _ in range(levels)]
    for axis in range(mesh.ndim if mesh.adaptive else 0):
        plans = axis_plans(mesh, axis)
        restrict, prolong = plans["restrict"], plans["prolong"]
        into, onto = level[restrict[:, P_DST]], level[restrict[:, P_SRC]]
        for lv in range(levels):
            rows = (into == lv) | (onto == lv)
            out["restrict"][axis, lv] = np.ascontiguousarray(restrict[rows])
            out["restrict_weight"][axis, lv] = np.ascontiguousarray(plans["restrict_weight"][rows])
            rows = level[prolong[:, P_DST]] == lv
            out["prolong"][axis, lv] = np.ascontiguousarray(prolong[rows])
            sources[lv].append(prolong[rows][:, [P_SRC, P_SX, P_SY, P_SZ]])
    out["interpolated"] = [_stencil_cells(mesh, np.concatenate(rows) if rows else np.zeros((0, 4), np.int64))
                           for rows in sources]
    out["fine_faces"] = [_fine_face_cells(mesh, axis) for axis in range(mesh.ndim if mesh.adaptive else 0)]
    out["near"] = [_near_cells(mesh, axis) for axis in range(mesh.ndim if mesh.adaptive else 0)]
    mesh.cache[key] = out
    return out


def _fine_face_cells(mesh: BlockMesh, axis: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each row e of the reflux plan of ``axis``, the 2^(ndim-1) fine cells beside the coarse
    face cell: (cells (E, J, 4) block and padded cell, volumes (E, J) m^3, weights (E, J) the shares
    of the coarse face's area, 1/2^(ndim-1), or the annuli's in 2d-cylindrical along z)."""
    plan = axis_plans(mesh, axis)["reflux"]
    t1 = 1 if axis == 0 else 0
    t2 = 1 if axis == 2 else 2
    offsets = [(a, c) for a in range(2 if mesh.ndim > 1 else 1) for c in range(2 if mesh.ndim > 2 else 1)]
    cells = np.zeros((len(plan), len(offsets), 4), dtype=np.int64)
    cells[:, :, 0] = plan[:, R_FINE, None]
    low_side = plan[:, R_SIDE] == 0  # the fine block lies below the coarse cell: its last layer
    cells[:, :, 1 + axis] = np.where(low_side, GHOST + mesh.block_cells - 1, GHOST)[:, None]
    for j, (a, c) in enumerate(offsets):
        if mesh.ndim > 1:
            cells[:, j, 1 + t1] = plan[:, R_F1] + a
        if mesh.ndim > 2:
            cells[:, j, 1 + t2] = plan[:, R_F2] + c
    interior = np.where(np.arange(3) < mesh.ndim, cells[:, :, 1:] - GHOST, 0)
    volume = mesh.cell_volumes()[cells[:, :, 0], interior[:, :, 0], interior[:, :, 1], interior[:, :, 2]]
    weight = np.full(volume.shape, 1.0 / len(offsets))
    if mesh.geometry == "2d-cylindrical" and axis == 1 and len(plan):
        r_lo = mesh.block_lo[cells[:, :, 0], 0] + interior[:, :, 0] * mesh.block_dx[cells[:, :, 0], 0]
        ring = (r_lo + mesh.block_dx[cells[:, :, 0], 0]) ** 2 - r_lo ** 2
        weight = ring / ring.sum(axis=1, keepdims=True)
    return cells, volume, weight


def _near_cells(mesh: BlockMesh, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """For each row e of the reflux plan of ``axis``, the interior cells of the coarse cell's block
    within NEAR_RADIUS cells of it along every used axis (itself included): (cells (E, N, 4) block
    and padded cell, block -1 where the box leaves the block, volumes (E, N) m^3, 0 there).  They
    take what neither side of the face holds of a register correction
    (:func:`~impactpipe.hydro.amr.transfer.reflux_register`)."""
    plan = axis_plans(mesh, axis)["reflux"]
    span = np.arange(-NEAR_RADIUS, NEAR_RADIUS + 1)
    offsets = np.stack(np.meshgrid(*([span] * mesh.ndim), indexing="ij"), axis=-1).reshape(-1, mesh.ndim)
    cells = np.zeros((len(plan), len(offsets), 4), dtype=np.int64)
    cells[:, :, 0] = plan[:, R_COARSE, None]
    cells[:, :, 1:] = plan[:, None, [R_CX, R_CY, R_CZ]]
    cells[:, :, 1:1 + mesh.ndim] += offsets[None, :, :]
    inside = np.ones(cells.shape[:2], dtype=bool)
    for d in range(mesh.ndim):
        inside &= (cells[:, :, 1 + d] >= GHOST) & (cells[:, :, 1 + d] < GHOST + mesh.block_cells)
    interior = np.where(np.arange(3) < mesh.ndim, cells[:, :, 1:] - GHOST, 0)
    interior[~inside] = 0
    volume = np.where(inside, mesh.cell_volumes()[cells[:, :, 0], interior[:, :, 0], interior[:, :, 1],
                                                  interior[:, :, 2]], 0.0)
    cells[~inside, 0] = -1
    return cells, volume


def _stencil_cells(mesh: BlockMesh, cells: np.ndarray) -> np.ndarray:
    """(N, 4) unique (block, padded cell) of ``cells`` and their face neighbours along the used
    axes that are interior cells of the same block: what a prolongation from ``cells`` reads.
    The rows come sorted as (block, cell) tuples: the unique flat indices of the cells in an
    array of shape (blocks,) + padded block shape, a sort of int64 keys rather than of rows."""
    shape = (mesh.nblocks,) + mesh.padded_shape
    inside = np.ones(len(cells), dtype=bool)
    for axis in range(mesh.ndim):
        inside &= (cells[:, 1 + axis] >= GHOST) & (cells[:, 1 + axis] < GHOST + mesh.block_cells)
    cells = cells[inside]
    flat = np.ravel_multi_index(tuple(cells.T), shape)
    keys = [flat]
    for axis in range(mesh.ndim):
        stride = int(np.prod(shape[2 + axis:]))
        for step in (-1, 1):
            moved = cells[:, 1 + axis] + step
            keys.append(flat[(moved >= GHOST) & (moved < GHOST + mesh.block_cells)] + step * stride)
    return np.column_stack(np.unravel_index(np.unique(np.concatenate(keys)), shape)).astype(np.int64)


def strength_levels(mesh: BlockMesh) -> list[tuple[LevelBlocks, np.ndarray, np.ndarray]]:
    """Per level l, cached on the mesh: (its :class:`~impactpipe.hydro.strength.model.LevelBlocks`,
    the level-(l + 1) blocks its work ghosts restrict from, the level-(l - 1) blocks they copy
    from; int64): what a strength step of level l alone reads (:meth:`LevelStepper._strength_step`)."""
    key = "strength_levels"
    if key in mesh.cache:
        return mesh.cache[key]
    plans = level_plans(mesh)
    level = mesh.block_level
    out = []
    for lv, blocks in enumerate(plans["blocks"]):
        mask = np.zeros(mesh.nblocks, dtype=np.uint8)
        mask[blocks] = 1
        restrict, prolong = {}, {}
        finer, coarser = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
        for axis in range(mesh.ndim if mesh.adaptive else 0):
            rows = plans["restrict"][axis, lv]
            into = level[rows[:, P_DST]] == lv
            restrict[axis] = (np.ascontiguousarray(rows[into]),
                              np.ascontiguousarray(plans["restrict_weight"][axis, lv][into]))
            prolong[axis] = plans["prolong"][axis, lv]
            finer.append(rows[into, P_SRC])
            coarser.append(prolong[axis][:, P_SRC])
        walls = {(axis, side): blocks[mesh.neighbor[blocks, axis, side] == REFLECTING]
                 for axis in range(mesh.ndim) for side in (0, 1)}
        out.append((LevelBlocks(blocks, mask, restrict, prolong, walls),
                    np.unique(np.concatenate(finer)).astype(np.int64),
                    np.unique(np.concatenate(coarser)).astype(np.int64)))
    mesh.cache[key] = out
    return out


def level_time_step(mesh: BlockMesh, rates: np.ndarray, cfl: float) -> float:
    """dt_0 (s): the root step whose level-l substeps dt_0 / 2^l keep every level's own CFL
    condition, min over the levels with a signal of 2^l cfl / rate_l (``rates`` per block, 1/s)."""
    dt = np.inf
    for lv, blocks in enumerate(level_plans(mesh)["blocks"]):
        if blocks.size:
            rate = float(rates[blocks].max())
            if rate > 0.0:
                dt = min(dt, 2.0 ** lv * cfl / rate)
    return dt


def _fields(state) -> tuple:
    return state.alpha, state.arho, state.arhoe, state.momentum, state.energy, state.arhoq


@njit(cache=True)
def gather_cells(fields, cells, out):
    """``out[f][i, c] = fields[f][b, c, x, y, z]`` for every field f and row i = (b, x, y, z) of ``cells``."""
    for f in range(len(fields)):
        field = fields[f]
        values = out[f]
        for i in range(cells.shape[0]):
            for c in range(field.shape[1]):
                values[i, c] = field[cells[i, 0], c, cells[i, 1], cells[i, 2], cells[i, 3]]


@njit(cache=True)
def blend_cells(fields, cells, before, after, theta):
    """Set the ``cells`` of every field to U_old + theta (U_new - U_old), ``before`` = U_old and
    ``after`` = U_new as gathered by :func:`gather_cells` (theta = 0 gives U_old exactly)."""
    for f in range(len(fields)):
        field = fields[f]
        old = before[f]
        new = after[f]
        for i in range(cells.shape[0]):
            b, x, y, z = cells[i, 0], cells[i, 1], cells[i, 2], cells[i, 3]
            for c in range(field.shape[1]):
                field[b, c, x, y, z] = old[i, c] + theta * (new[i, c] - old[i, c])


@njit(cache=True)
def put_cells(fields, cells, values):
    """``fields[f][b, c, x, y, z] = values[f][i, c]``: the inverse of :func:`gather_cells`."""
    for f in range(len(fields)):
        field = fields[f]
        value = values[f]
        for i in range(cells.shape[0]):
            for c in range(field.shape[1]):
                field[cells[i, 0], c, cells[i, 1], cells[i, 2], cells[i, 3]] = value[i, c]


#: The exponent bits of a float64: all set in an inf or a NaN, not in a finite value.
EXPONENT_BITS = 0x7FF0000000000000


@njit(cache=True)
def finite_run(bits):
    """Whether every value of ``bits`` (an int64 view of a C-contiguous float64 array) is
    finite: the largest of its exponent fields is below all ones.  ``np.isfinite(a).all()``
    without its boolean array; the integer maximum is a loop LLVM vectorizes (a float sum of
    x - x is not, and a test per value that stops early is not either)."""
    run = bits.reshape(bits.size)
    largest = 0
    for i in range(run.size):
        largest = max(largest, run[i] & EXPONENT_BITS)
    return largest < EXPONENT_BITS


@njit(cache=True)
def finite_blocks(field, blocks):
    """Whether every cell of ``field[b]`` (ghosts included) is finite for every b of ``blocks``
    (int64): ``np.isfinite(field[blocks]).all()`` without the copy of the blocks."""
    for e in range(blocks.shape[0]):
        run = field[blocks[e]].reshape(field[blocks[e]].size)
        for i in range(run.size):
            if not np.isfinite(run[i]):
                return False
    return True


def _gathered(state, cells: np.ndarray) -> tuple:
    """Copies (N, C) of every conserved field at ``cells`` (rows block, padded cell)."""
    fields = _fields(state)
    out = tuple(np.empty((cells.shape[0], field.shape[1])) for field in fields)
    gather_cells(fields, cells, out)
    return out


class LevelStepper:
    """The root step of ``time_stepping = "per_level"`` (module docstring): per mesh, the flux
    registers (one (E, NQ) array per sweep axis, E the reflux plan's rows) and, while a level
    steps, the copies of the coarser cells its finer level's ghosts interpolate from, before
    (U_old) and after (U_new) the coarser level's step.  U_new is gathered once per coarser step:
    the coarser level's cells stay as they are while its finer level takes its two substeps
    (only the finer levels sweep, and the reflux into the coarser cells follows them)."""

    def __init__(self):
        self._mesh: BlockMesh | None = None
        self._registers: list[np.ndarray] = []
        self._before: dict[int, tuple] = {}
        self._after: dict[int, tuple] = {}

    def _prepare(self, sim) -> None:
        """Registers sized for the current mesh, all zero (a failed step may have left some)."""
        mesh = sim.mesh
        if mesh is not self._mesh:
            columns = sim._face_flux.shape[2]
            self._registers = [np.zeros((axis_plans(mesh, a)["reflux"].shape[0], columns)) if mesh.adaptive
                               else np.zeros((0, columns)) for a in range(mesh.ndim)]
            self._mesh = mesh
        for register in self._registers:
            register[:] = 0.0
        self._before.clear()
        self._after.clear()

    def advance(self, sim, dt: float) -> int:
        """Advance every level of ``sim`` by the root step ``dt`` (s); returns the cell-updates
        (each level's cells once per substep of its own)."""
        self._prepare(sim)
        plans = level_plans(sim.mesh)
        finest = int(sim.mesh.block_level.max())
        return self._advance_level(sim, plans, 0, dt, sim.step_count, 0.0, finest)

    def _advance_level(self, sim, plans: dict, level: int, dt: float, substep: int, theta: float,
                       finest: int) -> int:
        """Level ``level`` by ``dt`` (s), then its finer levels twice by dt / 2 and the reflux, then
        (level >= 1, with tracers) the peak records of the tracers in this level's blocks at the
        substep's end (:meth:`~impactpipe.hydro.tracers.motion.Tracers.level_substep`);
        ``substep`` counts this level's substeps from the start of the run, ``theta`` is the
        fraction of the coarser level's step at which this substep starts."""
        mesh, st = sim.mesh, sim.state
        blocks = plans["blocks"][level]
        if level < finest:
            self._before[level + 1] = _gathered(st, plans["interpolated"][level + 1])
        updates = 0
        if blocks.size:
            axes = list(range(mesh.ndim))
            if substep % 2:
                axes.reverse()
            fields = _fields(st)
            cells = plans["interpolated"][level]
            if cells.shape[0]:
                blend_cells(fields, cells, self._before[level], self._after[level], theta)
            try:
                for axis in axes:
                    self.fill_level_ghosts(sim, plans, axis, level)
                    sim._observe("ghosts", axis)
                    sweep(axis, dt, mesh.geometry_code, st.alpha, st.arho, st.arhoe, st.arhoq, st.momentum,
                          st.energy, mesh.block_lo, mesh.block_dx, mesh.neighbor, mesh.neighbor_level, sim.eos.kind,
                          sim.eos.params, sim.eos.table, sim.shear_modulus, sim.tensile_strength, sim._scratch,
                          sim.boundary, sim.floors, sim.amounts, sim._failure, sim._face_flux, sim.plain_pencils,
                          blocks, NO_RECORD, NO_RECORD, NO_STAMPS[0], sim._sweep_grady_kipp, sim._sweep_porosity,
                          sim.bulk_pressure_predictor)
                    failed = sim.partition.first_failure(sim._failure)
                    if failed >= 0:
                        sim._raise_sweep_failure(failed)
                    sim._observe("sweep", axis)
                    if mesh.adaptive:
                        register_fluxes(axis, axis_plans(mesh, axis)["reflux"], sim._face_flux,
                                        self._registers[axis], mesh.block_level, level)
                if sim.strength is not None:
                    self._strength_step(sim, plans, level, dt)
            finally:
                if cells.shape[0]:
                    put_cells(fields, cells, self._after[level])
            updates += blocks.size * int(np.prod(mesh.interior_shape))
        if level < finest:
            self._after[level + 1] = _gathered(st, plans["interpolated"][level + 1])
            for k in range(2):
                updates += self._advance_level(sim, plans, level + 1, 0.5 * dt, 2 * substep + k, 0.5 * k, finest)
            for axis in range(mesh.ndim):
                plan = axis_plans(mesh, axis)
                reflux_register(plan["reflux"], plan["reflux_volume"], self._registers[axis], mesh.block_level, level,
                                *plans["fine_faces"][axis], *plans["near"][axis], st.alpha, st.arho, st.arhoe,
                                st.arhoq, st.momentum, st.energy, sim.floors, sim.amounts)
                sim._observe("reflux", axis)
        if level > 0 and sim.tracers is not None:
            sim.tracers.level_substep(sim, level, (substep - sim.step_count * 2 ** level + 1) * dt)
        return updates

    def _strength_step(self, sim, plans: dict, level: int, dt: float) -> None:
        """The strength step of level ``level``'s blocks over its substep ``dt`` (s), after its
        sweeps (module docstring): kick dt / 2, stress update dt, kick dt / 2
        (:class:`~impactpipe.hydro.strength.model.MaterialStrength`), each kick's amounts through
        the level's coarse/fine faces added to the flux registers.

        The work ghosts at coarse/fine faces come from the neighbouring levels' cells, computed
        first: level + 1's from its state now (the start of this substep, where that level
        stands), level - 1's from the cells its prolongation reads, which hold their values at
        the fraction theta of its step during the substep (:meth:`_advance_level`), as for the
        sweeps' ghosts.  They are
        not recomputed within the substep: the update's velocity ghosts and the second kick's
        stress ghosts from those levels keep these values (first order in time at the level
        faces; the registers keep the amounts exact whatever the ghosts hold)."""
        mesh, st, strength = sim.mesh, sim.state, sim.strength
        view, finer, coarser = strength_levels(mesh)[level]
        strength.load_work(st, sim.eos, finer)
        strength.load_work(st, sim.eos, coarser)
        strength.load_stress(st, sim.eos, sim.partition, view)
        self._strength_kick(sim, 0.5 * dt, view, level)
        strength.update(st, dt, sim.eos, sim.partition, view)
        self._strength_kick(sim, 0.5 * dt, view, level)
        sim._check_momentum(view.blocks)
        sim._observe("sources", -1)

    def _strength_kick(self, sim, dt: float, view: LevelBlocks, level: int) -> None:
        """Half kick ``dt`` (s) of the stress divergence on the ``view``'s blocks, its coarse/fine
        face amounts (momentum and total energy columns) into the flux registers."""
        mesh, strength = sim.mesh, sim.strength
        strength.kick(sim.state, dt, sim.boundary, sim.floors, sim.amounts, sim.partition, view)
        if mesh.adaptive:
            for axis in range(mesh.ndim):
                register_fluxes(axis, axis_plans(mesh, axis)["reflux"], strength.face_flux[axis],
                                self._registers[axis], mesh.block_level, level)

    def fill_level_ghosts(self, sim, plans: dict, axis: int, level: int) -> None:
        """Fill the ghosts of level ``level``'s blocks along ``axis`` (module docstring): same-level
        copies and domain faces, restriction from level + 1 (and of level - 1's ghosts from this
        level), prolongation from level - 1, whose cells it reads hold their values at the
        substep's time (:meth:`_advance_level`)."""
        mesh, st = sim.mesh, sim.state
        fields = _fields(st)
        g = int(mesh.ghost[axis])
        fill_state_ghost_slabs_of(*fields, mesh.neighbor, mesh.neighbor_level, axis, g, plans["blocks"][level],
                                  every_layer(st.arhoq, g))
        if not mesh.adaptive:
            return
        restrict_state_ghosts(fields, plans["restrict"][axis, level], plans["restrict_weight"][axis, level])
        prolong = plans["prolong"][axis, level]
        if prolong.shape[0]:
            prolong_state_ghosts(fields, prolong, mesh.block_lo, mesh.block_dx, mesh.geometry_code, mesh.ndim)
