"""Moving data between refinement levels: restriction, prolongation and refluxing (numba kernels).

Restriction (fine -> coarse) is the volume-weighted mean of the 2^ndim fine cells that make
up a coarse cell,

    U_c = sum_f V_f U_f / V_c,

for every conserved field (partial densities, momentum, total energy, material internal
energies, volume fractions, transported scalars), so it conserves every amount exactly.  In
2d-cylindrical the two radial children of a cell weigh by their annulus volumes.

Prolongation (coarse -> fine) places a child at offset o (in coarse cells, per axis, between
the child's and the parent's volume centroids: +-1/4 in planar axes, the annulus centroids
2 (r_+^3 - r_-^3) / (3 (r_+^2 - r_-^2)) along r) on a limited linear profile, with minmod
slopes s_d(q) = minmod(q_c - q_c-1, q_c+1 - q_c) along each used axis d:

- where one material fills the parent and its neighbours (alpha >= PHI_SECOND_ORDER, as for
  the sweeps' second-order reconstruction), the partial densities, momentum, total energy
  and the filling material's internal energy are linear, U_f = U_c + sum_d s_d(U) o_d
  (second order in smooth flow), unless that leaves a child with negative internal energy
  (E < |m|^2 / 2 rho); a trace of another material keeps the parent's density and specific
  internal energy (its volume fraction and internal energy scale with its linear partial
  density), and the filling material's volume fraction takes the difference;
- elsewhere (interfaces, free surfaces, and the exception above) only the volume fractions
  are linear, alpha_k,f = alpha_k,c + lambda sum_d s_d(alpha_k) o_d, and each material keeps
  its density rho_k, specific internal energy e_k and transported scalars, the cell its
  velocity u:  alpha_k rho_k,f = alpha_k,f rho_k,  E_f = sum_k alpha_k,f rho_k e_k
  + rho_f |u|^2 / 2 + (E_c - sum_k alpha_k rho_k e_k - rho_c |u|^2 / 2) rho_f / rho_c.
  Pressure and velocity stay exactly those of the parent (a moving interface at uniform p
  and u stays so across a coarse/fine face), and the interface stays as sharp as the coarse
  profile allows (copying the parent into both fine ghost layers would blind the sweeps'
  compressive volume-fraction limiter and smear every interface that crosses a level
  boundary).  lambda in [0, 1] is the largest factor that keeps sum_k alpha_k,f <= 1.

Both conserve every amount (the children's volume-weighted offsets sum to zero; the choice
is made per parent cell for all its children) and are monotone: a child's volume fractions
and amounts lie between its parent's neighbours'.

Refluxing: a sweep advances a coarse cell beside finer blocks with its own flux through the
coarse/fine face; the fine blocks' fluxes through the same face (area-weighted sum over the
2^(ndim-1) fine faces) are the better ones, so the coarse cell gets

    Delta U_c = +-(sum_f dt A_f F_f - dt A_c F_c) / V_c      (+ on its low face, - on its high face)

which makes what left the fine blocks exactly what entered the coarse one.  The amounts
dt A F per face come from :func:`impactpipe.hydro.scheme.directional.sweep` (``face_flux``).
With one global step the correction follows each sweep (:func:`reflux`); with a step per level
(:mod:`impactpipe.hydro.amr.subcycle`) the fine level takes two substeps of dt_c / 2 per coarse
step, and a flux register per sweep axis sums, per coarse face cell, the fine amounts of both
substeps less the coarse one (:func:`register_fluxes`) until the fine level has caught up
(:func:`reflux_register`): Delta U_c = +-(sum_substeps sum_f dt_f A_f F_f - dt_c A_c F_c) / V_c.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from impactpipe.hydro.mesh.blocks import CYLINDRICAL, GHOST
from impactpipe.hydro.scheme.reconstruct import minmod_slope
from impactpipe.hydro.scheme.pencil_layout import (
    AMOUNT_MASS_FLOOR,
    AMOUNT_MASS_VOID,
    EMPTIED_FRACTION,
    FLOOR_PARTIAL_DENSITY,
    FLOOR_REGISTER_REDISTRIBUTION,
    FLOOR_VOID_CLEANUP,
    FULL_TOLERANCE,
    PHI_SECOND_ORDER,
)

# Plan columns: destination block and padded cell, source block and padded cell.
P_DST, P_DX, P_DY, P_DZ, P_SRC, P_SX, P_SY, P_SZ = range(8)
# Reflux plan columns: coarse block, its side, the coarse cell, the fine block, first fine face cell.
R_COARSE, R_SIDE, R_CX, R_CY, R_CZ, R_FINE, R_F1, R_F2 = range(8)


@njit(cache=True)
def _centroid(lo, dx, i, radial):
    """Volume centroid (m) of padded cell ``i`` of a block starting at ``lo`` with cell size ``dx``."""
    a = lo + (i - GHOST) * dx
    b = a + dx
    if radial:
        a = abs(a)
        b = abs(b)
        if b * b - a * a > 0.0:
            return 2.0 * (b * b * b - a * a * a) / (3.0 * (b * b - a * a))
    return a + 0.5 * dx


@njit(cache=True)
def _offset(src_lo, src_dx, si, dst_lo, dst_dx, di, radial):
    """Offset of a destination cell's centroid from a source cell's, in source cells.

    A child lies inside its parent (|offset| < 1/2); across a periodic boundary the two
    centroids differ by the domain length, a whole number of source cells, which is removed.
    """
    if src_dx == 0.0:
        return 0.0
    offset = (_centroid(dst_lo, dst_dx, di, radial) - _centroid(src_lo, src_dx, si, radial)) / src_dx
    return offset - np.floor(offset + 0.5)


@njit(cache=True)
def _child_cell(px, py, pz, a, j, k, gy, gz, ny, nz):
    """Padded index of child cell (a, j, k) of the parent cell at interior offset (px, py, pz)."""
    return GHOST + 2 * px + a, (gy + 2 * py + j if ny > 1 else 0), (gz + 2 * pz + k if nz > 1 else 0)


@njit(cache=True)
def _child_offsets(old_lo, old_dx, new_lo, new_dx, pb, cb, sx, sy, sz, dxi, dyi, dzi, radial):
    """Offsets (in parent cells, per axis) of child cell (dxi, dyi, dzi) of block cb from the
    centroid of parent cell (sx, sy, sz) of old block pb (the radial axis by volume centroid)."""
    return (_offset(old_lo[pb, 0], old_dx[pb, 0], sx, new_lo[cb, 0], new_dx[cb, 0], dxi, radial),
            _offset(old_lo[pb, 1], old_dx[pb, 1], sy, new_lo[cb, 1], new_dx[cb, 1], dyi, False),
            _offset(old_lo[pb, 2], old_dx[pb, 2], sz, new_lo[cb, 2], new_dx[cb, 2], dzi, False))


@njit(cache=True)
def _linear(f, b, c, ix, iy, iz, o0, o1, o2, ndim):
    """f[b, c] at offsets (o0, o1, o2) cells from cell (ix, iy, iz) with minmod slopes."""
    q = f[b, c, ix, iy, iz]
    v = q + o0 * minmod_slope(f[b, c, ix - 1, iy, iz], q, f[b, c, ix + 1, iy, iz])
    if ndim > 1:
        v += o1 * minmod_slope(f[b, c, ix, iy - 1, iz], q, f[b, c, ix, iy + 1, iz])
    if ndim > 2:
        v += o2 * minmod_slope(f[b, c, ix, iy, iz - 1], q, f[b, c, ix, iy, iz + 1])
    return v


@njit(cache=True)
def _single_material(alpha, b, ix, iy, iz, ndim):
    """True when one material fills cell (ix, iy, iz) of block b and its face neighbours."""
    return _filling_material(alpha, b, ix, iy, iz, ndim) >= 0


@njit(cache=True)
def _filling_material(alpha, b, ix, iy, iz, ndim):
    """The material that fills cell (ix, iy, iz) of block b and its face neighbours, or -1."""
    for k in range(alpha.shape[1]):
        full = alpha[b, k, ix, iy, iz] >= PHI_SECOND_ORDER
        full = full and alpha[b, k, ix - 1, iy, iz] >= PHI_SECOND_ORDER and alpha[b, k, ix + 1, iy, iz] >= PHI_SECOND_ORDER
        if ndim > 1:
            full = full and alpha[b, k, ix, iy - 1, iz] >= PHI_SECOND_ORDER
            full = full and alpha[b, k, ix, iy + 1, iz] >= PHI_SECOND_ORDER
        if ndim > 2:
            full = full and alpha[b, k, ix, iy, iz - 1] >= PHI_SECOND_ORDER
            full = full and alpha[b, k, ix, iy, iz + 1] >= PHI_SECOND_ORDER
        if full:
            return k
    return -1


@njit(cache=True)
def _child_internal_energy(arho, mom, energy, b, ix, iy, iz, o0, o1, o2, ndim):
    """Internal energy density E - |m|^2 / (2 rho) (J/m^3) of the linear profile at an offset."""
    rho = 0.0
    for k in range(arho.shape[1]):
        rho += _linear(arho, b, k, ix, iy, iz, o0, o1, o2, ndim)
    if rho <= 0.0:
        return -1.0
    m2 = 0.0
    for c in range(3):
        m = _linear(mom, b, c, ix, iy, iz, o0, o1, o2, ndim)
        m2 += m * m
    return _linear(energy, b, 0, ix, iy, iz, o0, o1, o2, ndim) - 0.5 * m2 / rho


@njit(cache=True)
def _fraction_growth(alpha, b, ix, iy, iz, o0, o1, o2, ndim):
    """sum_k (alpha_k,f - alpha_k,c) of the linear volume-fraction profile at an offset."""
    grow = 0.0
    for k in range(alpha.shape[1]):
        grow += _linear(alpha, b, k, ix, iy, iz, o0, o1, o2, ndim) - alpha[b, k, ix, iy, iz]
    return grow


@njit(cache=True)
def _fraction_limit(alpha, b, ix, iy, iz, grow):
    """The factor lambda <= 1 that keeps a child's volume fractions summing to at most 1."""
    if grow <= 0.0:
        return 1.0
    room = 1.0
    for k in range(alpha.shape[1]):
        room -= alpha[b, k, ix, iy, iz]
    return min(1.0, max(room, 0.0) / grow)


@njit(cache=True)
def _put_child(src, dst, b, ix, iy, iz, db, dx_, dy, dz, o0, o1, o2, ndim, linear):
    """dst[db, :, cell] = src[b, :, cell] prolonged (linear or copied) to the offsets."""
    for c in range(src.shape[1]):
        if linear:
            dst[db, c, dx_, dy, dz] = _linear(src, b, c, ix, iy, iz, o0, o1, o2, ndim)
        else:
            dst[db, c, dx_, dy, dz] = src[b, c, ix, iy, iz]


@njit(cache=True)
def _put_fraction_child(src, dst, b, ix, iy, iz, db, dx_, dy, dz, o0, o1, o2, ndim, lam):
    """A child with linear volume fractions and the parent's material states (module docstring)."""
    alpha, arho, arhoe, mom, energy, arhoq = src
    n_alpha, n_arho, n_arhoe, n_mom, n_energy, n_arhoq = dst
    nmat = alpha.shape[1]
    nq = arhoq.shape[1] // nmat
    rho_c = 0.0
    rho_f = 0.0
    eint_f = 0.0
    eint_c = 0.0
    for k in range(nmat):
        a = alpha[b, k, ix, iy, iz]
        a_f = a + lam * (_linear(alpha, b, k, ix, iy, iz, o0, o1, o2, ndim) - a)
        ratio = a_f / a if a > 0.0 else 1.0
        n_alpha[db, k, dx_, dy, dz] = a_f
        n_arho[db, k, dx_, dy, dz] = ratio * arho[b, k, ix, iy, iz]
        n_arhoe[db, k, dx_, dy, dz] = ratio * arhoe[b, k, ix, iy, iz]
        for j in range(nq):
            n_arhoq[db, nq * k + j, dx_, dy, dz] = ratio * arhoq[b, nq * k + j, ix, iy, iz]
        rho_c += arho[b, k, ix, iy, iz]
        rho_f += ratio * arho[b, k, ix, iy, iz]
        eint_c += arhoe[b, k, ix, iy, iz]
        eint_f += ratio * arhoe[b, k, ix, iy, iz]
    if rho_c <= 0.0:
        for c in range(3):
            n_mom[db, c, dx_, dy, dz] = mom[b, c, ix, iy, iz]
        n_energy[db, 0, dx_, dy, dz] = energy[b, 0, ix, iy, iz]
        return
    share = rho_f / rho_c
    m2 = 0.0
    for c in range(3):
        m = mom[b, c, ix, iy, iz]
        n_mom[db, c, dx_, dy, dz] = share * m
        m2 += m * m
    kinetic = 0.5 * m2 / rho_c
    residual = energy[b, 0, ix, iy, iz] - eint_c - kinetic
    n_energy[db, 0, dx_, dy, dz] = eint_f + share * (kinetic + residual)


@njit(cache=True)
def _put_trace_children(alpha, arho, arhoe, n_alpha, n_arho, n_arhoe, b, ix, iy, iz, db, dx_, dy, dz,
                        o0, o1, o2, ndim):
    """Volume fractions and internal energies of a conserved-linear child (partial densities set).

    The filling material f's internal energy is linear; every other material k (a trace)
    keeps its parent's density and specific internal energy, alpha_k,child =
    alpha_k (alpha_k rho_k)_child / (alpha_k rho_k), so a trace's pressure is its parent's,
    and f takes the difference, alpha_f,child = alpha_f - sum_k (alpha_k,child - alpha_k).
    All are linear in the child's offset, so the children keep every amount of the parent.
    """
    fill = _filling_material(alpha, b, ix, iy, iz, ndim)
    moved = 0.0
    for k in range(alpha.shape[1]):
        if k == fill:
            continue
        a = alpha[b, k, ix, iy, iz]
        ar = arho[b, k, ix, iy, iz]
        ratio = n_arho[db, k, dx_, dy, dz] / ar if ar > 0.0 else 1.0
        n_alpha[db, k, dx_, dy, dz] = ratio * a
        n_arhoe[db, k, dx_, dy, dz] = ratio * arhoe[b, k, ix, iy, iz]
        moved += ratio * a - a
    n_alpha[db, fill, dx_, dy, dz] = alpha[b, fill, ix, iy, iz] - moved
    n_arhoe[db, fill, dx_, dy, dz] = _linear(arhoe, b, fill, ix, iy, iz, o0, o1, o2, ndim)


@njit(cache=True)
def _put_state_child(src, dst, b, ix, iy, iz, db, dx_, dy, dz, o0, o1, o2, ndim, linear, lam):
    """Prolong every conserved field to one child: conserved-linear or fraction-linear."""
    if linear:
        alpha, arho, arhoe, mom, energy, arhoq = src
        n_alpha, n_arho, n_arhoe, n_mom, n_energy, n_arhoq = dst
        _put_child(arhoq, n_arhoq, b, ix, iy, iz, db, dx_, dy, dz, o0, o1, o2, ndim, False)
        _put_child(arho, n_arho, b, ix, iy, iz, db, dx_, dy, dz, o0, o1, o2, ndim, True)
        _put_child(mom, n_mom, b, ix, iy, iz, db, dx_, dy, dz, o0, o1, o2, ndim, True)
        _put_child(energy, n_energy, b, ix, iy, iz, db, dx_, dy, dz, o0, o1, o2, ndim, True)
        _put_trace_children(alpha, arho, arhoe, n_alpha, n_arho, n_arhoe, b, ix, iy, iz, db, dx_, dy, dz,
                            o0, o1, o2, ndim)
    else:
        _put_fraction_child(src, dst, b, ix, iy, iz, db, dx_, dy, dz, o0, o1, o2, ndim, lam)


@njit(cache=True)
def restrict_ghosts(field, plan, weight0):
    """Fill coarse cells ``plan[:, P_DST..P_DZ]`` of ``field[NB, C, NX, NY, NZ]`` with fine means.

    The fine cells are the 2^ndim cells from ``plan[:, P_SRC..P_SZ]`` (their lowest corner)
    in block ``plan[:, P_SRC]``; ``weight0[e, a]`` is the share of the axis-0 child ``a``
    (1/2, or its annulus volume fraction in 2d-cylindrical): :func:`restrict_state_ghosts` of
    the one field.
    """
    restrict_state_ghosts((field,), plan, weight0)


@njit(cache=True)
def restrict_state_ghosts(state, plan, weight0):
    """Fill coarse cells ``plan[:, P_DST..P_DZ]`` of every field of ``state`` (a tuple of
    ``[NB, C, NX, NY, NZ]`` arrays, e.g. (alpha, arho, arhoe, mom, energy, arhoq)) with the
    volume-weighted means of their fine cells, in one pass over the plan.

    The fine cells are the 2^ndim cells from ``plan[:, P_SRC..P_SZ]`` (their lowest corner)
    in block ``plan[:, P_SRC]``; ``weight0[e, a]`` is the share of the axis-0 child ``a``
    (1/2, or its annulus volume fraction in 2d-cylindrical), the other axes' children 1/2 each.
    """
    nx, ny, nz = state[0].shape[2], state[0].shape[3], state[0].shape[4]
    ay = 2 if ny > 1 else 1
    az = 2 if nz > 1 else 1
    ax = 2 if nx > 1 else 1
    wy = 1.0 / ay
    wz = 1.0 / az
    for e in range(plan.shape[0]):
        sb = plan[e, P_SRC]
        sx, sy, sz = plan[e, P_SX], plan[e, P_SY], plan[e, P_SZ]
        db, dx_, dy, dz = plan[e, P_DST], plan[e, P_DX], plan[e, P_DY], plan[e, P_DZ]
        for f in range(len(state)):
            field = state[f]
            for c in range(field.shape[1]):
                acc = 0.0
                for a in range(ax):
                    for j in range(ay):
                        for k in range(az):
                            acc += weight0[e, a] * wy * wz * field[sb, c, sx + a, sy + j, sz + k]
                field[db, c, dx_, dy, dz] = acc


@njit(cache=True)
def prolong_field_ghosts(field, plan):
    """Fill fine cells of ``field`` with copies of the coarse cells that contain them (plan as above)."""
    for e in range(plan.shape[0]):
        for c in range(field.shape[1]):
            field[plan[e, P_DST], c, plan[e, P_DX], plan[e, P_DY], plan[e, P_DZ]] = \
                field[plan[e, P_SRC], c, plan[e, P_SX], plan[e, P_SY], plan[e, P_SZ]]


@njit(cache=True, parallel=True)
def prolong_state_ghosts(state, plan, block_lo, block_dx, geometry, ndim):
    """Fill fine ghost cells of every conserved field by prolongation (module docstring).

    ``state`` is the tuple (alpha, arho, arhoe, mom, energy, arhoq).  Each destination cell is
    set from the coarse source cell that contains it, at the offset between their centroids.
    The source cells' neighbours along every used axis must hold valid values (interior
    cells, or ghosts filled before).  Entries in parallel: each writes only its destination,
    a fine block's ghost cell along the plan's axis, and reads only coarse cells next to the
    coarse/fine face and their neighbours, which no entry of the same plan writes.
    """
    alpha, arho, arhoe, mom, energy, arhoq = state
    radial = geometry == CYLINDRICAL
    for e in prange(plan.shape[0]):
        db = plan[e, P_DST]
        sb = plan[e, P_SRC]
        dxi, dyi, dzi = plan[e, P_DX], plan[e, P_DY], plan[e, P_DZ]
        sx, sy, sz = plan[e, P_SX], plan[e, P_SY], plan[e, P_SZ]
        o0, o1, o2 = _child_offsets(block_lo, block_dx, block_lo, block_dx, sb, db, sx, sy, sz, dxi, dyi, dzi, radial)
        linear = _single_material(alpha, sb, sx, sy, sz, ndim)
        if linear and _child_internal_energy(arho, mom, energy, sb, sx, sy, sz, o0, o1, o2, ndim) < 0.0:
            linear = False
        lam = _fraction_limit(alpha, sb, sx, sy, sz, _fraction_growth(alpha, sb, sx, sy, sz, o0, o1, o2, ndim))
        _put_state_child(state, state, sb, sx, sy, sz, db, dxi, dyi, dzi, o0, o1, o2, ndim, linear, lam)


@njit(cache=True, parallel=True)
def prolong_blocks(src, dst, pairs, old_lo, old_dx, new_lo, new_dx, geometry, ndim):
    """Fill new child blocks from their parents, conservatively (module docstring).

    ``src`` and ``dst`` are tuples (alpha, arho, arhoe, mom, energy, arhoq) of the old and
    new meshes; ``pairs[e] = (child, parent, cx, cy, cz)``: new block ``child`` is the
    (cx, cy, cz) half of old block ``parent``, whose ghosts along every used axis are filled.
    The profile (and the volume-fraction factor lambda) is chosen per parent cell, for all its
    children together, so each parent cell's amounts are kept exactly.
    """
    alpha, arho, arhoe, mom, energy, arhoq = src
    radial = geometry == CYLINDRICAL
    nx, ny, nz = alpha.shape[2], alpha.shape[3], alpha.shape[4]
    half = (nx - 2 * GHOST) // 2
    hy = (ny - 2 * GHOST) // 2 if ny > 1 else 1
    hz = (nz - 2 * GHOST) // 2 if nz > 1 else 1
    gy = GHOST if ny > 1 else 0
    gz = GHOST if nz > 1 else 0
    ay = 2 if ny > 1 else 1
    az = 2 if nz > 1 else 1
    for e in prange(pairs.shape[0]):
        cb = pairs[e, 0]
        pb = pairs[e, 1]
        for px in range(half):
            for py in range(hy):
                for pz in range(hz):
                    sx = GHOST + pairs[e, 2] * half + px
                    sy = gy + pairs[e, 3] * hy + py
                    sz = gz + pairs[e, 4] * hz + pz
                    linear = _single_material(alpha, pb, sx, sy, sz, ndim)
                    lam = 1.0
                    for a in range(2):
                        for j in range(ay):
                            for k in range(az):
                                dxi, dyi, dzi = _child_cell(px, py, pz, a, j, k, gy, gz, ny, nz)
                                o0, o1, o2 = _child_offsets(old_lo, old_dx, new_lo, new_dx, pb, cb, sx, sy, sz, dxi,
                                                            dyi, dzi, radial)
                                if linear and _child_internal_energy(arho, mom, energy, pb, sx, sy, sz, o0, o1, o2,
                                                                     ndim) < 0.0:
                                    linear = False
                                grow = _fraction_growth(alpha, pb, sx, sy, sz, o0, o1, o2, ndim)
                                lam = min(lam, _fraction_limit(alpha, pb, sx, sy, sz, grow))
                    for a in range(2):
                        for j in range(ay):
                            for k in range(az):
                                dxi, dyi, dzi = _child_cell(px, py, pz, a, j, k, gy, gz, ny, nz)
                                o0, o1, o2 = _child_offsets(old_lo, old_dx, new_lo, new_dx, pb, cb, sx, sy, sz, dxi,
                                                            dyi, dzi, radial)
                                _put_state_child(src, dst, pb, sx, sy, sz, cb, dxi, dyi, dzi, o0, o1, o2, ndim, linear,
                                                 lam)


@njit(cache=True, parallel=True)
def restrict_blocks(src, dst, pairs, weight0):
    """Fill new parent blocks with the volume-weighted means of their old children.

    ``pairs[e] = (parent, child, cx, cy, cz)``: old block ``child`` is the (cx, cy, cz) half
    of new block ``parent``; ``weight0[e, i, a]`` is the share of axis-0 child ``a`` of the
    parent's interior cell row ``i`` (see :func:`restrict_ghosts`).
    """
    nx, ny, nz = src[0].shape[2], src[0].shape[3], src[0].shape[4]
    half = (nx - 2 * GHOST) // 2
    hy = (ny - 2 * GHOST) // 2 if ny > 1 else 1
    hz = (nz - 2 * GHOST) // 2 if nz > 1 else 1
    gy = GHOST if ny > 1 else 0
    gz = GHOST if nz > 1 else 0
    ay = 2 if ny > 1 else 1
    az = 2 if nz > 1 else 1
    wyz = 1.0 / (ay * az)
    for e in prange(pairs.shape[0]):
        pb = pairs[e, 0]
        cb = pairs[e, 1]
        for f in range(len(src)):
            fsrc = src[f]
            fdst = dst[f]
            for px in range(half):
                for py in range(hy):
                    for pz in range(hz):
                        dxi = GHOST + pairs[e, 2] * half + px
                        dyi = gy + pairs[e, 3] * hy + py
                        dzi = gz + pairs[e, 4] * hz + pz
                        for c in range(fsrc.shape[1]):
                            acc = 0.0
                            for a in range(2):
                                for j in range(ay):
                                    for k in range(az):
                                        acc += weight0[e, px, a] * wyz * fsrc[cb, c, GHOST + 2 * px + a,
                                                                             gy + 2 * py + j, gz + 2 * pz + k]
                            fdst[pb, c, dxi, dyi, dzi] = acc


@njit(cache=True)
def _face_difference(face_flux, cb, side, fb, f1, f2, j1, j2, q, a1, a2):
    """sum_f dt A_f F_f - dt A_c F_c of face-flux column q (fine sum over the fine face cells)."""
    return _fine_face_sum(face_flux, side, fb, f1, f2, q, a1, a2) - face_flux[cb, side, q, j1, j2]


@njit(cache=True)
def _fine_face_sum(face_flux, side, fb, f1, f2, q, a1, a2):
    """sum_f dt A_f F_f of face-flux column q over the fine face cells across from a coarse cell's ``side``."""
    fine = 0.0
    for a in range(a1):
        for c in range(a2):
            fine += face_flux[fb, 1 - side, q, f1 + a, f2 + c]
    return fine


@njit(cache=True)
def _coarse_face_cell(axis, ix, iy, iz):
    """The transverse indices (j1, j2) of padded cell (ix, iy, iz) in a face-flux slab along ``axis``."""
    if axis == 0:
        return iy, iz
    if axis == 1:
        return ix, iz
    return ix, iy


@njit(cache=True)
def reflux(axis, plan, volume, face_flux, alpha, arho, arhoe, arhoq, mom, energy, floors, amounts):
    """Correct coarse cells beside finer blocks with the fine face fluxes (module docstring).

    ``face_flux[NB, 2, NQ, N1, N2]`` holds dt A F through each block's low and high faces
    along ``axis`` (columns: volume, mass, internal energy of each material, momentum x y z,
    total energy, transported scalars).  ``plan`` rows are (coarse block, side, coarse cell,
    fine block, first fine face cell); ``volume`` the coarse cells' volumes V (m^3).  Each
    coarse cell takes the differences Delta = sum_f dt A_f F_f - dt A_c F_c of every column
    (:func:`_reflux_cell`).  Serial: a plan touches a few hundred cells.
    """
    n1 = face_flux.shape[3]
    n2 = face_flux.shape[4]
    a1 = 2 if n1 > 1 else 1
    a2 = 2 if n2 > 1 else 1
    delta = np.empty(face_flux.shape[2])
    for e in range(plan.shape[0]):
        cb = plan[e, R_COARSE]
        side = plan[e, R_SIDE]
        ix, iy, iz = plan[e, R_CX], plan[e, R_CY], plan[e, R_CZ]
        fb, f1, f2 = plan[e, R_FINE], plan[e, R_F1], plan[e, R_F2]
        j1, j2 = _coarse_face_cell(axis, ix, iy, iz)
        for q in range(delta.shape[0]):
            delta[q] = _face_difference(face_flux, cb, side, fb, f1, f2, j1, j2, q, a1, a2)
        _reflux_cell(cb, side, ix, iy, iz, volume[e], delta, alpha, arho, arhoe, arhoq, mom, energy, floors, amounts)


@njit(cache=True)
def _reflux_cell(cb, side, ix, iy, iz, volume, delta, alpha, arho, arhoe, arhoq, mom, energy, floors, amounts):
    """Correct coarse cell (ix, iy, iz) of block ``cb`` on its ``side`` face by the flux differences
    ``delta[NQ]`` = sum_f dt A_f F_f - dt A_c F_c (columns of :func:`reflux`), ``volume`` V (m^3).

    Every column gets the exact flux difference Delta, as if the sweep had used the fine
    fluxes: alpha_k += Delta(alpha_k,face s dt A) / V, alpha_k rho_k += Delta(mass_k) / V,
    alpha_k rho_k e_k += Delta(internal energy_k) / V, and so on (+ on the low face, - on the
    high face), with the sweep's volume
    closure: a cell without void (sum_k alpha_k >= 1 - FULL_TOLERANCE) stays exactly as full,
    each material taking its share alpha_k of the summed volume difference (equal strain,
    as the closure of an overfull cell), alpha_k += Delta_k - alpha_k sum_j Delta_j.  So a
    cell that one material fills keeps alpha = 1 and takes the mass difference in its
    density.  Each material takes the mass, volume and internal energy the fine faces carried
    at their own density and energy, as a uniform mesh would: for ideal gases at equal
    pressure p, Delta(alpha_k rho_k e_k) = p Delta alpha_k / (gamma_k - 1), so no material's
    pressure moves (converting the mass difference into volume at the coarse cell's density
    left a moving interface's cells over- or under-full by up to 7e-8 per reflux, which the
    next sweep's closure turned into pressure).  In a cell with void the void takes the
    difference.  The total energy stays exact; the sweeps reconcile the material energies with it.  A
    material driven below zero leaves the cell: the mass that brings it to zero is counted as
    added by the floors, or what remains of it as removed by the void cleanup (``floors``,
    ``amounts``).  So does a material left with less than EMPTIED_FRACTION of the mass it had:
    what remains of it is the round-off residue of two nearly equal amounts (the correction took
    all of it), and the residue's internal energy and transported scalars, which the correction
    need not have taken in the same proportion, would be unbounded per unit mass (an
    internal energy of 2.8e17 J/kg on 2.2e-16 kg/m^3 of basalt made the next sweep fail in
    case 8c per level).  A material that leaves keeps neither internal energy nor scalars; the
    cell's total energy and momentum are unchanged, the sweeps hand them to the materials present.
    """
    nmat = alpha.shape[1]
    nq = arhoq.shape[1] // nmat
    sign, strain = _face_volume_change(cb, side, ix, iy, iz, volume, delta, alpha)
    for k in range(nmat):
        a = alpha[cb, k, ix, iy, iz]
        a_new = a + sign * delta[k] - a * strain
        ar = arho[cb, k, ix, iy, iz] + sign * delta[nmat + k]
        if ar < 0.0 or a_new < 0.0 or ar < EMPTIED_FRACTION * arho[cb, k, ix, iy, iz]:
            if ar < 0.0:
                amounts[cb, AMOUNT_MASS_FLOOR] -= ar * volume
                floors[cb, FLOOR_PARTIAL_DENSITY] += 1
            elif a_new < 0.0:
                amounts[cb, AMOUNT_MASS_VOID] += ar * volume
                floors[cb, FLOOR_PARTIAL_DENSITY] += 1
            elif ar > 0.0 or a_new > 0.0:
                amounts[cb, AMOUNT_MASS_VOID] += ar * volume
                floors[cb, FLOOR_VOID_CLEANUP] += 1
            alpha[cb, k, ix, iy, iz] = 0.0
            arho[cb, k, ix, iy, iz] = 0.0
            arhoe[cb, k, ix, iy, iz] = 0.0
            for j in range(nq):
                arhoq[cb, nq * k + j, ix, iy, iz] = 0.0
        else:
            alpha[cb, k, ix, iy, iz] = a_new
            arho[cb, k, ix, iy, iz] = ar
            arhoe[cb, k, ix, iy, iz] += sign * delta[2 * nmat + k]
            for j in range(nq):
                arhoq[cb, nq * k + j, ix, iy, iz] += sign * delta[3 * nmat + 4 + nq * k + j]
    for c in range(3):
        mom[cb, c, ix, iy, iz] += sign * delta[3 * nmat + c]
    energy[cb, 0, ix, iy, iz] += sign * delta[3 * nmat + 3]


@njit(cache=True)
def register_fluxes(axis, plan, face_flux, register, block_level, level):
    """Add one sweep's face amounts of the blocks at ``level`` to the flux register of ``axis``.

    ``register[E, NQ]`` holds, per row e of the reflux ``plan`` (coarse cell, fine face cells),
    Delta_e = sum over the fine substeps of sum_f dt_f A_f F_f - dt_c A_c F_c since the
    last :func:`reflux_register`: a sweep of the coarse level (``block_level`` of the coarse
    block == ``level``) subtracts its amount dt A F, a sweep of the fine level adds the fine
    face cells' (``face_flux`` as :func:`reflux`).  Serial: a plan touches a few hundred cells.
    """
    n1 = face_flux.shape[3]
    n2 = face_flux.shape[4]
    a1 = 2 if n1 > 1 else 1
    a2 = 2 if n2 > 1 else 1
    for e in range(plan.shape[0]):
        cb = plan[e, R_COARSE]
        fb = plan[e, R_FINE]
        side = plan[e, R_SIDE]
        if block_level[cb] == level:
            j1, j2 = _coarse_face_cell(axis, plan[e, R_CX], plan[e, R_CY], plan[e, R_CZ])
            for q in range(register.shape[1]):
                register[e, q] -= face_flux[cb, side, q, j1, j2]
        elif block_level[fb] == level:
            for q in range(register.shape[1]):
                register[e, q] += _fine_face_sum(face_flux, side, fb, plan[e, R_F1], plan[e, R_F2], q, a1, a2)


@njit(cache=True)
def reflux_register(plan, volume, register, block_level, level, fine_cells, fine_volume, fine_weight, near_cells,
                    near_volume, alpha, arho, arhoe, arhoq, mom, energy, floors, amounts):
    """Correct the coarse cells at ``level`` by their flux register rows (:func:`register_fluxes`), then
    clear those rows: after the finer level's substeps have caught up with the coarse step, what
    crossed each coarse/fine face is the same amount on both sides.

    Every amount is kept when the cells together gain sigma R (R = sum_f F_f - F_c the register
    row, F_c the coarse amount, sigma = +1 on the coarse cell's low face, -1 on its high face,
    the columns as :func:`reflux`).  The coarse cell takes s R (:func:`_reflux_cell`), s = 1
    unless that would drive one of its materials below zero; then s < 1 is the largest share
    that keeps every partial density and volume fraction >= 0 (:func:`_largest_fraction`): the
    coarse face took from the fine cells' restricted ghost what they have since moved on, or the
    fine faces more of a trace than the cell held.  The remainder (1 - s) R goes, in turn, to
    the fine face cells across from it (``fine_cells[e, j]`` (block, padded cell) of volume
    ``fine_volume[e, j]`` (m^3) and face-area share ``fine_weight[e, j]``), then to the cells
    around the coarse cell in its block (``near_cells[e, j]``, ``near_volume[e, j]``; block -1
    where there is none), each set taking of every material what it holds (:func:`_absorb_shares`;
    counted as ``register_redistribution``), so no amount is lost; what none of them holds goes
    to the fine face cells by their area shares, and a material driven below zero there is
    removed and counted, as in :func:`_reflux_cell` (``negative_partial_density``,
    ``mass_added_by_floors``).
    """
    part = np.empty(register.shape[1])
    rest = np.empty(register.shape[1])
    weights = np.empty((max(fine_cells.shape[1], near_cells.shape[1]), register.shape[1]))
    for e in range(plan.shape[0]):
        cb = plan[e, R_COARSE]
        if block_level[cb] != level:
            continue
        side = plan[e, R_SIDE]
        ix, iy, iz = plan[e, R_CX], plan[e, R_CY], plan[e, R_CZ]
        share = _largest_fraction(cb, side, ix, iy, iz, volume[e], register[e], alpha, arho)
        for q in range(part.shape[0]):
            part[q] = share * register[e, q]
            rest[q] = (1.0 - share) * register[e, q]
        _reflux_cell(cb, side, ix, iy, iz, volume[e], part, alpha, arho, arhoe, arhoq, mom, energy, floors, amounts)
        if share < 1.0:
            floors[cb, FLOOR_REGISTER_REDISTRIBUTION] += 1
            _absorb_shares(fine_cells[e], fine_volume[e], fine_weight[e], side, rest, arho, weights)
            _absorb(fine_cells[e], fine_volume[e], side, rest, weights, alpha, arho, arhoe, arhoq, mom, energy, floors,
                    amounts)
            _absorb_shares(near_cells[e], near_volume[e], near_volume[e], side, rest, arho, weights)
            _absorb(near_cells[e], near_volume[e], side, rest, weights, alpha, arho, arhoe, arhoq, mom, energy, floors,
                    amounts)
            for j in range(fine_cells.shape[1]):
                for q in range(rest.shape[0]):
                    weights[j, q] = fine_weight[e, j]
            _absorb(fine_cells[e], fine_volume[e], side, rest, weights, alpha, arho, arhoe, arhoq, mom, energy, floors,
                    amounts)
        register[e, :] = 0.0


@njit(cache=True)
def _absorb(cells, volumes, side, rest, weights, alpha, arho, arhoe, arhoq, mom, energy, floors, amounts):
    """Cell j of ``cells`` (rows block, padded cell; block -1 skipped) of volume ``volumes[j]`` (m^3)
    gains sigma weights[j, q] rest[q] of every column q (:func:`_reflux_cell` through the coarse
    cell's ``side``); ``rest`` keeps what the cells did not take, rest[q] (1 - sum_j weights[j, q])."""
    part = np.empty(rest.shape[0])
    for j in range(cells.shape[0]):
        if cells[j, 0] < 0:
            continue
        for q in range(rest.shape[0]):
            part[q] = weights[j, q] * rest[q]
        _reflux_cell(cells[j, 0], side, cells[j, 1], cells[j, 2], cells[j, 3], volumes[j], part, alpha, arho, arhoe,
                     arhoq, mom, energy, floors, amounts)
    for q in range(rest.shape[0]):
        taken = 0.0
        for j in range(cells.shape[0]):
            if cells[j, 0] >= 0:
                taken += weights[j, q]
        rest[q] *= 1.0 - taken


@njit(cache=True)
def _absorb_shares(cells, volumes, area, side, rest, arho, weights):
    """``weights[j, q]``: the share of column q of the remainder ``rest`` (a gain sigma rest, sigma = +1
    through the coarse cell's low ``side``) that cell j of ``cells`` (block -1: none) takes so that
    none of its materials goes below zero; sum_j weights[j, q] <= 1.

    Material k's columns (volume, mass, internal energy, transported scalars): where the cells
    gain k, or lose T_k < 0 (kg) and each holds its share, m_jk + a_j T_k >= 0, by the shares
    a_j = ``area[j]`` / sum area; else t_k m_jk / sum_j m_jk, t_k = min(1, sum_j m_jk / -T_k), as
    much as they hold.  Momentum and total energy go with the mass moved,
    sum_k weights[j, k] |T_k| / sum_k |T_k| (the shares a_j where no mass moves), so the moved
    parcel keeps its velocity.
    """
    nmat = arho.shape[1]
    nq = (rest.shape[0] - 3 * nmat - 4) // nmat
    sigma = 1.0 if side == 0 else -1.0
    total = 0.0
    for j in range(cells.shape[0]):
        if cells[j, 0] >= 0:
            total += area[j]
    for j in range(cells.shape[0]):
        share = area[j] / total if cells[j, 0] >= 0 and total > 0.0 else 0.0
        for q in range(rest.shape[0]):
            weights[j, q] = share
    moved = 0.0
    for k in range(nmat):
        change = sigma * rest[nmat + k]
        moved += abs(change)
        if change >= 0.0:
            continue
        held = 0.0
        short = False
        for j in range(cells.shape[0]):
            if cells[j, 0] >= 0:
                m = arho[cells[j, 0], k, cells[j, 1], cells[j, 2], cells[j, 3]] * volumes[j]
                held += m
                short = short or m + weights[j, nmat + k] * change < 0.0
        if not short:
            continue
        scale = min(1.0, held / -change) / held if held > 0.0 else 0.0
        for j in range(cells.shape[0]):
            w = arho[cells[j, 0], k, cells[j, 1], cells[j, 2], cells[j, 3]] * volumes[j] * scale if cells[j, 0] >= 0 \
                else 0.0
            weights[j, k] = w
            weights[j, nmat + k] = w
            weights[j, 2 * nmat + k] = w
            for i in range(nq):
                weights[j, 3 * nmat + 4 + nq * k + i] = w
    if moved > 0.0:
        for j in range(cells.shape[0]):
            carried = 0.0
            for k in range(nmat):
                carried += weights[j, nmat + k] * abs(rest[nmat + k])
            for q in range(3 * nmat, 3 * nmat + 4):
                weights[j, q] = carried / moved


@njit(cache=True, inline="always")
def _face_volume_change(b, side, ix, iy, iz, volume, delta, alpha):
    """(sign, strain) of a correction ``delta`` of cell (ix, iy, iz) of block ``b`` through its
    ``side`` face (:func:`_reflux_cell`): sign = +1/V on the low face, -1/V on the high face
    (1/m^3), and the volume strain sign sum_k Delta(alpha_k) (-) that a cell without void
    (sum_k alpha_k >= 1 - FULL_TOLERANCE) shares among its materials, 0 in a cell with void."""
    sign = 1.0 / volume if side == 0 else -1.0 / volume
    filled = 0.0
    for k in range(alpha.shape[1]):
        filled += alpha[b, k, ix, iy, iz]
    strain = 0.0
    if filled >= 1.0 - FULL_TOLERANCE:
        for k in range(alpha.shape[1]):
            strain += sign * delta[k]
    return sign, strain


@njit(cache=True)
def _largest_fraction(b, side, ix, iy, iz, volume, delta, alpha, arho):
    """The largest t in [0, 1] for which the correction t ``delta`` of cell (ix, iy, iz) of block
    ``b`` through its ``side`` face (:func:`_reflux_cell`) leaves every partial density and volume
    fraction >= 0 (both are linear in t)."""
    nmat = alpha.shape[1]
    sign, strain = _face_volume_change(b, side, ix, iy, iz, volume, delta, alpha)
    largest = 1.0
    for k in range(nmat):
        a = alpha[b, k, ix, iy, iz]
        ar = arho[b, k, ix, iy, iz]
        da = sign * delta[k] - a * strain
        dm = sign * delta[nmat + k]
        if a + da < 0.0:
            largest = min(largest, a / -da)
        if ar + dm < 0.0:
            largest = min(largest, ar / -dm)
    return largest


def face_flux_columns(nmat: int, nq_total: int) -> int:
    """Number of face-flux columns: 3 per material, momentum (3), total energy, the scalars."""
    return 3 * nmat + 4 + nq_total


def allocate_face_flux(nblocks: int, padded_shape, ndim: int, nmat: int, nq_total: int, zeros=np.zeros) -> np.ndarray:
    """Zeroed ``face_flux[NB, 2, NQ, N1, N2]`` for :func:`impactpipe.hydro.scheme.directional.sweep`,
    from ``zeros(shape)`` (numpy's, or on several MPI ranks a partition's, whose rows of other
    ranks' blocks commit no memory until written).

    N1, N2 are the padded sizes of a sweep's two transverse axes (1 where unused), the same
    for every sweep axis since all used axes have the same padded size.
    """
    return zeros(face_flux_shape(nblocks, padded_shape, ndim, nmat, nq_total))


def face_flux_shape(nblocks: int, padded_shape, ndim: int, nmat: int, nq_total: int) -> tuple[int, ...]:
    """The shape (NB, 2, NQ, N1, N2) of :func:`allocate_face_flux`'s array."""
    n = max(padded_shape)
    return (nblocks, 2, face_flux_columns(nmat, nq_total), n if ndim > 1 else 1, n if ndim == 3 else 1)
