"""The hand-off budget: where the mesh's mass, momentum and kinetic energy went.

All vectors are in the output 3D Cartesian frame.  For a 2d-cylindrical mesh (axis z) the
mesh momentum is (0, 0, P_z): the radial momenta of an axisymmetric flow cancel as vectors.
What the hand-off conserves there is the axial momentum P_z and the scalar radial momentum

    P_r = sum_cells m_c v_r,c        (kg m/s),

which the particles carry as sum_i m_i (v_i . e_r,i), e_r,i the unit vector from the axis
to particle i; the vector sum of the particles' radial momenta is zero.

Conservation statements (before the velocity noise, to round-off):

    particle_mass + dropped_mass = mesh_mass
    particle_momentum + dropped_momentum = mesh_momentum
    particle_radial_momentum + dropped_radial_momentum + intact_radial_momentum
        = mesh_radial_momentum                                                 (2d-cylindrical)

(intact_radial_momentum: that of the intact fragments made single spheres on the axis,
handoff/bodies.py; 0 without them).

Kinetic energy is not conserved: a particle moves with its block's mean velocity (of the
merged block, when finer leaves were merged first), so the energy of the velocity
dispersion inside each block (``unresolved_kinetic_energy`` >= 0) is
not carried.  The velocity noise then adds ``noise_momentum`` and ``noise_kinetic_energy``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

BUDGET_UNITS = {
    "n_blocks": "dimensionless",
    "n_particles": "dimensionless",
    "total_mass": "kg",
    "mesh_mass": "kg",
    "mesh_momentum": "kg*m/s",
    "mesh_kinetic_energy": "J",
    "mesh_radial_momentum": "kg*m/s",
    "particle_mass": "kg",
    "particle_momentum": "kg*m/s",
    "particle_momentum_with_noise": "kg*m/s",
    "particle_kinetic_energy": "J",
    "particle_kinetic_energy_with_noise": "J",
    "particle_radial_momentum": "kg*m/s",
    "dropped_mass": "kg",
    "dropped_momentum": "kg*m/s",
    "dropped_kinetic_energy": "J",
    "dropped_radial_momentum": "kg*m/s",
    "dropped_count": "dimensionless",
    "radius_shrunk_count": "dimensionless",
    "overlapping_pairs": "dimensionless",
    "deepest_overlap": "dimensionless",
    "tracers_total": "dimensionless",
    "tracers_used": "dimensionless",
    "tracers_exited": "dimensionless",
    "tracers_outside": "dimensionless",
    "tracers_in_dropped": "dimensionless",
    "mass_left_mesh": "kg",
    "density_floor": "kg/m**3",
    "mass_floor": "kg",
    "noise_speed": "m/s",
    "seed": "dimensionless",
    "block_edge": "m",
    "sphere_blocks": "dimensionless",
    "intact_bodies": "dimensionless",
    "intact_mass": "kg",
    "intact_radial_momentum": "kg*m/s",
    "intact_rings_left": "dimensionless",
    "intact_internal_kinetic_energy": "J",
}


@dataclass
class HandoffBudget:
    """Mass, momentum, kinetic energy and tracer accounting of one hand-off (SI units).

    Attributes:
        geometry: geometry of the source mesh ("3d" or "2d-cylindrical").
        n_blocks: leaf blocks in the snapshot.
        n_particles: particles made.
        total_mass: M_tot the mass floor refers to (kg).
        mesh_mass: mass on the mesh at hand-off, sum_cells sum_k alpha_k rho_k V_c (kg).
        mesh_momentum: (3,) sum_cells m_c v_c in the output frame (kg m/s).
        mesh_kinetic_energy: sum_cells m_c |v_c|^2 / 2 (J).
        mesh_radial_momentum: sum_cells m_c v_r,c (kg m/s); None for 3d.
        particle_mass: sum_i m_i (kg).
        particle_momentum: (3,) sum_i m_i v_i before the noise (kg m/s).
        particle_momentum_with_noise: (3,) the same with the noise (kg m/s).
        particle_kinetic_energy: sum_i m_i |v_i|^2 / 2 before the noise (J).
        particle_kinetic_energy_with_noise: the same with the noise (J).
        particle_radial_momentum: sum_i m_i (v_i . e_r,i) before the noise (kg m/s); None for 3d.
        dropped_mass: mass of the non-empty blocks below the mass floor (kg).
        dropped_momentum: (3,) their momentum (kg m/s).
        dropped_kinetic_energy: their kinetic energy, cell by cell (J).
        dropped_radial_momentum: their radial momentum (kg m/s); None for 3d.
        dropped_count: number of non-empty blocks dropped.
        radius_shrunk_count: particles whose radius the density floor reduced.
        overlapping_pairs: particle pairs whose spheres overlap at hand-off
            (|x_i - x_j| < r_i + r_j; inscribed spheres of adjacent full blocks only touch).
        deepest_overlap: largest 1 - |x_i - x_j| / (r_i + r_j) over those pairs, 0 if none.
        tracers_total: tracers in the tracer set.
        tracers_used: tracers in blocks that made particles.
        tracers_exited: tracers flagged exited (they belong to no block).
        tracers_outside: tracers not flagged exited that lie in no leaf block.
        tracers_in_dropped: tracers in dropped or empty blocks.
        mass_left_mesh: mass that left the mesh before hand-off, as the hydro stage
            reports it (kg); None when not given.
        density_floor: min_density_fraction x target bulk density (kg/m^3).
        mass_floor: min_mass_fraction x total_mass (kg).
        noise_speed: magnitude of each particle's velocity noise (m/s).
        seed: seed of the random generator (ring phases, then noise).
        mirrored_y0: True when the snapshot was a half-domain 3d run mirrored across y = 0
            (handoff/mirror.py): every mesh, particle and dropped number then counts the full
            body, both halves (mesh_mass = 2 x the half-domain run's mass on its mesh).
        block_edge: the smallest block edge the spheres were made from (m) when finer leaf
            blocks were merged first (``handoff.particle_resolution``); None otherwise.
        sphere_blocks: blocks the spheres were made from (n_blocks unless merged); None in
            files written before it was recorded.
        intact_bodies: intact fragments made single spheres (handoff/bodies.py); they count
            among n_particles and in every particle sum.
        intact_mass: their mass (kg).
        intact_radial_momentum: 2d-cylindrical, their scalar radial momentum, which the
            spheres on the axis do not carry (kg m/s); None for 3d.
        intact_rings_left: 2d-cylindrical fragments off the axis, left to their blocks.
        intact_internal_kinetic_energy: the kinetic energy of the motion inside those fragments
            (J), part of ``unresolved_kinetic_energy``: large against the fragments' binding
            energy, it says they were not moving as rigid bodies.
    """

    geometry: str
    n_blocks: int
    n_particles: int
    total_mass: float
    mesh_mass: float
    mesh_momentum: np.ndarray
    mesh_kinetic_energy: float
    mesh_radial_momentum: float | None
    particle_mass: float
    particle_momentum: np.ndarray
    particle_momentum_with_noise: np.ndarray
    particle_kinetic_energy: float
    particle_kinetic_energy_with_noise: float
    particle_radial_momentum: float | None
    dropped_mass: float
    dropped_momentum: np.ndarray
    dropped_kinetic_energy: float
    dropped_radial_momentum: float | None
    dropped_count: int
    radius_shrunk_count: int
    overlapping_pairs: int
    deepest_overlap: float
    tracers_total: int
    tracers_used: int
    tracers_exited: int
    tracers_outside: int
    tracers_in_dropped: int
    mass_left_mesh: float | None
    density_floor: float
    mass_floor: float
    noise_speed: float
    seed: int
    mirrored_y0: bool = False
    block_edge: float | None = None
    sphere_blocks: int | None = None
    intact_bodies: int = 0
    intact_mass: float = 0.0
    intact_radial_momentum: float | None = None
    intact_rings_left: int = 0
    intact_internal_kinetic_energy: float = 0.0

    @property
    def noise_momentum(self) -> np.ndarray:
        """(3,) momentum the velocity noise added (kg m/s)."""
        return self.particle_momentum_with_noise - self.particle_momentum

    @property
    def noise_kinetic_energy(self) -> float:
        """Kinetic energy the velocity noise added (J); can be negative for single particles."""
        return self.particle_kinetic_energy_with_noise - self.particle_kinetic_energy

    @property
    def unresolved_kinetic_energy(self) -> float:
        """Kinetic energy of the velocity dispersion inside the particle-making blocks (J).

        mesh KE - dropped KE - particle KE (before noise); >= 0 up to round-off.
        """
        return self.mesh_kinetic_energy - self.dropped_kinetic_energy - self.particle_kinetic_energy

    @property
    def mass_residual(self) -> float:
        """particle_mass + dropped_mass - mesh_mass (kg): zero up to round-off."""
        return self.particle_mass + self.dropped_mass - self.mesh_mass

    def to_summary(self) -> dict:
        """Plain-Python dict for summary.json: floats, ints, lists of 3 floats, None, str."""
        out: dict = {}
        for f in fields(self):
            out[f.name] = _plain(getattr(self, f.name))
        for name in ("noise_momentum", "noise_kinetic_energy", "unresolved_kinetic_energy", "mass_residual"):
            out[name] = _plain(getattr(self, name))
        return out


def _plain(value):
    """A budget value as a JSON-ready Python object."""
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)):
        return int(value)
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return float(arr)
    return [float(x) for x in arr]
