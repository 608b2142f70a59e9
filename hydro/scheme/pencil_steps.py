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
- :func:`scalar_face_fluxes`: material k's transported scalars carried by its mass flux;
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
    un = sc[i, W_UN]
    dun = mc_slope(sc[i - 1, W_UN], un, sc[i + 1, W_UN])
    dp = mc_slope(sc[i - 1, W_P], sc[i, W_P], sc[i + 1, W_P])
    for c in range(3):
        row = W_UN + c
        q = sc[i, row]
        dq = mc_slope(sc[i - 1, row], q, sc[i + 1, row])
        if c == 0:
            qh = q - half * (un * dq + dp / sc[i, W_RHO])
        else:
            qh = q - half * un * dq
        sc[i, qm_row + Q_UN + c] = qh - 0.5 * dq
        sc[i, qp_row + Q_UN + c] = qh + 0.5 * dq
    p = sc[i, W_P]
    ph = p - half * (un * dp + sc[i, W_K] * dun)
    sc[i, qm_row + Q_P] = ph - 0.5 * dp
    sc[i, qp_row + Q_P] = ph + 0.5 * dp
    return un, dun, p, ph - 0.5 * abs(dp)


@njit(cache=True, inline="always")
def predict_material(sc, i, row, qrow, half, un, dun, qm_row, qp_row):
    """Face states of (alpha_k, rho_k, e_k) of cell i (W rows ``row``, Q rows ``qrow``).

    A neighbour without material k lends cell i its own rho_k and e_k for the slopes; face
    e_k of a cell with e_k >= 0 are clipped at 0.  Returns True if a face density is not
    positive (the cell must fall back to first order).
    """
    a = sc[i, row]
    da = mc_slope(sc[i - 1, row], a, sc[i + 1, row])
    ah = a - half * un * da
    sc[i, qm_row + qrow] = min(max(ah - 0.5 * da, 0.0), 1.0)
    sc[i, qp_row + qrow] = min(max(ah + 0.5 * da, 0.0), 1.0)
    rk = sc[i, row + 1]
    ek = sc[i, row + 2]
    if not rk > 0.0:
        for c in (1, 2):
            sc[i, qm_row + qrow + c] = 0.0
            sc[i, qp_row + qrow + c] = 0.0
        return False
    rkm = sc[i - 1, row + 1] if sc[i - 1, row + 1] > 0.0 else rk
    rkp = sc[i + 1, row + 1] if sc[i + 1, row + 1] > 0.0 else rk
    ekm = sc[i - 1, row + 2] if sc[i - 1, row + 1] > 0.0 else ek
    ekp = sc[i + 1, row + 2] if sc[i + 1, row + 1] > 0.0 else ek
    drk = mc_slope(rkm, rk, rkp)
    dek = mc_slope(ekm, ek, ekp)
    rh = rk - half * (un * drk + rk * dun)
    eh = ek - half * (un * dek + sc[i, row + 3] / rk * dun)
    em = eh - 0.5 * dek
    ep = eh + 0.5 * dek
    if ek >= 0.0:
        em = max(em, 0.0)
        ep = max(ep, 0.0)
    sc[i, qm_row + qrow + 1] = rh - 0.5 * drk
    sc[i, qp_row + qrow + 1] = rh + 0.5 * drk
    sc[i, qm_row + qrow + 2] = em
    sc[i, qp_row + qrow + 2] = ep
    return rh - 0.5 * abs(drk) <= 0.0


@njit(cache=True, inline="always")
def cell_value_faces(sc, i, qm_row, qp_row, rows, qrows, flow=True):
    """First order: both face states of cell i are its cell values (the given materials, and
    the flow (u_n, u_t1, u_t2, p) unless ``flow`` is False).

    ``rows``/``qrows``: the W and Q row offsets of the materials, as (first, stride, count).
    """
    if flow:
        for c in range(3):
            sc[i, qm_row + Q_UN + c] = sc[i, W_UN + c]
            sc[i, qp_row + Q_UN + c] = sc[i, W_UN + c]
        sc[i, qm_row + Q_P] = sc[i, W_P]
        sc[i, qp_row + Q_P] = sc[i, W_P]
    for k in range(rows[2]):
        row = rows[0] + rows[1] * k
        qrow = qrows[0] + qrows[1] * k
        for c in range(3):
            sc[i, qm_row + qrow + c] = sc[i, row + c]
            sc[i, qp_row + qrow + c] = sc[i, row + c]


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
        rho_l, sc[il, qp_row + Q_UN], sc[il, qp_row + Q_P], sc[il, W_C], void_l,
        rho_r, sc[ir, qm_row + Q_UN], sc[ir, qm_row + Q_P], sc[ir, W_C], void_r)
    if side == UPWIND_LEFT:
        return side, s, p_star, chi, de, il, il - 1, ir, qp_row, sc[il, W_IVR]
    return side, s, p_star, chi, de, ir, ir + 1, il, qm_row, sc[ir, W_IVL]


@njit(cache=True, inline="always")
def material_face_flux(sc, f, row, qrow, frow, donor, up, down, krow, nu, flow, share, s, chi, dt, iv_donor):
    """Material k's fluxes through face f (W rows ``row``, Q rows ``qrow``, F rows ``frow``).

    Volume flux alpha_face s with the ultrabee face value capped at 1 and at ``share`` of the
    donor's material volume (``flow`` = |s| dt A / V of the donor); mass flux alpha_face
    rho_k chi s with the donor's face state, or its cell-average density and energy when the
    donor is mixed or partly void, capped at ``share`` of the donor's mass; internal energy
    flux = mass flux x e_k.  Stores the three and returns (mass flux, specific energy e_k).
    """
    a_donor = sc[donor, row]
    af = ultrabee_face(sc[up, row], a_donor, sc[down, row], nu)
    if af > 1.0:
        af = 1.0
    if af * flow > share * a_donor:
        af = share * a_donor / flow
    if a_donor < 1.0 - FULL_TOLERANCE:
        mk = af * sc[donor, row + 1] * s
        ek = sc[donor, row + 2]
    else:
        mk = af * sc[donor, krow + qrow + 1] * chi * s
        ek = sc[donor, krow + qrow + 2]
    mcap = share * a_donor * sc[donor, row + 1] / (dt * iv_donor)
    if abs(mk) > mcap:
        mk = mcap if mk > 0.0 else -mcap
    sc[f, frow] = af * s
    sc[f, frow + 1] = mk
    sc[f, frow + 2] = mk * ek
    return mk, ek


@njit(cache=True, inline="always")
def scalar_face_fluxes(sc, f, fq_row, wq_row, nq, k, mass, donor, carried, edge):
    """Material k's NQ scalar fluxes through face f, into its column of the FQ rows: its mass
    flux ``mass`` times the donor cell's specific scalars where the pencil ``carried`` scalars;
    without them (every donor's scalars +0.0) ``mass`` x +0.0, the +-0.0 the product would
    give, and only at a block face (``edge``), which the sweep stores for refluxing: the
    updates do not apply the scalar fluxes of a pencil that carries none."""
    if carried:
        for j in range(nq):
            sc[f, fq_row + nq * k + j] = mass * sc[donor, wq_row + nq * k + j]
    elif edge:
        for j in range(nq):
            sc[f, fq_row + nq * k + j] = mass * 0.0


@njit(cache=True, inline="always")
def flow_fluxes(sc, f, f_row, krow, donor, mass, eint, s, p_star, de):
    """Momentum and total-energy fluxes through face f from the summed mass flux ``mass``.

    Normal momentum mass s + p*, transverse mass u_t,K, energy eint + mass (|u_K|^2 / 2 + de)
    + p* s with the upwind face state K (Q rows ``krow`` of cell ``donor``); stores s.
    """
    un = sc[donor, krow + Q_UN]
    ut1 = sc[donor, krow + Q_UT1]
    ut2 = sc[donor, krow + Q_UT2]
    sc[f, f_row + F_MN] = mass * s + p_star
    sc[f, f_row + F_MT1] = mass * ut1
    sc[f, f_row + F_MT2] = mass * ut2
    sc[f, f_row + F_E] = eint + mass * (0.5 * (un * un + ut1 * ut1 + ut2 * ut2) + de) + p_star * s
    sc[f, f_row + F_S] = s
