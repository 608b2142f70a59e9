"""Yield models against the formulas of method.md section 2.2, and the presets of section 2.3 by name."""

import math

import numpy as np
import pytest

from impactpipe.hydro.strength.damage import FAILURE_STRAIN_BRITTLE, FAILURE_STRAIN_DUCTILE, failure_strain
from impactpipe.hydro.strength.parameters import GEO, NONE, ROCK, VON_MISES, pack_strength, shear_ratio
from impactpipe.hydro.strength.yield_strength import (
    damaged_friction,
    lundborg_intact,
    tensile_taper,
    thermal_softening,
    yield_strength,
)
from impactpipe.pipeline.presets import resolve_strength, strength_presets

# method.md section 2.3
GEO_TABLE = {"hydro": (0.0, 0.0, 1e5), "weak": (1e6, 1e7, 1e5), "medium": (1e7, 1e8, 1e6),
             "strong": (1e6, 3.5e9, 1e5), "strongHT": (1e6, 3.5e9, 1e7)}
ROCK_TABLE = {"weak": (1e6, 0.01e9, 0.1e6, 0.003e9, 0.004e9), "strong": (10e6, 3.5e9, 0.1e6, 2.94e9, 4.11e9),
              "strongHT": (10e6, 3.5e9, 10e6, 2.94e9, 4.11e9)}


def test_lundborg_curve():
    y0, y_m, mu = 1e7, 3.5e9, 1.2
    for p in (0.0, 1e6, 1e8, 1e9, 1e10):
        expect = y0 + mu * p / (1.0 + mu * p / (y_m - y0))
        assert lundborg_intact(p, y0, y_m, mu) == pytest.approx(expect, rel=1e-14)
    # slope mu_i at P = 0, limit Y_M at large pressure
    assert (lundborg_intact(1.0, y0, y_m, mu) - y0) == pytest.approx(mu, rel=1e-6)
    assert lundborg_intact(1e16, y0, y_m, mu) == pytest.approx(y_m, rel=1e-5)
    assert lundborg_intact(1e9, 0.0, 0.0, 1.0) == 0.0


def test_damaged_friction_is_capped_by_intact():
    intact = lundborg_intact(1e9, 1e7, 3.5e9, 1.2)
    assert damaged_friction(1e8, 0.0, 0.6, intact) == pytest.approx(0.6e8)
    assert damaged_friction(1e11, 0.0, 0.6, intact) == intact
    assert damaged_friction(-1e8, 0.0, 0.6, intact) == 0.0


def test_tensile_taper_and_thermal_softening():
    assert tensile_taper(1e5, 1e6) == 1.0
    assert tensile_taper(-2.5e5, 1e6) == pytest.approx(0.75)
    assert tensile_taper(-1e6, 1e6) == 0.0
    assert tensile_taper(-1.0, 0.0) == 0.0
    assert thermal_softening(700.0, 1400.0, 1.2) == pytest.approx(math.tanh(1.2))
    assert thermal_softening(1400.0, 1400.0, 1.2) == 0.0
    assert thermal_softening(2000.0, 1400.0, 1.2) == 0.0


def _params(model, **values):
    return pack_strength([{"model": model, **values}]).params[0]


def test_yield_strength_models():
    geo = {"Y0": 1e7, "Y_M": 1e8, "Y_T": 1e6, "mu_i": 1.0, "poisson": 0.3, "T_melt": 1474.0, "xi": 1.2}
    p, t = 5e7, 300.0
    soft = math.tanh(1.2 * (1474.0 / t - 1.0))
    expect = (1e7 + p / (1.0 + p / 9e7)) * soft
    assert yield_strength(GEO, _params("geo", **geo), p, t, 0.0) == pytest.approx(expect, rel=1e-13)
    # GEO ignores damage; linear fall to zero in tension
    assert yield_strength(GEO, _params("geo", **geo), p, t, 1.0) == pytest.approx(expect, rel=1e-13)
    assert yield_strength(GEO, _params("geo", **geo), -0.5e6, t, 0.0) == pytest.approx(0.5e7 * soft, rel=1e-13)
    assert yield_strength(GEO, _params("geo", **geo), -2e6, t, 0.0) == 0.0
    rock = resolve_strength("rock", "strong", {})
    prow = _params("rock", **{k: v for k, v in rock.items() if k != "model"})
    p = 1e9
    y_i = 1e7 + 1.2 * p / (1.0 + 1.2 * p / (3.5e9 - 1e7))
    y_d = min(0.6 * p, y_i)
    soft = math.tanh(1.2 * (1392.0 / t - 1.0))
    for d in (0.0, 0.3, 1.0):
        assert yield_strength(ROCK, prow, p, t, d) == pytest.approx(((1 - d) * y_i + d * y_d) * soft, rel=1e-13)
    assert yield_strength(VON_MISES, _params("von_mises", yield_strength=2e8, poisson=0.25), 1e10, 5000.0, 1.0) == 2e8
    assert yield_strength(NONE, np.zeros(13), 1e9, 300.0, 0.0) == 0.0


def test_failure_strain_between_transitions():
    assert failure_strain(1e6, 3e6, 4e6) == FAILURE_STRAIN_BRITTLE
    mid = failure_strain(3.5e6, 3e6, 4e6)
    assert mid == pytest.approx(0.5 * (FAILURE_STRAIN_BRITTLE + FAILURE_STRAIN_DUCTILE))
    assert failure_strain(5e6, 3e6, 4e6) == 0.0   # plastic: no shear damage


@pytest.mark.parametrize("name", sorted(GEO_TABLE))
def test_geo_presets_by_name(name):
    spec = resolve_strength("geo", name, {})
    assert (spec["Y0"], spec["Y_M"], spec["Y_T"]) == GEO_TABLE[name]
    assert (spec["mu_i"], spec["poisson"], spec["T_melt"]) == (1.0, 0.3, 1474.0)


@pytest.mark.parametrize("name", sorted(ROCK_TABLE))
def test_rock_presets_by_name(name):
    spec = resolve_strength("rock", name, {})
    y0, y_m, y_t, p_bd, p_bp = ROCK_TABLE[name]
    assert (spec["Y0"], spec["Y_M"], spec["Y_T"], spec["P_bd"], spec["P_bp"]) == pytest.approx((y0, y_m, y_t, p_bd, p_bp))
    assert (spec["mu_i"], spec["Y_c"], spec["mu_d"], spec["T_melt"], spec["xi"], spec["poisson"]) == (
        1.2, 0.0, 0.6, 1392.0, 1.2, 0.23)


def test_presets_listed_and_overridable():
    assert strength_presets("geo") == sorted(GEO_TABLE)
    assert strength_presets("rock") == sorted(ROCK_TABLE)
    spec = resolve_strength("geo", "strong", {"Y_M": 2e9, "xi": 0.5})
    assert spec["Y_M"] == 2e9 and spec["xi"] == 0.5 and spec["Y0"] == 1e6


def test_packing_shear_table_and_strengthless_materials():
    arrays = pack_strength([resolve_strength("geo", "hydro", {}), None,
                            {"model": "von_mises", "yield_strength": 1e8, "poisson": 0.25, "shear_modulus": 3e10},
                            resolve_strength("geo", "weak", {})])
    assert list(arrays.model) == [NONE, NONE, VON_MISES, GEO]
    assert arrays.tensile_strength[0] == 1e5          # hydro preset: only its tensile strength acts
    assert tuple(arrays.shear[2]) == (3e10, 0.0)
    assert arrays.shear[3, 1] == pytest.approx(3 * (1 - 0.6) / (2 * 1.3))
    assert shear_ratio(0.25) == pytest.approx(0.6)
    assert not pack_strength([None, {"model": "none"}]).enabled


def test_inertial_friction_mu_of_I():
    """mu(I) = mu_s + (mu_2 - mu_s) / (I0 / I + 1), I = gamma_dot d / sqrt(P / rho_s) (Jop et al. 2006)."""
    from impactpipe.hydro.strength.update import _shear_rate
    from impactpipe.hydro.strength.yield_strength import inertial_friction

    mu_s, mu_2, i0, d = math.tan(math.radians(20.9)), math.tan(math.radians(32.76)), 0.279, 0.53e-3
    rho, p = 2500.0, 1000.0
    for inertial in (1e-3, 0.1, 0.279, 1.0, 10.0):
        gamma_dot = inertial / d * math.sqrt(p / rho)
        expect = mu_s + (mu_2 - mu_s) / (i0 / inertial + 1.0)
        assert inertial_friction(mu_s, mu_2, i0, d, gamma_dot, p, rho) == pytest.approx(expect, rel=1e-12)
    assert inertial_friction(mu_s, mu_2, i0, d, 0.0, p, rho) == mu_s
    assert inertial_friction(mu_s, mu_2, i0, d, 1.0, 0.0, rho) == mu_s
    assert inertial_friction(mu_s, mu_2, i0, d, 1e12, p, rho) == pytest.approx(mu_2, rel=1e-9)
    gamma_dot = i0 / d * math.sqrt(p / rho)
    assert inertial_friction(mu_s, mu_2, i0, d, gamma_dot, p, rho) == pytest.approx(0.5 * (mu_s + mu_2), rel=1e-12)
    # the shear rate convention: simple shear v_x = gamma_dot y gives gamma_dot = sqrt(2 D_dev:D_dev)
    assert _shear_rate(0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) == pytest.approx(3.0, rel=1e-14)
    # uniaxial strain rate eps: D_dev = eps diag(2, -1, -1) / 3, sqrt(2 D_dev:D_dev) = 2 eps / sqrt(3)
    assert _shear_rate(1.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) == pytest.approx(3.0 / math.sqrt(3.0), rel=1e-14)
    # an isotropic expansion has no shear
    assert _shear_rate(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0) == pytest.approx(0.0, abs=1e-15)


def test_mu_of_I_keys_packed_and_validated():
    """The mu(I) keys are packed into the GEO row; absent, the row and the yield strength are the constant friction's."""
    from impactpipe.hydro.strength.parameters import GRAIN_D, I0, MU_2, MU_I
    from impactpipe.hydro.strength.yield_strength import yield_strength_friction
    from impactpipe.pipeline.config import StrengthSpec

    base = resolve_strength("geo", None, {"Y0": 0.0, "Y_M": 1e12, "Y_T": 0.0, "mu_i": 0.4663, "poisson": 0.25})
    plain = pack_strength([base])
    assert plain.params[0, GRAIN_D] == 0.0 and plain.params[0, MU_2] == 0.0
    extra = {"mu_2": 0.7277, "inertial_number_I0": 0.279, "grain_diameter": 10.0}
    spec = resolve_strength("geo", None, {**base, **extra})
    packed = pack_strength([spec])
    assert (packed.params[0, MU_2], packed.params[0, I0], packed.params[0, GRAIN_D]) == (0.7277, 0.279, 10.0)
    for p in (-1e5, 0.0, 1e3, 1e7):
        assert yield_strength_friction(GEO, plain.params[0], p, 300.0, 0.0, plain.params[0, MU_I]) == \
            yield_strength(GEO, plain.params[0], p, 300.0, 0.0)
    for bad, message in (({"mu_2": 0.7}, "needs all of"), ({**extra, "mu_2": 0.3}, "must be >= mu_i"),
                         ({**extra, "grain_diameter": 0.0}, "grain_diameter must be > 0")):
        with pytest.raises(ValueError, match=message):
            pack_strength([{**base, **bad}])
    with pytest.raises(ValueError, match="GEO strength option"):
        pack_strength([{"model": "von_mises", "yield_strength": 1e6, "poisson": 0.25, **extra}])
    StrengthSpec(model="geo", mu_i=0.4663, **extra)
    with pytest.raises(ValueError, match="needs all of"):
        StrengthSpec(model="geo", mu_i=0.4663, mu_2=0.7)
    with pytest.raises(ValueError, match="GEO strength option"):
        StrengthSpec(model="rock", **extra)
