"""Porous materials: the epsilon-alpha compaction model (Wuennemann, Collins & Melosh 2006;
Collins, Melosh & Wuennemann 2011).

A porous material is its solid matrix (any EOS of :mod:`impactpipe.hydro.eos`) with pores.
Its distension alpha = rho_s / rho >= 1 (rho the bulk, distended density, rho_s the matrix
density; porosity phi = 1 - 1 / alpha) sets its state:

    P(rho, e, alpha)   = P_s(alpha rho, e) / alpha                         (Pa)
    c^2(rho, e, alpha) = dP/drho|_(e, alpha) + (P / rho^2) dP/de|_(rho, alpha)
                       = c_s^2(alpha rho, e)                               (m^2/s^2)

(:func:`impactpipe.hydro.scheme.mixture.material_state` with its ``distension``, and the
kernels that call the EOS in place; the second line is exact for any solid EOS at fixed
alpha: the split scheme advances the flow at frozen alpha, so this is the stiffness the
sweeps and the time step see).  The distension falls irreversibly with the volumetric
strain eps_v = ln(V / V_0) of the porous material (negative in compression):

    alpha(eps_v) = alpha_0                                          eps_v >= eps_e  (elastic)
                 = alpha_0 exp(kappa (eps_v - eps_e))               eps_x <= eps_v < eps_e
                 = 1 + (alpha_x - 1) ((eps_c - eps_v) / (eps_c - eps_x))^2
                                                                    eps_c <= eps_v < eps_x
                 = 1                                                eps_v < eps_c

with eps_x = eps_e + ln(alpha_x / alpha_0) / kappa (where the exponential reaches alpha_x)
and eps_c = eps_x + 2 (1 - alpha_x) / (kappa alpha_x) (full compaction, placed so that
d alpha / d eps_v is continuous at eps_x), Wuennemann et al. (2006) eqs. (8)-(10)
(:func:`distension_of_strain`).  A material element's strain is eps_v = ln(rho_00 / rho),
rho_00 = rho_s0 / alpha_0 the bulk density of the unstrained porous material (kg/m^3): the
integral of d eps_v = -d rho / rho along the element's path.  After each step's sweeps,
:func:`compact` sets alpha <- min(alpha, alpha(eps_v)) per material and cell: the pores close
under compression and never reopen (alpha never increases; a material unloaded or in
tension keeps its distension, and compresses again elastically, at frozen alpha, until its
strain passes the largest compression it has seen).

The distension rides with the material as the mass-weighted amount alpha_k rho_k alpha_dist,k
in the second-to-last transported scalar of the material (``arhoq``, :func:`distension_slot`;
the damage stays in the last), so the sweeps, the AMR transfers, the regrid, the ghosts and
the checkpoints carry it as they carry the strength scalars.  A material without porosity
has alpha = 1 there.

Elastic compaction (Collins, Melosh & Wuennemann 2011): with ``chi`` < 1 the unstrained porous
material's elastic (bulk) wave speed is chi c_s0, c_s0 (m/s) the matrix's sound speed at rho_s0
and e = 0, and in the elastic regime the distension follows the strain reversibly,

    d alpha / d eps_v = alpha (1 - (c(alpha) / c_s0)^2),    c(alpha) = c_s0 h(alpha),
    h(alpha) = 1 + (chi - 1) (alpha - 1) / (alpha_0 - 1)                (-)

(c interpolated linearly in alpha between chi c_s0 at alpha_0 and c_s0 at alpha = 1), so that
dP/drho = c_s0^2 (1 + (rho / alpha) d alpha / d rho) = c(alpha)^2 at rest: a weak wave runs at
chi c_s0.  Integrated from alpha_0 at eps_v = 0 (partial fractions, :func:`elastic_strain`):

    eps_el(alpha) = -(1/s) [ ln(alpha / alpha_0) / (s u) + ln((alpha - 1) / (alpha_0 - 1)) / 2
                             - ln((u - alpha) / (u - alpha_0)) / (2 u) ],
    s = (chi - 1) / (alpha_0 - 1),  u = 1 - 2 / s,

inverted by Newton's method (:func:`elastic_distension`).  The exponential and power-law
branches then start from alpha_e = alpha_el(eps_e) in place of alpha_0 (alpha_e = alpha_0
for chi = 1, where the elastic regime keeps alpha_0).  Elastic compaction is reversible:
:func:`compact` sets alpha <- alpha(eps_v) while alpha >= alpha_e (the material has not passed
eps_e) and keeps the min rule below.  The same h(alpha) scales the porous material's
shear modulus through its bulk modulus, G = G_0 + (G/K) rho c_s^2(alpha rho, e) h(alpha)^2
(:mod:`impactpipe.hydro.strength.update`).  Without ``chi`` (chi = 1) nothing of this runs and
the model is the one above, bit for bit.

Parameters per material (``porosity`` key of a resolved EOS spec): ``alpha0`` (>= 1; 1 is no
porosity), ``eps_e`` (<= 0), ``kappa`` (> 0), ``alpha_x`` (1 <= alpha_x <= alpha_e) and
optionally ``chi`` (0 < chi <= 1, default 1).
"""

from __future__ import annotations

import math
import numbers

import numpy as np
from numba import njit, prange

from impactpipe.hydro.eos import reference_density
from impactpipe.hydro.mesh.blocks import ghost_widths

# row slots of the packed parameters (``porosity[M, NPOROSITY]``)
ALPHA0 = 0      # initial distension alpha_0 (-)
EPS_E = 1       # elastic volumetric strain limit eps_e (-)
KAPPA = 2       # exponential compaction rate kappa (-)
ALPHA_X = 3     # transition distension alpha_x (-)
EPS_X = 4       # strain where alpha reaches alpha_x (-), derived
EPS_C = 5       # strain of full compaction (-), derived
RHO00 = 6       # bulk density of the unstrained porous material rho_s0 / alpha_0 (kg/m^3), derived
CHI = 7         # ratio chi = c_e / c_s0 of the unstrained porous material's elastic wave speed to the matrix's (-)
ALPHA_E = 8     # distension at the elastic limit, alpha_el(eps_e) (-), derived (alpha_0 for chi = 1)
NPOROSITY = 9
#: Newton iterations of :func:`elastic_distension` (from the first-order guess, the error after
#: three is below 1e-15 for |eps_v| <= 0.01).
ELASTIC_NEWTON = 4

#: Keys of a porosity spec: (key, check, what the check demands).
KEYS = (
    ("alpha0", lambda v: v >= 1.0, "must be >= 1"),
    ("eps_e", lambda v: v <= 0.0, "must be <= 0"),
    ("kappa", lambda v: v > 0.0, "must be > 0"),
    ("alpha_x", lambda v: v >= 1.0, "must be >= 1"),
)
#: Optional keys of a porosity spec: (key, default, check, what the check demands).
OPTIONAL_KEYS = (
    ("chi", 1.0, lambda v: 0.0 < v <= 1.0, "must be > 0 and <= 1"),
)
#: Counter of :func:`compact`: cells where the transported distension was below 1 (round-off of
#: the transport) and was set to 1, or, in a trace of mass without volume, above alpha_0 and was
#: set to alpha_0.
COUNT_NAMES = ("distension_floor",)


def initial_distension(spec: dict) -> float:
    """The initial distension alpha_0 (-) of a resolved EOS spec, 1 without porosity."""
    block = spec.get("porosity")
    return float(block["alpha0"]) if block else 1.0


def pack_porosity(specs: list[dict], eos) -> np.ndarray | None:
    """The (M, NPOROSITY) parameter rows of the materials' porosity, or None when no material is porous.

    ``specs`` are the resolved EOS specs (their ``porosity`` blocks), ``eos`` their packed
    :class:`impactpipe.hydro.eos.EOSArrays` (for the solid reference densities).  A material
    without porosity gets alpha0 = alpha_x = 1, which :func:`compact` leaves alone.  Raises
    ValueError naming the material and key when a key is missing, unknown or out of range.
    """
    if not any(s.get("porosity") for s in specs):
        return None
    rows = np.zeros((len(specs), NPOROSITY))
    for k, spec in enumerate(specs):
        rho_s0 = float(reference_density(eos.kind[k], eos.params[k], eos.table))
        block = spec.get("porosity")
        if not block:
            rows[k, [ALPHA0, ALPHA_X, KAPPA, CHI, ALPHA_E]] = 1.0
            rows[k, RHO00] = rho_s0
            continue
        name = f"material {k} porosity"
        known = [key for key, *_ in KEYS] + [key for key, *_ in OPTIONAL_KEYS]
        for key in block:
            if key not in known:
                raise ValueError(f"{name}: unknown key {key!r} (known: {known})")
        values = {}
        checks = [(key, None, check, demand) for key, check, demand in KEYS] + list(OPTIONAL_KEYS)
        for key, default, check, demand in checks:
            if key not in block:
                if default is None:
                    raise ValueError(f"{name}: missing key {key!r}")
                values[key] = default
                continue
            value = block[key]
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
                raise ValueError(f"{name}: key {key!r} must be a finite number, got {value!r}")
            if not check(float(value)):
                raise ValueError(f"{name}: key {key!r} {demand}, got {value!r}")
            values[key] = float(value)
        if values["alpha_x"] > values["alpha0"]:
            raise ValueError(f"{name}: key 'alpha_x' must be <= alpha0 = {values['alpha0']:g}, "
                             f"got {values['alpha_x']!r}")
        if values["alpha0"] > 1.0 and not rho_s0 > 0.0:
            raise ValueError(f"{name}: a porous material needs a solid EOS with a reference density (not an ideal gas)")
        rows[k, ALPHA0] = values["alpha0"]
        rows[k, EPS_E] = values["eps_e"]
        rows[k, KAPPA] = values["kappa"]
        rows[k, ALPHA_X] = values["alpha_x"]
        rows[k, CHI] = values["chi"]
        alpha_e = values["alpha0"]
        if values["chi"] != 1.0 and values["alpha0"] > 1.0:
            alpha_e = elastic_distension(rows[k], values["eps_e"])
            if values["alpha_x"] > alpha_e:
                raise ValueError(f"{name}: key 'alpha_x' must be <= the distension at the elastic limit "
                                 f"alpha_e = {alpha_e:.10g} (chi = {values['chi']:g}), got {values['alpha_x']!r}")
        rows[k, ALPHA_E] = alpha_e
        eps_x = values["eps_e"] + math.log(values["alpha_x"] / alpha_e) / values["kappa"]
        rows[k, EPS_X] = eps_x
        rows[k, EPS_C] = eps_x + 2.0 * (1.0 - values["alpha_x"]) / (values["kappa"] * values["alpha_x"])
        rows[k, RHO00] = rho_s0 / values["alpha0"]
    return rows if (rows[:, ALPHA0] > 1.0).any() else None


def distension_slot(nq: int) -> int:
    """Index (within a material's ``nq`` transported scalars) of the distension amount: second to last."""
    return nq - 2


def distension_field(arho: np.ndarray, arhoq: np.ndarray, porosity: np.ndarray) -> np.ndarray:
    """Mass-weighted distension (-) of the porous materials per cell, 0 where there are none:
    sum_k alpha_k rho_k alpha_dist,k / sum_k alpha_k rho_k over the porous k.  ``arho`` (NB, M, ...)
    and ``arhoq`` (NB, M NQ, ...) any matching cell selection, ``porosity`` the packed rows."""
    nmat = arho.shape[1]
    nq = arhoq.shape[1] // nmat
    amount = np.zeros(arho[:, 0].shape)
    mass = np.zeros_like(amount)
    for k in np.flatnonzero(porosity[:, ALPHA0] > 1.0):
        amount += arhoq[:, nq * k + distension_slot(nq)]
        mass += arho[:, k]
    return np.where(mass > 0.0, amount / np.where(mass > 0.0, mass, 1.0), 0.0)


@njit(cache=True, inline="always")
def wave_speed_ratio(row, alpha):
    """h(alpha) = c(alpha) / c_s0 = 1 + (chi - 1) (alpha - 1) / (alpha_0 - 1) (-): the porous material's
    elastic wave speed over the matrix's (Collins et al. 2011; module docstring); 1 for chi = 1."""
    if row[CHI] == 1.0:
        return 1.0
    return 1.0 + (row[CHI] - 1.0) * (alpha - 1.0) / (row[ALPHA0] - 1.0)


@njit(cache=True, inline="always")
def elastic_strain(row, alpha):
    """eps_el(alpha) (-): the volumetric strain at which elastic compaction (chi < 1, alpha_0 > 1)
    has brought the distension from alpha_0 to ``alpha`` (1 < alpha <= alpha_0); the integral of
    d eps_v = d alpha / (alpha (1 - h(alpha)^2)) from alpha_0 (module docstring)."""
    a0 = row[ALPHA0]
    s = (row[CHI] - 1.0) / (a0 - 1.0)
    u = 1.0 - 2.0 / s
    return -(math.log(alpha / a0) / (s * u) + 0.5 * math.log((alpha - 1.0) / (a0 - 1.0))
             - 0.5 * math.log((u - alpha) / (u - a0)) / u) / s


@njit(cache=True, inline="always")
def elastic_distension(row, eps_v):
    """alpha_el(eps_v) (-), the inverse of :func:`elastic_strain` for eps_v <= 0: Newton's method
    (ELASTIC_NEWTON steps, d eps_el / d alpha = 1 / (alpha (1 - h^2))) from the first-order
    alpha_0 exp((1 - chi^2) eps_v)."""
    chi = row[CHI]
    alpha = row[ALPHA0] * math.exp((1.0 - chi * chi) * eps_v)
    for _ in range(ELASTIC_NEWTON):
        h = wave_speed_ratio(row, alpha)
        alpha -= (elastic_strain(row, alpha) - eps_v) * alpha * (1.0 - h * h)
    return alpha


@njit(cache=True, inline="always")
def distension_of_strain(row, eps_v):
    """alpha(eps_v) (-) of the epsilon-alpha model (module docstring) for the parameter row ``row``:
    alpha_0 for eps_v >= 0, the elastic curve alpha_el(eps_v) down to eps_e (alpha_0 throughout
    for chi = 1), then the exponential and power-law branches from alpha_e."""
    if eps_v >= row[EPS_E]:
        if row[CHI] == 1.0 or eps_v >= 0.0:
            return row[ALPHA0]
        return elastic_distension(row, eps_v)
    if eps_v >= row[EPS_X]:
        return row[ALPHA_E] * math.exp(row[KAPPA] * (eps_v - row[EPS_E]))
    if eps_v >= row[EPS_C]:
        x = (row[EPS_C] - eps_v) / (row[EPS_C] - row[EPS_X])
        return 1.0 + (row[ALPHA_X] - 1.0) * x * x
    return 1.0


@njit(cache=True, inline="always")
def cell_distension(arhoq, nq, b, k, ix, iy, iz, ar):
    """Distension alpha_k (-) of material k in a cell from its transported amount (``ar`` = alpha_k rho_k > 0)."""
    return arhoq[b, nq * k + nq - 2, ix, iy, iz] / ar


@njit(cache=True, parallel=True)
def compact(alpha, arho, arhoq, porosity, counts, lo, hi):
    """Compaction step for the interior cells of the blocks ``lo .. hi - 1``: for every porous
    material present (alpha_k > 0, alpha_k rho_k > 0), alpha <- max(1, min(alpha, alpha(eps_v)))
    with eps_v = ln(rho_00 / rho_k), rho_k = alpha_k rho_k / alpha_k (module docstring); with
    chi < 1 a material still in its elastic regime (alpha >= alpha_e) takes alpha(eps_v) itself
    (reversible elastic compaction).

    ``porosity`` (M, NPOROSITY) the packed parameters; the distension amounts are the
    second-to-last of each material's transported scalars in ``arhoq``.  A transported
    distension below 1 (a mixture of round-off, or a round-off trace of mass without volume,
    alpha_k = 0 < alpha_k rho_k, that arrived without its distension) is set to 1, and that of
    such a trace above alpha_0 (the ratio of two round-off amounts) to alpha_0, each counted in
    ``counts[b, 0]``.
    """
    nb, nmat, nx, ny, nz = alpha.shape
    nq = arhoq.shape[1] // nmat
    gx, gy, gz = ghost_widths(nx, ny, nz)
    for b in prange(lo, hi):
        for k in range(nmat):
            row = porosity[k]
            if row[ALPHA0] <= 1.0:
                continue
            slot = nq * k + nq - 2
            for ix in range(gx, nx - gx):
                for iy in range(gy, ny - gy):
                    for iz in range(gz, nz - gz):
                        a = alpha[b, k, ix, iy, iz]
                        ar = arho[b, k, ix, iy, iz]
                        if not ar > 0.0:
                            continue
                        dist = arhoq[b, slot, ix, iy, iz] / ar
                        if dist < 1.0:
                            dist = 1.0
                            counts[b, 0] += 1
                        elif a > 0.0:
                            curve = distension_of_strain(row, math.log(row[RHO00] * a / ar))
                            if row[CHI] != 1.0 and dist >= row[ALPHA_E]:
                                dist = max(1.0, curve)
                            else:
                                dist = max(1.0, min(dist, curve))
                        elif dist > row[ALPHA0]:
                            dist = row[ALPHA0]
                            counts[b, 0] += 1
                        arhoq[b, slot, ix, iy, iz] = ar * dist
