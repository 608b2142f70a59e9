"""Signal speeds, the CFL time step and the cell thermodynamics of the mixture.

Time step (split scheme, every sweep must satisfy its own Courant condition):

    dt = cfl / max_cells max_d (|u_d| + c) / dx_d

with the cell signal speed c = max_k c_k over the materials present, and per material

    c_k^2 = c_K,k^2 + 4 G_k / (3 rho_k)        (:func:`signal_speed_squared`)

(``shear_modulus`` arguments are the (M, 2) shear table of
:mod:`impactpipe.hydro.strength.parameters`: G_k = shear[k, 0] + shear[k, 1] rho_k c_K,k^2.)

the longitudinal speed: bulk sound speed from the EOS plus the shear modulus term of
material strength (G_k = 0 for a strengthless material).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from impactpipe.hydro.eos import pressure_sound_speed, reference_density, temperature
from impactpipe.hydro.mesh.blocks import GHOST

#: Volume fraction below which a material is left out of a cell's thermodynamics.
ALPHA_MIN = 1.0e-10
#: Material volume fraction below which a cell counts as void (no signal, no Riemann state).
PHI_VOID = 1.0e-6
#: Material expanded below DISTENDED_FRACTION of its reference density rho0 is fragments or
#: vapour and holds no tension (p_k >= 0): its tensile strength Y_T belongs to the intact
#: solid.  Without this, a spray at 1e-6 rho0 held -Y_T = -0.1 MPa, a tension of 3e7 J/kg
#: per unit mass that flung it to 25 km/s.
DISTENDED_FRACTION = 0.5


@njit(cache=True, inline="always")
def signal_speed_squared(c2_bulk, rho, shear):
    """Longitudinal signal speed squared c_K^2 + 4 G / (3 rho) (m^2/s^2).

    c2_bulk: bulk sound speed squared (m^2/s^2); rho: material density (kg/m^3);
    shear: the material's row of the shear table, G = shear[0] + shear[1] K (Pa) with the
    bulk modulus K = rho c_K^2 (:mod:`impactpipe.hydro.strength.parameters`); zeros without strength.
    """
    g = shear[0] + shear[1] * rho * max(c2_bulk, 0.0)
    if g > 0.0:
        return c2_bulk + 4.0 * g / (3.0 * rho)
    return c2_bulk


@njit(cache=True)
def damaged_tensile_strength(tensile_strength, arhoq, nq, b, k, ix, iy, iz, ar):
    """Y_T (1 - D) (Pa): the tension material k still holds in a cell, D its damage (-).

    D = (alpha_k rho_k D_k) / (alpha_k rho_k) from the last of the ``nq`` transported
    scalars of material k in ``arhoq`` (:mod:`impactpipe.hydro.strength.update`; ``ar`` =
    alpha_k rho_k, kg/m^3): a failed material (D = 1) holds no tension.  Without transported
    scalars (nq = 0, no strength in the scene) Y_T itself.
    """
    if nq == 0 or not ar > 0.0:
        return tensile_strength
    damage = arhoq[b, nq * k + nq - 1, ix, iy, iz] / ar
    return tensile_strength * min(max(1.0 - damage, 0.0), 1.0)


@njit(cache=True, inline="always")
def material_state(a, ar, are, kind, params, table, shear, tensile_strength):
    """Thermodynamic state of one material in one cell from its conserved amounts.

    a = alpha_k (-), ar = alpha_k rho_k (kg/m^3), are = alpha_k rho_k e_k (J/m^3).
    Returns (present, rho_k, e_k, p_k, c2_bulk, c2_signal, eos_flag, tension_limited):
    rho_k = ar / a, e_k = are / ar, p_k = max(P(rho_k, e_k), -Y_T) with Y_T =
    ``tensile_strength`` (Pa) for rho_k >= DISTENDED_FRACTION rho0, else max(P, 0); c2_bulk
    the EOS bulk sound speed squared and c2_signal the time-step signal speed squared
    (:func:`signal_speed_squared` with the shear-table row ``shear``).  A material below
    ALPHA_MIN or without mass is absent (present False, zeros).
    """
    if not (a > ALPHA_MIN and ar > 0.0):
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0, False
    rk = ar / a
    ek = are / ar
    pk, c2k, flag = pressure_sound_speed(kind, params, table, rk, ek)
    p_min = -tensile_strength
    if rk < DISTENDED_FRACTION * reference_density(kind, params, table):
        p_min = 0.0
    limited = pk < p_min
    if limited:
        pk = p_min
    return True, rk, ek, pk, c2k, signal_speed_squared(c2k, rk, shear), flag, limited


@njit(cache=True, parallel=True)
def max_signal_rate(alpha, arho, arhoe, mom, block_dx, eos_kind, eos_params, eos_table, shear_modulus, ndim, out):
    """Per block, the largest max_d (|u_d| + c) / dx_d (1/s) over non-void interior cells, into ``out[NB]``."""
    nb, nmat, nx, ny, nz = alpha.shape
    gx = GHOST if nx > 1 else 0
    gy = GHOST if ny > 1 else 0
    gz = GHOST if nz > 1 else 0
    for b in prange(nb):
        rate = 0.0
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    rho = 0.0
                    phi = 0.0
                    kmod = 0.0
                    for k in range(nmat):
                        a = alpha[b, k, ix, iy, iz]
                        ar = arho[b, k, ix, iy, iz]
                        rho += ar
                        phi += a
                        present, rk, ek, pk, c2b, c2k, flag, limited = material_state(
                            a, ar, arhoe[b, k, ix, iy, iz], eos_kind[k], eos_params[k], eos_table,
                            shear_modulus[k], 0.0)
                        if present:
                            kmod += ar * c2k
                    if rho <= 0.0 or phi < PHI_VOID:
                        continue
                    c = np.sqrt(kmod / rho)
                    for d in range(ndim):
                        r = (abs(mom[b, d, ix, iy, iz]) / rho + c) / block_dx[b, d]
                        if r > rate:
                            rate = r
        out[b] = rate


@njit(cache=True, parallel=True)
def cell_thermodynamics(alpha, arho, arhoe, arhoq, eos_kind, eos_params, eos_table, shear_modulus, tensile_strength,
                        pressure, sound_speed, specific_energy, temp):
    """Interior-cell mixture thermodynamics into ``(NB, nx, ny, nz)`` outputs.

    pressure = sum_k alpha_k max(p_k, -Y_T,k (1 - D_k)) (Pa), the material pressures limited
    by the tensile strengths left by the damage D_k (:func:`damaged_tensile_strength`) as in
    the sweeps; sound_speed = sqrt(sum_k alpha_k rho_k c_k^2 / rho) (m/s),
    the equal-strain mixture's;
    specific_energy = sum_k alpha_k rho_k e_k / rho (J/kg); temp = sum_k alpha_k rho_k T_k / rho (K).
    Void cells get zeros.
    """
    nb, nmat, nx, ny, nz = alpha.shape
    nq = arhoq.shape[1] // nmat
    gx = GHOST if nx > 1 else 0
    gy = GHOST if ny > 1 else 0
    gz = GHOST if nz > 1 else 0
    for b in prange(nb):
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    rho = 0.0
                    p = 0.0
                    kmod = 0.0
                    esum = 0.0
                    tsum = 0.0
                    for k in range(nmat):
                        a = alpha[b, k, ix, iy, iz]
                        ar = arho[b, k, ix, iy, iz]
                        rho += ar
                        ytk = damaged_tensile_strength(tensile_strength[k], arhoq, nq, b, k, ix, iy, iz, ar)
                        present, rk, ek, pk, c2b, c2k, flag, limited = material_state(
                            a, ar, arhoe[b, k, ix, iy, iz], eos_kind[k], eos_params[k], eos_table,
                            shear_modulus[k], ytk)
                        if present:
                            p += a * pk
                            kmod += ar * c2k
                            esum += ar * ek
                            tsum += ar * temperature(eos_kind[k], eos_params[k], eos_table, rk, ek)
                    jx = ix - gx
                    jy = iy - gy
                    jz = iz - gz
                    pressure[b, jx, jy, jz] = p
                    sound_speed[b, jx, jy, jz] = np.sqrt(kmod / rho) if rho > 0.0 else 0.0
                    specific_energy[b, jx, jy, jz] = esum / rho if rho > 0.0 else 0.0
                    temp[b, jx, jy, jz] = tsum / rho if rho > 0.0 else 0.0
