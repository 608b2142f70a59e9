"""The N-body stage's result, ``nbody.h5``: final particles, provenance, escapes, diagnostics."""

from __future__ import annotations

import os
from dataclasses import dataclass, field, fields

import h5py
import numpy as np

from impactpipe.storage import atomic_path, write_dataset

NO_PARTICLES_LEFT = "no_particles_left"  # every particle was removed, or the hand-off had none
STABLE_ORBITS = "stable_orbits"  # nothing merged, escaped or stopped orbiting for max_quiet_dynamical_times
STATUSES = ("equilibrium", STABLE_ORBITS, "time_cap", "wall_cap", NO_PARTICLES_LEFT)
# a resumed run does not continue past these (it does past stable_orbits, time_cap and
# wall_cap: with other stop settings it goes on, with the same it stops at the next output)
TERMINAL_STATUSES = ("equilibrium", NO_PARTICLES_LEFT)
# escaped_reason codes
ESCAPE_ORBIT = 1   # beyond half the box half-width on an escape orbit, moving away
LEFT_BOX = 2       # still bound but about to leave the box (beyond 0.9 of its half-width)
LOST = 3           # removed by REBOUND's open boundary inside a chunk (state from the chunk start)
ESCAPE_REASONS = {ESCAPE_ORBIT: "escape_orbit", LEFT_BOX: "left_box", LOST: "lost"}

PARTICLE_FIELD_UNITS = {
    "id": "dimensionless",
    "mass": "kg",
    "radius": "m",
    "position": "m",
    "velocity": "m/s",
    "spin": "kg*m**2/s",
    "members_offset": "dimensionless",
    "members": "dimensionless",
    "escaped_id": "dimensionless",
    "escaped_mass": "kg",
    "escaped_momentum": "kg*m/s",
    "escaped_position": "m",
    "escaped_velocity": "m/s",
    "escaped_spin": "kg*m**2/s",
    "escaped_time": "s",
    "escaped_reason": "dimensionless",
    "escaped_members_offset": "dimensionless",
    "escaped_members": "dimensionless",
    "merge_time": "s",
    "merge_survivor": "dimensionless",
    "merge_absorbed": "dimensionless",
}

DIAGNOSTIC_UNITS = {
    "time": "s",
    "n_particles": "dimensionless",
    "energy_kinetic": "J",
    "energy_potential": "J",
    "energy_spin": "J",
    "energy": "J",
    "momentum": "kg*m/s",
    "angular_momentum": "kg*m**2/s",
    "spin_angular_momentum": "kg*m**2/s",
    "escaped_mass": "kg",
    "escaped_momentum": "kg*m/s",
    "escaped_angular_momentum": "kg*m**2/s",
    "escaped_energy": "J",
    "n_merge": "dimensionless",
    "n_bounce": "dimensionless",
    "largest_mass": "kg",
    "remnant_mass": "kg",
    "orbiting_mass": "kg",
    "time_step": "s",
    "collision_kinetic_energy_change": "J",
    "overlapping_pairs": "dimensionless",
    "max_overlap": "dimensionless",
    "n_overlap_push": "dimensionless",
    "overlap_push_energy": "J",
    "handoff_overlaps_open": "dimensionless",
}

DIAGNOSTIC_DESCRIPTIONS = {
    "energy": "kinetic + potential (direct sum) + spin energy of the particles in the simulation",
    "momentum": "total momentum of the particles in the simulation",
    "angular_momentum": "orbital (about the origin) + spin angular momentum of the particles in the simulation",
    "escaped_mass": "cumulative mass removed (escaped, left the box or lost)",
    "escaped_momentum": "cumulative momentum carried by removed particles; momentum + escaped_momentum is conserved",
    "escaped_angular_momentum": "cumulative angular momentum (about the origin, incl. spin) of removed particles",
    "escaped_energy": "cumulative energy removed particles took out of energy at their removal (kinetic, spin and "
                      "their potential energy with the rest); energy + escaped_energy - overlap_push_energy changes "
                      "only by collision losses and the integrator's error",
    "n_merge": "cumulative mergers",
    "n_bounce": "cumulative bounces",
    "largest_mass": "mass of the most massive particle",
    "remnant_mass": "mass of the contact group of the most massive particle (M_lr)",
    "orbiting_mass": "mass outside the largest remnant bound to it",
    "collision_kinetic_energy_change": "cumulative change of the translational kinetic energy made by the "
                                       "collision resolver (bounces, pushes paid from kinetic energy, mergers)",
    "n_overlap_push": "cumulative bounces of pairs overlapping since before the step, pushed apart",
    "overlap_push_energy": "cumulative potential energy that pushes added beyond what the pushed pairs' kinetic "
                           "energy paid: overlaps that arose during the run (resting contacts) pushed to contact, "
                           "pairs overlapping since t = 0 pushed back to their distance at t = 0",
    "handoff_overlaps_open": "pairs overlapping at t = 0 that have not yet been separated to contact",
    "overlapping_pairs": "pairs with |x_i - x_j| < r_i + r_j",
    "max_overlap": "largest 1 - |x_i - x_j| / (r_i + r_j) over the overlapping pairs (0 if none)",
}


@dataclass
class NBodyResult:
    """Final state of a reaccumulation run (SI units; frame of the hand-off particles).

    Attributes:
        id: (N,) hand-off id of each final particle's surviving representative.
        mass, radius: (N,) kg, m.  position, velocity: (N, 3) m, m/s.
        spin: (N, 3) spin angular momentum (kg m^2/s), including the orbital angular
            momentum of every pair merged into the particle about their centre of mass.
        members_offset, members: CSR provenance: the hand-off ids contained in final
            particle k are ``members[members_offset[k]:members_offset[k + 1]]``.
        escaped_*: particles removed from the simulation (id, mass, momentum, position,
            velocity, spin at removal, time, reason code in ``ESCAPE_REASONS``) and their
            members (CSR).  Final and escaped members together partition the hand-off ids.
        merge_time, merge_survivor, merge_absorbed: every merger (s, surviving id, absorbed id).
        diagnostics: time series, keys and units in ``DIAGNOSTIC_UNITS``.
        status: one of ``STATUSES``: 'equilibrium', 'stable_orbits' (mass keeps orbiting the
            largest remnant, but the particle count and the orbiting mass have not changed for
            ``max_quiet_dynamical_times``: a satellite in a stable orbit), 'time_cap',
            'wall_cap' or 'no_particles_left' (every particle was removed: no final particles,
            M_lr = 0; also for an empty hand-off, with time 0 and no diagnostics).
        time: simulated time reached (s).
        dynamical_time: 1 / sqrt(G rho_bulk) (s).  time_step: final leapfrog step (s).
        collision_model: 'merge', 'conditional_merge' or 'bounce'.
        initial_overlapping_pairs: hand-off particle pairs overlapping at t = 0.
        initial_overlap_energy: J, sum over them of G m_i m_j (1/d_ij - 1/(r_i + r_j)): the
            potential energy their separation costs, which the collision resolution can add
            in a cold start (docs/nbody.md).
        initial_unbound_mass: kg of hand-off mass on escape orbits at t = 0 (two-body energy
            relative to all the other mass >= 0, ``diagnostics.unbound_mass``); NaN in files
            written before it existed.
        initial_near_escape_mass: kg of hand-off mass moving at 0.6 to 1 times its escape speed
            from all the other mass at t = 0 (``diagnostics.escape_speed_ratio``): bound particle
            by particle, but the reaccumulation decides which of it escapes; NaN in files
            written before it existed.
        steps: leapfrog steps done (REBOUND ``steps_done``), over all resumes.
        particle_steps: sum over the steps of the particles each step integrated, over all
            resumes; -1 when the run resumed from a checkpoint written before this counter
            existed (the count is then unknown).
    """

    id: np.ndarray
    mass: np.ndarray
    radius: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    spin: np.ndarray
    members_offset: np.ndarray
    members: np.ndarray
    escaped_id: np.ndarray
    escaped_mass: np.ndarray
    escaped_momentum: np.ndarray
    escaped_position: np.ndarray
    escaped_velocity: np.ndarray
    escaped_spin: np.ndarray
    escaped_time: np.ndarray
    escaped_reason: np.ndarray
    escaped_members_offset: np.ndarray
    escaped_members: np.ndarray
    merge_time: np.ndarray
    merge_survivor: np.ndarray
    merge_absorbed: np.ndarray
    diagnostics: dict[str, np.ndarray] = field(default_factory=dict)
    status: str = "time_cap"
    time: float = 0.0
    dynamical_time: float = 0.0
    time_step: float = 0.0
    collision_model: str = "merge"
    initial_overlapping_pairs: int = 0
    initial_overlap_energy: float = 0.0
    initial_unbound_mass: float = 0.0
    initial_near_escape_mass: float = 0.0
    steps: int = 0
    particle_steps: int = 0

    def __len__(self) -> int:
        return int(self.id.shape[0])

    def members_of(self, k: int) -> np.ndarray:
        """Hand-off ids contained in final particle k."""
        return self.members[self.members_offset[k]:self.members_offset[k + 1]]


_SCALARS = ("status", "time", "dynamical_time", "time_step", "collision_model", "initial_overlapping_pairs",
            "initial_overlap_energy", "initial_unbound_mass", "initial_near_escape_mass", "steps", "particle_steps")
# attributes that files written before they existed lack, and the value read for them then
_LATER_SCALARS = {"initial_overlapping_pairs": -1, "initial_overlap_energy": float("nan"),
                  "initial_unbound_mass": float("nan"), "initial_near_escape_mass": float("nan"), "steps": -1,
                  "particle_steps": -1}


def write_result(path: str | os.PathLike, result: NBodyResult, attrs: dict) -> None:
    """Write ``result`` to HDF5 at ``path`` atomically; ``attrs`` become root attributes."""
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as f:
            for key, value in attrs.items():
                f.attrs[key] = value
            for name in _SCALARS:
                f.attrs[name] = getattr(result, name)
            for fl in fields(result):
                if fl.name in PARTICLE_FIELD_UNITS:
                    desc = "1 escape_orbit, 2 left_box, 3 lost" if fl.name == "escaped_reason" else None
                    write_dataset(f, fl.name, getattr(result, fl.name), PARTICLE_FIELD_UNITS[fl.name], desc)
            grp = f.create_group("diagnostics")
            for name, values in result.diagnostics.items():
                write_dataset(grp, name, values, DIAGNOSTIC_UNITS[name], DIAGNOSTIC_DESCRIPTIONS.get(name))


def read_result(path: str | os.PathLike) -> NBodyResult:
    """Read an ``NBodyResult`` written by :func:`write_result`.

    Example, on the quickstart's run directory (:func:`impactpipe.pipeline.run`)::

        >>> from impactpipe.nbody import read_result
        >>> result = read_result("runs/quickstart/nbody.h5")
        >>> result.status
        'equilibrium'
        >>> len(result.members_offset) == len(result) + 1
        True
    """
    with h5py.File(path, "r") as f:
        arrays = {name: f[name][()] for name in PARTICLE_FIELD_UNITS}
        diagnostics = {name: f["diagnostics"][name][()] for name in f["diagnostics"]}
        scalars = {name: f.attrs[name] for name in _SCALARS if name in f.attrs or name not in _LATER_SCALARS}
        for name, missing in _LATER_SCALARS.items():
            scalars.setdefault(name, missing)
    for name in ("status", "collision_model"):
        value = scalars[name]
        scalars[name] = value.decode() if isinstance(value, bytes) else str(value)
    for name in ("initial_overlapping_pairs", "steps", "particle_steps"):
        scalars[name] = int(scalars[name])
    for name in ("time", "dynamical_time", "time_step", "initial_overlap_energy", "initial_unbound_mass",
                 "initial_near_escape_mass"):
        scalars[name] = float(scalars[name])
    return NBodyResult(**arrays, diagnostics=diagnostics, **scalars)
