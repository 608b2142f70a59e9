"""Packing of resolved strength specs into the arrays the strength kernels read.

A material's strength is a *resolved* spec dict (presets expanded by the config layer,
:func:`impactpipe.pipeline.presets.resolve_strength`):

    {"model": "none"}                                   (optional "Y_T")
    {"model": "von_mises", "yield_strength", "poisson", optional "shear_modulus", "Y_T"}
    {"model": "geo", "Y0", "Y_M", "Y_T", "mu_i", "poisson", "T_melt", "xi", optional "shear_modulus",
     optional "mu_2", "inertial_number_I0", "grain_diameter" (the mu(I) friction, all three or none)}
    {"model": "rock", "Y0", "Y_M", "Y_T", "mu_i", "Y_c", "mu_d", "T_melt", "xi", "P_bd", "P_bp",
     "poisson", optional "shear_modulus", "initial_damage"}

:func:`pack_strength` gives one parameter row per material (SI: Pa, K, dimensionless) and
the shear table ``shear[M, 2]`` the signal speed and the elastic update use:
G = shear[k, 0] + shear[k, 1] K, with K = rho c_K^2 the EOS bulk modulus (Pa).  A constant
``shear_modulus`` fills column 0; otherwise Poisson's ratio nu gives the ratio

    G / K = 3 (1 - 2 nu) / (2 (1 + nu))

A material whose yield strength is zero everywhere (model none, or the GEO ``hydro``
preset) gets model code NONE: no stress is stored or updated for it, only its tensile
strength Y_T limits its pressure in the sweeps.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

NONE = 0
VON_MISES = 1
GEO = 2
ROCK = 3
MODEL_CODES = {"none": NONE, "von_mises": VON_MISES, "geo": GEO, "rock": ROCK}

# parameter row slots
# (MU_2, I0, GRAIN_D: the GEO model's optional mu(I) friction; GRAIN_D = 0, the default, is the
# constant friction mu_i, :func:`impactpipe.hydro.strength.yield_strength.inertial_friction`)
Y0, Y_M, MU_I, Y_C, MU_D, Y_T, T_MELT, XI, P_BD, P_BP, POISSON, YIELD_VM, DAMAGE0, MU_2, I0, GRAIN_D = range(16)
NPAR = 16
_KEYS = {Y0: "Y0", Y_M: "Y_M", MU_I: "mu_i", Y_C: "Y_c", MU_D: "mu_d", Y_T: "Y_T", T_MELT: "T_melt",
         XI: "xi", P_BD: "P_bd", P_BP: "P_bp", POISSON: "poisson", YIELD_VM: "yield_strength",
         DAMAGE0: "initial_damage", MU_2: "mu_2", I0: "inertial_number_I0", GRAIN_D: "grain_diameter"}
#: The keys of the GEO model's mu(I) friction (given all together, or none of them).
MU_I_RHEOLOGY_KEYS = ("mu_2", "inertial_number_I0", "grain_diameter")


def check_inertial_friction(spec: dict, label: str = "") -> None:
    """Raise ValueError unless the mu(I) keys of ``spec`` are all absent or all given with
    mu_2 >= mu_i, I0 > 0 and grain_diameter > 0, and only for the GEO model."""
    given = [key for key in MU_I_RHEOLOGY_KEYS if spec.get(key) is not None]
    if not given:
        return
    where = f"{label}: " if label else ""
    model = spec.get("model", "none")
    if model != "geo":
        raise ValueError(f"{where}the mu(I) friction ({', '.join(given)}) is a GEO strength option "
                         f"(model {model!r})")
    missing = [key for key in MU_I_RHEOLOGY_KEYS if key not in given]
    if missing:
        raise ValueError(f"{where}the mu(I) friction needs all of {', '.join(MU_I_RHEOLOGY_KEYS)} "
                         f"(missing {', '.join(missing)})")
    if not float(spec["inertial_number_I0"]) > 0.0:
        raise ValueError(f"{where}inertial_number_I0 must be > 0 (got {spec['inertial_number_I0']:g})")
    if not float(spec["grain_diameter"]) > 0.0:
        raise ValueError(f"{where}grain_diameter must be > 0 m (got {spec['grain_diameter']:g})")
    mu_s = spec.get("mu_i")
    if mu_s is not None and float(spec["mu_2"]) < float(mu_s):
        raise ValueError(f"{where}mu_2 ({spec['mu_2']:g}) must be >= mu_i ({mu_s:g}), the friction "
                         f"at I = 0 (mu_s)")


class StrengthArrays(NamedTuple):
    """Strength parameters of M materials for the kernels.

    model: (M,) int64 model codes; params: (M, NPAR) rows (slots above); shear: (M, 2)
    constant shear modulus (Pa) and shear-to-bulk modulus ratio; tensile_strength: (M,) Y_T (Pa).
    """

    model: np.ndarray
    params: np.ndarray
    shear: np.ndarray
    tensile_strength: np.ndarray

    @property
    def enabled(self) -> bool:
        """True when at least one material has a yield model (stress is stored and updated)."""
        return bool((self.model != NONE).any())


def shear_ratio(poisson: float) -> float:
    """Shear-to-bulk modulus ratio G / K = 3 (1 - 2 nu) / (2 (1 + nu)) for Poisson's ratio nu."""
    return 3.0 * (1.0 - 2.0 * poisson) / (2.0 * (1.0 + poisson))


def has_yield(spec: dict) -> bool:
    """Whether a strength spec has a non-zero yield strength anywhere (missing strengths count as 0)."""
    model = spec.get("model", "none")
    if model == "none":
        return False
    if model == "von_mises":
        return spec.get("yield_strength", 0.0) > 0.0
    return spec.get("Y0", 0.0) > 0.0 or spec.get("Y_M", 0.0) > 0.0


def pack_strength(specs: list[dict | None]) -> StrengthArrays:
    """Pack resolved strength specs (one per material, None = strengthless) into :class:`StrengthArrays`."""
    m = len(specs)
    model = np.zeros(m, dtype=np.int64)
    params = np.zeros((m, NPAR))
    shear = np.zeros((m, 2))
    tensile = np.zeros(m)
    for k, spec in enumerate(specs):
        spec = spec or {"model": "none"}
        name = spec.get("model", "none")
        if name not in MODEL_CODES:
            raise ValueError(f"material {k}: unknown strength model {name!r} (allowed: {', '.join(MODEL_CODES)})")
        tensile[k] = float(spec.get("Y_T", 0.0))
        if tensile[k] < 0.0:
            raise ValueError(f"material {k}: Y_T must be >= 0 (got {tensile[k]:g})")
        for slot, key in _KEYS.items():
            if key in spec:
                params[k, slot] = float(spec[key])
        check_inertial_friction(spec, f"material {k}")
        if not has_yield(spec):
            continue
        model[k] = MODEL_CODES[name]
        if name != "von_mises" and params[k, Y_M] < params[k, Y0]:
            raise ValueError(f"material {k}: Y_M ({params[k, Y_M]:g}) must be >= Y0 ({params[k, Y0]:g})")
        if "shear_modulus" in spec:
            shear[k, 0] = float(spec["shear_modulus"])
        else:
            shear[k, 1] = shear_ratio(float(spec["poisson"]))
    return StrengthArrays(model, params, shear, tensile)


INSTANT = 0
GRADY_KIPP = 1
DAMAGE_CODES = {"instant": INSTANT, "grady_kipp": GRADY_KIPP}

# damage parameter row slots: Weibull m, k, Young's modulus, the active-flaw limit (1 on, 0 off),
# then the FLAW_NODES node strains' eps_j^m of the cumulative flaw law (impactpipe.hydro.strength.flaws)
WEIBULL_M, WEIBULL_K, YOUNG, ACTIVE_LIMIT, NODE0 = range(5)
FLAW_NODES = 8
NDAMAGE = NODE0 + FLAW_NODES


class DamageArrays(NamedTuple):
    """Tensile-fracture parameters of M materials for the kernels.

    model: (M,) int64 damage model codes (INSTANT, GRADY_KIPP); params: (M, NDAMAGE) rows of
    Weibull m (-), Weibull k (m^-3), Young's modulus E (Pa; 0: E = 9 K G / (3 K + G) from
    the cell's moduli, :func:`impactpipe.hydro.strength.fracture.young_modulus`), the active-flaw
    limit (1: D <= n_act / n_tot, Benz & Asphaug 1995, ``active_flaw_limit``, the default; 0: none;
    :func:`impactpipe.hydro.strength.fracture.active_fraction`) and the
    FLAW_NODES node strains eps_j^m of the flaw law (``flaw_strains`` eps_j; zeros until the
    flaws are drawn, :class:`impactpipe.hydro.strength.model.MaterialStrength`); seed: (M,)
    int64 seed of each material's flaw draw (``flaw_seed``, default 0); flaw_count: (M,) int64
    number of flaws drawn for each material (``flaw_count``; 0: N ln N for its N cells,
    :func:`impactpipe.hydro.strength.flaws.default_flaw_count`); cross_section: (M,) the area (m^2)
    of the bar a 1-D mesh stands for in the flaw draw (``flaw_cross_section``, default 1): a 1-D
    cell of width dx holds the flaws of the volume dx A.
    """

    model: np.ndarray
    params: np.ndarray
    seed: np.ndarray
    flaw_count: np.ndarray
    cross_section: np.ndarray

    @property
    def fracture(self) -> bool:
        """True when some material's tensile damage follows Grady-Kipp (flaws are carried)."""
        return bool((self.model == GRADY_KIPP).any())


def pack_damage(specs: list[dict | None]) -> DamageArrays:
    """Pack resolved damage blocks (one per material, None = instant tensile failure) into
    :class:`DamageArrays`; raises ValueError for an unknown model or a parameter out of range
    (m > 0, k > 0, E >= 0, flaw_seed >= 0, flaw_count >= 0, flaw_cross_section > 0)."""
    m = len(specs)
    model = np.zeros(m, dtype=np.int64)
    params = np.zeros((m, NDAMAGE))
    seed = np.zeros(m, dtype=np.int64)
    flaw_count = np.zeros(m, dtype=np.int64)
    cross_section = np.ones(m)
    for k, spec in enumerate(specs):
        spec = spec or {"model": "instant"}
        name = spec.get("model", "instant")
        if name not in DAMAGE_CODES:
            raise ValueError(f"material {k}: unknown damage model {name!r} (allowed: {', '.join(DAMAGE_CODES)})")
        model[k] = DAMAGE_CODES[name]
        if model[k] == INSTANT:
            continue
        for slot, key in ((WEIBULL_M, "weibull_m"), (WEIBULL_K, "weibull_k")):
            if key not in spec:
                raise ValueError(f"material {k}: damage model {name} needs {key}")
            params[k, slot] = float(spec[key])
            if params[k, slot] <= 0.0:
                raise ValueError(f"material {k}: {key} must be > 0 (got {params[k, slot]:g})")
        params[k, YOUNG] = float(spec.get("young_modulus", 0.0))
        if params[k, YOUNG] < 0.0:
            raise ValueError(f"material {k}: young_modulus must be >= 0 (got {params[k, YOUNG]:g})")
        params[k, ACTIVE_LIMIT] = 1.0 if spec.get("active_flaw_limit", True) else 0.0
        seed[k] = int(spec.get("flaw_seed", 0))
        flaw_count[k] = int(spec.get("flaw_count", 0))
        for key, value in (("flaw_seed", seed[k]), ("flaw_count", flaw_count[k])):
            if value < 0:
                raise ValueError(f"material {k}: {key} must be >= 0 (got {value})")
        if "flaw_strains" in spec:
            strains = np.asarray(spec["flaw_strains"], dtype=float)
            if strains.shape != (FLAW_NODES,) or not (strains > 0.0).all() or not (np.diff(strains) > 0.0).all():
                raise ValueError(f"material {k}: flaw_strains must be {FLAW_NODES} increasing strains > 0")
            params[k, NODE0:] = strains ** params[k, WEIBULL_M]
        cross_section[k] = float(spec.get("flaw_cross_section", 1.0))
        if not cross_section[k] > 0.0:
            raise ValueError(f"material {k}: flaw_cross_section must be > 0 (got {cross_section[k]:g})")
    return DamageArrays(model, params, seed, flaw_count, cross_section)
