"""Exact solution of the Noh implosion problem (planar, cylindrical, spherical).

Cold ideal gas (p = 0) of density rho0 streams towards the centre (axis, plane) at speed
u0: u = -u0.  A shock forms at r = 0 and moves out at D = (gamma - 1) u0 / 2.  With
nu = 1, 2, 3 (planar, cylindrical, spherical):

    r < D t  (shocked, at rest):  rho = rho0 ((gamma + 1)/(gamma - 1))^nu,  u = 0,
                                  p = (gamma - 1) rho e with e = u0^2 / 2,
                                  i.e. p = rho0 u0^2 (gamma - 1)/2 ((gamma + 1)/(gamma - 1))^nu
    r > D t  (infalling):         rho = rho0 (1 + u0 t / r)^(nu - 1),  u = -u0,  p = 0

(W. F. Noh, J. Comput. Phys. 72, 78 (1987)).  Units: kg/m^3, m/s, Pa, m, s.
"""

import numpy as np


def noh_shock_speed(gamma, u0):
    """Shock speed D = (gamma - 1) u0 / 2 (m/s)."""
    return 0.5 * (gamma - 1.0) * u0


def noh_solution(r, t, gamma, nu, rho0=1.0, u0=1.0):
    """Density, radial velocity and pressure arrays at radii r >= 0 (m) and time t >= 0 (s)."""
    if nu not in (1, 2, 3):
        raise ValueError(f"nu must be 1 (planar), 2 (cylindrical) or 3 (spherical), got {nu}")
    if gamma <= 1.0:
        raise ValueError(f"gamma must be > 1, got {gamma}")
    r = np.abs(np.asarray(r, dtype=np.float64))
    compression = ((gamma + 1.0) / (gamma - 1.0)) ** nu
    shocked = r < noh_shock_speed(gamma, u0) * t
    safe_r = np.where(r > 0.0, r, 1.0)
    growth = np.where(r > 0.0, (1.0 + u0 * t / safe_r) ** (nu - 1), 1.0)
    rho = np.where(shocked, rho0 * compression, rho0 * growth)
    u = np.where(shocked, 0.0, -u0)
    p = np.where(shocked, 0.5 * (gamma - 1.0) * rho0 * compression * u0 * u0, 0.0)
    return rho, u, p
