"""Sedov-Taylor point blast in a cold uniform ideal gas (planar, cylindrical, spherical).

Energy E released at r = 0, t = 0 in gas of density rho0 and zero pressure; nu = 1, 2, 3
for planar, cylindrical, spherical symmetry.  The shock radius is

    R(t) = xi0 (E t^2 / rho0)^(1/(nu + 2)),   D = dR/dt = delta R / t,  delta = 2/(nu + 2)

with E the total energy (J) for nu = 3, the energy per unit length (J/m) for nu = 2 and,
for nu = 1, the energy per unit area (J/m^2) on one side of the symmetry plane x = 0 (the
planar blast runs both ways and holds 2 E in all; E is what a half-domain run with a
reflecting wall at x = 0 holds).

Behind the shock, with xi = r/R in [0, 1], u = D f(xi), rho = rho0 g(xi), p = rho0 D^2 h(xi).
Mass, momentum and entropy conservation reduce to the ODEs (' = d/dxi)

    (f - xi) g' + g f' + (nu - 1) g f / xi = 0
    (f - xi) f' + h'/g + (delta - 1) f / delta = 0
    (f - xi) (h' - gamma h g'/g) + 2 (delta - 1) h / delta = 0

integrated from the strong-shock (Rankine-Hugoniot) values at xi = 1,
f = 2/(gamma + 1), g = (gamma + 1)/(gamma - 1), h = 2/(gamma + 1), towards xi = 0.
Energy conservation then fixes xi0:

    E = sigma_nu rho0 D^2 R^nu I,  I = int_0^1 (g f^2 / 2 + h/(gamma - 1)) xi^(nu-1) dxi,
    sigma_nu = 1, 2 pi, 4 pi   =>   xi0 = (delta^2 sigma_nu I)^(-1/(nu + 2)).

Near the centre (xi < ``XI_MIN``) the profiles follow their asymptotic forms
f ~ xi, h -> const, g ~ xi^(nu/(gamma - 1)) matched to the integrated values at XI_MIN.
"""

import dataclasses
import math

import numpy as np
from scipy.integrate import quad, solve_ivp

#: Innermost similarity coordinate reached by the ODE integration.
XI_MIN = 1.0e-6
#: Relative tolerance of the ODE integration.
ODE_RTOL = 1.0e-11

GEOMETRY_FACTOR = {1: 1.0, 2: 2.0 * math.pi, 3: 4.0 * math.pi}


@dataclasses.dataclass(frozen=True)
class SedovSolution:
    """Similarity solution for one (gamma, nu): xi0, the energy integral I and the profiles.

    ``ode`` is the scipy ``solve_ivp`` result for (f, g, h) against ln xi (dense output).
    """

    gamma: float
    nu: int
    xi0: float
    energy_integral: float
    ode: object

    def similarity_profiles(self, xi):
        """(f, g, h) at similarity coordinates xi in [0, 1] (arrays)."""
        xi = np.atleast_1d(np.asarray(xi, dtype=np.float64))
        f = np.empty_like(xi)
        g = np.empty_like(xi)
        h = np.empty_like(xi)
        inner = xi < XI_MIN
        outer = ~inner
        if outer.any():
            f[outer], g[outer], h[outer] = self.ode.sol(np.log(xi[outer]))
        if inner.any():
            f_min, g_min, h_min = self.ode.sol(math.log(XI_MIN))
            scale = xi[inner] / XI_MIN
            f[inner] = f_min * scale
            g[inner] = g_min * scale ** (self.nu / (self.gamma - 1.0))
            h[inner] = h_min
        return f, g, h

    def shock_radius(self, energy, rho0, t):
        """R(t) = xi0 (E t^2 / rho0)^(1/(nu+2)) (m)."""
        return self.xi0 * (energy * t * t / rho0) ** (1.0 / (self.nu + 2.0))

    def profiles(self, r, t, energy, rho0):
        """Density (kg/m^3), velocity (m/s) and pressure (Pa) at radii r (m), time t (s).

        Ahead of the shock: rho0, 0, 0.  ``energy`` as defined in the module docstring.
        """
        r = np.abs(np.asarray(r, dtype=np.float64))
        big_r = self.shock_radius(energy, rho0, t)
        speed = 2.0 / (self.nu + 2.0) * big_r / t
        xi = r / big_r
        rho = np.full_like(r, rho0)
        u = np.zeros_like(r)
        p = np.zeros_like(r)
        inside = xi <= 1.0
        f, g, h = self.similarity_profiles(xi[inside])
        rho[inside] = rho0 * g
        u[inside] = speed * f
        p[inside] = rho0 * speed * speed * h
        return rho, u, p


def _rhs(log_xi, y, gamma, nu):
    """d(f, g, h)/d(ln xi) of the similarity ODEs, their linear system solved in closed form.

    With w = f - xi, k = (delta - 1) / delta and delta = 2 / (nu + 2), the system

        g f' + w g' = -(nu - 1) g f / xi,   w f' + h' / g = -k f,   -gamma h w g' / g + w h' = -2 k h

    (primes d/dxi) gives g' = (g r2 - w r1 - r3 / w) / (gamma h / g - w^2), then f' and h'.  Its
    determinant w (gamma h / g - w^2) vanishes only at w = 0 and at the sonic point; a trial state
    of the integrator near one gets a large derivative, which its error control rejects, where a
    general linear solver raised on the singular matrix.
    """
    f, g, h = y
    xi = math.exp(log_xi)
    delta = 2.0 / (nu + 2.0)
    k = (delta - 1.0) / delta
    w = f - xi
    r1 = -(nu - 1.0) * g * f / xi
    r2 = -k * f
    r3 = -2.0 * k * h
    dg = (g * r2 - w * r1 - r3 / w) / (gamma * h / g - w * w)
    df = (r1 - w * dg) / g
    dh = r3 / w + gamma * h * dg / g
    return np.array([xi * df, xi * dg, xi * dh])


def sedov_solution(gamma, nu):
    """Integrate the similarity ODEs and the energy integral for gamma > 1, nu in {1, 2, 3}."""
    if nu not in GEOMETRY_FACTOR:
        raise ValueError(f"nu must be 1 (planar), 2 (cylindrical) or 3 (spherical), got {nu}")
    if gamma <= 1.0:
        raise ValueError(f"gamma must be > 1, got {gamma}")
    shock = [2.0 / (gamma + 1.0), (gamma + 1.0) / (gamma - 1.0), 2.0 / (gamma + 1.0)]
    ode = solve_ivp(_rhs, (0.0, math.log(XI_MIN)), shock, method="LSODA", args=(gamma, nu),
                    dense_output=True, rtol=ODE_RTOL, atol=1.0e-14)
    if not ode.success:
        raise RuntimeError(f"Sedov similarity ODEs failed: {ode.message}")

    def integrand(xi):
        f, g, h = ode.sol(math.log(xi))
        return (0.5 * g * f * f + h / (gamma - 1.0)) * xi ** (nu - 1)

    f_min, g_min, h_min = ode.sol(math.log(XI_MIN))
    core = (h_min / (gamma - 1.0)) * XI_MIN**nu / nu
    integral = quad(integrand, XI_MIN, 1.0, epsabs=0.0, epsrel=1.0e-11, limit=200)[0] + core
    delta = 2.0 / (nu + 2.0)
    xi0 = (delta * delta * GEOMETRY_FACTOR[nu] * integral) ** (-1.0 / (nu + 2.0))
    return SedovSolution(gamma=float(gamma), nu=int(nu), xi0=xi0, energy_integral=integral, ode=ode)
