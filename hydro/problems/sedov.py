"""Sedov-Taylor point blast: ``energy`` (J, the whole sphere) released at the origin.

2d-cylindrical (r, z) on [0, extent]^2 with the z = 0 plane reflecting (the domain holds
half the sphere, energy / 2) or 3d on the octant [0, extent]^3 with reflecting planes
(energy / 8).  The energy is spread uniformly (per volume) over the cells whose centres lie
within ``deposit_cells`` finest cell sizes of the origin, in an ambient ideal gas at ``density``
and ``pressure``.  Exact solution: :func:`impactpipe.hydro.exact.sedov.sedov_solution`
with nu = 3 (a spherical blast in both geometries).

``cells`` is the number of cells per axis at the finest level.  With ``levels`` > 1 the mesh
is adaptive (:func:`~impactpipe.hydro.problems.common.adaptive_mesh`): the root level has
cells / 2^(levels - 1) cells per axis, the blocks around the source start at the finest
level (the deposit may be smaller than a root cell) and the rest refines where
``refinement`` (the ``hydro.refinement`` keys of
:class:`~impactpipe.hydro.amr.regrid.RefinementRule`) flags the initial state and, later,
the blast.
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.eos import energy_from_pressure
from impactpipe.hydro.problems.common import (ADAPTIVE_DEFAULTS, adaptive_mesh, adaptive_simulation, check_geometry,
                                              material_list, merged)
from impactpipe.hydro.problems.parameters import Parameter, Record, setup_defaults
from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.mesh.state import HydroState

#: Geometries this problem runs in.
GEOMETRIES = ('2d-cylindrical', '3d')

PARAMETERS = {
    "energy": Parameter(gt=0, units="J", description="blast energy of the whole sphere", example=1.0),
    "ambient": Record("AmbientState", {
        "material": Parameter(kind=str, description="material name"),
        "density": Parameter(gt=0, units="kg/m^3"),
        "pressure": Parameter(ge=0, units="Pa"),
    }, description="the medium at rest", example={"material": "gas", "density": 1.0, "pressure": 1.0e-6}),
    "extent": Parameter(1.0, gt=0, units="m", description="domain extent from the origin"),
    "cells": Parameter(128, kind=int, ge=8, description="cells along each axis"),
    "deposit_cells": Parameter(3.5, gt=0, description="radius of the energy deposit in cells"),
    "end_time": Parameter(0.3, gt=0, units="s", description="end of the run"),
}

#: What :func:`setup` takes for parameters a call leaves out; ``levels`` and ``refinement``
#: (the adaptive mesh of the module docstring) are parameters of ``setup`` only, not of a scene.
DEFAULTS = {**setup_defaults(PARAMETERS), **ADAPTIVE_DEFAULTS}


def setup(params: dict, materials: dict[str, dict], block_cells: int | None = None, cfl: float = 0.4,
          geometry: str = "2d-cylindrical", comm=None):
    """Build the Sedov :class:`~impactpipe.hydro.solver.Simulation` (SI units).

    With ``comm`` (an MPI communicator; collective) the ranks build the run together, each
    setting its own blocks (:func:`~impactpipe.hydro.parallel.distributed.shared_simulation`), and
    the Simulation returned is this rank's share of it."""
    check_geometry("sedov", GEOMETRIES, geometry)
    p = merged(DEFAULTS, params)
    names, specs, eos = material_list(materials, [p["ambient"]["material"]])
    ndim = 2 if geometry == "2d-cylindrical" else 3
    mesh = adaptive_mesh(geometry, [0.0] * ndim, [p["extent"]] * ndim, [p["cells"]] * ndim,
                         [("reflecting", "outflow")] * ndim, block_cells, p["levels"])
    source = (p["deposit_cells"] + 2) * p["extent"] / p["cells"]
    finest = mesh.max_level
    return adaptive_simulation(mesh, lambda m, blocks: initial_state(m, p, eos, blocks), names, specs, cfl,
                               p["refinement"],
                               lambda m: np.where((m.block_lo[:, :ndim] < source).all(axis=1), finest, 0),
                               comm=comm)


def initial_state(mesh: BlockMesh, p: dict, eos, blocks: slice = slice(None)) -> HydroState:
    """The ambient gas at rest with ``energy`` (J, of the whole sphere) in the cells within the
    deposit, in the blocks ``blocks`` of ``mesh``.

    The deposit holds the cells whose centres lie within ``deposit_cells`` finest cell sizes
    (extent / cells, m) of the origin; the domain holds the share 1/2 (2d-cylindrical) or 1/8
    (3d) of the sphere's energy, spread uniformly per volume over them (the volume summed over
    the whole mesh's deposit, :func:`deposit_volume`).
    """
    amb = p["ambient"]
    share = 0.5 if mesh.geometry == "2d-cylindrical" else 0.125
    deposit = p["deposit_cells"] * p["extent"] / p["cells"]
    e_amb = energy_from_pressure(eos.kind[0], eos.params[0], eos.table, amb["density"], amb["pressure"])
    e_hot = e_amb + share * p["energy"] / (amb["density"] * deposit_volume(mesh, deposit))
    some = mesh.some_blocks(blocks)
    state = HydroState.empty(some, 1)
    state.set_material(some, 1.0, 0, eos, amb["density"], np.zeros(3),
                       specific_energy=np.where(hot_cells(some, deposit), e_hot, e_amb))
    return state


def hot_cells(mesh: BlockMesh, deposit: float) -> np.ndarray:
    """(NB, nx, ny, nz) True for the cells whose centre lies within ``deposit`` (m) of the origin."""
    return np.sqrt((mesh.cell_centers()[:, :mesh.ndim] ** 2).sum(axis=1)) < deposit


def deposit_volume(mesh: BlockMesh, deposit: float) -> float:
    """The summed volume (m^3) of ``mesh``'s cells whose centre lies within ``deposit`` (m) of the
    origin, in block order: the blocks whose lower corner lies within ``deposit`` along every axis
    hold all of them (the domain starts at the origin)."""
    near = mesh.some_blocks(np.flatnonzero((mesh.block_lo[:, :mesh.ndim] < deposit).all(axis=1)))
    return float(near.cell_volumes()[hot_cells(near, deposit)].sum())
