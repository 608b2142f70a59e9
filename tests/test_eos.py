"""Analytic equations of state: exact values, thermodynamic consistency, branch continuity."""

import math

import numpy as np
import pytest
from numba import njit

from impactpipe.hydro.eos import (
    DEFAULT_T_REF,
    IDEAL_GAS,
    MIE_GRUNEISEN,
    NPARAM,
    TILLOTSON,
    energy_from_pressure,
    pack_eos,
    pressure_sound_speed,
    reference_density,
    temperature,
)
from impactpipe.hydro.eos import mie_gruneisen, tillotson
from impactpipe.hydro.eos.tillotson import tillotson_branch, tillotson_cold_energy

BASALT = {"model": "tillotson", "rho0": 2700.0, "A": 26.7e9, "B": 26.7e9, "E0": 487.0e6,
          "E_iv": 4.72e6, "E_cv": 18.2e6, "a": 0.5, "b": 1.5, "alpha": 5.0, "beta": 5.0,
          "rho_iv": 2000.0, "cv": 840.0, "T_ref": 293.0}
IRON = {"model": "tillotson", "rho0": 7800.0, "A": 128.0e9, "B": 105.0e9, "E0": 9.5e6,
        "E_iv": 2.4e6, "E_cv": 8.67e6, "a": 0.5, "b": 1.5, "alpha": 5.0, "beta": 5.0,
        "cv": 450.0}
ALUMINIUM = {"model": "mie_gruneisen", "rho0": 2790.0, "c0": 5330.0, "s": 1.34,
             "gamma0": 2.0, "cv": 897.0, "T_ref": 300.0}
AIR = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}

EOS = pack_eos([AIR, ALUMINIUM, BASALT, IRON])


def state(k, rho, e):
    return pressure_sound_speed(EOS.kind[k], EOS.params[k], EOS.table, rho, e)


def isentropic_c2(k, rho, e, rel_step=1.0e-6):
    """Centred finite difference of P along the isentrope de = (P/rho^2) drho."""
    p = state(k, rho, e)[0]
    h = rel_step * rho
    de = p / rho**2 * h
    return (state(k, rho + h, e + de)[0] - state(k, rho - h, e - de)[0]) / (2.0 * h)


def test_pack_layout_and_codes():
    assert list(EOS.kind) == [IDEAL_GAS, MIE_GRUNEISEN, TILLOTSON, TILLOTSON]
    assert EOS.params.shape == (4, NPARAM) and EOS.params.dtype == np.float64
    assert EOS.table.shape == (1,)
    assert EOS.params[3, tillotson.RHO_IV] == 0.0
    assert EOS.params[3, tillotson.T_REF] == DEFAULT_T_REF
    assert [reference_density(EOS.kind[k], EOS.params[k], EOS.table) for k in range(4)] == [
        0.0, 2790.0, 2700.0, 7800.0]


@pytest.mark.parametrize("change, key", [
    ({"A": None}, "A"),
    ({"cv": None}, "cv"),
    ({"A": -1.0}, "A"),
    ({"E0": float("nan")}, "E0"),
    ({"a": "0.5"}, "a"),
    ({"E_cv": 1.0e6}, "E_cv"),
    ({"rho_iv": 3000.0}, "rho_iv"),
    ({"Eiv": 1.0}, "Eiv"),
    ({"model": "tilotson"}, "model"),
])
def test_pack_rejects_bad_specs_naming_the_key(change, key):
    spec = dict(BASALT)
    for name, value in change.items():
        if value is None:
            del spec[name]
        else:
            spec[name] = value
    with pytest.raises(ValueError, match=f"'{key}'"):
        pack_eos([AIR, spec])


def test_pack_rejects_bad_ideal_gas_and_table_specs():
    with pytest.raises(ValueError, match="'gamma'"):
        pack_eos([{"model": "ideal_gas", "gamma": 1.0, "cv": 718.0}])
    with pytest.raises(ValueError, match="'path'"):
        pack_eos([{"model": "table"}])
    with pytest.raises(ValueError, match="'model'"):
        pack_eos([{"gamma": 1.4}])


def test_ideal_gas_exact():
    for rho, e in [(1.0, 2.5), (1.2, 2.1e5), (1.0e-3, 7.0e6)]:
        p, c2, flag = state(0, rho, e)
        assert p == pytest.approx(0.4 * rho * e, rel=1e-15)
        assert c2 == pytest.approx(1.4 * p / rho, rel=1e-15)
        assert c2 == pytest.approx(isentropic_c2(0, rho, e), rel=1e-8)
        assert flag == 0
        assert temperature(EOS.kind[0], EOS.params[0], EOS.table, rho, e) == pytest.approx(
            e / 718.0, rel=1e-15)
        assert energy_from_pressure(EOS.kind[0], EOS.params[0], EOS.table, rho, p) == (
            pytest.approx(e, rel=1e-14))


def test_mie_gruneisen_reference_hugoniot_is_linear_us_up():
    rho0, c0, s = 2790.0, 5330.0, 1.34
    for eta in [1.0, 1.05, 1.3, 1.8, 2.5]:
        rho = eta * rho0
        p_h, e_h, _, _, flag = mie_gruneisen.mie_gruneisen_hugoniot(EOS.params[1], rho)
        p, _, flag_p = state(1, rho, e_h)
        assert flag == 0 and flag_p == 0
        assert p == pytest.approx(p_h, rel=1e-12, abs=1e-6)
        u_p = math.sqrt(p_h * (1.0 / rho0 - 1.0 / rho))
        assert p_h == pytest.approx(rho0 * (c0 + s * u_p) * u_p, rel=1e-12, abs=1e-6)
        assert e_h == pytest.approx(0.5 * u_p**2, rel=1e-12, abs=1e-9)


def test_mie_gruneisen_sound_speed():
    p, c2, _ = state(1, 2790.0, 0.0)
    assert p == 0.0
    assert c2 == pytest.approx(5330.0**2, rel=1e-14)
    for rho, e in [(2500.0, 1.0e5), (2790.0, 1.0e6), (3300.0, 2.0e5), (5000.0, 3.0e6)]:
        assert state(1, rho, e)[1] == pytest.approx(isentropic_c2(1, rho, e), rel=1e-6)


def test_mie_gruneisen_compression_limit_flags():
    rho_limit = 2790.0 * (1.0 + mie_gruneisen.MU_LIMIT_FRACTION / 0.34)
    p_lim, _, flag_lim = state(1, rho_limit * 0.999, 0.0)
    p_over, _, flag_over = state(1, rho_limit * 1.1, 0.0)
    assert flag_lim == 0 and flag_over == 1
    assert np.isfinite(p_over) and p_over > p_lim


# Tillotson basalt states on every branch and on both sides of every branch boundary
# (offsets are 1e-4 relative, 100x the finite-difference step).
TILLOTSON_STATES = [
    (3500.0, 1.0e6, 1), (5400.0, 5.0e7, 1), (2700.0 * 1.0001, 1.0e7, 1),
    (2400.0, 2.0e6, 1), (2700.0 * 0.9999, 2.0e6, 1), (2000.0 * 1.0001, 1.0e6, 1),
    (2400.0, 4.72e6 * 0.9999, 1),
    (2400.0, 4.72e6 * 1.0001, 3), (2400.0, 1.0e7, 3), (2400.0, 18.2e6 * 0.9999, 3),
    (2700.0 * 0.9999, 1.0e7, 3),
    (2400.0, 18.2e6 * 1.0001, 2), (2400.0, 3.0e7, 2), (1000.0, 3.0e7, 2), (100.0, 5.0e7, 2),
    (2700.0 * 0.9999, 3.0e7, 2),
    (2000.0 * 0.9999, 1.0e6, 4), (1900.0, 1.0e7, 4), (1900.0, 18.2e6 * 0.9999, 4),
]


@pytest.mark.parametrize("rho, e, branch", TILLOTSON_STATES)
def test_tillotson_sound_speed_is_thermodynamic(rho, e, branch):
    row = EOS.params[2]
    assert tillotson_branch(row, rho, e) == branch
    p, dp_drho, dp_de = tillotson.tillotson_pressure_derivatives(row, rho, e)
    h = 1.0e-6 * rho
    de = 1.0e-6 * e
    fd_drho = (state(2, rho + h, e)[0] - state(2, rho - h, e)[0]) / (2.0 * h)
    fd_de = (state(2, rho, e + de)[0] - state(2, rho, e - de)[0]) / (2.0 * de)
    assert dp_drho == pytest.approx(fd_drho, rel=1e-5, abs=1e-5 * abs(p) / rho)
    assert dp_de == pytest.approx(fd_de, rel=1e-5)
    c2 = state(2, rho, e)[1]
    assert c2 > tillotson.C2_FLOOR_FRACTION * 26.7e9 / 2700.0
    assert c2 == pytest.approx(isentropic_c2(2, rho, e), rel=1e-5)


@pytest.mark.parametrize("e", [0.0, 2.0e6, 1.0e7, 3.0e7])
def test_tillotson_continuous_across_rho0(e):
    below = state(2, 2700.0 * (1.0 - 1e-12), e)
    above = state(2, 2700.0, e)
    assert below[0] == pytest.approx(above[0], rel=1e-9, abs=1e-9 * 26.7e9)
    assert below[1] == pytest.approx(above[1], rel=1e-9)


@pytest.mark.parametrize("rho", [2100.0, 2400.0, 2690.0])
@pytest.mark.parametrize("e_edge", [4.72e6, 18.2e6])
def test_tillotson_pressure_continuous_across_mixed_region_edges(rho, e_edge):
    below = state(2, rho, e_edge * (1.0 - 1e-13))[0]
    above = state(2, rho, e_edge * (1.0 + 1e-13))[0]
    assert below == pytest.approx(above, abs=1e-9 * 26.7e9)


def test_tillotson_incipient_vaporisation_density_jump_is_b_mu_squared():
    """At rho_iv, cold states switch from P1 to P4: the published form jumps by B mu_iv^2."""
    mu_iv = 2000.0 / 2700.0 - 1.0
    for e in [0.0, 1.0e6, 4.0e6]:
        jump = state(2, 2000.0, e)[0] - state(2, 2000.0 * (1.0 - 1e-13), e)[0]
        assert jump == pytest.approx(26.7e9 * mu_iv**2, rel=1e-9)


def test_tillotson_cold_curve_and_classic_form():
    row = EOS.params[2]
    for eta in [0.8, 1.0, 1.5, 2.0]:
        mu = eta - 1.0
        assert state(2, 2700.0 * eta, 0.0)[0] == pytest.approx(
            26.7e9 * (mu + mu * mu), rel=1e-14, abs=1e-3)
    iron = EOS.params[3]
    for rho in [7000.0, 5000.0, 1000.0]:
        assert tillotson_branch(iron, rho, 1.0e6) == 1
        assert tillotson_branch(iron, rho, 5.0e6) == 3
    assert tillotson_branch(row, 1000.0, 1.0e6) == 4


def test_tillotson_sound_speed_floor():
    c2 = state(2, 500.0, 1.0e3)[1]
    assert c2 == pytest.approx(tillotson.C2_FLOOR_FRACTION * 26.7e9 / 2700.0, rel=1e-14)


def test_tillotson_cold_energy_is_integral_of_cold_pressure():
    row = EOS.params[2]
    assert tillotson_cold_energy(row, 2700.0) == 0.0
    for rho in [1500.0, 2400.0, 3000.0, 6000.0]:
        mu = rho / 2700.0 - 1.0
        h = 1.0e-5 * rho
        slope = (tillotson_cold_energy(row, rho + h) - tillotson_cold_energy(row, rho - h)) / (2 * h)
        assert slope == pytest.approx(26.7e9 * (mu + mu * mu) / rho**2, rel=1e-8)


def test_temperature_rules():
    k = 2
    t = temperature(EOS.kind[k], EOS.params[k], EOS.table, 2700.0, 0.0)
    assert t == 293.0
    row = EOS.params[k]
    for rho, e in [(2700.0, 1.0e6), (4000.0, 2.0e7), (2400.0, 5.0e6)]:
        expected = 293.0 + (e - tillotson_cold_energy(row, rho)) / 840.0
        assert temperature(EOS.kind[k], row, EOS.table, rho, e) == pytest.approx(expected, rel=1e-14)
    assert temperature(EOS.kind[k], row, EOS.table, 100.0, 0.0) == tillotson.T_FLOOR
    mg = EOS.params[1]
    e_h = mie_gruneisen.mie_gruneisen_hugoniot(mg, 4000.0)[1]
    assert temperature(EOS.kind[1], mg, EOS.table, 4000.0, e_h) == pytest.approx(300.0, rel=1e-14)
    assert temperature(EOS.kind[1], mg, EOS.table, 4000.0, e_h + 8.97e5) == pytest.approx(
        1300.0, rel=1e-12)
    assert temperature(EOS.kind[1], mg, EOS.table, 2790.0, 8.97e5) == pytest.approx(1300.0, rel=1e-14)


@pytest.mark.parametrize("k, rho, e", [(1, 2500.0, 1.0e5), (1, 4000.0, 3.0e6)]
                         + [(2, rho, e) for rho, e, _ in TILLOTSON_STATES]
                         + [(3, 9000.0, 1.0e6), (3, 5000.0, 5.0e6), (3, 6000.0, 3.0e7)])
def test_energy_from_pressure_inverts_pressure(k, rho, e):
    p = state(k, rho, e)[0]
    e_back = energy_from_pressure(EOS.kind[k], EOS.params[k], EOS.table, rho, p)
    assert state(k, rho, e_back)[0] == pytest.approx(p, rel=1e-10, abs=1e-12 * 26.7e9)
    p4_below_e_cv = k == 2 and rho < 2000.0 and e > 0.9 * 18.2e6
    if not p4_below_e_cv:  # there P drops from P4 to P2 at E_cv: p is reached twice
        assert e_back == pytest.approx(e, rel=1e-8)


def test_energy_from_pressure_unreachable_is_nan():
    assert math.isnan(energy_from_pressure(EOS.kind[2], EOS.params[2], EOS.table, 1000.0, -1.0e20))


@njit(cache=True)
def _sweep(kind, params, table, material, rho, e, p, c2):
    flags = 0
    for n in range(rho.size):
        k = material[n]
        p[n], c2[n], flag = pressure_sound_speed(kind[k], params[k], table, rho[n], e[n])
        flags += flag
    return flags


def test_dispatcher_callable_from_njit_kernel():
    material = np.array([0, 1, 2, 3, 2], dtype=np.int64)
    rho = np.array([1.2, 3000.0, 2400.0, 9000.0, 2700.0])
    e = np.array([2.0e5, 1.0e5, 1.0e7, 1.0e6, 0.0])
    p = np.empty(5)
    c2 = np.empty(5)
    assert _sweep(EOS.kind, EOS.params, EOS.table, material, rho, e, p, c2) == 0
    for n in range(5):
        expected = state(material[n], rho[n], e[n])
        assert (p[n], c2[n]) == (expected[0], expected[1])


@pytest.mark.parametrize("spec", [BASALT, IRON, AIR], ids=["basalt", "iron", "gas"])
def test_pressure_not_negative_never_claims_a_negative_pressure(spec):
    """pressure_not_negative (the stress update skips the EOS where it holds) is True only where
    the EOS's pressure is >= 0: over a grid of densities 0.5-3 rho_ref and energies -1e6 to 1e8 J/kg,
    and it is True for the compressed, heated states it is meant for."""
    from impactpipe.hydro.eos import pressure_not_negative
    eos = pack_eos([spec])
    kind, params = int(eos.kind[0]), eos.params[0]
    rho_ref = spec.get("rho0", 1.0)
    claimed = 0
    for rho in rho_ref * np.linspace(0.5, 3.0, 26):
        for e in np.concatenate([[-1.0e6, -1.0, 0.0], np.geomspace(1.0, 1.0e8, 15)]):
            if pressure_not_negative(kind, params, rho, e):
                claimed += 1
                assert pressure_sound_speed(kind, params, eos.table, rho, e)[0] >= 0.0, (rho, e)
            elif rho >= rho_ref and e >= 0.0:
                pytest.fail(f"compressed and heated but not claimed: rho {rho}, e {e}")
    assert claimed > 100
