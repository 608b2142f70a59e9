"""Collapse of a granular column under gravity onto a rough floor (2d-planar).

A column of ``material``, ``width`` L0 (m) wide and ``height`` H0 (m) tall, stands on the
floor z = 0 against the wall x = 0 and is released at t = 0 in uniform gravity
g = (0, -``gravity``, 0) m/s^2 (mesh axis 1 is the vertical z).  It collapses, spreads
along +x and stops; the deposit's run-out L_f and height H_f are compared with the
laboratory scaling laws of quasi-two-dimensional collapses (:func:`scaling_runout`,
:func:`scaling_height`), which depend on the aspect ratio a = H0 / L0 only.

Boundaries: x = 0 reflecting (the back wall, free slip: a mirror plane), z = 0 reflecting
and rough (:meth:`impactpipe.hydro.strength.model.MaterialStrength.set_rough_wall`: the
floor holds the material by its own friction, as a bed glued with the same grains does),
outflow at x_max and z_max.  Mesh (:func:`domain`): square cells dx = H0 /
``cells_per_height`` at the finest level; x spans L0 plus twice the run-out the scaling law
predicts (``room`` = 2), z spans H0 plus one cell, each rounded up to whole root blocks.  With ``levels`` > 1
the mesh is adaptive: root cells are 2^(levels - 1) dx, the blocks the refinement rule flags
at t = 0 (the column's free surfaces) start at the finest level, and ``refinement`` decides
where the mesh refines and coarsens as the column collapses
(:func:`~impactpipe.hydro.amr.regrid.refine_initial`).

Initial state: the material at its reference density rho0, at rest, with the hydrostatic
pressure p = rho0 g (H0 - z_m) (z_m the centroid height of the material in the cell) put in
as internal energy at rho0, so the column starts in vertical equilibrium with no
deviatoric stress; void elsewhere.

The material should carry a pressure-dependent yield strength with no tensile strength (a
Drucker-Prager / Coulomb granular material): the GEO model with Y_T = 0, mu_i = tan(phi),
a large Y_M and no cohesion, sqrt(J2) <= mu_i P.  The scene gives the strength scheme the
gravity for the surface-layer pressure (the yield strength of a partly filled surface cell is
taken at the pressure at mid-depth of the layer it holds, not at the zero pressure the
free-surface closure leaves there) and ``hourglass`` viscosity against the odd-even velocity
modes (:mod:`impactpipe.hydro.strength.hourglass`); without them a cohesionless column does
not come to rest (docs/validation.md, "Granular column collapse").  Its sweeps' pressure
predictor takes the bulk modulus (``Simulation.bulk_pressure_predictor``): with K + 4G/3 it
left a viscosity G dt / 3 on the flow, and the run-out depended on the time step; and its
tensile limit acts on the state at the end of each step, not between the sweeps
(``Simulation.step_tensile_limit``, :mod:`impactpipe.hydro.scheme.step_tension`): between the
sweeps it held the flowing column at zero pressure in more cells the larger the step.  With ``settling``
(off by default) void under resting material settles out at the end of each step
(``Simulation.void_settling``, :mod:`impactpipe.hydro.scheme.settling`).  With ``face_shear`` (off by
default) each cell face carries an elastic-plastic shear stress against the odd-even modes
(:mod:`impactpipe.hydro.strength.face_shear`), for use with ``hourglass`` 0.  The mesh spans L0 plus
``room`` run-outs of the law; when the deposit reaches the mesh's far edge
:class:`ColumnCollapseSimulation` grows the mesh along x (up to :data:`GROWTH_LIMIT` times its
first length, on a mesh of one level) or else stops the run with an error.  A strengthless
material collapses as a fluid (dam break) on a free-slip floor.
"""

from __future__ import annotations

import logging

import numpy as np

from impactpipe.hydro.amr.regrid import refine_initial, rule_from_config
from impactpipe.hydro.eos import energy_from_pressure, pressure_sound_speed, reference_density
from impactpipe.hydro.gravity import ExternalGravity
from impactpipe.hydro.mesh.blocks import BlockMesh, morton_keys
from impactpipe.hydro.parallel.distributed import shared_simulation
from impactpipe.hydro.problems.common import (ADAPTIVE_DEFAULTS, adaptive_mesh, check_geometry, material_list, merged,
                                              root_cell_multiple, strength_specs, tensile_strengths)
from impactpipe.hydro.problems.parameters import Parameter, setup_defaults, violations
from impactpipe.hydro.solver import HydroFailure, Simulation
from impactpipe.hydro.mesh.state import HydroState

logger = logging.getLogger(__name__)

#: Geometries this problem runs in.
GEOMETRIES = ('2d-planar',)

#: Cells per block edge unless the hydro options give one (the column is small; 8 wastes less void).
BLOCK_CELLS = 8

#: Mesh axis of the vertical (gravity points along -z).
VERTICAL_AXIS = 1

#: Fewest cells across the initial height the setup accepts.
MIN_CELLS_PER_HEIGHT = 4

#: Largest Courant number the setup accepts, the largest at which the deposit was measured to
#: agree with the smaller steps' (docs/validation.md, "Granular column collapse": cfl 0.4, 0.2 and
#: 0.1 at a = 1 and 6, 16 cells per H0).
MAX_CFL = 0.4

#: Checkpoints do not carry the rough floor (Simulation.save_checkpoint),
#: so the hydro stage restarts an interrupted run of this problem from t = 0.
RESUMABLE = False

#: Hourglass viscosity coefficient C of the scene (:mod:`impactpipe.hydro.strength.hourglass`).
HOURGLASS_COEFFICIENT = 0.1

#: Material filling this fraction of a cell in the last cell column before x_max grows the mesh,
#: or stops the run where it cannot grow (:class:`ColumnCollapseSimulation`).
EDGE_FILL = 1.0e-3

#: The mesh grows to at most this many times its first length along x (:meth:`ColumnCollapseSimulation.grow`).
GROWTH_LIMIT = 4.0

#: The deposit ends where its thickness falls below this fraction of a cell (:func:`deposit`).
FRONT_THICKNESS_CELLS = 0.5

#: Thresholds of :func:`front_at_thickness` fixed in physical units, as fractions of H0 (the
#: benchmark's columns; docs/validation.md, "The front against a threshold fixed in H0").
FRONT_THICKNESS_H0 = (0.01, 0.02, 0.05, 0.1)

#: Shares of the deposit's volume for :func:`front_by_volume` (the benchmark's columns).
FRONT_VOLUME_SHARES = (0.9, 0.95, 0.99)

PARAMETERS = {
    "material": Parameter(kind=str, description="material name", example="sand"),
    "height": Parameter(1000.0, gt=0, units="m", description="initial column height H0"),
    "width": Parameter(1000.0, gt=0, units="m", description="initial column width L0 from the wall x = 0"),
    "gravity": Parameter(9.81, gt=0, units="m/s^2", description="downward acceleration g"),
    "cells_per_height": Parameter(16, kind=int, ge=MIN_CELLS_PER_HEIGHT,
                                  description="cells across the initial height"),
    "end_time": Parameter(120.0, gt=0, units="s", description="end of the run"),
    "hourglass": Parameter(HOURGLASS_COEFFICIENT, ge=0, description="hourglass viscosity coefficient C "
                           "(impactpipe.hydro.strength.hourglass); 0 for none"),
    "settling": Parameter(False, kind=bool, description="void under resting material settles out at the end of "
                          "each step (Simulation.void_settling; docs/validation.md, 'Void settling')"),
    "face_shear": Parameter(False, kind=bool, description="an elastic-plastic shear stress on each cell face "
                            "against the odd-even velocity modes (impactpipe.hydro.strength.face_shear)"),
    "room": Parameter(2.0, gt=0, description="mesh length beyond the column, in run-outs L_f - L0 of the scaling law"),
}

#: What :func:`setup` takes for parameters a call leaves out.
DEFAULTS = {**setup_defaults(PARAMETERS), **ADAPTIVE_DEFAULTS}


def scaling_runout(aspect_ratio: float) -> float:
    """Normalised run-out (L_f - L0) / L0 of a quasi-2d collapse (Lube et al. 2005), for a = H0 / L0.

    1.2 a for a <= 2.3 (the column's flank slides off), 1.9 a^(2/3) above (the column falls
    and spreads), as quoted by Kumar (2015, PhD thesis, Cambridge, ch. 2).
    """
    a = float(aspect_ratio)
    return 1.2 * a if a <= 2.3 else 1.9 * a ** (2.0 / 3.0)


def scaling_height(aspect_ratio: float) -> float:
    """Normalised final height H_f / L0 of a quasi-2d collapse (Lajeunesse et al. 2005), for a = H0 / L0.

    a for a <= 0.7 (the top of the column is not reached by the failure), a^(1/3) above, as
    quoted by Kumar (2015, PhD thesis, Cambridge, ch. 2).
    """
    a = float(aspect_ratio)
    return a if a <= 0.7 else a ** (1.0 / 3.0)


def domain(height: float, width: float, cells_per_height: int, block_cells: int | None = None,
           levels: int = 1, room: float = 2.0) -> dict:
    """The mesh box (see the module docstring); lengths in m.

    Returns ``cell_size`` (the finest), ``lo``, ``hi``, ``cells`` (per axis at the finest level,
    multiples of ``block_cells`` 2^(levels - 1)), ``boundaries`` and ``block_cells``.
    """
    bc = int(block_cells or BLOCK_CELLS)
    multiple = root_cell_multiple(bc, levels)
    dx = height / cells_per_height
    beyond = room * scaling_runout(height / width) * width

    def whole_blocks(length: float) -> int:
        return int(np.ceil(length / dx / multiple - 1e-9)) * multiple

    nx = whole_blocks(width + beyond)
    nz = whole_blocks(height + dx)
    return {"cell_size": dx, "lo": [0.0, 0.0], "hi": [nx * dx, nz * dx], "cells": [nx, nz],
            "boundaries": [("reflecting", "outflow"), ("reflecting", "outflow")], "block_cells": bc}


class ColumnCollapseSimulation(Simulation):
    """The scene's :class:`~impactpipe.hydro.solver.Simulation`: when material fills the last
    cell column before the outflow face x_max to :data:`EDGE_FILL` or more after a step, the
    mesh grows along x (:meth:`grow`) instead of losing the deposit's front through that face.
    Where it cannot grow (an adaptive mesh, several MPI ranks, or the mesh already
    :data:`GROWTH_LIMIT` times its first length) the run stops with a
    :class:`~impactpipe.hydro.solver.HydroFailure` whose message names the scene key ``room``
    that widens the mesh from the start."""

    #: Times the mesh grew (:meth:`grow`).
    growths = 0
    #: The mesh's length along x (m) before it first grew.
    first_length: float | None = None

    def step(self, dt_max: float = np.inf) -> float:
        dt = super().step(dt_max)
        mesh = self.mesh
        own = np.arange(mesh.nblocks)[self.partition.blocks]
        edge = own[mesh.neighbor[own, 0, 1] < 0]
        fill = mesh.interior(self.state.alpha)[edge, :, -1].sum(axis=1)
        if self.partition.any(bool(fill.size and fill.max() >= EDGE_FILL)):
            x_max = float(mesh.domain_hi[0])
            if not self.grow():
                raise HydroFailure(f"column_collapse: the deposit reached the far edge of the mesh, x = {x_max:g} m, "
                                   f"and would leave it; widen the mesh with scene.room (mesh length beyond the "
                                   f"column in run-outs of the scaling law)", self.time,
                                   int(edge[0]) if edge.size else -1, None, {})
            if self.partition.is_root:
                logger.info("column_collapse: the deposit reached x = %g m at t = %g s; the mesh grows to x = %g m",
                            x_max, self.time, float(self.mesh.domain_hi[0]))
        return dt

    def grow(self) -> bool:
        """Add root blocks of void along x beyond x_max: a quarter of the mesh's length, at least
        one column of blocks; False (nothing changed) on an adaptive mesh or where the mesh would
        pass :data:`GROWTH_LIMIT` times its first length.  Collective on several MPI ranks.

        The old blocks keep their state, ghosts included (``plan["keep"]``); the new ones are
        void.  The per-block counters' totals go to block 0 and every per-block array is built
        again for the new mesh, as after a regrid
        (:meth:`~impactpipe.hydro.solver.Simulation.move_to_mesh`), so the totals and the outflow
        budget carry on."""
        mesh = self.mesh
        if mesh.adaptive:
            return False
        if self.first_length is None:
            self.first_length = float(mesh.domain_hi[0] - mesh.domain_lo[0])
        nbx = int(mesh.blocks_per_axis[0])
        added = max(1, nbx // 4)
        root_dx = (mesh.domain_hi[0] - mesh.domain_lo[0]) / nbx
        hi = mesh.domain_hi.copy()
        hi[0] = mesh.domain_lo[0] + (nbx + added) * root_dx
        if hi[0] - mesh.domain_lo[0] > GROWTH_LIMIT * self.first_length * (1.0 + 1e-12):
            return False
        blocks = mesh.blocks_per_axis.copy()
        blocks[0] = nbx + added
        grid = np.stack(np.meshgrid(np.arange(nbx, nbx + added), np.arange(blocks[1]), np.arange(blocks[2]),
                                    indexing="ij"), axis=-1).reshape(-1, 3)
        index = np.concatenate([mesh.block_index, grid])
        level = np.zeros(len(index), dtype=np.int64)
        order = np.argsort(morton_keys(level, index, 0), kind="stable")
        new_mesh = BlockMesh.from_leaves(mesh.geometry, mesh.domain_lo, hi, blocks, mesh.block_cells, mesh.boundaries,
                                         level[order], index[order], 0)
        new_of_old = np.argsort(order)[:mesh.nblocks]
        plan = {"level": new_mesh.block_level, "index": new_mesh.block_index,
                "keep": np.column_stack([new_of_old, np.arange(mesh.nblocks)]).astype(np.int64),
                "children": np.zeros((0, 5), dtype=np.int64), "parents": np.zeros((0, 5), dtype=np.int64)}
        self.move_to_mesh(plan, new_mesh)
        self.growths += 1
        return True


def _overlap(lo: np.ndarray, hi: np.ndarray, a: float, b: float) -> np.ndarray:
    """Length of [lo, hi] inside [a, b] (m), elementwise."""
    return np.clip(np.minimum(hi, b) - np.maximum(lo, a), 0.0, None)


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = MAX_CFL,
          geometry: str = "2d-planar", comm=None) -> Simulation:
    """Build the column-collapse :class:`~impactpipe.hydro.solver.Simulation` (SI units; module docstring).

    With ``comm`` (an MPI communicator; collective) the ranks build the run together, each
    setting its own blocks (:func:`~impactpipe.hydro.parallel.distributed.shared_simulation`),
    and the Simulation returned is this rank's share of it."""
    check_geometry("column_collapse", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    errors = violations(PARAMETERS, p)
    if errors:
        raise ValueError("; ".join(errors))
    if cfl > MAX_CFL:
        raise ValueError(f"cfl: must be <= {MAX_CFL:g} for a column collapse (got {cfl:g}); see MAX_CFL")
    names, specs, eos = material_list(materials, [p["material"]])
    box = domain(p["height"], p["width"], int(p["cells_per_height"]), block_cells, p["levels"], p["room"])
    mesh = adaptive_mesh(geometry, box["lo"], box["hi"], box["cells"], box["boundaries"], box["block_cells"],
                         p["levels"])
    rule = rule_from_config(p["refinement"])

    def simulation(m: BlockMesh, state: HydroState, partition=None) -> Simulation:
        sim = ColumnCollapseSimulation(m, names, specs, state, cfl=cfl,
                                       tensile_strength=tensile_strengths(materials, names),
                                       strength=strength_specs(materials, names),
                                       gravity=ExternalGravity([0.0, -p["gravity"], 0.0], m), refinement=rule,
                                       partition=partition)
        sim.bulk_pressure_predictor = True
        sim.step_tensile_limit = True
        sim.void_settling = p["settling"]
        if sim.strength is not None:
            sim.strength.set_rough_wall(VERTICAL_AXIS, 0)
            sim.strength.set_surface_layer_pressure([0.0, -p["gravity"], 0.0])
            if p["hourglass"] > 0.0:
                sim.strength.set_hourglass_viscosity(p["hourglass"], impedance(eos, sim.shear_modulus[0]))
            if p["face_shear"]:
                sim.strength.set_face_shear(shear_modulus(eos, sim.shear_modulus[0]), partition)
        return sim

    def build(m: BlockMesh) -> Simulation:
        if comm is None:
            return simulation(m, initial_state(m, p, eos))
        return shared_simulation(comm, m, lambda whole, blocks: initial_state(whole, p, eos, blocks),
                                 lambda state, partition: simulation(m, state, partition))

    return refine_initial(mesh, build)


def _at_rest(eos, shear: np.ndarray) -> tuple[float, float, float]:
    """(rho0 (kg/m^3), c_K^2 (m^2/s^2), G (Pa)) of material 0 of the packed ``eos`` at its reference
    density and zero pressure, G = shear[0] + shear[1] rho0 c_K^2 from its ``shear`` row."""
    kind, row = eos.kind[0], eos.params[0]
    rho0 = float(reference_density(kind, row, eos.table))
    _, c2, _ = pressure_sound_speed(kind, row, eos.table, rho0, energy_from_pressure(kind, row, eos.table, rho0, 0.0))
    return rho0, float(c2), float(shear[0] + shear[1] * rho0 * c2)


def impedance(eos, shear: np.ndarray) -> float:
    """Longitudinal impedance rho0 c_L (kg/(m^2 s)) of material 0 of the packed ``eos`` at its
    reference density and zero pressure, c_L^2 = c_K^2 + 4 G / (3 rho0), G from its ``shear``
    row (G = shear[0] + shear[1] rho0 c_K^2, Pa)."""
    rho0, c2, modulus = _at_rest(eos, shear)
    return rho0 * float(np.sqrt(c2 + 4.0 * modulus / (3.0 * rho0)))


def shear_modulus(eos, shear: np.ndarray) -> float:
    """Shear modulus G (Pa) of material 0 of the packed ``eos`` at its reference density and zero
    pressure, from its ``shear`` row (G = shear[0] + shear[1] rho0 c_K^2)."""
    return _at_rest(eos, shear)[2]


def initial_state(mesh: BlockMesh, p: dict, eos, blocks: slice = slice(None)) -> HydroState:
    """The column at rest at its reference density (kg/m^3) in hydrostatic equilibrium, void
    elsewhere, in the blocks ``blocks`` of ``mesh``.

    Each cell's volume fraction is the area of the column inside it over its own; its pressure
    rho0 g (H0 - z_m) (Pa) is taken at the centroid height z_m (m) of the material in it.
    """
    mesh = mesh.some_blocks(blocks)
    dx = mesh.block_dx[:, 0].reshape(-1, 1, 1, 1)
    centres = mesh.cell_centers()
    x, z = centres[:, 0], centres[:, 1]
    depth = _overlap(z - 0.5 * dx, z + 0.5 * dx, 0.0, p["height"])
    fraction = _overlap(x - 0.5 * dx, x + 0.5 * dx, 0.0, p["width"]) * depth / (dx * dx)
    rho0 = float(reference_density(eos.kind[0], eos.params[0], eos.table))
    centroid = (z - 0.5 * dx) + 0.5 * depth
    pressure = rho0 * p["gravity"] * np.clip(p["height"] - centroid, 0.0, None)
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, fraction, 0, eos, rho0, np.zeros(3), pressure=pressure)
    return state


def kinetic_energy(snapshot) -> float:
    """Kinetic energy sum over cells of rho |u|^2 / 2 V of a 2d-planar ``snapshot`` (J, per m of depth)."""
    widths = (snapshot.block_hi - snapshot.block_lo)[:, :2] / np.asarray(snapshot.volume_fraction.shape[2:4])
    volume = (widths[:, 0] * widths[:, 1])[:, None, None, None]
    rho = snapshot.partial_density.sum(axis=1)
    return float((0.5 * rho * (snapshot.velocity ** 2).sum(axis=1) * volume).sum())


def deposit(snapshot) -> dict:
    """Run-out and height of the material in a 2d-planar ``snapshot`` of this problem (m).

    The thickness profile h(x) = sum_z alpha dz (m, alpha the material volume fraction summed
    over the materials) is taken per cell column of the finest level, dx (a coarser cell adds
    its column's thickness to each of the finest columns it spans).  ``runout`` L_f: going out from the wall, the
    right edge of the last column of the continuous deposit (h >= FRONT_THICKNESS_CELLS cell
    sizes) plus dx h_next / (FRONT_THICKNESS_CELLS dx) for the thinner column beyond it
    (at most one cell); detached spray further out is left out.  ``height`` H_f is the largest
    h(x) (at the wall in a deposit).  ``centroid``: the distance of the material's centre
    from the wall, sum_x x h(x) / sum_x h(x) (m), a measure of how far the bulk has moved that,
    unlike the front, does not jump by a cell when the thinnest column crosses the threshold.
    Also ``x`` (cell centres, m) and ``thickness`` h (m), arrays over the cell columns, and ``dx``
    (m); :func:`front_at_thickness` and :func:`front_by_volume` take other fronts from them.
    """
    lo = snapshot.block_lo
    nx = snapshot.volume_fraction.shape[2]
    widths = (snapshot.block_hi[:, 0] - lo[:, 0]) / nx
    dx = float(widths.min())
    fill = snapshot.volume_fraction[:, :, :, :, 0].sum(axis=1)
    first = float(lo[:, 0].min())
    column = np.rint((lo[:, 0] - first) / dx).astype(int)
    span = np.rint(widths / dx).astype(int)
    ncols = int((column + nx * span).max())
    thickness = np.zeros(ncols)
    for b in range(lo.shape[0]):
        thickness[column[b]:column[b] + nx * span[b]] += np.repeat(fill[b].sum(axis=1) * widths[b], span[b])
    x = first + (np.arange(ncols) + 0.5) * dx
    centroid = float((x * thickness).sum() / thickness.sum()) if thickness.sum() > 0.0 else float("nan")
    profile = {"height": float(thickness.max()), "centroid": centroid, "x": x, "thickness": thickness, "dx": dx}
    return {"runout": front_at_thickness(profile, FRONT_THICKNESS_CELLS * dx), **profile}


def front_at_thickness(deposit: dict, threshold: float) -> float:
    """The front of ``deposit`` (:func:`deposit`) where its thickness falls below ``threshold`` (m).

    As ``deposit``'s ``runout``, with a threshold fixed in length instead of half a cell: going out
    from the wall, the right edge of the last cell column of the continuous deposit
    (h >= ``threshold``) plus dx min(h_next / threshold, 1) for the column beyond it (m).
    """
    x, thickness, dx = deposit["x"], deposit["thickness"], deposit["dx"]
    thin = np.nonzero(thickness < threshold)[0]
    edge = int(thin[0]) if thin.size else thickness.size
    front = float(x[0] - 0.5 * dx + edge * dx)
    if edge < thickness.size:
        front += dx * min(thickness[edge] / threshold, 1.0)
    return front


def front_by_volume(deposit: dict, share: float) -> float:
    """The position from the wall that encloses ``share`` of the deposit's volume (m).

    The cumulative volume per unit depth sum h dx from the wall, interpolated linearly across
    the cell column where it reaches ``share`` of the total (all the material, detached spray
    included).
    """
    x, thickness, dx = deposit["x"], deposit["thickness"], deposit["dx"]
    cumulative = np.cumsum(thickness) * dx
    if cumulative.size == 0 or cumulative[-1] <= 0.0:
        return float("nan")
    target = share * cumulative[-1]
    k = int(np.searchsorted(cumulative, target))
    before = cumulative[k - 1] if k > 0 else 0.0
    return float(x[k] - 0.5 * dx + dx * (target - before) / (thickness[k] * dx))
