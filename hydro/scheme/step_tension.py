"""The tensile limit applied once per step, to the state the sweeps leave (``Simulation.step_tensile_limit``).

By default the sweeps hold each material's pressure at its tensile limit, p_k >= -Y_T,k (1 - D_k),
and a cell at that limit opens void instead of stretching its material
(:func:`impactpipe.hydro.scheme.mixture.material_state`, the sweeps' volume closure).  In a pair
of split sweeps the cell between them holds the one-dimensional strain of the first, dt u_x,
whose pressure change K dt u_x is first order in the time step: in a nearly incompressible
flow that stretches along x and shortens along z (a collapsing granular column) it takes the
material below zero pressure between the sweeps although the full step leaves it in
compression, and a cohesionless material (Y_T = 0) is then held at p = 0 for the second sweep.
How many cells that touches grows with the Courant number, and the deposit of the column
collapse depended on it (docs/validation.md, "Granular column collapse").

With ``step_tensile_limit`` the sweeps are given no tensile limit (Y_T = UNLIMITED_TENSION;
material expanded below DISTENDED_FRACTION rho0 still holds none) and :func:`open_void_in_tension`
applies it to the state at the end of the sweeps: material k of a cell at P_k(rho_k, e_k) below
-Y_T,k (1 - D_k) opens void, its volume fraction lowered at fixed mass and internal energy,

    alpha_k <- alpha_k rho_k / rho',   P_k(rho', e_k) = -Y_T,k (1 - D_k),

so the strength update and the next step's sweeps see it at its limit, as the sweeps' closure
leaves it.  Mass, momentum and energy are unchanged.  Not for porous or Grady-Kipp materials
(the solver refuses the option with them).
"""

from __future__ import annotations

from numba import njit, prange

from impactpipe.hydro.eos import pressure_sound_speed, reference_density
from impactpipe.hydro.mesh.blocks import ghost_widths
from impactpipe.hydro.scheme.mixture import ALPHA_MIN, DISTENDED_FRACTION, tension_left
from impactpipe.hydro.scheme.pencil_layout import FLOOR_TENSILE_LIMIT

#: The sweeps' tensile strength Y_T (Pa) with ``step_tensile_limit``: no tension they would hold back.
UNLIMITED_TENSION = 1.0e300

#: Newton iterations of :func:`open_void_in_tension` on P_k(rho', e_k) = -Y_T,k (1 - D_k).
TENSION_ITERATIONS = 30


@njit(cache=True, parallel=True)
def open_void_in_tension(alpha, arho, arhoe, arhoq, eos_kind, eos_params, eos_table, tensile_strength, floors, lo, hi):
    """Bring every material below its tensile limit back to it by opening void (module docstring).

    Interior cells of the blocks ``lo .. hi - 1``; fields ``(NB, C, NX, NY, NZ)``: ``alpha`` (-),
    ``arho`` alpha_k rho_k (kg/m^3), ``arhoe`` alpha_k rho_k e_k (J/m^3), ``arhoq`` the transported
    scalars (the damage D_k of material k the last of its NQ); ``tensile_strength`` (M,) Y_T (Pa).
    Material k is touched where present (alpha_k > ALPHA_MIN, alpha_k rho_k > 0), at
    rho_k >= DISTENDED_FRACTION rho0_k (below it the sweeps hold its pressure at zero) and at
    P_k < -Y_T,k (1 - D_k).  rho' from Newton steps rho <- rho + (P_target - P) / c_K^2 (c_K^2 the
    EOS's squared bulk sound speed, m^2/s^2), repeated while P < P_target (at most
    TENSION_ITERATIONS; for an EOS convex in rho the first step lands at or above P_target, above
    it by a second-order amount: 0.3 % of the excursion P_target - P from 0.999 rho0 of basalt, 3 %
    from 0.99), so the strength update finds the material at its limit or just inside it, not
    past it; each cell touched counts
    in ``floors[b, FLOOR_TENSILE_LIMIT]``.
    """
    nb, nmat, nx, ny, nz = alpha.shape
    nq = arhoq.shape[1] // nmat
    gx, gy, gz = ghost_widths(nx, ny, nz)
    for b in prange(lo, hi):
        for k in range(nmat):
            rho0 = reference_density(eos_kind[k], eos_params[k], eos_table)
            for ix in range(gx, nx - gx):
                for iy in range(gy, ny - gy):
                    for iz in range(gz, nz - gz):
                        a = alpha[b, k, ix, iy, iz]
                        ar = arho[b, k, ix, iy, iz]
                        if not (a > ALPHA_MIN and ar > 0.0):
                            continue
                        rk = ar / a
                        if rk < DISTENDED_FRACTION * rho0:
                            continue
                        ek = arhoe[b, k, ix, iy, iz] / ar
                        p_limit = -tensile_strength[k]
                        if nq > 0:
                            p_limit = -tension_left(tensile_strength[k], arhoq[b, nq * k + nq - 1, ix, iy, iz], ar)
                        pk, c2, flag = pressure_sound_speed(eos_kind[k], eos_params[k], eos_table, rk, ek)
                        if not pk < p_limit:
                            continue
                        rho_new = rk
                        for _ in range(TENSION_ITERATIONS):
                            rho_new += (p_limit - pk) / c2
                            pk, c2, flag = pressure_sound_speed(eos_kind[k], eos_params[k], eos_table, rho_new, ek)
                            if pk >= p_limit:
                                break
                        alpha[b, k, ix, iy, iz] = ar / rho_new
                        floors[b, FLOOR_TENSILE_LIMIT] += 1
