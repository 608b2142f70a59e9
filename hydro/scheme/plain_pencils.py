"""The sweep's path for plain pencils: every cell full of one material, the others absent.

Most pencils of a scene are plain: a single-material box everywhere, the inside of each
body of an impact.  There the multi-material machinery of :mod:`impactpipe.hydro.scheme.directional` does
no work (every volume fraction face value is 1, the volume closure and the energy
reconciliation are identities, no cell is small, mixed or void), so these functions do the
same arithmetic for material m alone:

- :func:`plain_material`: m if every cell of the pencil (ghosts included) has
  alpha_m > 1 - FULL_TOLERANCE and alpha_m rho_m > 0, and every other material has
  alpha_k = alpha_k rho_k = alpha_k rho_k e_k = 0; EMPTY_PENCIL if no cell holds anything
  (the general path would compute zero fluxes and leave every cell as it is); else -1;
- :func:`reconstruct_plain`, :func:`face_flux_plain`: the MUSCL-Hancock face states and
  the HLLC fluxes of steps 2-3 of the sweep with one material, from the cell values of the
  sweep's plain gather (step 1: :func:`impactpipe.hydro.scheme.directional._gather_plain`,
  the general gather's rows with material m's EOS called directly), written to the same
  scratch rows (absent materials get zero fluxes);
- :func:`update_plain`: the flux-form update of step 4 with the equal-strain closure
  alpha_m += alpha_m dV of a full cell (none at the tensile limit, which opens void) and
  rho e = E - |m|^2 / (2 rho).  A cell whose new state needs a rule of the general update
  (density at or below PHI_SMALL rho0, where the small-cell limits and the discard density
  apply, a volume fraction below PHI_VOID, a NaN) is left untouched and handed back to
  :func:`impactpipe.hydro.scheme.directional._update_cell`.

The answers agree with the general path bit for bit (tests/test_hydro_plain_pencils.py): the
shared pieces are in :mod:`impactpipe.hydro.scheme.pencil_steps`, and the rest repeats the general
path's order of operations.  A step costs 1.3-1.8x less with the plain path
(docs/performance.md, benchmarks/sweep_paths.py).
"""

from __future__ import annotations

import math

from numba import njit

from impactpipe.hydro.scheme.pencil_layout import (
    AMOUNT_ENERGY_FLOOR,
    AMOUNT_ENERGY_RECONCILED,
    F_E,
    F_MAT,
    F_MN,
    F_MT1,
    F_MT2,
    F_S,
    FLOOR_FIRST_ORDER,
    FLOOR_INTERNAL_ENERGY,
    FULL_TOLERANCE,
    PHI_SMALL,
    Q_MAT,
    Q_P,
    TENSION_TOLERANCE,
    W_IVL,
    W_IVR,
    W_K,
    W_MAT,
    W_STRIDE,
    W_VOL,
    pencil_cell_index,
    pencil_offset,
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


#: :func:`plain_material` of a pencil with no material, momentum or energy in any cell.
EMPTY_PENCIL = -2


@njit(cache=True, inline="always")
def plain_material(alpha, arho, arhoe, mom, energy, b, axis, j1, j2, ncell, alpha_f, arho_f, arhoe_f, cs):
    """The material m that fills every cell of the pencil alone, EMPTY_PENCIL, or -1.

    See the module docstring.  An empty pencil (every cell void, with zero momentum and
    energy) has no fluxes and no update: the sweep leaves it as it is.  Its transported
    scalars are not read: a cell without mass has none, since every kernel that removes a
    material's last mass zeroes its scalars with it (the sweeps' floors and cleanups, the
    stress update's void cells and absent materials), and skipping the check spares the
    sweep a read of every scalar column of the void pencils, half of an impact's.
    ``alpha_f``, ``arho_f``, ``arhoe_f``: the first three fields flattened, ``cs`` the length
    of one column (:func:`impactpipe.hydro.scheme.pencil_layout.pencil_offset`).
    """
    nmat = alpha.shape[1]
    ix, iy, iz = pencil_cell_index(axis, 0, j1, j2)
    m = 0
    for k in range(1, nmat):
        if alpha[b, k, ix, iy, iz] > alpha[b, m, ix, iy, iz]:
            m = k
    if alpha[b, m, ix, iy, iz] == 0.0:
        for i in range(ncell):
            ix, iy, iz = pencil_cell_index(axis, i, j1, j2)
            if energy[b, 0, ix, iy, iz] != 0.0:
                return -1
            for c in range(mom.shape[1]):
                if mom[b, c, ix, iy, iz] != 0.0:
                    return -1
            for k in range(nmat):
                if alpha[b, k, ix, iy, iz] != 0.0 or arho[b, k, ix, iy, iz] != 0.0 or arhoe[b, k, ix, iy, iz] != 0.0:
                    return -1
        return EMPTY_PENCIL
    offset, stride = pencil_offset(alpha.shape[2], alpha.shape[3], alpha.shape[4], axis, j1, j2)
    im = (b * nmat + m) * cs + offset
    for i in range(ncell):
        if not (alpha_f[im + i * stride] > 1.0 - FULL_TOLERANCE and arho_f[im + i * stride] > 0.0):
            return -1
    for k in range(nmat):
        if k != m:
            ik = (b * nmat + k) * cs + offset
            for i in range(ncell):
                c = ik + i * stride
                if alpha_f[c] != 0.0 or arho_f[c] != 0.0 or arhoe_f[c] != 0.0:
                    return -1
    return m


@njit(cache=True, inline="always")
def reconstruct_plain(sc, m, i, half, qm_row, qp_row, floors, b, interior):
    """Step 2 for cell i of a plain pencil: MUSCL-Hancock face states of (u, p, alpha_m, rho_m, e_m).

    The same predictor and admissibility rules as the general path
    (:func:`impactpipe.hydro.scheme.directional._reconstruct_cell`): a face pressure from p > 0 below
    -TENSION_TOLERANCE K, or below the tensile limit -alpha_m Y_T,m (1 - D_m) and below p, or
    a non-positive face density gives the cell values (first order, counted).
    """
    row = W_MAT + W_STRIDE * m
    qrow = Q_MAT + 3 * m
    un, dun, p, p_face = predict_flow(sc, i, half, qm_row, qp_row)
    first_order = ((p > 0.0 and p_face < -TENSION_TOLERANCE * sc[i, W_K])
                   or (p_face < -sc[i, row] * sc[i, row + 5] and p_face < p))
    if predict_material(sc, i, row, qrow, half, un, dun, qm_row, qp_row):
        first_order = True
    if first_order:
        if interior:
            floors[b, FLOOR_FIRST_ORDER] += 1
        cell_value_faces(sc, i, qm_row, qp_row, (row, W_STRIDE, 1), (qrow, 3, 1))


@njit(cache=True, inline="always")
def face_flux_plain(sc, m, nmat, f, dt, dtdx, qm_row, qp_row, f_row, nq, wq_row, fq_row, edge, donor_row):
    """Step 3 for face f (between cells f-1 and f) of a plain pencil: HLLC fluxes into column f.

    No void on either side; material m's volume flux is alpha_face s with the ultrabee face
    value and its mass flux alpha_face rho_m,K chi s, capped as in the general path
    (:func:`impactpipe.hydro.scheme.directional._face_flux`); absent materials carry zero fluxes.
    The donor cell's index goes to row ``donor_row`` of column f.  The scalar fluxes are left to
    :func:`plain_scalar_fluxes`, which the sweep calls where the pencil moves mass and carries
    scalars; here, at a block face (``edge``), which the sweep stores for refluxing at a
    coarse/fine face, they are written as the pencil without scalars has them: material m's
    mass flux times +0.0, the other materials' +0.0.  Neither :func:`update_plain` nor, for a
    cell it hands back, the general update (:func:`impactpipe.hydro.scheme.directional._update_cell`)
    applies scalar fluxes without ``carried``.
    """
    row = W_MAT + W_STRIDE * m
    qrow = Q_MAT + 3 * m
    frow = f_row + F_MAT + 3 * m
    il = f - 1
    ir = f
    rho_l = sc[il, qp_row + qrow] * sc[il, qp_row + qrow + 1]
    rho_r = sc[ir, qm_row + qrow] * sc[ir, qm_row + qrow + 1]
    side, s, p_star, chi, de, donor, up, down, krow, iv_donor = upwind_face(sc, f, rho_l, False, rho_r, False,
                                                                             qm_row, qp_row)
    sc[f, donor_row] = donor
    mass, ek = material_face_flux(sc, f, row, qrow, frow, donor, up, down, krow, abs(s) * dtdx,
                                  abs(s) * dt * iv_donor, 1.0, s, chi, dt, iv_donor)
    for k in range(nmat):
        if k != m:
            for c in range(3):
                sc[f, f_row + F_MAT + 3 * k + c] = 0.0
            if edge:
                for j in range(nq):
                    sc[f, fq_row + nq * k + j] = 0.0
    scalar_face_fluxes(sc, f, fq_row, wq_row, nq, m, mass, donor, False, edge)
    flow_fluxes(sc, f, f_row, krow, donor, mass, mass * ek, s, p_star, de)


@njit(cache=True, inline="always")
def update_plain(sc, m, i, dt, radial, qm_row, qp_row, f_row, b, alpha_f, arho_f, arhoe_f, mom_f, energy_f, arhoq_f,
                 ia, imn, im1, im2, ie, iq, cs, floors, amounts, rho0, nq, fq_row, carried):
    """Step 4 for interior cell i of a plain pencil; False (cell untouched) if it needs the general update.

    U_new = U - dt (A_+ F_+ - A_- F_-) / V for alpha_m rho_m, momentum, E and the transported
    scalars; alpha_m after the volume flux, then closed as a full cell: alpha_m += alpha_m dV
    (dV = dt div s) unless p_m is at the tensile limit -Y_T,m (1 - D_m), capped at 1 after
    its p dV work; alpha_m rho_m e_m -> E - |m|^2 / (2 rho) (J/m^3) by the general path's
    reconciliation for one material, in its arithmetic (the difference from the transported
    internal energy counted as reconciled), a negative value floored at 0 with E raised to
    match (counted).  ``rho0`` is material m's reference density (kg/m^3; 0 for a gas).
    The fields come flattened (:func:`impactpipe.hydro.scheme.pencil_layout.pencil_offset`) with
    the cell's flat indices: ``ia`` in material m's column of alpha, arho and arhoe, ``imn``,
    ``im1``, ``im2`` of the normal and transverse momentum, ``ie`` of E, ``iq`` of material m's
    first transported scalar (scalar j at ``iq + j cs``, ``cs`` the length of a column).
    Without ``carried`` (:func:`scalars_carried`) the scalars are +0.0 and their fluxes +0.0,
    and +0.0 - (+-0.0) is +0.0: they are left as they are.
    """
    row = W_MAT + W_STRIDE * m
    frow = f_row + F_MAT + 3 * m
    wl = dt * sc[i, W_IVL]
    wr = dt * sc[i, W_IVR]
    fl = i
    fr = i + 1
    ar = arho_f[ia] - (wr * sc[fr, frow + 1] - wl * sc[fl, frow + 1])
    mn = mom_f[imn] - (wr * sc[fr, f_row + F_MN] - wl * sc[fl, f_row + F_MN])
    if radial:
        mn += 0.5 * (sc[i, qm_row + Q_P] + sc[i, qp_row + Q_P]) * (wr - wl)
    m1 = mom_f[im1] - (wr * sc[fr, f_row + F_MT1] - wl * sc[fl, f_row + F_MT1])
    m2 = mom_f[im2] - (wr * sc[fr, f_row + F_MT2] - wl * sc[fl, f_row + F_MT2])
    e_tot = energy_f[ie] - (wr * sc[fr, f_row + F_E] - wl * sc[fl, f_row + F_E])
    dv = wr * sc[fr, f_row + F_S] - wl * sc[fl, f_row + F_S]
    a_flux = alpha_f[ia] - (wr * sc[fr, frow] - wl * sc[fl, frow])
    if a_flux > 1.0:
        a_new = 1.0
    elif dv > 0.0 and sc[i, row + 3] > -sc[i, row + 5]:
        a_new = a_flux + sc[i, row] * dv
    else:
        a_new = a_flux
    if not (ar > PHI_SMALL * rho0 and a_new >= PHI_VOID and e_tot == e_tot and mn == mn and m1 == m1
            and m2 == m2):
        return False
    ae = (arhoe_f[ia] - (wr * sc[fr, frow + 2] - wl * sc[fl, frow + 2])
          - sc[i, row + 3] * (a_new - a_flux))
    e_int = e_tot - 0.5 * (mn * mn + m1 * m1 + m2 * m2) / ar
    vol = sc[i, W_VOL]
    amounts[b, AMOUNT_ENERGY_RECONCILED] += abs(e_int - ae) * vol
    delta = (e_int - ae) / ar
    if delta < 0.0 and ae > 0.0 and e_int >= 0.0:
        ae *= e_int / ae
    else:
        ae += delta * ar
    if ae < 0.0:
        floors[b, FLOOR_INTERNAL_ENERGY] += 1
        amounts[b, AMOUNT_ENERGY_FLOOR] -= ae * vol
        e_tot -= ae
        ae = 0.0
    alpha_f[ia] = min(a_new, 1.0)
    arho_f[ia] = ar
    arhoe_f[ia] = ae
    if carried:
        for j in range(nq):
            c = nq * m + j
            arhoq_f[iq + j * cs] -= wr * sc[fr, fq_row + c] - wl * sc[fl, fq_row + c]
    mom_f[imn] = mn
    mom_f[im1] = m1
    mom_f[im2] = m2
    energy_f[ie] = e_tot
    return True


@njit(cache=True, inline="always")
def moves_mass(sc, mass_row, first, stop):
    """Whether some face ``first .. stop - 1`` of a plain pencil carries a mass flux: a value other
    than +-0.0 in its ``mass_row`` (material m's mass flux row of the F rows).

    Where none does, every scalar flux of the pencil is that zero times the donor's specific
    value, +-0.0, and the update U - dt (A_+ F_+ - A_- F_-) / V leaves each scalar at its value
    (up to the sign of a zero): the sweep neither gathers, fluxes nor updates the scalars
    (:func:`plain_scalar_fluxes`).  Material at rest makes such a pencil: the inside of a body
    before the shock reaches it, whose flaws (Grady-Kipp) or distension (porosity) are not zero.
    """
    for f in range(first, stop):
        if sc[f, mass_row] != 0.0:
            return True
    return False


@njit(cache=True, inline="always")
def plain_scalar_fluxes(sc, m, nmat, nq, first, stop, arho_f, arhoq_f, ia, iq, stride, cs, wq_row, fq_row, mass_row,
                        donor_row):
    """Material m's scalar fluxes through faces ``first .. stop - 1`` of a plain pencil, once
    :func:`moves_mass` says they move mass.

    The specific scalars q_j = (alpha_m rho_m q_j) / (alpha_m rho_m) of the donor cells
    ``first - 1 .. stop - 1`` into the WQ rows (0 where alpha_m rho_m <= 0), then each face's
    mass flux times its donor's q_j into the FQ rows, with the mass flux and donor that
    :func:`face_flux_plain` stored (rows ``mass_row``, ``donor_row``): the values the gather
    (:func:`impactpipe.hydro.scheme.directional._gather_plain`) and the face fluxes give with
    ``carried``, bit for bit; the other materials' scalar fluxes are +0.0 (a cell the update
    hands back to the general path applies every material's).  ``ia``, ``iq``: the flat indices
    of cell 0 of the pencil in material m's columns (:func:`update_plain`), ``stride`` the
    pencil's, ``cs`` a column's length.
    """
    for i in range(first - 1, stop):
        ar = arho_f[ia + i * stride]
        inv_ar = 1.0 / ar if ar > 0.0 else 0.0
        for j in range(nq):
            sc[i, wq_row + nq * m + j] = arhoq_f[iq + i * stride + j * cs] * inv_ar
    for f in range(first, stop):
        for k in range(nmat):
            if k != m:
                for j in range(nq):
                    sc[f, fq_row + nq * k + j] = 0.0
        scalar_face_fluxes(sc, f, fq_row, wq_row, nq, m, sc[f, mass_row], int(sc[f, donor_row]), True, False)


@njit(cache=True, inline="always")
def scalars_carried(arhoq_f, iq, stride, cs, nq, first, stop):
    """Whether some of the ``nq`` transported scalars of a plain pencil's material is not +0.0
    (its bits not all zero, so -0.0 counts) in the pencil's cells ``first .. stop - 1``, the
    donor cells of its faces.  ``arhoq_f`` is ``arhoq`` flattened, ``iq`` the flat index of
    the material's first scalar in cell 0 of the pencil, ``stride`` the pencil's stride and
    ``cs`` the length of a column (:func:`impactpipe.hydro.scheme.pencil_layout.pencil_offset`).

    Where none is, the pencil's scalar fluxes are +-0.0 and leave the scalars at +0.0
    (:func:`face_flux_plain`, :func:`update_plain`): the sweep neither gathers, fluxes nor
    stores them.  Right after an impact's contact most of the target is at rest without
    stress, plastic strain or damage.
    """
    for j in range(nq):
        column = iq + j * cs
        for i in range(first, stop):
            v = arhoq_f[column + i * stride]
            if v != 0.0 or math.copysign(1.0, v) < 0.0:
                return True
    return False
