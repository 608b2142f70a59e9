"""Impact energies, velocity scaling and the published Q*_D laws on worked numbers."""

import numpy as np
import pytest

from impactpipe.analysis import (
    benz_asphaug_1999,
    fit_qstar_size_law,
    impact_energy,
    leinhardt_stewart_2012_qrd,
    leinhardt_stewart_2012_qstar_d,
    mass_ratio,
    reduced_impact_energy,
    scale_qstar_to_velocity,
    sphere_mass,
)


def test_case8_q_at_critical_velocity_matches_reference_qstar():
    # method.md section 6, case 8: R_T = 10 km, R_P = 0.83 km, equal densities;
    # Q = 0.5 (R_P/R_T)^3 v^2, at v_crit = 2.50 km/s gives Q*_D = 1.79 (+-0.06) x 10^3 J/kg
    m_t = sphere_mass(10e3, 2700.0)
    m_p = sphere_mass(0.83e3, 2700.0)
    q = impact_energy(m_p, m_t, 2500.0)
    assert q == pytest.approx(0.5 * 0.083**3 * 2500.0**2, rel=1e-12)
    assert q == pytest.approx(1786.8, abs=0.1)
    assert abs(q - 1.79e3) < 0.06e3
    assert mass_ratio(m_p, m_t) == pytest.approx(0.083**3)


def test_reduced_energy_forms_agree():
    m_t, m_p, v = 3.0e15, 6.0e14, 1500.0
    gamma = m_p / m_t
    q_r = reduced_impact_energy(m_p, m_t, v)
    assert q_r == pytest.approx(0.5 * gamma * v**2 / (1 + gamma) ** 2, rel=1e-14)
    assert q_r == pytest.approx(impact_energy(m_p, m_t, v) / (1 + gamma) ** 2, rel=1e-14)
    # equal masses: Q_R = 0.5 * 1 * v^2 / 4
    assert reduced_impact_energy(1.0, 1.0, 1000.0) == pytest.approx(1.25e5)


def test_velocity_scaling_exponent():
    # Q*_D ~ V^(2 - 3 mu): mu = 0.45 -> exponent 0.65; mu = 2/3 (momentum scaling) -> invariant
    assert scale_qstar_to_velocity(1000.0, 1.0e3, 2.0e3) == pytest.approx(1000.0 * 2**0.65)
    assert scale_qstar_to_velocity(1000.0, 1.0e3, 5.0e3, mu=2 / 3) == pytest.approx(1000.0)
    assert scale_qstar_to_velocity(1000.0, 3.0e3, 3.0e3) == pytest.approx(1000.0)


def test_benz_asphaug_1999_basalt_in_si():
    # 3 km/s at R = 1 cm: Q0 + B rho = 3.5e7 + 0.3 * 2.7 erg/g
    assert benz_asphaug_1999(0.01, 2700.0) == pytest.approx((3.5e7 + 0.81) * 1e-4, rel=1e-12)
    # 3 km/s at R = 10 km = 1e6 cm: 3.5e7 * 10^-2.28 + 0.81 * 10^8.16 = 1.17264e8 erg/g
    assert benz_asphaug_1999(1.0e4, 2700.0) == pytest.approx(1.17264e4, rel=1e-4)
    # 5 km/s at R = 1 m = 100 cm: 9e7 * 100^-0.36 + 0.5 * 2.7 * 100^1.36
    expected = (9.0e7 * 100**-0.36 + 1.35 * 100**1.36) * 1e-4
    assert benz_asphaug_1999(1.0, 2700.0, velocity_kms=5.0) == pytest.approx(expected, rel=1e-12)
    with pytest.raises(ValueError):
        benz_asphaug_1999(1.0, velocity_kms=4.0)


def test_leinhardt_stewart_2012_worked_numbers():
    # R_C1 = 10 km <=> M_tot = 4/3 pi 1000 (1e4)^3; gamma = 1: Q*_RD = 1.9 (4/5) pi 1000 G 1e8 = 31.87 J/kg
    m_tot = 4.0 / 3.0 * np.pi * 1000.0 * 1.0e12
    assert leinhardt_stewart_2012_qrd(m_tot, 1.0) == pytest.approx(31.87, rel=1e-3)
    # gamma = 0.1: factor (1.21 / 0.4)^(2/1.08 - 1) = 2.5674
    assert leinhardt_stewart_2012_qrd(m_tot, 0.1) == pytest.approx(31.87 * 2.5674, rel=2e-3)


def test_leinhardt_stewart_qstar_d_halves_the_target_on_the_universal_law():
    gamma, r_t, rho = 0.2, 5.0e3, 2000.0
    qstar_d = leinhardt_stewart_2012_qstar_d(r_t, rho, gamma)
    m_t = sphere_mass(r_t, rho)
    q_rd = leinhardt_stewart_2012_qrd(m_t * (1 + gamma), gamma)
    q_r = qstar_d / (1 + gamma) ** 2
    mlr_over_mtot = 1 - q_r / (2 * q_rd)
    assert mlr_over_mtot * (1 + gamma) == pytest.approx(0.5, rel=1e-12)


def test_size_law_fit_recovers_benz_asphaug_5kms():
    radius = np.logspace(-2, 5, 15)
    truth = benz_asphaug_1999(radius, 2700.0, velocity_kms=5.0)
    rng = np.random.default_rng(3)
    noisy = truth * np.exp(rng.normal(0.0, 0.03, radius.size))
    fit = fit_qstar_size_law(radius, noisy, 2700.0)
    assert fit.alpha == pytest.approx(-0.36, abs=0.02)
    assert fit.beta == pytest.approx(1.36, abs=0.02)
    q_b_si = 9.0e7 * 1e-4 * 100**-0.36
    q_g_si = 0.5 * 1e-4 * 1e-3 * 100**1.36
    assert fit.q_b == pytest.approx(q_b_si, rel=0.2)
    assert fit.q_g == pytest.approx(q_g_si, rel=0.5)
    np.testing.assert_allclose(fit(radius, 2700.0), truth, rtol=0.06)
    assert fit.rms_log10 < 0.03
