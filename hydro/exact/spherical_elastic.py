"""A spherically symmetric elastic wave in an infinite linear-elastic solid (exact, closed form).

The solid (density rho, bulk modulus K, shear modulus G) starts unstrained with the radial
velocity

    v0(R) = V0 (R / w) (1 - R^2 / w^2)^3   for R < w,   0 beyond                     (m/s)

about the origin.  The displacement u(R, t) (m) is the gradient of a potential phi that obeys
the wave equation with the longitudinal speed c = sqrt((K + 4 G / 3) / rho); with zero
initial displacement and phi_t(R, 0) = psi(R), psi' = v0,

    R phi(R, t) = (Q(R + c t) - Q(R - c t)) / (2 c),    Q(x) = int_0^x s psi(|s|) ds

(d'Alembert for R phi, Q even).  Here psi(R) = -(V0 w / 8) (1 - R^2 / w^2)^4 inside w and
0 beyond, so Q(x) = -(V0 w^3 / 80) (1 - (1 - x^2 / w^2)^5) inside w and -(V0 w^3 / 80)
beyond, Q'(x) = x psi(|x|) and Q''(x) = psi(|x|) + |x| v0(|x|).  With D_k = Q^(k)(R + c t)
- Q^(k)(R - c t):

    u = D_1 / (2 c R) - D_0 / (2 c R^2)
    u_R = D_2 / (2 c R) - D_1 / (c R^2) + D_0 / (c R^3)
    v = u_t = (S_2 / R - S_1 / R^2) / 2,   S_k = Q^(k)(R + c t) + Q^(k)(R - c t)

and the stress follows Hooke's law: the volumetric strain theta = u_R + 2 u / R, the
pressure P = -K theta (Pa, compression positive), the deviatoric stress
S_RR = 2 G (u_R - theta / 3) and S_TT = 2 G (u / R - theta / 3) (each tangential direction),
the total stress sigma = -P + S.  The hydro stage's wave is this one while its strains stay
small (|theta| << 1: Tillotson's and the ideal solid's pressure are then K theta) and the
displacements much smaller than the cells.  At R -> 0 the closed forms cancel; they are
meant for R of a few cells and more.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class SphericalWave(NamedTuple):
    """The exact fields at radii R (m) and one time: radial displacement (m), radial velocity
    (m/s), pressure P (Pa, compression positive), deviatoric stress S_RR and S_TT (Pa)."""

    displacement: np.ndarray
    velocity: np.ndarray
    pressure: np.ndarray
    radial_deviator: np.ndarray
    tangential_deviator: np.ndarray


def _potential_terms(x: np.ndarray, speed_amplitude: float, width: float):
    """Q(x), Q'(x), Q''(x) of the module docstring (m^3/s, m^2/s, m/s) at the arguments ``x`` (m)."""
    s = np.abs(x) / width
    inside = s < 1.0
    one = np.where(inside, 1.0 - s * s, 0.0)
    psi = -speed_amplitude * width / 8.0 * one ** 4
    v0 = speed_amplitude * s * one ** 3
    q0 = -speed_amplitude * width ** 3 / 80.0 * (1.0 - one ** 5)
    q1 = x * psi
    q2 = psi + np.abs(x) * v0
    return q0, q1, q2


def spherical_elastic_wave(radius, time: float, speed_amplitude: float, width: float, density: float,
                           bulk_modulus: float, shear_modulus: float) -> SphericalWave:
    """The exact wave of the module docstring at ``radius`` (m, > 0) and ``time`` (s): the initial
    velocity V0 = ``speed_amplitude`` (m/s) over the ``width`` w (m) in a solid of ``density``
    (kg/m^3), ``bulk_modulus`` K and ``shear_modulus`` G (Pa)."""
    r = np.asarray(radius, dtype=float)
    c = np.sqrt((bulk_modulus + 4.0 * shear_modulus / 3.0) / density)
    plus = _potential_terms(r + c * time, speed_amplitude, width)
    minus = _potential_terms(r - c * time, speed_amplitude, width)
    d0, d1, d2 = (p - m for p, m in zip(plus, minus))
    s1, s2 = plus[1] + minus[1], plus[2] + minus[2]
    u = d1 / (2.0 * c * r) - d0 / (2.0 * c * r * r)
    u_r = d2 / (2.0 * c * r) - d1 / (c * r * r) + d0 / (c * r ** 3)
    velocity = 0.5 * (s2 / r - s1 / (r * r))
    theta = u_r + 2.0 * u / r
    return SphericalWave(u, velocity, -bulk_modulus * theta, 2.0 * shear_modulus * (u_r - theta / 3.0),
                         2.0 * shear_modulus * (u / r - theta / 3.0))
