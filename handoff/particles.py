"""The particle table the hand-off produces and the N-body stage consumes."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

PARTICLE_UNITS = {
    "id": "dimensionless",
    "mass": "kg",
    "radius": "m",
    "position": "m",
    "velocity": "m/s",
    "tracer_count": "dimensionless",
    "peak_pressure_mean": "Pa",
    "peak_pressure_max": "Pa",
    "origin_position": "m",
    "projectile_fraction": "dimensionless",
    "distension": "dimensionless",
    "source_level": "dimensionless",
    "source_block": "dimensionless",
}


@dataclass
class ParticleSet:
    """N spherical particles in a 3D Cartesian frame (SI units).

    For a hand-off from 2d-cylindrical the symmetry axis is z and (x, y) come from
    rotating r about it.  ``origin_position`` is in the hydro mesh coordinates.

    Attributes:
        id: (N,) int64 unique ids >= 1.
        mass: (N,) kg.
        radius: (N,) m.
        position: (N, 3) m.
        velocity: (N, 3) m/s.
        tracer_count: (N,) tracers that sat in the source block at hand-off.
        peak_pressure_mean: (N,) mean tracer peak pressure (Pa); for particles without
            tracers, the mean of the 2 nearest particles that have tracers.
        peak_pressure_max: (N,) largest tracer peak pressure (Pa), NaN without tracers.
        origin_position: (N, 3) mass-weighted pre-impact position of the material (m).
        projectile_fraction: (N,) projectile mass fraction.
        distension: (N,) mass-weighted distension rho_solid / rho of the particle's material at
            hand-off (1: non-porous; docs/eos.md, "Porosity"; handoff/moments.py); NaN when read
            from a hand-off file written before it was recorded.
        source_level: (N,) refinement level of the source block.
        source_block: (N,) id of the source block.
    """

    id: np.ndarray
    mass: np.ndarray
    radius: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    tracer_count: np.ndarray
    peak_pressure_mean: np.ndarray
    peak_pressure_max: np.ndarray
    origin_position: np.ndarray
    projectile_fraction: np.ndarray
    distension: np.ndarray
    source_level: np.ndarray
    source_block: np.ndarray

    def __len__(self) -> int:
        return int(self.id.shape[0])

    @classmethod
    def from_bodies(cls, mass, radius, position, velocity) -> "ParticleSet":
        """A particle set from masses, radii, positions and velocities alone (synthetic sets, tests)."""
        mass = np.asarray(mass, dtype=float)
        n = mass.shape[0]
        return cls(
            id=np.arange(1, n + 1, dtype=np.int64),
            mass=mass,
            radius=np.asarray(radius, dtype=float),
            position=np.asarray(position, dtype=float).reshape(n, 3),
            velocity=np.asarray(velocity, dtype=float).reshape(n, 3),
            tracer_count=np.zeros(n, dtype=np.int64),
            peak_pressure_mean=np.full(n, np.nan),
            peak_pressure_max=np.full(n, np.nan),
            origin_position=np.full((n, 3), np.nan),
            projectile_fraction=np.zeros(n),
            distension=np.ones(n),
            source_level=np.zeros(n, dtype=np.int64),
            source_block=np.full(n, -1, dtype=np.int64),
        )

    def select(self, mask: np.ndarray) -> "ParticleSet":
        """The particles where ``mask`` (boolean or index array) selects."""
        return ParticleSet(**{f.name: getattr(self, f.name)[mask] for f in fields(self)})
