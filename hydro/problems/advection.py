"""Smooth density wave advected through a periodic box at uniform velocity and pressure.

rho(x, 0) = density (1 + amplitude sin(2 pi x / length)), u = (velocity, 0, 0),
p = pressure.  The exact solution is the initial profile shifted by velocity * t; after
``end_time`` = length / velocity (one crossing) it equals the initial data.  1d-planar,
or along x in 2d-planar / 3d (one periodic block across).
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.problems.common import check_geometry, material_list, merged, new_simulation
from impactpipe.hydro.problems.parameters import Parameter, setup_defaults
from impactpipe.hydro.mesh.state import HydroState

#: Geometries this problem runs in.
GEOMETRIES = ('1d-planar', '2d-planar', '3d')

PARAMETERS = {
    "material": Parameter(kind=str, description="material name", example="gas"),
    "length": Parameter(1.0, gt=0, units="m"),
    "cells": Parameter(128, kind=int, ge=8, description="cells along the box"),
    "density": Parameter(1.0, gt=0, units="kg/m^3", description="mean density"),
    "amplitude": Parameter(0.2, ge=0, lt=1, description="relative amplitude of the density wave"),
    "velocity": Parameter(1.0, units="m/s"),
    "pressure": Parameter(1.0, gt=0, units="Pa"),
    "end_time": Parameter(1.0, gt=0, units="s", description="end of the run"),
}

#: What :func:`setup` takes for parameters a call leaves out.
DEFAULTS = setup_defaults(PARAMETERS)


def exact_density(p: dict, x: np.ndarray, t: float) -> np.ndarray:
    """Exact density (kg/m^3) at positions x (m) and time t (s) for merged parameters ``p``."""
    phase = 2.0 * np.pi * (x - p["velocity"] * t) / p["length"]
    return p["density"] * (1.0 + p["amplitude"] * np.sin(phase))


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "1d-planar"):
    """Build the advection :class:`~impactpipe.hydro.solver.Simulation` (SI units)."""
    check_geometry("advection", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    names, specs, eos = material_list(materials, [p["material"]])
    ndim = {"1d-planar": 1, "2d-planar": 2, "3d": 3}[geometry]
    bc = block_cells or {1: 8, 2: 16, 3: 8}[ndim]
    dx = p["length"] / p["cells"]
    mesh = BlockMesh.uniform(geometry, [0.0] * ndim, [p["length"]] + [bc * dx] * (ndim - 1),
                             [p["cells"]] + [bc] * (ndim - 1), [("periodic", "periodic")] * ndim, bc)
    state = HydroState.empty(mesh, 1)
    x = mesh.cell_centers()[:, 0]
    # cell averages of the sine profile (exact integral over each cell)
    k = 2.0 * np.pi / p["length"]
    avg = (np.cos(k * (x - 0.5 * dx)) - np.cos(k * (x + 0.5 * dx))) / (k * dx)
    rho = p["density"] * (1.0 + p["amplitude"] * avg)
    state.set_material(mesh, 1.0, 0, eos, rho, np.array([p["velocity"], 0.0, 0.0]), pressure=p["pressure"])
    return new_simulation(mesh, names, specs, state, cfl)
