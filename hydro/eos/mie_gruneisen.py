"""Mie-Grueneisen equation of state referenced to a linear U_s-u_p Hugoniot.

Reference curve: the principal Hugoniot of a material with U_s = c0 + s u_p, centred on
(rho0, e = 0, P = 0).  With mu = rho/rho0 - 1 and rho Gamma = rho0 Gamma0:

    compression (mu >= 0):  P_H = rho0 c0^2 mu (1 + mu) / (1 - (s - 1) mu)^2
    expansion   (mu <  0):  P_H = rho0 c0^2 mu
    e_H = P_H (1/rho0 - 1/rho) / 2 = P_H mu / (2 rho0 (1 + mu))      (J/kg)
    P   = P_H + rho0 Gamma0 (e - e_H)                                   (Pa)

Derivatives used for the bulk sound speed c_K^2 = dP/drho|_e + (P/rho^2) dP/de|_rho:

    dP_H/drho = c0^2 (1 + (s + 1) mu) / (1 - (s - 1) mu)^3   (compression)
              = c0^2                                          (expansion)
    de_H/drho = (dP_H/drho) (1/rho0 - 1/rho) / 2 + P_H / (2 rho^2)
    dP/drho|_e = dP_H/drho - rho0 Gamma0 de_H/drho,   dP/de|_rho = rho0 Gamma0

The linear Hugoniot is singular at mu = 1/(s - 1) (rho/rho0 = s/(s - 1)).  Compressions
beyond ``MU_LIMIT_FRACTION / (s - 1)`` are clamped to that value and flagged (flag = 1).

Temperature (approximation): T = T_ref + (e - e_H(rho)) / c_v, i.e. the thermal energy is
measured from the reference Hugoniot with a constant specific heat.  On the Hugoniot
itself this gives T = T_ref, so it does not give shock temperatures; it gives the
heating left after release to rho0 (where e_H = 0).  Floored at ``T_FLOOR``.

Parameter row layout (``params[k]``, float64):

====  ========  ===========================================
slot  name      meaning
====  ========  ===========================================
0     rho0      reference density (kg/m^3)
1     c0        bulk sound speed intercept of U_s(u_p) (m/s)
2     s         slope of U_s(u_p) (-)
3     gamma0    Grueneisen parameter at rho0 (-)
4     cv        specific heat (J/kg/K)
5     T_ref     temperature at rho0, e = 0 (K)
====  ========  ===========================================
"""

from numba import njit

RHO0 = 0
C0 = 1
S = 2
GAMMA0 = 3
CV = 4
T_REF = 5

#: Largest compression used, as a fraction of the Hugoniot singularity mu = 1/(s - 1).
MU_LIMIT_FRACTION = 0.95
#: Floor on c_K^2 as a fraction of c0^2 (reached only in strong tension).
C2_FLOOR_FRACTION = 1.0e-2
#: Floor on the temperature (K).
T_FLOOR = 1.0


@njit(cache=True)
def mie_gruneisen_hugoniot(params, rho):
    """Reference Hugoniot at density rho (kg/m^3).

    Returns (P_H (Pa), e_H (J/kg), dP_H/drho (m^2/s^2), de_H/drho (J m^3/kg^2), flag),
    flag = 1 when the compression was clamped at ``MU_LIMIT_FRACTION / (s - 1)``.
    """
    rho0 = params[RHO0]
    c0 = params[C0]
    s = params[S]
    flag = 0
    mu = rho / rho0 - 1.0
    if mu >= 0.0:
        if s > 1.0 and mu > MU_LIMIT_FRACTION / (s - 1.0):
            mu = MU_LIMIT_FRACTION / (s - 1.0)
            flag = 1
        denom = 1.0 - (s - 1.0) * mu
        p_h = rho0 * c0 * c0 * mu * (1.0 + mu) / (denom * denom)
        dp_h = c0 * c0 * (1.0 + (s + 1.0) * mu) / (denom * denom * denom)
    else:
        p_h = rho0 * c0 * c0 * mu
        dp_h = c0 * c0
    rho_h = rho0 * (1.0 + mu)
    dv = 1.0 / rho0 - 1.0 / rho_h
    e_h = 0.5 * p_h * dv
    de_h = 0.5 * dp_h * dv + 0.5 * p_h / (rho_h * rho_h)
    return p_h, e_h, dp_h, de_h, flag


@njit(cache=True)
def mie_gruneisen_pressure_sound_speed(params, rho, e):
    """Pressure P (Pa), c_K^2 (m^2/s^2) and clamp flag at (rho kg/m^3, e J/kg).

    P = P_H + rho0 Gamma0 (e - e_H); c_K^2 = dP/drho|_e + (P/rho^2) rho0 Gamma0, floored at
    ``C2_FLOOR_FRACTION * c0^2``.
    """
    p_h, e_h, dp_h, de_h, flag = mie_gruneisen_hugoniot(params, rho)
    g = params[RHO0] * params[GAMMA0]
    p = p_h + g * (e - e_h)
    c2 = dp_h - g * de_h + p / (rho * rho) * g
    c2_floor = C2_FLOOR_FRACTION * params[C0] * params[C0]
    if c2 < c2_floor:
        c2 = c2_floor
    return p, c2, flag


@njit(cache=True)
def mie_gruneisen_temperature(params, rho, e):
    """Temperature T = T_ref + (e - e_H(rho)) / c_v (K), floored at ``T_FLOOR``."""
    e_h = mie_gruneisen_hugoniot(params, rho)[1]
    t = params[T_REF] + (e - e_h) / params[CV]
    if t < T_FLOOR:
        t = T_FLOOR
    return t


@njit(cache=True)
def mie_gruneisen_energy_from_pressure(params, rho, p):
    """Specific internal energy e = e_H + (P - P_H) / (rho0 Gamma0) (J/kg); exact inverse."""
    p_h, e_h, dp_h, de_h, flag = mie_gruneisen_hugoniot(params, rho)
    return e_h + (p - p_h) / (params[RHO0] * params[GAMMA0])
