"""Specific impact energies, velocity scaling of Q*_D, and published Q*_D laws (SI units).

Definitions (method reference, section 5):

- projectile-to-target mass ratio  gamma = m_p / M_T
- specific impact energy relative to the target (gravity-regime disruption studies)
      Q = 0.5 m_p v^2 / M_T                                          [J/kg]
- centre-of-mass (reduced) specific impact energy (Leinhardt & Stewart 2012)
      Q_R = 0.5 mu v^2 / M_tot = 0.5 M_T m_p v^2 / (M_T + m_p)^2
          = 0.5 gamma v^2 / (1 + gamma)^2 = Q / (1 + gamma)^2       [J/kg]
  with mu = m_p M_T / M_tot the reduced mass and M_tot = M_T + m_p.
- point-source velocity scaling (Housen & Holsapple 1990): at fixed target size,
      Q*_D ~ C rho R_T^(3 mu) V^(2 - 3 mu),
  so Q*_D(V2) = Q*_D(V1) (V2 / V1)^(2 - 3 mu); mu ~ 0.45 for rock in the gravity
  regime (0.55-0.6 for rock/water, ~0.4 for sand).

Published laws (coefficients and sources in docs/analysis.md):

- Benz & Asphaug (1999), Icarus 142, 5-20, Table III, basalt (SPH with strength
  and self-gravity, head-on-averaged impacts):
      Q*_D = Q0 (R / 1 cm)^a + B rho (R / 1 cm)^b     [erg/g; rho in g/cm^3]
  evaluated here in cgs and converted to J/kg (1 erg/g = 1e-4 J/kg).
- Leinhardt & Stewart (2012), ApJ 745, 79, the catastrophic disruption criterion
  for head-on impacts (their eqs. 23 and 28):
      R_C1 = (3 M_tot / (4 pi rho1))^(1/3),  rho1 = 1000 kg/m^3
      Q*_RD,gamma=1 = c* (4/5) pi rho1 G R_C1^2
      Q*_RD = Q*_RD,gamma=1 [(1 + gamma)^2 / (4 gamma)]^(2 / (3 mu_bar) - 1)
  with c* = 1.9 +- 0.3, mu_bar = 0.36 +- 0.01 for small bodies ("principal
  disruption curve" fitted to small-body simulations; c* = 5 +- 2, mu_bar = 0.37
  for strengthless planets).
- Size law fit Q*_D(R) = q_b R^alpha + rho q_g R^beta (strength + gravity).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.constants import G as G_SI
from scipy.optimize import curve_fit

ERG_PER_G = 1.0e-4  # J/kg

#: Benz & Asphaug (1999) Table III, basalt: impact speed (km/s) -> (Q0 [erg/g], a, B [erg cm^3 g^-2], b)
BA99_BASALT = {
    3.0: (3.5e7, -0.38, 0.3, 1.36),
    5.0: (9.0e7, -0.36, 0.5, 1.36),
}
#: Leinhardt & Stewart (2012) principal disruption curve parameters.
LS12_SMALL_BODIES = {"c_star": 1.9, "mu_bar": 0.36}
LS12_STRENGTHLESS_PLANETS = {"c_star": 5.0, "mu_bar": 0.37}
LS12_RHO1 = 1000.0  # kg/m^3


def mass_ratio(m_p, M_T):
    """gamma = m_p / M_T (dimensionless)."""
    return np.asarray(m_p, dtype=float) / np.asarray(M_T, dtype=float)


def impact_energy(m_p, M_T, v):
    """Q = 0.5 m_p v^2 / M_T (J/kg) for projectile mass m_p (kg), target mass M_T (kg), speed v (m/s)."""
    return 0.5 * np.asarray(m_p, dtype=float) * np.asarray(v, dtype=float) ** 2 / np.asarray(M_T, dtype=float)


def reduced_impact_energy(m_p, M_T, v):
    """Q_R = 0.5 M_T m_p v^2 / (M_T + m_p)^2 = 0.5 gamma v^2 / (1 + gamma)^2 (J/kg)."""
    m_p = np.asarray(m_p, dtype=float)
    M_T = np.asarray(M_T, dtype=float)
    return 0.5 * M_T * m_p * np.asarray(v, dtype=float) ** 2 / (M_T + m_p) ** 2


def sphere_mass(radius, density):
    """Mass (kg) of a sphere of ``radius`` (m) and ``density`` (kg/m^3): 4/3 pi rho R^3."""
    return 4.0 / 3.0 * np.pi * np.asarray(density, dtype=float) * np.asarray(radius, dtype=float) ** 3


def escape_speed(mass, radius, G: float = G_SI):
    """Surface escape speed sqrt(2 G M / R) (m/s)."""
    return np.sqrt(2.0 * G * np.asarray(mass, dtype=float) / np.asarray(radius, dtype=float))


def scale_qstar_to_velocity(qstar, v_from, v_to, mu: float = 0.45):
    """Move Q*_D measured at impact speed ``v_from`` to speed ``v_to`` (m/s).

    Point-source coupling at fixed target size: Q*_D ~ V^(2 - 3 mu), so
    Q*_D(v_to) = Q*_D(v_from) (v_to / v_from)^(2 - 3 mu).  mu = 0.45 (rock, gravity
    regime) by default.
    """
    ratio = np.asarray(v_to, dtype=float) / np.asarray(v_from, dtype=float)
    return np.asarray(qstar, dtype=float) * ratio ** (2.0 - 3.0 * mu)


def benz_asphaug_1999(radius, density=2700.0, *, velocity_kms: float = 3.0):
    """Q*_D (J/kg) of basalt targets of ``radius`` (m) from Benz & Asphaug (1999).

    Q*_D = Q0 (R/1 cm)^a + B rho (R/1 cm)^b in erg/g with rho in g/cm^3 (Table III);
    ``velocity_kms`` picks the 3 or 5 km/s set.  ``density`` in kg/m^3 (their basalt:
    2700 kg/m^3).
    """
    if velocity_kms not in BA99_BASALT:
        raise ValueError(f"Benz & Asphaug (1999) basalt sets exist for {sorted(BA99_BASALT)} km/s")
    q0, a, b_coef, b = BA99_BASALT[velocity_kms]
    r_cm = np.asarray(radius, dtype=float) * 100.0
    rho_cgs = np.asarray(density, dtype=float) * 1.0e-3
    return (q0 * r_cm**a + b_coef * rho_cgs * r_cm**b) * ERG_PER_G


def leinhardt_stewart_2012_qrd(total_mass, gamma, *, c_star: float = 1.9, mu_bar: float = 0.36,
                               rho1: float = LS12_RHO1, G: float = G_SI):
    """Head-on catastrophic disruption criterion Q*_RD (J/kg) of Leinhardt & Stewart (2012).

    Q*_RD = c* (4/5) pi rho1 G R_C1^2 [(1 + gamma)^2 / (4 gamma)]^(2/(3 mu_bar) - 1),
    R_C1 = (3 M_tot / (4 pi rho1))^(1/3); M_tot in kg, gamma = m_p / M_T.
    Defaults: small bodies (c* = 1.9, mu_bar = 0.36).
    """
    total_mass = np.asarray(total_mass, dtype=float)
    gamma = np.asarray(gamma, dtype=float)
    r_c1 = (3.0 * total_mass / (4.0 * np.pi * rho1)) ** (1.0 / 3.0)
    q_equal = c_star * 0.8 * np.pi * rho1 * G * r_c1**2
    return q_equal * ((1.0 + gamma) ** 2 / (4.0 * gamma)) ** (2.0 / (3.0 * mu_bar) - 1.0)


def leinhardt_stewart_2012_qstar_d(target_radius, target_density, gamma, **kwargs):
    """The Leinhardt & Stewart (2012) criterion expressed as Q*_D (target frame, M_lr = M_T/2).

    LS12 define Q*_RD by M_lr = M_tot/2 and the universal law
    M_lr/M_tot = 1 - Q_R / (2 Q*_RD).  M_lr = M_T/2 then needs
    Q_R = Q*_RD (1 + 2 gamma)/(1 + gamma), and Q = (1 + gamma)^2 Q_R, so

        Q*_D = Q*_RD (1 + 2 gamma)(1 + gamma).

    Args:
        target_radius: R_T (m).
        target_density: target bulk density (kg/m^3); M_T = 4/3 pi rho R_T^3.
        gamma: m_p / M_T.
        **kwargs: c_star, mu_bar, rho1, G for :func:`leinhardt_stewart_2012_qrd`.
    """
    gamma = np.asarray(gamma, dtype=float)
    total_mass = sphere_mass(target_radius, target_density) * (1.0 + gamma)
    return leinhardt_stewart_2012_qrd(total_mass, gamma, **kwargs) * (1.0 + 2.0 * gamma) * (1.0 + gamma)


def comparison_laws(radius, density, gamma) -> dict[str, np.ndarray]:
    """Q*_D (J/kg) against target radius (m) from the published laws, keyed by a plot label."""
    return {
        "Benz & Asphaug 1999, basalt 3 km/s": benz_asphaug_1999(radius, density, velocity_kms=3.0),
        "Benz & Asphaug 1999, basalt 5 km/s": benz_asphaug_1999(radius, density, velocity_kms=5.0),
        "Leinhardt & Stewart 2012, small bodies": leinhardt_stewart_2012_qstar_d(radius, density, gamma),
    }


@dataclass(frozen=True)
class SizeLawFit:
    """Q*_D(R) = q_b R^alpha + rho q_g R^beta with R in m and Q*_D in J/kg.

    Attributes:
        q_b: strength coefficient (J/kg m^-alpha).
        alpha: strength-regime exponent.
        q_g: gravity coefficient (J m^3 kg^-2 m^-beta).
        beta: gravity-regime exponent.
        covariance: (4, 4) covariance of (ln q_b, alpha, ln q_g, beta).
        rms_log10: rms residual of log10 Q*_D.
    """

    q_b: float
    alpha: float
    q_g: float
    beta: float
    covariance: np.ndarray
    rms_log10: float

    def __call__(self, radius, density):
        """Q*_D (J/kg) at ``radius`` (m) and ``density`` (kg/m^3)."""
        r = np.asarray(radius, dtype=float)
        return self.q_b * r**self.alpha + np.asarray(density, dtype=float) * self.q_g * r**self.beta


def _log10_size_law(x, ln_qb, alpha, ln_qg, beta):
    r, rho = x
    return np.log10(np.exp(ln_qb) * r**alpha + rho * np.exp(ln_qg) * r**beta)


def fit_qstar_size_law(radius, qstar, density) -> SizeLawFit:
    """Least-squares fit of Q*_D(R) = q_b R^alpha + rho q_g R^beta in log space.

    Minimises sum (log10 Q*_D,i - log10 model(R_i))^2 over (ln q_b, alpha, ln q_g,
    beta) with scipy.optimize.curve_fit, starting from Benz & Asphaug (1999) basalt
    at 3 km/s converted to SI.  Needs at least 5 points spanning both regimes for the
    four parameters to be constrained.

    Args:
        radius: (n,) target radii (m).
        qstar: (n,) Q*_D values (J/kg).
        density: target density (kg/m^3), scalar or (n,).
    """
    r = np.asarray(radius, dtype=float)
    q = np.asarray(qstar, dtype=float)
    rho = np.broadcast_to(np.asarray(density, dtype=float), r.shape)
    if r.shape != q.shape or r.ndim != 1 or r.size < 5:
        raise ValueError("radius and qstar must be matching 1-D arrays with at least 5 points")
    q0, a, b_coef, b = BA99_BASALT[3.0]
    p0 = [np.log(q0 * ERG_PER_G * 100.0**a), a, np.log(b_coef * ERG_PER_G * 1.0e-3 * 100.0**b), b]
    popt, pcov = curve_fit(_log10_size_law, (r, rho), np.log10(q), p0=p0, maxfev=20000)
    resid = np.log10(q) - _log10_size_law((r, rho), *popt)
    return SizeLawFit(
        q_b=float(np.exp(popt[0])),
        alpha=float(popt[1]),
        q_g=float(np.exp(popt[2])),
        beta=float(popt[3]),
        covariance=pcov,
        rms_log10=float(np.sqrt(np.mean(resid**2))),
    )
