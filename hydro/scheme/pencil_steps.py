"""Pieces of a pencil update that the sweep's general and plain paths share.

Each works on one cell or face of the per-thread scratch (:mod:`impactpipe.hydro.scheme.pencil_layout`),
so both paths do the same arithmetic (the plain path's bit-for-bit agreement rests on it):

- :func:`predict_flow`: the MUSCL-Hancock half-step face states of the velocity and the
  pressure, u_t = -u u_x - p_x / rho, p_t = -u p_x - K u_x, with MC-limited slopes;
- :func:`predict_material`: the same for material k's alpha_k, rho_k and e_k,
  alpha_t = -u alpha_x, rho_k,t = -u rho_k,x - rho_k u_x, e_k,t = -u e_k,x - (p_k / rho_k) u_x;
- :func:`cell_value_faces`: the first-order fallback (face states = cell values);
- :func:`upwind_face`: the HLLC face solution and the upwind (donor) cell of a face;
- :func:`material_face_flux`: material k's volume, mass and internal-energy fluxes through a
  face (compressive ultrabee volume fraction, donor caps);
- :func:`flow_fluxes`: the momentum and total-energy fluxes of the summed mass flux.

The equations and the rules behind the caps are in :mod:`impactpipe.hydro.scheme.directional`.
"""

from __future__ import annotations

from numba import njit

from impactpipe.hydro.scheme.reconstruct import mc_slope, ultrabee_face
from impactpipe.hydro.scheme.riemann import UPWIND_LEFT, hllc_face
from impactpipe.hydro.scheme.pencil_layout import (
    F_E,
    F_MN,
    F_MT1,
    F_MT2,
    F_S,
    FULL_TOLERANCE,
    Q_P,
    Q_UN,
    Q_UT1,
    Q_UT2,
    W_C,
    W_IVL,
    W_IVR,
    W_K,
    W_P,
    W_RHO,
    W_UN,
)


@njit(cache=True, inline="always")
def predict_flow(sc, i, half, qm_row, qp_row):
    """Face states of (u_n, u_t1, u_t2, p) of cell i; returns (u_n, du_n, p, lowest face pressure)."""
    un = sc[W_UN, i]
    dun = mc_slope(sc[W_UN, i - 1], un, sc[W_UN, i + 1])
    dp = mc_slope(sc[W_P, i - 1], sc[W_P, i], sc[W_P, i + 1])
    for c in range(3):
        row = W_UN + c
        q = sc[row, i]
        dq = mc_slope(sc[row, i - 1], q, sc[row, i + 1])
        if c == 0:
            qh = q - half * (un * dq + dp / sc[W_RHO, i])
        else:
            qh = q - half * un * dq
        sc[qm_row + Q_UN + c, i] = qh - 0.5 * dq
        sc[qp_row + Q_UN + c, i] = qh + 0.5 * dq
    p = sc[W_P, i]
    ph = p - half * (un * dp + sc[W_K, i] * dun)
    sc[qm_row + Q_P, i] = ph - 0.5 * dp
    sc[qp_row + Q_P, i] = ph + 0.5 * dp
    return un, dun, p, ph - 0.5 * abs(dp)


@njit(cache=True, inline="always")
def predict_material(sc, i, row, qrow, half, un, dun, qm_row, qp_row):
    """Face states of (alpha_k, rho_k, e_k) of cell i (W rows ``row``, Q rows ``qrow``).

    A neighbour without material k lends cell i its own rho_k and e_k for the slopes; face
    e_k of a cell with e_k >= 0 are clipped at 0.  Returns True if a face density is not
    positive (the cell must fall back to first order).
    """
    a = sc[row, i]
    da = mc_slope(sc[row, i - 1], a, sc[row, i + 1])
    ah = a - half * un * da
    sc[qm_row + qrow, i] = min(max(ah - 0.5 * da, 0.0), 1.0)
    sc[qp_row + qrow, i] = min(max(ah + 0.5 * da, 0.0), 1.0)
    rk = sc[row + 1, i]
    ek = sc[row + 2, i]
    if not rk > 0.0:
        for c in (1, 2):
            sc[qm_row + qrow + c, i] = 0.0
            sc[qp_row + qrow + c, i] = 0.0
        return False
    rkm = sc[row + 1, i - 1] if sc[row + 1, i - 1] > 0.0 else rk
    rkp = sc[row + 1, i + 1] if sc[row + 1, i + 1] > 0.0 else rk
    ekm = sc[row + 2, i - 1] if sc[row + 1, i - 1] > 0.0 else ek
    ekp = sc[row + 2, i + 1] if sc[row + 1, i + 1] > 0.0 else ek
    drk = mc_slope(rkm, rk, rkp)
    dek = mc_slope(ekm, ek, ekp)
    rh = rk - half * (un * drk + rk * dun)
    eh = ek - half * (un * dek + sc[row + 3, i] / rk * dun)
    em = eh - 0.5 * dek
    ep = eh + 0.5 * dek
    if ek >= 0.0:
        em = max(em, 0.0)
        ep = max(ep, 0.0)
    sc[qm_row + qrow + 1, i] = rh - 0.5 * drk
    sc[qp_row + qrow + 1, i] = rh + 0.5 * drk
    sc[qm_row + qrow + 2, i] = em
    sc[qp_row + qrow + 2, i] = ep
    return rh - 0.5 * abs(drk) <= 0.0


@njit(cache=True, inline="always")
def cell_value_faces(sc, i, qm_row, qp_row, rows, qrows, flow=True):
    """First order: both face states of cell i are its cell values (the given materials, and
    the flow (u_n, u_t1, u_t2, p) unless ``flow`` is False).

    ``rows``/``qrows``: the W and Q row offsets of the materials, as (first, stride, count).
    """
    if flow:
        for c in range(3):
            sc[qm_row + Q_UN + c, i] = sc[W_UN + c, i]
            sc[qp_row + Q_UN + c, i] = sc[W_UN + c, i]
        sc[qm_row + Q_P, i] = sc[W_P, i]
        sc[qp_row + Q_P, i] = sc[W_P, i]
    for k in range(rows[2]):
        row = rows[0] + rows[1] * k
        qrow = qrows[0] + qrows[1] * k
        for c in range(3):
            sc[qm_row + qrow + c, i] = sc[row + c, i]
            sc[qp_row + qrow + c, i] = sc[row + c, i]


@njit(cache=True, inline="always")
def upwind_face(sc, f, rho_l, void_l, rho_r, void_r, qm_row, qp_row):
    """HLLC at face f (between cells f-1 and f) and its upwind cell.

    ``rho_l``, ``rho_r``: the face densities of the two sides (kg/m^3); ``void_*``: whether a
    side is void.  Returns (side, s, p*, chi, de, donor, upwind neighbour of the donor,
    downwind cell, the donor's Q row block, the donor's A / V on this face (1/m)).
    """
    il = f - 1
    ir = f
    side, s, p_star, chi, de = hllc_face(
        rho_l, sc[qp_row + Q_UN, il], sc[qp_row + Q_P, il], sc[W_C, il], void_l,
        rho_r, sc[qm_row + Q_UN, ir], sc[qm_row + Q_P, ir], sc[W_C, ir], void_r)
    if side == UPWIND_LEFT:
        return side, s, p_star, chi, de, il, il - 1, ir, qp_row, sc[W_IVR, il]
    return side, s, p_star, chi, de, ir, ir + 1, il, qm_row, sc[W_IVL, ir]


@njit(cache=True, inline="always")
def material_face_flux(sc, f, row, qrow, frow, donor, up, down, krow, nu, flow, share, s, chi, dt, iv_donor):
    """Material k's fluxes through face f (W rows ``row``, Q rows ``qrow``, F rows ``frow``).

    Volume flux alpha_face s with the ultrabee face value capped at 1 and at ``share`` of the
    donor's material volume (``flow`` = |s| dt A / V of the donor); mass flux alpha_face
    rho_k chi s with the donor's face state, or its cell-average density and energy when the
    donor is mixed or partly void, capped at ``share`` of the donor's mass; internal energy
    flux = mass flux x e_k.  Stores the three and returns (mass flux, specific energy e_k).
    """
    a_donor = sc[row, donor]
    af = ultrabee_face(sc[row, up], a_donor, sc[row, down], nu)
    if af > 1.0:
        af = 1.0
    if af * flow > share * a_donor:
        af = share * a_donor / flow
    if a_donor < 1.0 - FULL_TOLERANCE:
        mk = af * sc[row + 1, donor] * s
        ek = sc[row + 2, donor]
    else:
        mk = af * sc[krow + qrow + 1, donor] * chi * s
        ek = sc[krow + qrow + 2, donor]
    mcap = share * a_donor * sc[row + 1, donor] / (dt * iv_donor)
    if abs(mk) > mcap:
        mk = mcap if mk > 0.0 else -mcap
    sc[frow, f] = af * s
    sc[frow + 1, f] = mk
    sc[frow + 2, f] = mk * ek
    return mk, ek


@njit(cache=True, inline="always")
def flow_fluxes(sc, f, f_row, krow, donor, mass, eint, s, p_star, de):
    """Momentum and total-energy fluxes through face f from the summed mass flux ``mass``.

    Normal momentum mass s + p*, transverse mass u_t,K, energy eint + mass (|u_K|^2 / 2 + de)
    + p* s with the upwind face state K (Q rows ``krow`` of cell ``donor``); stores s.
    """
    un = sc[krow + Q_UN, donor]
    ut1 = sc[krow + Q_UT1, donor]
    ut2 = sc[krow + Q_UT2, donor]
    sc[f_row + F_MN, f] = mass * s + p_star
    sc[f_row + F_MT1, f] = mass * ut1
    sc[f_row + F_MT2, f] = mass * ut2
    sc[f_row + F_E, f] = eint + mass * (0.5 * (un * un + ut1 * ut1 + ut2 * ut2) + de) + p_star * s
    sc[f_row + F_S, f] = s
