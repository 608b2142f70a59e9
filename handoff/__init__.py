"""Hand-off: hydro leaf blocks and tracers to N-body spheres (docs/handoff.md)."""

from impactpipe.handoff.budget import HandoffBudget
from impactpipe.handoff.particles import ParticleSet
from impactpipe.handoff.spheres import blocks_to_spheres
from impactpipe.handoff.store import read_budget, read_particles, write_particles

__all__ = ["HandoffBudget", "ParticleSet", "blocks_to_spheres", "read_budget", "read_particles", "write_particles"]
