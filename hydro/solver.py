"""The hydro driver: :class:`Simulation` advances a :class:`HydroState` on a :class:`BlockMesh`.

One step: on an adaptive mesh, every ``refinement.interval`` steps, a regrid
(:mod:`impactpipe.hydro.amr.regrid`); dt from the CFL condition over all blocks
(:mod:`impactpipe.hydro.scheme.timestep`; one global step for every level, or with
``time_stepping = "per_level"`` a root step whose levels subcycle, :mod:`impactpipe.hydro.amr.subcycle`,
which replaces what follows); then one sweep per used
axis (:mod:`impactpipe.hydro.scheme.directional`), each after filling the ghosts along its axis and, on an
adaptive mesh, followed by refluxing the coarse cells beside finer blocks
(:func:`impactpipe.hydro.amr.transfer.reflux`); the sweep order alternates every step
(x y z, then z y x), which makes the splitting second order over a pair of steps (Strang).  The state is
copied every LAST_GOOD_INTERVAL steps and the steps since are listed, so a failing step leaves the
last good state available (:meth:`Simulation.restore_last_good` copies the state back and takes
those steps again, bit for bit).
On several MPI ranks each process advances its share of the blocks (``Simulation.partition``,
:mod:`impactpipe.hydro.parallel`).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import h5py
import numba
import numpy as np

from impactpipe.hydro.amr.regrid import RefinementRule, flag_blocks, plan_leaves
from impactpipe.hydro.amr.subcycle import (GLOBAL, PER_LEVEL, TIME_STEPPING, LevelStepper, finite_blocks,
                                           finite_run, level_time_step)
from impactpipe.hydro.amr.transfer import allocate_face_flux, reflux
from impactpipe.hydro.mesh.boundary import NO_RECORD
from impactpipe.hydro.mesh.last_good import RECORD_VOID, block_runs, scalar_clear_blocks, void_blocks
from impactpipe.hydro.mesh.scalar_stamps import NO_STAMPS, ScalarStamps
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.eos.porosity import (COUNT_NAMES as POROSITY_COUNT_NAMES, ALPHA0, NPOROSITY, compact,
                                           distension_field, pack_porosity)
from impactpipe.hydro.gravity import gravity_from_spec
from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.output.snapshot import Snapshot
from impactpipe.hydro.parallel.distributed import WholeMesh, checkpoint_partition
from impactpipe.hydro.parallel.owned_memory import read_owned_rows, receive_halos
from impactpipe.hydro.mesh.state import FIELDS, HydroState
from impactpipe.hydro.strength import MaterialStrength, StrengthArrays, pack_strength
from impactpipe.hydro.strength.parameters import GRADY_KIPP, pack_damage
from impactpipe.hydro.scheme.directional import sweep
from impactpipe.hydro.scheme.pencil_layout import (
    AMOUNT_NAMES,
    BND_ENERGY,
    BND_MASS,
    BND_MATERIAL,
    BND_MOMENTUM,
    FLOOR_NAMES,
    NAMOUNT,
    NFLOOR,
    allocate_scratch,
    transport_ghost_layers,
)
from impactpipe.hydro.scheme.timestep import allocate_rate_work, cell_thermodynamics, max_signal_rate
from impactpipe.hydro.scheme.settling import settle_void
from impactpipe.hydro.scheme.step_tension import UNLIMITED_TENSION, open_void_in_tension
from impactpipe.storage import store_array

logger = logging.getLogger(__name__)

#: A time step below this fraction of the first step is a collapse (HydroFailure).
DT_COLLAPSE_FRACTION = 1.0e-8
LOG_INTERVAL = 100
#: Per level (``time_stepping = "per_level"``), a root step dt_0 is taken again at the step the
#: state at its end allows when that is more than this factor shorter: the signal speed grew
#: during the root step (up to 2.7x in the first 0.25 s of the hydro-only impact,
#: docs/hydro.md), which the global step follows every finest step.
LEVEL_STEP_GROWTH = 1.25
#: At most this many retakes of one root step; the last one stands, or its failure is raised.
LEVEL_STEP_RETAKES = 3
#: Steps between two last-good copies of the state (:meth:`Simulation.restore_last_good` takes
#: the steps since the copy again).  A copy reads and writes every interior cell of the state,
#: which costs as much as the time step on a one-gas box (docs/performance.md); one copy per 8
#: steps costs an eighth of that, and a failure at most 7 steps taken again.
LAST_GOOD_INTERVAL = 8


class HydroFailure(RuntimeError):
    """The hydro step failed (NaN, negative density, time-step collapse).

    Attributes: ``time`` (s) of the last good state, ``block`` and ``cell`` (padded
    indices) of the failing cell (-1 / None when not cell-specific), ``state`` a dict of
    that cell's conserved values after the failed update.
    """

    def __init__(self, message: str, time: float, block: int, cell, state: dict):
        super().__init__(f"{message} (t = {time:.6g} s, block {block}, cell {cell})")
        self.time = time
        self.block = block
        self.cell = cell
        self.state = state


class Simulation:
    """Multi-material Eulerian hydrodynamics on a block mesh.

    Args:
        mesh: the block mesh (geometry, boundaries, neighbour table).
        material_names: names of the M materials.
        eos_specs: resolved EOS dicts, one per material (see :func:`impactpipe.hydro.eos.pack_eos`).
        state: initial conserved state (interior cells set; ghosts are filled here).
        cfl: Courant number (0 < cfl <= 0.5 for the split scheme with HLLC, default 0.4).
        shear_modulus: (M,) constant shear modulus per material (Pa) for the signal speed of a
            scene without ``strength``; zeros for strengthless materials.
        tensile_strength: (M,) tensile strength Y_T per material (Pa): the most tension a
            material holds before it fails and opens void; by default the strength specs'
            Y_T, zeros (no tension) without them.
        strength: resolved strength specs, one per material (None or model "none" =
            strengthless; :mod:`impactpipe.hydro.strength.parameters`).  When some material
            has a yield model, the deviatoric stress is stored, transported and updated every
            step and the signal speed is the longitudinal one (docs/strength.md).  A spec's
            ``damage`` block (:func:`impactpipe.hydro.strength.parameters.pack_damage`) makes
            the material's tensile damage Grady-Kipp: flaws drawn and carried, (1 - D) of its
            tension borne (:attr:`grady_kipp`); its ``flaw_strains`` are recorded here when drawn.
            A porous material (an EOS spec with a ``porosity`` block of alpha0 > 1,
            :mod:`impactpipe.hydro.eos.porosity`) carries its distension in the transported
            scalars, compacted after each step's sweeps; it may have a yield model and
            Grady-Kipp damage (its flaws counted per unit volume of matrix,
            :meth:`impactpipe.hydro.strength.model.MaterialStrength.prepare_state`).
        time: initial time (s).
        tracers: Lagrangian tracers carried with the flow, or None.  Any object with
            ``before_step(sim)``, ``after_step(sim, dt)``, ``restore_good()``,
            ``save(h5group)`` and ``mesh_changed(mesh)`` (see :mod:`impactpipe.hydro.tracers.motion`).
        refinement: when and where an adaptive mesh (``mesh.max_level`` > 0) refines; the
            default :class:`~impactpipe.hydro.amr.regrid.RefinementRule` if None.
        time_stepping: ``"global"`` (one step, the finest cells' CFL step, for every level) or
            ``"per_level"`` (level l steps dt_0 / 2^l, :mod:`impactpipe.hydro.amr.subcycle`; one
            process, without gravity or porosity; tracers move once per root step and record peaks
            after each substep of the level holding them; :meth:`check_time_stepping`).
        gravity: gravity, applied in two half kicks around the stress update, or None: an object
            with ``prepare(state, mesh, partition)`` (once per step, before the kicks),
            ``advance(state, dt, block_lo, block_dx, partition)``, ``spec()`` (what a checkpoint
            stores to rebuild it) and ``work`` (J): uniform
            (:class:`impactpipe.hydro.gravity.ExternalGravity`) or the bodies' own
            (:class:`impactpipe.hydro.self_gravity.SelfGravity`).
        partition: which blocks this process advances
            (:mod:`impactpipe.hydro.parallel.distributed`); None: every block
            (:class:`~impactpipe.hydro.parallel.distributed.WholeMesh`).  A
            :class:`~impactpipe.hydro.parallel.distributed.BlockRanges` here needs ``state`` to
            hold this rank's rows (:meth:`from_checkpoint`,
            :func:`~impactpipe.hydro.parallel.distributed.shared_simulation`); the constructor is
            then collective, and the strength work arrays and the scalars it adds are the
            partition's zeros with this rank's rows set.
        fill_ghosts: fill the ghost cells of an adaptive mesh's state from its interior; False
            keeps them as ``state`` holds them (a checkpoint's).
    """

    def __init__(self, mesh: BlockMesh, material_names: list[str], eos_specs: list[dict], state: HydroState,
                 cfl: float = 0.4, shear_modulus: Iterable[float] | None = None, time: float = 0.0,
                 tracers=None, tensile_strength: Iterable[float] | None = None,
                 strength: list[dict | None] | None = None, gravity=None,
                 refinement: RefinementRule | None = None, time_stepping: str = GLOBAL, partition=None,
                 fill_ghosts: bool = True):
        self.gravity = gravity
        #: ``"global"`` or ``"per_level"`` (:mod:`impactpipe.hydro.amr.subcycle`); may be changed
        #: between steps, checked by :meth:`check_time_stepping`.
        self.time_stepping = time_stepping
        self._level_stepper = LevelStepper()
        self.refinement = refinement or RefinementRule()
        #: Regrids that changed the mesh, blocks split into children and sibling groups merged.
        self.regrids = 0
        #: Per level, root steps taken again at a shorter step (:meth:`_level_step`: the signal speed
        #: grew past :data:`LEVEL_STEP_GROWTH`, or a substep failed).
        self.level_step_retakes = 0
        self.blocks_refined = 0
        self.blocks_coarsened = 0
        #: Wall seconds spent in :meth:`regrid` (flagging, balancing, moving the state).
        self.regrid_seconds = 0.0
        #: Largest |p| (Pa) the regrids have seen: the scale of the refinement's pressure floor.
        self.peak_pressure = 0.0
        if not 0.0 < cfl <= 1.0:
            raise ValueError(f"cfl must be in (0, 1], got {cfl}")
        if len(material_names) != state.nmat or len(eos_specs) != state.nmat:
            raise ValueError("one name and one EOS spec per material")
        self.mesh = mesh
        self.material_names = list(material_names)
        self.eos_specs = [dict(s) for s in eos_specs]
        self.eos = pack_eos(self.eos_specs)
        #: (M, NPOROSITY) porosity rows (:func:`impactpipe.hydro.eos.porosity.pack_porosity`); None without
        #: porous materials.
        self.porosity = pack_porosity(self.eos_specs, self.eos)
        self.state = state
        self.cfl = float(cfl)
        self.strength_specs = None if strength is None else [dict(s) if s else None for s in strength]
        arrays: StrengthArrays = pack_strength(self.strength_specs or [None] * state.nmat)
        if arrays.model.shape != (state.nmat,):
            raise ValueError(f"strength needs {state.nmat} specs, one per material")
        #: (M, 2) shear table: G = shear_modulus[k, 0] + shear_modulus[k, 1] K (Pa).
        self.shear_modulus = arrays.shear.copy()
        if shear_modulus is not None:
            self.shear_modulus[:, 0] = np.asarray(shear_modulus, float)
        if tensile_strength is None:
            tensile_strength = arrays.tensile_strength
        self.tensile_strength = np.asarray(tensile_strength, float)
        if self.tensile_strength.shape != (state.nmat,) or (self.tensile_strength < 0).any():
            raise ValueError(f"tensile_strength must be {state.nmat} values >= 0 (Pa)")
        self.time = float(time)
        self.tracers = tracers
        self.step_count = 0
        self.cell_updates = 0
        #: Pencils that one material fills alone take the sweep's plain path
        #: (:mod:`impactpipe.hydro.scheme.plain_pencils`); False sends every pencil through the general
        #: path, which gives the same answer to round-off at about twice the cost.
        self.plain_pencils = True
        #: The sweeps' pressure predictor takes the bulk modulus K, not K + 4G/3, in cells holding a
        #: material with a shear modulus (:func:`impactpipe.hydro.scheme.directional.sweep`); set by the
        #: granular column collapse, where K + 4G/3 left a viscosity G dt / 3 on its flow.
        self.bulk_pressure_predictor = False
        #: The tensile limit acts on the state at the end of each step's sweeps, not within them
        #: (:mod:`impactpipe.hydro.scheme.step_tension`); set by the granular column collapse, where the
        #: limit between the split sweeps made the deposit depend on the time step.  Not with porous or
        #: Grady-Kipp materials.
        self.step_tensile_limit = False
        #: Void under material resting on it settles out at the end of each step's sweeps
        #: (:mod:`impactpipe.hydro.scheme.settling`): set by the granular column collapse, whose flow rode on
        #: cells held open at zero pressure and ran out further the finer the mesh.  2d-planar, one level,
        #: uniform gravity along -axis 1; :attr:`settled_cells` counts the transfers.
        self.void_settling = False
        self.settled_cells = 0
        #: (work, counts) per block that :meth:`_settle_void` reuses every step.
        self._settling_buffers: tuple[np.ndarray, np.ndarray] | None = None
        self._unlimited_tension: np.ndarray | None = None
        self.dt_first: float | None = None
        self.last_dt = 0.0
        #: Called as ``observer(event, axis)`` between the operations of a step, for diagnostics
        #: (benchmarks/energy_budget.py): "regrid" after the regrid (or its check), "ghosts" after
        #: a sweep's ghosts are filled, "sweep" and "reflux" after them, "sources" after the
        #: strength and gravity sources (axis -1 where none applies); per level, "ghosts" and
        #: "sweep" for each level substep's sweeps and "reflux" after each level's register
        #: correction.  None: no calls.
        self.observer: Callable[[str, int], None] | None = None
        #: Which blocks this process advances and how it combines with the others
        #: (:mod:`impactpipe.hydro.parallel.distributed`); every block by default.
        self.partition = WholeMesh() if partition is None else partition
        nb = mesh.nblocks
        self.boundary = np.zeros((nb, BND_MATERIAL + state.nmat))
        self.floors = np.zeros((nb, NFLOOR), dtype=np.int64)
        self.amounts = np.zeros((nb, NAMOUNT))
        self._failure = np.zeros((nb, 4), dtype=np.int64)
        self._rate = np.zeros(nb)
        damage = pack_damage([(s or {}).get("damage") for s in (self.strength_specs or [None] * state.nmat)])
        gradual = damage.model == GRADY_KIPP
        if (gradual & ~(self.tensile_strength > 0.0)).any():
            k = int(np.flatnonzero(gradual & ~(self.tensile_strength > 0.0))[0])
            raise ValueError(f"material {k}: damage model grady_kipp needs a tensile strength Y_T > 0 (the most "
                             f"tension the intact material holds, where its yield curve closes)")
        #: (M,) True for the materials whose tension is borne as (1 - D) of the EOS tension (Grady-Kipp
        #: fracture, :func:`impactpipe.hydro.scheme.mixture.tension_factor`); None when there are none.
        self.grady_kipp = gradual if gradual.any() else None
        #: The sweep's ``grady_kipp`` and ``porosity`` arguments, arrays in every scene (all False;
        #: rows of alpha_0 = 1 without porous materials, which the sweep reads as non-porous): one
        #: compiled sweep serves every scene, where None and arrays would compile four (a cold
        #: compile of the sweep takes minutes).  The results are the same bit for bit.
        self._sweep_grady_kipp = gradual
        self._sweep_porosity = self.porosity if self.porosity is not None else np.ones((state.nmat, NPOROSITY))
        porous = self.porosity is not None
        #: Counters of the compaction step (:data:`impactpipe.hydro.eos.porosity.COUNT_NAMES`), per block.
        self.porosity_counts = np.zeros((nb, len(POROSITY_COUNT_NAMES)), dtype=np.int64)
        fresh = porous and state.arhoq.shape[1] == 0
        self.strength = MaterialStrength(arrays, mesh, state.nmat, damage, self.porosity) if arrays.enabled else None
        if self.strength is not None:
            self.strength.work = self.partition.zeros(self.strength.work.shape)
            self.strength.prepare_state(state, self.partition)
            for k, strains in self.strength.flaw_strains.items():  # recorded, so a checkpoint resumes with them
                self.strength_specs[k] = {**self.strength_specs[k],
                                          "damage": {**self.strength_specs[k]["damage"], "flaw_strains": strains}}
        elif self.grady_kipp is not None:
            raise ValueError("damage model grady_kipp needs a strength model with a yield strength")
        elif porous and fresh:
            own = self.partition.blocks
            state.arhoq = self.partition.zeros((mesh.nblocks, 2 * state.nmat) + mesh.padded_shape)
            for k in range(state.nmat):
                state.arhoq[own, 2 * k] = self.porosity[k, ALPHA0] * state.arho[own, k]
        elif state.arhoq.shape[1] and not porous:
            raise ValueError("the state carries per-material strength scalars but no material has strength")
        nq = state.arhoq.shape[1] // state.nmat
        #: Ghost layers of each column of ``state.arhoq`` that a step fills for the sweeps
        #: (:func:`~impactpipe.hydro.scheme.pencil_layout.transport_ghost_layers`; every layer on an adaptive mesh).
        self._q_layers = transport_ghost_layers(state.nmat, nq, porous)
        self._scratch = allocate_scratch(numba.config.NUMBA_NUM_THREADS, state.nmat, max(mesh.padded_shape), nq)
        self._rate_work = allocate_rate_work(numba.config.NUMBA_NUM_THREADS, mesh.padded_shape)
        self._face_flux = allocate_face_flux(mesh.nblocks if mesh.adaptive else 0, mesh.padded_shape, mesh.ndim,
                                             state.nmat, state.arhoq.shape[1])
        if mesh.adaptive and fill_ghosts:
            for axis in range(mesh.ndim):
                self.partition.fill_ghosts(state, mesh, axis)
        self._keep_good()
        self.check_time_stepping()

    def _keep_good(self) -> None:
        """Start the last-good copies (interior cells of the state, counters, clock) from the current ones:
        of the state, the rows of the blocks this process advances (in the partition's
        :meth:`~impactpipe.hydro.parallel.distributed.WholeMesh.zeros`: on several ranks the other
        rows are zero and never written)."""
        own = self.partition.blocks
        self._good = {}
        for name, arr in self.state.arrays().items():
            interior = self.mesh.interior(arr)
            self._good[name] = self.partition.zeros(interior.shape)
            self._good[name][own] = interior[own]
        #: per block, 1 where the last-good copy is of a void block (:mod:`impactpipe.hydro.mesh.last_good`)
        self._good_void = np.zeros(self.mesh.nblocks, dtype=np.uint8)
        #: per block, 1 where the block is void now (:func:`~impactpipe.hydro.mesh.last_good.void_blocks`)
        self._void_now = np.zeros(self.mesh.nblocks, dtype=np.uint8)
        #: per block, 1 where the last step left the block void (every pencil of its last sweep
        #: empty, nothing written to it since), for the next void test (:meth:`_keeps_void_record`)
        self._void_after = np.zeros(self.mesh.nblocks, dtype=np.uint8)
        #: per block, 1 where the last step left the block's scalars +0.0 (its last sweep's record
        #: not 0, its scalar stamp unchanged by the stress update), for the next clear-block record
        self._clear_after = np.zeros(self.mesh.nblocks, dtype=np.uint8)
        #: per block, not 0 where the last-good copy's transported scalars are +0.0
        self._good_clear = np.zeros(self.mesh.nblocks, dtype=np.uint8)
        #: per block, RECORD_CLEAR where its transported scalars are +0.0
        #: (:func:`~impactpipe.hydro.mesh.last_good.scalar_clear_blocks`), RECORD_VOID where it is
        #: void (:mod:`impactpipe.hydro.mesh.last_good`), else 0: row 0 at the start of a step,
        #: then the rows take turns as each sweep writes the record after it (:meth:`step`)
        self._scalars_clear = np.zeros((2, self.mesh.nblocks), dtype=np.uint8)
        #: per block, a column of its transported scalars last found not +0.0, or -1
        #: (:func:`~impactpipe.hydro.mesh.last_good.scalar_clear_blocks`)
        self._clear_hint = np.full(self.mesh.nblocks, -1, dtype=np.int64)
        #: the blocks' scalar stamps, for the ghost fills (:mod:`~impactpipe.hydro.mesh.scalar_stamps`)
        self._stamps = ScalarStamps(self.mesh.nblocks)
        self._good_counters = tuple(a.copy() for a in self._counter_arrays())
        self._good_clock = (self.time, self.step_count, self.cell_updates)
        self._good_gravity_work = None if self.gravity is None else self.gravity.work
        self._good_settled_cells = self.settled_cells
        self._good_last_dt = self.last_dt
        #: (dt, time after) of each step since the last-good copy (s), for :meth:`restore_last_good`
        #: to take them again; None: the next step takes a copy first (of the tracers' records too)
        self._replay: list[tuple[float, float]] | None = None
        #: how many of them precede the step begun last (the one a restore goes back to the start of)
        self._replay_upto = 0
        #: the time (s) at the start of the step being taken, where a failure is reported
        self._step_start_time = self.time

    # ------------------------------------------------------------------ stepping

    def stable_dt(self) -> float:
        """CFL time step of the current state (s).  It first records the void blocks of the state
        (:func:`~impactpipe.hydro.mesh.last_good.void_blocks`, into ``_void_now``), whose signal
        rate is 0 without a look at their cells; :meth:`step` takes its last-good copy of the same
        state right after, with this record."""
        st = self.state
        own = self.partition.blocks
        lo, hi, _ = own.indices(self.mesh.nblocks)
        fields = [arr.view(np.int64) for arr in (st.alpha, st.arho, st.arhoe, st.momentum, st.energy)]
        void_blocks(*fields, lo, hi, self._void_now, self._void_after)
        rates = self._rate[own]
        max_signal_rate(st.alpha[own], st.arho[own], st.arhoe[own], st.momentum[own], self.mesh.block_dx[own],
                        self.eos.kind, self.eos.params, self.eos.table, self.shear_modulus, self.mesh.ndim,
                        self._rate_work, rates, None if self.porosity is None else st.arhoq[own], self.porosity,
                        self._void_now[own])
        bad = np.flatnonzero(~np.isfinite(rates))
        first_bad = (own.start or 0) + int(bad[0]) if bad.size else -1
        rate, first_bad = self.partition.combine_rate(float(rates.max()), first_bad)
        if first_bad >= 0:
            raise HydroFailure("non-finite signal speed", self.time, first_bad, None, {})
        if rate <= 0.0:
            raise HydroFailure("no signal speed anywhere (empty or cold mesh)", self.time, -1, None, {})
        return self.cfl / rate

    def check_time_stepping(self) -> None:
        """Raise ValueError for an unknown ``time_stepping``, or naming what ``"per_level"`` does not
        support yet in this Simulation (gravity, porosity, several MPI ranks; of material strength:
        Grady-Kipp fracture, the hourglass viscosity, rough walls, the surface-layer pressure and
        the step-end tensile limit)."""
        if self.time_stepping not in TIME_STEPPING:
            raise ValueError(f"time_stepping must be one of {', '.join(TIME_STEPPING)} (got {self.time_stepping!r})")
        if self.time_stepping != PER_LEVEL:
            return
        strength = self.strength
        missing = [what for what, present in (
            ("gravity", self.gravity is not None),
            ("porosity", self.porosity is not None),
            ("more than one MPI rank", not isinstance(self.partition, WholeMesh)),
            ("grady_kipp fracture", self.grady_kipp is not None),
            ("the hourglass viscosity", strength is not None and strength.hourglass[0] > 0.0),
            ("rough walls", strength is not None and bool(strength.rough_walls)),
            ("the surface-layer pressure", strength is not None and strength.surface_gravity is not None),
            ("the step-end tensile limit (step_tensile_limit)", self.step_tensile_limit),
            ("void settling (void_settling)", self.void_settling)) if present]
        if missing:
            raise ValueError(f"time_stepping per_level does not support {', '.join(missing)} yet; use global")

    def regrid_interval(self) -> int:
        """Steps between regrids: ``refinement.interval``; per level, the root steps that hold as
        many finest substeps, max(1, interval // 2^max_level), so a shock crosses as many finest
        cells between regrids as with the global step."""
        if self.time_stepping == PER_LEVEL:
            return max(1, self.refinement.interval // 2 ** self.mesh.max_level)
        return self.refinement.interval

    def regrid_reach(self) -> int:
        """Cells a wave may cross between two regrids, plus the indicators' stencil cell:
        ceil(cfl x finest substeps between regrids) + 1 (``refinement.buffer: reach``,
        :func:`impactpipe.hydro.amr.regrid.block_wants`)."""
        substeps = self.regrid_interval() * (2 ** self.mesh.max_level if self.time_stepping == PER_LEVEL else 1)
        return int(np.ceil(self.cfl * substeps)) + 1

    def step(self, dt_max: float = np.inf) -> float:
        """Advance one step of at most ``dt_max`` (s); returns the step taken (s).

        Per level (``time_stepping``), one root-level step: level l in 2^l substeps of dt / 2^l.
        """
        self.check_time_stepping()
        per_level = self.time_stepping == PER_LEVEL
        if self.mesh.adaptive and self.step_count % self.regrid_interval() == 0:
            self.regrid()
        self._observe("regrid", -1)
        dt = self.stable_dt()
        if per_level:
            dt = level_time_step(self.mesh, self._rate, self.cfl)
        if self.dt_first is None:
            self.dt_first = dt
        elif dt < DT_COLLAPSE_FRACTION * self.dt_first:
            raise HydroFailure(f"time step collapsed to {dt:.3e} s (first step {self.dt_first:.3e} s)",
                               self.time, -1, None, {})
        dt = min(dt, dt_max)
        self._save_good()
        # the records of the step before are used; until this step ends (a failed step leaves none)
        self._void_after.fill(0)
        self._clear_after.fill(0)
        if self.tracers is not None:
            self.tracers.before_step(self)
        if per_level:
            self._stamps.forget()
            dt = self._level_step(dt)
            self.time += dt
            self.step_count += 1
            self.last_dt = dt
            if self.tracers is not None:
                self.tracers.after_step(self, dt)
            self._replay.append((dt, self.time))
            return dt
        axes = list(range(self.mesh.ndim))
        if self.step_count % 2:
            axes.reverse()
        st = self.state
        own = self.partition.blocks
        recorded = self._keeps_block_record()
        clear_now, clear_next = self._scalars_clear if recorded else (NO_RECORD, NO_RECORD)
        stamps = self._stamps if self._keeps_scalar_stamps() else None
        if stamps is None:
            self._stamps.forget()
        stamp = NO_STAMPS[0] if stamps is None else stamps.block
        for axis in axes:
            fill = self.partition.start_ghosts(st, self.mesh, axis, self._q_layers, clear_now if recorded else None,
                                               stamps)
            self._sweep(axis, dt, fill.early, clear_now, clear_next, stamp)
            self.partition.finish_ghosts(fill, st, self.mesh, axis)
            self._observe("ghosts", axis)
            self._sweep(axis, dt, fill.late, clear_now, clear_next, stamp)
            clear_now, clear_next = clear_next, clear_now
            failed = self.partition.first_failure(self._failure)
            if failed >= 0:
                self._raise_sweep_failure(failed)
            self._observe("sweep", axis)
            if self.mesh.adaptive:
                plans = self.partition.plans(self.mesh, axis)
                self.partition.share_face_flux(self._face_flux, axis)
                reflux(axis, plans["reflux"], plans["reflux_volume"], self._face_flux, st.alpha, st.arho, st.arhoe,
                       st.arhoq, st.momentum, st.energy, self.floors, self.amounts)
                self._observe("reflux", axis)
        if self.step_tensile_limit:
            lo, hi, _ = own.indices(self.mesh.nblocks)
            open_void_in_tension(st.alpha, st.arho, st.arhoe, st.arhoq, self.eos.kind, self.eos.params, self.eos.table,
                                 self.tensile_strength, self.floors, lo, hi)
        if self.void_settling:
            self._settle_void()
        if self.porosity is not None:
            lo, hi, _ = own.indices(self.mesh.nblocks)
            compact(st.alpha, st.arho, st.arhoq, self.porosity, self.porosity_counts, lo, hi)
        stamp_after_sweeps = None if stamps is None else stamp.copy()
        if self.strength is not None or self.gravity is not None:
            # the blocks still void after the sweeps (void settling moves material between them)
            self._momentum_sources(dt, clear_now if recorded and not self.void_settling else NO_RECORD, stamp)
            self._observe("sources", -1)
        if self._keeps_void_record():
            np.equal(clear_now, RECORD_VOID, out=self._void_after, casting="unsafe")
        if stamp_after_sweeps is not None:
            np.logical_and(clear_now != 0, stamp == stamp_after_sweeps, out=self._clear_after, casting="unsafe")
        self.time += dt
        self.step_count += 1
        self.cell_updates += self.mesh.ncells
        self.last_dt = dt
        if self.tracers is not None:
            self.partition.share_neighbourhood(st)
            self.tracers.after_step(self, dt)
        self._replay.append((dt, self.time))
        return dt

    def _keeps_block_record(self) -> bool:
        """Whether a step keeps the record of the void blocks and of the blocks whose transported
        scalars are +0.0 (:data:`~impactpipe.hydro.mesh.last_good.RECORD_VOID`,
        :func:`~impactpipe.hydro.mesh.last_good.scalar_clear_blocks`), for the ghost fills, the
        sweeps and the last-good copy to skip them: on a uniform mesh in one process (an adaptive
        mesh's coarse/fine ghosts and other ranks' strips are filled otherwise)."""
        return not self.mesh.adaptive and self.partition.keeps_scalar_record

    def _keeps_scalar_stamps(self) -> bool:
        """Whether a step keeps the blocks' scalar stamps (:mod:`~impactpipe.hydro.mesh.scalar_stamps`),
        for the ghost fills to skip the scalars a slab holds already: with the block record, where
        only the sweeps and the stress update change the scalars (no tensile limit at the end of
        the step, void settling or compaction).  A step without them forgets the ghost stamps."""
        return (self._keeps_block_record() and not self.step_tensile_limit and not self.void_settling
                and self.porosity is None)

    def _keeps_void_record(self) -> bool:
        """Whether the next void test may take the blocks the last sweep of a step recorded as void
        (RECORD_VOID: void at the start of the step, every pencil empty) as void without a look
        (:func:`~impactpipe.hydro.mesh.last_good.void_blocks`): with the scalar stamps
        (:meth:`_keeps_scalar_stamps`), where no kernel after the sweeps writes a void cell (the
        stress kicks and gravity leave a void cell's +0.0; not with the hourglass viscosity or the
        face shear stress)."""
        strength = self.strength
        return self._keeps_scalar_stamps() and (
            strength is None or (strength.hourglass[0] == 0.0 and strength.face is None))

    def _sweep(self, axis: int, dt: float, blocks: np.ndarray, scalars_clear: np.ndarray,
               clear_after: np.ndarray, scalar_stamp: np.ndarray = NO_STAMPS[0]) -> None:
        """Advance the partition's blocks listed in ``blocks`` (indices within ``partition.blocks``)
        by ``dt`` (s) along ``axis`` (:func:`~impactpipe.hydro.scheme.directional.sweep`, with
        its record of the blocks whose scalars are +0.0, or NO_RECORD, and the blocks' scalar
        stamps, or none)."""
        if blocks.size == 0:
            return
        st = self.state
        own = self.partition.blocks
        sweep(axis, dt, self.mesh.geometry_code, st.alpha[own], st.arho[own], st.arhoe[own], st.arhoq[own],
              st.momentum[own], st.energy[own], self.mesh.block_lo[own], self.mesh.block_dx[own],
              self.mesh.neighbor[own], self.mesh.neighbor_level[own], self.eos.kind, self.eos.params,
              self.eos.table, self.shear_modulus, self._sweep_tensile_strength(), self._scratch, self.boundary[own],
              self.floors[own], self.amounts[own], self._failure[own], self._face_flux[own], self.plain_pencils,
              blocks, scalars_clear, clear_after, scalar_stamp, self._sweep_grady_kipp, self._sweep_porosity,
              self.bulk_pressure_predictor)

    def _settle_void(self) -> None:
        """Settle the void under resting material out of every column (:attr:`void_settling`,
        :func:`~impactpipe.hydro.scheme.settling.settle_void`); the potential energy it releases is
        added to the work of gravity."""
        mesh = self.mesh
        g = None if self.gravity is None else getattr(self.gravity, "acceleration", None)
        if (mesh.geometry != "2d-planar" or g is None or g[0] != 0.0 or not g[1] < 0.0
                or int(mesh.block_level.max()) != int(mesh.block_level.min())
                or not isinstance(self.partition, WholeMesh)):
            raise ValueError("void_settling needs a 2d-planar mesh on one level, one process and a uniform "
                             "gravity along -axis 1")
        st = self.state
        if self._settling_buffers is None or self._settling_buffers[0].shape[0] != mesh.nblocks:
            self._settling_buffers = (np.zeros(mesh.nblocks), np.zeros(mesh.nblocks, np.int64))
        work, counts = self._settling_buffers
        work[:] = 0.0
        counts[:] = 0
        settle_void(st.alpha, st.arho, st.arhoe, st.arhoq, st.momentum, st.energy, mesh.neighbor, mesh.block_dx,
                    -float(g[1]), work, counts)
        self.gravity.work += float(work.sum())
        self.settled_cells += int(counts.sum())

    def _sweep_tensile_strength(self) -> np.ndarray:
        """The tensile strengths Y_T (Pa) the sweeps hold: the materials', or UNLIMITED_TENSION for every
        material with :attr:`step_tensile_limit` (the limit then acts after the sweeps)."""
        if not self.step_tensile_limit:
            return self.tensile_strength
        if self.porosity is not None or self.grady_kipp is not None:
            raise ValueError("step_tensile_limit is not supported with porous or grady_kipp materials")
        if self._unlimited_tension is None:
            self._unlimited_tension = np.full_like(self.tensile_strength, UNLIMITED_TENSION)
        return self._unlimited_tension

    def _observe(self, event: str, axis: int) -> None:
        if self.observer is not None:
            self.observer(event, axis)

    def _level_step(self, dt: float) -> float:
        """Advance every level by the root step ``dt`` (s) and count the cell-updates (those of a
        root step taken again too); returns the step taken (s).

        The level-l substeps keep the CFL condition of the state at the root step's start, while
        the global step takes its finest step anew from the state every finest step.  So on a
        mesh of several levels the root step is taken again from the last good copy, at most
        :data:`LEVEL_STEP_RETAKES` times (counted in ``level_step_retakes``), where

        - the signal speed grew during the root step so much that the state at its end allows
          only dt' < dt / :data:`LEVEL_STEP_GROWTH` (level_time_step of the rates at the end):
          again at dt';
        - a substep failed (a sweep's negative density or NaN, :class:`HydroFailure`): again at
          dt / 2, the failure raised only when the last retake fails too.

        The tracers' records are put back with the state (:meth:`restore_last_good`), so the
        peaks that the discarded root step's substeps recorded are dropped and the retaken one
        records its own.
        """
        updates = 0
        retakes = 0
        while True:
            try:
                updates += self._level_stepper.advance(self, dt)
            except HydroFailure:
                if self.mesh.block_level.max() == 0 or retakes >= LEVEL_STEP_RETAKES:
                    raise
                self.restore_last_good()
                dt *= 0.5
            else:
                if self.mesh.block_level.max() == 0 or retakes >= LEVEL_STEP_RETAKES:
                    break
                self.stable_dt()
                allowed = level_time_step(self.mesh, self._rate, self.cfl)
                if dt <= LEVEL_STEP_GROWTH * allowed:
                    break
                self.restore_last_good()
                dt = allowed
            retakes += 1
            self.level_step_retakes += 1
        self.cell_updates += updates
        return dt

    def _momentum_sources(self, dt: float, record: np.ndarray = NO_RECORD,
                          stamp: np.ndarray = NO_STAMPS[0]) -> None:
        """Stress divergence and gravity over ``dt`` (s), kick - stress update - kick.

        Half of each impulse before the stress update and half after it
        (:mod:`impactpipe.hydro.strength.model`), so the stress sees the half-step velocity: a
        body at rest in equilibrium between its stress and gravity feels no net kick before
        the update and is not strained by it.  ``record``: the last sweep's record of the
        blocks (RECORD_VOID: void, untouched by the step), or NO_RECORD; ``stamp``: the blocks'
        scalar stamps (:mod:`~impactpipe.hydro.mesh.scalar_stamps`), or empty.
        """
        st = self.state
        half = 0.5 * dt
        part = self.partition
        if self.gravity is not None:
            self.gravity.prepare(st, self.mesh, part)
        if self.strength is not None:
            self.strength.load_stress(st, self.eos, part, record=record)
            self.strength.kick(st, half, self.boundary, self.floors, self.amounts, part)
        if self.gravity is not None:
            self.gravity.advance(st, half, self.mesh.block_lo, self.mesh.block_dx, part)
        if self.strength is not None:
            self.strength.update(st, dt, self.eos, part, kicked_only=self.gravity is None, record=record,
                                 stamp=stamp)
            self.strength.kick(st, half, self.boundary, self.floors, self.amounts, part)
        if self.gravity is not None:
            self.gravity.advance(st, half, self.mesh.block_lo, self.mesh.block_dx, part)
        self._check_momentum(part.blocks)

    def _check_momentum(self, blocks) -> None:
        """Raise HydroFailure where the momentum of ``blocks`` (a slice or int64 indices) is not finite
        after the strength and gravity step (on any process)."""
        momentum = self.state.momentum
        finite = (finite_blocks(momentum, blocks) if isinstance(blocks, np.ndarray)
                  else finite_run(momentum[blocks].view(np.int64)))
        if self.partition.any(not finite):
            raise HydroFailure("NaN in the momentum after the strength and gravity step", self._step_start_time, -1,
                               None, {})

    def run(self, end_time: float, output_times: Iterable[float] = (), on_output: Callable | None = None,
            progress: Callable[[float], None] | None = None, max_steps: int | None = None) -> int:
        """Advance to ``end_time`` (s); returns the number of steps taken.

        At each of ``output_times`` (s, within (time, end_time]) the step is shortened to land
        on it and ``on_output(self.snapshot())`` is called.  ``progress(t)`` is called after
        every step.  ``max_steps`` stops the run early (no error).
        """
        outputs = sorted(t for t in output_times if self.time < t <= end_time)
        steps = 0
        while self.time < end_time * (1.0 - 1e-14) and (max_steps is None or steps < max_steps):
            target = outputs[0] if outputs else end_time
            self.step(dt_max=target - self.time)
            steps += 1
            if outputs and self.time >= outputs[0] * (1.0 - 1e-14):
                self.time = outputs.pop(0)
                self._replay[-1] = (self._replay[-1][0], self.time)
                if on_output is not None:
                    on_output(self.snapshot())
            if progress is not None:
                progress(self.time)
            if self.step_count % LOG_INTERVAL == 0:
                logger.info("step %d t=%.6g s dt=%.3e s max p=%.4g Pa", self.step_count, self.time,
                            self.last_dt, self.max_pressure())
        if self.time >= end_time * (1.0 - 1e-14):
            self.time = end_time
        return steps

    # ------------------------------------------------------------------ refinement

    def regrid(self) -> bool:
        """Refine and coarsen the adaptive mesh by the refinement rule; True when it changed.

        The state moves onto the new blocks conservatively (:mod:`impactpipe.hydro.amr.regrid`).
        Per-block counters are summed into the new mesh's first block, so every total stays.
        """
        started = time.perf_counter()
        try:
            return self._regrid()
        finally:
            self.regrid_seconds += time.perf_counter() - started

    def refinement_flags(self) -> tuple[np.ndarray, np.ndarray]:
        """(refine, coarsen): per block, whether the refinement rule refines it or lets it coarsen now.

        Fills the state's first ghost layer along every axis (what the indicators and the
        regrid read, :func:`~impactpipe.hydro.mesh.boundary.fill_first_ghost_layer`, through the
        partition's exchanges on several ranks; the step fills every layer along an axis before
        its sweep; the last axis's strips travel while the pressure of the blocks whose layer is
        complete is evaluated) and raises ``peak_pressure`` (Pa) to the largest |p| on the mesh
        (:func:`impactpipe.hydro.amr.regrid.flag_blocks`; on several ranks each reads its own
        blocks, and every rank gets the same flags).  Collective on several ranks.
        """
        last = self.mesh.ndim - 1
        for axis in range(last):
            self.partition.fill_first_ghost_layer(self.state, self.mesh, axis)
        fill = self.partition.start_first_ghost_layer(self.state, self.mesh, last)

        def finish_fill() -> None:
            self.partition.finish_first_ghost_layer(fill, self.state, self.mesh, last)

        if not fill.late.size:
            finish_fill()
        refine, coarsen, self.peak_pressure = flag_blocks(
            self.mesh, self.state, self.eos, self.shear_modulus, self.tensile_strength, self.refinement,
            self.peak_pressure, self.grady_kipp, self.porosity, self.regrid_reach(),
            None if self.partition.whole else self.partition, fill.late, finish_fill if fill.late.size else None)
        return refine, coarsen

    def _regrid(self) -> bool:
        """:meth:`regrid`: on several ranks each reads and builds its own blocks only, and every
        rank reaches the same plan (:meth:`~impactpipe.hydro.parallel.distributed.BlockRanges.regrid`)."""
        refine, coarsen = self.refinement_flags()
        plan = plan_leaves(self.mesh, refine, coarsen)
        if plan is None:
            return False
        self.regrids += 1
        self.blocks_refined += len(plan["children"]) // 2 ** self.mesh.ndim
        self.blocks_coarsened += len(plan["parents"]) // 2 ** self.mesh.ndim
        self.move_to_mesh(plan)
        return True

    def move_to_mesh(self, plan: dict, new_mesh: BlockMesh | None = None) -> None:
        """Move the state onto the new blocks of ``plan`` (:func:`~impactpipe.hydro.amr.regrid.plan_leaves`:
        ``level``, ``index`` of the new leaves, and rows ``keep``, ``children``, ``parents``) on
        the mesh of its leaves, or on ``new_mesh`` where a scene changes the root grid (the column
        collapse's growth along x,
        :meth:`impactpipe.hydro.problems.column_collapse.ColumnCollapseSimulation.grow`); collective
        on several ranks (:meth:`~impactpipe.hydro.parallel.distributed.BlockRanges.regrid`).  The
        per-block counters' totals go to block 0, every other per-block array is built again for
        the new blocks and the last-good copy is taken again."""
        old = self.partition
        self._good = {}  # taken again once the state has moved (_keep_good): not held through the move
        new_mesh, self.state, self.partition = old.regrid(self, plan, new_mesh)
        st = self.state
        self.mesh = new_mesh
        nb = new_mesh.nblocks
        self.boundary, self.floors, self.amounts, self.porosity_counts = (
            old.summed_rows(a, nb) for a in (self.boundary, self.floors, self.amounts, self.porosity_counts))
        self._failure = np.zeros((nb, 4), dtype=np.int64)
        self._rate = np.zeros(nb)
        self._face_flux = allocate_face_flux(nb if new_mesh.adaptive else 0, new_mesh.padded_shape, new_mesh.ndim,
                                             st.nmat, st.arhoq.shape[1], self.partition.zeros)
        if self.strength is not None:
            self.strength.mesh_changed(new_mesh, None if self.partition.whole else self.partition, old.summed_rows)
        if self.tracers is not None:
            self.tracers.mesh_changed(new_mesh)
        self._keep_good()

    # ------------------------------------------------------------------ failure handling

    def _last_good_interval(self) -> int:
        """Steps between two last-good copies: LAST_GOOD_INTERVAL, or 1 where the solver takes a
        step again from the copy itself (an adaptive mesh's regrids, the root steps per level) or a
        step changes more than the state, the counters, the tracers and the clock (the face shear
        stresses of the strength model)."""
        if self.mesh.adaptive or self.time_stepping == PER_LEVEL or (
                self.strength is not None and self.strength.face is not None):
            return 1
        return LAST_GOOD_INTERVAL

    def _save_good(self) -> None:
        """At the start of a step: the records of the void blocks and of the blocks whose scalars
        are +0.0 (for the ghost fills and the sweeps); then, on the first step after the copies were
        taken anew (:meth:`_keep_good`) or once :meth:`_last_good_interval` steps were taken since
        the last copy, the last-good copies: the interior cells of the state (the ghosts are
        refilled before every use, so a restore refills them instead of keeping a copy: 35 % less
        memory in 3D with 8^3 blocks), the counters, the clock and the tracers' records
        (:meth:`restore_last_good` takes the steps since again).  A void block whose copy is void
        already is not copied again (:mod:`impactpipe.hydro.mesh.last_good`; the void blocks as
        :meth:`stable_dt` recorded them, on this state, just before); the others are
        copied by numpy's strided copy, one run of consecutive blocks at a time (on the
        machines measured it copies at 4-5 ns per 2D gas-box cell on one thread, where a
        parallel numba kernel took 7 ns on two, docs/performance.md)."""
        own = self.partition.blocks
        st = self.state
        lo, hi, _ = own.indices(self.mesh.nblocks)
        self._step_start_time = self.time
        void = self._void_now
        clear = self._scalars_clear[0]
        if self._keeps_block_record():
            scalar_clear_blocks(st.arhoq.view(np.int64), void, lo, hi, clear, self._clear_hint, self._clear_after)
            clear[lo:hi][void[lo:hi] != 0] = RECORD_VOID
        else:
            clear[lo:hi] = 0
        if self._replay is not None and len(self._replay) < self._last_good_interval():
            self._replay_upto = len(self._replay)
            return
        copy = np.zeros(self.mesh.nblocks, dtype=bool)
        copy[lo:hi] = (void[lo:hi] == 0) | (self._good_void[lo:hi] == 0)
        # a block whose scalars are +0.0 now and were at the copy keeps its copy of them
        copy_scalars = copy.copy()
        copy_scalars[lo:hi] &= (clear[lo:hi] == 0) | (self._good_clear[lo:hi] == 0)
        runs = block_runs(copy)
        scalar_runs = block_runs(copy_scalars)
        for name, arr in st.arrays().items():
            interior = self.mesh.interior(arr)
            if self._good[name].shape != interior.shape:
                self._good[name] = interior.copy()
                continue
            for start, stop in (scalar_runs if name == "arhoq" else runs):
                np.copyto(self._good[name][start:stop], interior[start:stop])
        self._good_void[lo:hi] = void[lo:hi]
        self._good_clear[lo:hi] = clear[lo:hi]
        for dst, src in zip(self._good_counters, self._counter_arrays()):
            np.copyto(dst, src)
        self._good_clock = (self.time, self.step_count, self.cell_updates)
        self._good_gravity_work = None if self.gravity is None else self.gravity.work
        self._good_settled_cells = self.settled_cells
        self._good_last_dt = self.last_dt
        self._replay = []
        self._replay_upto = 0
        if self.tracers is not None:
            self.tracers.keep_good(self)

    def state_changed(self) -> None:
        """Say that the state was changed from outside between two steps: the next step takes its
        last-good copy first, so that :meth:`restore_last_good` after a failure gives the state
        with the change (the steps it takes again start from the copy, and would not make it),
        and its ghost fills copy every slab's transported scalars (a change to them from outside
        raised no stamp, :mod:`~impactpipe.hydro.mesh.scalar_stamps`) and its void test looks at
        every block (:meth:`_keeps_void_record`): a change to the state between two steps must be
        announced so."""
        self._replay = None
        self._stamps.forget()
        self._void_after.fill(0)
        self._clear_after.fill(0)

    def restore_last_good(self) -> None:
        """Put back the state and counters from the start of the last (failed) step: the last-good
        copies (:meth:`_save_good`; the interior cells, the ghosts filled from them), then the steps
        taken since the copy, again, each to its dt and landing time, which gives the same state
        bit for bit (collective on several ranks: each restores its own blocks, and with tracers the
        cells around them that the tracers read; every rank takes the same steps again).  A change
        made to the state from outside between two steps is kept only where :meth:`state_changed`
        said so."""
        own = self.partition.blocks
        self._stamps.forget()
        self._void_after.fill(0)
        self._clear_after.fill(0)
        for name, arr in self.state.arrays().items():
            np.copyto(self.mesh.interior(arr)[own], self._good[name][own])
        for axis in range(self.mesh.ndim):
            self.partition.fill_ghosts(self.state, self.mesh, axis)
        for dst, src in zip(self._counter_arrays(), self._good_counters):
            np.copyto(dst, src)
        self.time, self.step_count, self.cell_updates = self._good_clock
        if self.gravity is not None:
            self.gravity.work = self._good_gravity_work
        self.settled_cells = self._good_settled_cells
        if self.strength is not None and self._keeps_block_record():
            # the work arrays of the steps undone: a block void in the copy is passed over by the
            # first step taken again (cell_velocity_and_stress), whose fills must be 0 as it left them
            self.strength.work.fill(0.0)
        self.last_dt = self._good_last_dt
        self._failure[:] = 0
        if self.tracers is not None:
            self.partition.share_neighbourhood(self.state)
            self.tracers.restore_good(self.partition)
        steps = [] if self._replay is None else self._replay[:self._replay_upto]
        self._replay = None if self._replay is None else []
        for dt, landed in steps:
            self.step(dt_max=dt)
            self.time = landed
        if self._replay is not None:
            self._replay_upto = len(self._replay)

    def _strength_counters(self) -> tuple:
        if self.strength is None:
            return ()
        return (self.strength.counts.copy(), self.strength.amounts.copy())

    def _named_counters(self) -> dict[str, np.ndarray]:
        """The per-block counters a checkpoint stores, by their names there."""
        counters = {"boundary": self.boundary, "floors": self.floors, "amounts": self.amounts}
        if self.porosity is not None:
            counters["porosity_counts"] = self.porosity_counts
        if self.strength is not None:
            counters.update(strength_counts=self.strength.counts, strength_amounts=self.strength.amounts)
        return counters

    def _counter_arrays(self) -> tuple:
        arrays = (self.boundary, self.floors, self.amounts, self.porosity_counts)
        if self.strength is not None:
            arrays += (self.strength.counts, self.strength.amounts)
        return arrays

    def _raise_sweep_failure(self, b: int) -> None:
        """Raise the HydroFailure of block ``b``, the first whose sweep failed (on every process,
        with the values of the process that owns it)."""
        code, cell, values = self.partition.from_owner(b, lambda: self._failure_record(b))
        what = {1: "NaN in the updated state", 2: "negative density"}.get(code, "sweep failure")
        raise HydroFailure(what, self._step_start_time, b, cell, values)

    def _failure_record(self, b: int) -> tuple[int, tuple[int, int, int], dict]:
        """(failure code, padded cell, the cell's values) of block ``b``: after the failed sweep, and
        under "before" in the last-good copy, taken at the start of step "before_step"."""
        code, ix, iy, iz = (int(v) for v in self._failure[b])
        values = {name: getattr(self.state, name)[b, :, ix, iy, iz].tolist() for name in FIELDS}
        g = self.mesh.ghost
        values["before"] = {name: self._good[name][b, :, ix - g[0], iy - g[1], iz - g[2]].tolist() for name in FIELDS}
        values["before_step"] = self._good_clock[1]
        return code, (ix, iy, iz), values

    # ------------------------------------------------------------------ diagnostics

    @property
    def floor_counts(self) -> dict[str, int]:
        """How often each floor / fallback was applied since the start (cells x sweeps; with
        :attr:`void_settling`, ``void_settling``: the cells that took settled material)."""
        totals = self.floors.sum(axis=0)
        counts = {name: int(v) for name, v in zip(FLOOR_NAMES, totals)}
        if self.strength is not None:
            counts.update(self.strength.count_totals)
        if self.porosity is not None:
            counts.update({name: int(v) for name, v in zip(POROSITY_COUNT_NAMES, self.porosity_counts.sum(axis=0))})
        if self.void_settling:
            counts["void_settling"] = self.settled_cells
        return counts

    @property
    def floor_amounts(self) -> dict[str, float]:
        """Mass (kg), energy (J) and signed momentum components (kg m/s) added, reconciled or removed
        by the floors, since the start (names: :data:`~impactpipe.hydro.scheme.pencil_layout.AMOUNT_NAMES`)."""
        totals = self.amounts.sum(axis=0)
        amounts = {name: float(v) for name, v in zip(AMOUNT_NAMES, totals)}
        if self.strength is not None:
            amounts.update(self.strength.amount_totals)
        return amounts

    def totals(self) -> dict:
        """Mesh totals and what left through the domain boundaries (SI).

        ``mass`` (kg), ``material_mass`` (M,), ``momentum`` (3,) (kg m/s; in 2d-cylindrical
        only the z component is a conserved total), ``energy`` (J); ``outflow_*`` the
        amounts that left through domain faces (wall impulse included for momentum);
        ``*_with_outflow`` the sums, constant in time up to the floor amounts.
        ``momentum_magnitude`` is sum |rho u| V over the cells (kg m/s), the scale of the
        momentum budget; ``momentum_conserved`` (3 bools) the components that nothing but the
        fluxes and the counted floors change: every one in 3d and 2d-planar, z alone in
        2d-cylindrical, less those along an external g, none under self-gravity
        (:func:`impactpipe.hydro.budget.conservation_budget`).  Collective on several ranks:
        each process sums its own blocks, every process receives every block's sums
        (:meth:`~impactpipe.hydro.parallel.distributed.WholeMesh.share_rows`, a row of
        M + 5 values and one of the boundary counters per block) and adds them up in block
        order, so any number of ranks gives the same bits and no process gathers the state.
        """
        mesh = self.mesh
        own = self.partition.blocks
        nmat = self.state.nmat
        vol = mesh.cell_volumes(own)[:, None]
        sums = np.zeros((mesh.nblocks, nmat + 5))
        sums[own, :nmat] = (mesh.interior(self.state.arho[own]) * vol).sum(axis=(2, 3, 4))
        mom = mesh.interior(self.state.momentum[own])
        sums[own, nmat : nmat + 3] = (mom * vol).sum(axis=(2, 3, 4))
        sums[own, nmat + 3] = (np.sqrt((mom * mom).sum(axis=1)) * vol[:, 0]).sum(axis=(1, 2, 3))
        sums[own, nmat + 4] = (mesh.interior(self.state.energy[own])[:, 0] * vol[:, 0]).sum(axis=(1, 2, 3))
        boundary = np.zeros_like(self.boundary)
        boundary[own] = self.boundary[own]
        self.partition.share_rows(sums)
        self.partition.share_rows(boundary)
        total = sums.sum(axis=0)
        material_mass = total[:nmat]
        momentum = total[nmat : nmat + 3]
        magnitude = float(total[nmat + 3])
        energy = float(total[nmat + 4])
        bnd = boundary.sum(axis=0)
        out = {
            "mass": float(material_mass.sum()),
            "material_mass": material_mass,
            "momentum": momentum,
            "momentum_magnitude": magnitude,
            "momentum_conserved": self._momentum_conserved(),
            "energy": energy,
            "outflow_mass": float(bnd[BND_MASS]),
            "outflow_material_mass": bnd[BND_MATERIAL:].copy(),
            "outflow_momentum": bnd[BND_MOMENTUM : BND_MOMENTUM + 3].copy(),
            "outflow_energy": float(bnd[BND_ENERGY]),
        }
        out["mass_with_outflow"] = out["mass"] + out["outflow_mass"]
        out["momentum_with_outflow"] = out["momentum"] + out["outflow_momentum"]
        out["energy_with_outflow"] = out["energy"] + out["outflow_energy"]
        return out

    def _momentum_conserved(self) -> tuple[bool, bool, bool]:
        """The momentum components (x, y, z) only the fluxes and the counted floors change (:meth:`totals`)."""
        if self.mesh.geometry == "2d-cylindrical":
            conserved = [False, True, False]
        else:
            conserved = [True, True, True]
        if self.gravity is not None:
            g = getattr(self.gravity, "acceleration", None)
            conserved = [c and g is not None and g[axis] == 0.0 for axis, c in enumerate(conserved)]
        return tuple(conserved)

    def max_pressure(self) -> float:
        """The largest mixture pressure of any cell (Pa; the snapshots' ``pressure``), from the
        blocks each process advances and one reduction (MAX) over the processes."""
        own = self.partition.blocks
        st = self.state
        shape = (len(range(*own.indices(self.mesh.nblocks))),) + self.mesh.interior_shape
        pressure, sound, eint, temp = (np.zeros(shape) for _ in range(4))
        cell_thermodynamics(st.alpha[own], st.arho[own], st.arhoe[own], st.arhoq[own], self.eos.kind,
                            self.eos.params, self.eos.table, self.shear_modulus, self.tensile_strength, pressure,
                            sound, eint, temp, self.grady_kipp, self.porosity)
        return self.partition.largest(float(pressure.max()))

    def snapshot(self) -> Snapshot:
        """The interior cells at the current time as a :class:`Snapshot` (copies).  Collective
        on several ranks: each computes the fields of its own blocks, and the process that
        writes (rank 0) receives them, unless the ranks write the snapshot together
        (:attr:`~impactpipe.hydro.parallel.distributed.WholeMesh.writes_together`); the other
        ranks' snapshots (every rank's, writing together) hold only their own blocks (zeros
        elsewhere, in the partition's :meth:`~impactpipe.hydro.parallel.distributed.WholeMesh.zeros`:
        pages never written)."""
        mesh = self.mesh
        st = self.state
        own = self.partition.blocks
        shape = (mesh.nblocks,) + mesh.interior_shape
        zeros = self.partition.zeros
        pressure, sound, eint, temp = (zeros(shape) for _ in range(4))
        cell_thermodynamics(st.alpha[own], st.arho[own], st.arhoe[own], st.arhoq[own], self.eos.kind,
                            self.eos.params, self.eos.table, self.shear_modulus, self.tensile_strength,
                            pressure[own], sound[own], eint[own], temp[own], self.grady_kipp, self.porosity)
        arho = zeros((mesh.nblocks, st.nmat) + mesh.interior_shape)
        alpha = zeros(arho.shape)
        arho[own] = mesh.interior(st.arho)[own]
        alpha[own] = mesh.interior(st.alpha)[own]
        velocity = zeros((mesh.nblocks, 3) + mesh.interior_shape)
        rho = arho[own].sum(axis=1)
        safe = np.where(rho > 0.0, rho, 1.0)
        velocity[own] = np.where(rho[:, None] > 0.0, mesh.interior(st.momentum)[own] / safe[:, None], 0.0)
        extra = {} if self.strength is None else self.strength.cell_fields(st, own)
        if self.porosity is not None:
            extra["distension"] = np.zeros(shape)
            extra["distension"][own] = distension_field(mesh.interior(st.arho)[own], mesh.interior(st.arhoq)[own],
                                                        self.porosity)
        if not self.partition.writes_together:
            self.partition.gather_to_root([pressure, sound, eint, temp, arho, alpha, velocity, *extra.values()])
        return Snapshot(
            time=self.time,
            geometry=mesh.geometry,
            material_names=list(self.material_names),
            block_lo=mesh.block_lo.copy(),
            block_hi=mesh.block_hi.copy(),
            block_level=mesh.block_level.copy(),
            block_id=mesh.block_id.copy(),
            partial_density=arho,
            volume_fraction=alpha,
            velocity=velocity,
            specific_internal_energy=eint,
            pressure=pressure,
            temperature=temp,
            sound_speed=sound,
            extra=extra,
        )

    # ------------------------------------------------------------------ checkpoints

    def save_checkpoint(self, path: str | Path) -> None:
        """Write the full state (ghosts included), mesh, materials and counters to HDF5, atomically.

        Collective on several ranks: rank 0 receives every block's rows of the state and the
        counters in arrays of their own (:meth:`~impactpipe.hydro.parallel.distributed.WholeMesh.rows_at_root`),
        writes them and drops them; the other ranks' arrays are unchanged.  Where the ranks
        write together (:attr:`~impactpipe.hydro.parallel.distributed.WholeMesh.writes_together`)
        each writes its own blocks' rows into the one file instead, and the attributes are rank 0's.
        The tracers, each held by the rank owning its block, are gathered in their order on the
        ranks that write (:meth:`~impactpipe.hydro.tracers.motion.Tracers.assembled`).
        """
        part = self.partition
        attrs = self._checkpoint_attributes()
        tracers = None if self.tracers is None else self.tracers.assembled(part, everywhere=part.writes_together)
        if part.writes_together:
            attrs = part.agree(attrs)
            state = {name: getattr(self.state, name) for name in FIELDS}
            counters = self._named_counters()
            rows = part.blocks
        else:
            state = {name: part.rows_at_root(getattr(self.state, name)) for name in FIELDS}
            counters = {name: part.rows_at_root(array) for name, array in self._named_counters().items()}
            rows = None
            if not part.is_root:
                return
        with part.atomic_output(path) as tmp:
            with part.output_file(tmp, "w") as fh:
                fh.attrs.update(attrs)
                mesh_grp = fh.create_group("mesh")
                for key, value in self.mesh.to_arrays().items():
                    if isinstance(value, (str, int)):
                        mesh_grp.attrs[key] = value
                    else:
                        store_array(mesh_grp, key, value)
                state_grp = fh.create_group("state")
                for name in FIELDS:
                    store_array(state_grp, name, state[name], rows)
                ctr = fh.create_group("counters")
                store_array(ctr, "boundary", counters["boundary"], rows)
                store_array(ctr, "floors", counters["floors"], rows).attrs["names"] = json.dumps(FLOOR_NAMES)
                store_array(ctr, "amounts", counters["amounts"], rows).attrs["names"] = json.dumps(AMOUNT_NAMES)
                store_array(ctr, "shear_modulus", self.shear_modulus)
                store_array(ctr, "tensile_strength", self.tensile_strength)
                if self.porosity is not None:
                    store_array(ctr, "porosity_counts", counters["porosity_counts"], rows)
                if self.strength is not None:
                    store_array(ctr, "strength_counts", counters["strength_counts"], rows)
                    store_array(ctr, "strength_amounts", counters["strength_amounts"], rows)
                if tracers is not None:
                    tracers.save(fh.create_group("tracers"))

    def _checkpoint_attributes(self) -> dict:
        """The scalars of a checkpoint: clock, counts, the scene's settings (JSON where not a number)."""
        return {
            "time": self.time,
            "step_count": self.step_count,
            "cell_updates": self.cell_updates,
            "cfl": self.cfl,
            "time_stepping": self.time_stepping,
            "dt_first": -1.0 if self.dt_first is None else self.dt_first,
            "material_names": json.dumps(self.material_names),
            "eos_specs": json.dumps(self.eos_specs),
            "strength_specs": json.dumps(self.strength_specs),
            "refinement": json.dumps(dataclasses.asdict(self.refinement)),
            "regrids": self.regrids,
            "level_step_retakes": self.level_step_retakes,
            "settled_cells": self.settled_cells,
            "blocks_refined": self.blocks_refined,
            "blocks_coarsened": self.blocks_coarsened,
            "peak_pressure": self.peak_pressure,
            "gravity": json.dumps(None if self.gravity is None else self.gravity.spec()),
        }

    @classmethod
    def from_checkpoint(cls, path: str | Path, comm=None) -> "Simulation":
        """Rebuild a Simulation written by :meth:`save_checkpoint`; it continues bit for bit.

        With ``comm`` (an MPI communicator; collective) the run is shared between its ranks as
        :func:`~impactpipe.hydro.parallel.distributed.distribute` would share the whole run,
        but no rank holds more of the state than its own blocks and their halo: the blocks are
        cut by the saved state's costs
        (:func:`~impactpipe.hydro.parallel.distributed.checkpoint_partition`), each rank reads
        its own rows (:func:`~impactpipe.hydro.parallel.owned_memory.read_owned_rows`) and
        receives its halo from their owners
        (:func:`~impactpipe.hydro.parallel.owned_memory.receive_halos`).  Raises ValueError on
        every rank for a mesh it cannot share (more ranks than blocks)."""
        if comm is not None:
            comm.Barrier()  # a checkpoint the ranks have just written is complete (renamed by rank 0)
        with h5py.File(path, "r") as fh:
            mesh_data = dict(fh["mesh"].attrs)
            mesh_data.update({key: fh["mesh"][key][()] for key in fh["mesh"]})
            mesh = BlockMesh.from_arrays(mesh_data)
            nmat = fh["state/alpha"].shape[1]
            partition = None if comm is None else checkpoint_partition(comm, mesh, fh["state/alpha"])
            arrays = {name: read_owned_rows(fh["state"][name], partition) for name in FIELDS if name in fh["state"]}
            arrays.setdefault("arhoq", np.zeros((mesh.nblocks, 0) + mesh.padded_shape))
            state = HydroState(**arrays)
            strength = json.loads(fh.attrs.get("strength_specs", "null"))
            shear = fh["counters/shear_modulus"][()]
            sim = cls(mesh, json.loads(fh.attrs["material_names"]), json.loads(fh.attrs["eos_specs"]), state,
                      cfl=float(fh.attrs["cfl"]), shear_modulus=None if strength else shear.reshape(nmat, -1)[:, 0],
                      tensile_strength=fh["counters/tensile_strength"][()],
                      time=float(fh.attrs["time"]), strength=strength,
                      refinement=_rule_from_json(fh.attrs.get("refinement")),
                      time_stepping=str(fh.attrs.get("time_stepping", GLOBAL)), partition=partition,
                      fill_ghosts=False)  # the ghosts as saved, so an adaptive run continues exactly
            if partition is not None:
                receive_halos(sim, partition)
            sim.regrids = int(fh.attrs.get("regrids", 0))
            sim.level_step_retakes = int(fh.attrs.get("level_step_retakes", 0))
            sim.settled_cells = int(fh.attrs.get("settled_cells", 0))
            sim.blocks_refined = int(fh.attrs.get("blocks_refined", 0))
            sim.blocks_coarsened = int(fh.attrs.get("blocks_coarsened", 0))
            sim.peak_pressure = float(fh.attrs.get("peak_pressure", 0.0))
            gravity = json.loads(fh.attrs.get("gravity", "null"))
            if gravity is not None:
                sim.gravity = gravity_from_spec(gravity, mesh)
            sim.step_count = int(fh.attrs["step_count"])
            sim.cell_updates = int(fh.attrs["cell_updates"])
            dt_first = float(fh.attrs["dt_first"])
            sim.dt_first = None if dt_first < 0 else dt_first
            sim.boundary[:] = fh["counters/boundary"][()]
            _load_named_columns(fh["counters/floors"], FLOOR_NAMES, sim.floors)
            _load_named_columns(fh["counters/amounts"], AMOUNT_NAMES, sim.amounts, FIRST_AMOUNT_NAMES)
            if sim.porosity is not None:
                sim.porosity_counts[:] = fh["counters/porosity_counts"][()]
            if sim.strength is not None:
                sim.strength.counts[:] = fh["counters/strength_counts"][()]
                sim.strength.amounts[:] = fh["counters/strength_amounts"][()]
            if "tracers" in fh:
                from impactpipe.hydro.tracers.motion import Tracers

                sim.tracers = Tracers.load(fh["tracers"])
        return sim


def _rule_from_json(text) -> RefinementRule | None:
    """The refinement rule saved by :meth:`Simulation.save_checkpoint` (None in older checkpoints)."""
    if text is None:
        return None
    values = json.loads(text)
    values["boxes"] = tuple((tuple(lo), tuple(hi), int(level)) for lo, hi, level in values.get("boxes", ()))
    return RefinementRule(**values)


#: The amount columns of the checkpoints that stored no names (the first format), in their order.
FIRST_AMOUNT_NAMES = ("mass_added_by_floors", "energy_added_by_floors", "energy_reconciled",
                      "energy_removed_by_void_cleanup", "mass_removed_by_void_cleanup",
                      "momentum_removed_by_void_cleanup", "momentum_removed_by_velocity_limit",
                      "energy_removed_by_velocity_limit")


def _load_named_columns(dataset, names: tuple[str, ...], out: np.ndarray, first: tuple[str, ...] | None = None) -> None:
    """Copy the counter columns of ``dataset`` into ``out`` by name.

    A checkpoint written before a counter existed leaves that counter at 0 (so do the
    momentum magnitudes of the floors, which the signed components replaced).  One without
    column names (the first format) holds the leading columns of ``first`` (by default of the
    current list, for counters only ever appended).
    """
    values = dataset[()]
    stored = (json.loads(dataset.attrs["names"]) if "names" in dataset.attrs
              else list((first or names)[:values.shape[1]]))
    if values.shape[1] != len(stored):
        raise ValueError(f"checkpoint counters {dataset.name}: {values.shape[1]} columns, expected {len(stored)}")
    for column, name in enumerate(stored):
        if name in names:
            out[:, names.index(name)] = values[:, column]
