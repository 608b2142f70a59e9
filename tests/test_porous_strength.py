"""Strength of porous rock (docs/strength.md, "Porous materials"): the matrix's yield curve at the matrix
pressure alpha p spread over the bulk, Y = Y_s(alpha p) / alpha; the shear modulus from the porous bulk
modulus rho c_s^2 h(alpha)^2; the tensile limit of the matrix, P_s >= -Y_T; a porous body with strength
at rest stays at rest."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from impactpipe.hydro import BlockMesh, HydroState, Simulation
from impactpipe.hydro.eos import energy_from_pressure, pack_eos, pressure_sound_speed, temperature
from impactpipe.hydro.eos.porosity import pack_porosity, wave_speed_ratio
from impactpipe.hydro.mesh.blocks import GHOST
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.problems.impact import sphere_fraction
from impactpipe.hydro.strength import MaterialStrength, pack_strength
from impactpipe.hydro.strength.parameters import GEO
from impactpipe.hydro.strength.update import CNT_TENSILE_FAILURE, CNT_YIELD, WK_PHI
from impactpipe.hydro.strength.yield_strength import equivalent_yield_stress, yield_strength
from impactpipe.hydro.parallel.distributed import WholeMesh
from impactpipe.pipeline.presets import resolve_strength

BASALT = preset_material("basalt")["eos"]
WEAK = resolve_strength("geo", "weak", {})
ALPHA0 = 1.5


def porous_spec(chi=0.5):
    return {**BASALT, "porosity": {"alpha0": ALPHA0, "eps_e": -2.0e-3, "kappa": 0.98, "alpha_x": 1.0, "chi": chi}}


def matrix_density(pressure):
    """The basalt matrix density (kg/m^3) where P_s(rho, e = 0) = ``pressure`` (Pa)."""
    eos = pack_eos([BASALT])
    return brentq(lambda r: pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, r, 0.0)[0] - pressure,
                  0.99 * BASALT["rho0"], 1.01 * BASALT["rho0"], xtol=1e-12)


def shear_cell_run(matrix_pressure, shear_rate, steps, dt=1.0e-6, chi=0.5):
    """A uniform porous basalt block (alpha = alpha0, matrix at ``matrix_pressure``, e = 0) sheared at
    v_x = ``shear_rate`` y for ``steps`` strength steps of ``dt`` (velocities held, as the rotation test
    of tests/test_strength_rest_and_rotation.py does).  Returns (mesh, state, strength, eos, rows, the centre
    cell's S_xy after the first step, its specific energy before the last step: the state its yield saw)."""
    spec = porous_spec(chi)
    mesh = BlockMesh.uniform("2d-planar", [-1.0, -1.0], [1.0, 1.0], [16, 16], [("outflow", "outflow")] * 2, 16)
    eos = pack_eos([spec])
    rows = pack_porosity([spec], eos)
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, eos, matrix_density(matrix_pressure) / ALPHA0, np.zeros(3), specific_energy=0.0)
    strength = MaterialStrength(pack_strength([WEAK]), mesh, 1, porosity=rows)
    strength.prepare_state(state, WholeMesh())
    nq = strength.nq
    state.arhoq[:, nq - 2] = ALPHA0 * state.arho[:, 0]
    xs = (np.arange(16 + 2 * GHOST) - GHOST + 0.5) * 0.125 - 1.0
    first = last_energy = None
    strength.has_mass[:] = 1
    for _ in range(steps):
        last_energy = mesh.interior(state.arhoe)[0, 0, 8, 8, 0] / mesh.interior(state.arho)[0, 0, 8, 8, 0]
        strength.work[:] = 0.0
        strength.work[0, 0, :, :, 0] = shear_rate * xs[None, :]
        strength.work[0, WK_PHI] = 1.0
        strength.stress_step(state, dt, eos, np.arange(mesh.nblocks))
        if first is None:
            first = mesh.interior(state.arhoq)[0, 3, 8, 8, 0] / mesh.interior(state.arho)[0, 0, 8, 8, 0]
    return mesh, state, strength, eos, rows, first, last_energy


def cell_state(mesh, state, eos, nq):
    """(bulk density, specific energy, distension, matrix pressure, matrix c^2) of the centre cell."""
    ar = mesh.interior(state.arho)[0, 0, 8, 8, 0]
    rho = ar / mesh.interior(state.alpha)[0, 0, 8, 8, 0]
    e = mesh.interior(state.arhoe)[0, 0, 8, 8, 0] / ar
    dist = mesh.interior(state.arhoq)[0, nq - 2, 8, 8, 0] / ar
    p_s, c2, _ = pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, dist * rho, e)
    return rho, e, dist, p_s, c2


def test_porous_shear_modulus_follows_the_porous_wave_speed():
    """One step of shear from S = 0: S_xy = G gamma_dot dt with G = (G/K) rho c_s^2(alpha rho) h(alpha)^2
    (Collins et al. 2011's elastic wave speed c = h c_s; h = chi at alpha0): a quarter of the frozen-alpha
    value for chi = 0.5."""
    rate, dt = 10.0, 1.0e-7
    mesh, state, strength, eos, rows, first, _ = shear_cell_run(2.0e7, rate, 1, dt=dt)
    rho, e, dist, p_s, c2 = cell_state(mesh, state, eos, strength.nq)
    assert dist == ALPHA0 and wave_speed_ratio(rows[0], dist) == 0.5
    ratio = strength.arrays.shear[0, 1]
    expected = ratio * rho * c2 * 0.25
    assert first == pytest.approx(expected * rate * dt, rel=1e-9)
    assert strength.counts[:, CNT_YIELD].sum() == 0


def test_porous_yield_surface_is_the_matrix_curve_at_matrix_pressure_over_alpha():
    """Sheared past yield, the porous material's von Mises stress sits at Y_s(alpha p, T) / alpha (GEO weak,
    matrix pressure 20 MPa, alpha = 1.5): 4.8 MPa against 6.4 MPa for the solid curve at the bulk pressure p."""
    mesh, state, strength, eos, rows, _, e = shear_cell_run(2.0e7, 1.0e3, 60)
    assert strength.counts[:, CNT_YIELD].sum() > 0
    nq = strength.nq
    rho, _, dist, _, _ = cell_state(mesh, state, eos, nq)
    p_s = pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, dist * rho, e)[0]
    ar = mesh.interior(state.arho)[0, 0, 8, 8, 0]
    s = mesh.interior(state.arhoq)[0, :4, 8, 8, 0] / ar
    von_mises = math.sqrt(1.5 * (s[0] ** 2 + s[1] ** 2 + s[2] ** 2 + 2.0 * s[3] ** 2))
    params = strength.arrays.params[0]
    t = temperature(eos.kind[0], eos.params[0], eos.table, dist * rho, e)
    porous = equivalent_yield_stress(GEO, yield_strength(GEO, params, p_s, t, 0.0)) / dist
    solid_at_bulk = equivalent_yield_stress(GEO, yield_strength(GEO, params, p_s / dist, t, 0.0))
    assert von_mises == pytest.approx(porous, rel=1e-10)
    assert abs(von_mises / solid_at_bulk - 1.0) > 0.2


@pytest.mark.parametrize("share, fails", [(1.2, True), (0.8, False)])
def test_porous_tensile_strength_is_the_matrix_one(share, fails):
    """The matrix at P_s = -share Y_T: fails in tension for share 1.2 although the bulk tension P_s / alpha =
    -0.8 Y_T is below Y_T, holds for share 0.8."""
    mesh, state, strength, eos, rows, _, _ = shear_cell_run(-share * WEAK["Y_T"], 0.0, 1)
    cells = int(np.prod(mesh.interior_shape)) * mesh.nblocks
    nq = strength.nq
    damage = mesh.interior(state.arhoq)[:, nq - 1] / mesh.interior(state.arho)[:, 0]
    assert strength.counts[:, CNT_TENSILE_FAILURE].sum() == (cells if fails else 0)
    assert (damage == (1.0 if fails else 0.0)).all()


def test_porous_body_with_strength_at_rest_stays_at_rest():
    """A porous basalt disc (alpha0 = 1.5, chi = 0.5, GEO weak) in water, both at 1 MPa (the matrix at
    alpha0 times that), periodic 32^2 box: over a crossing of the box at the porous wave speed the speeds stay
    below 1e-8 of the sound speed, the pressure within 1e-8, no yield and no compaction."""
    spec = porous_spec()
    water = preset_material("water")["eos"]
    mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [1.0, 1.0], [32, 32], [("periodic", "periodic")] * 2, 16)
    eos = pack_eos([spec, water])
    frac = sphere_fraction(mesh, (0.5, 0.5), 0.3, 8)
    pressure = 1.0e6
    e_matrix = energy_from_pressure(eos.kind[0], eos.params[0], eos.table, BASALT["rho0"], ALPHA0 * pressure)
    state = HydroState.empty(mesh, 2)
    state.set_material(mesh, 1.0, 1, eos, water["rho0"], np.zeros(3), pressure=pressure)
    state.set_material(mesh, frac, 0, eos, BASALT["rho0"] / ALPHA0, np.zeros(3), specific_energy=e_matrix)
    sim = Simulation(mesh, ["porous_basalt", "water"], [spec, water], state, strength=[WEAK, None])
    c_s0 = pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, BASALT["rho0"], 0.0)[1] ** 0.5
    sim.run(1.0 / (0.5 * c_s0))
    snap = sim.snapshot()
    assert sim.step_count > 20
    assert np.abs(snap.velocity).max() < 1e-8 * snap.sound_speed.max()
    assert np.abs(snap.pressure / pressure - 1.0).max() < 1e-8
    assert np.abs(snap.extra["von_mises_stress"]).max() < 1e-8 * pressure
    assert sim.floor_counts["yield_return"] == 0
    dist = snap.extra["distension"]
    assert dist[frac.reshape(dist.shape) > 0.5].min() == pytest.approx(ALPHA0, rel=1e-12)
