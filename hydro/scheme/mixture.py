"""The thermodynamic state of a cell's material mixture, gathered from its conserved amounts.

A cell holds per material k its volume fraction alpha_k (-), partial density alpha_k rho_k
(kg/m^3) and internal energy density alpha_k rho_k e_k (J/m^3) (``hydro.state``); void fills
1 - sum_k alpha_k.  Material k is present where alpha_k > ALPHA_MIN and alpha_k rho_k > 0;
then (:func:`material_state`)

    rho_k = (alpha_k rho_k) / alpha_k,   e_k = (alpha_k rho_k e_k) / (alpha_k rho_k),
    p_k = max(P_k(rho_k, e_k), -Y_T,k (1 - D_k))      (max(P_k, 0) below DISTENDED_FRACTION rho0_k)
    c_k^2 = c_K,k^2 + 4 G_k / (3 rho_k)               (:func:`signal_speed_squared`)

with P_k, c_K,k the material's EOS pressure and bulk sound speed, Y_T,k its tensile strength,
D_k its damage (:func:`damaged_tensile_strength`) and G_k its shear modulus.  A material whose
damage grows by Grady-Kipp (``grady_kipp[k]``, docs/strength.md) bears (1 - D_k) of its EOS
tension, p_k = max((1 - D_k) P_k, -Y_T,k (1 - D_k)) for P_k < 0 (:func:`tension_factor`):
intact, it holds tension up to Y_T (where the yield curve closes), damaged, that share of it,
none once D_k = 1; the kernels get ``grady_kipp`` None in scenes without it.  The cell's
mixture (:func:`mixture_state`, the gather every kernel that needs the cell's pressure or
signal speed uses: the sweeps, the time step, the cell thermodynamics of the output and the
refinement criteria) is the equal-strain mixture, void a zero-pressure component:

    rho = sum_k alpha_k rho_k              (kg/m^3)
    phi = sum_k alpha_k                    (-, the material fill)
    p   = sum_k alpha_k p_k                (Pa)
    K   = sum_k alpha_k rho_k c_k^2        (Pa, bulk modulus; signal speed c = sqrt(K / rho))
    rho e = sum_k alpha_k rho_k e_k        (J/m^3; specific internal energy e = rho e / rho)
    rho T = sum_k alpha_k rho_k T_k        (K kg/m^3; mass-weighted temperature T = rho T / rho)

the sums of p, K, rho e and rho T over the present materials only.  A partly filled cell
keeps its material's wave speed (K / rho = c_k^2), and a trace of a material (alpha_k of
1e-10 holding a round-off share of the energy, hence an enormous c_k) does not set it.
"""

from __future__ import annotations

from numba import njit

from impactpipe.hydro.eos import pressure_sound_speed, reference_density, temperature
from impactpipe.hydro.eos.porosity import ALPHA0, cell_distension

#: Volume fraction below which a material is left out of a cell's thermodynamics.
ALPHA_MIN = 1.0e-10
#: Material expanded below DISTENDED_FRACTION of its reference density rho0 is fragments or
#: vapour and holds no tension (p_k >= 0): its tensile strength Y_T belongs to the intact
#: solid.  Without this, a spray at 1e-6 rho0 held -Y_T = -0.1 MPa, a tension of 3e7 J/kg
#: per unit mass that flung it to 25 km/s.
DISTENDED_FRACTION = 0.5
#: Rows per material of the per-material output of :func:`mixture_state`, in this order:
#: alpha_k (-), rho_k (kg/m^3), e_k (J/kg), p_k (Pa), K_k = rho_k c_K,k^2 (Pa, the bulk
#: modulus from the EOS sound speed) and Y_T,k (1 - D_k) (Pa, the tension it still holds).
MATERIAL_ROWS = 6


@njit(cache=True, inline="always")
def signal_speed_squared(c2_bulk, rho, shear, rho0):
    """Longitudinal signal speed squared c_K^2 + 4 G / (3 rho) (m^2/s^2).

    c2_bulk: bulk sound speed squared (m^2/s^2); rho: material density (kg/m^3);
    shear: the material's row of the shear table, G = shear[0] + shear[1] K (Pa) with the
    bulk modulus K = rho c_K^2 (:mod:`impactpipe.hydro.strength.parameters`); zeros without strength.
    Material expanded below DISTENDED_FRACTION of its reference density ``rho0`` (kg/m^3)
    carries no deviatoric stress (the strength update gives it none), so no shear wave: its
    signal speed is the bulk one.  (A constant G would otherwise give fragments and spray
    of density rho a speed sqrt(4 G / (3 rho)) without bound as rho falls.)
    """
    if rho < DISTENDED_FRACTION * rho0:
        return c2_bulk
    g = shear[0] + shear[1] * rho * max(c2_bulk, 0.0)
    if g > 0.0:
        return c2_bulk + 4.0 * g / (3.0 * rho)
    return c2_bulk


@njit(cache=True, inline="always")
def damaged_tensile_strength(tensile_strength, arhoq, nq, b, k, ix, iy, iz, ar):
    """Y_T (1 - D) (Pa): the tension material k still holds in a cell, D its damage (-).

    D = (alpha_k rho_k D_k) / (alpha_k rho_k) from the last of the ``nq`` transported
    scalars of material k in ``arhoq`` (:mod:`impactpipe.hydro.strength.update`; ``ar`` =
    alpha_k rho_k, kg/m^3): a failed material (D = 1) holds no tension.  Without transported
    scalars (nq = 0, no strength in the scene) Y_T itself.
    """
    if nq == 0 or not ar > 0.0:
        return tensile_strength
    return tension_left(tensile_strength, arhoq[b, nq * k + nq - 1, ix, iy, iz], ar)


@njit(cache=True, inline="always")
def tension_left(tensile_strength, damage_amount, ar):
    """Y_T (1 - D) (Pa) with D = ``damage_amount`` / ``ar`` (alpha_k rho_k D_k over alpha_k rho_k,
    both kg/m^3, ``ar`` > 0), 1 - D clipped to [0, 1]."""
    damage = damage_amount / ar
    return tensile_strength * min(max(1.0 - damage, 0.0), 1.0)


@njit(cache=True, inline="always")
def tension_factor(grady_kipp, arhoq, nq, b, k, ix, iy, iz, ar):
    """Share 1 - D_k (-) of its EOS tension that material k bears: 1 - D for a Grady-Kipp material
    (``grady_kipp[k]``, D from the last of its ``nq`` transported scalars, ``ar`` = alpha_k rho_k
    > 0), 1 otherwise (instant failure: full tension up to Y_T)."""
    if grady_kipp is None:
        return 1.0
    if not grady_kipp[k] or nq == 0 or not ar > 0.0:
        return 1.0
    return tension_left(1.0, arhoq[b, nq * k + nq - 1, ix, iy, iz], ar)


@njit(cache=True, inline="always")
def material_state(a, ar, are, kind, params, table, shear, tensile_strength, tension_share=1.0, distension=1.0):
    """Thermodynamic state of one material in one cell from its conserved amounts.

    a = alpha_k (-), ar = alpha_k rho_k (kg/m^3), are = alpha_k rho_k e_k (J/m^3).
    Returns (present, rho_k, e_k, p_k, c2_bulk, c2_signal, eos_flag, tension_limited):
    rho_k = ar / a, e_k = are / ar, p_k = max(P(rho_k, e_k), -Y_T) with Y_T =
    ``tensile_strength`` (Pa) for rho_k >= DISTENDED_FRACTION rho0, else max(P, 0), a tension
    P < 0 first scaled by ``tension_share`` (1 - D of a Grady-Kipp material; 1 by default); c2_bulk
    the EOS bulk sound speed squared and c2_signal the time-step signal speed squared
    (:func:`signal_speed_squared` with the shear-table row ``shear``).  A material below
    ALPHA_MIN or without mass is absent (present False, zeros).  A porous material
    (:mod:`impactpipe.hydro.eos.porosity`) of ``distension`` alpha > 1 has p_k = P(alpha rho_k, e_k) / alpha
    and c2_bulk = c_K^2(alpha rho_k, e_k), its solid EOS at the matrix density alpha rho_k, which also
    decides whether it is distended below DISTENDED_FRACTION rho0 (a fracture, not its pores), and
    the tension limit -Y_T / alpha (the matrix's P_s >= -Y_T).
    """
    if not (a > ALPHA_MIN and ar > 0.0):
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0, False
    rk = ar / a
    ek = are / ar
    pk, c2k, flag = pressure_sound_speed(kind, params, table, distension * rk, ek)
    p_min = -tensile_strength
    rho0 = reference_density(kind, params, table)
    if distension != 1.0:
        pk /= distension
        p_min = -tensile_strength / distension
        rho0 = rho0 / distension
    if tension_share != 1.0 and pk < 0.0:
        pk *= tension_share
    if rk < DISTENDED_FRACTION * rho0:
        p_min = 0.0
    limited = pk < p_min
    if limited:
        pk = p_min
    return True, rk, ek, pk, c2k, signal_speed_squared(c2k, rk, shear, rho0), flag, limited


@njit(cache=True, inline="always")
def mixture_state(alpha, arho, arhoe, arhoq, b, ix, iy, iz, eos_kind, eos_params, eos_table, shear_modulus,
                  tensile_strength, with_temperature, materials, row, col, grady_kipp=None, porosity=None):
    """The mixture state of cell (ix, iy, iz) of block b; see the module docstring.

    Fields are ``(NB, C, NX, NY, NZ)``: ``alpha``, ``arho``, ``arhoe`` with C = M materials,
    ``arhoq`` the transported scalars (M * NQ columns, the damage of material k in its last);
    ``eos_kind``, ``eos_params``, ``eos_table`` the packed EOS (:mod:`impactpipe.hydro.eos`),
    ``shear_modulus`` the (M, 2) shear table, ``tensile_strength`` (M,) Y_T (Pa), ``grady_kipp``
    (M,) booleans of the Grady-Kipp materials or None (:func:`tension_factor`), ``porosity`` the
    (M, NPOROSITY) porosity rows (:func:`impactpipe.hydro.eos.porosity.pack_porosity`) or None: a
    porous material's distension is the second-to-last of its transported scalars, and its
    tension limit Y_T,k (1 - D_k) / alpha_k (the matrix's, spread over the bulk).

    Returns (rho, phi, p, K, rho e, rho T, eos_clamps, tension_limits): the sums of the
    module docstring (rho T only with ``with_temperature``, else 0) and how many present
    materials the EOS clamped and how many sit at their tensile limit (p_k raised to
    -Y_T,k (1 - D_k), or to 0 when distended).  With ``materials`` an array (not None),
    material k's MATERIAL_ROWS values go to ``materials[col, row + MATERIAL_ROWS k + j]``
    (an absent material gets alpha_k, zeros and its Y_T,k (1 - D_k)).
    """
    nmat = alpha.shape[1]
    nq = arhoq.shape[1] // nmat
    rho = 0.0
    phi = 0.0
    p = 0.0
    kmod = 0.0
    eint = 0.0
    tmass = 0.0
    clamps = 0
    limits = 0
    for k in range(nmat):
        a = alpha[b, k, ix, iy, iz]
        ar = arho[b, k, ix, iy, iz]
        phi += a
        rho += ar
        ytk = damaged_tensile_strength(tensile_strength[k], arhoq, nq, b, k, ix, iy, iz, ar)
        dist = 1.0
        if porosity is not None:
            if porosity[k, ALPHA0] > 1.0 and ar > 0.0:
                dist = cell_distension(arhoq, nq, b, k, ix, iy, iz, ar)
        present, rk, ek, pk, c2b, c2k, flag, limited = material_state(
            a, ar, arhoe[b, k, ix, iy, iz], eos_kind[k], eos_params[k], eos_table, shear_modulus[k], ytk,
            tension_factor(grady_kipp, arhoq, nq, b, k, ix, iy, iz, ar), dist)
        if porosity is not None:
            if present and dist != 1.0:
                ytk /= dist
        if present:
            p += a * pk
            kmod += ar * c2k
            eint += ar * ek
            if with_temperature:
                tmass += ar * temperature(eos_kind[k], eos_params[k], eos_table, dist * rk, ek)
            if flag != 0:
                clamps += 1
            if limited:
                limits += 1
        if materials is not None:
            r = row + MATERIAL_ROWS * k
            materials[col, r] = a
            materials[col, r + 1] = rk
            materials[col, r + 2] = ek
            materials[col, r + 3] = pk
            materials[col, r + 4] = rk * c2b
            materials[col, r + 5] = ytk
    return rho, phi, p, kmod, eint, tmass, clamps, limits
