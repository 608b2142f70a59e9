"""REBOUND reaccumulation of hand-off particles with merge, conditional-merge and bounce models."""

from .diagnostics import bound_mask, conserved_quantities, remnant_and_orbiting
from .driver import ArchiveMismatch, reaccumulate
from .resolver import COLLISION_MODELS, CollisionResolver
from .result import NBodyResult, read_result, write_result
from .simulation import G, collision_time_step, dynamical_time

__all__ = [
    "ArchiveMismatch",
    "COLLISION_MODELS",
    "CollisionResolver",
    "G",
    "NBodyResult",
    "bound_mask",
    "collision_time_step",
    "conserved_quantities",
    "dynamical_time",
    "reaccumulate",
    "read_result",
    "remnant_and_orbiting",
    "write_result",
]
