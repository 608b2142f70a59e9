"""HLLC face solver with free surfaces (material next to void).

Inputs per side K in {L, R}: density rho_K (kg/m^3), normal velocity u_K (m/s), pressure
p_K (Pa), sound speed c_K (m/s), and whether the side is void.

Material on both sides (Toro's HLLC with Davis wave speeds):

    S_L = min(u_L - c_L, u_R - c_R),   S_R = max(u_L + c_L, u_R + c_R)
    S*  = [p_R - p_L + rho_L u_L (S_L - u_L) - rho_R u_R (S_R - u_R)]
          / [rho_L (S_L - u_L) - rho_R (S_R - u_R)]
    p*  = (p_L + rho_L (S_L - u_L)(S* - u_L) + p_R + rho_R (S_R - u_R)(S* - u_R)) / 2

Void on one side (free surface, the acoustic limit of the vacuum Riemann problem): with
the material on the left, ``S_L = u_L - c_L``, ``S* = u_L + p_L / (rho_L c_L)``, ``p* = 0``
(mirror for material on the right).  This is HLLC with rho = p = 0 on the void side, so a
material at zero pressure next to void stays put and a surface under pressure moves off.

Every flux is then written as "upwind star state times face velocity plus pressure": with
the upwind side K (L if S* >= 0) and the compression factor ``chi = (S_K - u_K)/(S_K - S*)``
the star state is ``rho*_K = chi rho_K`` and

    mass flux       m = chi rho_K s
    momentum flux   m s + p*   (normal),  m u_t,K (transverse)
    energy flux     m (e_K + |u_K|^2 / 2 + de) + p* s,
                    de = (S* - u_K)(S* + p_K / (rho_K (S_K - u_K)))

with the face velocity s = S*.  A supersonic face (S_L >= 0 or S_R <= 0) takes the upwind
flux itself: chi = 1, s = u_K, p* = p_K, de = 0.  This form lets the multi-material sweep
split the mass flux among materials (``m_k = alpha_k,face rho_k,K chi s``) while the single
material case is exactly HLLC.
"""

from __future__ import annotations

from numba import njit

#: Upwind side codes returned by :func:`hllc_face`.
UPWIND_LEFT = 0
UPWIND_RIGHT = 1
UPWIND_NONE = -1


@njit(cache=True, inline="always")
def hllc_face(rho_l, u_l, p_l, c_l, void_l, rho_r, u_r, p_r, c_r, void_r):
    """Face velocity, pressure and upwind star factors; see the module docstring.

    Returns ``(side, s, p_star, chi, de)``: the upwind side code, the face velocity s
    (m/s), the face pressure p* (Pa), the compression factor chi of the upwind star state
    (-) and the specific energy term de (J/kg) of the energy flux.
    """
    if void_l and void_r:
        return UPWIND_NONE, 0.0, 0.0, 0.0, 0.0
    if void_r:
        s_l = u_l - c_l
        if s_l >= 0.0:
            return UPWIND_LEFT, u_l, p_l, 1.0, 0.0
        s_star = u_l + p_l / (rho_l * c_l) if c_l > 0.0 else u_l
        if s_star < s_l:
            s_star = s_l
        if s_star < 0.0:
            return UPWIND_RIGHT, s_star, 0.0, 0.0, 0.0
        return _star(UPWIND_LEFT, rho_l, u_l, p_l, s_l, s_star, 0.0)
    if void_l:
        s_r = u_r + c_r
        if s_r <= 0.0:
            return UPWIND_RIGHT, u_r, p_r, 1.0, 0.0
        s_star = u_r - p_r / (rho_r * c_r) if c_r > 0.0 else u_r
        if s_star > s_r:
            s_star = s_r
        if s_star >= 0.0:
            return UPWIND_LEFT, s_star, 0.0, 0.0, 0.0
        return _star(UPWIND_RIGHT, rho_r, u_r, p_r, s_r, s_star, 0.0)
    s_l = min(u_l - c_l, u_r - c_r)
    s_r = max(u_l + c_l, u_r + c_r)
    if s_l >= 0.0:
        return UPWIND_LEFT, u_l, p_l, 1.0, 0.0
    if s_r <= 0.0:
        return UPWIND_RIGHT, u_r, p_r, 1.0, 0.0
    ml = rho_l * (s_l - u_l)
    mr = rho_r * (s_r - u_r)
    den = ml - mr
    if den == 0.0:
        return UPWIND_LEFT, 0.0, 0.5 * (p_l + p_r), 0.0, 0.0
    s_star = (p_r - p_l + ml * u_l - mr * u_r) / den
    p_star = 0.5 * (p_l + ml * (s_star - u_l) + p_r + mr * (s_star - u_r))
    if s_star >= 0.0:
        return _star(UPWIND_LEFT, rho_l, u_l, p_l, s_l, s_star, p_star)
    return _star(UPWIND_RIGHT, rho_r, u_r, p_r, s_r, s_star, p_star)


@njit(cache=True, inline="always")
def _star(side, rho, u, p, s_k, s_star, p_star):
    """Upwind star factors chi and de for side K with outer wave speed s_k.

    A degenerate fan (s_k equal to u or to S*, only for a vanishing sound speed) gives the
    unshocked upwind state, chi = 1 and de = 0.
    """
    ds = s_k - s_star
    mk = rho * (s_k - u)
    if ds == 0.0 or mk == 0.0:
        return side, s_star, p_star, 1.0, 0.0
    chi = (s_k - u) / ds
    de = (s_star - u) * (s_star + p / mk)
    return side, s_star, p_star, chi, de
