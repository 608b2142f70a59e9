"""The CFL time step and the cell thermodynamics of the mixture for the snapshots.

Time step (split scheme, every sweep must satisfy its own Courant condition):

    dt = cfl / max_cells max_d (|u_d| + c) / dx_d

with the cell signal speed c = sqrt(K / rho) of the equal-strain mixture, K = sum_k alpha_k
rho_k c_k^2 over the materials present and per material the longitudinal speed

    c_k^2 = c_K,k^2 + 4 G_k / (3 rho_k)        (:func:`impactpipe.hydro.scheme.mixture.signal_speed_squared`)

the bulk sound speed from the EOS plus the shear modulus term of material strength (G_k = 0
for a strengthless material; ``shear_modulus`` arguments are the (M, 2) shear table of
:mod:`impactpipe.hydro.strength.parameters`: G_k = shear[k, 0] + shear[k, 1] rho_k c_K,k^2).
Both kernels gather the cell's mixture with :func:`impactpipe.hydro.scheme.mixture.mixture_state`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from impactpipe.hydro.mesh.blocks import GHOST
from impactpipe.hydro.scheme.mixture import mixture_state

#: Material volume fraction below which a cell counts as void (no signal, no Riemann state).
PHI_VOID = 1.0e-6


@njit(cache=True, parallel=True)
def max_signal_rate(alpha, arho, arhoe, arhoq, mom, block_dx, eos_kind, eos_params, eos_table, shear_modulus,
                    tensile_strength, ndim, out):
    """Per block, the largest max_d (|u_d| + c) / dx_d (1/s) over non-void interior cells, into ``out[NB]``.

    c = sqrt(K / rho), the signal speed of the cell's mixture (:func:`impactpipe.hydro.scheme.mixture.mixture_state`).
    """
    nb, nmat, nx, ny, nz = alpha.shape
    gx = GHOST if nx > 1 else 0
    gy = GHOST if ny > 1 else 0
    gz = GHOST if nz > 1 else 0
    for b in prange(nb):
        rate = 0.0
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    rho, phi, p, kmod, eint, tmass, clamps, limits = mixture_state(
                        alpha, arho, arhoe, arhoq, b, ix, iy, iz, eos_kind, eos_params, eos_table, shear_modulus,
                        tensile_strength, False, None, 0, 0)
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

    From :func:`impactpipe.hydro.scheme.mixture.mixture_state`: pressure = sum_k alpha_k max(p_k,
    -Y_T,k (1 - D_k)) (Pa), the material pressures limited by the tensile strengths left by
    the damage D_k as in the sweeps; sound_speed = sqrt(sum_k alpha_k rho_k c_k^2 / rho) (m/s),
    the equal-strain mixture's; specific_energy = sum_k alpha_k rho_k e_k / rho (J/kg);
    temp = sum_k alpha_k rho_k T_k / rho (K).  Void cells get zeros.
    """
    nb, nmat, nx, ny, nz = alpha.shape
    gx = GHOST if nx > 1 else 0
    gy = GHOST if ny > 1 else 0
    gz = GHOST if nz > 1 else 0
    for b in prange(nb):
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    rho, phi, p, kmod, eint, tmass, clamps, limits = mixture_state(
                        alpha, arho, arhoe, arhoq, b, ix, iy, iz, eos_kind, eos_params, eos_table, shear_modulus,
                        tensile_strength, True, None, 0, 0)
                    jx = ix - gx
                    jy = iy - gy
                    jz = iz - gz
                    pressure[b, jx, jy, jz] = p
                    sound_speed[b, jx, jy, jz] = np.sqrt(kmod / rho) if rho > 0.0 else 0.0
                    specific_energy[b, jx, jy, jz] = eint / rho if rho > 0.0 else 0.0
                    temp[b, jx, jy, jz] = tmass / rho if rho > 0.0 else 0.0
