"""A uniform sphere held together by its own gravity, in hydrostatic equilibrium, at rest.

The body (``body``: material and radius R, m) is centred at the origin at its reference
density rho0 with the internal energy that gives its EOS the lithostatic pressure of a
uniform self-gravitating sphere (:func:`~impactpipe.hydro.problems.impact.lithostatic_pressure`),

    p(r) = (2 pi / 3) G rho0^2 (R^2 - r^2),

void around it, and its self-gravity on (:class:`~impactpipe.hydro.self_gravity.SelfGravity`,
expansion ``order``).  The exact solution is the initial state: the body stays at rest, its
surface speed bounded by its escape speed v_esc = R sqrt(8 pi G rho0 / 3) times the
discretisation error (docs/hydro.md, "Self-gravity").

A porous material (epsilon-alpha, :mod:`impactpipe.hydro.eos.porosity`) starts at its bulk
density rho0 = rho_s0 / alpha_0 and distension alpha_0, unstrained, with the internal energy
e that solves P_s(rho_s0, e) / alpha_0 = p(r) (:func:`~impactpipe.hydro.problems.impact.set_lithostatic_sphere`;
docs/eos.md, "Self-gravity on a porous body"): its distension, too, stays alpha_0.

2d-cylindrical: (r, z) on [0, L] x [-L, L]; 3d: the half y >= 0 of [-L, L]^3 with a reflecting
plane at y = 0 (the gravity counts the mirror half).  L = R + ``margin_cells`` cells, rounded
up to whole blocks; ``cells_per_radius`` cells of the finest level span R.
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.eos import reference_density
from impactpipe.hydro.mesh.blocks import DEFAULT_BLOCK_CELLS, BlockMesh
from impactpipe.hydro.eos.porosity import initial_distension
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.problems.common import (ADAPTIVE_DEFAULTS, adaptive_mesh, adaptive_simulation, check_geometry,
                                              material_list, merged, root_cell_multiple, strength_specs,
                                              tensile_strengths)
from impactpipe.hydro.problems.impact import set_lithostatic_sphere, sphere_fraction
from impactpipe.hydro.problems.parameters import Parameter, Record, setup_defaults
from impactpipe.hydro.self_gravity import DEFAULT_ORDER, SelfGravity

#: Geometries this problem runs in.
GEOMETRIES = ("2d-cylindrical", "3d")

PARAMETERS = {
    "body": Record("Body", {
        "material": Parameter(kind=str, description="material name"),
        "radius": Parameter(gt=0, units="m"),
    }, description="the sphere, centred at the origin", example={"material": "basalt", "radius": 50.0e3}),
    "cells_per_radius": Parameter(32, kind=int, ge=4, description="finest cells across the radius"),
    "margin_cells": Parameter(8, kind=int, ge=2, description="cells of void beyond the surface"),
    "order": Parameter(DEFAULT_ORDER, kind=int, ge=0, le=16, description="order of the gravity's multipole expansion"),
    "end_time": Parameter(16.0, gt=0, units="s", description="end of the run"),
}

#: What :func:`setup` takes for parameters a call leaves out (``levels``, ``refinement``: the
#: adaptive mesh, parameters of ``setup`` only).
DEFAULTS = {**setup_defaults(PARAMETERS), **ADAPTIVE_DEFAULTS}


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "2d-cylindrical", comm=None):
    """Build the :class:`~impactpipe.hydro.solver.Simulation` of the module docstring (SI units).

    With ``comm`` (an MPI communicator; collective) the ranks build the run together, each
    setting its own blocks (:func:`~impactpipe.hydro.parallel.distributed.shared_simulation`), and
    the Simulation returned is this rank's share of it."""
    check_geometry("hydrostatic_body", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    body = p["body"]
    names, specs, eos = material_list(materials, [body["material"]])
    ndim = 2 if geometry == "2d-cylindrical" else 3
    block = int(block_cells or DEFAULT_BLOCK_CELLS[ndim])
    multiple = root_cell_multiple(block, p["levels"])
    dx = body["radius"] / p["cells_per_radius"]
    n = int(np.ceil((p["cells_per_radius"] + p["margin_cells"]) / multiple)) * multiple
    side = n * dx
    if geometry == "2d-cylindrical":
        lo, hi, cells = [0.0, -side], [side, side], [n, 2 * n]
        boundaries = [("reflecting", "outflow"), ("outflow", "outflow")]
    else:
        lo, hi, cells = [-side, 0.0, -side], [side, side, side], [2 * n, n, 2 * n]
        boundaries = [("outflow", "outflow"), ("reflecting", "outflow"), ("outflow", "outflow")]
    mesh = adaptive_mesh(geometry, lo, hi, cells, boundaries, block_cells, p["levels"])
    distension = initial_distension(specs[0])
    rho0 = float(reference_density(eos.kind[0], eos.params[0], eos.table)) / distension
    gravity = SelfGravity(mesh, order=p["order"], mirror_y=geometry == "3d")
    return adaptive_simulation(mesh, lambda m, blocks: initial_state(m, eos, rho0, body["radius"], distension, blocks),
                               names, specs, cfl, p["refinement"], comm=comm, tensile_strength=tensile_strengths(materials, names),
                               strength=strength_specs(materials, names), gravity=gravity)


def initial_state(mesh: BlockMesh, eos, density: float, radius: float, distension: float = 1.0,
                  blocks: slice = slice(None)) -> HydroState:
    """The sphere of ``radius`` (m) at bulk ``density`` (kg/m^3), ``distension`` (-) and the
    lithostatic pressure, at rest, in the blocks ``blocks`` of ``mesh``."""
    mesh = mesh.some_blocks(blocks)
    state = HydroState.empty(mesh, 1)
    fill = sphere_fraction(mesh, (0.0, 0.0, 0.0), radius, 4)
    set_lithostatic_sphere(state, mesh, fill, 0, eos, density, radius, distension)
    return state
