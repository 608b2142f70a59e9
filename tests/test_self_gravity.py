"""Self-gravity in the hydro stage: the multipole potential against exact ones, a body in
hydrostatic equilibrium at rest (solid and porous), energy with the potential conserved,
bit-for-bit sums."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from impactpipe.hydro.eos import pack_eos, reference_density
from impactpipe.hydro.eos.porosity import distension_slot
from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.problems import PROBLEMS
from impactpipe.hydro.problems.impact import lithostatic_pressure, sphere_fraction
from impactpipe.hydro.self_gravity import G, SelfGravity
from impactpipe.hydro.solver import Simulation
from impactpipe.pipeline.presets import resolve_eos, resolve_porosity, resolve_strength

BASALT = resolve_eos("tillotson", "basalt", {})


def body_mesh(geometry: str, cells_per_radius: int, radius: float, half: bool = True) -> BlockMesh:
    """A uniform mesh around a body of ``radius`` (m) centred at the origin, 8 cells of margin:
    r-z, or 3d (the y >= 0 half with a reflecting plane, or the full box)."""
    dx = radius / cells_per_radius
    block = 16 if geometry == "2d-cylindrical" else 8
    n = int(np.ceil((radius + 8 * dx) / dx / block)) * block
    side = n * dx
    if geometry == "2d-cylindrical":
        return BlockMesh.uniform(geometry, [0.0, -side], [side, side], [n, 2 * n],
                                 [("reflecting", "outflow"), ("outflow", "outflow")], block_cells=block)
    y_lo, ny, y_bc = (0.0, n, ("reflecting", "outflow")) if half else (-side, 2 * n, ("outflow", "outflow"))
    return BlockMesh.uniform(geometry, [-side, y_lo, -side], [side, side, side], [2 * n, ny, 2 * n],
                             [("outflow", "outflow"), y_bc, ("outflow", "outflow")], block_cells=block)


def spheres_state(mesh: BlockMesh, spheres, density: float = 2700.0) -> HydroState:
    """Void with uniform spheres ((centre (3,), radius) in m; centres on the axis in r-z) of ``density``."""
    eos = pack_eos([BASALT])
    state = HydroState.empty(mesh, 1)
    fill = np.zeros((mesh.nblocks,) + mesh.interior_shape)
    for centre, radius in spheres:
        centre = centre if mesh.geometry == "3d" else (0.0, centre[2])
        fill = np.maximum(fill, sphere_fraction(mesh, centre, radius, 4))
    state.set_material(mesh, fill, 0, eos, density, np.zeros(3), specific_energy=0.0)
    return state


def sphere_potential(distance, radius: float, mass: float):
    """Exact potential (J/kg) of a uniform sphere: -G M (3 R^2 - r^2) / (2 R^3) inside, -G M / r outside."""
    r = np.asarray(distance)
    return np.where(r < radius, -G * mass * (3 * radius ** 2 - r ** 2) / (2 * radius ** 3), -G * mass / r)


def distances(mesh: BlockMesh, centre) -> np.ndarray:
    c = mesh.cell_centers()
    if mesh.geometry == "2d-cylindrical":
        return np.sqrt(c[:, 0] ** 2 + (c[:, 1] - centre[2]) ** 2)
    return np.sqrt(sum((c[:, d] - centre[d]) ** 2 for d in range(3)))


def potential(mesh, state, order=4, half=False) -> np.ndarray:
    gravity = SelfGravity(mesh, order=order, mirror_y=half)
    gravity.prepare(state, mesh)
    return gravity.potential(mesh)


@pytest.mark.parametrize("geometry, cells", [("2d-cylindrical", 32), ("3d", 16)])
def test_uniform_sphere_potential_within_one_percent_inside_and_outside(geometry, cells):
    radius, density = 1.0e3, 2700.0
    centre = (0.0, 0.0, 0.1 * radius)  # off the mesh's origin: the expansion centre is found
    mesh = body_mesh(geometry, cells, 1.3 * radius, half=False)
    state = spheres_state(mesh, [(centre, radius)], density)
    phi = potential(mesh, state)
    r = distances(mesh, centre)
    exact = sphere_potential(r, radius, 4.0 / 3.0 * np.pi * radius ** 3 * density)
    evaluated = phi != 0.0  # the blocks that hold mass (the kicks need no more)
    error = np.abs(phi / exact - 1.0)
    assert error[r < radius].max() < 0.01
    assert (evaluated & (r > 1.05 * radius)).sum() > 100
    assert error[evaluated & (r > radius)].max() < 0.01


def test_two_bodies_converge_with_the_expansion_order():
    """A target and a projectile touching it (r-z): the error of the monopole falls with L."""
    target, projectile = ((0.0, 0.0, 0.0), 1.0e3), ((0.0, 0.0, 1.2e3), 0.25e3)
    mesh = body_mesh("2d-cylindrical", 32, 1.5e3)
    state = spheres_state(mesh, [target, projectile])
    exact = sum(sphere_potential(distances(mesh, c), radius, 4.0 / 3.0 * np.pi * radius ** 3 * 2700.0)
                for c, radius in (target, projectile))
    inside = distances(mesh, target[0]) < target[1]
    mean_error = [np.abs(potential(mesh, state, order) / exact - 1.0)[inside].mean() for order in (0, 4, 8)]
    assert mean_error[0] > mean_error[1] > mean_error[2]
    assert mean_error[2] < 0.3 * mean_error[0]
    assert np.abs(potential(mesh, state, 8) / exact - 1.0)[inside].max() < 0.025


def test_the_half_domain_gives_the_whole_body_potential():
    bodies = [((0.0, 0.0, 0.0), 1.0e3), ((0.5e3, 0.0, 1.1e3), 0.25e3)]  # off the z axis: m > 0 terms
    full_mesh = body_mesh("3d", 8, 1.4e3, half=False)
    half_mesh = body_mesh("3d", 8, 1.4e3, half=True)
    full = potential(full_mesh, spheres_state(full_mesh, bodies))
    half = potential(half_mesh, spheres_state(half_mesh, bodies), half=True)
    upper = full_mesh.block_lo[:, 1] >= 0.0
    order = np.lexsort(full_mesh.block_lo[upper].T)
    np.testing.assert_allclose(full[upper][order], half[np.lexsort(half_mesh.block_lo.T)], rtol=1e-12)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two numba threads")
def test_the_potential_does_not_depend_on_the_thread_count():
    mesh = body_mesh("3d", 8, 1.2e3)
    state = spheres_state(mesh, [((0.0, 0.0, 0.0), 1.0e3), ((0.3e3, 0.0, 1.1e3), 0.2e3)])
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = potential(mesh, state, half=True)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        many = potential(mesh, state, half=True)
    finally:
        numba.set_num_threads(threads)
    assert one.tobytes() == many.tobytes()


def hydrostatic_body(geometry: str, cells_per_radius: int, radius: float = 50.0e3) -> Simulation:
    """The hydrostatic_body problem: a strengthless basalt sphere at rest, lithostatic pressure."""
    params = {"body": {"material": "basalt", "radius": radius}, "cells_per_radius": cells_per_radius}
    return PROBLEMS["hydrostatic_body"].setup(params, {"basalt": {"eos": BASALT}}, geometry=geometry)


def test_a_body_in_hydrostatic_equilibrium_stays_at_rest_and_conserves_energy_with_its_potential():
    """A 50 km basalt body in r-z, 64 cells per radius, over one sound-crossing time R / c."""
    radius = 50.0e3
    sim = hydrostatic_body("2d-cylindrical", 64, radius)
    mesh, state = sim.mesh, sim.state
    rho0 = 2700.0
    escape_speed = np.sqrt(8.0 * np.pi * G * rho0 / 3.0) * radius
    crossing = radius / np.sqrt(26.7e9 / rho0)
    energy0 = sim.totals()["energy"]
    sim.step()
    potential0, energy1 = sim.gravity.potential_energy, sim.totals()["energy"]
    fastest = inside = 0.0
    r = distances(mesh, (0.0, 0.0, 0.0))
    while sim.time < crossing:
        sim.step()
        rho = mesh.interior(state.arho).sum(axis=1)
        speed = np.linalg.norm(mesh.interior(state.momentum), axis=1) / np.where(rho > 0.0, rho, 1.0)
        fastest = max(fastest, speed[rho > 0.5 * rho0].max())
        inside = max(inside, speed[(rho > 0.5 * rho0) & (r < 0.95 * radius)].max())
    assert fastest < 1.0e-3 * escape_speed
    assert inside < 5.0e-4 * escape_speed
    totals = sim.totals()
    drift = (totals["energy"] + sim.gravity.potential_energy) - (energy1 + potential0)
    assert abs(drift) < 1.0e-6 * abs(potential0)
    assert sim.gravity.work == pytest.approx(totals["energy"] - energy0, rel=1e-3)


#: Compaction parameters (and strength) of the porous hydrostatic body (alpha_0 = 1.5), with the
#: largest relative change of its distension the test allows over a sound-crossing time: the
#: `basalt` preset (eps_e = -1.88e-7, kappa = 0.86), whose elastic limit the scheme's small strains
#: at the surface pass (4.1e-6 measured at 32 cells per radius), without and with the GEO `weak`
#: strength of configs/large_body/porous.yaml, and the set of configs/porous/case9_porous.yaml
#: (eps_e = -1e-5), which they do not pass (2.3e-15, round-off).
POROUS_BODIES = [
    ({"preset": "basalt", "alpha0": 1.5}, None, 1.0e-5),
    ({"preset": "basalt", "alpha0": 1.5}, resolve_strength("geo", "weak", {}), 1.0e-5),
    ({"alpha0": 1.5, "eps_e": -1.0e-5, "kappa": 0.98, "alpha_x": 1.0}, None, 1.0e-12),
]


@pytest.mark.parametrize("porosity, strength, distension_tolerance", POROUS_BODIES)
def test_a_porous_body_in_hydrostatic_equilibrium_stays_at_rest_and_unstrained(porosity, strength,
                                                                                distension_tolerance):
    """A 50 km porous basalt body (alpha_0 = 1.5, bulk density 1800 kg/m^3) in r-z, 32 cells per
    radius, over one sound-crossing time R / c_s0: its initial porous pressure P_s(alpha_0 rho, e) /
    alpha_0 is the lithostatic one, it stays at rest (speeds below 1e-3 of v_esc, 5e-4 inside 0.95 R)
    and keeps its distension (docs/eos.md, "Self-gravity on a porous body";
    benchmarks/porous_hydrostatic_body.py)."""
    radius, alpha0 = 50.0e3, 1.5
    rho0 = 2700.0 / alpha0
    material = {"eos": BASALT, "porosity": resolve_porosity(porosity)}
    if strength is not None:
        material["strength"] = strength
    params = {"body": {"material": "porous_basalt", "radius": radius}, "cells_per_radius": 32}
    sim = PROBLEMS["hydrostatic_body"].setup(params, {"porous_basalt": material})
    mesh, state = sim.mesh, sim.state
    r = distances(mesh, (0.0, 0.0, 0.0))
    snap = sim.snapshot()
    fill = snap.volume_fraction[:, 0]
    body = fill > 0.0
    exact = lithostatic_pressure(rho0, radius, r)
    pressure_error = np.abs(snap.pressure[body] / fill[body] - exact[body]).max()
    assert pressure_error < 1.0e-10 * lithostatic_pressure(rho0, radius, 0.0)
    assert np.abs(snap.extra["distension"][body] / alpha0 - 1.0).max() < 1.0e-15
    escape_speed = np.sqrt(8.0 * np.pi * G * rho0 / 3.0) * radius
    crossing = radius / np.sqrt(26.7e9 / 2700.0)
    sim.step()
    start = sim.totals()["energy"] + sim.gravity.potential_energy
    fastest = inside = change = 0.0
    slot = distension_slot(state.arhoq.shape[1])
    while sim.time < crossing:
        sim.step()
        rho = mesh.interior(state.arho).sum(axis=1)
        full = rho > 0.5 * rho0
        speed = np.linalg.norm(mesh.interior(state.momentum), axis=1) / np.where(rho > 0.0, rho, 1.0)
        distension = mesh.interior(state.arhoq)[:, slot] / np.where(rho > 0.0, rho, 1.0)
        fastest = max(fastest, speed[full].max())
        inside = max(inside, speed[full & (r < 0.95 * radius)].max())
        change = max(change, np.abs(distension[full] / alpha0 - 1.0).max())
    assert fastest < 1.0e-3 * escape_speed
    assert inside < 5.0e-4 * escape_speed
    assert change < distension_tolerance
    drift = sim.totals()["energy"] + sim.gravity.potential_energy - start
    assert abs(drift) < 1.0e-6 * abs(sim.gravity.potential_energy)
