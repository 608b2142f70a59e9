"""Head-on impact of a projectile sphere on a target sphere (2d-cylindrical, void around).

The target (radius R_T) is centred on the axis at z = 0, the projectile (radius R_P)
at z = R_T + R_P, touching the target at t = 0 and moving at -velocity along z.  Both
start at their reference density with e = 0 (p = 0).  Material 0 is the target, material 1
the projectile (named "<material> (projectile)" when both are the same material), so the
projectile's mass can be followed.  The mesh spans r in [0, (1 + margin)
R_T] and z in [-(1 + margin) R_T, R_T + 2 R_P + margin R_T] with cell size
R_P / cells_per_projectile_radius (cell counts rounded up to whole blocks), reflecting on
the axis and outflow elsewhere.  Volume fractions are set by ``subsamples``^2 point samples
per cell.
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.eos import pack_eos, reference_density
from impactpipe.hydro.mesh import DEFAULT_BLOCK_CELLS, BlockMesh
from impactpipe.hydro.problems.common import (
    check_geometry,
    material_list,
    merged,
    new_simulation,
    strength_specs,
    tensile_strengths,
)
from impactpipe.hydro.state import HydroState

#: Geometries this problem runs in.
GEOMETRIES = ('2d-cylindrical',)

DEFAULTS = {
    "target": {"material": "basalt", "radius": 1000.0},
    "projectile": {"material": "basalt", "radius": 100.0, "velocity": 3000.0},
    "cells_per_projectile_radius": 10,
    "margin": 0.25,
    "subsamples": 4,
    "end_time": 1.0,
}


def sphere_fraction(mesh: BlockMesh, z_center: float, radius: float, subsamples: int) -> np.ndarray:
    """Volume fraction (NB, nr, nz, 1) of a sphere on the axis, by volume-weighted point samples."""
    n = subsamples
    offsets = (np.arange(n) + 0.5) / n - 0.5
    centers = mesh.cell_centers()
    dr = mesh.block_dx[:, 0].reshape(-1, 1, 1, 1)
    dz = mesh.block_dx[:, 1].reshape(-1, 1, 1, 1)
    inside = np.zeros_like(centers[:, 0])
    weight = np.zeros_like(inside)
    for a in offsets:
        r = centers[:, 0] + a * dr
        w = np.abs(r)
        for b in offsets:
            z = centers[:, 1] + b * dz
            inside += w * ((r * r + (z - z_center) ** 2) < radius * radius)
            weight += w
    return inside / weight


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "2d-cylindrical"):
    """Build the impact :class:`~impactpipe.hydro.solver.Simulation` (SI units)."""
    check_geometry("impact", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    tgt, prj = p["target"], p["projectile"]
    _, specs, _ = material_list(materials, [tgt["material"], prj["material"]])
    names = [tgt["material"], prj["material"]]
    if names[0] == names[1]:
        names[1] = f"{names[1]} (projectile)"
        specs = [specs[0], dict(specs[0])]
    eos = pack_eos(specs)
    bc = int(block_cells or DEFAULT_BLOCK_CELLS[2])
    dx = prj["radius"] / p["cells_per_projectile_radius"]
    r_hi = (1.0 + p["margin"]) * tgt["radius"]
    z_lo = -(1.0 + p["margin"]) * tgt["radius"]
    z_hi = tgt["radius"] + 2.0 * prj["radius"] + p["margin"] * tgt["radius"]
    nr = int(np.ceil(r_hi / dx / bc)) * bc
    nz = int(np.ceil((z_hi - z_lo) / dx / bc)) * bc
    mesh = BlockMesh.uniform(geometry, [0.0, z_lo], [nr * dx, z_lo + nz * dx], [nr, nz],
                             [("reflecting", "outflow"), ("outflow", "outflow")], bc)
    state = HydroState.empty(mesh, len(names))
    bodies = (
        (tgt, 0.0, 0.0),
        (prj, tgt["radius"] + prj["radius"], -prj["velocity"]),
    )
    for k, (body, z_center, vz) in enumerate(bodies):
        rho0 = float(reference_density(eos.kind[k], eos.params[k], eos.table))
        frac = sphere_fraction(mesh, z_center, body["radius"], p["subsamples"])
        state.set_material(mesh, frac, k, eos, rho0, np.array([0.0, vz, 0.0]), specific_energy=0.0)
    strengths = tensile_strengths(materials, [tgt["material"], prj["material"]])
    return new_simulation(mesh, names, specs, state, cfl, strengths,
                          strength_specs(materials, [tgt["material"], prj["material"]]))
