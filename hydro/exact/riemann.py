"""Exact solution of the Riemann problem for the 1D Euler equations of an ideal gas.

Left state (rho_L, u_L, p_L) for x < x0, right state (rho_R, u_R, p_R) for x > x0 at
t = 0 (kg/m^3, m/s, Pa), ratio of specific heats gamma.  The star pressure p* solves

    f(p) = f_L(p) + f_R(p) + u_R - u_L = 0,
    f_K(p) = (p - p_K) sqrt(A_K / (p + B_K))                      p > p_K (shock)
           = 2 c_K / (gamma - 1) [(p/p_K)^((gamma-1)/(2 gamma)) - 1]   p <= p_K (rarefaction)
    A_K = 2 / ((gamma + 1) rho_K),  B_K = (gamma - 1) p_K / (gamma + 1),  c_K^2 = gamma p_K / rho_K

by Newton iteration from the primitive-variable guess (f is monotone and concave, so the
iteration converges), and u* = (u_L + u_R)/2 + (f_R(p*) - f_L(p*))/2.  The solution is
sampled on S = (x - x0)/t through shocks, rarefaction fans and contacts.  A vacuum is
generated when 2 (c_L + c_R)/(gamma - 1) <= u_R - u_L; a side with rho = 0 is a vacuum
state.  The method is the classical one (e.g. Toro, Riemann Solvers and Numerical Methods
for Fluid Dynamics, ch. 4).
"""

import math

import numpy as np

#: Relative change of p* at which the Newton iteration stops.
PRESSURE_RTOL = 1.0e-14
#: Most Newton iterations.
MAXITER = 100


def _pressure_function(p, rho_k, p_k, c_k, gamma):
    """f_K(p) and df_K/dp for one side."""
    if p > p_k:
        a_k = 2.0 / ((gamma + 1.0) * rho_k)
        b_k = (gamma - 1.0) / (gamma + 1.0) * p_k
        root = math.sqrt(a_k / (p + b_k))
        return (p - p_k) * root, root * (1.0 - 0.5 * (p - p_k) / (b_k + p))
    ratio = p / p_k
    f = 2.0 * c_k / (gamma - 1.0) * (ratio ** ((gamma - 1.0) / (2.0 * gamma)) - 1.0)
    df = ratio ** (-(gamma + 1.0) / (2.0 * gamma)) / (rho_k * c_k)
    return f, df


def riemann_star_state(left, right, gamma):
    """Star-region pressure p* (Pa) and velocity u* (m/s) for non-vacuum data.

    Raises ValueError when the data generate a vacuum (no star region).
    """
    rho_l, u_l, p_l = (float(v) for v in left)
    rho_r, u_r, p_r = (float(v) for v in right)
    c_l = math.sqrt(gamma * p_l / rho_l)
    c_r = math.sqrt(gamma * p_r / rho_r)
    if 2.0 * (c_l + c_r) / (gamma - 1.0) <= u_r - u_l:
        raise ValueError("the Riemann data generate a vacuum: no star state")
    p_pv = 0.5 * (p_l + p_r) - 0.125 * (u_r - u_l) * (rho_l + rho_r) * (c_l + c_r)
    p = max(p_pv, 1.0e-8 * min(p_l, p_r))
    for _ in range(MAXITER):
        f_l, df_l = _pressure_function(p, rho_l, p_l, c_l, gamma)
        f_r, df_r = _pressure_function(p, rho_r, p_r, c_r, gamma)
        p_new = p - (f_l + f_r + u_r - u_l) / (df_l + df_r)
        if p_new <= 0.0:
            p_new = 0.5 * p
        change = abs(p_new - p) / (0.5 * (p_new + p))
        p = p_new
        if change < PRESSURE_RTOL:
            break
    f_l = _pressure_function(p, rho_l, p_l, c_l, gamma)[0]
    f_r = _pressure_function(p, rho_r, p_r, c_r, gamma)[0]
    return p, 0.5 * (u_l + u_r) + 0.5 * (f_r - f_l)


def _left_fan(s, rho_l, u_l, p_l, c_l, gamma):
    base = 2.0 / (gamma + 1.0) + (gamma - 1.0) / ((gamma + 1.0) * c_l) * (u_l - s)
    return (rho_l * base ** (2.0 / (gamma - 1.0)),
            2.0 / (gamma + 1.0) * (c_l + 0.5 * (gamma - 1.0) * u_l + s),
            p_l * base ** (2.0 * gamma / (gamma - 1.0)))


def _right_fan(s, rho_r, u_r, p_r, c_r, gamma):
    base = 2.0 / (gamma + 1.0) - (gamma - 1.0) / ((gamma + 1.0) * c_r) * (u_r - s)
    return (rho_r * base ** (2.0 / (gamma - 1.0)),
            2.0 / (gamma + 1.0) * (-c_r + 0.5 * (gamma - 1.0) * u_r + s),
            p_r * base ** (2.0 * gamma / (gamma - 1.0)))


def _sample_left(s, p_star, u_star, rho_l, u_l, p_l, c_l, gamma):
    """State at speed s <= u* (left of the contact)."""
    gm = (gamma - 1.0) / (gamma + 1.0)
    if p_star > p_l:
        shock = u_l - c_l * math.sqrt((gamma + 1.0) / (2.0 * gamma) * p_star / p_l
                                      + (gamma - 1.0) / (2.0 * gamma))
        if s <= shock:
            return rho_l, u_l, p_l
        ratio = p_star / p_l
        return rho_l * (ratio + gm) / (gm * ratio + 1.0), u_star, p_star
    head = u_l - c_l
    if s <= head:
        return rho_l, u_l, p_l
    c_star = c_l * (p_star / p_l) ** ((gamma - 1.0) / (2.0 * gamma))
    if s < u_star - c_star:
        return _left_fan(s, rho_l, u_l, p_l, c_l, gamma)
    return rho_l * (p_star / p_l) ** (1.0 / gamma), u_star, p_star


def _sample_right(s, p_star, u_star, rho_r, u_r, p_r, c_r, gamma):
    """State at speed s > u* (right of the contact)."""
    gm = (gamma - 1.0) / (gamma + 1.0)
    if p_star > p_r:
        shock = u_r + c_r * math.sqrt((gamma + 1.0) / (2.0 * gamma) * p_star / p_r
                                      + (gamma - 1.0) / (2.0 * gamma))
        if s >= shock:
            return rho_r, u_r, p_r
        ratio = p_star / p_r
        return rho_r * (ratio + gm) / (gm * ratio + 1.0), u_star, p_star
    head = u_r + c_r
    if s >= head:
        return rho_r, u_r, p_r
    c_star = c_r * (p_star / p_r) ** ((gamma - 1.0) / (2.0 * gamma))
    if s > u_star + c_star:
        return _right_fan(s, rho_r, u_r, p_r, c_r, gamma)
    return rho_r * (p_star / p_r) ** (1.0 / gamma), u_star, p_star


def _sample_vacuum(s, left, right, gamma):
    """State at speed s when the solution contains a vacuum (given or generated)."""
    rho_l, u_l, p_l = left
    rho_r, u_r, p_r = right
    if rho_l > 0.0:
        c_l = math.sqrt(gamma * p_l / rho_l)
        if s <= u_l - c_l:
            return rho_l, u_l, p_l
        if s < u_l + 2.0 * c_l / (gamma - 1.0):
            return _left_fan(s, rho_l, u_l, p_l, c_l, gamma)
    if rho_r > 0.0:
        c_r = math.sqrt(gamma * p_r / rho_r)
        if s >= u_r + c_r:
            return rho_r, u_r, p_r
        if s > u_r - 2.0 * c_r / (gamma - 1.0):
            return _right_fan(s, rho_r, u_r, p_r, c_r, gamma)
    return 0.0, math.nan, 0.0


def exact_riemann(x, t, x0, left, right, gamma):
    """Exact Riemann solution (rho, u, p) arrays at positions x (m) and time t (s).

    ``left`` and ``right`` are (rho, u, p) tuples; rho = 0 marks a vacuum side (its u and p
    are ignored).  In a vacuum region rho = p = 0 and u = NaN.  At t = 0 the initial data
    are returned.
    """
    x = np.asarray(x, dtype=np.float64)
    left = tuple(float(v) for v in left)
    right = tuple(float(v) for v in right)
    if gamma <= 1.0:
        raise ValueError(f"gamma must be > 1, got {gamma}")
    for name, side in (("left", left), ("right", right)):
        if side[0] < 0.0 or side[2] < 0.0 or (side[0] > 0.0 and side[2] == 0.0):
            raise ValueError(f"{name} state needs rho >= 0 and p > 0 (or rho = 0), got {side}")
    rho = np.empty_like(x)
    u = np.empty_like(x)
    p = np.empty_like(x)
    if t <= 0.0:
        for n, xn in enumerate(x.flat):
            rho.flat[n], u.flat[n], p.flat[n] = left if xn < x0 else right
        return rho, u, p
    vacuum = left[0] == 0.0 or right[0] == 0.0
    if not vacuum:
        c_l = math.sqrt(gamma * left[2] / left[0])
        c_r = math.sqrt(gamma * right[2] / right[0])
        vacuum = 2.0 * (c_l + c_r) / (gamma - 1.0) <= right[1] - left[1]
    if not vacuum:
        p_star, u_star = riemann_star_state(left, right, gamma)
    for n, xn in enumerate(x.flat):
        s = (xn - x0) / t
        if vacuum:
            values = _sample_vacuum(s, left, right, gamma)
        elif s <= u_star:
            values = _sample_left(s, p_star, u_star, *left, c_l, gamma)
        else:
            values = _sample_right(s, p_star, u_star, *right, c_r, gamma)
        rho.flat[n], u.flat[n], p.flat[n] = values
    return rho, u, p
