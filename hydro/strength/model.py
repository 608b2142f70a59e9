"""Operator-split material strength for :class:`impactpipe.hydro.solver.Simulation`.

:class:`MaterialStrength` owns the strength work arrays and counters.  After the hydro
sweeps (which transport the stress with the material, ``arhoq``), the solver integrates the
momentum sources with a kick - update - kick splitting (velocity Verlet; docs/strength.md,
"Time integration"):

1. :meth:`~MaterialStrength.load_stress`: cell velocities v^n, fills and the transported
   mixture stress S^n of the interior cells, then their ghosts;
2. :meth:`~MaterialStrength.kick` over dt / 2 with S^n
   (:func:`impactpipe.hydro.strength.divergence.apply_stress_divergence`, conservative
   fluxes), then gravity over dt / 2 when the scene has it;
3. :meth:`~MaterialStrength.update` over dt with the half-step velocities v^(n+1/2)
   (:func:`impactpipe.hydro.strength.update.cell_velocities`, then
   :func:`impactpipe.hydro.strength.update.update_stress`: Jaumann update, tensile failure,
   yield, damage, stress power);
4. :meth:`~MaterialStrength.kick` over dt / 2 with S^(n+1), then gravity over dt / 2.

The work arrays' ghosts are filled after each of steps 1 to 3, for the slots that step wrote
and a kernel reads in a ghost, one layer deep unless the hourglass viscosity reads two
(:meth:`MaterialStrength._ghost_reads`; reflecting walls mirror them: the normal velocity and
the shear components with one index normal to the wall change sign).  Across MPI ranks a
fill sends all its slots along every axis in one message per neighbouring rank on a uniform
mesh (along each axis in turn on an adaptive one), and on a uniform mesh it only starts
there: the next kernel (the kick's stress divergence, or the stress update) runs on the
blocks with no face towards another rank's block while the strips travel, and on the others
once they have arrived (:meth:`MaterialStrength._around_ghosts`).  The state's ghosts are
not used.  Updating the stress between two half kicks is neutral for elastic waves up to the
CFL limit; updating it before one full kick (the scheme this replaced) amplified them by 2 %
per step at cfl 0.4 (docs/strength.md).

It exists only when some material has a yield model; a strengthless scene allocates none
of its arrays and runs none of its kernels.

Grady-Kipp fracture (a material whose damage model is ``grady_kipp``,
:func:`impactpipe.hydro.strength.parameters.pack_damage`): the state carries NFLAW more
scalars per material, the cells' local Weibull laws per unit mass
(:mod:`impactpipe.hydro.strength.update`), drawn by :meth:`MaterialStrength.prepare_state`
when the state is new (not from a checkpoint): per Grady-Kipp material k, its flaws are
assigned over the cells it fills (:func:`impactpipe.hydro.strength.flaws.assign_flaws`, body
volume V = sum v_i alpha_k, weight v_i alpha_k; for a porous material the matrix volume,
V = sum v_i alpha_k / alpha_dist, weight v_i alpha_k / alpha_dist, since the Weibull k counts
flaws per unit volume of intact rock; n_tot = N ln N or the block's ``flaw_count``,
counted below the law's node strains, :func:`impactpipe.hydro.strength.flaws.flaw_nodes` of the
draw unless the block gives ``flaw_strains``) with the generator
``numpy.random.default_rng([flaw_seed, k])``.  On a 1-D mesh a cell of width dx holds the flaws
of the volume dx A, A the block's ``flaw_cross_section`` (m^2, default 1): the flaws per unit
mass do not depend on A, their sampling does (a cell holds k A dx eps^m flaws below eps, and a
fixed ``flaw_count`` reaches the strain (n_tot / (k A L))^(1/m) over a length L).  A material made of several bodies (two plates
of one material) draws one law over their union, which has the statistics of each part.

Rough walls (:meth:`MaterialStrength.set_rough_wall`): a reflecting domain face can be made
no-slip for the stress.  Its ghosts then mirror the tangential velocity with the sign
flipped (the velocity is zero on the wall, so the velocity gradient sees the shear against
it) and carry the shear stress unchanged (the wall takes the traction S.n of the cell next
to it instead of none).  The traction is bounded by the material's yield strength, so the
wall holds the material by Coulomb friction with the material's own friction coefficient, as
a bed roughened with the same grains does.  The face velocity is zero, so the traction does
no work: the kinetic energy it removes becomes internal energy through the stress power.
The sweeps still see a free-slip wall (they carry the pressure only).

Options a scene may switch on (the granular column collapse does):
:meth:`MaterialStrength.set_surface_layer_pressure` (the yield strength of material in a cell
with void at no less than the pressure at mid-depth of the layer it forms under gravity,
:func:`impactpipe.hydro.strength.update.update_stress` step 4),
:meth:`MaterialStrength.set_hourglass_viscosity` (the traction of
:mod:`impactpipe.hydro.strength.hourglass` against odd-even velocity modes, added in each kick)
and :meth:`MaterialStrength.set_face_shear` (the elastic-plastic face stresses of
:mod:`impactpipe.hydro.strength.face_shear` against the same modes: advanced at the start of the
kick that follows the stress update, their tractions added in each kick).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from impactpipe.hydro.eos import reference_densities
from impactpipe.hydro.eos.porosity import ALPHA0, NPOROSITY
from impactpipe.hydro.amr.regrid import summed_rows
from impactpipe.hydro.amr.transfer import face_flux_shape, prolong_field_ghosts, reflux, restrict_ghosts
from impactpipe.hydro.mesh.blocks import CYLINDRICAL, GHOST, REFLECTING, BlockMesh
from impactpipe.hydro.mesh.boundary import fill_ghosts_where
from impactpipe.hydro.mesh.scalar_stamps import NO_STAMPS
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.parallel.distributed import FieldFill
from impactpipe.hydro.parallel.owned_memory import lazy_zeros
from impactpipe.hydro.strength.divergence import apply_stress_divergence, quiet_blocks, zero_face_flux_columns
from impactpipe.hydro.strength.face_shear import apply_face_shear, update_face_shear
from impactpipe.hydro.strength.hourglass import apply_hourglass_viscosity
from impactpipe.hydro.strength.flaws import (BodyShare, assign_flaws, default_flaw_count, flaw_law_per_mass, flaw_nodes,
                                             running_sum)
from impactpipe.hydro.strength.parameters import (
    DAMAGE0, GRADY_KIPP, NODE0, NONE, WEIBULL_K, WEIBULL_M, DamageArrays, StrengthArrays, pack_damage,
)
from impactpipe.hydro.strength.update import (
    AMOUNT_NAMES, COUNT_NAMES, NCOUNT, NFLAW, NSAMOUNT, NWORK, NWORK_FACE, WK_L, WK_S, WK_V, WK_Y, cell_velocities,
    cell_velocity_and_stress, gradient_slot, scalar_slots, snapshot_stress_fields, stress_slots, update_stress,
)

#: Work slots whose sign flips in a reflecting ghost, per wall-normal axis (velocity and shear stress).
_REFLECT_FLIP = {0: (WK_V, WK_S + 3, WK_S + 4), 1: (WK_V + 1, WK_S + 3, WK_S + 5), 2: (WK_V + 2, WK_S + 4, WK_S + 5)}
#: Work slots whose sign flips in a rough (no-slip) wall's ghost: every velocity component, no stress.
_ROUGH_FLIP = (WK_V, WK_V + 1, WK_V + 2)
#: Work slots of the face shear stress whose sign flips in a wall's ghost, reflecting or rough, per
#: wall-normal axis a: the velocity gradients L_ai along the wall (the face across the wall reads them).
#: (``gradient_slot``'s Python function: calling the kernel here would compile it at every import.)
_GRADIENT_FLIP = {a: tuple(WK_L + gradient_slot.py_func(a, i) for i in range(3) if i != a) for a in range(3)}
#: The surface gravity :func:`update_stress` gets without a surface-layer pressure: none (empty).
_NO_GRAVITY = np.zeros(0)
#: ``unchanged`` of :func:`cell_velocities` where every block's velocities are found again.
_NO_BLOCKS = np.zeros(0, dtype=np.uint8)


def work_ghost_reads(ndim: int, geometry_code: int, wide: bool) -> tuple[int, frozenset]:
    """(layers, slots): how many ghost layers of the work arrays the kernels of the stress step
    read, and the work slots they read in no ghost.  The velocity gradient (:func:`update_stress`)
    and the stress divergence read the cells next to a cell, one layer, and on a 2-D mesh neither
    S_zz (the hoop stress of r-z, read in its own cell only) nor, in r-z (``geometry_code``
    :data:`CYLINDRICAL`), v_theta (the update sets the theta derivatives to zero).  With ``wide``
    a kernel reads two layers and every slot (the hourglass viscosity, the face shear stress); a
    3-D mesh fills two layers of every slot."""
    if wide or ndim != 2:
        return GHOST, frozenset()
    skipped = {WK_S + 2}
    if geometry_code == CYLINDRICAL:
        skipped.add(WK_V + 2)
    return 1, frozenset(skipped)


def slot_runs(slots: slice, skipped: frozenset) -> tuple[slice, ...]:
    """The runs of consecutive work slots of ``slots`` left when the ``skipped`` slots are taken
    out: the components of one ghost fill, all sent in one message per peer rank across MPI
    ranks (packed one run after another)."""
    runs, start = [], slots.start
    for stop in sorted(skipped & set(range(slots.start, slots.stop))) + [slots.stop]:
        if stop > start:
            runs.append(slice(start, stop))
        start = stop + 1
    return tuple(runs)


def _in_runs(slot: int, runs: tuple[slice, ...]) -> bool:
    """Whether the work slot ``slot`` lies in one of the ``runs`` (:func:`slot_runs`)."""
    return any(run.start <= slot < run.stop for run in runs)


class LevelBlocks(NamedTuple):
    """One refinement level's share of a strength step per level (``time_stepping = "per_level"``,
    :mod:`impactpipe.hydro.amr.subcycle`): the kernels run on ``blocks`` (int64, the level's
    blocks) only, and the work arrays' ghosts of those blocks are filled from same-level copies
    (``mask[NB]`` uint8, 1 on the level's blocks), from the finer level by the ``restrict[axis]``
    rows and weights of the axis's restrict plan whose destination is on the level, and from the
    coarser level by the ``prolong[axis]`` rows into the level (copies of the coarse cell);
    ``walls[axis, side]``: the level's blocks with a reflecting face on that side (int64), whose
    ghosts' normal components are negated."""

    blocks: np.ndarray
    mask: np.ndarray
    restrict: dict
    prolong: dict
    walls: dict


class MaterialStrength:
    """Stress update and stress divergence of the materials with a yield model.

    Args:
        arrays: packed strength parameters (:func:`impactpipe.hydro.strength.parameters.pack_strength`).
        mesh: the block mesh.
        nmat: number of materials M.
        damage: packed tensile damage models (:func:`impactpipe.hydro.strength.parameters.pack_damage`);
            instant failure for every material when None.  A Grady-Kipp material needs a yield model.
        porous: whether the scene has porous materials (the state then carries each material's
            distension before its damage, :mod:`impactpipe.hydro.eos.porosity`).
    """

    def __init__(self, arrays: StrengthArrays, mesh: BlockMesh, nmat: int, damage: DamageArrays | None = None,
                 porosity: np.ndarray | None = None):
        self.arrays = arrays
        #: (M, NPOROSITY) porosity rows of a porous scene (:func:`impactpipe.hydro.eos.porosity.pack_porosity`)
        #: or None: a porous material's strength is its matrix's, scaled (:func:`update_stress`).
        self.porosity = porosity
        porous = porosity is not None
        #: the porosity rows :func:`update_stress` gets: ``porosity``, or rows of ones (no porous material)
        self._porosity_rows = porosity if porous else np.ones((nmat, NPOROSITY))
        self.mesh = mesh
        self.nmat = nmat
        self.damage = damage if damage is not None else pack_damage([None] * nmat)
        gradual = self.damage.model == GRADY_KIPP
        if (gradual & (arrays.model == NONE)).any():
            k = int(np.flatnonzero(gradual & (arrays.model == NONE))[0])
            raise ValueError(f"material {k}: damage model grady_kipp needs a strength model with a yield strength")
        #: whether flaws are carried (some material fractures by Grady-Kipp)
        self.fracture = self.damage.fracture
        #: node strains (-) of each Grady-Kipp material's flaw law drawn by :meth:`prepare_state`
        self.flaw_strains: dict[int, list[float]] = {}
        self.ns = stress_slots(mesh.ndim)
        self.nq = scalar_slots(mesh.ndim, self.fracture, porous)
        self.work = np.zeros((mesh.nblocks, NWORK) + mesh.padded_shape)
        #: face shear stress (:meth:`set_face_shear`): the shear modulus G (Pa), None while off
        self.face_modulus: float | None = None
        #: the faces' shear stresses T (Pa, NaN on a face carrying none;
        #: :mod:`impactpipe.hydro.strength.face_shear`) while it is on
        self.face: np.ndarray | None = None
        #: the step dt (s) of the last :meth:`update`, whose face stresses the next :meth:`kick` advances first
        self._face_dt: float | None = None
        #: per block, whether it has a cell holding material at the last :meth:`load_stress` (1) or not (0)
        self.holds = np.zeros(mesh.nblocks, dtype=np.uint8)
        #: per block, whether some cell has mass at the last :meth:`load_stress` (1) or not (0)
        self.has_mass = np.zeros(mesh.nblocks, dtype=np.uint8)
        #: per block, whether an interior cell carries a mixture stress in the work arrays (1) or
        #: not (0), from the last kernel that wrote them: :meth:`kick` skips a block without
        #: one whose ghosts carry none either
        self.stressed = np.zeros(mesh.nblocks, dtype=np.uint8)
        #: per block, whether the next :meth:`kick` skips it on the flags of :attr:`stressed` alone
        #: (1) or not (0), and whether its stress slots' ghosts are filled for it (:meth:`_mark_quiet`)
        self._quiet = np.zeros(mesh.nblocks, dtype=np.uint8)
        self._stress_ghosts = np.zeros(mesh.nblocks, dtype=np.uint8)
        self.counts = np.zeros((mesh.nblocks, NCOUNT), dtype=np.int64)
        self.amounts = np.zeros((mesh.nblocks, NSAMOUNT))
        self.face_flux = self._face_flux_arrays(mesh)
        #: (axis, side) of the reflecting domain faces that are rough (module docstring).
        self.rough_walls: list[tuple[int, int]] = []
        #: The wall flips of :meth:`_wall_flips`, per (axis, side, runs).
        self._flips: dict[tuple, list[int]] = {}
        #: hourglass viscosity: coefficient C (-) and impedance Z (kg/(m^2 s)); none while C = 0
        self.hourglass = (0.0, 0.0)
        #: gravity (m/s^2, (3,)) of the surface-layer pressure of the yield strength; None: none
        self.surface_gravity: np.ndarray | None = None
        self._rho0: tuple[object, np.ndarray] | None = None
        #: The work ghosts' fills :meth:`load_stress` or :meth:`update` started, which the next
        #: :meth:`kick` completes (:meth:`_start_work_ghosts`).
        self._incoming: list[FieldFill] = []

    def set_rough_wall(self, axis: int, side: int) -> None:
        """Make the reflecting domain face on ``side`` (0 low, 1 high) of ``axis`` a rough, no-slip wall."""
        if not 0 <= axis < self.mesh.ndim or side not in (0, 1):
            raise ValueError(f"no domain face on side {side} of axis {axis} in {self.mesh.ndim} dimensions")
        if not (self.mesh.neighbor[:, axis, side] == REFLECTING).any():
            raise ValueError(f"the domain face on side {side} of axis {axis} is not reflecting; only a wall can be rough")
        if (axis, side) not in self.rough_walls:
            self.rough_walls.append((axis, side))
            self._flips.clear()

    def set_hourglass_viscosity(self, coefficient: float, impedance: float) -> None:
        """Resist the odd-even velocity modes with the face traction C dx Z e of
        :mod:`impactpipe.hydro.strength.hourglass` (planar meshes); ``coefficient`` C (-),
        ``impedance`` Z = rho0 c_L (kg/(m^2 s))."""
        if self.mesh.geometry_code == CYLINDRICAL:
            raise ValueError("hourglass viscosity is implemented on planar meshes only")
        if not (coefficient >= 0.0 and impedance >= 0.0):
            raise ValueError(f"hourglass viscosity: coefficient and impedance must be >= 0 (got {coefficient}, "
                             f"{impedance})")
        self.hourglass = (float(coefficient), float(impedance))

    def set_face_shear(self, modulus: float, partition=None) -> None:
        """Give each cell face the elastic-plastic shear stress of
        :mod:`impactpipe.hydro.strength.face_shear` against the odd-even velocity modes (planar
        meshes on one level); ``modulus`` G (Pa), the material's shear modulus.  The work arrays
        get the slots ``WK_Y`` and ``WK_L`` for the cells' shear strength and off-diagonal velocity
        gradients (NWORK_FACE in all).  ``partition``: on several MPI ranks this rank's, whose
        :meth:`~impactpipe.hydro.parallel.distributed.WholeMesh.zeros` hold the arrays (the face
        stresses NaN in its own rows only: each block reads its own faces); None: one process."""
        if self.mesh.geometry_code == CYLINDRICAL or self.mesh.ndim < 2:
            raise ValueError("the face shear stress is implemented on 2-D and 3-D planar meshes only")
        if self.mesh.adaptive:
            raise ValueError("the face shear stress is implemented on a mesh of one level only")
        if not modulus > 0.0:
            raise ValueError(f"face shear stress: the shear modulus must be > 0 (got {modulus})")
        self.face_modulus = float(modulus)
        zeros = np.zeros if partition is None else partition.zeros
        self.work = zeros((self.mesh.nblocks, NWORK_FACE) + self.mesh.padded_shape)
        self.face = zeros((self.mesh.nblocks, self.mesh.ndim ** 2) + self.mesh.padded_shape)
        self.face[slice(None) if partition is None else partition.blocks] = np.nan

    def set_surface_layer_pressure(self, gravity) -> None:
        """Let the yield strength of material in a cell with void see at least the pressure at
        mid-depth of the layer it forms under ``gravity`` (m/s^2, three components)
        (:func:`impactpipe.hydro.strength.update.update_stress`, step 4)."""
        self.surface_gravity = np.array(gravity, dtype=float).reshape(3)

    def _face_flux_arrays(self, mesh: BlockMesh, zeros=np.zeros) -> np.ndarray:
        """Per-axis coarse/fine face amounts of the stress divergence (empty on a uniform mesh),
        from ``zeros(shape)``."""
        return zeros((3,) + face_flux_shape(mesh.nblocks if mesh.adaptive else 0, mesh.padded_shape, mesh.ndim,
                                            self.nmat, self.nmat * self.nq))

    def mesh_changed(self, mesh: BlockMesh, partition=None, summed=summed_rows) -> None:
        """Follow a regrid: new work arrays (the face shear stresses start again from the cells'
        stress, NaN); the per-block counters' totals move to block 0 (``summed(counters,
        nblocks)``: on several ranks the old partition's
        :meth:`~impactpipe.hydro.parallel.distributed.WholeMesh.summed_rows`).  ``partition``:
        the new mesh's on several ranks, whose :meth:`~impactpipe.hydro.parallel.distributed.WholeMesh.zeros`
        hold the work arrays (only its own rows of the face stresses are set: each block reads
        its own faces only), and the coarse/fine face fluxes are in
        :func:`~impactpipe.hydro.parallel.owned_memory.lazy_zeros` (the kick writes its own
        blocks' rows, the exchange before a reflux those it reads), or None (one process)."""
        self.mesh = mesh
        zeros = np.zeros if partition is None else partition.zeros
        self.work = zeros((mesh.nblocks, self.work.shape[1]) + mesh.padded_shape)
        if self.face is not None:
            self.face = zeros((mesh.nblocks, mesh.ndim ** 2) + mesh.padded_shape)
            self.face[slice(None) if partition is None else partition.blocks] = np.nan
        self.holds = np.zeros(mesh.nblocks, dtype=np.uint8)
        self.has_mass = np.zeros(mesh.nblocks, dtype=np.uint8)
        self.stressed = np.zeros(mesh.nblocks, dtype=np.uint8)
        self._quiet = np.zeros(mesh.nblocks, dtype=np.uint8)
        self._stress_ghosts = np.zeros(mesh.nblocks, dtype=np.uint8)
        self.face_flux = self._face_flux_arrays(mesh, np.zeros if partition is None else lazy_zeros)
        self.counts = summed(self.counts, mesh.nblocks)
        self.amounts = summed(self.amounts, mesh.nblocks)

    def prepare_state(self, state: HydroState, partition) -> None:
        """Give ``state`` its per-material stress, plastic strain and damage columns (zero stress,
        initial damage from the parameters), in a porous scene each material's distension column
        (its initial distension alpha_0, 1 for a compact material, :mod:`impactpipe.hydro.eos.porosity`)
        and, with Grady-Kipp fracture, the flaws of each Grady-Kipp material drawn over its cells
        (module docstring), unless it already has them (a checkpoint).  ``partition``
        (:mod:`impactpipe.hydro.parallel.distributed`): the blocks this process sets (its
        ``blocks``; collective over several MPI ranks, whose flaws are those of one process)."""
        want = self.nmat * self.nq
        if state.arhoq.shape[1] == want:
            return
        own = partition.blocks
        state.arhoq = partition.zeros((self.mesh.nblocks, want) + self.mesh.padded_shape)
        for k in range(self.nmat):
            state.arhoq[own, k * self.nq + self.nq - 1] = self.arrays.params[k, DAMAGE0] * state.arho[own, k]
            if self.porosity is not None:
                state.arhoq[own, k * self.nq + self.nq - 2] = self.porosity[k, ALPHA0] * state.arho[own, k]
        for k in np.flatnonzero(self.damage.model == GRADY_KIPP):
            self._draw_flaws(state, int(k), partition)

    def _draw_flaws(self, state: HydroState, k: int, partition) -> None:
        """Flaws of material k over the cells it fills (of ``partition``'s blocks), as
        mass-weighted cumulative flaw laws in ``state.arhoq``; the node strains are the block's
        ``flaw_strains`` or, without them, :func:`impactpipe.hydro.strength.flaws.flaw_nodes` of
        this draw (then recorded in :attr:`flaw_strains` and the damage parameters).  The
        Weibull law counts flaws per unit volume of matrix (m^-3): a porous material's cell i
        holds the matrix volume v_i alpha_k / alpha_dist (m^3), its distension alpha_dist from
        ``state.arhoq``.  The body's volume V is the running sum of its cells' in block order
        (:func:`~impactpipe.hydro.strength.flaws.running_sum`), carried from process to process
        on several MPI ranks (:meth:`~impactpipe.hydro.parallel.distributed.WholeMesh.carry_through`),
        so every process draws the single process's flaws (:class:`~impactpipe.hydro.strength.flaws.BodyShare`)."""
        mesh = self.mesh
        own = partition.blocks
        fill = mesh.interior(state.alpha[own])[:, k]
        mass = mesh.interior(state.arho[own])[:, k]
        volume = mesh.cell_volumes(own) * (self.damage.cross_section[k] if mesh.ndim == 1 else 1.0)
        cells = np.flatnonzero((fill > 0.0) & (mass > 0.0))
        material_volume = volume.ravel()[cells] * fill.ravel()[cells]
        if self.porosity is not None and self.porosity[k, ALPHA0] > 1.0:
            distension = (mesh.interior(state.arhoq[own])[:, k * self.nq + self.nq - 2].ravel()[cells]
                          / mass.ravel()[cells])
            material_volume = material_volume / distension

        def after_these(carried: tuple[float, int]) -> tuple[float, int]:
            running = running_sum(material_volume, carried[0])
            return (float(running[-1]) if running.size else carried[0]), carried[1] + cells.size

        (before, cells_before), (body_volume, n_cells) = partition.carry_through((0.0, 0), after_these)
        if n_cells == 0:
            return
        m, kw = self.damage.params[k, WEIBULL_M], self.damage.params[k, WEIBULL_K]
        n_tot = int(self.damage.flaw_count[k]) or default_flaw_count(n_cells)
        if (self.damage.params[k, NODE0:] > 0.0).all():
            strains = self.damage.params[k, NODE0:] ** (1.0 / m)
        else:
            strains = flaw_nodes(body_volume, n_tot, m, kw)
            self.damage.params[k, NODE0:] = strains ** m
        self.flaw_strains[k] = [float(e) for e in strains]
        if cells.size == 0:
            return
        flaws = assign_flaws(material_volume, body_volume, m, kw, np.random.default_rng([int(self.damage.seed[k]), k]),
                             n_flaws=n_tot, node_strains=strains,
                             share=BodyShare(before, body_volume, cells_before + cells.size == n_cells))
        law = flaw_law_per_mass(flaws, volume.ravel()[cells] * mass.ravel()[cells])
        first = k * self.nq + self.ns + 1
        for j in range(NFLAW):
            amount = np.zeros(fill.size)
            amount[cells] = law[:, j] * mass.ravel()[cells]
            mesh.interior(state.arhoq[own])[:, first + j] = amount.reshape(fill.shape)

    def load_stress(self, state: HydroState, eos, partition, level: LevelBlocks | None = None,
                    record: np.ndarray = _NO_BLOCKS) -> None:
        """Cell velocities, fills and the transported mixture stress S^n (from ``arhoq``) of the
        blocks this process advances (``partition``, :mod:`impactpipe.hydro.parallel`; or one
        refinement ``level``'s blocks, :class:`LevelBlocks`) into the work arrays, then their
        ghosts: what the first half kick (:meth:`kick`) uses.  The ghost fills are only started
        here (:meth:`_start_work_ghosts`); the kick completes them.  ``record``: the last sweep's
        record of the blocks still void (:func:`cell_velocity_and_stress`), or empty."""
        cell_velocity_and_stress(state.alpha, state.arho, state.arhoq, state.momentum, self._fill_densities(eos),
                                 self.arrays.model, self.ns, self.work, self._blocks(partition, level), self.holds,
                                 self.has_mass, self.stressed, record)
        self._mark_quiet(partition, level)
        self._incoming = self._start_work_ghosts(partition, slice(WK_V, WK_S + self.ns), level)

    def load_work(self, state: HydroState, eos, blocks: np.ndarray) -> None:
        """Velocities, fills and mixture stresses of the interior cells of ``blocks`` (int64) into
        the work arrays, without ghosts: the cells of the levels beside a level that steps alone
        (:mod:`impactpipe.hydro.amr.subcycle`), which its ghosts are filled from."""
        if blocks.size:
            cell_velocity_and_stress(state.alpha, state.arho, state.arhoq, state.momentum, self._fill_densities(eos),
                                     self.arrays.model, self.ns, self.work, blocks, self.holds, self.has_mass,
                                     self.stressed, _NO_BLOCKS)

    def update(self, state: HydroState, dt: float, eos, partition, level: LevelBlocks | None = None,
               kicked_only: bool = False, record: np.ndarray = _NO_BLOCKS, stamp: np.ndarray = NO_STAMPS[0]) -> None:
        """Advance the stress of the ``partition``'s blocks (or of the ``level``'s) over ``dt`` (s)
        with the current velocities (the half-step ones after the first kick, into the work
        arrays with their ghosts first): Jaumann update, failure, yield, damage and stress
        power; the new mixture stress S^(n+1) goes to the work arrays, ghosts included (their
        fill only started, :meth:`_start_work_ghosts`: the second kick completes it).  While the
        velocities' strips travel, the update runs on the blocks that need none of them
        (:meth:`_around_ghosts`).  ``kicked_only``: nothing but the first :meth:`kick` changed
        the momentum since :meth:`load_stress` (no gravity between them), so the blocks that kick
        passed over (:meth:`_mark_quiet`) keep the velocities load_stress found.  ``record``: the
        last sweep's record of the blocks whose scalars are +0.0 (:func:`update_stress`), or empty;
        ``stamp``: the blocks' scalar stamps (:mod:`impactpipe.hydro.mesh.scalar_stamps`), or empty."""
        unchanged = self._quiet if kicked_only else _NO_BLOCKS
        cell_velocities(state.arho, state.momentum, self.work, self._blocks(partition, level), unchanged)
        fills = self._start_work_ghosts(partition, slice(WK_V, WK_V + 3), level)
        self._around_ghosts(partition, fills, lambda blocks: self.stress_step(state, dt, eos, blocks, record, stamp),
                            level)
        self._mark_quiet(partition, level)
        self._incoming = self._start_work_ghosts(partition, slice(WK_S, WK_S + self.ns), level)
        if self.face is not None:
            self._incoming += self._start_work_ghosts(partition, slice(WK_Y, NWORK_FACE), level)
            self._face_dt = dt

    def stress_step(self, state: HydroState, dt: float, eos, blocks: np.ndarray,
                    record: np.ndarray = _NO_BLOCKS, stamp: np.ndarray = NO_STAMPS[0]) -> None:
        """The stress update of :meth:`update` over ``dt`` (s) on the ``blocks`` listed (int64)
        alone (:func:`update_stress`), from the velocities and fills in the work arrays (their
        ghosts filled) and the blocks with mass in :attr:`has_mass`: no velocities computed, no
        ghosts filled."""
        a = self.arrays
        mesh = self.mesh
        update_stress(dt, mesh.geometry_code, mesh.ndim, state.alpha, state.arho, state.arhoe, state.arhoq,
                      mesh.block_lo, mesh.block_dx, eos.kind, eos.params, eos.table, self._reference_densities(eos),
                      a.model, a.params, a.shear, a.tensile_strength, self.work, self.counts, self.amounts, blocks,
                      self.damage.model, self.damage.params,
                      _NO_GRAVITY if self.surface_gravity is None else self.surface_gravity, self._porosity_rows,
                      self.has_mass, self.stressed, self.face is not None, record, stamp)

    def kick(self, state: HydroState, dt: float, boundary: np.ndarray, floors: np.ndarray,
             amounts: np.ndarray, partition, level: LevelBlocks | None = None) -> None:
        """Add the divergence of the work arrays' stress over ``dt`` (s) to the momentum and
        energy of the ``partition``'s blocks.

        Domain-face fluxes go to ``boundary``.  On an adaptive mesh the coarse cells beside
        finer blocks are refluxed with the fine blocks' stress fluxes (momentum and energy only;
        ``floors``, ``amounts``: the hydro counters the reflux kernel reports to, untouched here
        since no mass moves).  With a ``level`` (:class:`LevelBlocks`) only its blocks are
        kicked and nothing is refluxed: the amounts through the level's coarse/fine faces stay in
        :attr:`face_flux` for the flux registers of :mod:`impactpipe.hydro.amr.subcycle`: the
        momentum and energy columns of the used axes, the only ones the kernel writes, are zeroed
        on the level's blocks' faces to other levels first (:func:`zero_face_flux_columns`; the
        other columns and the unused axes stay zero from the allocation).  The hourglass
        viscosity and the face shear stress are not split by levels.
        With the face shear stress the kick that follows :meth:`update` first advances the
        faces' stresses over that update's dt (with the work arrays' ghosts complete), and
        every kick adds their tractions (:mod:`impactpipe.hydro.strength.face_shear`).

        The work ghosts' fills that :meth:`load_stress` or :meth:`update` started are completed
        here: the stress divergence runs on the blocks that need no other rank's strips while
        they travel, then on the rest (:meth:`_around_ghosts`).
        """
        mesh = self.mesh
        lo, hi = self._range(partition)
        fills, self._incoming = self._incoming, []
        if level is not None:
            self._finish_work_ghosts(partition, fills)
            if self.hourglass[0] > 0.0 or self.face is not None:
                raise ValueError("the hourglass viscosity and the face shear stress do not step per refinement level")
            if mesh.adaptive:
                col0 = 3 * self.nmat
                zero_face_flux_columns(self.face_flux, mesh.neighbor_level, mesh.ndim, level.blocks, col0, 4)
            apply_stress_divergence(dt, mesh.geometry_code, mesh.ndim, state.momentum, state.energy, mesh.block_lo,
                                    mesh.block_dx, mesh.neighbor, mesh.neighbor_level, self.work, boundary,
                                    self.face_flux, 3 * self.nmat, level.blocks, self.stressed)
            return
        self.face_flux[:, lo:hi] = 0.0  # the other rows are received whole before a reflux reads them

        def kick_blocks(blocks):
            """The stress divergence of ``blocks`` (int64)."""
            apply_stress_divergence(dt, mesh.geometry_code, mesh.ndim, state.momentum, state.energy, mesh.block_lo,
                                    mesh.block_dx, mesh.neighbor, mesh.neighbor_level, self.work, boundary,
                                    self.face_flux, 3 * self.nmat, blocks, self.stressed, self._quiet)

        self._around_ghosts(partition, fills, kick_blocks)
        if self.hourglass[0] > 0.0:
            apply_hourglass_viscosity(dt, mesh.ndim, self.hourglass[0], self.hourglass[1], state.momentum,
                                      state.energy, mesh.block_dx, mesh.neighbor, mesh.neighbor_level, self.work,
                                      boundary, lo, hi)
        if self.face is not None:
            if self._face_dt is not None:
                update_face_shear(self._face_dt, mesh.ndim, self.face_modulus, mesh.block_dx, mesh.neighbor,
                                  mesh.neighbor_level, self.work, self.face, lo, hi)
                self._face_dt = None
            apply_face_shear(dt, mesh.ndim, state.momentum, state.energy, mesh.block_dx, mesh.neighbor,
                             mesh.neighbor_level, self.work, self.face, boundary, lo, hi)
        if mesh.adaptive:
            for axis in range(mesh.ndim):
                plans = partition.plans(mesh, axis)
                partition.share_face_flux(self.face_flux[axis], axis)
                reflux(axis, plans["reflux"], plans["reflux_volume"], self.face_flux[axis], state.alpha, state.arho,
                       state.arhoe, state.arhoq, state.momentum, state.energy, floors, amounts)

    def _range(self, partition) -> tuple[int, int]:
        """(first, one past the last) block of the contiguous range the ``partition`` advances."""
        lo, hi, step = partition.blocks.indices(self.mesh.nblocks)
        if step != 1:
            raise ValueError("the strength kernels take a contiguous range of blocks")
        return lo, hi

    def _blocks(self, partition, level: LevelBlocks | None = None) -> np.ndarray:
        """The blocks (int64) the kernels visit: the ``level``'s, or the ``partition``'s range (:meth:`_range`)."""
        if level is not None:
            return level.blocks
        return np.arange(*self._range(partition), dtype=np.int64)

    def _reference_densities(self, eos) -> np.ndarray:
        """The materials' reference densities (kg/m^3) of the packed EOS ``eos``, computed once per EOS."""
        if self._rho0 is None or self._rho0[0] is not eos:
            self._rho0 = (eos, reference_densities(eos))
        return self._rho0[1]

    def _fill_densities(self, eos) -> np.ndarray:
        """The densities (kg/m^3) that fill a cell (:func:`cell_velocity_and_stress`): the reference
        densities, a porous material's the bulk rho_s0 / alpha_0 of its unstrained state (its pores
        fill the cell; they are not void)."""
        rho0 = self._reference_densities(eos)
        if self.porosity is None:
            return rho0
        return rho0 / self.porosity[:, ALPHA0]

    def _mark_quiet(self, partition, level: LevelBlocks | None = None) -> None:
        """Mark the blocks the next :meth:`kick` skips on the flags of :attr:`stressed` alone, just
        written by the kernel whose stress it applies (:func:`impactpipe.hydro.strength.divergence.
        quiet_blocks`), among the ``partition``'s blocks (a neighbour of another rank counts as
        stressed), and those whose stress slots' ghosts are filled for it: of the blocks holding
        material (:attr:`holds`), the others (on one process, :meth:`_start_work_ghosts`).  Only
        a uniform mesh's kick uses them, without the hourglass viscosity and the face shear
        stress (which read the stress ghosts of every block holding material); elsewhere no
        block is quiet."""
        mesh = self.mesh
        if level is None and not mesh.adaptive and self.hourglass[0] == 0.0 and self.face is None:
            lo, hi = self._range(partition)
            quiet_blocks(self.stressed, self.holds, mesh.neighbor, mesh.neighbor_level, mesh.ndim, lo, hi,
                         self._quiet, self._stress_ghosts)
        else:
            self._quiet[:] = 0
            self._stress_ghosts[:] = self.holds

    def _ghost_reads(self) -> tuple[int, frozenset]:
        """(layers, slots) of :func:`work_ghost_reads` for this mesh, the hourglass viscosity and the
        face shear stress."""
        return work_ghost_reads(self.mesh.ndim, self.mesh.geometry_code,
                                self.hourglass[0] > 0.0 or self.face is not None)

    def _start_work_ghosts(self, partition, slots: slice, level: LevelBlocks | None = None) -> list[FieldFill]:
        """Start the ghost fills of the work arrays' ``slots`` along every axis, for the slots'
        runs that some kernel reads in a ghost (:meth:`_ghost_reads`, :func:`slot_runs`), then
        the wall sign flips.  A copied velocity or fill equals the one computed from copied
        conserved ghosts, so the work arrays never need the state's ghosts.

        On a uniform mesh the axes are one fill (``partition.start_field_ghosts``): copies of
        the neighbours' cells, and across MPI ranks the strips of every axis and run in one
        message per peer rank.  The strips are interior cells and each axis's copies and
        flips write only its own ghost slabs (corners excepted, which no kernel reads: every
        stencil steps along one axis), so no axis waits for another's.  Only the blocks
        holding material get ghosts (:attr:`holds`), and of those only the layers the kernels
        read: the stress step reads none of a void block's (every kernel skips its void cells),
        and half of an impact's blocks are void.  The ghosts left stale may be flipped at a
        wall; nothing reads them.  The fill is returned while strips from other ranks may still
        travel, for :meth:`_finish_work_ghosts` (after :meth:`_around_ghosts` ran the kernels
        that need none of them).  On one process the stress slots are filled in a fill of their
        own, for the blocks of :meth:`_mark_quiet` alone: the kick reads no stress ghost of a
        quiet block (most of an impact's target right after contact); across MPI ranks they
        go with the others, one message per peer, and every block holding material gets them.
        An adaptive mesh fills every layer of every block, the coarse/fine faces by restriction
        and copies of the coarse cells, which read interior cells only: its axes are one fill
        too, and across MPI ranks the strips, the restriction's fine cells and the copied
        coarse cells of every axis travel in one message per peer.  With a ``level`` (steps per
        level) an adaptive mesh's level's blocks are filled axis after axis, completely
        (:meth:`_fill_work_ghosts_of_level`), and no fill is returned."""
        layers, skipped = self._ghost_reads()
        runs = slot_runs(slots, skipped)
        if self.mesh.adaptive and level is not None:
            for axis in range(self.mesh.ndim):
                self._fill_work_ghosts_of_level(axis, runs, level)
            return []
        if self.mesh.adaptive:
            fills = [partition.start_field_ghosts(self.work, self.mesh, runs, self.holds, GHOST)]
            layers = GHOST
        elif partition.whole:
            flow = slot_runs(slice(slots.start, max(slots.start, min(slots.stop, WK_S))), skipped)
            stress = slot_runs(slice(min(slots.stop, max(slots.start, WK_S)), slots.stop), skipped)
            fills = [partition.start_field_ghosts(self.work, self.mesh, part, wanted, layers)
                     for part, wanted in ((flow, self.holds), (stress, self._stress_ghosts)) if part]
        else:
            fills = [partition.start_field_ghosts(self.work, self.mesh, runs, self.holds, layers)]
        for axis in range(self.mesh.ndim):
            self._flip_work_walls(axis, runs, layers, owned=self._range(partition))
        return fills

    def _finish_work_ghosts(self, partition, fills: list[FieldFill]) -> None:
        """Complete the ghost ``fills`` of :meth:`_start_work_ghosts`: the slabs facing other
        MPI ranks' blocks from their strips (``partition.finish_field_ghosts``)."""
        for fill in fills:
            partition.finish_field_ghosts(fill, self.work, self.mesh)

    def _around_ghosts(self, partition, fills: list[FieldFill], kernel, level: LevelBlocks | None = None) -> None:
        """Run ``kernel(blocks)`` (a stress-step kernel on the int64 ``blocks``) on every block the
        ``partition`` advances (or on the ``level``'s), the ghost ``fills`` completed first where
        the kernel reads them: the
        blocks whose ghosts need no other MPI rank's cells (``partition.field_groups``)
        run while the strips travel, the others after :meth:`_finish_work_ghosts`.  Every
        block runs the same arithmetic either way, and each writes only its own cells and
        counters, so the answer does not depend on the split."""
        early, late = partition.field_groups(self.mesh)
        if level is not None or early.size == 0:
            self._finish_work_ghosts(partition, fills)
            kernel(self._blocks(partition, level))
            return
        kernel(early)
        self._finish_work_ghosts(partition, fills)
        kernel(late)

    def _fill_work_ghosts_of_level(self, axis: int, runs: tuple[slice, ...], level: LevelBlocks) -> None:
        """Ghosts along ``axis`` of the work arrays' ``runs`` of slots of the ``level``'s blocks
        (:class:`LevelBlocks`, steps per level on one process): the same-level copies of the
        layers the kernels read into the blocks holding material, as on a uniform mesh, then
        every layer at the level's coarse/fine faces (restriction from the finer level, copies of
        the coarser level's interior cells: :func:`_fill_level_work_ghosts`, which read no
        ghost), and the wall sign flips of the level's blocks.  The slots from the first run's
        start to the last run's stop are filled in one pass: the skipped slots between the runs
        get ghosts too, which no kernel reads (:func:`work_ghost_reads`), so that one call per
        kernel serves every run."""
        if not runs:
            return
        layers = self._ghost_reads()[0]
        _fill_level_work_ghosts(self.work[:, runs[0].start:runs[-1].stop], self.mesh, axis, level,
                                level.mask & self.holds, layers)
        self._flip_work_walls(axis, runs, layers, level)

    def _flip_work_walls(self, axis: int, runs: tuple[slice, ...], layers: int, level: LevelBlocks | None = None,
                         owned: tuple[int, int] | None = None) -> None:
        """Negate, in the ``layers`` ghost layers of the reflecting faces along ``axis`` (of the
        ``level``'s blocks when given, else of the blocks ``owned[0] .. owned[1] - 1`` when given,
        else of every block), the work slots of the ``runs`` whose sign flips there:
        the normal velocity and the shear stress with one index normal to the wall (at a rough
        wall, :meth:`set_rough_wall`, every velocity component and no stress), and the velocity
        gradients along the wall (:meth:`_wall_flips`)."""
        for side in (0, 1):
            self._flip_wall_ghosts(self.work, axis, side, self._wall_flips(axis, side, runs), layers,
                                   None if level is None else level.walls[axis, side], owned)

    def _wall_flips(self, axis: int, side: int, runs: tuple[slice, ...]) -> list[int]:
        """The work slots of the ``runs`` whose sign flips at a reflecting face on ``side`` of
        ``axis`` (:meth:`_flip_work_walls`), remembered per face and runs."""
        key = (axis, side, tuple((run.start, run.stop) for run in runs))
        flips = self._flips.get(key)
        if flips is None:
            every = _ROUGH_FLIP if (axis, side) in self.rough_walls else _REFLECT_FLIP[axis]
            flips = self._flips[key] = [c for c in every + _GRADIENT_FLIP[axis] if _in_runs(c, runs)]
        return flips

    def _flip_wall_ghosts(self, array: np.ndarray, axis: int, side: int, components, layers: int,
                          blocks: np.ndarray | None = None, owned: tuple[int, int] | None = None) -> None:
        """Negate ``components`` of ``array`` in the ``layers`` ghost layers next to the interior
        of the reflecting faces on ``side`` of ``axis``: of the ``blocks`` (int64) when given, which
        must all have a reflecting face there, else of every block that has one among the blocks
        ``owned[0] .. owned[1] - 1`` (every block when None: on several MPI ranks of a uniform mesh
        a rank flips only its own blocks' ghosts, which alone it reads, so that it writes no other
        rank's block, :mod:`impactpipe.hydro.parallel.owned_memory`)."""
        mesh = self.mesh
        if blocks is None:
            lo, hi = (0, mesh.nblocks) if owned is None else owned
            blocks = lo + np.nonzero(mesh.neighbor[lo:hi, axis, side] == REFLECTING)[0]
        if blocks.size == 0 or not components:
            return
        n = mesh.interior_shape[axis]
        index = [blocks, 0, slice(None), slice(None), slice(None)]
        index[2 + axis] = slice(GHOST - layers, GHOST) if side == 0 else slice(GHOST + n, GHOST + n + layers)
        for comp in components:
            index[1] = comp
            array[tuple(index)] *= -1.0

    # ------------------------------------------------------------------ diagnostics

    @property
    def count_totals(self) -> dict[str, int]:
        """Strength events since the start (cell-material-steps): yield returns, tensile failures..."""
        return {name: int(v) for name, v in zip(COUNT_NAMES, self.counts.sum(axis=0))}

    @property
    def amount_totals(self) -> dict[str, float]:
        """Stress work put into internal energy, sum of dt alpha_k S_k : D V (J)."""
        return {name: float(v) for name, v in zip(AMOUNT_NAMES, self.amounts.sum(axis=0))}

    def cell_fields(self, state: HydroState, blocks: slice = slice(None)) -> dict[str, np.ndarray]:
        """Interior block-shaped fields for snapshots (see :data:`impactpipe.hydro.output.io.EXTRA_UNITS`),
        computed for the ``blocks`` (zeros in the other rows).

        ``deviatoric_stress_<ij>``: mixture sum_k alpha_k S_k,ij (Pa); ``von_mises_stress``:
        sqrt(3/2 S:S) of the mixture (Pa); ``plastic_strain``, ``damage``: mass-weighted
        means over the materials with strength (-).
        """
        lo, hi, _ = blocks.indices(self.mesh.nblocks)
        out = np.zeros((self.ns + 3, self.mesh.nblocks) + self.mesh.interior_shape)
        snapshot_stress_fields(state.alpha, state.arho, state.arhoq, self.arrays.model, self.ns, self.nq, lo, hi, out)
        names = [f"deviatoric_stress_{n}" for n in ("xx", "yy", "zz", "xy", "xz", "yz")[: self.ns]]
        return dict(zip(names + ["von_mises_stress", "plastic_strain", "damage"], out))


def _fill_level_work_ghosts(field: np.ndarray, mesh: BlockMesh, axis: int, level: LevelBlocks, wanted: np.ndarray,
                            layers: int) -> None:
    """Ghosts along ``axis`` of the ``level``'s blocks of ``field`` (a view of some work slots,
    (NB, C, ...)): copies of the same level's neighbours and domain faces (no sign flips) into
    the ``layers`` layers next to the interior of the blocks where ``wanted[NB]`` (uint8) is not 0,
    then every layer at the coarse/fine faces: the volume-weighted means of the finer level's
    cells, copies of the coarser level's cells (:func:`impactpipe.hydro.mesh.boundary.fill_field_ghosts`
    restricted to one level)."""
    if axis >= mesh.ndim:
        return
    fill_ghosts_where(field, mesh.neighbor, mesh.neighbor_level, axis, GHOST, 0, mesh.nblocks, wanted, layers)
    restrict_ghosts(field, *level.restrict[axis])
    prolong_field_ghosts(field, level.prolong[axis])
