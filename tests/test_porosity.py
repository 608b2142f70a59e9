"""Porous materials (epsilon-alpha model, hydro.eos.porosity): the compaction curve, the packing
checks, the porous Hugoniot against the analytic one of the solid EOS, and conservation."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from impactpipe.hydro import BlockMesh, HydroState, Simulation
from impactpipe.hydro.budget import conservation_budget
from impactpipe.hydro.eos import pack_eos, pressure_sound_speed
from impactpipe.hydro.exact import porous_hugoniot, two_wave_speeds
from impactpipe.hydro.eos.porosity import ALPHA0, EPS_C, EPS_X, RHO00, distension_of_strain, pack_porosity
from impactpipe.hydro.problems import porous_slab
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.scheme.mixture import material_state

BASALT = preset_material("basalt")["eos"]
COMPACTION = {"eps_e": -1.0e-5, "kappa": 0.98}


def porous_basalt(alpha0, alpha_x=1.0):
    return {**BASALT, "porosity": {"alpha0": alpha0, "alpha_x": alpha_x, **COMPACTION}}


def test_compaction_curve_is_continuous_and_monotone():
    """alpha(eps_v) runs from alpha0 to 1, continuous with a continuous slope at eps_x (power-law branch)."""
    spec = porous_basalt(2.0, alpha_x=1.3)
    row = pack_porosity([spec], pack_eos([spec]))[0]
    assert row[ALPHA0] == 2.0 and row[RHO00] == pytest.approx(BASALT["rho0"] / 2.0)
    assert distension_of_strain(row, 0.0) == 2.0
    assert distension_of_strain(row, -0.5e-5) == 2.0
    assert distension_of_strain(row, row[EPS_X]) == pytest.approx(1.3, rel=1e-12)
    assert distension_of_strain(row, row[EPS_C] - 1e-3) == 1.0
    h = 1e-7
    for eps in (row[EPS_X], row[EPS_C]):
        left = (distension_of_strain(row, eps) - distension_of_strain(row, eps - h)) / h
        right = (distension_of_strain(row, eps + h) - distension_of_strain(row, eps)) / h
        assert abs(left - right) < 1e-4 * max(abs(left), 1.0)
    # slope kappa alpha at eps_x from both branches (Wuennemann et al. 2006 choose eps_c for this)
    slope = (distension_of_strain(row, row[EPS_X] + h) - distension_of_strain(row, row[EPS_X] - h)) / (2 * h)
    assert slope == pytest.approx(0.98 * 1.3, rel=1e-5)
    strains = np.linspace(0.0, row[EPS_C] - 0.1, 400)
    values = np.array([distension_of_strain(row, e) for e in strains])
    assert (np.diff(values) <= 0.0).all()


def test_porous_pressure_is_solid_pressure_at_matrix_density_over_alpha():
    """The mixture's material state of a porous material: P_s(alpha rho, e) / alpha and c_s^2(alpha rho, e)."""
    eos = pack_eos([BASALT])
    p_s, c2_s, _ = pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, 2900.0, 1.0e5)
    present, rho, e, p, c2, c2_signal, flag, limited = material_state(
        0.5, 0.5 * 2900.0 / 1.5, 0.5 * 2900.0 / 1.5 * 1.0e5, eos.kind[0], eos.params[0], eos.table, np.zeros(2),
        0.0, 1.0, 1.5)
    assert present and rho == pytest.approx(2900.0 / 1.5) and e == pytest.approx(1.0e5)
    assert p == pytest.approx(p_s / 1.5, rel=1e-14) and c2 == c2_s and c2_signal == c2_s


@pytest.mark.parametrize("block, message", [
    ({"alpha0": 0.9, "eps_e": 0.0, "kappa": 1.0, "alpha_x": 1.0}, "'alpha0' must be >= 1"),
    ({"alpha0": 1.5, "eps_e": 0.1, "kappa": 1.0, "alpha_x": 1.0}, "'eps_e' must be <= 0"),
    ({"alpha0": 1.5, "eps_e": 0.0, "kappa": 0.0, "alpha_x": 1.0}, "'kappa' must be > 0"),
    ({"alpha0": 1.5, "eps_e": 0.0, "kappa": 1.0, "alpha_x": 1.6}, "'alpha_x' must be <= alpha0"),
    ({"alpha0": 1.5, "eps_e": 0.0, "kappa": 1.0}, "missing key 'alpha_x'"),
    ({"alpha0": 1.5, "eps_e": 0.0, "kappa": 1.0, "alpha_x": 1.0, "chi": 1.2}, "'chi' must be > 0 and <= 1"),
    ({"alpha0": 1.5, "eps_e": 0.0, "kappa": 1.0, "alpha_x": 1.0, "chi": 0.0}, "'chi' must be > 0 and <= 1"),
    ({"alpha0": 1.5, "eps_e": -0.01, "kappa": 1.0, "alpha_x": 1.5, "chi": 0.5}, "'alpha_x' must be <= the distension "
                                                                               "at the elastic limit"),
    ({"alpha0": 1.5, "eps_e": 0.0, "kappa": 1.0, "alpha_x": 1.0, "c": 1.0}, "unknown key 'c'"),
])
def test_pack_porosity_names_the_bad_key(block, message):
    spec = {**BASALT, "porosity": block}
    with pytest.raises(ValueError, match=message):
        pack_porosity([spec], pack_eos([spec]))


def wall_shock(alpha0, speed, cells=384, length=1.0, courant=0.4):
    """A porous basalt slab of ``length`` (m) moving at -``speed`` (m/s) onto a reflecting wall at x = 0:
    a steady shock runs back into it and leaves the material at rest, with particle velocity ``speed``."""
    return porous_slab.setup(porous_basalt(alpha0), speed, cells, length, courant)


@pytest.mark.parametrize("alpha0", [1.2, 2.0])
@pytest.mark.parametrize("target_pressure", [1.0e9, 5.0e9, 20.0e9, 50.0e9])
def test_porous_hugoniot_against_analytic(alpha0, target_pressure):
    """The shocked plateau's pressure and density within 2 % of the analytic porous Hugoniot (1-50 GPa)."""
    spec = porous_basalt(alpha0)
    speed = brentq(lambda u: porous_hugoniot(spec, u)[0] - target_pressure, 10.0, 2.0e4, rtol=1e-8)
    p_exact, rho_exact, _ = porous_hugoniot(spec, speed)
    sim = wall_shock(alpha0, speed)
    shock_speed = speed * rho_exact / (rho_exact - spec["rho0"] / alpha0)  # mass flux rho00 U = rho (U - u_p)
    end = 0.6 / shock_speed
    before = sim.totals()
    sim.run(end)
    snap = sim.snapshot()
    x = snap.centers[:, 0]
    p = snap.pressure.reshape(-1)
    rho = snap.density.reshape(-1)
    front = (shock_speed - speed) * end  # the wall frame: the shocked material is at rest
    plateau = (x > 0.15 * front) & (x < 0.8 * front)
    assert plateau.sum() > 20
    assert np.median(p[plateau]) == pytest.approx(p_exact, rel=0.02)
    assert np.median(rho[plateau]) == pytest.approx(rho_exact, rel=0.02)
    # the front where the pressure rises through half its plateau value, within 3 cells of U t
    half = np.flatnonzero(p > 0.5 * p_exact)
    assert abs(x[half.max()] - front) < 3.0 * sim.mesh.min_cell_size()
    # conservation (the wall does no work, nothing leaves): mass and momentum to round-off, energy up to what the
    # floors added or removed (counted), as for solid materials (tests/test_hydro_conservation.py)
    after = sim.totals()
    assert after["mass_with_outflow"] == pytest.approx(before["mass"], rel=1e-12)
    # momentum with the wall's impulse (counted as outflow), up to what the floors removed (counted)
    budget = conservation_budget(before, after, sim.floor_amounts)
    assert abs(budget["momentum_x_unaccounted"]) < 1e-12
    added = sim.floor_amounts["energy_added_by_floors"] - sim.floor_amounts["energy_removed_by_void_cleanup"]
    assert abs(after["energy_with_outflow"] - before["energy"] - added) < 1e-12 * before["energy"]


def test_porous_material_is_fully_compacted_behind_a_strong_shock_and_untouched_ahead(tmp_path):
    sim = wall_shock(1.5, 500.0, cells=192)
    sim.run(4.0e-4)  # the front (U - u_p = 940 m/s in the wall frame) at 0.38 m, the slab's back at 0.8 m
    snap = sim.snapshot()
    x = snap.centers[:, 0]
    dist = snap.extra["distension"].reshape(-1)
    # behind the shock, leaving out the cells next to the wall (the wall-heating density deficit)
    assert np.allclose(dist[(x > 0.02) & (x < 0.3)], 1.0)
    assert np.allclose(dist[(x > 0.45) & (x < 0.75)], 1.5)
    # a checkpoint carries the distension: the restarted run continues bit for bit
    sim.save_checkpoint(tmp_path / "c.h5")
    again = Simulation.from_checkpoint(tmp_path / "c.h5")
    for run in (sim, again):
        run.run(5.0e-4)
    for name, array in sim.state.arrays().items():
        assert np.array_equal(array, getattr(again.state, name)), name
    assert again.floor_counts == sim.floor_counts


def test_planar_compaction_wave_behind_elastic_precursor():
    """A piston (the wall) into porous basalt with an elastic limit eps_e = -2e-3: the elastic
    precursor and the compaction wave run at the two-wave solution's speeds, each front within
    3 cells (precursor, spread by the scheme: 5) of where U t puts it."""
    alpha0, speed = 1.5, 150.0
    spec = {**BASALT, "porosity": {"alpha0": alpha0, "eps_e": -2.0e-3, "kappa": 0.98, "alpha_x": 1.0}}
    u_precursor, u_compaction, p_precursor, p_final = two_wave_speeds(spec, speed)
    assert u_compaction < 0.5 * u_precursor  # two separate waves
    sim = porous_slab.setup(spec, speed, cells=512)
    end = 0.7 / (u_precursor - speed)
    sim.run(end)
    snap = sim.snapshot()
    xs = snap.centers[:, 0]
    p = snap.pressure.reshape(-1)
    dx = sim.mesh.min_cell_size()
    # wall frame: the waves leave the wall at U - u_piston
    precursor = xs[np.flatnonzero(p > 0.5 * p_precursor).max()]
    compaction = xs[np.flatnonzero(p > 0.5 * (p_precursor + p_final)).max()]
    assert abs(precursor - (u_precursor - speed) * end) < 5.0 * dx
    assert abs(compaction - (u_compaction - speed) * end) < 3.0 * dx
    between = (xs > compaction + 5 * dx) & (xs < precursor - 8 * dx)
    assert np.median(p[between]) == pytest.approx(p_precursor, rel=0.02)
    behind = (xs > 0.2 * compaction) & (xs < compaction - 5 * dx)
    assert np.median(p[behind]) == pytest.approx(p_final, rel=0.02)


def elastic_basalt(chi, eps_e=-2.0e-3, alpha0=1.5):
    return {**BASALT, "porosity": {"alpha0": alpha0, "eps_e": eps_e, "kappa": 0.98, "alpha_x": 1.0, "chi": chi}}


def matrix_sound_speed():
    """c_s0 (m/s): the basalt matrix's sound speed at its reference density and e = 0."""
    eos = pack_eos([BASALT])
    return pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, BASALT["rho0"], 0.0)[1] ** 0.5


def test_elastic_compaction_curve_of_chi():
    """Collins et al. (2011): d alpha / d eps_v = alpha (1 - h^2) in the elastic regime, h = 1 + (chi - 1)
    (alpha - 1) / (alpha0 - 1); the exponential branch starts from alpha_e = alpha_el(eps_e); chi = 1 keeps alpha0;
    and the porous material at rest carries weak waves at chi c_s0: dP/drho of P_s(alpha(eps_v) rho) / alpha(eps_v)."""
    from impactpipe.hydro.eos.porosity import ALPHA_E, EPS_E, elastic_strain, wave_speed_ratio

    spec = elastic_basalt(0.5)
    eos = pack_eos([spec])
    row = pack_porosity([spec], eos)[0]
    assert row[ALPHA_E] < 1.5 and distension_of_strain(row, row[EPS_E]) == pytest.approx(row[ALPHA_E], rel=1e-14)
    assert elastic_strain(row, row[ALPHA_E]) == pytest.approx(-2.0e-3, rel=1e-12)
    assert distension_of_strain(row, 1e-3) == 1.5 and distension_of_strain(row, 0.0) == 1.5
    h = 1e-8
    for eps in (-1e-4, -1e-3, -1.9e-3):
        a = distension_of_strain(row, eps)
        slope = (distension_of_strain(row, eps + h) - distension_of_strain(row, eps - h)) / (2 * h)
        assert slope == pytest.approx(a * (1 - wave_speed_ratio(row, a) ** 2), rel=1e-6)
    # continuous at eps_e (elastic -> exponential)
    e = row[EPS_E]
    assert distension_of_strain(row, e - 1e-12) == pytest.approx(distension_of_strain(row, e), rel=1e-10)
    one = pack_porosity([elastic_basalt(1.0)], eos)[0]
    assert distension_of_strain(one, -1.9e-3) == 1.5 and one[ALPHA_E] == 1.5
    rho00 = BASALT["rho0"] / 1.5

    def bulk_pressure(rho):
        a = distension_of_strain(row, math.log(rho00 / rho))
        return pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, a * rho, 0.0)[0] / a

    d = 1e-6 * rho00
    c2 = (bulk_pressure(rho00 * (1 + 1e-4) + d) - bulk_pressure(rho00 * (1 + 1e-4) - d)) / (2 * d)
    assert c2 ** 0.5 == pytest.approx(0.5 * matrix_sound_speed(), rel=1e-3)


def test_elastic_compaction_is_reversible_and_plastic_compaction_is_not():
    from impactpipe.hydro.eos.porosity import ALPHA_E, compact

    spec = elastic_basalt(0.5)
    row = pack_porosity([spec], pack_eos([spec]))
    rho00 = BASALT["rho0"] / 1.5

    def step(dist, strain):
        alpha = np.ones((1, 1, 1, 1, 1))
        arho = np.full_like(alpha, rho00 * math.exp(-strain))
        arhoq = np.zeros((1, 2, 1, 1, 1))
        arhoq[0, 0] = dist * arho[0, 0]
        compact(alpha, arho, arhoq, row, np.zeros((1, 1), dtype=np.int64), 0, 1)
        return arhoq[0, 0, 0, 0, 0] / arho[0, 0, 0, 0, 0]

    loaded = step(1.5, -1e-3)
    assert loaded == pytest.approx(distension_of_strain(row[0], -1e-3), rel=1e-14) and loaded < 1.5
    assert step(loaded, 0.0) == 1.5                                 # unloaded: the pores open again
    crushed = step(loaded, -5e-3)
    assert crushed < row[0, ALPHA_E]
    assert step(crushed, 0.0) == crushed                            # past eps_e: they stay closed
    assert step(crushed, -1e-3) == crushed


def test_elastic_wave_speed_in_a_porous_plate():
    """A weak planar pulse (a porous slab at 1 m/s onto a wall, strain 1e-3 below eps_e = -2e-3) runs through
    porous basalt of chi = 0.5 at the porous elastic wave speed chi c_s0 (Collins et al. 2011), not at the
    matrix's c_s0: the front (half the plateau pressure) within 1 % of (chi c_s0 - u) t, the plateau
    pressure within 1 % of the acoustic rho_00 chi c_s0 u."""
    chi, speed = 0.5, 1.0
    c = chi * matrix_sound_speed()
    rho00 = BASALT["rho0"] / 1.5
    sim = porous_slab.setup(elastic_basalt(chi), speed, cells=512)
    sim.run(0.7 / (c - speed))
    snap = sim.snapshot()
    plateau, measured = porous_slab.wave_front(snap, speed)
    assert plateau == pytest.approx(rho00 * c * speed, rel=0.01)
    assert measured == pytest.approx(c, rel=0.01)
    xs = snap.centers[:, 0]
    dist = snap.extra["distension"].reshape(-1)
    assert dist[(xs > 0.1) & (xs < 0.5)].min() > 1.49  # elastic: the pores are only squeezed
