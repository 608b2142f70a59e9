"""The sweep's plain-pencil path (hydro.scheme.plain_pencils) against the general path it stands in for.

Each scene runs twice from the same start, once with ``Simulation.plain_pencils`` (the
default) and once with every pencil on the general path; the states, the floor counters and
amounts and the outflow must agree bit for bit (the plain path does the general path's
arithmetic, so a block face computed by a plain pencil on one side and a general one on
the other carries the same flux both ways, and conservation stays exact).  Without the plain path these tests pass trivially, so
the first test checks that the pencils of such scenes are classified as plain.
"""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS, BlockMesh, HydroState, Simulation
from impactpipe.hydro.mesh.boundary import fill_state_ghosts
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.scheme.plain_pencils import EMPTY_PENCIL, plain_material
from impactpipe.pipeline.presets import resolve_damage, resolve_strength

GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}
FIELDS = ("alpha", "arho", "arhoe", "arhoq", "momentum", "energy")


def smooth_gas_box():
    """64^2 periodic box of one ideal gas with a smooth density and shear flow."""
    mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [1.0, 1.0], [64, 64], [("periodic", "periodic")] * 2, 16)
    eos = pack_eos([GAS])
    c = mesh.cell_centers()
    x, y = c[:, 0], c[:, 1]
    rho = 1.0 + 0.3 * np.sin(2 * np.pi * x) * np.cos(2 * np.pi * y)
    vel = np.stack([0.3 + 0.2 * np.sin(2 * np.pi * y), -0.1 + 0.2 * np.cos(2 * np.pi * x), np.zeros_like(x)], axis=1)
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, eos, rho, vel, pressure=1.0)
    return Simulation(mesh, ["gas"], [GAS], state)


def heavy_sphere_3d():
    """24^3 periodic box of a light gas around a sphere of a heavy one, moving diagonally."""
    heavy = {"model": "ideal_gas", "gamma": 1.6, "cv": 300.0}
    mesh = BlockMesh.uniform("3d", [0.0] * 3, [1.0] * 3, [24] * 3, [("periodic", "periodic")] * 3, 8)
    eos = pack_eos([GAS, heavy])
    c = mesh.cell_centers()
    sphere = (((c - 0.5) ** 2).sum(axis=1) < 0.06).astype(float)
    vel = np.array([0.3, -0.2, 0.1])
    state = HydroState.empty(mesh, 2)
    state.set_material(mesh, 1.0 - sphere, 0, eos, 1.0, vel, pressure=1.0)
    state.set_material(mesh, sphere, 1, eos, 20.0, vel, pressure=1.0)
    return Simulation(mesh, ["gas", "heavy"], [GAS, heavy], state)


def sod_tube():
    return PROBLEMS["shock_tube"].setup({"cells": 200}, {"gas": {"eos": GAS}})


def strong_impact():
    """Basalt on basalt at 2 km/s in r-z with GEO strength: void, mixed cells, AMR, stress scalars."""
    materials = {"basalt": preset_material("basalt")}
    materials["basalt"]["strength"] = resolve_strength("geo", "strong", {})
    return PROBLEMS["impact"].setup(
        {"target": {"material": "basalt", "radius": 1000.0},
         "projectile": {"material": "basalt", "radius": 100.0, "velocity": 2000.0},
         "cells_per_projectile_radius": 4, "end_time": 1.0}, materials, block_cells=8)


def fracture_impact():
    """The same impact with Grady-Kipp fracture: flaws in every cell of the bodies, so the pencils
    inside the target at rest carry scalars that do not move, and those the shock reaches carry
    them with the mass."""
    materials = {"basalt": preset_material("basalt")}
    materials["basalt"]["strength"] = resolve_strength("geo", "strong", {})
    materials["basalt"]["strength"]["damage"] = resolve_damage({"model": "grady_kipp", "preset": "basalt"})
    return PROBLEMS["impact"].setup(
        {"target": {"material": "basalt", "radius": 1000.0},
         "projectile": {"material": "basalt", "radius": 100.0, "velocity": 2000.0},
         "cells_per_projectile_radius": 4, "end_time": 1.0}, materials, block_cells=8)


def iron_on_basalt():
    """1D iron flyer on a basalt plate at 3 km/s, void margins: two materials, each filling pencils."""
    materials = {"iron": preset_material("iron"), "basalt": preset_material("basalt")}
    return PROBLEMS["planar_impact"].setup(
        {"flyer": {"material": "iron", "thickness": 1.0, "velocity": 3000.0},
         "target": {"material": "basalt", "thickness": 1.0}, "cells": 200}, materials)


def copper_on_aluminium():
    """1D copper flyer on an aluminium plate at 2 km/s, void margins: Mie-Grueneisen materials,
    whose plain pencils gather through the EOS dispatcher rather than an in-place call."""
    copper = {"model": "mie_gruneisen", "rho0": 8930.0, "c0": 3940.0, "s": 1.489, "gamma0": 2.02, "cv": 385.0}
    aluminium = {"model": "mie_gruneisen", "rho0": 2790.0, "c0": 5330.0, "s": 1.34, "gamma0": 2.0, "cv": 897.0}
    return PROBLEMS["planar_impact"].setup(
        {"flyer": {"material": "copper", "thickness": 1.0, "velocity": 2000.0},
         "target": {"material": "aluminium", "thickness": 1.0}, "cells": 200},
        {"copper": {"eos": copper}, "aluminium": {"eos": aluminium}})


def pencil_kinds(sim):
    """(block, j1, j2, plain_material) of every pencil along x, after filling the x ghosts."""
    st = sim.state
    fill_state_ghosts(st, sim.mesh, 0)
    ny, nz = st.alpha.shape[3:]
    rows = [range(2, n - 2) if n > 1 else [0] for n in (ny, nz)]
    return [(b, j1, j2, kind(sim, b, j1, j2)) for b in range(st.alpha.shape[0]) for j1 in rows[0] for j2 in rows[1]]


def kind(sim, b, j1, j2=0):
    st = sim.state
    column = int(np.prod(st.alpha.shape[2:]))
    return plain_material(st.alpha, st.arho, st.arhoe, st.momentum, st.energy, b, 0, j1, j2,
                          st.alpha.shape[2], st.alpha.ravel(), st.arho.ravel(), st.arhoe.ravel(), column)


def test_pencils_are_classified_plain_empty_or_general():
    assert {k for *_, k in pencil_kinds(smooth_gas_box())} == {0}
    assert {k for *_, k in pencil_kinds(iron_on_basalt())} == {0, 1, -1, EMPTY_PENCIL}
    assert {k for *_, k in pencil_kinds(copper_on_aluminium())} == {0, 1, -1, EMPTY_PENCIL}
    assert {k for *_, k in pencil_kinds(heavy_sphere_3d())} == {0, 1, -1}
    sim = strong_impact()
    kinds = pencil_kinds(sim)
    assert {k for *_, k in kinds} == {0, -1, EMPTY_PENCIL}, "target, mixed and void pencils"
    st = sim.state
    b, j, _, _ = next(p for p in kinds if p[3] == 0)
    st.arho[b, 1, 5, j, 0] = 1e-300  # a trace of the other material in one cell
    assert kind(sim, b, j) == -1
    st.arho[b, 1, 5, j, 0] = 0.0
    st.alpha[b, 0, 0, j, 0] = 1.0 - 1e-7  # a ghost cell with void in it
    assert kind(sim, b, j) == -1
    b, j, _, _ = next(p for p in kinds if p[3] == EMPTY_PENCIL)
    st.momentum[b, 1, 7, j, 0] = 1e-30  # momentum without mass is not empty
    assert kind(sim, b, j) == -1


@pytest.mark.parametrize("build, steps", [(smooth_gas_box, 30), (sod_tube, 150), (iron_on_basalt, 150),
                                          (copper_on_aluminium, 150), (heavy_sphere_3d, 10), (strong_impact, 40),
                                          (fracture_impact, 40)],
                         ids=["smooth-gas-box", "sod", "iron-on-basalt", "copper-on-aluminium", "heavy-sphere-3d",
                              "impact-with-strength", "impact-with-fracture"])
def test_plain_path_gives_the_general_paths_answer_bit_for_bit(build, steps):
    runs = []
    for plain in (True, False):
        sim = build()
        sim.plain_pencils = plain
        for _ in range(steps):
            sim.step()
        runs.append(sim)
    fast, general = runs
    assert fast.time == general.time
    assert fast.mesh.nblocks == general.mesh.nblocks
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(fast.state, name), getattr(general.state, name), err_msg=name)
    assert fast.floor_counts == general.floor_counts
    assert fast.floor_amounts == general.floor_amounts
    np.testing.assert_array_equal(fast.boundary, general.boundary)
