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

**Several processes** (MPI ranks, :mod:`impactpipe.hydro.parallel`): a tracer is held by the
rank that owns the block holding it, and moves between ranks with its material.  Each sample
(v_n at x_n, v_{n+1} at x*, the peaks at x_{n+1}) is taken by the rank that owns the block
holding the point, whose stencil then reads only its own blocks and the cells within one cell
of them (brought up to date after the sweeps): a tracer whose predictor point x* lies in
another rank's blocks is handed to that rank before v_{n+1} is sampled, and one whose new
position x_{n+1} does, before its peaks are recorded, with everything it carries (its records,
v_n, its last-good records and its history samples).  An exited tracer stays where it is.
Each tracer's arithmetic is the single process's, so the records are the same bit for bit on
any number of ranks; an output gathers them in the order they were given in
(:meth:`Tracers.assembled`).  Every rank starts with every tracer (built or read the same way
on each) and keeps those in its own blocks at the first step, and after every regrid the
tracers go to the owners of their new blocks.

**Time stepping per level** (``time_stepping = "per_level"``, :mod:`impactpipe.hydro.amr.subcycle`):
a Simulation step is one root step dt_0, in which level l advances in 2^l substeps of
dt_0 / 2^l.  The tracers move once per root step, by the Heun step above with dt = dt_0: v_n
from the field at the root step's start, v_{n+1}(x*) from the field at its end, when every
level has caught up (second order in dt_0, as the global step's Heun is in its dt).  The
peaks are recorded at the root step's end as above and, in between, after each substep of
level l >= 1 (:meth:`Tracers.level_substep`) at the point of the predicted path

    x(t_n + s) = x_n + s v_n(x_n),        s = k dt_0 / 2^l, k = 1 .. 2^l,

for the tracers whose point lies in a level-l block, with the time t_n + s: a tracer in fine
blocks is sampled as often as the global step samples it.  The point is the predictor's, first
order in s (its distance to the straight segment from x_n to x_{n+1} is s |v_{n+1}(x*) - v_n| / 2,
less than the root step's displacement); a stencil cell in a coarser block is read at that
block's step end.  A root step taken
again, or undone by :meth:`restore_good`, drops the records of its substeps with the rest.
Measured on the hydro-only impact (benchmarks/per_level_tracers.py, docs/tracers.md): the
peak pressures agree with the global step's to a median 0.78 % (98 % of the tracers within
10 %); recorded at the root steps' ends only they were 2.7 % off (85 % within 10 %).

**History** (optional): every ``history_interval`` seconds of simulated time the first step
that reaches k * history_interval appends (time, all positions): the times to an array
preallocated for ``end_time`` and doubled when full, the positions to a log of (tracer,
position) entries that each process keeps for the tracers it holds at the sample (doubled
when full; 32 bytes per tracer and sample), which stays where it was written when a tracer
moves to another process and is put in order for an output (:attr:`Tracers.history`).
"""

from __future__ import annotations

import copy
import math

import numpy as np
from numba import njit, prange

from impactpipe.hydro.mesh.blocks import OUTFLOW, REFLECTING, BlockMesh
from impactpipe.hydro.output.snapshot import TracerSet
from impactpipe.hydro.tracers.locate import PERIODIC, BlockLocator, as_positions
from impactpipe.hydro.tracers.sampling import record_peaks, sample_velocity
from impactpipe.storage import write_dataset

#: Tracer record arrays (the :class:`~impactpipe.hydro.output.snapshot.TracerSet` fields) with their
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




class Tracers:
    """Massless Lagrangian tracers driven by a :class:`~impactpipe.hydro.solver.Simulation`.

    Pass to the Simulation (``Simulation(..., tracers=tracers)`` or ``sim.tracers = tracers``
    before the first step); it calls :meth:`keep_good`, :meth:`before_step`, :meth:`after_step`,
    :meth:`restore_good` and :meth:`save`.  Method and equations: module docstring.

    Args:
        positions: (N, 3) (or (N, ndim)) initial positions (m), mesh coordinates.
        materials: (N,) material index of each tracer.
        ids: (N,) int64 ids (default 1..N).
        history_interval: simulated seconds between trajectory samples, or None (no history).
        end_time: expected end time (s), used to preallocate the history.

    Attributes: the :class:`~impactpipe.hydro.output.snapshot.TracerSet` fields (``id``,
    ``material``, ``initial_position``, ``position``, ``velocity``, ``peak_pressure``,
    ``peak_pressure_time``, ``peak_temperature``, ``exited``, ``exit_time``), updated in place.
    """

    def __init__(self, positions, materials, ids=None, history_interval: float | None = None,
                 end_time: float | None = None):
        pos = as_positions(positions)
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
        #: (N,) each tracer's index in the order it was given in: the order of every output.
        self.slot = np.arange(n, dtype=np.int64)
        #: The history's positions as a log: entry e is tracer ``_log_slot[e]`` at ``_log_position[e]``
        #: (m); sample k's entries are ``_log_start[k]`` .. ``_log_start[k + 1] - 1``.
        self._log_slot = np.zeros(0, dtype=np.int64)
        self._log_position = np.zeros((0, 3))
        self._v_start = np.zeros((n, 3))
        self._scratch(n)
        self._t_start = 0.0
        self._missing = n  # tracers on the mesh without a peak record (recounted after each step)
        self._good = {name: getattr(self, name).copy() for name in self._MUTABLE}
        self._good_counts = (0, 0.0)
        self._mesh = None
        self._nmat = None
        #: Whether every process holds every tracer (as built or loaded on each), until the first
        #: step on several processes keeps each tracer on the owner of its block (:meth:`_place`).
        self._every_process_holds_all = True
        #: Whether each tracer is held by the process owning its block on the bound mesh.
        self._placed = False

    #: Arrays that a step changes (kept by :meth:`keep_good` for :meth:`restore_good`).
    _MUTABLE = ("position", "velocity", "peak_pressure", "peak_pressure_time", "peak_temperature", "exited",
                "exit_time")
    #: The per-tracer arrays a tracer takes with it to another process, with its last-good
    #: records and its history.
    _CARRIED = ("id", "slot", "material", "initial_position", *_MUTABLE, "_v_start")

    def _scratch(self, n: int) -> None:
        """The per-step work arrays of ``n`` tracers (no allocation per step)."""
        self._v_end = np.zeros((n, 3))
        self._trial = np.zeros((n, 3))
        self._sign = np.ones((n, 3))
        self._block = np.full(n, -1, dtype=np.int64)
        self._owner = np.full(n, -1, dtype=np.int64)
        self._skip = np.ones(n, dtype=np.bool_)
        self._path = np.zeros((n, 3))
        self._path_sign = np.ones((n, 3))
        self._path_block = np.full(n, -1, dtype=np.int64)
        self._path_skip = np.ones(n, dtype=np.bool_)

    def __len__(self) -> int:
        return int(self.id.shape[0])

    def _allocate_history(self, capacity: int) -> None:
        self.history_time = np.zeros(capacity)
        self._log_start = np.zeros(capacity + 1, dtype=np.int64)

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
        self._placed = False

    @property
    def owning_block(self) -> np.ndarray:
        """(N,) index of the block holding each tracer on the bound mesh (-1 once exited), as found
        by the last step or :meth:`mesh_changed` (a copy)."""
        return self._block.copy()

    def _fold_and_locate(self, sim, dt: float) -> None:
        """The points x_n + dt v_n of the tracers on the mesh, folded into the domain (into
        ``self._trial``, velocity signs ``self._sign``), their blocks (``self._block``) and the
        process that samples each (``self._owner``, the owner of its block; -1 once exited)."""
        mesh = sim.mesh
        _fold(self.position, self._v_start, dt, self.exited, mesh.domain_lo, mesh.domain_hi, self._codes, mesh.ndim,
              self._trial, self._sign)
        self._locate(self._trial, self.exited, self._block)
        self._assign(sim.partition)

    def _assign(self, partition) -> None:
        """``self._owner`` from ``self._block``; ``self._skip``: the tracers this process does not sample."""
        partition.block_owners(self._block, self._owner)
        np.not_equal(self._owner, partition.rank, out=self._skip)

    # ------------------------------------------------------------------ several processes

    def _rows(self) -> list[np.ndarray]:
        """Every per-tracer array a tracer takes to another process (:data:`_CARRIED` and the
        last-good records; its history entries stay in the log where they were written)."""
        return [getattr(self, name) for name in self._CARRIED] + [self._good[name] for name in self._MUTABLE]

    def _set_rows(self, rows: list[np.ndarray]) -> None:
        """Hold the tracers of ``rows`` (as :meth:`_rows` gives them) instead; the work arrays are
        new, so the blocks must be found again."""
        carried = len(self._CARRIED)
        for name, array in zip(self._CARRIED, rows[:carried]):
            setattr(self, name, array)
        self._good = dict(zip(self._MUTABLE, rows[carried:]))
        self._scratch(len(rows[0]))
        self._count_missing()

    def _log_samples(self) -> np.ndarray:
        """(E,) the sample k of each history log entry."""
        k = self.history_count
        return np.repeat(np.arange(k, dtype=np.int64), np.diff(self._log_start[:k + 1]))

    def _set_log(self, slots: np.ndarray, samples: np.ndarray, positions: np.ndarray) -> None:
        """The history log from its entries, in the order of their samples."""
        order = np.argsort(samples, kind="stable")
        self._log_slot = np.ascontiguousarray(slots[order])
        self._log_position = np.ascontiguousarray(positions[order])
        counts = np.bincount(samples, minlength=self._log_start.shape[0] - 1)
        self._log_start[:] = np.concatenate([[0], np.cumsum(counts)])

    def _count_missing(self) -> None:
        """Count the tracers on the mesh without a peak record (they record at the next step's start)."""
        self._missing = int(np.count_nonzero(np.isnan(self.peak_pressure_time) & ~self.exited))

    def _place(self, partition) -> None:
        """Each tracer on the mesh to the process owning its block (on a new mesh, and at the first
        step, when every process holds every tracer: each then keeps its own, and rank 0 the
        exited ones); an exited tracer stays where it is.  Collective on several processes."""
        self._locate(self.position, self.exited, self._block)
        self._assign(partition)
        if not partition.whole:
            if self._every_process_holds_all:
                kept = (self._owner == partition.rank) | (self.exited & partition.is_root)
                entries = self._log_start[self.history_count]
                logged = np.isin(self._log_slot[:entries], self.slot[kept])
                self._set_log(self._log_slot[:entries][logged], self._log_samples()[logged],
                              self._log_position[:entries][logged])
                self._set_rows([row[kept] for row in self._rows()])
                self._every_process_holds_all = False
                self._locate(self.position, self.exited, self._block)
                self._assign(partition)
            elif self._hand_over(partition):
                self._locate(self.position, self.exited, self._block)
                self._assign(partition)
        self._placed = True

    def _hand_over(self, partition) -> bool:
        """Send each tracer whose point (``self._owner``) lies in another process's blocks to that
        process, with everything it carries (:meth:`_rows`), and hold those sent here
        (collective; :meth:`~impactpipe.hydro.parallel.distributed.BlockRanges.hand_over`).
        Whether tracers came or went: their work arrays are then new, the blocks unknown."""
        destination = np.where(self._owner >= 0, self._owner, partition.rank)
        held = partition.hand_over(destination, self._rows())
        if held is not None:
            self._set_rows(held)
        return held is not None

    def held_by_every_process(self) -> None:
        """Say that every process now holds every tracer (after a broadcast of one process's
        tracers): at the next step each keeps those in its own blocks."""
        self._every_process_holds_all = True
        self._placed = False

    def assembled(self, partition, everywhere: bool = False) -> "Tracers | None":
        """Every tracer, in the order they were given in, on the process that writes (rank 0; every
        process with ``everywhere``), None on the others: for an output or the end of a shared
        run (collective on several processes).  This object itself on one process."""
        if partition.whole or self._every_process_holds_all:
            return self if everywhere or partition.is_root else None
        rows = partition.gather_items(self._rows(), everywhere)
        entries = self._log_start[self.history_count]
        log = partition.gather_items([self._log_slot[:entries], self._log_samples(), self._log_position[:entries]],
                                     everywhere)
        if rows is None:
            return None
        order = np.argsort(rows[self._CARRIED.index("slot")], kind="stable")
        whole = copy.copy(self)
        whole._log_start = self._log_start.copy()
        whole._set_log(*log)
        whole._set_rows([row[order] for row in rows])
        whole._every_process_holds_all = True
        whole._placed = False
        return whole

    def _sample(self, sim, out: np.ndarray) -> None:
        """Velocity at the points ``self._trial`` of the tracers this process samples into ``out``."""
        mesh = sim.mesh
        loc = self._locate
        sample_velocity(self._trial, self._sign, self.material, self._skip, self._block, mesh.block_lo,
                         mesh.block_dx, mesh.block_index, mesh.block_level, mesh.block_cells, self._ncell, mesh.ndim,
                         self._codes, self._cells, loc.root, loc.children, sim.state.arho, sim.state.momentum, out)

    def _record(self, sim, unrecorded_only: bool) -> None:
        """Peak pressure / temperature at the current positions of the tracers this process samples
        (``self._block`` and ``self._skip`` must be current)."""
        mesh = sim.mesh
        st = sim.state
        eos = sim.eos
        loc = self._locate
        record_peaks(self.position, self.material, self._skip, self._block, unrecorded_only, sim.time, mesh.block_lo,
                      mesh.block_dx, mesh.block_index, mesh.block_level, mesh.block_cells, self._ncell, mesh.ndim,
                      self._codes, self._cells, loc.root, loc.children, st.alpha, st.arho, st.arhoe, eos.kind,
                      eos.params, eos.table, self.peak_pressure, self.peak_pressure_time, self.peak_temperature,
                      None if sim.porosity is None else st.arhoq, sim.porosity)

    def _sample_history(self, time: float) -> None:
        k = self.history_count
        if k == self.history_time.shape[0]:
            old_t, old_start = self.history_time, self._log_start
            self._allocate_history(max(2 * old_t.shape[0], HISTORY_CHUNK))
            self.history_time[:k] = old_t
            self._log_start[:k + 1] = old_start
        start, n = self._log_start[k], len(self)
        if start + n > self._log_slot.shape[0]:
            size = max(2 * self._log_slot.shape[0], start + n)
            self._log_slot = np.concatenate([self._log_slot[:start], np.zeros(size - start, dtype=np.int64)])
            self._log_position = np.concatenate([self._log_position[:start], np.zeros((size - start, 3))])
        self.history_time[k] = time
        self._log_slot[start:start + n] = self.slot
        self._log_position[start:start + n] = self.position
        self._log_start[k + 1] = start + n
        self.history_count += 1
        self.history_next = (math.floor(time / self.history_interval) + 1.0) * self.history_interval

    # ------------------------------------------------------------------ Simulation hooks

    def keep_good(self, sim) -> None:
        """Keep the records for :meth:`restore_good`: the Simulation calls it where it takes its
        last-good copy of the state, at the start of a step (on several processes each holds the
        tracers in its blocks, placed first on a new mesh)."""
        self._bind(sim.mesh, sim.state.nmat)
        if not self._placed:
            self._place(sim.partition)
        for name in self._MUTABLE:
            np.copyto(self._good[name], getattr(self, name))
        self._good_counts = (self.history_count, self.history_next)

    def before_step(self, sim) -> None:
        """Sample v_n(x_n) from ``sim.state`` at t_n (on several processes each holds the tracers
        in its blocks, placed first on a new mesh)."""
        self._bind(sim.mesh, sim.state.nmat)
        if not self._placed:
            self._place(sim.partition)
        self._t_start = sim.time
        self._fold_and_locate(sim, 0.0)
        self._sample(sim, self._v_start)
        if self._missing:
            self._record(sim, unrecorded_only=True)  # self._block holds the blocks of the positions
        if self.history_interval is not None and self.history_count == 0:
            self._sample_history(sim.time)

    def after_step(self, sim, dt: float) -> None:
        """Heun step over ``dt`` (s) with the field after the sweeps; faces, exits and peak records.

        On several processes a tracer whose predictor point x* lies in another process's blocks
        is handed to that process before v_{n+1}(x*) is sampled, and one whose new position
        x_{n+1} does after the corrector, before its peaks are recorded
        (:meth:`~impactpipe.hydro.parallel.distributed.BlockRanges.hand_over`).
        """
        mesh = sim.mesh
        partition = sim.partition
        self._fold_and_locate(sim, dt)
        if not partition.whole and self._hand_over(partition):
            self._fold_and_locate(sim, dt)
        self._sample(sim, self._v_end)
        _correct(self.position, self._v_start, self._v_end, self.exited, dt, self._t_start, mesh.domain_lo,
                 mesh.domain_hi, self._codes, mesh.ndim, mesh.geometry == "2d-cylindrical", self.velocity,
                 self.exit_time)
        self._locate(self.position, self.exited, self._block)
        self._assign(partition)
        if not partition.whole and self._hand_over(partition):
            self._locate(self.position, self.exited, self._block)
            self._assign(partition)
        self._record(sim, unrecorded_only=False)
        self._count_missing()
        if self.history_interval is not None and sim.time >= self.history_next * (1.0 - 1e-12):
            self._sample_history(sim.time)

    def level_substep(self, sim, level: int, elapsed: float) -> None:
        """Per level (``time_stepping = "per_level"``, :mod:`impactpipe.hydro.amr.subcycle`): peak
        pressure and temperature after a substep of level ``level`` >= 1 that ends ``elapsed`` s
        into the root step, for the tracers whose point on the predicted path

            x(t_n + s) = x_n + s v_n(x_n),    s = ``elapsed``,

        (folded into the domain as the predictor is) lies in a block of that level, recorded at
        the time t_n + s.  The tracers move once per root step (:meth:`after_step`); this samples
        the fine levels' cells as often as the global step would, so a shock crossing a fine
        block within a root step is seen at its substeps' states (module docstring, "Time
        stepping per level").  One process only (``per_level`` runs on one)."""
        mesh = sim.mesh
        _fold(self.position, self._v_start, elapsed, self.exited, mesh.domain_lo, mesh.domain_hi, self._codes,
              mesh.ndim, self._path, self._path_sign)
        self._locate(self._path, self.exited, self._path_block)
        np.not_equal(mesh.block_level[self._path_block], level, out=self._path_skip)
        self._path_skip |= self.exited
        st = sim.state
        eos = sim.eos
        loc = self._locate
        record_peaks(self._path, self.material, self._path_skip, self._path_block, False, self._t_start + elapsed,
                     mesh.block_lo, mesh.block_dx, mesh.block_index, mesh.block_level, mesh.block_cells, self._ncell,
                     mesh.ndim, self._codes, self._cells, loc.root, loc.children, st.alpha, st.arho, st.arhoe,
                     eos.kind, eos.params, eos.table, self.peak_pressure, self.peak_pressure_time,
                     self.peak_temperature, None if sim.porosity is None else st.arhoq, sim.porosity)

    def restore_good(self, partition=None) -> None:
        """Put back the records kept last (:meth:`keep_good`, after a failed step); on the
        processes of ``partition`` (collective) each tracer goes back to the owner of its block."""
        for name in self._MUTABLE:
            np.copyto(getattr(self, name), self._good[name])
        self.history_count, self.history_next = self._good_counts
        if partition is not None and not partition.whole and self._placed:
            self._locate(self.position, self.exited, self._block)
            self._assign(partition)
            self._hand_over(partition)  # the next step finds the blocks again
        self._count_missing()

    # ------------------------------------------------------------------ output and checkpoints

    @property
    def history(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(times (K,) s, positions (K, N, 3) m) of the trajectory samples, or None without history;
        of the tracers this object holds, every tracer on one process or after :meth:`assembled`."""
        if self.history_interval is None:
            return None
        k = self.history_count
        entries = self._log_start[k]
        positions = np.zeros((k, len(self), 3))
        column = np.empty(int(self.slot.max(initial=-1)) + 1, dtype=np.int64)
        column[self.slot] = np.arange(len(self))
        positions[self._log_samples(), column[self._log_slot[:entries]]] = self._log_position[:entries]
        return self.history_time[:k].copy(), positions

    def to_tracer_set(self) -> TracerSet:
        """The records as a :class:`~impactpipe.hydro.output.snapshot.TracerSet` (copies)."""
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
            times, positions = self.history
            write_dataset(group, "history_time", times, *HISTORY_UNITS["history_time"])
            write_dataset(group, "history_position", positions, *HISTORY_UNITS["history_position"])

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
            tracers.history_count = k
            n = len(tracers)
            tracers._set_log(np.tile(tracers.slot, k), np.repeat(np.arange(k, dtype=np.int64), n),
                             group["history_position"][()].reshape(k * n, 3))
            tracers.history_next = float(group.attrs["history_next"])
        return tracers


def interpolate_velocity(sim, positions, materials) -> np.ndarray:
    """(N, 3) tracer velocity (m/s) at ``positions`` (inside the domain) for tracers of ``materials``,
    from the current state of ``sim`` (the field a tracer sees; module docstring), a simulation
    run by one process (on several MPI ranks a rank samples only the points in its blocks)."""
    probe = Tracers(positions, materials)
    probe._bind(sim.mesh, sim.state.nmat)
    out = np.zeros((len(probe), 3))
    probe._fold_and_locate(sim, 0.0)
    probe._sample(sim, out)
    return out


# ---------------------------------------------------------------------------- placement
