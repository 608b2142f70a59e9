"""Equations of state for the hydro stage: packing of resolved specs and a numba dispatcher.

A material's EOS is a *resolved* spec dict (presets already expanded by the config layer):

    {"model": "ideal_gas", "gamma", "cv"}
    {"model": "mie_gruneisen", "rho0", "c0", "s", "gamma0", "cv", "T_ref" (optional)}
    {"model": "tillotson", "rho0", "A", "B", "E0", "E_iv", "E_cv", "a", "b", "alpha", "beta",
     "rho_iv" (optional, default 0 = classic three-region form), "cv", "T_ref" (optional)}
    {"model": "table", "path"}

Any of them may carry a ``porosity`` block (the epsilon-alpha model of a porous material
made of that solid, :mod:`impactpipe.hydro.eos.porosity`), which ``pack_eos`` leaves to
:func:`impactpipe.hydro.eos.porosity.pack_porosity`.

``pack_eos`` turns a list of them into ``EOSArrays`` (model codes, one parameter row per
material, one flat array holding every table).  The jitted functions below branch on the
model code and can be called from other ``@njit`` kernels and from Python:

    p, c2, flag = pressure_sound_speed(kind[k], params[k], table, rho, e)
    T = temperature(kind[k], params[k], table, rho, e)
    e = energy_from_pressure(kind[k], params[k], table, rho, p)
    rho0 = reference_density(kind[k], params[k], table)

Units: rho kg/m^3, e J/kg, p Pa, c2 m^2/s^2, T K.  ``flag`` is 0, or 1 when the state
was outside the model's range (table bounds, or the Mie-Grueneisen compression limit) and
was clamped.  Void is not a material and has no EOS here.
"""

import math
import numbers
import os
from typing import NamedTuple

import numpy as np
from numba import njit

from impactpipe.hydro.eos import ideal_gas, mie_gruneisen, table as eos_table, tillotson
from impactpipe.hydro.eos.ideal_gas import (
    ideal_gas_energy_from_pressure,
    ideal_gas_pressure_sound_speed,
    ideal_gas_temperature,
)
from impactpipe.hydro.eos.mie_gruneisen import (
    mie_gruneisen_energy_from_pressure,
    mie_gruneisen_pressure_sound_speed,
    mie_gruneisen_temperature,
)
from impactpipe.hydro.eos.table import (
    EOSTableError,
    TabulatedEOS,
    read_sesame_table,
    table_energy_from_pressure,
    table_pressure_sound_speed,
    table_reference_density,
    table_temperature,
    write_sesame_table,
)
from impactpipe.hydro.eos.tillotson import (
    tillotson_energy_from_pressure,
    tillotson_pressure_not_negative,
    tillotson_pressure_sound_speed,
    tillotson_temperature,
)

__all__ = [
    "IDEAL_GAS", "MIE_GRUNEISEN", "TILLOTSON", "TABLE", "NPARAM", "MODEL_CODES",
    "DEFAULT_T_REF", "SPECIFIC_HEAT_DEFAULTS", "EOSArrays", "pack_eos",
    "pressure_sound_speed", "temperature", "energy_from_pressure", "reference_density",
    "pressure_sound_speed_in_line", "temperature_in_line", "pressure_not_negative", "reference_densities",
    "EOSTableError", "TabulatedEOS", "read_sesame_table", "write_sesame_table",
]

IDEAL_GAS = 0
MIE_GRUNEISEN = 1
TILLOTSON = 2
TABLE = 3

#: Length of a material's parameter row.
NPARAM = 16

#: Model name in a spec -> model code.
MODEL_CODES = {"ideal_gas": IDEAL_GAS, "mie_gruneisen": MIE_GRUNEISEN,
               "tillotson": TILLOTSON, "table": TABLE}

#: Temperature at the reference state (rho0, e = 0) when a spec gives no T_ref (K).
DEFAULT_T_REF = 293.0

#: Specific heats (J/kg/K) near room temperature for the presets of
#: pipeline/data/materials.yaml (handbook values); the config layer may use them as ``cv``.
SPECIFIC_HEAT_DEFAULTS = {
    "basalt": 840.0, "basalt_isale": 840.0, "granite": 790.0, "ice": 2050.0,
    "iron": 450.0, "dunite": 840.0, "water": 4186.0, "nylon": 1700.0,
    "aluminium": 897.0, "copper": 385.0,
}


class EOSArrays(NamedTuple):
    """Packed EOS data for M materials.

    kind   int64[M]            model code per material
    params float64[M, NPARAM]  parameter rows (layouts in each model module)
    table  float64[:]          all tabulated data, flat; length 1 when no table is used
    """

    kind: np.ndarray
    params: np.ndarray
    table: np.ndarray


# (key, required, default, check, what the check demands); checks take the value
_POSITIVE = (lambda v: v > 0.0, "must be > 0")
_NON_NEGATIVE = (lambda v: v >= 0.0, "must be >= 0")
_GAMMA = (lambda v: v > 1.0, "must be > 1")

_LAYOUTS = {
    "ideal_gas": [
        ("gamma", True, None, _GAMMA, ideal_gas.GAMMA),
        ("cv", True, None, _POSITIVE, ideal_gas.CV),
    ],
    "mie_gruneisen": [
        ("rho0", True, None, _POSITIVE, mie_gruneisen.RHO0),
        ("c0", True, None, _POSITIVE, mie_gruneisen.C0),
        ("s", True, None, _NON_NEGATIVE, mie_gruneisen.S),
        ("gamma0", True, None, _POSITIVE, mie_gruneisen.GAMMA0),
        ("cv", True, None, _POSITIVE, mie_gruneisen.CV),
        ("T_ref", False, DEFAULT_T_REF, _POSITIVE, mie_gruneisen.T_REF),
    ],
    "tillotson": [
        ("rho0", True, None, _POSITIVE, tillotson.RHO0),
        ("A", True, None, _POSITIVE, tillotson.A),
        ("B", True, None, _NON_NEGATIVE, tillotson.B),
        ("E0", True, None, _POSITIVE, tillotson.E0),
        ("E_iv", True, None, _NON_NEGATIVE, tillotson.E_IV),
        ("E_cv", True, None, _POSITIVE, tillotson.E_CV),
        ("a", True, None, _POSITIVE, tillotson.A_SMALL),
        ("b", True, None, _NON_NEGATIVE, tillotson.B_SMALL),
        ("alpha", True, None, _NON_NEGATIVE, tillotson.ALPHA),
        ("beta", True, None, _NON_NEGATIVE, tillotson.BETA),
        ("rho_iv", False, 0.0, _NON_NEGATIVE, tillotson.RHO_IV),
        ("cv", True, None, _POSITIVE, tillotson.CV),
        ("T_ref", False, DEFAULT_T_REF, _POSITIVE, tillotson.T_REF),
    ],
}


def _number(spec_name, key, value):
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{spec_name}: key {key!r} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{spec_name}: key {key!r} must be finite, got {value!r}")
    return value


def _pack_analytic(index, spec, model, row):
    name = f"material {index} ({model})"
    layout = _LAYOUTS[model]
    known = {"model"} | {key for key, *_ in layout}
    for key in spec:
        if key not in known:
            raise ValueError(f"{name}: unknown key {key!r} (known: {sorted(known - {'model'})})")
    for key, required, default, (check, demand), slot in layout:
        if key not in spec:
            if required:
                raise ValueError(f"{name}: missing key {key!r}")
            value = default
        else:
            value = _number(name, key, spec[key])
            if not check(value):
                raise ValueError(f"{name}: key {key!r} {demand}, got {value!r}")
        row[slot] = value
    if model == "tillotson":
        if row[tillotson.E_CV] <= row[tillotson.E_IV]:
            raise ValueError(f"{name}: key 'E_cv' must be > E_iv, got {row[tillotson.E_CV]!r}")
        if row[tillotson.RHO_IV] >= row[tillotson.RHO0]:
            raise ValueError(f"{name}: key 'rho_iv' must be < rho0, got {row[tillotson.RHO_IV]!r}")


def pack_eos(materials):
    """Pack resolved EOS specs (list of dicts, see module docstring) into ``EOSArrays``.

    Raises ValueError naming the material and the key when a key is missing, unknown, not a
    finite number or out of range; ``EOSTableError`` for a malformed table file.
    """
    if len(materials) == 0:
        raise ValueError("pack_eos: no materials given")
    kind = np.zeros(len(materials), dtype=np.int64)
    params = np.zeros((len(materials), NPARAM), dtype=np.float64)
    chunks = []
    table_size = 0
    for index, spec in enumerate(materials):
        if not isinstance(spec, dict):
            raise ValueError(f"material {index}: EOS spec must be a dict, got {type(spec).__name__}")
        spec = {key: value for key, value in spec.items() if key != "porosity"}  # hydro.eos.porosity's
        if "model" not in spec:
            raise ValueError(f"material {index}: missing key 'model'")
        model = spec["model"]
        if model not in MODEL_CODES:
            raise ValueError(f"material {index}: key 'model' must be one of "
                             f"{sorted(MODEL_CODES)}, got {model!r}")
        kind[index] = MODEL_CODES[model]
        if model == "table":
            name = f"material {index} (table)"
            for key in spec:
                if key not in ("model", "path"):
                    raise ValueError(f"{name}: unknown key {key!r} (known: ['path'])")
            if "path" not in spec:
                raise ValueError(f"{name}: missing key 'path'")
            if not isinstance(spec["path"], (str, os.PathLike)):
                raise ValueError(f"{name}: key 'path' must be a file path, got {spec['path']!r}")
            tab = read_sesame_table(spec["path"])
            flat = tab.flat()
            params[index, eos_table.OFFSET] = table_size
            params[index, eos_table.N_RHO] = tab.density.size
            params[index, eos_table.N_T] = tab.temperature.size
            params[index, eos_table.RHO_REF] = tab.rho_ref
            chunks.append(flat)
            table_size += flat.size
        else:
            _pack_analytic(index, spec, model, params[index])
    table = np.concatenate(chunks) if chunks else np.zeros(1, dtype=np.float64)
    return EOSArrays(kind=kind, params=params, table=table)


@njit(cache=True)
def pressure_sound_speed(kind, params_row, table, rho, e):
    """Pressure (Pa), squared bulk sound speed c_K^2 (m^2/s^2, > 0) and flag at (rho, e).

    c_K^2 = dP/drho|_e + (P/rho^2) dP/de|_rho, floored per model at a small positive
    value.  flag = 1 when the state was clamped into the model's range, else 0.
    """
    if kind == IDEAL_GAS:
        p, c2 = ideal_gas_pressure_sound_speed(params_row, rho, e)
        return p, c2, 0
    if kind == MIE_GRUNEISEN:
        return mie_gruneisen_pressure_sound_speed(params_row, rho, e)
    if kind == TILLOTSON:
        p, c2 = tillotson_pressure_sound_speed(params_row, rho, e)
        return p, c2, 0
    return table_pressure_sound_speed(params_row, table, rho, e)


@njit(cache=True, inline="always")
def pressure_sound_speed_in_line(kind, params_row, table, rho, e):
    """:func:`pressure_sound_speed`, bit for bit, for the kernels that call it once per cell:
    ideal gas and Tillotson are called in place, where the compiler can inline them (the
    dispatcher call costs about 12 ns against 1 ns for an ideal gas), the other models
    through the dispatcher (inlining the table lookup everywhere makes the kernels slower)."""
    if kind == IDEAL_GAS:
        p, c2 = ideal_gas_pressure_sound_speed(params_row, rho, e)
        return p, c2, 0
    if kind == TILLOTSON:
        p, c2 = tillotson_pressure_sound_speed(params_row, rho, e)
        return p, c2, 0
    return pressure_sound_speed(kind, params_row, table, rho, e)


@njit(cache=True, inline="always")
def pressure_not_negative(kind, params_row, rho, e):
    """Whether the pressure at (rho kg/m^3, e J/kg) is certain to be >= 0 without evaluating the
    EOS: an ideal gas with e >= 0 (P = (gamma - 1) rho e, gamma >= 1), Tillotson compressed
    with e >= 0 (:func:`~impactpipe.hydro.eos.tillotson.tillotson_pressure_not_negative`); False
    otherwise (the other models are not bounded here), so a caller then evaluates the EOS."""
    if kind == IDEAL_GAS:
        return e >= 0.0 and rho >= 0.0 and params_row[ideal_gas.GAMMA] >= 1.0
    if kind == TILLOTSON:
        return tillotson_pressure_not_negative(params_row, rho, e)
    return False


@njit(cache=True, inline="always")
def temperature_in_line(kind, params_row, table, rho, e):
    """:func:`temperature`, bit for bit, with ideal gas and Tillotson called in place (as
    :func:`pressure_sound_speed_in_line`)."""
    if kind == IDEAL_GAS:
        return ideal_gas_temperature(params_row, rho, e)
    if kind == TILLOTSON:
        return tillotson_temperature(params_row, rho, e)
    return temperature(kind, params_row, table, rho, e)


@njit(cache=True)
def temperature(kind, params_row, table, rho, e):
    """Temperature (K) at (rho kg/m^3, e J/kg); rules in each model module and docs/eos.md."""
    if kind == IDEAL_GAS:
        return ideal_gas_temperature(params_row, rho, e)
    if kind == MIE_GRUNEISEN:
        return mie_gruneisen_temperature(params_row, rho, e)
    if kind == TILLOTSON:
        return tillotson_temperature(params_row, rho, e)
    return table_temperature(params_row, table, rho, e)


@njit(cache=True)
def energy_from_pressure(kind, params_row, table, rho, p):
    """Specific internal energy e (J/kg) with P(rho, e) = p (Pa); NaN if none is found.

    Exact for ideal gas and Mie-Grueneisen (P is linear in e), a bracketed root find for
    Tillotson, an exact inverse of the interpolation for tables.
    """
    if kind == IDEAL_GAS:
        return ideal_gas_energy_from_pressure(params_row, rho, p)
    if kind == MIE_GRUNEISEN:
        return mie_gruneisen_energy_from_pressure(params_row, rho, p)
    if kind == TILLOTSON:
        return tillotson_energy_from_pressure(params_row, rho, p)
    return table_energy_from_pressure(params_row, table, rho, p)


@njit(cache=True)
def reference_density(kind, params_row, table):
    """Reference (zero-pressure, cold) density rho0 (kg/m^3); 0 for an ideal gas."""
    if kind == IDEAL_GAS:
        return 0.0
    if kind == TABLE:
        return table_reference_density(params_row)
    return params_row[0]


def reference_densities(eos: EOSArrays) -> np.ndarray:
    """Reference density rho0 (kg/m^3) of every material, 0 for an ideal gas: for the kernels
    that need it per cell, where calling :func:`reference_density` each time costs a dispatch."""
    return np.array([reference_density(eos.kind[k], eos.params[k], eos.table) for k in range(eos.kind.size)])
