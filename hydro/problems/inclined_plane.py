"""A granular layer on a rough plane inclined at ``slope`` theta (2d-planar): the verification scene
of the GEO strength's mu(I) friction against the steady uniform (Bagnold) flow.

Mesh axis 0 (x) runs down the slope and is periodic, axis 1 (z) is normal to the plane: the
layer of ``thickness`` h (m) fills 0 <= z < h on the rough floor z = 0
(:meth:`~impactpipe.hydro.strength.model.MaterialStrength.set_rough_wall`: no-slip for the
stress, its ghost cells mirror the velocity with the sign flipped, so it is zero on the floor),
void above it up to an outflow face.  The tilt is in the gravity vector,
g = |g| (sin theta, -cos theta, 0) (m/s^2).  The layer starts at rest at the pressure
p = rho0 |g| cos theta (h - z) (Pa) of the cell centre, put in as the density at which the
material's reference curve gives that pressure at e = 0 (:func:`cold_density`; no deviatoric
stress); it is then loaded by the slope's shear.

The exact solution (GDR MiDi 2004, Eur. Phys. J. E 14, 341; Jop, Forterre & Pouliquen 2005,
J. Fluid Mech. 541, 167): in a steady flow uniform along x the momentum balance across the layer
gives the shear stress tau = rho |g| sin theta (h - z) and the pressure
P = rho |g| cos theta (h - z), so tau / P = tan theta at every depth.  The GEO strength with the
mu(I) friction (cohesionless, Y_M large: sqrt(J2) <= mu(I) P, and sqrt(J2) = |tau| in simple
shear) flows where mu(I) = tan theta, at the uniform inertial number

    I_theta = I0 (tan theta - mu_s) / (mu_2 - tan theta)          (mu_s < tan theta < mu_2)

(:func:`slope_inertial_number`).  With the code's I = gamma_dot d / sqrt(P / rho_s)
(:func:`impactpipe.hydro.strength.yield_strength.inertial_friction`: rho_s the material's
density, gamma_dot = sqrt(2 D_dev:D_dev) = du/dz in simple shear u(z)) the shear rate is
du/dz = (I_theta / d) sqrt(|g| cos theta (h - z)), which integrates from u(0) = 0 to the
Bagnold profile (:func:`bagnold_velocity`)

    u(z) = (2 I_theta / (3 d)) sqrt(|g| cos theta) [h^(3/2) - (h - z)^(3/2)]      (m/s).

Below the static friction (tan theta <= mu_s) the layer stays at rest; above mu_2 no inertial
number balances the slope and the layer accelerates without bound, its mean acceleration at
least |g| (sin theta - mu_2 cos theta) (the floor's friction is below mu_2 P).

Scheme: as the granular column collapse's (:mod:`impactpipe.hydro.problems.column_collapse`),
the sweeps' bulk-modulus pressure predictor, the tensile limit at the end of the step and the
surface-layer pressure, here of the normal component of gravity (a partly filled cell's yield
strength is taken at no less than rho |g| cos theta phi dx / 2, the pressure at mid-depth of a
layer parallel to the plane), with ``hourglass`` viscosity or the ``face_shear`` stress against
the odd-even velocity modes as asked (neither by default; without either an odd-even velocity
mode across the layer grows unresisted).  The flow is uniform along x; the layer's free surface
stays within its top row of cells.

Not a config scene (it is not in :data:`impactpipe.hydro.problems.PROBLEMS`): tests and
benchmarks build it from a material spec (:func:`granular_material`).
"""

from __future__ import annotations

import math

import numpy as np

from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.gravity import ExternalGravity
from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.problems.column_collapse import impedance, shear_modulus
from impactpipe.hydro.solver import Simulation

#: Mesh axis normal to the plane (gravity's normal component points along -z).
NORMAL_AXIS = 1

#: Cells per block edge: the mesh is one block along the slope.
BLOCK_CELLS = 4


def slope_inertial_number(slope: float, mu_s: float, mu_2: float, i0: float) -> float:
    """The inertial number I_theta (-) at which mu(I) = tan(``slope``) (rad), for mu_s < tan theta < mu_2:
    I0 (tan theta - mu_s) / (mu_2 - tan theta).  Raises ValueError outside that range (no steady flow)."""
    t = math.tan(slope)
    if not mu_s < t < mu_2:
        raise ValueError(f"tan(slope) = {t:g} is outside (mu_s, mu_2) = ({mu_s:g}, {mu_2:g}): no steady flow")
    return i0 * (t - mu_s) / (mu_2 - t)


def bagnold_velocity(z, thickness: float, slope: float, gravity: float, mu_s: float, mu_2: float, i0: float,
                     grain_diameter: float):
    """The steady velocity u(z) (m/s) down the slope at height z (m) above the floor of a layer of
    ``thickness`` h (m) on a plane inclined at ``slope`` theta (rad) in gravity |g| (m/s^2) (module
    docstring): (2 I_theta / (3 d)) sqrt(|g| cos theta) [h^(3/2) - (h - z)^(3/2)], d the grain
    diameter (m)."""
    inertial = slope_inertial_number(slope, mu_s, mu_2, i0)
    depth = np.clip(thickness - np.asarray(z, dtype=float), 0.0, None)
    return (2.0 * inertial / (3.0 * grain_diameter) * math.sqrt(gravity * math.cos(slope))
            * (thickness ** 1.5 - depth ** 1.5))


def granular_material(sound_speed: float, mu_s: float, mu_2: float, i0: float, grain_diameter: float,
                      density: float = 2500.0, poisson: float = 0.3) -> dict:
    """A cohesionless granular material with the mu(I) friction (resolved spec, SI units).

    EOS: Mie-Grueneisen with s = 1 and Gamma0 = 1e-6, P = rho0 c^2 mu (1 + mu), mu = rho / rho0 - 1:
    an elastic solid of bulk modulus K = rho0 c^2 (``sound_speed`` c, m/s; ``density`` rho0, kg/m^3)
    whose pressure hardly depends on the heat the flow dissipates.  Strength: GEO, Y0 = 0, no
    tension, Y_M = 1e30 Pa and T_melt = 1e30 K (neither the cap nor the thermal softening acts), so
    sqrt(J2) <= mu(I) P with mu_s = ``mu_s``, ``mu_2``, ``i0`` and ``grain_diameter`` d (m).
    """
    return {"eos": {"model": "mie_gruneisen", "rho0": density, "c0": sound_speed, "s": 1.0, "gamma0": 1.0e-6,
                    "cv": 1000.0},
            "strength": {"model": "geo", "Y0": 0.0, "Y_M": 1.0e30, "Y_T": 0.0, "mu_i": mu_s, "poisson": poisson,
                         "T_melt": 1.0e30, "xi": 1.2, "mu_2": mu_2, "inertial_number_I0": i0,
                         "grain_diameter": grain_diameter}}


def cold_density(spec: dict, pressure):
    """Density (kg/m^3) at which the Mie-Grueneisen s = 1 ``spec``'s reference curve
    P_H = rho0 c^2 mu (1 + mu) gives ``pressure`` (Pa), mu = rho / rho0 - 1: the root
    mu = (sqrt(1 + 4 P / (rho0 c^2)) - 1) / 2.  At e = 0 the pressure differs from P_H by
    rho0 Gamma0 e_H, a fraction Gamma0 mu / 2 of it."""
    stiffness = spec["rho0"] * spec["c0"] ** 2
    mu = 0.5 * (np.sqrt(1.0 + 4.0 * np.asarray(pressure, dtype=float) / stiffness) - 1.0)
    return spec["rho0"] * (1.0 + mu)


def setup(material: dict, slope: float, thickness: float, cells: int, gravity: float = 9.81, cfl: float = 0.4,
          hourglass: float = 0.0, face_shear: bool = False) -> Simulation:
    """The layer (module docstring) of ``material`` (:func:`granular_material`) on the plane inclined at
    ``slope`` (rad), ``cells`` cells across its ``thickness`` (m; a multiple of :data:`BLOCK_CELLS`),
    in gravity |g| = ``gravity`` (m/s^2).  ``hourglass``: the hourglass viscosity coefficient C
    (:mod:`impactpipe.hydro.strength.hourglass`), 0 for none; ``face_shear``: the face shear stress
    (:mod:`impactpipe.hydro.strength.face_shear`)."""
    if cells % BLOCK_CELLS:
        raise ValueError(f"cells: {cells} must be a multiple of {BLOCK_CELLS}")
    dx = thickness / cells
    nz = cells + BLOCK_CELLS
    mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [BLOCK_CELLS * dx, nz * dx], [BLOCK_CELLS, nz],
                             [("periodic", "periodic"), ("reflecting", "outflow")], BLOCK_CELLS)
    spec = material["eos"]
    eos = pack_eos([spec])
    z = mesh.cell_centers()[:, 1]
    inside = z < thickness
    pressure = spec["rho0"] * gravity * math.cos(slope) * np.where(inside, thickness - z, 0.0)
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, inside.astype(float), 0, eos, cold_density(spec, pressure), np.zeros(3),
                       specific_energy=0.0)
    g = [gravity * math.sin(slope), -gravity * math.cos(slope), 0.0]
    sim = Simulation(mesh, ["granular"], [spec], state, cfl=cfl, tensile_strength=[0.0],
                     strength=[material["strength"]], gravity=ExternalGravity(g, mesh))
    sim.bulk_pressure_predictor = True
    sim.step_tensile_limit = True
    sim.strength.set_rough_wall(NORMAL_AXIS, 0)
    sim.strength.set_surface_layer_pressure([0.0, -gravity * math.cos(slope), 0.0])
    if hourglass > 0.0:
        sim.strength.set_hourglass_viscosity(hourglass, impedance(eos, sim.shear_modulus[0]))
    if face_shear:
        sim.strength.set_face_shear(shear_modulus(eos, sim.shear_modulus[0]))
    return sim


def velocity_profile(snapshot, thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """The heights z (m) of the cell rows inside the layer (z < ``thickness``) and their velocity
    u (m/s) down the slope, the mean over the cells of each row of a ``snapshot`` of this scene."""
    z = snapshot.centers[:, 1].reshape(-1)
    u = snapshot.velocity[:, 0].reshape(-1)
    rows = np.unique(z[z < thickness])
    return rows, np.array([u[z == row].mean() for row in rows])
