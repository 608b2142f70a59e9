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
   void counts as a zero-pressure component), signal speed c = sqrt(K_L / rho) with
   K_L = sum alpha_k rho_k c_k^2 (c_k the longitudinal signal speed), the sound speed of
   the equal-strain mixture, and the modulus K of the pressure predictor: K_L, or with
   ``bulk_predictor`` the bulk modulus sum alpha_k rho_k c_K,k^2 (c_K,k the EOS sound speed;
   :func:`_bulk_modulus`) where a material with a shear modulus is present (elsewhere the
   two are equal, and K_L is kept bit for bit).  A partly filled cell keeps the wave
   speed of its material (K_L / rho = c_k^2), and a trace of a material (a volume fraction of
   1e-10 holding a round-off share of the energy, hence an enormous c_k) does not set the
   time step.
2. MUSCL-Hancock: MC-limited slopes of (u_n, u_t1, u_t2, p) and per material
   (alpha_k, rho_k, e_k); half-step predictor with the primitive equations
   u_t = -u u_x - p_x / rho, p_t = -u p_x - K u_x, alpha_t = -u alpha_x,
   rho_k,t = -u rho_k,x - rho_k u_x, e_k,t = -u e_k,x - (p_k / rho_k) u_x.
   With ``bulk_predictor`` (:attr:`impactpipe.hydro.solver.Simulation.bulk_pressure_predictor`,
   set by the granular column collapse) K is the bulk modulus, not K_L = K + 4 G / 3: the
   sweeps carry the pressure only, and the deviatoric share 4 G / 3 of a uniaxial strain's
   stress is the strength update's (docs/strength.md).  With K_L the face pressures of a sweep
   along x fall by dt/2 (4 G / 3) u_x more than the pressure itself does, and a split pair of
   sweeps leaves the viscous stress sigma_xx - sigma_zz = dt (4 G / 3) u_x (a viscosity
   G dt / 3, first order in the time step) on every shearing flow of a material with
   strength: in the cohesionless column collapse (docs/validation.md) it held the run-out
   (L_f - L0) / L0 to 0.875 at Courant number 0.4 against 1.234 at 0.1.  The other scenes
   keep K_L: with K, the 1-D spall test (tests/test_fracture_hydro.py) failed its target at
   3.64 us, before the rarefactions meet (4.33 us); the K_L term damps the ringing of its
   elastic waves.
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
from impactpipe.hydro.eos.porosity import ALPHA0
from impactpipe.hydro.scheme.mixture import (ALPHA_MIN, DISTENDED_FRACTION, mixture_state, signal_speed_squared,
                                             tension_left)
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
    pencil_offset,
)
from impactpipe.hydro.mesh.last_good import RECORD_CLEAR, RECORD_VOID
from impactpipe.hydro.scheme.plain_pencils import (
    EMPTY_PENCIL,
    face_flux_plain,
    moves_mass,
    plain_material,
    plain_scalar_fluxes,
    scalars_carried,
    reconstruct_plain,
    update_plain,
)
from impactpipe.hydro.scheme.pencil_steps import (
    cell_value_faces,
    flow_fluxes,
    material_face_flux,
    predict_flow,
    predict_material,
    scalar_face_fluxes,
    upwind_face,
)
from impactpipe.hydro.scheme.timestep import PHI_VOID


# allocates nothing: compiled without reference counting (docs/performance.md, "Compile time")
@njit(cache=True, parallel=True, _nrt=False)
def sweep(axis, dt, geometry, alpha, arho, arhoe, arhoq, mom, energy, block_lo, block_dx, neighbor,
          neighbor_level, eos_kind, eos_params, eos_table, shear_modulus, tensile_strength, scratch, boundary,
          floors, amounts, failure, face_flux, plain_pencils, blocks, scalars_clear, clear_after, scalar_stamp,
          grady_kipp=None, porosity=None, bulk_predictor=False):
    """Advance the blocks listed in ``blocks`` by ``dt`` (s) along ``axis``; see the module docstring.

    Field arrays are ``(NB, C, NX, NY, NZ)`` with filled ghosts along ``axis``.  Counters
    ``boundary``, ``floors``, ``amounts`` accumulate per block; ``failure`` records the first
    failing cell of each block.  Through each block face along ``axis`` whose neighbour is at
    another refinement level (``neighbor_level`` != 0) the amounts dt A F are stored in
    ``face_flux[b, side, :, j1, j2]`` for refluxing (:mod:`impactpipe.hydro.amr.transfer`).
    ``blocks`` (int64) lists the blocks to advance, in parallel over the list: every block of
    the arrays for one global step, one refinement level's for a level's substep
    (:mod:`impactpipe.hydro.amr.subcycle`); the others are left as they are.
    With ``plain_pencils`` a pencil that one material fills alone takes the plain path
    (:mod:`impactpipe.hydro.scheme.plain_pencils`); without, every pencil takes the general path.
    ``scalars_clear`` (uint8, (NB,), or empty: no record): the blocks whose transported scalars
    are +0.0 in their interior and their filled ghost layers
    (:func:`impactpipe.hydro.mesh.last_good.scalar_clear_blocks`; a uniform mesh's blocks on
    one process, indexed like ``blocks``).  A clear block whose neighbours along ``axis`` (itself
    at a domain face) are clear got +0.0 scalar ghosts from them: none of its plain pencils
    carries scalars, which is then not scanned for
    (:func:`impactpipe.hydro.scheme.plain_pencils.scalars_carried`).  When every pencil of such
    a block is plain or empty and every cell takes the plain update, its scalars are still
    +0.0 after the sweep: ``clear_after[b]`` (written with a record) is RECORD_CLEAR for such a
    block, else 0, the record for the sweep along the next axis; RECORD_VOID for a block that
    was void (``scalars_clear[b]`` RECORD_VOID) and whose pencils were all empty, so that the
    sweep left its interior as it was (:data:`impactpipe.hydro.mesh.last_good.RECORD_VOID`).
    ``scalar_stamp`` (int64, (NB,) indexed like ``blocks``, or empty: none): raised by one for
    a block where the sweep may have changed a transported scalar: where some plain pencil
    moved scalars, or the general update changed the bits of one
    (:mod:`impactpipe.hydro.mesh.scalar_stamps`).
    ``grady_kipp``: (M,) booleans of the materials that bear (1 - D) of their tension
    (:func:`impactpipe.hydro.scheme.mixture.tension_factor`), or None.
    ``porosity``: the (M, NPOROSITY) porosity rows (:func:`impactpipe.hydro.eos.porosity.pack_porosity`;
    a row of alpha_0 = 1 is a material without pores), or None.  The solver passes arrays in every
    scene (all False, all alpha_0 = 1 where none applies), so that one compiled sweep serves them all;
    a distension of exactly 1 divides nothing, so the answers are those of None bit for bit.  ``bulk_predictor``: the pressure predictor of
    cells holding a material with a shear modulus uses the bulk modulus K, not K_L (module
    docstring, step 2).
    """
    _, nmat, nx, ny, nz = alpha.shape
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
    donor_row = f_row + F_MAT + 3 * nmat
    wq_row = donor_row + 1
    fq_row = wq_row + nmat * nq
    radial = geometry == CYLINDRICAL and axis == 0
    axial = geometry == CYLINDRICAL and axis == 1
    # the fields flattened (C order) for the plain path, and the length of one column
    alpha_f = alpha.reshape(alpha.size)
    arho_f = arho.reshape(arho.size)
    arhoe_f = arhoe.reshape(arhoe.size)
    arhoq_f = arhoq.reshape(arhoq.size)
    mom_f = mom.reshape(mom.size)
    energy_f = energy.reshape(energy.size)
    cs = nx * ny * nz
    ncomp = mom.shape[1]
    tracked = scalars_clear.shape[0] > 0
    stamped = scalar_stamp.shape[0] > 0
    for e in prange(blocks.shape[0]):
        b = blocks[e]
        sc = scratch[get_thread_id()]
        # no plain pencil of a clear block between clear neighbours carries scalars
        quiet = tracked and scalars_clear[b] != 0
        for side in range(2):
            src = neighbor[b, axis, side]
            quiet = quiet and (src < 0 or (neighbor_level[b, axis, side] == 0 and scalars_clear[src] != 0))
        stays_clear = quiet
        stays_void = tracked and scalars_clear[b] == RECORD_VOID
        # no plain pencil moved scalars and no general update changed the bits of one
        scalars_kept = True
        dx = block_dx[b, axis]
        dtdx = dt / dx
        half = 0.5 * dtdx
        d1 = block_dx[b, t1] if n1 > 1 else 1.0
        d2 = block_dx[b, t2] if n2 > 1 else 1.0
        # the pencils' geometry rows are the same for every pencil of the block, except along the
        # axis of r-z, where each pencil's ring has its own volume: written once per block
        area_lo = area_hi = 0.0
        if not axial:
            area_lo, area_hi = _pencil_geometry(sc, ncell, g, n, radial, False, block_lo[b, 0], dx, d1, d2, 0)
        for j1 in range(lo1, hi1):
            for j2 in range(lo2, hi2):
                face_area_lo, face_area_hi = area_lo, area_hi
                if axial:
                    face_area_lo, face_area_hi = _pencil_geometry(sc, ncell, g, n, False, True, block_lo[b, 0], dx, d1,
                                                                  d2, j1)
                # 1-3. cell values, face states and fluxes: the plain path for a pencil that one material
                # fills alone (hydro.scheme.plain_pencils), the general path otherwise
                m = -1
                if plain_pencils:
                    m = plain_material(alpha, arho, arhoe, mom, energy, b, axis, j1, j2, ncell, alpha_f, arho_f,
                                       arhoe_f, cs)
                rho0_m = reference_density(eos_kind[m], eos_params[m], eos_table) if m >= 0 else 0.0
                # where material m's columns and the momentum and energy of this pencil start in the
                # flattened fields, and the pencil's stride (the plain path's indexing)
                offset, stride = pencil_offset(nx, ny, nz, axis, j1, j2)
                ia = (b * nmat + max(m, 0)) * cs + offset
                imn = (b * ncomp + axis) * cs + offset
                im1 = (b * ncomp + t1) * cs + offset
                im2 = (b * ncomp + t2) * cs + offset
                ie = b * cs + offset
                iq = (b * nmat + max(m, 0)) * nq * cs + offset
                carried = False
                if m != EMPTY_PENCIL:
                    stays_void = False
                if m == EMPTY_PENCIL:
                    for f in (g, g + n):
                        for r in range(f_row, fq_row + nmat * nq):
                            sc[f, r] = 0.0
                elif m >= 0:
                    # a strengthless material's signal speed is its bulk sound speed: its gather skips
                    # the shear term (which the compiler would evaluate, division included, either way)
                    shear_m = shear_modulus[m]
                    if shear_m[0] != 0.0 or shear_m[1] != 0.0:
                        for i in range(ncell):
                            _gather_plain(sc, i, m, rho0_m, i >= g and i < g + n, alpha_f, arho_f, arhoe_f, mom_f,
                                          arhoq_f, ia + i * stride, imn + i * stride, im1 + i * stride,
                                          im2 + i * stride, iq + i * stride, cs, eos_kind[m], eos_params[m], eos_table,
                                          shear_m, True, tensile_strength, nq, floors, b, grady_kipp,
                                          porosity, bulk_predictor)
                    else:
                        for i in range(ncell):
                            _gather_plain(sc, i, m, rho0_m, i >= g and i < g + n, alpha_f, arho_f, arhoe_f, mom_f,
                                          arhoq_f, ia + i * stride, imn + i * stride, im1 + i * stride,
                                          im2 + i * stride, iq + i * stride, cs, eos_kind[m], eos_params[m], eos_table,
                                          shear_m, False, tensile_strength, nq, floors, b, grady_kipp,
                                          porosity, False)
                    for i in range(1, ncell - 1):
                        reconstruct_plain(sc, m, i, half, qm_row, qp_row, floors, b, i >= g and i < g + n)
                    for f in range(g, g + n + 1):
                        face_flux_plain(sc, m, nmat, f, dt, dtdx, qm_row, qp_row, f_row, nq, wq_row, fq_row,
                                        f == g or f == g + n, donor_row)
                    # material m's scalars move only where a face moves mass and some donor cell holds one
                    mass_row = f_row + F_MAT + 3 * m + 1
                    carried = (nq > 0 and not quiet and moves_mass(sc, mass_row, g, g + n + 1)
                               and scalars_carried(arhoq_f, iq, stride, cs, nq, g - 1, g + n + 1))
                    if carried:
                        scalars_kept = False
                        plain_scalar_fluxes(sc, m, nmat, nq, g, g + n + 1, arho_f, arhoq_f, ia, iq, stride, cs,
                                            wq_row, fq_row, mass_row, donor_row)
                else:
                    stays_clear = False
                    # every material's scalars move only where some donor cell holds one
                    if nq > 0 and not quiet:
                        for k in range(nmat):
                            if not carried:
                                carried = scalars_carried(arhoq_f, (b * nmat + k) * nq * cs + offset, stride, cs, nq,
                                                          g - 1, g + n + 1)
                    _general_pencil_fluxes(sc, ncell, g, n, b, axis, t1, t2, j1, j2, alpha, arho, arhoe, arhoq, mom,
                                           eos_kind, eos_params, eos_table, shear_modulus, tensile_strength, nq,
                                           wq_row, fq_row, floors, grady_kipp, porosity, bulk_predictor, carried,
                                           half, dt, dtdx, qm_row, qp_row, f_row)
                # boundary counters: fluxes through domain faces (positive = leaving)
                for side in range(2):
                    if neighbor[b, axis, side] < 0:
                        f = g if side == 0 else g + n
                        w = -dt * face_area_lo if side == 0 else dt * face_area_hi
                        mass = 0.0
                        for k in range(nmat):
                            mk = sc[f, f_row + F_MAT + 3 * k + 1]
                            mass += mk
                            boundary[b, BND_MATERIAL + k] += w * mk
                        boundary[b, BND_MASS] += w * mass
                        boundary[b, BND_MOMENTUM + axis] += w * sc[f, f_row + F_MN]
                        boundary[b, BND_MOMENTUM + t1] += w * sc[f, f_row + F_MT1]
                        boundary[b, BND_MOMENTUM + t2] += w * sc[f, f_row + F_MT2]
                        boundary[b, BND_ENERGY] += w * sc[f, f_row + F_E]
                    elif neighbor_level[b, axis, side] != 0:
                        f = g if side == 0 else g + n
                        area = dt * (face_area_lo if side == 0 else face_area_hi)
                        for k in range(nmat):
                            for c in range(3):
                                face_flux[b, side, c * nmat + k, j1, j2] = area * sc[f, f_row + F_MAT + 3 * k + c]
                        face_flux[b, side, 3 * nmat + axis, j1, j2] = area * sc[f, f_row + F_MN]
                        face_flux[b, side, 3 * nmat + t1, j1, j2] = area * sc[f, f_row + F_MT1]
                        face_flux[b, side, 3 * nmat + t2, j1, j2] = area * sc[f, f_row + F_MT2]
                        face_flux[b, side, 3 * nmat + 3, j1, j2] = area * sc[f, f_row + F_E]
                        for c in range(nmat * nq):
                            face_flux[b, side, 3 * nmat + 4 + c, j1, j2] = area * sc[f, fq_row + c]
                # 4-5. update interior cells
                if m == EMPTY_PENCIL:
                    continue
                if m < 0:
                    if _general_update(sc, g, g + n, nmat, dt, radial, qm_row, qp_row, f_row, b, axis, t1, t2, j1, j2,
                                       alpha, arho, arhoe, mom, energy, floors, amounts, failure, eos_kind, eos_params,
                                       eos_table, arhoq, nq, fq_row, carried):
                        scalars_kept = False
                    continue
                for i in range(g, g + n):
                    if update_plain(sc, m, i, dt, radial, qm_row, qp_row, f_row, b, alpha_f, arho_f, arhoe_f, mom_f,
                                    energy_f, arhoq_f, ia + i * stride, imn + i * stride, im1 + i * stride,
                                    im2 + i * stride, ie + i * stride, iq + i * stride, cs, floors, amounts, rho0_m, nq,
                                    fq_row, carried):
                        continue
                    stays_clear = False
                    if _general_update(sc, i, i + 1, nmat, dt, radial, qm_row, qp_row, f_row, b, axis, t1, t2, j1, j2,
                                       alpha, arho, arhoe, mom, energy, floors, amounts, failure, eos_kind, eos_params,
                                       eos_table, arhoq, nq, fq_row, carried):
                        scalars_kept = False
        if tracked:
            clear_after[b] = RECORD_VOID if stays_void else (RECORD_CLEAR if stays_clear else 0)
        if stamped and not scalars_kept:
            scalar_stamp[b] += 1


@njit(cache=True, _nrt=False)
def _general_pencil_fluxes(sc, ncell, g, n, b, axis, t1, t2, j1, j2, alpha, arho, arhoe, arhoq, mom, eos_kind,
                           eos_params, eos_table, shear_modulus, tensile_strength, nq, wq_row, fq_row, floors,
                           grady_kipp, porosity, bulk_predictor, carried, half, dt, dtdx, qm_row, qp_row, f_row):
    """Steps 1-3 of a pencil on the general path, into the scratch ``sc``: the cell values of its
    ``ncell`` cells (:func:`_gather_cell`), the face states of cells 1 .. ncell - 2
    (:func:`_reconstruct_cell`) and the fluxes through faces g .. g + n (:func:`_face_flux`).

    Compiled apart from :func:`sweep`, which calls it once per general pencil: numba types the
    sweep, these steps and :func:`_general_update`, each with its cell functions inlined, as three
    units instead of one, which compile in a third of the time (docs/performance.md, "Compile
    time").  All three are compiled without numba's reference counting (``_nrt=False``; none
    allocates): with it each call increfs and decrefs every array it passes, 14 atomic pairs
    here, which made the impacts' steps 4-9 % slower.
    """
    nmat = alpha.shape[1]
    for i in range(ncell):
        _gather_cell(sc, i, b, axis, t1, t2, j1, j2, i >= g and i < g + n, alpha, arho, arhoe, arhoq, mom, eos_kind,
                     eos_params, eos_table, shear_modulus, tensile_strength, nq, wq_row, floors, grady_kipp, porosity,
                     bulk_predictor, carried)
    for i in range(1, ncell - 1):
        _reconstruct_cell(sc, i, nmat, half, qm_row, qp_row, floors, b, i >= g and i < g + n)
    for f in range(g, g + n + 1):
        _face_flux(sc, f, nmat, dt, dtdx, qm_row, qp_row, f_row, nq, wq_row, fq_row, carried, f == g or f == g + n)


@njit(cache=True, _nrt=False)
def _general_update(sc, first, stop, nmat, dt, radial, qm_row, qp_row, f_row, b, axis, t1, t2, j1, j2, alpha, arho,
                    arhoe, mom, energy, floors, amounts, failure, eos_kind, eos_params, eos_table, arhoq, nq, fq_row,
                    carried):
    """Steps 4-5 on the general path (:func:`_update_cell`) for the cells ``first .. stop - 1`` of the
    pencil at transverse indices (j1, j2): every interior cell of a general pencil, or one cell
    that the plain update handed back.  Returns whether some transported scalar changed its bits.

    Compiled apart from :func:`sweep`, as :func:`_general_pencil_fluxes` is.
    """
    changed = False
    for i in range(first, stop):
        ix, iy, iz = pencil_cell_index(axis, i, j1, j2)
        if _update_cell(sc, i, nmat, dt, radial, qm_row, qp_row, f_row, b, ix, iy, iz, alpha, arho, arhoe, mom, energy,
                        axis, t1, t2, floors, amounts, failure, eos_kind, eos_params, eos_table, arhoq, nq, fq_row,
                        carried):
            changed = True
    return changed


@njit(cache=True, inline="always")
def _pencil_geometry(sc, ncell, g, n, radial, axial, r0, dx, d1, d2, j1):
    """The geometry rows of a pencil of ``ncell`` cells (``n`` interior, ``g`` ghosts per side):
    A/V on both sides of each cell (1/m) and its volume (m^3; in r-z the whole ring's), into ``sc[i, W_IVL]``, ``sc[i, W_IVR]``, ``sc[i, W_VOL]``; returns the areas (m^2) of the
    pencil's first and last interior faces.  ``dx`` the cell size along the pencil, ``d1``,
    ``d2`` across it (1 for an axis the mesh lacks), ``r0`` the block's lower radius (m):

    - planar: A/V = 1/dx, V = dx d1 d2, A = d1 d2;
    - r-z along r (``radial``): V = pi |r_+^2 - r_-^2| d1, A/V = 2 |r_-+| / |r_+^2 - r_-^2|,
      A = 2 pi |r| d1 at the block's faces;
    - r-z along z (``axial``): A = pi |r_+^2 - r_-^2| of the pencil's ring (radial index
      ``j1``), V = A dx, A/V = 1/dx.
    """
    face_area_lo = d1 * d2
    face_area_hi = d1 * d2
    for i in range(ncell):
        if radial:
            r_lo = r0 + (i - g) * dx
            r_hi = r_lo + dx
            vol = abs(r_hi * r_hi - r_lo * r_lo)
            sc[i, W_IVL] = 2.0 * abs(r_lo) / vol
            sc[i, W_IVR] = 2.0 * abs(r_hi) / vol
            sc[i, W_VOL] = np.pi * vol * d1
            if i == g:
                face_area_lo = 2.0 * np.pi * abs(r_lo) * d1
            if i == g + n - 1:
                face_area_hi = 2.0 * np.pi * abs(r_hi) * d1
        elif axial:
            r_lo = r0 + (j1 - g) * d1
            r_hi = r_lo + d1
            ring = np.pi * abs(r_hi * r_hi - r_lo * r_lo)
            sc[i, W_IVL] = 1.0 / dx
            sc[i, W_IVR] = 1.0 / dx
            sc[i, W_VOL] = ring * dx
            face_area_lo = ring
            face_area_hi = ring
        else:
            sc[i, W_IVL] = 1.0 / dx
            sc[i, W_IVR] = 1.0 / dx
            sc[i, W_VOL] = dx * d1 * d2
    return face_area_lo, face_area_hi


@njit(cache=True, inline="always")
def _bulk_modulus(sc, i, nmat):
    """Bulk modulus K = sum_k alpha_k K_k (Pa) of cell i's equal-strain mixture, K_k = rho_k c_K,k^2
    the materials' EOS moduli from their W rows (zero for an absent material): the modulus of
    the pressure p = sum_k alpha_k p_k, which the Hancock predictor evolves (module docstring,
    step 2).  Used where a material with a shear modulus is present; elsewhere K_L = K and the
    gathers keep their sum K_L bit for bit."""
    kmod = 0.0
    for k in range(nmat):
        r = W_MAT + W_STRIDE * k
        kmod += sc[i, r] * sc[i, r + 4]
    return kmod


@njit(cache=True, inline="always")
def _holds_sheared(sc, i, shear_modulus):
    """Whether cell i holds a material (rho_k > 0 in its W rows) whose shear table row
    ``shear_modulus[k]`` is not zero (:mod:`impactpipe.hydro.strength.parameters`)."""
    for k in range(shear_modulus.shape[0]):
        if sc[i, W_MAT + W_STRIDE * k + 1] > 0.0 and (shear_modulus[k, 0] != 0.0 or shear_modulus[k, 1] != 0.0):
            return True
    return False


@njit(cache=True, inline="always")
def _gather_plain(sc, i, m, rho0_m, interior, alpha_f, arho_f, arhoe_f, mom_f, arhoq_f, ia, imn, im1, im2, iq, cs,
                  kind, params, eos_table, shear, sheared, tensile_strength, nq, floors, b, grady_kipp,
                  porosity, bulk_predictor):
    """Step 1 for cell i of a plain pencil (material m alone, full, ``rho0_m`` its reference
    density, kg/m^3): the W rows of :func:`_gather_cell`, bit for bit, with material m's EOS
    (``kind``, ``params``) called in place (:func:`impactpipe.hydro.eos.pressure_sound_speed_in_line`)
    and the absent materials' rows written without an EOS call (alpha_k, zeros, Y_T,k: an
    absent material holds no damage).

    The fields come flattened (:func:`impactpipe.hydro.scheme.pencil_layout.pencil_offset`), with
    the cell's flat indices: ``ia`` in material m's column of alpha, arho and arhoe (material
    k's is ``ia + (k - m) cs``, ``cs`` the length of a column), ``imn``, ``im1``, ``im2`` of the
    normal and transverse momentum, ``iq`` of material m's first transported scalar (scalar j
    at ``iq + j cs``).  ``sheared``: whether material m's shear table ``shear`` is not zero
    (without shear modulus its signal speed is the bulk sound speed, bit for bit).  A Grady-Kipp
    material (``grady_kipp[m]``) bears (1 - D) of its EOS tension, as in
    :func:`impactpipe.hydro.scheme.mixture.material_state`; a porous material (``porosity[m]``
    alpha0 > 1, its distension the second-to-last transported scalar) has the porous pressure,
    sound speed and tension limit Y_T (1 - D) / alpha of that function too.  The specific
    transported scalars are not gathered here: only the faces read them, and only where the
    pencil moves mass and carries some (:func:`impactpipe.hydro.scheme.plain_pencils.plain_scalar_fluxes`,
    material m's alone); the damage and distension still set the pressure.
    An undamaged cell (damage amount +-0) keeps Y_T and its tension without the division of
    :func:`impactpipe.hydro.scheme.mixture.tension_left`, whose factor would be exactly 1.0.
    """
    a = alpha_f[ia]
    ar = arho_f[ia]
    rk = ar / a
    ek = arhoe_f[ia] / ar
    dist = 1.0
    if porosity is not None:
        if porosity[m, ALPHA0] > 1.0 and ar > 0.0:
            dist = arhoq_f[iq + (nq - 2) * cs] / ar
    pk, c2b, flag = pressure_sound_speed_in_line(kind, params, eos_table, dist * rk, ek)
    if dist != 1.0:
        pk /= dist
        rho0_m = rho0_m / dist
    ytk = tensile_strength[m]
    if nq > 0 and ar > 0.0:
        damage = arhoq_f[iq + (nq - 1) * cs]
        # undamaged (D = +-0 / ar): tension_left would multiply Y_T and the tension by exactly 1.0
        if damage != 0.0:
            ytk = tension_left(ytk, damage, ar)
            if grady_kipp is not None:
                if grady_kipp[m] and pk < 0.0:
                    pk *= tension_left(1.0, damage, ar)
    if dist != 1.0:
        ytk /= dist
    p_min = -ytk
    if rk < DISTENDED_FRACTION * rho0_m:
        p_min = 0.0
    if pk < p_min:
        pk = p_min
        if interior:
            floors[b, FLOOR_TENSILE_LIMIT] += 1
    if interior and flag != 0:
        floors[b, FLOOR_EOS_CLAMP] += 1
    c2k = signal_speed_squared(c2b, rk, shear, rho0_m) if sheared else c2b
    r = W_MAT + W_STRIDE * m
    sc[i, r] = a
    sc[i, r + 1] = rk
    sc[i, r + 2] = ek
    sc[i, r + 3] = pk
    sc[i, r + 4] = rk * c2b
    sc[i, r + 5] = ytk
    for k in range(tensile_strength.shape[0]):
        if k != m:
            r = W_MAT + W_STRIDE * k
            sc[i, r] = alpha_f[ia + (k - m) * cs]
            sc[i, r + 1] = 0.0
            sc[i, r + 2] = 0.0
            sc[i, r + 3] = 0.0
            sc[i, r + 4] = 0.0
            sc[i, r + 5] = tensile_strength[k]
    kmod = ar * c2k
    sc[i, W_PHI] = a
    sc[i, W_C] = np.sqrt(kmod / ar)
    sc[i, W_RHO] = ar
    sc[i, W_P] = a * pk
    sc[i, W_K] = _bulk_modulus(sc, i, tensile_strength.shape[0]) if sheared and bulk_predictor else kmod
    inv = 1.0 / ar
    sc[i, W_UN] = mom_f[imn] * inv
    sc[i, W_UT1] = mom_f[im1] * inv
    sc[i, W_UT2] = mom_f[im2] * inv


@njit(cache=True, inline="always")
def _gather_cell(sc, i, b, axis, t1, t2, j1, j2, interior, alpha, arho, arhoe, arhoq, mom, eos_kind, eos_params,
                 eos_table, shear_modulus, tensile_strength, nq, wq_row, floors, grady_kipp, porosity,
                 bulk_predictor, carried):
    """Step 1 for cell i of the pencil: the cell values of the W rows.

    The mixture and per-material states from :func:`impactpipe.hydro.scheme.mixture.mixture_state`
    (its EOS clamps and tensile limits counted for interior cells), the velocity m / rho and,
    where the pencil ``carried`` scalars (:func:`_face_flux`), the specific transported scalars
    q_k,j = (alpha_k rho_k q_k,j) / (alpha_k rho_k); a void cell (rho <= 0 or phi < PHI_VOID)
    has zero density, velocity, pressure and bulk modulus.
    """
    ix, iy, iz = pencil_cell_index(axis, i, j1, j2)
    rho, phi, p, kmod, eint, tmass, clamps, limits = mixture_state(
        alpha, arho, arhoe, arhoq, b, ix, iy, iz, eos_kind, eos_params, eos_table, shear_modulus, tensile_strength,
        False, sc, W_MAT, i, grady_kipp, porosity)
    if interior and clamps > 0:
        floors[b, FLOOR_EOS_CLAMP] += clamps
    if interior and limits > 0:
        floors[b, FLOOR_TENSILE_LIMIT] += limits
    if carried:
        for k in range(alpha.shape[1]):
            ar = arho[b, k, ix, iy, iz]
            inv_ar = 1.0 / ar if ar > 0.0 else 0.0
            for j in range(nq):
                sc[i, wq_row + nq * k + j] = arhoq[b, nq * k + j, ix, iy, iz] * inv_ar
    sc[i, W_PHI] = phi
    sc[i, W_C] = np.sqrt(kmod / rho) if rho > 0.0 else 0.0
    if rho > 0.0 and phi >= PHI_VOID:
        sc[i, W_RHO] = rho
        sc[i, W_P] = p
        sheared = bulk_predictor and _holds_sheared(sc, i, shear_modulus)
        sc[i, W_K] = _bulk_modulus(sc, i, alpha.shape[1]) if sheared else kmod
        inv = 1.0 / rho
        sc[i, W_UN] = mom[b, axis, ix, iy, iz] * inv
        sc[i, W_UT1] = mom[b, t1, ix, iy, iz] * inv
        sc[i, W_UT2] = mom[b, t2, ix, iy, iz] * inv
    else:
        sc[i, W_RHO] = 0.0
        sc[i, W_P] = 0.0
        sc[i, W_K] = 0.0
        sc[i, W_UN] = 0.0
        sc[i, W_UT1] = 0.0
        sc[i, W_UT2] = 0.0


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
    flow_second = sc[i, W_RHO] > 0.0
    material_second = flow_second
    for j in range(i - 1, i + 2):
        fill = 0.0
        rho_min = 1.0e300
        rho_max = 0.0
        for k in range(nmat):
            a = sc[j, W_MAT + W_STRIDE * k]
            fill += a
            if a > ALPHA_MIN:
                r = sc[j, W_MAT + W_STRIDE * k + 1]
                rho_min = min(rho_min, r)
                rho_max = max(rho_max, r)
        alike = rho_max <= DENSITY_RATIO_SECOND_ORDER * rho_min
        if not (fill >= PHI_SECOND_ORDER and alike):
            material_second = False
        if not (sc[j, W_RHO] > 0.0 and fill >= PHI_FLOW_SECOND_ORDER and alike):
            flow_second = False
    if flow_second:
        un, dun, p, p_face = predict_flow(sc, i, half, qm_row, qp_row)
        fallback = p > 0.0 and p_face < -TENSION_TOLERANCE * sc[i, W_K]
        p_min = 0.0
        for k in range(nmat):
            p_min -= sc[i, W_MAT + W_STRIDE * k] * sc[i, W_MAT + W_STRIDE * k + 5]
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
def _face_flux(sc, f, nmat, dt, dtdx, qm_row, qp_row, f_row, nq, wq_row, fq_row, carried, edge):
    """Fluxes through face f (between cells f-1 and f), stored in column f of the F rows.

    Without ``carried`` (every material's scalars +0.0 in the donor cells g - 1 .. g + n of
    the pencil, :func:`impactpipe.hydro.scheme.plain_pencils.scalars_carried`) the scalar
    fluxes are the mass fluxes times the +0.0 specific values, +-0.0 (the inverse partial
    density of a donor is finite wherever it is a normal number), which leave the scalars at
    +0.0 (:func:`_update_cell` does not apply them then): they are not gathered, and written
    at a block face (``edge``) only, which the sweep stores for refluxing."""
    il = f - 1
    ir = f
    rho_l = 0.0
    rho_r = 0.0
    for k in range(nmat):
        qrow = Q_MAT + 3 * k
        rho_l += sc[il, qp_row + qrow] * sc[il, qp_row + qrow + 1]
        rho_r += sc[ir, qm_row + qrow] * sc[ir, qm_row + qrow + 1]
    void_l = sc[il, W_PHI] < PHI_VOID or rho_l <= 0.0
    void_r = sc[ir, W_PHI] < PHI_VOID or rho_r <= 0.0
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
        a_donor = sc[donor, row]
        frow = f_row + F_MAT + 3 * k
        if side == UPWIND_NONE or donor_void or a_donor < ALPHA_MIN or s == 0.0:
            sc[f, frow] = 0.0
            sc[f, frow + 1] = 0.0
            sc[f, frow + 2] = 0.0
            if carried or edge:
                for j in range(nq):
                    sc[f, fq_row + nq * k + j] = 0.0
            continue
        # a donor cell holding void in a diverging flow (its velocity or its left neighbour's
        # negative, its own or its right neighbour's positive) may lose material through both
        # faces: each face takes at most half of its content, so together they never overdraw
        # it (the test uses cell values, the same in both blocks of a face)
        share = 1.0
        if (sc[donor, W_PHI] <= 1.0 - FULL_TOLERANCE
                and min(sc[donor - 1, W_UN], sc[donor, W_UN]) < 0.0 < max(sc[donor, W_UN], sc[donor + 1, W_UN])):
            share = 0.5
        mk, ek = material_face_flux(sc, f, row, qrow, frow, donor, up, down, krow, nu, flow, share, s, chi, dt,
                                    iv_donor)
        scalar_face_fluxes(sc, f, fq_row, wq_row, nq, k, mk, donor, carried, edge)
        mass += mk
        eint += mk * ek
    flow_fluxes(sc, f, f_row, krow, donor, mass, eint, s, p_star, de)


@njit(cache=True, inline="always")
def _update_cell(sc, i, nmat, dt, radial, qm_row, qp_row, f_row, b, ix, iy, iz,
                 alpha, arho, arhoe, mom, energy, axis, t1, t2, floors, amounts, failure,
                 eos_kind, eos_params, eos_table, arhoq, nq, fq_row, carried):
    """Flux-form update of cell i with volume closure, energy reconciliation and floors.

    Without ``carried`` (:func:`_face_flux`, or for a cell of a plain pencil
    :func:`impactpipe.hydro.scheme.plain_pencils.face_flux_plain`) every scalar flux of the
    cell's faces is +-0.0, and the scalars are left as the fluxes would leave them (+0.0 -
    (+-0.0) is +0.0, and x - (+0.0) is x); the floors still clear them with the material.

    A material at its tensile limit (pressure <= -Y_T (1 - D), the damaged tensile strength
    the gather put in scratch row 5 of the material; a failed material, D = 1, holds none) does
    not share the expansion of a full cell: the cell opens void instead (tensile failure
    by void insertion, as CTH does), so no material is stretched beyond its strength.

    Returns whether some transported scalar of the cell changed its bits (for the blocks'
    scalar stamps, :mod:`impactpipe.hydro.mesh.scalar_stamps`).
    """
    changed = False
    wl = dt * sc[i, W_IVL]
    wr = dt * sc[i, W_IVR]
    vol = sc[i, W_VOL]
    fl = i
    fr = i + 1
    dv = wr * sc[fr, f_row + F_S] - wl * sc[fl, f_row + F_S]
    rho_old = sc[i, W_RHO]
    # volume fractions after the fluxes
    asum = 0.0
    for k in range(nmat):
        frow = f_row + F_MAT + 3 * k
        a_new = alpha[b, k, ix, iy, iz] - (wr * sc[fr, frow] - wl * sc[fl, frow])
        alpha[b, k, ix, iy, iz] = a_new
        asum += a_new
    # volume closure and p dV work
    full = sc[i, W_PHI] > 1.0 - FULL_TOLERANCE
    relax = 0.0
    if asum <= 1.0 and not full:
        want = 0.0
        for k in range(nmat):
            row = W_MAT + W_STRIDE * k
            if sc[i, row + 3] > 0.0 and sc[i, row + 4] > 0.0:
                want += alpha[b, k, ix, iy, iz] * sc[i, row + 3] / sc[i, row + 4]
        if want > 0.0:
            relax = min(1.0, (1.0 - asum) / want)
    for k in range(nmat):
        frow = f_row + F_MAT + 3 * k
        row = W_MAT + W_STRIDE * k
        a_flux = alpha[b, k, ix, iy, iz]
        work_pressure = sc[i, row + 3]
        if asum > 1.0:
            a_new = a_flux / asum
        elif dv > 0.0 and full and sc[i, row + 3] > -sc[i, row + 5]:
            a_new = a_flux + sc[i, row] * dv
        elif relax > 0.0 and sc[i, row + 3] > 0.0 and sc[i, row + 4] > 0.0:
            a_new = a_flux * (1.0 + relax * sc[i, row + 3] / sc[i, row + 4])
            work_pressure = 0.5 * sc[i, row + 3]
        else:
            a_new = a_flux
        ar = arho[b, k, ix, iy, iz] - (wr * sc[fr, frow + 1] - wl * sc[fl, frow + 1])
        ae = arhoe[b, k, ix, iy, iz] - (wr * sc[fr, frow + 2] - wl * sc[fl, frow + 2])
        ae -= work_pressure * (a_new - a_flux)
        if a_new < 0.0:
            a_new = 0.0
            floors[b, FLOOR_ALPHA] += 1
        elif a_new > 1.0:
            a_new = 1.0
        alpha[b, k, ix, iy, iz] = a_new
        arho[b, k, ix, iy, iz] = ar
        arhoe[b, k, ix, iy, iz] = ae
        if carried:
            for j in range(nq):
                c = nq * k + j
                old = arhoq[b, c, ix, iy, iz]
                new = old - (wr * sc[fr, fq_row + c] - wl * sc[fl, fq_row + c])
                arhoq[b, c, ix, iy, iz] = new
                changed = changed or _bits(new) != _bits(old)
    mn = mom[b, axis, ix, iy, iz] - (wr * sc[fr, f_row + F_MN] - wl * sc[fl, f_row + F_MN])
    if radial:
        p_half = 0.5 * (sc[i, qm_row + Q_P] + sc[i, qp_row + Q_P])
        mn += p_half * (wr - wl)
    m1 = mom[b, t1, ix, iy, iz] - (wr * sc[fr, f_row + F_MT1] - wl * sc[fl, f_row + F_MT1])
    m2 = mom[b, t2, ix, iy, iz] - (wr * sc[fr, f_row + F_MT2] - wl * sc[fl, f_row + F_MT2])
    e_tot = energy[b, 0, ix, iy, iz] - (wr * sc[fr, f_row + F_E] - wl * sc[fl, f_row + F_E])
    rho = 0.0
    for k in range(nmat):
        rho += arho[b, k, ix, iy, iz]
    if not (rho == rho and e_tot == e_tot and mn == mn and m1 == m1 and m2 == m2):
        _record_failure(failure, b, FAIL_NAN, ix, iy, iz)
    elif rho < -FAIL_NEGATIVE_FRACTION * rho_old and sc[i, W_PHI] > PHI_SMALL:
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
                changed = _zero_scalar(arhoq, b, nq * k + j, ix, iy, iz) or changed
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
            removed = arhoe[b, k, ix, iy, iz] + share * 0.5 * (mn * mn + m1 * m1 + m2 * m2) / rho
            amounts[b, AMOUNT_ENERGY_VOID] += removed * vol
            e_tot -= removed
            dn = share * mn
            d1 = share * m1
            d2 = share * m2
            amounts[b, AMOUNT_MOMENTUM_VOID + axis] += dn * vol
            amounts[b, AMOUNT_MOMENTUM_VOID + t1] += d1 * vol
            amounts[b, AMOUNT_MOMENTUM_VOID + t2] += d2 * vol
            mn -= dn
            m1 -= d1
            m2 -= d2
            rho -= ark
            alpha[b, k, ix, iy, iz] = 0.0
            arho[b, k, ix, iy, iz] = 0.0
            arhoe[b, k, ix, iy, iz] = 0.0
            for j in range(nq):
                changed = _zero_scalar(arhoq, b, nq * k + j, ix, iy, iz) or changed
    phi_new = 0.0
    for k in range(nmat):
        phi_new += alpha[b, k, ix, iy, iz]
    if rho <= 0.0 or (phi_new < PHI_VOID and rho < EMPTIED_FRACTION * rho_old):
        if rho > 0.0 or e_tot != 0.0 or mn != 0.0 or m1 != 0.0 or m2 != 0.0:
            floors[b, FLOOR_VOID_CLEANUP] += 1
            amounts[b, AMOUNT_ENERGY_VOID] += e_tot * vol
            amounts[b, AMOUNT_MASS_VOID] += rho * vol
            amounts[b, AMOUNT_MOMENTUM_VOID + axis] += mn * vol
            amounts[b, AMOUNT_MOMENTUM_VOID + t1] += m1 * vol
            amounts[b, AMOUNT_MOMENTUM_VOID + t2] += m2 * vol
        for k in range(nmat):
            alpha[b, k, ix, iy, iz] = 0.0
            arho[b, k, ix, iy, iz] = 0.0
            arhoe[b, k, ix, iy, iz] = 0.0
        for c in range(nmat * nq):
            changed = _zero_scalar(arhoq, b, c, ix, iy, iz) or changed
        mom[b, axis, ix, iy, iz] = 0.0
        mom[b, t1, ix, iy, iz] = 0.0
        mom[b, t2, ix, iy, iz] = 0.0
        energy[b, 0, ix, iy, iz] = 0.0
        return changed
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
        vmax = max(abs(sc[fl, f_row + F_S]), abs(sc[fr, f_row + F_S]))
        for j in range(i - 1, i + 2):
            vj = np.sqrt(sc[j, W_UN] ** 2 + sc[j, W_UT1] ** 2 + sc[j, W_UT2] ** 2)
            if vj > vmax:
                vmax = vj
        m_abs = np.sqrt(mn * mn + m1 * m1 + m2 * m2)
        if m_abs > vmax * rho:
            # the excess momentum is a flux residue, so is any kinetic energy it implies: keep
            # the materials' internal energies and rebuild the total energy around them
            scale = vmax * rho / m_abs
            rest = (1.0 - scale) * vol
            amounts[b, AMOUNT_MOMENTUM_LIMITER + axis] += mn * rest
            amounts[b, AMOUNT_MOMENTUM_LIMITER + t1] += m1 * rest
            amounts[b, AMOUNT_MOMENTUM_LIMITER + t2] += m2 * rest
            mn *= scale
            m1 *= scale
            m2 *= scale
            esum = 0.0
            for k in range(nmat):
                esum += max(arhoe[b, k, ix, iy, iz], 0.0)
            e_new = esum + 0.5 * m_abs * m_abs * scale * scale / rho
            floors[b, FLOOR_VELOCITY_LIMIT] += 1
            amounts[b, AMOUNT_ENERGY_LIMITER] += (e_tot - e_new) * vol
            e_tot = e_new
        h_max = 0.0
        for j in range(i - 1, i + 2):
            rho_j = sc[j, W_RHO]
            if rho_j > 0.0:
                e_j = 0.0
                for k in range(nmat):
                    row = W_MAT + W_STRIDE * k
                    e_j += sc[j, row] * sc[j, row + 1] * sc[j, row + 2]
                h_j = ((e_j + max(sc[j, W_P], 0.0)) / rho_j
                       + 0.5 * (sc[j, W_UN] ** 2 + sc[j, W_UT1] ** 2 + sc[j, W_UT2] ** 2))
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
    return changed


@njit(cache=True, inline="always")
def _bits(x):
    """The bits of the float64 ``x`` as an int64 (a -0.0 differs from a +0.0)."""
    return np.float64(x).view(np.int64)


@njit(cache=True, inline="always")
def _zero_scalar(arhoq, b, c, ix, iy, iz):
    """Set scalar c of a cell to +0.0; whether that changed its bits."""
    changed = _bits(arhoq[b, c, ix, iy, iz]) != 0
    arhoq[b, c, ix, iy, iz] = 0.0
    return changed


@njit(cache=True, inline="always")
def _record_failure(failure, b, code, ix, iy, iz):
    if failure[b, 0] == 0:
        failure[b, 0] = code
        failure[b, 1] = ix
        failure[b, 2] = iy
        failure[b, 3] = iz
