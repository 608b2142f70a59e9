"""Hourglass viscosity: a face traction that resists the odd-even velocity modes the central
stress update cannot see (2d- and 3d-planar).

The strength update takes the velocity gradient from central differences over 2 dx and the
stress divergence from face stresses that are the mean of the two cells', so a velocity that
alternates from cell to cell (v_j = (-1)^j v) strains no cell and meets no stress: rows of
cells can slide past each other without friction.  In a granular deposit under gravity the
basal row then slides on (docs/validation.md, "Granular column collapse").

At the face j + 1/2 along axis d, the part of the velocity jump that the cells' central
gradients do not account for,

    e_i = [(v_i,j+1 - v_i,j) - dx (L_id,j + L_id,j+1) / 2] / dx
        = (-v_i,j+2 + 3 v_i,j+1 - 3 v_i,j + v_i,j-1) / (4 dx)        (1/s),

is zero for a linear velocity field and 2 v / dx for the odd-even mode.  It drives a viscous
traction t_i = eta e_i (Pa) with eta = C dx Z min(phi_j, phi_j+1) (Pa s), Z the longitudinal
impedance rho0 c_L of the material at rest (kg/(m^2 s)) and phi the cells' fills: the odd-even
mode decays at the rate 4 C c_L / dx per axis whatever the time step, a smooth field feels a
traction of order C Z dx^3 |d^3 v / dx^3|.  The traction's magnitude is capped at the shear
stress the material carries at the face, min(phi_j, phi_j+1) (sqrt(J2)_j + sqrt(J2)_j+1) / 2
(sqrt(J2) of S / phi, S the cell's mixture deviator): the odd-even mode meets at most the
friction the material has, and a thin, fast, barely stressed front (where the third difference
is large without any hourglass) is not held back by it.  Added like the deviatoric stress (flux form,
:mod:`impactpipe.hydro.strength.divergence`):

    (rho v_i) += dt / dx sum_faces n t_i        E += dt / dx sum_faces n t_i v_i,face

so momentum and total energy are conserved and the kinetic energy removed becomes internal
energy.  Faces where any of the four cells of the stencil holds no material, and block faces
next to another refinement level, carry none.  What crosses a domain face is added to the
boundary counters.
"""

from __future__ import annotations

from numba import njit, prange

from impactpipe.hydro.mesh.blocks import GHOST, ghost_widths
from impactpipe.hydro.mesh.cells import shifted_cell
from impactpipe.hydro.scheme.pencil_layout import BND_ENERGY, BND_MOMENTUM
from impactpipe.hydro.strength.update import WK_PHI, WK_S, WK_V


@njit(cache=True, inline="always")
def at_block_edge(i_face, n, side):
    """Whether the face on ``side`` (0 low, 1 high) of the cell at index ``i_face`` along an axis of
    ``n`` cells (ghosts included) is a face of its block."""
    return (side == 0 and i_face == GHOST) or (side == 1 and i_face == n - GHOST - 1)


@njit(cache=True, inline="always")
def face_area(ndim, block_dx, b, d):
    """Area (m^2) of a cell face along ``d`` in block ``b`` (the product of the other used axes' widths)."""
    return block_dx[b, 0] * (block_dx[b, 1] if ndim > 1 else 1.0) * (
        block_dx[b, 2] if ndim > 2 else 1.0) / block_dx[b, d]


@njit(cache=True, inline="always")
def face_weights(dt, h, area, side):
    """(w, wa) of the face on ``side`` (0 low, 1 high) of a cell ``h`` wide (m) along the face's
    axis, of ``area`` (m^2): a traction t on it (Pa) adds w t = n dt / h t to the cell's momentum
    (energy) density and, on a domain face, wa t = -n dt area t to what crossed it (n = -1, +1 on
    the low, high face)."""
    if side == 1:
        return dt / h, -dt * area
    return -dt / h, dt * area


@njit(cache=True, inline="always")
def kick_cell(mom, energy, b, ix, iy, iz, d_mom0, d_mom1, d_mom2, d_e):
    """Add the changes ``d_mom0 .. d_mom2`` (kg/(m^2 s)) and ``d_e`` (J/m^3) to the momentum and total
    energy densities of a cell."""
    mom[b, 0, ix, iy, iz] += d_mom0
    mom[b, 1, ix, iy, iz] += d_mom1
    mom[b, 2, ix, iy, iz] += d_mom2
    energy[b, 0, ix, iy, iz] += d_e


@njit(cache=True, inline="always")
def _shear_stress(work, b, ix, iy, iz):
    """sqrt(J2) (Pa) of the material's deviatoric stress S / phi in a cell holding material."""
    s = work[b, WK_S:WK_S + 6, ix, iy, iz]
    ss = s[0] * s[0] + s[1] * s[1] + s[2] * s[2] + 2.0 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5])
    return (0.5 * ss) ** 0.5 / work[b, WK_PHI, ix, iy, iz]


@njit(cache=True, parallel=True)
def apply_hourglass_viscosity(dt, ndim, coefficient, impedance, mom, energy, block_dx, neighbor, neighbor_level,
                              work, boundary, lo, hi):
    """Add the hourglass tractions over ``dt`` (s) to the momentum and total energy of the blocks
    ``lo .. hi - 1`` (module docstring); ``coefficient`` C (-), ``impedance`` Z (kg/(m^2 s))."""
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
                            # the face between cells j and j + 1 along d; this cell is j (side 1) or j + 1 (side 0)
                            first = 0 if side == 1 else -1
                            at_edge = at_block_edge(i_face, shape[d], side)
                            if at_edge and neighbor[b, d, side] >= 0 and neighbor_level[b, d, side] != 0:
                                continue
                            phi_min = 1.0e300
                            for k in range(-1, 3):
                                jx, jy, jz = shifted_cell(ix, iy, iz, d, first + k)
                                phi_min = min(phi_min, work[b, WK_PHI, jx, jy, jz])
                            if phi_min <= 0.0:
                                continue
                            ax, ay, az = shifted_cell(ix, iy, iz, d, first)
                            bx, by, bz = shifted_cell(ix, iy, iz, d, first + 1)
                            eta = coefficient * h * impedance * min(work[b, WK_PHI, ax, ay, az],
                                                                    work[b, WK_PHI, bx, by, bz])
                            t0 = 0.0
                            t1 = 0.0
                            t2 = 0.0
                            power = 0.0
                            for c in range(3):
                                mx, my, mz = shifted_cell(ix, iy, iz, d, first - 1)
                                px, py, pz = shifted_cell(ix, iy, iz, d, first + 2)
                                jump = (-work[b, WK_V + c, px, py, pz] + 3.0 * work[b, WK_V + c, bx, by, bz]
                                        - 3.0 * work[b, WK_V + c, ax, ay, az] + work[b, WK_V + c, mx, my, mz])
                                traction = eta * jump / (4.0 * h)
                                power += traction * 0.5 * (work[b, WK_V + c, ax, ay, az]
                                                           + work[b, WK_V + c, bx, by, bz])
                                if c == 0:
                                    t0 = traction
                                elif c == 1:
                                    t1 = traction
                                else:
                                    t2 = traction
                            # no more than the shear stress the material carries at the face
                            cap = 0.5 * min(work[b, WK_PHI, ax, ay, az], work[b, WK_PHI, bx, by, bz]) * (
                                _shear_stress(work, b, ax, ay, az) + _shear_stress(work, b, bx, by, bz))
                            size = (t0 * t0 + t1 * t1 + t2 * t2) ** 0.5
                            if size > cap:
                                scale = cap / size
                                t0 *= scale
                                t1 *= scale
                                t2 *= scale
                                power *= scale
                            w, wa = face_weights(dt, h, area, side)
                            d_mom0 += w * t0
                            d_mom1 += w * t1
                            d_mom2 += w * t2
                            d_e += w * power
                            if at_edge and neighbor[b, d, side] < 0:
                                boundary[b, BND_MOMENTUM] += wa * t0
                                boundary[b, BND_MOMENTUM + 1] += wa * t1
                                boundary[b, BND_MOMENTUM + 2] += wa * t2
                                boundary[b, BND_ENERGY] += wa * power
                    kick_cell(mom, energy, b, ix, iy, iz, d_mom0, d_mom1, d_mom2, d_e)
