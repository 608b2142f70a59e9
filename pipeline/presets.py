"""Published material parameter sets shipped with the package, and their resolution.

The data file ``data/materials.yaml`` holds Tillotson and Mie-Grueneisen EOS sets and
the GEO / ROCK strength presets of the reference study, the Weibull flaw parameters of
tensile fracture and the epsilon-alpha compaction parameters of porous materials (SI units).  A material in a config names a preset and may override any
parameter; :func:`resolve_eos`, :func:`resolve_strength`, :func:`resolve_damage` and
:func:`resolve_porosity` return
the complete parameter dicts the solver consumes.
"""

from __future__ import annotations

from functools import lru_cache
from importlib import resources
from typing import Any

import yaml

TILLOTSON_KEYS = ("rho0", "A", "B", "E0", "E_iv", "E_cv", "a", "b", "alpha", "beta")
TILLOTSON_OPTIONAL = ("rho_iv",)
MIE_GRUNEISEN_KEYS = ("rho0", "c0", "s", "gamma0")
IDEAL_GAS_KEYS = ("gamma",)

#: Specific heat at constant volume (J/kg/K) when neither the material nor its preset gives one.
DEFAULT_CV = {"ideal_gas": 718.0, "tillotson": 840.0, "mie_gruneisen": 900.0}

GEO_KEYS = ("Y0", "Y_M", "Y_T", "mu_i", "poisson", "T_melt", "xi")
ROCK_KEYS = ("Y0", "Y_M", "Y_T", "mu_i", "Y_c", "mu_d", "T_melt", "xi", "P_bd", "P_bp", "poisson")
VON_MISES_KEYS = ("yield_strength", "poisson")
OPTIONAL_STRENGTH_KEYS = ("shear_modulus", "Y_T", "initial_damage", "mu_2", "inertial_number_I0", "grain_diameter")
GRADY_KIPP_KEYS = ("weibull_m", "weibull_k")
OPTIONAL_GRADY_KIPP_KEYS = ("young_modulus", "flaw_cross_section")
#: Integer keys of a Grady-Kipp block: the seed and the number of flaws of each material's draw.
FLAW_DRAW_KEYS = ("flaw_seed", "flaw_count")
#: Boolean keys of a Grady-Kipp block: the limit D <= n_act / n_tot (Benz & Asphaug 1995).
GRADY_KIPP_SWITCHES = ("active_flaw_limit",)
POROSITY_KEYS = ("alpha0", "eps_e", "kappa", "alpha_x")
#: Porosity parameters a block or preset may leave out (:data:`impactpipe.hydro.eos.porosity.OPTIONAL_KEYS`).
POROSITY_OPTIONAL_KEYS = ("chi",)
#: Thermal-softening exponent for GEO presets, which publish none (the ROCK presets use 1.2).
GEO_DEFAULT_XI = 1.2


@lru_cache(maxsize=1)
def material_data() -> dict[str, Any]:
    """The parsed ``materials.yaml`` shipped in the package."""
    text = resources.files("impactpipe.pipeline").joinpath("data/materials.yaml").read_text()
    return yaml.safe_load(text)


def eos_presets(model: str) -> list[str]:
    """Names of the EOS presets available for ``model``."""
    return sorted(material_data().get(model, {}))


def strength_presets(model: str) -> list[str]:
    """Names of the strength presets available for ``model`` (geo or rock)."""
    table = material_data()["strength"].get(model, {})
    return sorted(k for k in table if k != "common")


def resolve_eos(model: str, preset: str | None, overrides: dict[str, Any]) -> dict[str, Any]:
    """Complete EOS parameters: the preset's values updated with ``overrides``.

    Raises KeyError naming the first missing parameter.
    """
    params: dict[str, Any] = {}
    if preset is not None:
        params.update({k: v for k, v in material_data()[model][preset].items()})
    params.update({k: v for k, v in overrides.items() if v is not None})
    required = {"tillotson": TILLOTSON_KEYS, "mie_gruneisen": MIE_GRUNEISEN_KEYS, "ideal_gas": IDEAL_GAS_KEYS}
    if model == "table":
        return {"model": "table", "path": params["path"]}
    for key in required[model]:
        if key not in params:
            raise KeyError(key)
    keep = set(required[model]) | set(TILLOTSON_OPTIONAL if model == "tillotson" else ()) | {"cv", "T_ref"}
    resolved = {k: float(v) for k, v in params.items() if k in keep}
    from impactpipe.hydro.eos import SPECIFIC_HEAT_DEFAULTS

    resolved.setdefault("cv", SPECIFIC_HEAT_DEFAULTS.get(preset or "", DEFAULT_CV[model]))
    return {"model": model, **resolved}


def resolve_strength(model: str, preset: str | None, overrides: dict[str, Any]) -> dict[str, Any]:
    """Complete strength parameters for ``model`` (none, von_mises, geo, rock).

    Raises KeyError naming the first missing parameter.
    """
    if model == "none":
        return {"model": "none"}
    params: dict[str, Any] = {}
    if model == "geo":
        params.update(material_data()["strength"]["geo"]["common"])
        params["xi"] = GEO_DEFAULT_XI
    if preset is not None:
        params.update(material_data()["strength"][model][preset])
    params.update({k: v for k, v in overrides.items() if v is not None})
    required = {"geo": GEO_KEYS, "rock": ROCK_KEYS, "von_mises": VON_MISES_KEYS}[model]
    for key in required:
        if key not in params:
            raise KeyError(key)
    resolved = {k: float(params[k]) for k in required}
    for key in OPTIONAL_STRENGTH_KEYS:
        if key in params and key not in resolved:
            resolved[key] = float(params[key])
    return {"model": model, **resolved}


def damage_presets(model: str) -> list[str]:
    """Names of the damage presets available for ``model`` (grady_kipp)."""
    return sorted(material_data()["damage"].get(model, {}))


def resolve_damage(spec: dict[str, Any] | None) -> dict[str, Any]:
    """Complete damage block of a strength spec: ``{model, preset, parameters...}`` with the
    preset's values updated by the parameters given; None or model ``instant`` is the instant
    tensile failure.  Raises KeyError naming the first missing parameter."""
    spec = dict(spec or {})
    model = spec.pop("model", "instant")
    preset = spec.pop("preset", None)
    if model == "instant":
        return {"model": "instant"}
    params: dict[str, Any] = {}
    if preset is not None:
        params.update(material_data()["damage"][model][preset])
    params.update({k: v for k, v in spec.items() if v is not None})
    for key in GRADY_KIPP_KEYS:
        if key not in params:
            raise KeyError(key)
    keep = GRADY_KIPP_KEYS + OPTIONAL_GRADY_KIPP_KEYS
    resolved = {"model": model, **{k: float(params[k]) for k in keep if k in params}}
    for key in FLAW_DRAW_KEYS:
        if key in params:
            resolved[key] = int(params[key])
    for key in GRADY_KIPP_SWITCHES:
        if key in params:
            resolved[key] = bool(params[key])
    return resolved


def porosity_presets() -> list[str]:
    """Names of the porosity presets."""
    return sorted(material_data()["porosity"])


def resolve_porosity(spec: dict[str, Any]) -> dict[str, float]:
    """Complete epsilon-alpha parameters of a material's ``porosity`` block: the preset's values
    updated by the parameters given.  Raises KeyError naming the first missing parameter."""
    spec = dict(spec)
    preset = spec.pop("preset", None)
    params: dict[str, Any] = {}
    if preset is not None:
        params.update(material_data()["porosity"][preset])
    params.update({k: v for k, v in spec.items() if v is not None})
    for key in POROSITY_KEYS:
        if key not in params:
            raise KeyError(key)
    out = {k: float(params[k]) for k in POROSITY_KEYS}
    for key in POROSITY_OPTIONAL_KEYS:
        if key in params:
            out[key] = float(params[key])
    return out
