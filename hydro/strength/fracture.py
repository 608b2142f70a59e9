"""Grady-Kipp tensile fracture with Weibull flaws: the damage rate of one cell (njit kernels).

Flaws (:mod:`impactpipe.hydro.strength.flaws`): each cell keeps the smallest and largest
activation strain eps_min, eps_max (-) of its flaws and their count n, drawn from the body's
Weibull law n(eps) = k eps^m (Benz & Asphaug 1994).  Per step of dt (s) and material:

1. largest tensile principal stress sigma_max (Pa, tension > 0) of sigma = -p I + S
   (:func:`largest_principal_stress`);
2. local tensile strain eps_t = sigma_max / ((1 - D) E) (:func:`tensile_strain`), E Young's
   modulus (Pa; :func:`young_modulus` from the shear and bulk moduli, or given): the strain
   of the undamaged matrix, which is what activates flaws;
3. active flaws n_act(eps_t) from the cell's local Weibull law (:func:`active_flaws`);
4. damage growth (Grady & Kipp 1980; Benz & Asphaug 1994; Melosh, Ryan & Asphaug 1992):

       d(D^(1/3))/dt = n_act^(1/3) c_g / R_s                       (:func:`damage_growth_rate`)

   with the crack speed c_g = 0.4 c_p (c_p the longitudinal wave speed, m/s;
   :func:`crack_speed`) and R_s = (3 v / (4 pi))^(1/3) the radius of the sphere of the cell's
   volume v (m; :func:`crack_sphere_radius`).  An active crack grows at c_g and relieves the
   stress in the sphere it has swept: one crack of radius c_g t damages D = (c_g t / R_s)^3 of
   the cell (Benz & Asphaug 1994's d(D^(1/3))/dt = c_g / R_s), and n_act cracks the summed
   volume, D = n_act (c_g t / R_s)^3, hence the cube root of n_act.  With it the rate is
   c_g (4 pi n_act / (3 v))^(1/3), set by the density of active flaws and not by the cell
   size, and a homogeneous bar pulled at a constant strain rate reaches
   D = 36 pi k c_g^3 eps_dot^m t^(m+3) / (m+3)^3, the time dependence of Grady & Kipp's
   D = 8 pi k c_g^3 eps_dot^m t^(m+3) / ((m+1)(m+2)(m+3)), so that its fragmentation stress
   grows as eps_dot^(3/(m+3)) (Grady 1982; tests/test_fracture.py).  Read with n_act to the
   first power (method.md 2.4 as written), the rate grows with the cell volume (n_act ~ k v
   eps^m) and the bar's fragmentation stress as eps_dot^(1/(m+1)) instead (measured in the same
   test);
5. the active-flaw limit (Benz & Asphaug 1995): a cell with n_act of its n_tot flaws active
   holds at most the damage

       D_max = n_act / n_tot                                          (:func:`active_fraction`)

   A crack relieves the stress of the volume its flaw stands for, v / n_tot of the cell, and no
   more: a cell's damage grows to 1 only once the strain has reached its strongest flaw, and a
   passing tensile pulse that activates a few of its flaws leaves it partly damaged instead of
   broken (without the limit one active flaw takes any cell to D = 1 in R_s / c_g).  With
   n_tot = N ln N flaws over N cells, as drawn in the hydro stage, a cell holds about ln N of
   them, as a particle of Benz & Asphaug's does.  The limit is a material's
   ``active_flaw_limit`` (on unless switched off; off, the continuum law of many flaws per cell
   that tests/test_fracture.py verifies);
6. one step D^(1/3) <- min(D^(1/3) + dt rate, D_max^(1/3)), D never decreasing
   (:func:`damage_step`): explicit, with the rate at the start of the step, monotone and
   bounded for any dt (D never exceeds D_max <= 1).

Damaged material (:func:`damaged_pressure`, :func:`damaged_deviator`) carries (1 - D) of
the deviatoric stress and of tension and the full pressure in compression.

In the hydro stage the flaws travel with the material as a cumulative law per unit mass at
node strains (:func:`cumulative_flaws`; :mod:`impactpipe.hydro.strength.flaws`,
:func:`~impactpipe.hydro.strength.flaws.flaw_law_per_mass`), and the rate is written with the
density of active flaws, n_act / v = rho n_act,m (:func:`damage_growth_rate_of_density`):

    d(D^(1/3))/dt = c_g (4 pi rho n_act,m / 3)^(1/3)

the same rate as n_act^(1/3) c_g / R_s for the n_act = rho v n_act,m flaws of any volume v.
"""

from __future__ import annotations

import math

from numba import njit

#: Crack speed over the longitudinal wave speed, c_g / c_p (Benz & Asphaug 1994, after Lawn & Wilshaw 1975).
CRACK_SPEED_FRACTION = 0.4


@njit(cache=True, inline="always")
def young_modulus(shear_modulus, bulk_modulus):
    """Young's modulus E = 9 K G / (3 K + G) (Pa) from the shear and bulk moduli G, K (Pa)."""
    denominator = 3.0 * bulk_modulus + shear_modulus
    if denominator <= 0.0:
        return 0.0
    return 9.0 * bulk_modulus * shear_modulus / denominator


@njit(cache=True, inline="always")
def crack_speed(longitudinal_speed):
    """Crack growth speed c_g = 0.4 c_p (m/s) for the longitudinal wave speed c_p (m/s)."""
    return CRACK_SPEED_FRACTION * longitudinal_speed


@njit(cache=True, inline="always")
def crack_sphere_radius(cell_volume):
    """Radius R_s = (3 v / (4 pi))^(1/3) (m) of the sphere of the cell volume v (m^3)."""
    return (3.0 * cell_volume / (4.0 * math.pi)) ** (1.0 / 3.0)


@njit(cache=True)
def largest_principal_stress(pressure, sxx, syy, szz, sxy, sxz, syz):
    """Largest principal stress (Pa, tension positive) of sigma = -p I + S.

    ``pressure`` p (Pa, compression positive); S the symmetric deviatoric stress (Pa; in
    2d-cylindrical (r, z, theta) pass S_rr, S_zz, S_thth, S_rz, 0, 0).  Largest eigenvalue of
    the symmetric 3x3 matrix by the trigonometric solution of its characteristic cubic
    (Smith 1961): with q = tr(S) / 3, B = (S - q I) / r, r = sqrt(tr((S - q I)^2) / 6),
    lambda_max = q + 2 r cos(acos(det(B) / 2) / 3).
    """
    q = (sxx + syy + szz) / 3.0
    off = sxy * sxy + sxz * sxz + syz * syz
    a = sxx - q
    b = syy - q
    c = szz - q
    r2 = (a * a + b * b + c * c + 2.0 * off) / 6.0
    r = math.sqrt(r2)
    if r2 * r <= 0.0:  # isotropic, or so nearly that r^3 underflows
        return q - pressure
    det = (a * (b * c - syz * syz) - sxy * (sxy * c - syz * sxz) + sxz * (sxy * syz - b * sxz)) / (r2 * r)
    half = min(max(0.5 * det, -1.0), 1.0)
    return q + 2.0 * r * math.cos(math.acos(half) / 3.0) - pressure


@njit(cache=True, inline="always")
def tensile_strain(sigma_max, damage, young):
    """Local tensile strain eps_t = sigma_max / ((1 - D) E) (-); 0 in compression, without
    stiffness (E <= 0) or when fully damaged (D >= 1)."""
    if sigma_max <= 0.0 or young <= 0.0 or damage >= 1.0:
        return 0.0
    return sigma_max / ((1.0 - damage) * young)


@njit(cache=True, inline="always")
def active_flaws(strain, eps_min, eps_max, count, weibull_m):
    """Number of the cell's flaws active at tensile ``strain`` eps (-): its local Weibull law.

    The cell holds ``count`` n flaws between eps_min and eps_max.  Given those two, its other
    n - 2 flaws are a random draw from the body's flaws in between, whose number below eps grows
    as eps^m (:mod:`impactpipe.hydro.strength.flaws`), so the expected count active at eps is

        n_act = 0                                                      eps < eps_min
        n_act = 1 + (n - 2) (eps^m - eps_min^m) / (eps_max^m - eps_min^m)   eps_min <= eps < eps_max
        n_act = n                                                      eps >= eps_max

    (a cell with one flaw: 1 from eps_min on).  Summed over the cells of a body this is
    k V eps^m within sampling error at any resolution (tests/test_fracture.py).
    """
    if count <= 0 or strain < eps_min:
        return 0.0
    if strain >= eps_max:
        return float(count)
    lo = eps_min ** weibull_m
    return 1.0 + (count - 2.0) * (strain ** weibull_m - lo) / (eps_max ** weibull_m - lo)


@njit(cache=True, inline="always")
def damage_growth_rate(n_active, crack_growth_speed, sphere_radius):
    """Growth rate of the damage's cube root, d(D^(1/3))/dt = n_act^(1/3) c_g / R_s (1/s)."""
    if n_active <= 0.0:
        return 0.0
    return n_active ** (1.0 / 3.0) * crack_growth_speed / sphere_radius


@njit(cache=True, inline="always")
def active_fraction(n_active, n_total):
    """Damage limit D_max = n_act / n_tot (-) of a cell with n_act of its n_tot flaws active
    (Benz & Asphaug 1995; 0 without flaws, at most 1)."""
    if n_total <= 0.0 or n_active <= 0.0:
        return 0.0
    return min(n_active / n_total, 1.0)


@njit(cache=True, inline="always")
def damage_step(damage, rate, dt, limit=1.0):
    """Damage after dt (s) at the growth ``rate`` of D^(1/3) (1/s): D^(1/3) grows linearly, capped
    at ``limit``^(1/3) (D_max, 1 without the active-flaw limit); D never decreases (a cell above
    a limit that has fallen keeps its damage).  Stable and monotone for any dt."""
    d = max(damage, 0.0)
    root = min(d ** (1.0 / 3.0) + rate * dt, min(limit, 1.0) ** (1.0 / 3.0))
    return max(d, root * root * root)


@njit(cache=True)
def grady_kipp_damage(damage, sigma_max, young, eps_min, eps_max, count, weibull_m, crack_growth_speed,
                      sphere_radius, dt, limited):
    """Damage D after one step of dt (s) for the largest principal stress ``sigma_max`` (Pa):
    tensile strain, active flaws, growth rate and step of the module docstring, with the
    active-flaw limit D <= n_act / n_tot when ``limited``."""
    strain = tensile_strain(sigma_max, damage, young)
    n_active = active_flaws(strain, eps_min, eps_max, count, weibull_m)
    limit = active_fraction(n_active, float(count)) if limited else 1.0
    return damage_step(damage, damage_growth_rate(n_active, crack_growth_speed, sphere_radius), dt, limit)


@njit(cache=True, inline="always")
def damaged_pressure(pressure, damage):
    """Pressure (Pa) borne by material of damage D: full in compression (p >= 0), (1 - D) p in tension."""
    if pressure >= 0.0:
        return pressure
    return (1.0 - damage) * pressure


@njit(cache=True, inline="always")
def damaged_deviator(deviatoric_stress, damage):
    """Deviatoric stress component (Pa) borne by material of damage D: (1 - D) S."""
    return (1.0 - damage) * deviatoric_stress


@njit(cache=True, inline="always")
def cumulative_flaws(x, node_x, law, first, b, ix, iy, iz, scale):
    """Active flaws per unit mass (1/kg) at x = eps^m from a cumulative law at nodes.

    ``node_x`` (J,) the nodes' eps_j^m, increasing; the law's values C_j = ``scale`` times
    ``law[b, first + j, ix, iy, iz]`` (the state's mass-weighted amounts times 1 / (alpha rho)).
    Linear in x between nodes, from 0 at x = 0, C_(J-1) beyond the last node
    (:mod:`impactpipe.hydro.strength.flaws`).
    """
    if x <= 0.0:
        return 0.0
    x_lo = 0.0
    c_lo = 0.0
    for j in range(node_x.shape[0]):
        c = law[b, first + j, ix, iy, iz] * scale
        if x <= node_x[j]:
            return c_lo + (c - c_lo) * (x - x_lo) / (node_x[j] - x_lo)
        x_lo = node_x[j]
        c_lo = c
    return c_lo


@njit(cache=True, inline="always")
def damage_growth_rate_of_density(active_density, crack_growth_speed):
    """d(D^(1/3))/dt = c_g (4 pi n / 3)^(1/3) (1/s) for n active flaws per unit volume (m^-3):
    n_act^(1/3) c_g / R_s of :func:`damage_growth_rate` for the n_act = n v flaws of a volume v."""
    if active_density <= 0.0:
        return 0.0
    return crack_growth_speed * (4.0 * math.pi * active_density / 3.0) ** (1.0 / 3.0)
