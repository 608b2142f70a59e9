"""A slab of one material carried at uniform velocity and pressure through a periodic box.

The slab [slab_lo, slab_hi) (m) holds ``inner`` ({material, density}); the rest holds
``outer`` ({material, density}) or void when ``outer["material"]`` is None.  Everything
moves at ``velocity`` (m/s) at ``pressure`` (Pa) (0 with void: a material next to void is in
equilibrium only at zero pressure, e.g. Tillotson at its reference state).  The exact
solution keeps velocity and pressure uniform and shifts the slab; after ``end_time`` =
length / velocity the slab is back where it started.
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.problems.common import check_geometry, material_list, merged, new_simulation
from impactpipe.hydro.mesh.state import HydroState

#: Geometries this problem runs in.
GEOMETRIES = ('1d-planar', '2d-planar', '3d')

DEFAULTS = {
    "length": 1.0,
    "cells": 128,
    "slab_lo": 0.25,
    "slab_hi": 0.75,
    "inner": {"material": "heavy", "density": 1000.0},
    "outer": {"material": "light", "density": 1.0},
    "velocity": 1.0,
    "pressure": 1.0,
    "end_time": 1.0,
}


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "1d-planar"):
    """Build the interface-advection :class:`~impactpipe.hydro.solver.Simulation` (SI units)."""
    check_geometry("interface_advection", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    used = [p["inner"]["material"]] + ([p["outer"]["material"]] if p["outer"]["material"] else [])
    names, specs, eos = material_list(materials, used)
    ndim = {"1d-planar": 1, "2d-planar": 2, "3d": 3}[geometry]
    bc = block_cells or {1: 8, 2: 16, 3: 8}[ndim]
    dx = p["length"] / p["cells"]
    mesh = BlockMesh.uniform(geometry, [0.0] * ndim, [p["length"]] + [bc * dx] * (ndim - 1),
                             [p["cells"]] + [bc] * (ndim - 1), [("periodic", "periodic")] * ndim, bc)
    state = HydroState.empty(mesh, len(names))
    x = mesh.cell_centers()[:, 0]
    inside = (x >= p["slab_lo"]) & (x < p["slab_hi"])
    velocity = np.array([p["velocity"], 0.0, 0.0])
    state.set_material(mesh, inside.astype(float), names.index(p["inner"]["material"]), eos,
                       p["inner"]["density"], velocity, pressure=p["pressure"])
    if p["outer"]["material"]:
        state.set_material(mesh, (~inside).astype(float), names.index(p["outer"]["material"]), eos,
                           p["outer"]["density"], velocity, pressure=p["pressure"])
    return new_simulation(mesh, names, specs, state, cfl)


def interface_width(sim, threshold: float = 0.01) -> float:
    """Mean number of mixed cells (threshold < alpha < 1 - threshold) per interface of the slab material."""
    alpha = sim.snapshot().volume_fraction[:, 0]
    mixed = int(((alpha > threshold) & (alpha < 1.0 - threshold)).sum())
    rows = int(np.prod(alpha.shape[2:]))
    return mixed / (2.0 * rows)
