"""Riemann problem (Sod's shock tube by default) along x.

Two uniform states meet at ``interface`` (m) in a tube of ``length`` (m) with ``cells``
cells along x and outflow ends.  1d-planar, or along x in 2d-planar / 3d with one root block
of periodic cells across (the solution must not depend on y, z).  ``cells`` counts the
finest level; with ``levels`` > 1 the mesh is adaptive
(:func:`~impactpipe.hydro.problems.common.adaptive_simulation`: refined where ``refinement``
flags the diaphragm at t = 0, then where the waves go).  Exact solution:
:func:`impactpipe.hydro.exact.riemann.exact_riemann` (ideal gas, one material or two
materials with the same gamma).
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.problems.common import (ADAPTIVE_DEFAULTS, adaptive_simulation, check_geometry, material_list,
                                              merged, tube_mesh)
from impactpipe.hydro.problems.parameters import Parameter, Record, setup_defaults
from impactpipe.hydro.mesh.state import HydroState

#: Geometries this problem runs in.
GEOMETRIES = ('1d-planar', '2d-planar', '3d')

#: A uniform state on one side of the diaphragm.
FLUID_STATE = {
    "material": Parameter(kind=str, description="material name"),
    "density": Parameter(gt=0, units="kg/m^3"),
    "velocity": Parameter(0.0, units="m/s"),
    "pressure": Parameter(units="Pa"),
}

PARAMETERS = {
    "length": Parameter(1.0, gt=0, units="m"),
    "cells": Parameter(400, kind=int, ge=8, description="cells along the tube"),
    "interface": Parameter(0.5, units="m", description="diaphragm position"),
    "left": Record("FluidState", FLUID_STATE, description="state left of the diaphragm",
                   example={"material": "gas", "density": 1.0, "velocity": 0.0, "pressure": 1.0}),
    "right": Record("FluidState", FLUID_STATE, description="state right of the diaphragm",
                    example={"material": "gas", "density": 0.125, "velocity": 0.0, "pressure": 0.1}),
    "end_time": Parameter(gt=0, units="s", description="end of the run", example=0.2),
}

#: What :func:`setup` takes for parameters a call leaves out: Sod's shock tube on a uniform mesh.
DEFAULTS = {**setup_defaults(PARAMETERS), **ADAPTIVE_DEFAULTS}


def check_parameters(p: dict) -> list[str]:
    """Cross checks of the parameters ``p`` beyond each one's bounds, one message per problem."""
    if not 0.0 < p["interface"] < p["length"]:
        return [f"interface must lie inside (0, length={p['length']:g}) (got {p['interface']:g})"]
    return []


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "1d-planar", comm=None):
    """Build the shock-tube :class:`~impactpipe.hydro.solver.Simulation` (SI units).

    With ``comm`` (an MPI communicator; collective) the ranks build the run together, each
    setting its own blocks (:func:`~impactpipe.hydro.parallel.distributed.shared_simulation`), and
    the Simulation returned is this rank's share of it."""
    check_geometry("shock_tube", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    errors = check_parameters(p)
    if errors:
        raise ValueError("; ".join(errors))
    names, specs, eos = material_list(materials, [p["left"]["material"], p["right"]["material"]])
    mesh = tube_mesh(geometry, p["length"], p["cells"], ("outflow", "outflow"), block_cells, p["levels"])
    return adaptive_simulation(mesh, lambda m, blocks: initial_state(m, p, names, eos, blocks), names, specs, cfl,
                               p["refinement"], comm=comm)


def initial_state(mesh: BlockMesh, p: dict, names: list[str], eos, blocks: slice = slice(None)) -> HydroState:
    """The ``left`` state (density kg/m^3, velocity m/s, pressure Pa) in the cells whose centre lies
    left of ``interface`` (m), the ``right`` state in the others, in the blocks ``blocks`` of ``mesh``."""
    mesh = mesh.some_blocks(blocks)
    state = HydroState.empty(mesh, len(names))
    x = mesh.cell_centers()[:, 0]
    for side, sel in (("left", x < p["interface"]), ("right", x >= p["interface"])):
        s = p[side]
        state.set_material(mesh, sel.astype(float), names.index(s["material"]), eos, s["density"],
                           np.array([s["velocity"], 0.0, 0.0]), pressure=s["pressure"])
    return state
