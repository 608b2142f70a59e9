"""Tillotson equation of state (method.md section 2.1), with analytic derivatives.

With eta = rho/rho0, mu = eta - 1, nu = 1/eta - 1 and omega = E/(E0 eta^2) + 1
(rho in kg/m^3, E specific internal energy in J/kg, A, B in Pa, E0, E_iv, E_cv in J/kg):

    P1 = (a + b/omega) rho E + A mu + B mu^2                              compressed / cold expanded
    P2 = a rho E + (b rho E / omega + A mu exp(-beta nu)) exp(-alpha nu^2)  hot expanded
    P3 = (P2 (E - E_iv) + P1 (E_cv - E)) / (E_cv - E_iv)                    mixed
    P4 = (a + b/omega) rho E + A mu                                        cold expanded, rho < rho_iv

Branch selection (``tillotson_branch``):

    rho >= rho0                                  -> P1
    rho <  rho0 and E >= E_cv                    -> P2
    rho_iv <= rho < rho0 and E <= E_iv           -> P1
    rho_iv <= rho < rho0 and E_iv < E < E_cv     -> P3
    rho <  rho_iv and E < E_cv                   -> P4

Without an incipient-vaporisation density (rho_iv = 0) this is the classic three-region
form.  P is continuous across rho = rho0 and across E = E_iv, E_cv in the mixed region; it
is *not* continuous across rho = rho_iv (jump B mu_iv^2 for E <= E_iv) nor across E = E_cv
below rho_iv (P4 to P2): that is the published form.

Bulk sound speed c_K^2 = dP/drho|_E + (P/rho^2) dP/dE|_rho from the analytic derivatives
of the branch in use (the mixed branch differentiates P3 itself, so c_K^2 is consistent
with P everywhere; it is continuous across rho0 and jumps where P has a kink or a jump).
Floored at ``C2_FLOOR_FRACTION * A / rho0`` (A/rho0 is c_K^2 of the cold material at rho0).
Tensile (negative) pressures are returned unchanged.

Temperature (approximation: constant specific heat, cold energy from the elastic terms):

    e_cold(rho) = [A (ln eta + 1/eta - 1) + B (eta - 2 ln eta - 1/eta)] / rho0
                = integral_{rho0}^{rho} (A mu + B mu^2) / rho'^2 drho'        (J/kg)
    T = T_ref + (E - e_cold(rho)) / c_v,   floored at ``T_FLOOR``               (K)

e_cold grows like A/(rho0 eta) as eta -> 0, so strongly expanded cold states reach the
floor: temperatures below about rho_iv (or rho0/2 without rho_iv) are not meaningful.

Parameter row layout (``params[k]``, float64):

====  ========  ====================================================
slot  name      meaning
====  ========  ====================================================
0     rho0      reference density (kg/m^3)
1     A         bulk modulus term (Pa)
2     B         non-linear compression term (Pa)
3     E0        reference specific energy (J/kg)
4     E_iv      specific energy of incipient vaporisation (J/kg)
5     E_cv      specific energy of complete vaporisation (J/kg)
6     a         (-)
7     b         (-)
8     alpha     (-)
9     beta      (-)
10    rho_iv    incipient-vaporisation density (kg/m^3), 0 = none
11    cv        specific heat (J/kg/K)
12    T_ref     temperature at rho0, E = 0 (K)
====  ========  ====================================================
"""

import math

from numba import njit

RHO0 = 0
A = 1
B = 2
E0 = 3
E_IV = 4
E_CV = 5
A_SMALL = 6
B_SMALL = 7
ALPHA = 8
BETA = 9
RHO_IV = 10
CV = 11
T_REF = 12

COMPRESSED = 1
HOT_EXPANDED = 2
MIXED = 3
COLD_EXPANDED_LOW_DENSITY = 4

#: Floor on c_K^2 as a fraction of A/rho0.
C2_FLOOR_FRACTION = 1.0e-2
#: Floor on the temperature (K).
T_FLOOR = 1.0
#: Relative tolerance on e of the root find in ``tillotson_energy_from_pressure``.
ROOT_RTOL = 1.0e-13
#: Most bracket-doubling steps and bisection/regula-falsi steps of the root find.
ROOT_MAXITER = 200


@njit(cache=True)
def tillotson_branch(params, rho, e):
    """Branch index (1 = P1, 2 = P2, 3 = P3 mixed, 4 = P4) used at (rho, e)."""
    if rho >= params[RHO0]:
        return COMPRESSED
    if e >= params[E_CV]:
        return HOT_EXPANDED
    if rho >= params[RHO_IV]:
        if e <= params[E_IV]:
            return COMPRESSED
        return MIXED
    return COLD_EXPANDED_LOW_DENSITY


@njit(cache=True)
def _condensed(params, rho, e, with_b):
    """P1 (with_b) or P4 and their partial derivatives (P, dP/drho|_e, dP/de|_rho).

    P = (a + b/omega) rho E + A mu [+ B mu^2];
    dP/drho = (a + b/omega) E + 2 b E^2 / (E0 eta^2 omega^2) + (A [+ 2 B mu]) / rho0;
    dP/dE = rho (a + b / omega^2).
    """
    rho0 = params[RHO0]
    eta = rho / rho0
    mu = eta - 1.0
    x = e / (params[E0] * eta * eta)
    omega = x + 1.0
    a = params[A_SMALL]
    b = params[B_SMALL]
    f = a + b / omega
    p = f * rho * e + params[A] * mu
    dp_drho = f * e + 2.0 * b * e * x / (omega * omega) + params[A] / rho0
    if with_b:
        p += params[B] * mu * mu
        dp_drho += 2.0 * params[B] * mu / rho0
    dp_de = rho * (a + b / (omega * omega))
    return p, dp_drho, dp_de


@njit(cache=True)
def _hot_expanded(params, rho, e):
    """P2 and its partial derivatives (P, dP/drho|_e, dP/de|_rho).

    With g = b rho E/omega + A mu exp(-beta nu), h = exp(-alpha nu^2), dnu/drho = -rho0/rho^2:
    dg/drho = b E/omega + 2 b E^2/(E0 eta^2 omega^2) + A exp(-beta nu) (1/rho0 + beta mu rho0/rho^2),
    dh/drho = 2 alpha nu rho0 h / rho^2,
    dP/drho = a E + h dg/drho + g dh/drho,  dP/dE = a rho + h b rho / omega^2.
    """
    rho0 = params[RHO0]
    eta = rho / rho0
    mu = eta - 1.0
    nu = 1.0 / eta - 1.0
    x = e / (params[E0] * eta * eta)
    omega = x + 1.0
    a = params[A_SMALL]
    b = params[B_SMALL]
    exp_beta = math.exp(-params[BETA] * nu)
    h = math.exp(-params[ALPHA] * nu * nu)
    g = b * rho * e / omega + params[A] * mu * exp_beta
    dg = (b * e / omega + 2.0 * b * e * x / (omega * omega)
          + params[A] * exp_beta * (1.0 / rho0 + params[BETA] * mu * rho0 / (rho * rho)))
    dh = 2.0 * params[ALPHA] * nu * rho0 / (rho * rho) * h
    p = a * rho * e + g * h
    dp_drho = a * e + h * dg + g * dh
    dp_de = a * rho + h * b * rho / (omega * omega)
    return p, dp_drho, dp_de


@njit(cache=True)
def tillotson_pressure_derivatives(params, rho, e):
    """Tillotson pressure P (Pa), dP/drho|_e (m^2/s^2) and dP/de|_rho (kg/m^3).

    The mixed branch differentiates P3 = (P2 (E - E_iv) + P1 (E_cv - E)) / (E_cv - E_iv):
    dP3/dE = (P2' (E - E_iv) + P2 + P1' (E_cv - E) - P1) / (E_cv - E_iv).
    """
    branch = tillotson_branch(params, rho, e)
    if branch == COMPRESSED:
        return _condensed(params, rho, e, True)
    if branch == HOT_EXPANDED:
        return _hot_expanded(params, rho, e)
    if branch == COLD_EXPANDED_LOW_DENSITY:
        return _condensed(params, rho, e, False)
    p1, dp1_drho, dp1_de = _condensed(params, rho, e, True)
    p2, dp2_drho, dp2_de = _hot_expanded(params, rho, e)
    width = params[E_CV] - params[E_IV]
    w2 = (e - params[E_IV]) / width
    w1 = (params[E_CV] - e) / width
    p = w2 * p2 + w1 * p1
    dp_drho = w2 * dp2_drho + w1 * dp1_drho
    dp_de = w2 * dp2_de + w1 * dp1_de + (p2 - p1) / width
    return p, dp_drho, dp_de


@njit(cache=True)
def tillotson_pressure_sound_speed(params, rho, e):
    """Pressure P (Pa) and c_K^2 = dP/drho|_e + (P/rho^2) dP/de|_rho (m^2/s^2).

    c_K^2 is floored at ``C2_FLOOR_FRACTION * A / rho0``.
    """
    p, dp_drho, dp_de = tillotson_pressure_derivatives(params, rho, e)
    c2 = dp_drho + p / (rho * rho) * dp_de
    c2_floor = C2_FLOOR_FRACTION * params[A] / params[RHO0]
    if c2 < c2_floor:
        c2 = c2_floor
    return p, c2


@njit(cache=True, inline="always")
def tillotson_pressure_not_negative(params, rho, e):
    """Whether P(rho, e) >= 0 (Pa) is certain without evaluating it: at rho >= rho0 (kg/m^3) the
    compressed branch P1 = (a + b/omega) rho E + A mu + B mu^2 applies, and with E >= 0 (J/kg),
    E0 > 0 and a, b, A, B >= 0 each of its terms is >= 0 (omega >= 1, mu >= 0), in floating
    point too (products and sums of numbers >= 0)."""
    return (rho >= params[RHO0] and e >= 0.0 and params[E0] > 0.0 and params[A] >= 0.0 and params[B] >= 0.0
            and params[A_SMALL] >= 0.0 and params[B_SMALL] >= 0.0)


@njit(cache=True)
def tillotson_cold_energy(params, rho):
    """Cold-compression energy e_cold(rho) (J/kg), zero at rho0.

    e_cold = [A (ln eta + 1/eta - 1) + B (eta - 2 ln eta - 1/eta)] / rho0, the integral of
    (A mu + B mu^2)/rho^2 from rho0 to rho.
    """
    eta = rho / params[RHO0]
    log_eta = math.log(eta)
    return (params[A] * (log_eta + 1.0 / eta - 1.0)
            + params[B] * (eta - 2.0 * log_eta - 1.0 / eta)) / params[RHO0]


@njit(cache=True)
def tillotson_temperature(params, rho, e):
    """Temperature T = T_ref + (E - e_cold(rho)) / c_v (K), floored at ``T_FLOOR``."""
    t = params[T_REF] + (e - tillotson_cold_energy(params, rho)) / params[CV]
    if t < T_FLOOR:
        t = T_FLOOR
    return t


@njit(cache=True)
def tillotson_energy_from_pressure(params, rho, p):
    """Specific internal energy e (J/kg) with P(rho, e) = p, by a bracketed root find.

    Starts at e = 0 and steps towards the root (up if P(rho, 0) < p, else down) with steps
    |P(rho, 0) - p| / (a rho) doubling each time (dP/dE >= a rho on P1, P2, P4) until the
    sign changes; the lowest e tried is -E0 eta^2 / 2 (omega = 1/2).  The bracket is then
    closed by Illinois regula falsi with bisection safeguards until the bracket is narrower
    than ``ROOT_RTOL * (|e_a| + |e_b| + E_iv)``.
    Returns NaN when no bracket is found (p not reachable at this density).
    """
    eta = rho / params[RHO0]
    e_min = -0.5 * params[E0] * eta * eta
    e_a = 0.0
    f_a = tillotson_pressure_derivatives(params, rho, e_a)[0] - p
    if f_a == 0.0:
        return 0.0
    step = abs(f_a) / (params[A_SMALL] * rho)
    direction = 1.0 if f_a < 0.0 else -1.0
    e_b = e_a
    f_b = f_a
    found = False
    for _ in range(ROOT_MAXITER):
        e_b = e_a + direction * step
        if e_b < e_min:
            e_b = e_min
        f_b = tillotson_pressure_derivatives(params, rho, e_b)[0] - p
        if f_b == 0.0:
            return e_b
        if (f_b > 0.0) != (f_a > 0.0):
            found = True
            break
        if e_b == e_min:
            break
        e_a = e_b
        f_a = f_b
        step *= 2.0
    if not found:
        return math.nan
    side = 0
    for _ in range(ROOT_MAXITER):
        e_c = (e_a * f_b - e_b * f_a) / (f_b - f_a)
        if not (min(e_a, e_b) < e_c < max(e_a, e_b)):
            e_c = 0.5 * (e_a + e_b)
        f_c = tillotson_pressure_derivatives(params, rho, e_c)[0] - p
        if f_c == 0.0:
            return e_c
        if (f_c > 0.0) == (f_b > 0.0):
            e_b = e_c
            f_b = f_c
            if side == 1:
                f_a *= 0.5
            side = 1
        else:
            e_a = e_c
            f_a = f_c
            if side == -1:
                f_b *= 0.5
            side = -1
        if abs(e_b - e_a) <= ROOT_RTOL * (abs(e_a) + abs(e_b) + params[E_IV]):
            break
    return e_b if abs(f_b) < abs(f_a) else e_a
