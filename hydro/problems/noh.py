"""Noh implosion: cold ideal gas streaming at ``velocity`` towards the origin.

1d-planar (nu = 1) on [0, extent] with a reflecting wall at x = 0, or 2d-cylindrical
(r, z) on [0, extent]^2 with the velocity aimed at the origin (a spherical implosion,
nu = 3) and the z = 0 plane reflecting.  Outer boundaries are outflow (zero gradient),
which is exact in planar symmetry and approximate (the inflowing density should grow as
(1 + u0 t / r)^(nu - 1)) otherwise.  ``cells`` counts the finest level; with ``levels`` > 1
the mesh is adaptive (:func:`~impactpipe.hydro.problems.common.adaptive_simulation`): the
uniform inflow shows the refinement rule no jump at t = 0, so a box over the origin, where
the shock forms and the wall heating stays, holds the finest level throughout
(:func:`origin_box`); the rest refines as the shock moves out.  Exact solution:
:func:`impactpipe.hydro.exact.noh.noh_solution`.  The scheme shows the usual wall heating:
a density deficit (and temperature excess) in the first cells next to the origin.
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.problems.common import (ADAPTIVE_DEFAULTS, adaptive_mesh, adaptive_simulation, check_geometry,
                                              material_list, merged)
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
DEFAULTS = {**setup_defaults(PARAMETERS), **ADAPTIVE_DEFAULTS}


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "1d-planar", comm=None):
    """Build the Noh :class:`~impactpipe.hydro.solver.Simulation` (SI units).

    With ``comm`` (an MPI communicator; collective) the ranks build the run together, each
    setting its own blocks (:func:`~impactpipe.hydro.parallel.distributed.shared_simulation`), and
    the Simulation returned is this rank's share of it."""
    check_geometry("noh", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    names, specs, eos = material_list(materials, [p["material"]])
    ndim = 1 if geometry == "1d-planar" else 2
    mesh = adaptive_mesh(geometry, [0.0] * ndim, [p["extent"]] * ndim, [p["cells"]] * ndim,
                         [("reflecting", "outflow")] * ndim, block_cells, p["levels"])
    refinement = origin_box(p["refinement"], ndim, mesh.block_cells * p["extent"] / p["cells"], mesh.max_level)
    return adaptive_simulation(mesh, lambda m, blocks: initial_state(m, p, eos, blocks), names, specs, cfl, refinement,
                               comm=comm)


def origin_box(refinement: dict | None, ndim: int, block_width: float, finest: int) -> dict:
    """The ``hydro.refinement`` mapping with a box holding the block at the origin at the ``finest`` level.

    ``block_width`` (m) is the width of a block of the finest level; the box spans half of it.
    Without it the shock would form on root cells (the initial state has no jump for the
    rule to see) and leave a wall-heating defect as wide as a root cell: 1d-planar, 256
    finest cells, 3 levels, density L1 error 2.4x the uniform run's (1.3x with the origin's
    block refined at t = 0 only, the first regrid coarsening it again).
    """
    values = dict(refinement or {})
    box = {"lo": [0.0] * ndim, "hi": [0.5 * block_width] * ndim, "level": finest}
    values["boxes"] = [*values.get("boxes", ()), box]
    return values


def initial_state(mesh: BlockMesh, p: dict, eos, blocks: slice = slice(None)) -> HydroState:
    """The gas at ``density`` (kg/m^3) and ``pressure`` (Pa) streaming at ``velocity`` (m/s) towards the
    origin, in the blocks ``blocks`` of ``mesh``."""
    mesh = mesh.some_blocks(blocks)
    ndim = mesh.ndim
    centers = mesh.cell_centers()
    radius = np.sqrt((centers[:, :ndim] ** 2).sum(axis=1))
    velocity = np.zeros((mesh.nblocks, 3) + mesh.interior_shape)
    for d in range(ndim):
        velocity[:, d] = -p["velocity"] * centers[:, d] / radius
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, eos, p["density"], velocity, pressure=p["pressure"])
    return state
