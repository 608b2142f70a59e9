"""Smooth density wave advected through a periodic box at uniform velocity and pressure.

rho(x, 0) = density (1 + amplitude sin(2 pi x / length)), u = (velocity, 0, 0),
p = pressure.  The exact solution is the initial profile shifted by velocity * t; after
``end_time`` = length / velocity (one crossing) it equals the initial data.  1d-planar,
or along x in 2d-planar / 3d (one periodic root block across).  ``cells`` counts the finest
level; with ``levels`` > 1 the mesh is adaptive
(:func:`~impactpipe.hydro.problems.common.adaptive_simulation`); the wave refines only where
its density changes across a cell by more than ``refinement.density_jump``.
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.problems.common import (ADAPTIVE_DEFAULTS, adaptive_simulation, check_geometry, material_list,
                                              merged, tube_mesh)
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
DEFAULTS = {**setup_defaults(PARAMETERS), **ADAPTIVE_DEFAULTS}


def exact_density(p: dict, x: np.ndarray, t: float) -> np.ndarray:
    """Exact density (kg/m^3) at positions x (m) and time t (s) for merged parameters ``p``."""
    phase = 2.0 * np.pi * (x - p["velocity"] * t) / p["length"]
    return p["density"] * (1.0 + p["amplitude"] * np.sin(phase))


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "1d-planar", comm=None):
    """Build the advection :class:`~impactpipe.hydro.solver.Simulation` (SI units).

    With ``comm`` (an MPI communicator; collective) the ranks build the run together, each
    setting its own blocks (:func:`~impactpipe.hydro.parallel.distributed.shared_simulation`), and
    the Simulation returned is this rank's share of it."""
    check_geometry("advection", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    names, specs, eos = material_list(materials, [p["material"]])
    mesh = tube_mesh(geometry, p["length"], p["cells"], ("periodic", "periodic"), block_cells, p["levels"])
    return adaptive_simulation(mesh, lambda m, blocks: initial_state(m, p, eos, blocks), names, specs, cfl, p["refinement"],
                               comm=comm)


def initial_state(mesh: BlockMesh, p: dict, eos, blocks: slice = slice(None)) -> HydroState:
    """The density wave (kg/m^3, cell averages of the sine over each cell's own width) at ``velocity``
    (m/s) and ``pressure`` (Pa), in the blocks ``blocks`` of ``mesh``."""
    mesh = mesh.some_blocks(blocks)
    x = mesh.cell_centers()[:, 0]
    dx = mesh.block_dx[:, 0].reshape(-1, 1, 1, 1)
    k = 2.0 * np.pi / p["length"]
    average = (np.cos(k * (x - 0.5 * dx)) - np.cos(k * (x + 0.5 * dx))) / (k * dx)
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, eos, p["density"] * (1.0 + p["amplitude"] * average),
                       np.array([p["velocity"], 0.0, 0.0]), pressure=p["pressure"])
    return state
