"""One directionally split sweep of the multi-material Godunov scheme (the hydro kernel).

Conserved fields per cell (:mod:`impactpipe.hydro.mesh.state`): volume fraction ``alpha_k``, partial density
``alpha_k rho_k`` (kg/m^3), material internal energy density ``alpha_k rho_k e_k`` (J/m^3),
momentum density (kg/m^2/s) and total energy density E (J/m^3).  Void fills ``1 - sum alpha_k``.

A sweep along axis d advances every pencil of cells along d by dt in flux form

    U_i^{n+1} = U_i - dt (A_{i+1/2} F_{i+1/2} - A_{i-1/2} F_{i-1/2}) / V_i  + dt S_i

(A face areas, V cell volumes; 2d-cylindrical r faces have A = 2 pi r dz, V = pi (r_+^2 -
r_-^2) dz and the radial momentum source S = p (A_{i+1/2} - A_{i-1/2}) / V, the same
difference as in the flux term, so a uniform state at rest stays at rest to round-off).

Stencil, cell i with ghosts g = 2 (``|`` faces)::

      i-2 | i-1 | i | i+1 | i+2
            slopes of i-1, i, i+1 -> face states at i-1/2 and i+1/2 -> fluxes

1. Gather (:func:`impactpipe.hydro.scheme.mixture.mixture_state`): mixture density
   rho = sum alpha_k rho_k, velocity, pressure p = sum alpha_k p_k (equal-strain mixture;
   void counts as a zero-pressure component), bulk modulus K = sum alpha_k rho_k c_k^2
   (c_k the longitudinal signal speed), signal speed c = sqrt(K / rho), the sound speed of
   the equal-strain mixture.  A partly filled cell keeps the wave speed of its material
   (K / rho = c_k^2), and a trace of a material (a volume fraction of 1e-10 holding a
   round-off share of the energy, hence an enormous c_k) does not set the time step.
2. MUSCL-Hancock: MC-limited slopes of (u_n, u_t1, u_t2, p) and per material
   (alpha_k, rho_k, e_k); half-step predictor with the primitive equations
   u_t = -u u_x - p_x / rho, p_t = -u p_x - K u_x, alpha_t = -u alpha_x,
   rho_k,t = -u rho_k,x - rho_k u_x, e_k,t = -u e_k,x - (p_k / rho_k) u_x.
   The flow (u, p) is reconstructed where the cell and its neighbours are filled to
   PHI_FLOW_SECOND_ORDER (0.9) and hold materials of like density (rho_k within a factor
   DENSITY_RATIO_SECOND_ORDER of each other); the materials (alpha_k, rho_k, e_k) only where
   they are moreover full (fill >= PHI_SECOND_ORDER), elsewhere they keep their cell values,
   so a partly void cell's face density is its own.  A cell next to void, thinner or mixed
   with a much lighter material, or whose face state loses positivity (density <= 0, or a
   pressure drop from p > 0 to below -TENSION_TOLERANCE K), uses its cell values; face e_k
   of a cell with e_k >= 0 are clipped at 0.
3. Faces: :func:`impactpipe.hydro.scheme.riemann.hllc_face` (free surface next to void) gives the
   face velocity s, pressure p* and upwind star factors.  Material k's volume flux is
   alpha_k,face s with the compressive ultrabee face value of alpha_k (capped so no more than
   the donor's material volume leaves), its mass flux alpha_k,face rho_k,K chi s (capped by the
   donor's mass), its internal energy flux the mass flux times e_k,K.  Momentum and total
   energy fluxes use the summed mass flux (HLLC exactly for one material).
4. Update with the volume closure: after the fluxes, a cell whose materials fill more than
   its volume is compressed (alpha_k scaled to sum 1: void is squeezed out first, then the
   materials share the strain); a full cell (no void) with positive velocity divergence
   dV = dt div(s) expands each material by alpha_k dV (equal strain), while in a cell with
   void the void takes the expansion (no material is spread into void by a divergence),
   and a material at positive pressure p_k relaxes into the cell's void: it expands by
   alpha_k p_k / K_k (the acoustic volume change that brings p_k to zero), all materials
   scaled down together if the void is smaller, doing the work p_k / 2 per unit volume.  Each material takes the work
   -p_k (change of its volume fraction from the closure).  Total energy is conserved by
   the fluxes; the difference between E - |m|^2 / (2 rho) and sum alpha_k rho_k e_k is
   given to the materials in proportion to their mass (counted as reconciled energy).
5. Transported per-material scalars (the generic hook for material strength): each column
   j of ``arhoq[NB, M * NQ, ...]`` holds a mass-weighted amount alpha_k rho_k q_k,j of
   material k = column // NQ; it moves with material k's mass flux at the donor cell's
   specific value q_k,j (first order), and is removed with the material by the cleanups.
   With NQ = 0 (no strength) the hook does no work.
6. Floors (counted per block): negative alpha_k or partial density -> 0, negative material
   internal energy -> 0 with E raised to match, an emptied cell -> void.  NaN or a
   mixture density below -FAIL_NEGATIVE_FRACTION of the cell's previous density is a
   failure recorded in ``failure`` for the solver to raise.

A pencil that one material fills alone takes the plain path of
:mod:`impactpipe.hydro.scheme.plain_pencils` (the same arithmetic without the multi-material
machinery) after the same gather; the predictor and flux pieces both paths use are in
:mod:`impactpipe.hydro.scheme.pencil_steps`, the thresholds, counter slots and scratch rows in
:mod:`impactpipe.hydro.scheme.pencil_layout`.
"""

from __future__ import annotations

import numpy as np
from numba import get_thread_id, njit, prange

from impactpipe.hydro.eos import reference_density
from impactpipe.hydro.mesh.blocks import CYLINDRICAL, GHOST
from impactpipe.hydro.eos import pressure_sound_speed_in_line
from impactpipe.hydro.scheme.mixture import (ALPHA_MIN, DISTENDED_FRACTION, damaged_tensile_strength, mixture_state,
                                             signal_speed_squared)
from impactpipe.hydro.scheme.riemann import UPWIND_LEFT, UPWIND_NONE
from impactpipe.hydro.scheme.pencil_layout import (
    AMOUNT_ENERGY_CAP,
    AMOUNT_ENERGY_FLOOR,
    AMOUNT_ENERGY_LIMITER,
    AMOUNT_ENERGY_RECONCILED,
    AMOUNT_ENERGY_VOID,
    AMOUNT_MASS_FLOOR,
    AMOUNT_MASS_VOID,
    AMOUNT_MOMENTUM_LIMITER,
    AMOUNT_MOMENTUM_VOID,
    BND_ENERGY,
    BND_MASS,
    BND_MATERIAL,
    BND_MOMENTUM,
    DISCARD_FRACTION,
    EMPTIED_FRACTION,
    F_E,
    F_MAT,
    F_MN,
    F_MT1,
    F_MT2,
    F_S,
    FAIL_NAN,
    FAIL_NEGATIVE_DENSITY,
    FAIL_NEGATIVE_FRACTION,
    FLOOR_ALPHA,
    FLOOR_ENERGY_LIMIT,
    FLOOR_EOS_CLAMP,
    FLOOR_FIRST_ORDER,
    FLOOR_INTERNAL_ENERGY,
    FLOOR_PARTIAL_DENSITY,
    FLOOR_TENSILE_LIMIT,
    FLOOR_VELOCITY_LIMIT,
    FLOOR_VOID_CLEANUP,
    FULL_TOLERANCE,
    DENSITY_RATIO_SECOND_ORDER,
    PHI_FLOW_SECOND_ORDER,
    PHI_SECOND_ORDER,
    PHI_SMALL,
    Q_MAT,
    Q_P,
    Q_UN,
    TENSION_TOLERANCE,
    W_C,
    W_IVL,
    W_IVR,
    W_K,
    W_MAT,
    W_P,
    W_PHI,
    W_RHO,
    W_STRIDE,
    W_UN,
    W_UT1,
    W_UT2,
    W_VOL,
    pencil_cell_index,
)
from impactpipe.hydro.scheme.plain_pencils import (
    EMPTY_PENCIL,
    face_flux_plain,
    plain_material,
    reconstruct_plain,
    update_plain,
)
from impactpipe.hydro.scheme.pencil_steps import (
    cell_value_faces,
    flow_fluxes,
    material_face_flux,
    predict_flow,
    predict_material,
    upwind_face,
)
from impactpipe.hydro.scheme.timestep import PHI_VOID


@njit(cache=True, parallel=True)
def sweep(axis, dt, geometry, alpha, arho, arhoe, arhoq, mom, energy, block_lo, block_dx, neighbor,
          neighbor_level, eos_kind, eos_params, eos_table, shear_modulus, tensile_strength, scratch, boundary,
          floors, amounts, failure, face_flux, plain_pencils):
    """Advance all blocks by ``dt`` (s) along ``axis``; see the module docstring.

    Field arrays are ``(NB, C, NX, NY, NZ)`` with filled ghosts along ``axis``.  Counters
    ``boundary``, ``floors``, ``amounts`` accumulate per block; ``failure`` records the first
    failing cell of each block.  Through each block face along ``axis`` whose neighbour is at
    another refinement level (``neighbor_level`` != 0) the amounts dt A F are stored in
    ``face_flux[b, side, :, j1, j2]`` for refluxing (:mod:`impactpipe.hydro.amr.transfer`).
    With ``plain_pencils`` a pencil that one material fills alone takes the plain path
    (:mod:`impactpipe.hydro.scheme.plain_pencils`); without, every pencil takes the general path.
    """
    nb, nmat, nx, ny, nz = alpha.shape
    npad = (nx, ny, nz)
    ncell = npad[axis]
    g = GHOST
    n = ncell - 2 * g
    t1 = 1 if axis == 0 else 0
    t2 = 1 if axis == 2 else 2
    n1 = npad[t1]
    n2 = npad[t2]
    lo1 = g if n1 > 1 else 0
    hi1 = n1 - g if n1 > 1 else 1
    lo2 = g if n2 > 1 else 0
    hi2 = n2 - g if n2 > 1 else 1
    q0 = W_MAT + W_STRIDE * nmat
    qm_row = q0
    qp_row = q0 + Q_MAT + 3 * nmat
    f_row = qp_row + Q_MAT + 3 * nmat
    nq = arhoq.shape[1] // nmat
    wq_row = f_row + F_MAT + 3 * nmat
    fq_row = wq_row + nmat * nq
    radial = geometry == CYLINDRICAL and axis == 0
    axial = geometry == CYLINDRICAL and axis == 1
    for b in prange(nb):
        sc = scratch[get_thread_id()]
        dx = block_dx[b, axis]
        dtdx = dt / dx
        half = 0.5 * dtdx
        d1 = block_dx[b, t1] if n1 > 1 else 1.0
        d2 = block_dx[b, t2] if n2 > 1 else 1.0
        for j1 in range(lo1, hi1):
            for j2 in range(lo2, hi2):
                # geometry of the pencil: A/V on both sides of each cell and physical volumes
                face_area_lo = d1 * d2
                face_area_hi = d1 * d2
                for i in range(ncell):
                    if radial:
                        r_lo = block_lo[b, 0] + (i - g) * dx
                        r_hi = r_lo + dx
                        vol = abs(r_hi * r_hi - r_lo * r_lo)
                        sc[W_IVL, i] = 2.0 * abs(r_lo) / vol
                        sc[W_IVR, i] = 2.0 * abs(r_hi) / vol
                        sc[W_VOL, i] = np.pi * vol * d1
                        if i == g:
                            face_area_lo = 2.0 * np.pi * abs(r_lo) * d1
                        if i == g + n - 1:
                            face_area_hi = 2.0 * np.pi * abs(r_hi) * d1
                    elif axial:
                        r_lo = block_lo[b, 0] + (j1 - g) * d1
                        r_hi = r_lo + d1
                        ring = np.pi * abs(r_hi * r_hi - r_lo * r_lo)
                        sc[W_IVL, i] = 1.0 / dx
                        sc[W_IVR, i] = 1.0 / dx
                        sc[W_VOL, i] = ring * dx
                        face_area_lo = ring
                        face_area_hi = ring
                    else:
                        sc[W_IVL, i] = 1.0 / dx
                        sc[W_IVR, i] = 1.0 / dx
                        sc[W_VOL, i] = dx * d1 * d2
                # 1-3. cell values, face states and fluxes: the plain path for a pencil that one material
                # fills alone (hydro.scheme.plain_pencils), the general path otherwise
                m = -1
                if plain_pencils:
                    m = plain_material(alpha, arho, arhoe, arhoq, mom, energy, b, axis, j1, j2, ncell)
                rho0_m = reference_density(eos_kind[m], eos_params[m], eos_table) if m >= 0 else 0.0
                if m == EMPTY_PENCIL:
                    for f in (g, g + n):
                        for r in range(f_row, fq_row + nmat * nq):
                            sc[r, f] = 0.0
                elif m >= 0:
                    for i in range(ncell):
                        _gather_plain(sc, i, m, rho0_m, b, axis, t1, t2, j1, j2, i >= g and i < g + n, alpha, arho,
                                      arhoe, arhoq, mom, eos_kind, eos_params, eos_table, shear_modulus,
                                      tensile_strength, nq, wq_row, floors)
                    for i in range(1, ncell - 1):
                        reconstruct_plain(sc, m, i, half, qm_row, qp_row, floors, b, i >= g and i < g + n)
                    for f in range(g, g + n + 1):
                        face_flux_plain(sc, m, nmat, f, dt, dtdx, qm_row, qp_row, f_row, nq, wq_row, fq_row)
                else:
                    # 1. gather cell values
                    for i in range(ncell):
                        _gather_cell(sc, i, b, axis, t1, t2, j1, j2, i >= g and i < g + n, alpha, arho, arhoe,
                                     arhoq, mom, eos_kind, eos_params, eos_table, shear_modulus, tensile_strength,
                                     nq, wq_row, floors)
                    # 2. MUSCL-Hancock face states of cells 1 .. ncell-2
                    for i in range(1, ncell - 1):
                        _reconstruct_cell(sc, i, nmat, half, qm_row, qp_row, floors, b, i >= g and i < g + n)
                    # 3. face fluxes, faces g .. g+n (face f between cells f-1 and f)
                    for f in range(g, g + n + 1):
                        _face_flux(sc, f, nmat, dt, dtdx, qm_row, qp_row, f_row, nq, wq_row, fq_row)
                # boundary counters: fluxes through domain faces (positive = leaving)
                for side in range(2):
                    if neighbor[b, axis, side] < 0:
                        f = g if side == 0 else g + n
                        w = -dt * face_area_lo if side == 0 else dt * face_area_hi
                        mass = 0.0
                        for k in range(nmat):
                            mk = sc[f_row + F_MAT + 3 * k + 1, f]
                            mass += mk
                            boundary[b, BND_MATERIAL + k] += w * mk
                        boundary[b, BND_MASS] += w * mass
                        boundary[b, BND_MOMENTUM + axis] += w * sc[f_row + F_MN, f]
                        boundary[b, BND_MOMENTUM + t1] += w * sc[f_row + F_MT1, f]
                        boundary[b, BND_MOMENTUM + t2] += w * sc[f_row + F_MT2, f]
                        boundary[b, BND_ENERGY] += w * sc[f_row + F_E, f]
                    elif neighbor_level[b, axis, side] != 0:
                        f = g if side == 0 else g + n
                        area = dt * (face_area_lo if side == 0 else face_area_hi)
                        for k in range(nmat):
                            for c in range(3):
                                face_flux[b, side, c * nmat + k, j1, j2] = area * sc[f_row + F_MAT + 3 * k + c, f]
                        face_flux[b, side, 3 * nmat + axis, j1, j2] = area * sc[f_row + F_MN, f]
                        face_flux[b, side, 3 * nmat + t1, j1, j2] = area * sc[f_row + F_MT1, f]
                        face_flux[b, side, 3 * nmat + t2, j1, j2] = area * sc[f_row + F_MT2, f]
                        face_flux[b, side, 3 * nmat + 3, j1, j2] = area * sc[f_row + F_E, f]
                        for c in range(nmat * nq):
                            face_flux[b, side, 3 * nmat + 4 + c, j1, j2] = area * sc[fq_row + c, f]
                # 4-5. update interior cells
                if m == EMPTY_PENCIL:
                    continue
                for i in range(g, g + n):
                    ix, iy, iz = pencil_cell_index(axis, i, j1, j2)
                    if m >= 0 and update_plain(sc, m, i, dt, radial, qm_row, qp_row, f_row, b, ix, iy, iz, alpha,
                                               arho, arhoe, mom, energy, axis, t1, t2, floors, amounts,
                                               rho0_m, arhoq, nq, fq_row):
                        continue
                    _update_cell(sc, i, nmat, dt, radial, qm_row, qp_row, f_row, b, ix, iy, iz,
                                 alpha, arho, arhoe, mom, energy, axis, t1, t2, floors, amounts, failure,
                                 eos_kind, eos_params, eos_table, arhoq, nq, fq_row)


@njit(cache=True, inline="always")
def _gather_plain(sc, i, m, rho0_m, b, axis, t1, t2, j1, j2, interior, alpha, arho, arhoe, arhoq, mom, eos_kind,
                  eos_params, eos_table, shear_modulus, tensile_strength, nq, wq_row, floors):
    """Step 1 for cell i of a plain pencil (material m alone, full, ``rho0_m`` its reference
    density, kg/m^3): the W rows of :func:`_gather_cell`, bit for bit, with material m's EOS
    called in place (:func:`impactpipe.hydro.eos.pressure_sound_speed_in_line`) and the absent
    materials' rows written without an EOS call (alpha_k, zeros, their Y_T,k (1 - D_k)).
    """
    ix, iy, iz = pencil_cell_index(axis, i, j1, j2)
    kind = eos_kind[m]
    params = eos_params[m]
    a = alpha[b, m, ix, iy, iz]
    ar = arho[b, m, ix, iy, iz]
    rk = ar / a
    ek = arhoe[b, m, ix, iy, iz] / ar
    pk, c2b, flag = pressure_sound_speed_in_line(kind, params, eos_table, rk, ek)
    ytk = damaged_tensile_strength(tensile_strength[m], arhoq, nq, b, m, ix, iy, iz, ar)
    p_min = -ytk
    if rk < DISTENDED_FRACTION * rho0_m:
        p_min = 0.0
    if pk < p_min:
        pk = p_min
        if interior:
            floors[b, FLOOR_TENSILE_LIMIT] += 1
    if interior and flag != 0:
        floors[b, FLOOR_EOS_CLAMP] += 1
    c2k = signal_speed_squared(c2b, rk, shear_modulus[m])
    for k in range(alpha.shape[1]):
        r = W_MAT + W_STRIDE * k
        if k == m:
            sc[r, i] = a
            sc[r + 1, i] = rk
            sc[r + 2, i] = ek
            sc[r + 3, i] = pk
            sc[r + 4, i] = rk * c2b
            sc[r + 5, i] = ytk
        else:
            sc[r, i] = alpha[b, k, ix, iy, iz]
            sc[r + 1, i] = 0.0
            sc[r + 2, i] = 0.0
            sc[r + 3, i] = 0.0
            sc[r + 4, i] = 0.0
            sc[r + 5, i] = damaged_tensile_strength(tensile_strength[k], arhoq, nq, b, k, ix, iy, iz,
                                                    arho[b, k, ix, iy, iz])
        if nq > 0:
            ark = arho[b, k, ix, iy, iz]
            inv_ar = 1.0 / ark if ark > 0.0 else 0.0
            for j in range(nq):
                sc[wq_row + nq * k + j, i] = arhoq[b, nq * k + j, ix, iy, iz] * inv_ar
    kmod = ar * c2k
    sc[W_PHI, i] = a
    sc[W_C, i] = np.sqrt(kmod / ar)
    sc[W_RHO, i] = ar
    sc[W_P, i] = a * pk
    sc[W_K, i] = kmod
    inv = 1.0 / ar
    sc[W_UN, i] = mom[b, axis, ix, iy, iz] * inv
    sc[W_UT1, i] = mom[b, t1, ix, iy, iz] * inv
    sc[W_UT2, i] = mom[b, t2, ix, iy, iz] * inv


@njit(cache=True, inline="always")
def _gather_cell(sc, i, b, axis, t1, t2, j1, j2, interior, alpha, arho, arhoe, arhoq, mom, eos_kind, eos_params,
                 eos_table, shear_modulus, tensile_strength, nq, wq_row, floors):
    """Step 1 for cell i of the pencil: the cell values of the W rows.

    The mixture and per-material states from :func:`impactpipe.hydro.scheme.mixture.mixture_state`
    (its EOS clamps and tensile limits counted for interior cells), the velocity m / rho and
    the specific transported scalars q_k,j = (alpha_k rho_k q_k,j) / (alpha_k rho_k); a void
    cell (rho <= 0 or phi < PHI_VOID) has zero density, velocity, pressure and bulk modulus.
    """
    ix, iy, iz = pencil_cell_index(axis, i, j1, j2)
    rho, phi, p, kmod, eint, tmass, clamps, limits = mixture_state(
        alpha, arho, arhoe, arhoq, b, ix, iy, iz, eos_kind, eos_params, eos_table, shear_modulus, tensile_strength,
        False, sc, W_MAT, i)
    if interior and clamps > 0:
        floors[b, FLOOR_EOS_CLAMP] += clamps
    if interior and limits > 0:
        floors[b, FLOOR_TENSILE_LIMIT] += limits
    if nq > 0:
        for k in range(alpha.shape[1]):
            ar = arho[b, k, ix, iy, iz]
            inv_ar = 1.0 / ar if ar > 0.0 else 0.0
            for j in range(nq):
                sc[wq_row + nq * k + j, i] = arhoq[b, nq * k + j, ix, iy, iz] * inv_ar
    sc[W_PHI, i] = phi
    sc[W_C, i] = np.sqrt(kmod / rho) if rho > 0.0 else 0.0
    if rho > 0.0 and phi >= PHI_VOID:
        sc[W_RHO, i] = rho
        sc[W_P, i] = p
        sc[W_K, i] = kmod
        inv = 1.0 / rho
        sc[W_UN, i] = mom[b, axis, ix, iy, iz] * inv
        sc[W_UT1, i] = mom[b, t1, ix, iy, iz] * inv
        sc[W_UT2, i] = mom[b, t2, ix, iy, iz] * inv
    else:
        sc[W_RHO, i] = 0.0
        sc[W_P, i] = 0.0
        sc[W_K, i] = 0.0
        sc[W_UN, i] = 0.0
        sc[W_UT1, i] = 0.0
        sc[W_UT2, i] = 0.0


@njit(cache=True, inline="always")
def _reconstruct_cell(sc, i, nmat, half, qm_row, qp_row, floors, b, interior):
    """MUSCL-Hancock states at the low (row block ``qm_row``) and high (``qp_row``) faces of cell i.

    Second order for the flow (u, p) where the cell and both neighbours are filled to
    PHI_FLOW_SECOND_ORDER with materials whose densities rho_k differ by at most a factor
    DENSITY_RATIO_SECOND_ORDER, and for the materials (alpha_k, rho_k, e_k) where they are
    moreover filled to PHI_SECOND_ORDER (the contact of two solids); otherwise cell values.
    The face pressures must stay admissible: not below the most tension the cell's materials
    hold, p_min = -sum_k alpha_k Y_T,k (1 - D_k) (Pa), and not from p > 0 to below -TENSION_TOLERANCE K.
    A predictor that leaves that range (the Hancock term K du/dx of a cell at its tensile
    limit can predict tens of MPa of tension, which would pull a light neighbour to many
    km/s) falls back to the cell values (first order, counted).
    """
    flow_second = sc[W_RHO, i] > 0.0
    material_second = flow_second
    for j in range(i - 1, i + 2):
        fill = 0.0
        rho_min = 1.0e300
        rho_max = 0.0
        for k in range(nmat):
            a = sc[W_MAT + W_STRIDE * k, j]
            fill += a
            if a > ALPHA_MIN:
                r = sc[W_MAT + W_STRIDE * k + 1, j]
                rho_min = min(rho_min, r)
                rho_max = max(rho_max, r)
        alike = rho_max <= DENSITY_RATIO_SECOND_ORDER * rho_min
        if not (fill >= PHI_SECOND_ORDER and alike):
            material_second = False
        if not (sc[W_RHO, j] > 0.0 and fill >= PHI_FLOW_SECOND_ORDER and alike):
            flow_second = False
    if flow_second:
        un, dun, p, p_face = predict_flow(sc, i, half, qm_row, qp_row)
        fallback = p > 0.0 and p_face < -TENSION_TOLERANCE * sc[W_K, i]
        p_min = 0.0
        for k in range(nmat):
            p_min -= sc[W_MAT + W_STRIDE * k, i] * sc[W_MAT + W_STRIDE * k + 5, i]
        if p_face < p_min and p_face < p:
            fallback = True
        if material_second and not fallback:
            for k in range(nmat):
                if predict_material(sc, i, W_MAT + W_STRIDE * k, Q_MAT + 3 * k, half, un, dun, qm_row, qp_row):
                    fallback = True
        if fallback:
            flow_second = False
            if interior:
                floors[b, FLOOR_FIRST_ORDER] += 1
    if not flow_second:
        cell_value_faces(sc, i, qm_row, qp_row, (W_MAT, W_STRIDE, nmat), (Q_MAT, 3, nmat))
    elif not material_second:
        cell_value_faces(sc, i, qm_row, qp_row, (W_MAT, W_STRIDE, nmat), (Q_MAT, 3, nmat), flow=False)


@njit(cache=True, inline="always")
def _face_flux(sc, f, nmat, dt, dtdx, qm_row, qp_row, f_row, nq, wq_row, fq_row):
    """Fluxes through face f (between cells f-1 and f), stored in column f of the F rows."""
    il = f - 1
    ir = f
    rho_l = 0.0
    rho_r = 0.0
    for k in range(nmat):
        qrow = Q_MAT + 3 * k
        rho_l += sc[qp_row + qrow, il] * sc[qp_row + qrow + 1, il]
        rho_r += sc[qm_row + qrow, ir] * sc[qm_row + qrow + 1, ir]
    void_l = sc[W_PHI, il] < PHI_VOID or rho_l <= 0.0
    void_r = sc[W_PHI, ir] < PHI_VOID or rho_r <= 0.0
    side, s, p_star, chi, de, donor, up, down, krow, iv_donor = upwind_face(sc, f, rho_l, void_l, rho_r, void_r,
                                                                             qm_row, qp_row)
    donor_void = void_l if side == UPWIND_LEFT else void_r
    nu = abs(s) * dtdx
    flow = abs(s) * dt * iv_donor
    mass = 0.0
    eint = 0.0
    for k in range(nmat):
        row = W_MAT + W_STRIDE * k
        qrow = Q_MAT + 3 * k
        a_donor = sc[row, donor]
        frow = f_row + F_MAT + 3 * k
        if side == UPWIND_NONE or donor_void or a_donor < ALPHA_MIN or s == 0.0:
            sc[frow, f] = 0.0
            sc[frow + 1, f] = 0.0
            sc[frow + 2, f] = 0.0
            for j in range(nq):
                sc[fq_row + nq * k + j, f] = 0.0
            continue
        # a donor cell holding void in a diverging flow (its velocity or its left neighbour's
        # negative, its own or its right neighbour's positive) may lose material through both
        # faces: each face takes at most half of its content, so together they never overdraw
        # it (the test uses cell values, the same in both blocks of a face)
        share = 1.0
        if (sc[W_PHI, donor] <= 1.0 - FULL_TOLERANCE
                and min(sc[W_UN, donor - 1], sc[W_UN, donor]) < 0.0 < max(sc[W_UN, donor], sc[W_UN, donor + 1])):
            share = 0.5
        mk, ek = material_face_flux(sc, f, row, qrow, frow, donor, up, down, krow, nu, flow, share, s, chi, dt,
                                    iv_donor)
        for j in range(nq):
            sc[fq_row + nq * k + j, f] = mk * sc[wq_row + nq * k + j, donor]
        mass += mk
        eint += mk * ek
    flow_fluxes(sc, f, f_row, krow, donor, mass, eint, s, p_star, de)


@njit(cache=True, inline="always")
def _update_cell(sc, i, nmat, dt, radial, qm_row, qp_row, f_row, b, ix, iy, iz,
                 alpha, arho, arhoe, mom, energy, axis, t1, t2, floors, amounts, failure,
                 eos_kind, eos_params, eos_table, arhoq, nq, fq_row):
    """Flux-form update of cell i with volume closure, energy reconciliation and floors.

    A material at its tensile limit (pressure <= -Y_T (1 - D), the damaged tensile strength
    the gather put in scratch row 5 of the material; a failed material, D = 1, holds none) does
    not share the expansion of a full cell: the cell opens void instead (tensile failure
    by void insertion, as CTH does), so no material is stretched beyond its strength.
    """
    wl = dt * sc[W_IVL, i]
    wr = dt * sc[W_IVR, i]
    vol = sc[W_VOL, i]
    fl = i
    fr = i + 1
    dv = wr * sc[f_row + F_S, fr] - wl * sc[f_row + F_S, fl]
    rho_old = sc[W_RHO, i]
    # volume fractions after the fluxes
    asum = 0.0
    for k in range(nmat):
        frow = f_row + F_MAT + 3 * k
        a_new = alpha[b, k, ix, iy, iz] - (wr * sc[frow, fr] - wl * sc[frow, fl])
        alpha[b, k, ix, iy, iz] = a_new
        asum += a_new
    # volume closure and p dV work
    full = sc[W_PHI, i] > 1.0 - FULL_TOLERANCE
    relax = 0.0
    if asum <= 1.0 and not full:
        want = 0.0
        for k in range(nmat):
            row = W_MAT + W_STRIDE * k
            if sc[row + 3, i] > 0.0 and sc[row + 4, i] > 0.0:
                want += alpha[b, k, ix, iy, iz] * sc[row + 3, i] / sc[row + 4, i]
        if want > 0.0:
            relax = min(1.0, (1.0 - asum) / want)
    for k in range(nmat):
        frow = f_row + F_MAT + 3 * k
        row = W_MAT + W_STRIDE * k
        a_flux = alpha[b, k, ix, iy, iz]
        work_pressure = sc[row + 3, i]
        if asum > 1.0:
            a_new = a_flux / asum
        elif dv > 0.0 and full and sc[row + 3, i] > -sc[row + 5, i]:
            a_new = a_flux + sc[row, i] * dv
        elif relax > 0.0 and sc[row + 3, i] > 0.0 and sc[row + 4, i] > 0.0:
            a_new = a_flux * (1.0 + relax * sc[row + 3, i] / sc[row + 4, i])
            work_pressure = 0.5 * sc[row + 3, i]
        else:
            a_new = a_flux
        ar = arho[b, k, ix, iy, iz] - (wr * sc[frow + 1, fr] - wl * sc[frow + 1, fl])
        ae = arhoe[b, k, ix, iy, iz] - (wr * sc[frow + 2, fr] - wl * sc[frow + 2, fl])
        ae -= work_pressure * (a_new - a_flux)
        if a_new < 0.0:
            a_new = 0.0
            floors[b, FLOOR_ALPHA] += 1
        elif a_new > 1.0:
            a_new = 1.0
        alpha[b, k, ix, iy, iz] = a_new
        arho[b, k, ix, iy, iz] = ar
        arhoe[b, k, ix, iy, iz] = ae
        for j in range(nq):
            c = nq * k + j
            arhoq[b, c, ix, iy, iz] -= wr * sc[fq_row + c, fr] - wl * sc[fq_row + c, fl]
    mn = mom[b, axis, ix, iy, iz] - (wr * sc[f_row + F_MN, fr] - wl * sc[f_row + F_MN, fl])
    if radial:
        p_half = 0.5 * (sc[qm_row + Q_P, i] + sc[qp_row + Q_P, i])
        mn += p_half * (wr - wl)
    m1 = mom[b, t1, ix, iy, iz] - (wr * sc[f_row + F_MT1, fr] - wl * sc[f_row + F_MT1, fl])
    m2 = mom[b, t2, ix, iy, iz] - (wr * sc[f_row + F_MT2, fr] - wl * sc[f_row + F_MT2, fl])
    e_tot = energy[b, 0, ix, iy, iz] - (wr * sc[f_row + F_E, fr] - wl * sc[f_row + F_E, fl])
    rho = 0.0
    for k in range(nmat):
        rho += arho[b, k, ix, iy, iz]
    if not (rho == rho and e_tot == e_tot and mn == mn and m1 == m1 and m2 == m2):
        _record_failure(failure, b, FAIL_NAN, ix, iy, iz)
    elif rho < -FAIL_NEGATIVE_FRACTION * rho_old and sc[W_PHI, i] > PHI_SMALL:
        # in spray cells (filled below PHI_SMALL) an overdraw is a transport artifact, floored
        # and counted below; in any fuller cell a negative density is a failure
        _record_failure(failure, b, FAIL_NEGATIVE_DENSITY, ix, iy, iz)
    # floors on partial densities
    rho = 0.0
    for k in range(nmat):
        ar = arho[b, k, ix, iy, iz]
        if ar < 0.0:
            # the floored material keeps no internal energy of its own (a remnant energy on no
            # mass would give the next arrival an unbounded e_k); the cell's total energy is
            # unchanged and the reconciliation below hands it to the materials present
            amounts[b, AMOUNT_MASS_FLOOR] -= ar * vol
            floors[b, FLOOR_PARTIAL_DENSITY] += 1
            arho[b, k, ix, iy, iz] = 0.0
            arhoe[b, k, ix, iy, iz] = 0.0
            for j in range(nq):
                arhoq[b, nq * k + j, ix, iy, iz] = 0.0
            ar = 0.0
        rho += ar
    for k in range(nmat):
        ak = alpha[b, k, ix, iy, iz]
        ark = arho[b, k, ix, iy, iz]
        rho0 = reference_density(eos_kind[k], eos_params[k], eos_table)
        if ark > 0.0 and rho0 > 0.0 and ark < DISCARD_FRACTION * rho0 * ak:
            share = ark / rho
            floors[b, FLOOR_VOID_CLEANUP] += 1
            amounts[b, AMOUNT_MASS_VOID] += ark * vol
            amounts[b, AMOUNT_MOMENTUM_VOID] += share * np.sqrt(mn * mn + m1 * m1 + m2 * m2) * vol
            removed = arhoe[b, k, ix, iy, iz] + share * 0.5 * (mn * mn + m1 * m1 + m2 * m2) / rho
            amounts[b, AMOUNT_ENERGY_VOID] += removed * vol
            e_tot -= removed
            mn -= share * mn
            m1 -= share * m1
            m2 -= share * m2
            rho -= ark
            alpha[b, k, ix, iy, iz] = 0.0
            arho[b, k, ix, iy, iz] = 0.0
            arhoe[b, k, ix, iy, iz] = 0.0
            for j in range(nq):
                arhoq[b, nq * k + j, ix, iy, iz] = 0.0
    phi_new = 0.0
    for k in range(nmat):
        phi_new += alpha[b, k, ix, iy, iz]
    if rho <= 0.0 or (phi_new < PHI_VOID and rho < EMPTIED_FRACTION * rho_old):
        if rho > 0.0 or e_tot != 0.0 or mn != 0.0 or m1 != 0.0 or m2 != 0.0:
            floors[b, FLOOR_VOID_CLEANUP] += 1
            amounts[b, AMOUNT_ENERGY_VOID] += e_tot * vol
            amounts[b, AMOUNT_MASS_VOID] += rho * vol
            amounts[b, AMOUNT_MOMENTUM_VOID] += np.sqrt(mn * mn + m1 * m1 + m2 * m2) * vol
        for k in range(nmat):
            alpha[b, k, ix, iy, iz] = 0.0
            arho[b, k, ix, iy, iz] = 0.0
            arhoe[b, k, ix, iy, iz] = 0.0
        for c in range(nmat * nq):
            arhoq[b, c, ix, iy, iz] = 0.0
        mom[b, axis, ix, iy, iz] = 0.0
        mom[b, t1, ix, iy, iz] = 0.0
        mom[b, t2, ix, iy, iz] = 0.0
        energy[b, 0, ix, iy, iz] = 0.0
        return
    # how full the cell is, by volume and by mass: material expanded far below its reference
    # density (vapour) fills a cell by volume but is as light as a spray of it
    fill = phi_new
    solid = 0.0
    for k in range(nmat):
        rho0 = reference_density(eos_kind[k], eos_params[k], eos_table)
        solid += arho[b, k, ix, iy, iz] / rho0 if rho0 > 0.0 else alpha[b, k, ix, iy, iz]
    if solid < fill:
        fill = solid
    if fill < PHI_SMALL:
        vmax = max(abs(sc[f_row + F_S, fl]), abs(sc[f_row + F_S, fr]))
        for j in range(i - 1, i + 2):
            vj = np.sqrt(sc[W_UN, j] ** 2 + sc[W_UT1, j] ** 2 + sc[W_UT2, j] ** 2)
            if vj > vmax:
                vmax = vj
        m_abs = np.sqrt(mn * mn + m1 * m1 + m2 * m2)
        if m_abs > vmax * rho:
            # the excess momentum is a flux residue, so is any kinetic energy it implies: keep
            # the materials' internal energies and rebuild the total energy around them
            scale = vmax * rho / m_abs
            mn *= scale
            m1 *= scale
            m2 *= scale
            esum = 0.0
            for k in range(nmat):
                esum += max(arhoe[b, k, ix, iy, iz], 0.0)
            e_new = esum + 0.5 * m_abs * m_abs * scale * scale / rho
            floors[b, FLOOR_VELOCITY_LIMIT] += 1
            amounts[b, AMOUNT_MOMENTUM_LIMITER] += m_abs * (1.0 - scale) * vol
            amounts[b, AMOUNT_ENERGY_LIMITER] += (e_tot - e_new) * vol
            e_tot = e_new
        h_max = 0.0
        for j in range(i - 1, i + 2):
            rho_j = sc[W_RHO, j]
            if rho_j > 0.0:
                e_j = 0.0
                for k in range(nmat):
                    row = W_MAT + W_STRIDE * k
                    e_j += sc[row, j] * sc[row + 1, j] * sc[row + 2, j]
                h_j = ((e_j + max(sc[W_P, j], 0.0)) / rho_j
                       + 0.5 * (sc[W_UN, j] ** 2 + sc[W_UT1, j] ** 2 + sc[W_UT2, j] ** 2))
                if h_j > h_max:
                    h_max = h_j
        if e_tot > rho * h_max:
            floors[b, FLOOR_ENERGY_LIMIT] += 1
            amounts[b, AMOUNT_ENERGY_CAP] += (e_tot - rho * h_max) * vol
            e_tot = rho * h_max
    # reconcile material internal energies with the conserved total energy
    kinetic = 0.5 * (mn * mn + m1 * m1 + m2 * m2) / rho
    e_int = e_tot - kinetic
    esum = 0.0
    for k in range(nmat):
        esum += arhoe[b, k, ix, iy, iz]
    delta = (e_int - esum) / rho
    amounts[b, AMOUNT_ENERGY_RECONCILED] += abs(e_int - esum) * vol
    # a gain is shared by mass; a loss by internal energy, so cold material is not driven
    # below zero while the cell as a whole still has internal energy to give
    shrink = e_int / esum if (delta < 0.0 and esum > 0.0 and e_int >= 0.0) else -1.0
    added = 0.0
    for k in range(nmat):
        if shrink >= 0.0:
            ae = arhoe[b, k, ix, iy, iz] * shrink
        else:
            ae = arhoe[b, k, ix, iy, iz] + delta * arho[b, k, ix, iy, iz]
        if ae < 0.0:
            added -= ae
            ae = 0.0
            floors[b, FLOOR_INTERNAL_ENERGY] += 1
        arhoe[b, k, ix, iy, iz] = ae
    if added > 0.0:
        e_tot += added
        amounts[b, AMOUNT_ENERGY_FLOOR] += added * vol
    mom[b, axis, ix, iy, iz] = mn
    mom[b, t1, ix, iy, iz] = m1
    mom[b, t2, ix, iy, iz] = m2
    energy[b, 0, ix, iy, iz] = e_tot


@njit(cache=True, inline="always")
def _record_failure(failure, b, code, ix, iy, iz):
    if failure[b, 0] == 0:
        failure[b, 0] = code
        failure[b, 1] = ix
        failure[b, 2] = iy
        failure[b, 3] = iz
