"""Face shear stress: an elastic-plastic shear stress on each cell face, driven by the face's own
strain rate, so that the odd-even (hourglass) velocity modes the cell-centred stress update
does not see meet the material's stress (planar meshes).

The strength update takes the velocity gradient from central differences over 2 dx and the
stress divergence from face stresses that are the mean of the two cells', so a velocity that
alternates from cell to cell (v_j = (-1)^j v) strains no cell and meets no stress.  The
hourglass viscosity (:mod:`impactpipe.hydro.strength.hourglass`) resists that mode with a
viscous traction on top of the cells' stress, which adds friction that depends on the mesh;
here each face carries a shear stress of its own instead, a staggered copy of the tangential
components whose strain rate takes the velocity difference across the face, so that the mode
strains it, and whose yield limits the shear it carries to the material's friction.

At the face j + 1/2 along axis d (cells j, j + 1, width dx_d) and for each tangential component
i != d, the face stress T_i (Pa, the material's S_id on that face) advances over the stress
update's dt with the same half-step velocities and the shear modulus G (Pa):

    gamma_i = (v_i,j+1 - v_i,j) / dx_d + (L_di,j + L_di,j+1) / 2        (1/s),
    T_i* = T_i + G dt gamma_i,

gamma the engineering shear rate of the face: the velocity difference across it (2 v / dx for
the odd-even mode, which the cells' central gradients give as 0) and the mean of the two cells'
gradients L_di = d v_d / d x_i along it, as the stress update takes them (central, one-sided
next to void; it stores them in ``WK_L``, so that no kernel reads a corner ghost).  The face then yields as a Coulomb slip
plane: the norm of its tangential stress over the components i != d is held to the face's
shear strength k = (k_j / phi_j + k_j+1 / phi_j+1) / 2, k the cells' sqrt(J2) yield limit
Y_eq / sqrt(3) (Pa; mu_i p for a cohesionless GEO material), phi their fills
(:func:`impactpipe.hydro.strength.update.update_stress` stores k, fill-weighted, in ``WK_Y``):

    |T*| > k:  T = T* k / |T*|.

The stress divergence (:mod:`impactpipe.hydro.strength.divergence`) applies the cells' mean
shear s_i = (S_id,j / phi_j + S_id,j+1 / phi_j+1) / 2 on the face; both half kicks add the rest,
the traction min(phi_j, phi_j+1) (T_i - s_i), in flux form,

    (rho v_i) += (dt / 2) / dx_d sum_faces n tau_i        E += (dt / 2) / dx_d sum_faces n tau_i v_i,face

(v_face the mean of the two cells' velocities), so the face's tangential traction is
min(phi_j, phi_j+1) T and momentum and total energy are conserved.  Where the cells deform
smoothly and elastically T follows their mean shear (both integrate the same rate; T has no
Jaumann rotation and is not transported); the odd-even mode strains T, oscillates at
2 c_s / dx (c_s = sqrt(G / rho), inside the CFL step) and is held at rest by it up to the
face's yield.  Where the material yields the face carries up to k, the Coulomb friction on its
plane, while a cell carries |S_id| <= sqrt(k^2 - the rest of J2): the faces are slip planes
along the mesh axes with the material's friction.

Storage: ``face[b, d * ndim + i, ...]`` at cell j holds T_i of the face j + 1/2 along d; NaN on a
face that carries none (one of its cells holds no material, or it is a block face next to
another refinement level).  A face that starts to carry one starts at T = s.  Each block
updates every face of its interior cells, the low face of its first cell at the ghost index
GHOST - 1: a face shared by two blocks is updated by both from the same ghost copies with the
same arithmetic, so both copies agree bit for bit and the kick reads only its own.
"""

from __future__ import annotations

import math

from numba import njit, prange

from impactpipe.hydro.mesh.blocks import GHOST, ghost_widths
from impactpipe.hydro.scheme.pencil_layout import BND_ENERGY, BND_MOMENTUM
from impactpipe.hydro.mesh.cells import shifted_cell
from impactpipe.hydro.strength.hourglass import at_block_edge, face_area, face_weights, kick_cell
from impactpipe.hydro.strength.update import WK_L, WK_PHI, WK_S, WK_V, WK_Y, gradient_slot


@njit(cache=True, inline="always")
def _shear_slot(i, d):
    """Work slot of the deviatoric shear component S_id (i != d): xy, xz, yz at WK_S + 3, 4, 5."""
    lo = min(i, d)
    hi = max(i, d)
    if lo == 0:
        return WK_S + 2 + hi
    return WK_S + 5


@njit(cache=True, inline="always")
def _next_to_level(b, d, j, n, neighbor, neighbor_level):
    """Whether the face j + 1/2 along ``d`` of block ``b`` (``n`` cells with ghosts) is a block face
    next to another refinement level."""
    if j == GHOST - 1:
        return neighbor[b, d, 0] >= 0 and neighbor_level[b, d, 0] != 0
    if j == n - GHOST - 1:
        return neighbor[b, d, 1] >= 0 and neighbor_level[b, d, 1] != 0
    return False


@njit(cache=True, inline="always")
def _mean_shear(work, b, ix, iy, iz, d, i):
    """The cells' mean shear s = (S_id,j / phi_j + S_id,j+1 / phi_j+1) / 2 (Pa) at the face j + 1/2
    along ``d``, j = (ix, iy, iz)."""
    bx, by, bz = shifted_cell(ix, iy, iz, d, 1)
    slot = _shear_slot(i, d)
    return 0.5 * (work[b, slot, ix, iy, iz] / work[b, WK_PHI, ix, iy, iz]
                  + work[b, slot, bx, by, bz] / work[b, WK_PHI, bx, by, bz])


@njit(cache=True, inline="always")
def _trial(work, face, b, ix, iy, iz, d, i, ndim, h, gdt):
    """The trial face stress T* = T + G dt gamma_i (Pa) of component ``i`` at the face j + 1/2 along
    ``d``, j = (ix, iy, iz), cells of width ``h`` along d (m); the cells' mean shear s on a face that
    starts to carry one; ``gdt`` = G dt (Pa s)."""
    old = face[b, d * ndim + i, ix, iy, iz]
    if math.isnan(old):
        return _mean_shear(work, b, ix, iy, iz, d, i)
    bx, by, bz = shifted_cell(ix, iy, iz, d, 1)
    slot = WK_L + gradient_slot(d, i)
    rate = (work[b, WK_V + i, bx, by, bz] - work[b, WK_V + i, ix, iy, iz]) / h + 0.5 * (
        work[b, slot, ix, iy, iz] + work[b, slot, bx, by, bz])
    return old + gdt * rate


@njit(cache=True, parallel=True)
def update_face_shear(dt, ndim, modulus, block_dx, neighbor, neighbor_level, work, face, lo, hi):
    """Advance the face stresses T (Pa) of the blocks ``lo .. hi - 1`` over ``dt`` (s) with the
    velocities, fills, mixture stresses and yield limits in ``work`` (ghosts filled two layers
    deep); ``modulus`` G (Pa).  Module docstring: T* = T + G dt gamma, held to |T| <= k."""
    nb, nw, nx, ny, nz = work.shape
    shape = (nx, ny, nz)
    for b in prange(lo, hi):
        for d in range(ndim):
            h = block_dx[b, d]
            n = shape[d]
            x0 = GHOST - 1 if d == 0 else GHOST
            y0 = GHOST - 1 if d == 1 else (GHOST if ny > 1 else 0)
            z0 = GHOST - 1 if d == 2 else (GHOST if nz > 1 else 0)
            for ix in range(x0, nx - GHOST):
                for iy in range(y0, ny - GHOST if ny > 1 else 1):
                    for iz in range(z0, nz - GHOST if nz > 1 else 1):
                        j = ix if d == 0 else (iy if d == 1 else iz)
                        bx, by, bz = shifted_cell(ix, iy, iz, d, 1)
                        fa = work[b, WK_PHI, ix, iy, iz]
                        fb = work[b, WK_PHI, bx, by, bz]
                        if fa <= 0.0 or fb <= 0.0 or _next_to_level(b, d, j, n, neighbor, neighbor_level):
                            for i in range(ndim):
                                if i != d:
                                    face[b, d * ndim + i, ix, iy, iz] = math.nan
                            continue
                        strength = 0.5 * (work[b, WK_Y, ix, iy, iz] / fa + work[b, WK_Y, bx, by, bz] / fb)
                        # the tangential components (d + 1) % 3 and (d + 2) % 3 that the mesh carries
                        i1 = (d + 1) % 3
                        i2 = (d + 2) % 3
                        t1 = t2 = 0.0
                        if i1 < ndim:
                            t1 = _trial(work, face, b, ix, iy, iz, d, i1, ndim, h, modulus * dt)
                        if i2 < ndim:
                            t2 = _trial(work, face, b, ix, iy, iz, d, i2, ndim, h, modulus * dt)
                        size = (t1 * t1 + t2 * t2) ** 0.5
                        scale = strength / size if size > strength else 1.0
                        if i1 < ndim:
                            face[b, d * ndim + i1, ix, iy, iz] = t1 * scale
                        if i2 < ndim:
                            face[b, d * ndim + i2, ix, iy, iz] = t2 * scale


@njit(cache=True, parallel=True)
def apply_face_shear(dt, ndim, mom, energy, block_dx, neighbor, neighbor_level, work, face, boundary, lo, hi):
    """Add the face tractions min(phi_j, phi_j+1) (T - s) (Pa) over ``dt`` (s) to the momentum and total
    energy of the interior cells of the blocks ``lo .. hi - 1`` (module docstring); what crosses a
    domain face goes to ``boundary``."""
    nb, nw, nx, ny, nz = work.shape
    gx, gy, gz = ghost_widths(nx, ny, nz)
    shape = (nx, ny, nz)
    for b in prange(lo, hi):
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    if work[b, WK_PHI, ix, iy, iz] <= 0.0:
                        continue
                    d_mom0 = 0.0
                    d_mom1 = 0.0
                    d_mom2 = 0.0
                    d_e = 0.0
                    for d in range(ndim):
                        h = block_dx[b, d]
                        area = face_area(ndim, block_dx, b, d)
                        i_face = ix if d == 0 else (iy if d == 1 else iz)
                        for side in range(2):
                            # the face j + 1/2 is stored at cell j: this cell (side 1) or the one below (side 0)
                            ax, ay, az = shifted_cell(ix, iy, iz, d, side - 1)
                            bx, by, bz = shifted_cell(ix, iy, iz, d, side)
                            fill = min(work[b, WK_PHI, ax, ay, az], work[b, WK_PHI, bx, by, bz])
                            if fill <= 0.0:
                                continue
                            w, wa = face_weights(dt, h, area, side)
                            at_edge = at_block_edge(i_face, shape[d], side)
                            for i in range(ndim):
                                if i == d:
                                    continue
                                stress = face[b, d * ndim + i, ax, ay, az]
                                if math.isnan(stress):
                                    continue
                                traction = fill * (stress - _mean_shear(work, b, ax, ay, az, d, i))
                                power = traction * 0.5 * (work[b, WK_V + i, ax, ay, az] + work[b, WK_V + i, bx, by, bz])
                                if i == 0:
                                    d_mom0 += w * traction
                                elif i == 1:
                                    d_mom1 += w * traction
                                else:
                                    d_mom2 += w * traction
                                d_e += w * power
                                if at_edge and neighbor[b, d, side] < 0:
                                    boundary[b, BND_MOMENTUM + i] += wa * traction
                                    boundary[b, BND_ENERGY] += wa * power
                    kick_cell(mom, energy, b, ix, iy, iz, d_mom0, d_mom1, d_mom2, d_e)
