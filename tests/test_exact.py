"""Exact reference solutions: Riemann (ideal gas), Sedov-Taylor, Noh, Hugoniots and impacts."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from impactpipe.hydro.exact.impedance import (
    hugoniot_from_particle_velocity,
    hugoniot_state,
    planar_impact_state,
)
from impactpipe.hydro.exact.noh import noh_shock_speed, noh_solution
from impactpipe.hydro.exact.riemann import exact_riemann, riemann_star_state
from impactpipe.hydro.exact.sedov import sedov_solution

BASALT = {"model": "tillotson", "rho0": 2700.0, "A": 26.7e9, "B": 26.7e9, "E0": 487.0e6,
          "E_iv": 4.72e6, "E_cv": 18.2e6, "a": 0.5, "b": 1.5, "alpha": 5.0, "beta": 5.0,
          "rho_iv": 2000.0, "cv": 840.0}
IRON = {"model": "tillotson", "rho0": 7800.0, "A": 128.0e9, "B": 105.0e9, "E0": 9.5e6,
        "E_iv": 2.4e6, "E_cv": 8.67e6, "a": 0.5, "b": 1.5, "alpha": 5.0, "beta": 5.0,
        "cv": 450.0}
ALUMINIUM = {"model": "mie_gruneisen", "rho0": 2790.0, "c0": 5330.0, "s": 1.34,
             "gamma0": 2.0, "cv": 897.0}

GAMMA = 1.4


# Star states of Toro's five test problems (Riemann Solvers and Numerical Methods for
# Fluid Dynamics, 3rd ed., table 4.3): left, right, p*, u*.
TORO_TESTS = [
    ((1.0, 0.0, 1.0), (0.125, 0.0, 0.1), 0.30313, 0.92745),
    ((1.0, -2.0, 0.4), (1.0, 2.0, 0.4), 0.00189, 0.00000),
    ((1.0, 0.0, 1000.0), (1.0, 0.0, 0.01), 460.894, 19.5975),
    ((1.0, 0.0, 0.01), (1.0, 0.0, 100.0), 46.0950, -6.19633),
    ((5.99924, 19.5975, 460.894), (5.99242, -6.19633, 46.0950), 1691.64, 8.68975),
]


@pytest.mark.parametrize("left, right, p_star, u_star", TORO_TESTS)
def test_riemann_star_states_match_published_values(left, right, p_star, u_star):
    p, u = riemann_star_state(left, right, GAMMA)
    assert p == pytest.approx(p_star, rel=5e-5, abs=5e-6)
    assert u == pytest.approx(u_star, rel=5e-5, abs=5e-6)


def test_sod_profile_regions():
    """Sod at t = 0.2: each region's state from the Rankine-Hugoniot / isentropic relations."""
    left, right = (1.0, 0.0, 1.0), (0.125, 0.0, 0.1)
    p_star, u_star = riemann_star_state(left, right, GAMMA)
    x = np.array([0.1, 0.55, 0.65, 0.8, 0.95])
    rho, u, p = exact_riemann(x, 0.2, 0.5, left, right, GAMMA)
    ratio = p_star / 0.1
    rho_shocked = 0.125 * (ratio + 1.0 / 6.0) / (ratio / 6.0 + 1.0)
    shock = u_star * rho_shocked / (rho_shocked - 0.125)   # mass flux continuity
    assert 0.5 + shock * 0.2 == pytest.approx(0.5 + 1.75216 * 0.2, rel=1e-5)
    expected_rho = [1.0, 1.0 * (p_star / 1.0) ** (1.0 / GAMMA), 1.0 * (p_star / 1.0) ** (1.0 / GAMMA),
                    rho_shocked, 0.125]
    assert np.allclose(rho, expected_rho, rtol=1e-12)
    assert np.allclose(p, [1.0, p_star, p_star, p_star, 0.1], rtol=1e-12)
    assert np.allclose(u, [0.0, u_star, u_star, u_star, 0.0], rtol=1e-12, atol=1e-14)


def test_riemann_rarefaction_fan_is_isentropic_simple_wave():
    left, right = (1.0, 0.0, 1.0), (0.125, 0.0, 0.1)
    t = 0.2
    x = np.linspace(0.5 - 1.18 * t, 0.5 - 0.08 * t, 25)   # inside the left fan
    rho, u, p = exact_riemann(x, t, 0.5, left, right, GAMMA)
    c = np.sqrt(GAMMA * p / rho)
    c_l = math.sqrt(GAMMA)
    assert np.max(np.abs(p / rho**GAMMA - 1.0)) < 1e-12
    assert np.max(np.abs(u + 2.0 * c / (GAMMA - 1.0) - 2.0 * c_l / (GAMMA - 1.0))) < 1e-12
    assert np.max(np.abs(u - c - (x - 0.5) / t)) < 1e-12   # characteristics through the origin


def test_riemann_vacuum_generation():
    left, right = (1.0, -4.0, 0.4), (1.0, 4.0, 0.4)
    with pytest.raises(ValueError, match="vacuum"):
        riemann_star_state(left, right, GAMMA)
    t = 0.1
    c = math.sqrt(GAMMA * 0.4)
    tail = -4.0 + 2.0 * c / (GAMMA - 1.0)
    x = np.array([-4.9, -4.5, -1.0, 1.1 * tail, 0.0, -1.1 * tail, 1.0, 4.5, 4.9]) * t
    rho, u, p = exact_riemann(x, t, 0.0, left, right, GAMMA)
    assert (rho[0], u[0], p[0]) == (1.0, -4.0, 0.4) and (rho[-1], u[-1], p[-1]) == (1.0, 4.0, 0.4)
    assert rho[4] == 0.0 and p[4] == 0.0
    fan = [1, 2, 3, 5, 6, 7]
    assert np.all(rho[fan] > 0.0)
    c_fan = np.sqrt(GAMMA * p[fan] / rho[fan])
    # left fan: u + 2c/(gamma-1) = u_L + 2c_L/(gamma-1); right fan: u - 2c/(gamma-1) likewise
    invariant = u[fan] - np.sign(x[fan]) * 2.0 * c_fan / (GAMMA - 1.0)
    expected = np.where(x[fan] < 0.0, -4.0 + 2.0 * c / (GAMMA - 1.0), 4.0 - 2.0 * c / (GAMMA - 1.0))
    assert np.max(np.abs(invariant - expected)) < 1e-12
    assert np.max(np.abs(p[fan] / rho[fan] ** GAMMA - 0.4)) < 1e-12


def test_riemann_expansion_into_vacuum():
    t = 0.1
    c = math.sqrt(GAMMA)
    front = 2.0 * c / (GAMMA - 1.0)
    x = np.array([-1.5 * c, -0.5 * c, 0.5 * front, 1.01 * front]) * t
    rho, u, p = exact_riemann(x, t, 0.0, (1.0, 0.0, 1.0), (0.0, 0.0, 0.0), GAMMA)
    assert rho[0] == 1.0 and rho[3] == 0.0 and math.isnan(u[3])
    assert u[2] == pytest.approx(2.0 / (GAMMA + 1.0) * (c + 0.5 * front), rel=1e-14)


@pytest.mark.parametrize("gamma, nu, xi0, tol", [
    (1.4, 3, 1.033, 1e-3),          # Landau & Lifshitz, Fluid Mechanics, section 106
    (5.0 / 3.0, 3, 1.15167, 1e-5),  # standard gamma = 5/3 spherical value
    (1.4, 2, 1.004, 1e-3),          # cylindrical, E per unit length (alpha = 0.9840)
])
def test_sedov_xi0_matches_published(gamma, nu, xi0, tol):
    assert sedov_solution(gamma, nu).xi0 == pytest.approx(xi0, abs=tol)


@pytest.mark.parametrize("nu", [1, 2, 3])
def test_sedov_profiles_hold_the_energy_and_jump_conditions(nu):
    gamma, energy, rho0, t = 1.4, 2.0, 1.5, 0.3
    solution = sedov_solution(gamma, nu)
    big_r = solution.shock_radius(energy, rho0, t)
    sigma = {1: 1.0, 2: 2.0 * math.pi, 3: 4.0 * math.pi}[nu]

    def density_of_energy(r):
        rho, u, p = solution.profiles(np.array([r]), t, energy, rho0)
        return (0.5 * rho[0] * u[0] ** 2 + p[0] / (gamma - 1.0)) * sigma * r ** (nu - 1)

    total = quad(density_of_energy, 0.0, big_r, epsrel=1e-10, limit=200)[0]
    assert total == pytest.approx(energy, rel=1e-6)
    speed = 2.0 / (nu + 2.0) * big_r / t
    rho, u, p = solution.profiles(np.array([big_r * (1 - 1e-12), big_r * 1.01]), t, energy, rho0)
    assert rho[0] == pytest.approx(rho0 * 6.0, rel=1e-9)
    assert u[0] == pytest.approx(2.0 * speed / 2.4, rel=1e-9)
    assert p[0] == pytest.approx(2.0 * rho0 * speed**2 / 2.4, rel=1e-9)
    assert (rho[1], u[1], p[1]) == (rho0, 0.0, 0.0)


@pytest.mark.parametrize("nu", [1, 2, 3])
def test_noh_solution(nu):
    gamma, t = 5.0 / 3.0, 0.6
    shock = noh_shock_speed(gamma, 1.0) * t
    assert shock == pytest.approx(0.2, rel=1e-15)
    r = np.array([0.0, 0.1, 0.19, 0.21, 0.5])
    rho, u, p = noh_solution(r, t, gamma, nu)
    assert np.allclose(rho[:3], 4.0**nu, rtol=1e-15)
    assert np.allclose(p[:3], 4.0**nu / 3.0, rtol=1e-14)
    assert np.all(u[:3] == 0.0) and np.all(u[3:] == -1.0) and np.all(p[3:] == 0.0)
    assert np.allclose(rho[3:], (1.0 + t / r[3:]) ** (nu - 1), rtol=1e-15)
    # mass conservation: the shocked mass equals the mass that has crossed the shock
    crossed = {1: 0.2 + 0.6, 2: (0.2 + 0.6) ** 2 / 2.0, 3: (0.2 + 0.6) ** 3 / 3.0}[nu]
    shocked = 4.0**nu * 0.2**nu / nu
    assert shocked == pytest.approx(crossed, rel=1e-14)


def test_mie_gruneisen_hugoniot_is_linear_us_up():
    for u_p in [100.0, 1000.0, 3000.0]:
        state = hugoniot_from_particle_velocity(ALUMINIUM, u_p)
        assert state.particle_velocity == pytest.approx(u_p, rel=1e-9)
        assert state.pressure == pytest.approx(2790.0 * (5330.0 + 1.34 * u_p) * u_p, rel=1e-6)
        assert state.shock_velocity == pytest.approx(5330.0 + 1.34 * u_p, rel=1e-6)
        assert state.energy == pytest.approx(0.5 * u_p**2, rel=1e-6)


def test_ideal_gas_hugoniot_strong_shock_limit():
    gas = {"model": "ideal_gas", "gamma": GAMMA, "cv": 718.0}
    rho0, e0 = 1.0, 2.5
    for ratio in [1.5, 3.0, 5.9]:
        state = hugoniot_state(gas, ratio * rho0, rho0=rho0, e0=e0)
        pressure_ratio = ((GAMMA + 1.0) * ratio - (GAMMA - 1.0)) / ((GAMMA + 1.0) - (GAMMA - 1.0) * ratio)
        assert state.pressure == pytest.approx(1.0 * pressure_ratio, rel=1e-10)
    with pytest.raises(ValueError, match="limiting"):
        hugoniot_state(gas, 6.5 * rho0, rho0=rho0, e0=e0)


@pytest.mark.parametrize("velocity", [2.0e3, 5.0e3])
def test_symmetric_impact_halves_the_velocity(velocity):
    for material in (BASALT, ALUMINIUM):
        state = planar_impact_state(material, material, velocity)
        assert state.particle_velocity == pytest.approx(0.5 * velocity, rel=1e-10)


def test_mie_gruneisen_impact_matches_linear_us_up():
    copper = {"model": "mie_gruneisen", "rho0": 8930.0, "c0": 3940.0, "s": 1.489,
              "gamma0": 2.02, "cv": 385.0}
    velocity = 4000.0
    state = planar_impact_state(copper, ALUMINIUM, velocity)
    u = state.particle_velocity
    p_target = 2790.0 * (5330.0 + 1.34 * u) * u
    p_flyer = 8930.0 * (3940.0 + 1.489 * (velocity - u)) * (velocity - u)
    assert state.pressure == pytest.approx(p_target, rel=1e-6)
    assert state.pressure == pytest.approx(p_flyer, rel=1e-6)


def test_tillotson_impacts_are_finite_and_ordered():
    for velocity in [2.0e3, 5.0e3]:
        basalt = planar_impact_state(BASALT, BASALT, velocity)
        iron = planar_impact_state(IRON, BASALT, velocity)
        for state in (basalt, iron):
            assert all(math.isfinite(v) for v in (*state.target, *state.flyer))
            assert state.target.pressure == pytest.approx(state.flyer.pressure, rel=1e-9)
            assert state.target.density > 2700.0 and state.target.energy > 0.0
        assert iron.pressure > basalt.pressure
        assert iron.particle_velocity > basalt.particle_velocity
    assert planar_impact_state(BASALT, BASALT, 5.0e3).pressure > planar_impact_state(
        BASALT, BASALT, 2.0e3).pressure
