"""Planar impact: a flyer plate at ``velocity`` hits a target plate at rest (1d-planar).

The flyer occupies [-thickness_f, 0) and moves at +velocity (m/s); the target occupies
[0, thickness_t) at rest; both start at their reference density with e = 0 (p = 0), with
void margins of ``margin`` times the thicker plate on both sides (free surfaces) and
outflow ends.  ``cells`` cells of the finest level span the whole domain; with ``levels`` > 1
the mesh is adaptive (:func:`~impactpipe.hydro.problems.common.adaptive_simulation`: the
plates' faces refine at t = 0, then the shocks).  Until the shocks reach the free
surfaces, the shocked states on both sides of the contact share the pressure and particle
velocity of :func:`impactpipe.hydro.exact.impedance.planar_impact_state`.  A porous plate
(:mod:`impactpipe.hydro.eos.porosity`) starts at its bulk density rho0 / alpha0.
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.eos import reference_density
from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.problems.common import (ADAPTIVE_DEFAULTS, adaptive_mesh, adaptive_simulation, check_geometry,
                                              material_list, merged, strength_specs, tensile_strengths)
from impactpipe.hydro.eos.porosity import initial_distension
from impactpipe.hydro.problems.parameters import Parameter, Record, setup_defaults
from impactpipe.hydro.mesh.state import HydroState

#: Geometries this problem runs in.
GEOMETRIES = ('1d-planar',)

#: A plate.
SLAB = {
    "material": Parameter(kind=str, description="material name"),
    "thickness": Parameter(gt=0, units="m"),
    "velocity": Parameter(0.0, units="m/s"),
}

PARAMETERS = {
    "flyer": Record("Slab", SLAB, description="the moving plate",
                    example={"material": "basalt", "thickness": 1.0, "velocity": 2000.0}),
    "target": Record("Slab", SLAB, description="the plate at rest (its velocity is not used)",
                     example={"material": "basalt", "thickness": 1.0}),
    "margin": Parameter(0.25, ge=0, description="void on each side, as a fraction of the thicker plate's thickness"),
    "cells": Parameter(400, kind=int, ge=8, description="cells across the domain"),
    "end_time": Parameter(1.0e-4, gt=0, units="s", description="end of the run"),
}

#: What :func:`setup` takes for parameters a call leaves out.
DEFAULTS = {**setup_defaults(PARAMETERS), **ADAPTIVE_DEFAULTS}


def domain(p: dict) -> tuple[float, float]:
    """Domain ends (m) for merged parameters ``p``."""
    pad = p["margin"] * max(p["flyer"]["thickness"], p["target"]["thickness"])
    return -p["flyer"]["thickness"] - pad, p["target"]["thickness"] + pad


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "1d-planar", comm=None):
    """Build the planar-impact :class:`~impactpipe.hydro.solver.Simulation` (SI units).

    With ``comm`` (an MPI communicator; collective) the ranks build the run together, each
    setting its own blocks (:func:`~impactpipe.hydro.parallel.distributed.shared_simulation`), and
    the Simulation returned is this rank's share of it."""
    check_geometry("planar_impact", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    names, specs, eos = material_list(materials, [p["flyer"]["material"], p["target"]["material"]])
    lo, hi = domain(p)
    mesh = adaptive_mesh(geometry, [lo], [hi], [p["cells"]], [("outflow", "outflow")], block_cells, p["levels"])
    distension = [initial_distension(spec) for spec in specs]
    return adaptive_simulation(mesh, lambda m, blocks: initial_state(m, p, names, eos, distension, blocks), names,
                               specs, cfl, p["refinement"], comm=comm,
                               tensile_strength=tensile_strengths(materials, names),
                               strength=strength_specs(materials, names))


def initial_state(mesh: BlockMesh, p: dict, names: list[str], eos, distension=None,
                  blocks: slice = slice(None)) -> HydroState:
    """Both plates at their reference density (kg/m^3) with e = 0, the flyer at its ``velocity`` (m/s);
    each cell's volume fractions are the lengths of the plates inside it over its width.  A porous
    material (``distension[k]`` = alpha0 > 1) starts at its bulk density rho0 / alpha0.  In the
    blocks ``blocks`` of ``mesh``."""
    mesh = mesh.some_blocks(blocks)
    state = HydroState.empty(mesh, len(names))
    x = mesh.cell_centers()[:, 0]
    dx = mesh.block_dx[:, 0].reshape(-1, 1, 1, 1)
    edges_lo = x - 0.5 * dx
    edges_hi = x + 0.5 * dx

    def overlap(a, b):
        return np.clip((np.minimum(edges_hi, b) - np.maximum(edges_lo, a)) / dx, 0.0, 1.0)

    plates = (
        (p["flyer"], overlap(-p["flyer"]["thickness"], 0.0), p["flyer"]["velocity"]),
        (p["target"], overlap(0.0, p["target"]["thickness"]), 0.0),
    )
    for plate, frac, speed in plates:
        k = names.index(plate["material"])
        rho0 = float(reference_density(eos.kind[k], eos.params[k], eos.table))
        if distension is not None:
            rho0 /= distension[k]
        state.set_material(mesh, frac, k, eos, rho0, np.array([speed, 0.0, 0.0]), specific_energy=0.0)
    return state
