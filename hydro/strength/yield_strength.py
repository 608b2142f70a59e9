"""Yield strength Y(P, T, D) of the von Mises, GEO and ROCK models (Collins, Melosh & Ivanov 2004 form).

Conventions (docs/strength.md): the von Mises model's Y is the uniaxial yield stress, the
material yields where the equivalent stress sqrt(3 J2) = sqrt(3/2 S:S) reaches Y; the GEO and
ROCK models' Y is the Collins, Melosh & Ivanov (2004) strength in the form of method.md,
compared with sqrt(J2), so their yield surface is sqrt(3 J2) = sqrt(3) Y
(:func:`equivalent_yield_stress`).  P is the material pressure (Pa, compression > 0),
T its temperature (K), D its damage (0 intact, 1 fully damaged).

- intact (Lundborg):      Y_i = Y0 + mu_i P / (1 + mu_i P / (Y_M - Y0))      (P >= 0)
- damaged (dry friction): Y_d = min(Y_c + mu_d P, Y_i)                        (P >= 0)
- tension (P < 0):        both fall linearly to zero at the tensile limit P = -Y_T (1 - D):
                          Y(P) = Y(0) (1 + P / (Y_T (1 - D))), 0 below (failed material,
                          D = 1, has no strength in tension)
- GEO:   Y = Y_i;  ROCK: Y = (1 - D) Y_i + D Y_d;  von Mises: Y = yield_strength
- thermal softening (GEO, ROCK): Y -> Y tanh(xi (T_melt / T - 1)), zero at and above T_melt.
- GEO with the optional mu(I) friction (``mu_2``, ``inertial_number_I0``, ``grain_diameter``;
  Jop, Forterre & Pouliquen 2006, Nature 441, 727): mu_i in Y_i is replaced by
  mu(I) = mu_s + (mu_2 - mu_s) / (I0 / I + 1), mu_s = mu_i, with the inertial number
  I = gamma_dot d / sqrt(P / rho_s) (:func:`inertial_friction`, evaluated by the strength
  update, which knows the strain rate; :func:`yield_strength_friction` takes the friction).

The parameter row is :mod:`impactpipe.hydro.strength.parameters`' ``params[k]``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from impactpipe.hydro.strength.parameters import (
    GEO, MU_D, MU_I, ROCK, T_MELT, VON_MISES, XI, Y0, Y_C, Y_M, Y_T, YIELD_VM,
)

#: sqrt(3), the ratio of the von Mises equivalent stress sqrt(3 J2) to sqrt(J2).
SQRT3 = 1.7320508075688772


@njit(cache=True, inline="always")
def lundborg_intact(pressure, y0, y_m, mu_i):
    """Intact yield strength Y_i = Y0 + mu_i P / (1 + mu_i P / (Y_M - Y0)) (Pa) for P >= 0.

    Y_M <= Y0 gives the constant Y_M (a cap below the cohesion); P < 0 gives Y0.
    """
    if y_m <= y0:
        return y_m
    if pressure <= 0.0:
        return y0
    return y0 + mu_i * pressure / (1.0 + mu_i * pressure / (y_m - y0))


@njit(cache=True, inline="always")
def damaged_friction(pressure, y_c, mu_d, intact):
    """Damaged yield strength Y_d = min(Y_c + mu_d max(P, 0), Y_i) (Pa)."""
    y = y_c + mu_d * max(pressure, 0.0)
    return min(y, intact)


@njit(cache=True, inline="always")
def tensile_taper(pressure, tensile_strength):
    """Factor of the zero-pressure strength left in tension: 1 + P / Y_T for -Y_T < P < 0, 0 below, 1 for P >= 0."""
    if pressure >= 0.0:
        return 1.0
    if tensile_strength <= 0.0 or pressure <= -tensile_strength:
        return 0.0
    return 1.0 + pressure / tensile_strength


@njit(cache=True, inline="always")
def thermal_softening(temperature, t_melt, xi):
    """Softening factor tanh(xi (T_melt / T - 1)) for T < T_melt, 0 at and above T_melt."""
    if temperature >= t_melt or temperature <= 0.0:
        return 0.0
    return np.tanh(xi * (t_melt / temperature - 1.0))


@njit(cache=True, inline="always")
def inertial_friction(mu_s, mu_2, i0, grain_diameter, shear_rate, pressure, density):
    """The mu(I) friction coefficient (-) of a dense granular flow (Jop, Forterre & Pouliquen 2006):

        mu(I) = mu_s + (mu_2 - mu_s) / (I0 / I + 1),    I = gamma_dot d / sqrt(P / rho_s)

    ``shear_rate`` gamma_dot (1/s) = sqrt(2 D_dev:D_dev) = 2 sqrt(J2(D_dev)) (D the strain rate,
    the convention under which sqrt(J2(S)) <= mu P is |tau| <= mu P in simple shear, where
    gamma_dot = dv_x / dy), ``grain_diameter`` d (m), ``pressure`` P (Pa) and ``density`` rho_s
    (kg/m^3) the grains' (the material's).  mu_s at rest (I = 0), mu_2 as I -> infinity,
    (mu_s + mu_2) / 2 at I = I0.  P <= 0 gives mu_s (a cohesionless material has no strength
    there whatever its friction).
    """
    if pressure <= 0.0 or shear_rate <= 0.0:
        return mu_s
    inertial = shear_rate * grain_diameter * math.sqrt(density / pressure)
    return mu_s + (mu_2 - mu_s) / (i0 / inertial + 1.0)


@njit(cache=True)
def yield_strength(model, params, pressure, temperature, damage):
    """Yield strength Y(P, T, D) (Pa, von Mises equivalent stress) of one material; see the module docstring."""
    return yield_strength_friction(model, params, pressure, temperature, damage, params[MU_I])


@njit(cache=True)
def yield_strength_friction(model, params, pressure, temperature, damage, mu_i):
    """:func:`yield_strength` with the intact friction coefficient ``mu_i`` (-) given instead of
    the row's (the GEO model's mu(I), :func:`inertial_friction`)."""
    if model == VON_MISES:
        return params[YIELD_VM]
    if model != GEO and model != ROCK:
        return 0.0
    intact = lundborg_intact(pressure, params[Y0], params[Y_M], mu_i)
    if model == ROCK:
        damaged = damaged_friction(pressure, params[Y_C], params[MU_D], intact)
        d = min(max(damage, 0.0), 1.0)
        y = (1.0 - d) * intact + d * damaged
    else:
        y = intact
    if pressure < 0.0:
        y *= tensile_taper(pressure, params[Y_T] * (1.0 - min(max(damage, 0.0), 1.0)))
    return y * thermal_softening(temperature, params[T_MELT], params[XI])


@njit(cache=True, inline="always")
def equivalent_yield_stress(model, strength):
    """The von Mises equivalent stress sqrt(3 J2) (Pa) at which material of ``model`` yields.

    von Mises: Y itself (uniaxial yield stress).  GEO and ROCK: sqrt(3) Y, since their Y bounds
    sqrt(J2) (the reference study's convention; docs/strength.md).  Reading the presets as
    sqrt(3 J2) <= Y instead lowers case 8c's M_lr/M_T well below the published value
    (docs/validation.md, "The yield convention").
    """
    if model == GEO or model == ROCK:
        return SQRT3 * strength
    return strength
