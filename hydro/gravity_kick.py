"""The per-cell gravity kick shared by the uniform external field (:mod:`impactpipe.hydro.gravity`)
and self-gravity (:mod:`impactpipe.hydro.self_gravity`): over dt (s) a cell of density rho
(kg/m^3) in the acceleration g (m/s^2) gets

    (rho u)_new = (rho u)_old + rho g dt,   E_new = E_old + g . (rho u)_old dt + rho |g|^2 dt^2 / 2,

the exact solution of d(rho u)/dt = rho g, dE/dt = g . (rho u) over the step, so the internal
energy is unchanged.
"""

from __future__ import annotations

import math

from numba import njit

from impactpipe.hydro.mesh.blocks import CYLINDRICAL


@njit(cache=True, inline="always")
def cell_volume(geometry, r_lo, dx0, dx1, dx2):
    """Volume of a cell (m^3): the annulus pi ((r_lo + dx0)^2 - r_lo^2) dx1 in 2d-cylindrical
    (r_lo its inner radius, m), dx0 dx1 dx2 otherwise (unused axes 1 m)."""
    if geometry == CYLINDRICAL:
        return math.pi * ((r_lo + dx0) ** 2 - r_lo * r_lo) * dx1
    return dx0 * dx1 * dx2


@njit(cache=True, inline="always")
def gravity_kick(dt, g0, g1, g2, rho, momentum, energy, b, ix, iy, iz):
    """Kick one cell of density ``rho`` (kg/m^3) by the acceleration (g0, g1, g2) (m/s^2) over
    ``dt`` (s): (rho u) += rho g dt, E += g . (rho u)_old dt + rho |g|^2 dt^2 / 2 (module
    docstring).  Returns the energy density added (J/m^3)."""
    de = (g0 * momentum[b, 0, ix, iy, iz] + g1 * momentum[b, 1, ix, iy, iz]
          + g2 * momentum[b, 2, ix, iy, iz]) * dt + 0.5 * rho * (g0 * g0 + g1 * g1 + g2 * g2) * dt * dt
    momentum[b, 0, ix, iy, iz] += rho * g0 * dt
    momentum[b, 1, ix, iy, iz] += rho * g1 * dt
    momentum[b, 2, ix, iy, iz] += rho * g2 * dt
    energy[b, 0, ix, iy, iz] += de
    return de
