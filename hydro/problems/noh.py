"""Noh implosion: cold ideal gas streaming at ``velocity`` towards the origin.

1d-planar (nu = 1) on [0, extent] with a reflecting wall at x = 0, or 2d-cylindrical
(r, z) on [0, extent]^2 with the velocity aimed at the origin (a spherical implosion,
nu = 3) and the z = 0 plane reflecting.  Outer boundaries are outflow (zero gradient),
which is exact in planar symmetry and approximate (the inflowing density should grow as
(1 + u0 t / r)^(nu - 1)) otherwise.  Exact solution:
:func:`impactpipe.hydro.exact.noh.noh_solution`.  The scheme shows the usual wall heating:
a density deficit (and temperature excess) in the first cells next to the origin.
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.problems.common import check_geometry, material_list, merged, new_simulation
from impactpipe.hydro.problems.parameters import Parameter, setup_defaults
from impactpipe.hydro.mesh.state import HydroState

#: Geometries this problem runs in.
GEOMETRIES = ('1d-planar', '2d-cylindrical')

PARAMETERS = {
    "material": Parameter(kind=str, description="material name", example="gas"),
    "density": Parameter(1.0, gt=0, units="kg/m^3"),
    "velocity": Parameter(1.0, gt=0, units="m/s", description="inflow speed"),
    "pressure": Parameter(1.0e-6, ge=0, units="Pa"),
    "cells": Parameter(128, kind=int, ge=8, description="cells along each axis"),
    "extent": Parameter(1.0, gt=0, units="m"),
    "end_time": Parameter(0.6, gt=0, units="s", description="end of the run"),
}

#: What :func:`setup` takes for parameters a call leaves out.
DEFAULTS = setup_defaults(PARAMETERS)


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "1d-planar"):
    """Build the Noh :class:`~impactpipe.hydro.solver.Simulation` (SI units)."""
    check_geometry("noh", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    names, specs, eos = material_list(materials, [p["material"]])
    ndim = 1 if geometry == "1d-planar" else 2
    mesh = BlockMesh.uniform(geometry, [0.0] * ndim, [p["extent"]] * ndim, [p["cells"]] * ndim,
                             [("reflecting", "outflow")] * ndim, block_cells)
    centers = mesh.cell_centers()
    radius = np.sqrt((centers[:, :ndim] ** 2).sum(axis=1))
    velocity = np.zeros((mesh.nblocks, 3) + mesh.interior_shape)
    for d in range(ndim):
        velocity[:, d] = -p["velocity"] * centers[:, d] / radius
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, eos, p["density"], velocity, pressure=p["pressure"])
    return new_simulation(mesh, names, specs, state, cfl)
