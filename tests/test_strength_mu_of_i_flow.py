"""The GEO strength's mu(I) friction in a flow: a granular layer on a rough inclined plane
(hydro/problems/inclined_plane.py; docs/validation.md, "mu(I) friction on an inclined plane").

Exact solution (GDR MiDi 2004; Jop, Forterre & Pouliquen 2005, 2006).  A layer of thickness h on a
plane inclined at theta, uniform along the slope x and steady: the momentum balance across it
(z normal to the plane, the free surface at z = h stress-free) gives

    tau(z) = rho g sin(theta) (h - z),    P(z) = rho g cos(theta) (h - z)      (Pa),

so tau / P = tan(theta) at every depth.  The code's friction bound is sqrt(J2(S)) <= mu(I) P, which
in simple shear u(z) is |tau| <= mu(I) P, with mu(I) = mu_s + (mu_2 - mu_s) / (I0 / I + 1) and
I = gamma_dot d / sqrt(P / rho_s) (rho_s the material's density, d the grain diameter),
gamma_dot = sqrt(2 D_dev:D_dev) = du/dz in simple shear
(:func:`impactpipe.hydro.strength.yield_strength.inertial_friction`).  A flowing layer is on its yield
surface, so mu(I) = tan(theta): the inertial number is uniform,

    I_theta = I0 (tan theta - mu_s) / (mu_2 - tan theta)        (mu_s < tan theta < mu_2),

and du/dz = (I_theta / d) sqrt(P / rho_s) = (I_theta / d) sqrt(g cos(theta) (h - z)).  With the
no-slip floor u(0) = 0 it integrates to the Bagnold profile

    u(z) = (2 I_theta / (3 d)) sqrt(g cos theta) [h^(3/2) - (h - z)^(3/2)]     (m/s).

Below the static friction (tan theta < mu_s) no flow balances the slope's shear below mu_s P and
the layer stays at rest; above mu_2 none does either (mu(I) < mu_2 at every I) and the layer
accelerates, its mean acceleration at least g (sin theta - mu_2 cos theta).

The scene (lengths scaled by the grain: d = 0.53 mm, h = 10 d, the glass beads' mu_s = tan 20.9 deg,
mu_2 = tan 32.76 deg, I0 = 0.279 of Jop et al. 2006): periodic along the slope, the rough floor no-slip
(its ghost cells mirror the velocity with the sign flipped), the tilt in the gravity vector, an elastic
material of compressibility rho0 g h / K = 1e-2, the column collapse's hourglass viscosity C = 0.1
(without it an odd-even velocity mode across the layer grows unresisted).  The flow settles within
1 % of its steady mean velocity by 53 to 60 tau, tau = sqrt(h / g); the test averages the profile
over (80, 100] tau, as `python benchmarks/mu_of_i_inclined_plane.py` does.  Measured (`python -m
pytest tests/test_strength_mu_of_i_flow.py -s -q` prints them; the bounds have room over them): relative L2 error 0.0766 and 0.0342 at 8 and 16 cells across h (the profile
lies above the exact one from the floor cell up; at this compressibility the error stops falling
near 2.5 %, 0.0247 at 32 cells, where at rho0 g h / K = 1e-3 it is 0.104, 0.028 and 0.0045 at 8, 16
and 32 cells: docs/validation.md, "mu(I) friction on an inclined plane"); at 18 deg the layer below its top row of cells moves at most at 9.5e-4
sqrt(g h) (the top row, held at the surface-layer pressure, creeps at 8.9e-3 sqrt(g h)); at 35 deg
the mean acceleration over [10, 20] tau is 0.952 m/s^2 against the bound 0.456 m/s^2.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from impactpipe.hydro.problems import inclined_plane
from impactpipe.hydro.strength.yield_strength import inertial_friction

MU_S = math.tan(math.radians(20.9))
MU_2 = math.tan(math.radians(32.76))
I0 = 0.279
GRAIN = 0.53e-3
THICKNESS = 10.0 * GRAIN
G = 9.81
#: sqrt(h / g) (s), the layer's time unit.
TAU = math.sqrt(THICKNESS / G)
#: rho0 g h / K of the material.
COMPRESSIBILITY = 1.0e-2
HOURGLASS = 0.1


def layer(slope_deg: float, cells: int):
    """The scene at ``slope_deg`` with ``cells`` cells across h."""
    material = inclined_plane.granular_material(math.sqrt(G * THICKNESS / COMPRESSIBILITY), MU_S, MU_2, I0, GRAIN)
    return inclined_plane.setup(material, math.radians(slope_deg), THICKNESS, cells, G, 0.4, HOURGLASS)


def test_the_bagnold_profile_is_the_steady_solution_of_the_codes_friction():
    slope = math.radians(25.0)
    inertial = inclined_plane.slope_inertial_number(slope, MU_S, MU_2, I0)
    z = np.linspace(0.0, THICKNESS, 11)[:-1]
    u = inclined_plane.bagnold_velocity(z, THICKNESS, slope, G, MU_S, MU_2, I0, GRAIN)
    assert u[0] == 0.0
    rho = 2500.0
    for depth in (0.1 * THICKNESS, 0.5 * THICKNESS, THICKNESS):
        pressure = rho * G * math.cos(slope) * depth
        shear_rate = inertial / GRAIN * math.sqrt(G * math.cos(slope) * depth)
        assert inertial_friction(MU_S, MU_2, I0, GRAIN, shear_rate, pressure, rho) == pytest.approx(
            math.tan(slope), rel=1e-12)
        step = 1e-6 * THICKNESS
        zs = np.array([THICKNESS - depth - step, THICKNESS - depth + step])
        du = np.diff(inclined_plane.bagnold_velocity(zs, THICKNESS, slope, G, MU_S, MU_2, I0, GRAIN))[0]
        assert du / (2.0 * step) == pytest.approx(shear_rate, rel=1e-6)
    for outside in (20.0, 33.0):
        with pytest.raises(ValueError, match="no steady flow"):
            inclined_plane.slope_inertial_number(math.radians(outside), MU_S, MU_2, I0)


def _steady_error(cells: int) -> float:
    """Relative L2 error of the velocity profile averaged over (80, 100] tau (sampled every tau) against
    the Bagnold profile (as `python benchmarks/mu_of_i_inclined_plane.py` measures it)."""
    slope = math.radians(25.0)
    sim = layer(25.0, cells)
    profiles = []
    for k in range(1, 101):
        sim.run(k * TAU)
        if k > 80:
            z, u = inclined_plane.velocity_profile(sim.snapshot(), THICKNESS)
            profiles.append(u)
    u = np.mean(profiles, axis=0)
    exact = inclined_plane.bagnold_velocity(z, THICKNESS, slope, G, MU_S, MU_2, I0, GRAIN)
    return float(np.sqrt(((u - exact) ** 2).sum() / (exact ** 2).sum()))


def test_the_steady_flow_converges_to_the_bagnold_profile():
    coarse, fine = _steady_error(8), _steady_error(16)
    print(f"relative L2 error of the steady profile: {coarse:.4f} (8 cells), {fine:.4f} (16 cells)")
    assert coarse < 0.09
    assert fine < 0.045
    assert fine < 0.6 * coarse


def test_below_the_static_friction_the_layer_stays_at_rest():
    sim = layer(18.0, 8)
    scale = math.sqrt(G * THICKNESS)
    for t in (10.0, 20.0):
        sim.run(t * TAU)
        z, u = inclined_plane.velocity_profile(sim.snapshot(), THICKNESS)
        print(f"{t:g} tau: rows below the top at most {np.abs(u[:-1]).max() / scale:.2e} sqrt(g h), "
              f"top row {abs(u[-1]) / scale:.2e} sqrt(g h)")
        assert np.abs(u[:-1]).max() < 2.0e-3 * scale
        assert abs(u[-1]) < 2.0e-2 * scale


def test_above_mu_2_the_layer_accelerates_at_least_at_the_friction_bound():
    slope = math.radians(35.0)
    sim = layer(35.0, 8)
    means = []
    for t in (10.0, 20.0):
        sim.run(t * TAU)
        means.append(inclined_plane.velocity_profile(sim.snapshot(), THICKNESS)[1].mean())
    acceleration = (means[1] - means[0]) / (10.0 * TAU)
    print(f"mean acceleration over [10, 20] tau {acceleration:.3f} m/s^2, "
          f"bound {G * (math.sin(slope) - MU_2 * math.cos(slope)):.3f} m/s^2")
    assert acceleration > G * (math.sin(slope) - MU_2 * math.cos(slope))
