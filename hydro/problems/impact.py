"""Impact of a projectile sphere on a target sphere, void around (2d-cylindrical or 3d).

The target (radius R_T) is centred at the origin, the projectile (radius R_P) at
(0, 0, R_T + R_P): the two touch at the contact point (0, 0, R_T), whose tangent plane is
z = R_T.  Both start at their reference density rho0 with e = 0 (p = 0).  Material 0 is the
target, material 1 the projectile (named "<material> (projectile)" when both are the same
material), so the projectile's mass can be followed.

The projectile moves in the target frame at

    v_P = V (cos theta, 0, -sin theta)      (m/s),

theta = ``angle`` (degrees) measured from the tangent plane at the contact point (90 is
head-on); the impact plane is x-z and the projectile travels downrange towards +x.

Geometries:

- 2d-cylindrical (head-on only, theta = 90): axes (r, z), the symmetry axis is z,
  reflecting at r = 0.
- 3d: axes (x, y, z).  The scene is mirror-symmetric about y = 0, so by default only
  y >= 0 is computed, with a reflecting plane at y = 0 (``full_domain`` computes
  y in [-Y, Y] instead, the mesh being the mirror image of the half one).

Mesh (:func:`domain`): finest cell size dx = R_P / ``cells_per_projectile_radius``; with
L = (1 + ``margin``) R_T the box spans r or x in [-L, L] (r in [0, L]), y in [0, L]
(or [-L, L]) and z in [-L, R_T + 2 R_P + margin R_T]; each axis's cell count is rounded up
to whole root blocks (x is centred on 0, the others grow away from the target's lower / the
symmetry side).  Outflow everywhere else: what leaves is counted by the solver.  With
``levels`` > 1 the mesh is adaptive: root cells are 2^(levels - 1) dx, the blocks that the
bodies' surfaces cross start at the finest level (so both spheres are resolved at dx from
t = 0), and ``refinement`` (:class:`~impactpipe.hydro.amr.regrid.RefinementRule` keys)
decides where the mesh refines and coarsens as the impact proceeds.
With ``self_gravity`` the bodies' own gravity acts in the hydro stage
(:class:`~impactpipe.hydro.self_gravity.SelfGravity`, expansion order ``self_gravity_order``;
a 3d half domain stands for the whole body) and the target starts in hydrostatic equilibrium,
at its reference (bulk) density with the internal energy that gives the EOS the lithostatic pressure
(:func:`lithostatic_pressure`, :func:`set_lithostatic_sphere`; a porous target at its distension
alpha_0, its matrix carrying alpha_0 times that pressure); the projectile starts at p = 0.
Volume fractions are set by ``subsamples`` point samples per cell and axis in the cells that
the sphere's surface may cut (cells wholly inside or outside are set directly), weighted by
the annular volume in 2d-cylindrical.  The cells both spheres cut near the contact point hold
both materials; they take the sum of the two bodies' momenta and are heated by the kinetic
energy that merge loses (:meth:`~impactpipe.hydro.mesh.state.HydroState.set_material`), so
the state carries exactly the projectile's momentum m_P v_P and kinetic energy m_P V^2 / 2.
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.amr.regrid import refine_to, rule_from_config
from impactpipe.hydro.eos import pack_eos, reference_density
from impactpipe.hydro.eos.porosity import initial_distension
from impactpipe.hydro.mesh.blocks import DEFAULT_BLOCK_CELLS, BlockMesh
from impactpipe.hydro.problems.common import (
    ADAPTIVE_DEFAULTS,
    adaptive_mesh,
    check_geometry,
    material_list,
    merged,
    new_simulation,
    root_cell_multiple,
    strength_specs,
    tensile_strengths,
)
from impactpipe.hydro.problems.parameters import Parameter, Record
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.parallel.distributed import shared_simulation
from impactpipe.hydro.self_gravity import DEFAULT_ORDER, G, SelfGravity
from impactpipe.hydro.tracers.placement import place_on_grid, place_on_rays

#: Material index of the projectile (the target is 0).
PROJECTILE_MATERIAL = 1

#: Geometries this problem runs in.
GEOMETRIES = ('2d-cylindrical', '3d')

#: A sphere of one material.
BODY = {
    "material": Parameter(kind=str, description="material name"),
    "radius": Parameter(gt=0, units="m"),
}

#: The parameters of an impact scene, as a run configuration states them.  :func:`setup`
#: takes them in another shape (the projectile's velocity with the projectile, the mesh's
#: resolution, margin and levels resolved by the pipeline) with :data:`DEFAULTS`.
PARAMETERS = {
    "target": Record("Body", BODY, description="the target sphere, centred at the origin",
                     example={"material": "basalt", "radius": 1000.0}),
    "projectile": Record("Body", BODY, description="the projectile sphere, touching the target at (0, 0, R_T)",
                         example={"material": "basalt", "radius": 100.0}),
    "impact": Record("Impact", {
        "velocity": Parameter(gt=0, units="m/s", description="impact speed in the target frame", example=3000.0),
        "angle": Parameter(90.0, gt=0, le=90, description="degrees from the tangent plane; 90 = head-on"),
    }, description="how the projectile moves"),
    "temperature": Parameter(293.0, gt=0, units="K", description="initial temperature of both bodies"),
    "domain_margin": Parameter(0.25, ge=0, description="mesh extends this many target radii beyond the target"),
    "full_domain": Parameter(False, kind=bool,
                             description="3d only: compute both halves instead of using the y = 0 symmetry plane"),
}

#: What :func:`setup` takes for parameters a call leaves out; ``angle``, ``full_domain`` and
#: ``margin`` default as the scene's ``impact.angle``, ``full_domain`` and ``domain_margin``.
DEFAULTS = {
    "target": dict(PARAMETERS["target"].example),
    "projectile": {**PARAMETERS["projectile"].example, "velocity": PARAMETERS["impact"].fields["velocity"].example},
    "angle": PARAMETERS["impact"].fields["angle"].default,
    "full_domain": PARAMETERS["full_domain"].default,
    "cells_per_projectile_radius": 10,
    "margin": PARAMETERS["domain_margin"].default,
    "subsamples": 4,
    "end_time": 1.0,
    "self_gravity": False,
    "self_gravity_order": DEFAULT_ORDER,
    **ADAPTIVE_DEFAULTS,
}


def projectile_start(target_radius: float, projectile_radius: float, speed: float, angle: float):
    """(centre (3,) m, velocity (3,) m/s) of the projectile at t = 0, in 3d Cartesian coordinates.

    Centre (0, 0, R_T + R_P); velocity V (cos theta, 0, -sin theta), theta = ``angle`` in
    degrees from the tangent plane at the contact point (0, 0, R_T).  At theta = 90 the
    x component is exactly 0.
    """
    if not 0.0 < angle <= 90.0:
        raise ValueError(f"angle: the impact angle must lie in (0, 90] degrees from the tangent plane (got {angle})")
    theta = np.radians(angle)
    cos_theta = 0.0 if angle == 90.0 else float(np.cos(theta))
    centre = np.array([0.0, 0.0, target_radius + projectile_radius])
    return centre, speed * np.array([cos_theta, 0.0, -np.sin(theta)])


def domain(geometry: str, target_radius: float, projectile_radius: float, cells_per_projectile_radius: float,
           margin: float, block_cells: int | None = None, full_domain: bool = False, levels: int = 1) -> dict:
    """The impact mesh box (see the module docstring); every length in m.

    Returns a dict with ``cell_size`` dx (the finest), ``lo`` and ``hi`` (one entry per used
    axis), ``cells`` (per used axis at the finest level, multiples of ``block_cells``
    2^(levels - 1)), ``boundaries`` ((low, high) kind per axis), ``block_cells``, ``symmetry``
    (a sentence naming the symmetry used) and ``half_domain`` (True when only y >= 0 of a 3d
    scene is computed).
    """
    check_geometry("impact", GEOMETRIES, geometry)
    ndim = 2 if geometry == "2d-cylindrical" else 3
    bc = int(block_cells or DEFAULT_BLOCK_CELLS[ndim])
    multiple = root_cell_multiple(bc, levels)
    dx = projectile_radius / cells_per_projectile_radius
    half_width = (1.0 + margin) * target_radius
    z_lo = -half_width
    z_hi = target_radius + 2.0 * projectile_radius + margin * target_radius

    def whole_blocks(length: float) -> int:
        return int(np.ceil(length / dx / multiple)) * multiple

    nz = whole_blocks(z_hi - z_lo)
    n_side = whole_blocks(half_width)
    if geometry == "2d-cylindrical":
        return {"cell_size": dx, "lo": [0.0, z_lo], "hi": [n_side * dx, z_lo + nz * dx], "cells": [n_side, nz],
                "boundaries": [("reflecting", "outflow"), ("outflow", "outflow")], "block_cells": bc,
                "symmetry": "axisymmetric about z (reflecting axis r = 0)", "half_domain": False}
    nx = whole_blocks(2.0 * half_width)
    x_lo = -0.5 * nx * dx
    if full_domain:
        y_lo, ny, y_bc = -n_side * dx, 2 * n_side, ("outflow", "outflow")
        symmetry = "none: both halves y < 0 and y > 0 computed (full_domain)"
    else:
        y_lo, ny, y_bc = 0.0, n_side, ("reflecting", "outflow")
        symmetry = "mirror plane y = 0 (reflecting), half domain y >= 0; the hand-off mirrors it"
    return {"cell_size": dx, "lo": [x_lo, y_lo, z_lo], "hi": [x_lo + nx * dx, y_lo + ny * dx, z_lo + nz * dx],
            "cells": [nx, ny, nz],
            "boundaries": [("outflow", "outflow"), y_bc, ("outflow", "outflow")],
            "block_cells": bc, "symmetry": symmetry, "half_domain": not full_domain}


def sphere_fraction(mesh: BlockMesh, center, radius: float, subsamples: int) -> np.ndarray:
    """Volume fraction (NB, nx, ny, nz) of the ball |x - center| < radius in each cell (-).

    ``center`` is (x, y, z) in 3d and (0, z) (on the axis) in 2d-cylindrical.  Cells whose
    centre lies more than half a cell diagonal inside (outside) the sphere get 1 (0); the
    others are sampled at ``subsamples`` points per axis (offsets (i + 1/2)/n - 1/2 cells),
    each weighted by its radius r in 2d-cylindrical (annular volume) and equally in 3d.
    """
    ndim = mesh.ndim
    center = np.asarray(center, dtype=float)[:ndim]
    centers = mesh.cell_centers()[:, :ndim]
    widths = mesh.block_dx[:, :ndim]
    shape = (mesh.nblocks, 1, 1, 1)
    distance = np.sqrt(sum((centers[:, d] - center[d]) ** 2 for d in range(ndim)))
    half_diagonal = 0.5 * np.sqrt((widths ** 2).sum(axis=1)).reshape(shape)
    frac = (distance < radius - half_diagonal).astype(float)
    cut = np.abs(distance - radius) <= half_diagonal
    block, *cell = np.nonzero(cut)
    offsets = (np.arange(subsamples) + 0.5) / subsamples - 0.5
    grids = np.meshgrid(*([offsets] * ndim), indexing="ij")
    inside = np.zeros(block.size)
    weight = np.zeros(block.size)
    for sample in zip(*(g.ravel() for g in grids)):
        points = [centers[(block, d, *cell)] + sample[d] * widths[block, d] for d in range(ndim)]
        w = np.abs(points[0]) if mesh.geometry == "2d-cylindrical" else np.ones(block.size)
        r2 = sum((points[d] - center[d]) ** 2 for d in range(ndim))
        inside += w * (r2 < radius * radius)
        weight += w
    frac[cut] = inside / weight
    return frac


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "2d-cylindrical", comm=None):
    """Build the impact :class:`~impactpipe.hydro.solver.Simulation` (SI units; module docstring).

    With ``comm`` (an MPI communicator; collective) the ranks build the run together, each
    setting its own blocks (:func:`~impactpipe.hydro.parallel.distributed.shared_simulation`), and
    the Simulation returned is this rank's share of it."""
    check_geometry("impact", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    tgt, prj = p["target"], p["projectile"]
    if geometry == "2d-cylindrical" and p["angle"] != 90.0:
        raise ValueError(f"angle: {p['angle']:g} is oblique, which is not axisymmetric; "
                         f"2d-cylindrical runs head-on impacts (angle 90) only, use 3d")
    if geometry == "2d-cylindrical" and p["full_domain"]:
        raise ValueError("full_domain: True applies to 3d only (2d-cylindrical uses the symmetry axis); "
                         "use False or geometry 3d")
    _, specs, _ = material_list(materials, [tgt["material"], prj["material"]])
    names = [tgt["material"], prj["material"]]
    if names[0] == names[1]:
        names[1] = f"{names[1]} (projectile)"
        specs = [specs[0], dict(specs[0])]
    eos = pack_eos(specs)
    levels = int(p["levels"])
    box = domain(geometry, tgt["radius"], prj["radius"], p["cells_per_projectile_radius"], p["margin"],
                 block_cells, p["full_domain"], levels)
    mesh = adaptive_mesh(geometry, box["lo"], box["hi"], box["cells"], box["boundaries"], box["block_cells"], levels)
    centre, velocity = projectile_start(tgt["radius"], prj["radius"], prj["velocity"], p["angle"])
    if geometry == "2d-cylindrical":  # mesh components (r, z, 0)
        centre, velocity = centre[1:], np.array([0.0, velocity[2], 0.0])
    bodies = ((tgt, np.zeros(3), np.zeros(3)), (prj, centre, velocity))
    mesh = refine_to(mesh, lambda m: np.where(
        np.logical_or.reduce([surface_crosses(m, c, body["radius"]) for body, c, _ in bodies]), levels - 1, 0))

    def initial_state(whole: BlockMesh, blocks: slice = slice(None)) -> HydroState:
        """The two bodies set on the cells of the blocks ``blocks`` of ``whole`` (``mesh``)."""
        blocks_mesh = whole.some_blocks(blocks)
        state = HydroState.empty(blocks_mesh, len(names))
        for k, (body, body_centre, body_velocity) in enumerate(bodies):
            rho0 = float(reference_density(eos.kind[k], eos.params[k], eos.table)) / initial_distension(specs[k])
            frac = sphere_fraction(blocks_mesh, body_centre, body["radius"], p["subsamples"])
            if k == 0 and p["self_gravity"]:
                set_lithostatic_sphere(state, blocks_mesh, frac, k, eos, rho0, body["radius"],
                                       initial_distension(specs[k]))
            else:
                state.set_material(blocks_mesh, frac, k, eos, rho0, body_velocity, specific_energy=0.0)
        return state

    strengths = tensile_strengths(materials, [tgt["material"], prj["material"]])
    gravity = None
    if p["self_gravity"]:
        gravity = SelfGravity(mesh, order=p["self_gravity_order"], mirror_y=box["half_domain"])

    def build(state: HydroState, partition=None):
        return new_simulation(mesh, names, specs, state, cfl, strengths,
                              strength_specs(materials, [tgt["material"], prj["material"]]),
                              refinement=rule_from_config(p["refinement"]), gravity=gravity, partition=partition)

    if comm is None:
        return build(initial_state(mesh))
    return shared_simulation(comm, mesh, initial_state, build)


def lithostatic_pressure(density: float, radius: float, distance):
    """Pressure (Pa) at ``distance`` r (m) from the centre of a uniform self-gravitating sphere
    of ``density`` rho (kg/m^3) and ``radius`` R (m) in hydrostatic equilibrium:
    p = (2 pi / 3) G rho^2 (R^2 - r^2) inside, 0 outside."""
    r = np.asarray(distance, dtype=float)
    return 2.0 * np.pi / 3.0 * G * density ** 2 * np.clip(radius * radius - r * r, 0.0, None)


def set_lithostatic_sphere(state: HydroState, mesh: BlockMesh, fraction, material: int, eos, density: float,
                           radius: float, distension: float = 1.0) -> None:
    """Put ``material`` at rest into the cells ``fraction`` of a uniform self-gravitating sphere of
    ``radius`` R (m) centred at the origin, in hydrostatic equilibrium.

    Every cell holds the bulk density ``density`` rho (kg/m^3) and the internal energy e (J/kg)
    that gives the lithostatic pressure p(r) of :func:`lithostatic_pressure`.  A porous material
    (``distension`` alpha_0 > 1) starts unstrained, at its alpha_0 (the epsilon-alpha model
    compacts with strain, and a body at rest has none), and e solves P_s(alpha_0 rho, e) = alpha_0 p:
    the matrix at its reference density alpha_0 rho = rho_s0 carries alpha_0 times the overburden
    through its thermal pressure (docs/eos.md, "Self-gravity on a porous body").
    """
    distance = np.sqrt((mesh.cell_centers() ** 2).sum(axis=1))
    pressure = np.where(fraction > 0.0, lithostatic_pressure(density, radius, distance), 0.0)
    state.set_material(mesh, fraction, material, eos, density, np.zeros(3), pressure=pressure,
                       distension=distension)


def surface_crosses(mesh: BlockMesh, center, radius: float) -> np.ndarray:
    """(NB,) True for the blocks that the sphere |x - center| = radius (m) passes through.

    ``center`` is (x, y, z) in 3d and (0, z) in 2d-cylindrical (as :func:`sphere_fraction`).
    The nearest and farthest points of each block box from the centre bracket the radius.
    """
    ndim = mesh.ndim
    c = np.asarray(center, dtype=float)[:ndim]
    lo = mesh.block_lo[:, :ndim]
    hi = mesh.block_hi[:, :ndim]
    nearest = np.sqrt((np.maximum(np.maximum(lo - c, c - hi), 0.0) ** 2).sum(axis=1))
    farthest = np.sqrt((np.maximum(np.abs(lo - c), np.abs(hi - c)) ** 2).sum(axis=1))
    return (nearest <= radius) & (farthest >= radius)


#: Rays of the 2d-cylindrical tracer layout (the count per ray is ``count`` / rays).
TRACER_RAYS = 30


def tracer_grid_spacing(target_radius: float, count: int) -> float:
    """Lattice spacing h (m) of the 3d tracer grid: the whole target holds about ``count`` tracers.

    h = (V_T / count)^(1/3), V_T = (4 pi / 3) R_T^3.
    """
    return (4.0 * np.pi / 3.0 * target_radius ** 3 / count) ** (1.0 / 3.0)


def tracer_positions(geometry: str, target_radius: float, projectile_radius: float, count: int,
                     full_domain: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(positions (m), material indices) of the impact scene's tracers, about ``count`` of them.

    2d-cylindrical: rays from the impact point plus a projectile grid (:func:`place_on_rays`).
    3d: cubic lattices filling both bodies (:func:`place_on_grid`), spacing
    :func:`tracer_grid_spacing` in the target and min(h, R_P / 4) in the projectile; a
    half-domain run (mirror plane y = 0, ``full_domain`` False) keeps the lattice points with
    y > 0 (none lies on y = 0), and the hand-off mirrors them with the mesh.
    """
    r_t, r_p = target_radius, projectile_radius
    if geometry == "3d":
        positions, materials = place_on_grid((0.0, 0.0, 0.0), r_t, (0.0, 0.0, r_t + r_p), r_p,
                                             tracer_grid_spacing(r_t, max(count, 1)))
        if not full_domain:
            half = positions[:, 1] > 0.0
            positions, materials = positions[half], materials[half]
        return positions, materials
    rays = min(TRACER_RAYS, max(1, count))
    return place_on_rays((0.0, r_t), r_t, 0.0, n_rays=rays, count=max(count, rays),
                         projectile_radius=r_p, projectile_center_z=r_t + r_p)
