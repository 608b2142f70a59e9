"""A slab of one material carried at uniform velocity and pressure through a periodic box.

The slab [slab_lo, slab_hi) (m) holds ``inner`` ({material, density}); the rest holds
``outer`` ({material, density}) or void when ``outer`` is None.  Everything
moves at ``velocity`` (m/s) at ``pressure`` (Pa) (0 with void: a material next to void is in
equilibrium only at zero pressure, e.g. Tillotson at its reference state).  The exact
solution keeps velocity and pressure uniform and shifts the slab; after ``end_time`` =
length / velocity the slab is back where it started.  1d-planar, or along x in 2d-planar /
3d (one periodic root block across).  ``cells`` counts the finest level; with ``levels`` > 1
the mesh is adaptive (:func:`~impactpipe.hydro.problems.common.adaptive_simulation`: the
slab's faces refine).
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

#: A region of one material.
REGION = {
    "material": Parameter(kind=str, description="material name"),
    "density": Parameter(gt=0, units="kg/m^3"),
}

PARAMETERS = {
    "length": Parameter(1.0, gt=0, units="m"),
    "cells": Parameter(128, kind=int, ge=8, description="cells along the box"),
    "slab_lo": Parameter(0.25, units="m", description="lower edge of the slab"),
    "slab_hi": Parameter(0.75, units="m", description="upper edge of the slab"),
    "inner": Record("Region", REGION, description="material of the slab",
                    example={"material": "heavy", "density": 1000.0}),
    "outer": Record("Region", REGION, default=None, description="material around the slab; none leaves void",
                    example={"material": "light", "density": 1.0}),
    "velocity": Parameter(1.0, units="m/s"),
    "pressure": Parameter(1.0, ge=0, units="Pa"),
    "end_time": Parameter(1.0, gt=0, units="s", description="end of the run"),
}

#: What :func:`setup` takes for parameters a call leaves out.
DEFAULTS = {**setup_defaults(PARAMETERS), **ADAPTIVE_DEFAULTS}


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "1d-planar", comm=None):
    """Build the interface-advection :class:`~impactpipe.hydro.solver.Simulation` (SI units).

    With ``comm`` (an MPI communicator; collective) the ranks build the run together, each
    setting its own blocks (:func:`~impactpipe.hydro.parallel.distributed.shared_simulation`), and
    the Simulation returned is this rank's share of it."""
    check_geometry("interface_advection", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    used = [p["inner"]["material"]] + ([p["outer"]["material"]] if p["outer"] is not None else [])
    names, specs, eos = material_list(materials, used)
    mesh = tube_mesh(geometry, p["length"], p["cells"], ("periodic", "periodic"), block_cells, p["levels"])
    return adaptive_simulation(mesh, lambda m, blocks: initial_state(m, p, names, eos, blocks), names, specs, cfl,
                               p["refinement"], comm=comm)


def initial_state(mesh: BlockMesh, p: dict, names: list[str], eos, blocks: slice = slice(None)) -> HydroState:
    """``inner`` in the cells whose centre lies in [slab_lo, slab_hi) (m), ``outer`` (or void) in the
    others, all at ``velocity`` (m/s) and ``pressure`` (Pa), in the blocks ``blocks`` of ``mesh``."""
    mesh = mesh.some_blocks(blocks)
    state = HydroState.empty(mesh, len(names))
    x = mesh.cell_centers()[:, 0]
    inside = (x >= p["slab_lo"]) & (x < p["slab_hi"])
    velocity = np.array([p["velocity"], 0.0, 0.0])
    state.set_material(mesh, inside.astype(float), names.index(p["inner"]["material"]), eos,
                       p["inner"]["density"], velocity, pressure=p["pressure"])
    if p["outer"] is not None:
        state.set_material(mesh, (~inside).astype(float), names.index(p["outer"]["material"]), eos,
                           p["outer"]["density"], velocity, pressure=p["pressure"])
    return state


def interface_width(sim, threshold: float = 0.01) -> float:
    """Mean number of mixed cells (threshold < alpha < 1 - threshold) per interface of the slab material."""
    alpha = sim.snapshot().volume_fraction[:, 0]
    mixed = int(((alpha > threshold) & (alpha < 1.0 - threshold)).sum())
    rows = int(np.prod(alpha.shape[2:]))
    return mixed / (2.0 * rows)
