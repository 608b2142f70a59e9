"""The cell mixture gather (hydro.mixture.mixture_state) against the sums it stands for."""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.eos import pack_eos, pressure_sound_speed, temperature
from impactpipe.hydro.scheme.mixture import MATERIAL_ROWS, mixture_state
from impactpipe.hydro.problems.common import preset_material

BASALT = preset_material("basalt")["eos"]
GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}


def _cell(alpha, rho, e, damage):
    """One cell of two materials (basalt, gas) with one transported scalar each (the damage)."""
    shape = (1, 2, 1, 1, 1)
    a = np.array(alpha).reshape(shape)
    ar = (np.array(alpha) * np.array(rho)).reshape(shape)
    are = ar * np.array(e).reshape(shape)
    arhoq = ar * np.array(damage).reshape(shape)
    return a, ar, are, arhoq


def test_a_mixed_cell_is_the_equal_strain_mixture_of_its_materials():
    """Basalt stretched to 0.9 rho0 beside a hot gas and 10 % void: rho, phi, p, K, rho e and
    rho T are the volume- and mass-weighted sums of the module docstring, the basalt pressure
    held at -Y_T (1 - D) (counted as a tension limit), the per-material rows written."""
    eos = pack_eos([BASALT, GAS])
    y_t = np.array([1.0e7, 0.0])
    shear = np.zeros((2, 2))
    alpha, rho, e, damage = [0.6, 0.3], [0.9 * BASALT["rho0"], 2.0], [0.0, 3.0e5], [0.5, 0.0]
    a, ar, are, arhoq = _cell(alpha, rho, e, damage)
    rows = np.full((4, 3 + 2 * MATERIAL_ROWS), np.nan)
    state = mixture_state(a, ar, are, arhoq, 0, 0, 0, 0, eos.kind, eos.params, eos.table, shear, y_t, True, rows,
                          3, 1)
    m_rho, m_phi, m_p, m_k, m_eint, m_tmass, clamps, limits = state
    p_basalt_eos, c2_basalt, _ = pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, rho[0], e[0])
    p_gas, c2_gas, _ = pressure_sound_speed(eos.kind[1], eos.params[1], eos.table, rho[1], e[1])
    p_basalt = -y_t[0] * (1.0 - damage[0])
    assert p_basalt_eos < p_basalt
    assert m_rho == ar.sum() and m_phi == a.sum()
    np.testing.assert_allclose(m_p, alpha[0] * p_basalt + alpha[1] * p_gas, rtol=1e-14)
    np.testing.assert_allclose(m_k, alpha[0] * rho[0] * c2_basalt + alpha[1] * rho[1] * c2_gas, rtol=1e-14)
    np.testing.assert_allclose(m_eint, alpha[1] * rho[1] * e[1], rtol=1e-14)
    t = [temperature(eos.kind[k], eos.params[k], eos.table, rho[k], e[k]) for k in range(2)]
    np.testing.assert_allclose(m_tmass, alpha[0] * rho[0] * t[0] + alpha[1] * rho[1] * t[1], rtol=1e-14)
    assert (clamps, limits) == (0, 1)
    expected = [alpha[0], rho[0], e[0], p_basalt, rho[0] * c2_basalt, y_t[0] * (1.0 - damage[0]),
                alpha[1], rho[1], e[1], p_gas, rho[1] * c2_gas, 0.0]
    np.testing.assert_allclose(rows[1, 3:], expected, rtol=1e-14)
    assert np.isnan(rows[:, :3]).all() and np.isnan(rows[[0, 2, 3]]).all()
    without = mixture_state(a, ar, are, arhoq, 0, 0, 0, 0, eos.kind, eos.params, eos.table, shear, y_t, False, None,
                            0, 0)
    assert without[:5] == state[:5] and without[5] == 0.0


def test_a_trace_is_absent_from_the_sums_but_keeps_its_tension_row():
    """Gas below ALPHA_MIN adds its partial density and volume to rho and phi only; its
    material rows hold alpha_k, zeros and its tensile strength."""
    eos = pack_eos([BASALT, GAS])
    y_t = np.array([1.0e7, 3.0])
    shear = np.zeros((2, 2))
    a, ar, are, arhoq = _cell([1.0 - 1e-11, 1e-11], [BASALT["rho0"], 2.0], [0.0, 3.0e14], [0.0, 0.0])
    rows = np.zeros((1, 2 * MATERIAL_ROWS))
    m_rho, m_phi, m_p, m_k, *_ = mixture_state(a, ar, are, arhoq, 0, 0, 0, 0, eos.kind, eos.params, eos.table, shear,
                                               y_t, False, rows, 0, 0)
    p_basalt, c2_basalt, _ = pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, BASALT["rho0"], 0.0)
    assert m_rho == ar.sum() and m_phi == a.sum()
    assert m_p == a[0, 0, 0, 0, 0] * p_basalt and m_k == ar[0, 0, 0, 0, 0] * c2_basalt
    assert list(rows[0, MATERIAL_ROWS:]) == [1e-11, 0.0, 0.0, 0.0, 0.0, 3.0]


def _sod_in_two_labels(cells, split):
    """Sod's shock tube in one ideal gas, or in a 50/50 mixture of two labels of that gas (every
    cell mixed at equal densities); the L1 density error against the exact solution at 0.2 s,
    relative to the density jump."""
    from impactpipe.hydro.exact.riemann import exact_riemann

    gas = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}
    materials = {"gas": {"eos": gas}, "twin": {"eos": gas}}
    sim = PROBLEMS["shock_tube"].setup(
        {"cells": cells, "right": {"material": "twin", "density": 0.125, "pressure": 0.1}}, materials)
    x = sim.mesh.cell_centers()[:, 0].reshape((sim.mesh.nblocks,) + sim.mesh.interior_shape)
    rho = np.where(x < 0.5, 1.0, 0.125)
    p = np.where(x < 0.5, 1.0, 0.1)
    sim.state.set_material(sim.mesh, 1.0, 0, sim.eos, rho, np.zeros(3), pressure=p)
    if split:
        sim.state.set_material(sim.mesh, 0.5, 1, sim.eos, rho, np.zeros(3), pressure=p)
    sim.run(0.2)
    snap = sim.snapshot()
    exact, _, _ = exact_riemann(snap.centers[:, 0], 0.2, 0.5, (1.0, 0.0, 1.0), (0.125, 0.0, 0.1), 1.4)
    return np.abs(snap.density.reshape(-1) - exact).mean() / 0.875


def test_mixed_cells_of_like_density_reconstruct_at_second_order():
    """Every cell mixed 50/50: the materials' reconstruction of like-density mixtures (docs/hydro.md,
    "Scheme", step 2) keeps the L1 error at 384 cells at 0.0055 (0.0094 when mixed cells ran at
    first order; one gas alone: 0.0017)."""
    assert _sod_in_two_labels(384, True) < 0.0065


@pytest.mark.xfail(strict=True, reason="two labels of one gas, mixed 50/50, do not yet reproduce the one-gas "
                                       "solution: 3x its L1 error at 384 cells (a known gap, docs/hydro.md)")
def test_two_labels_of_one_gas_match_one_gas():
    assert _sod_in_two_labels(384, True) < 1.2 * _sod_in_two_labels(384, False)
