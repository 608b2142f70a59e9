"""The N-body stage\'s adapter: reaccumulate the hand-off particles, write nbody.h5.

The REBOUND Simulationarchive ``nbody.bin`` is the checkpoint: an interrupted stage
resumes from its last snapshot when the particles and settings are unchanged, and starts
over (replacing it) when they changed.  The summary's ``stages.nbody`` records the cost
counters ``steps`` and ``particle_steps`` (see :func:`impactpipe.nbody.driver.reaccumulate`).
"""

from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np

from impactpipe.handoff.store import read_particles
from impactpipe import storage
from impactpipe.nbody.driver import ArchiveMismatch, reaccumulate
from impactpipe.nbody.result import LEFT_BOX, LOST, NO_PARTICLES_LEFT, write_result

from ..stages import StageContext


log = logging.getLogger(__name__)

ARCHIVE_FILE = "nbody.bin"
#: Fraction of the hand-off mass removed as left_box above which the stage warns.
LEFT_BOX_WARNING = 1.0e-3


def run_nbody_stage(ctx: StageContext) -> dict[str, Any]:
    """Reaccumulate the particles of ``handoff.h5``; returns the summary entries."""
    started = storage.utc_now()
    t0 = time.perf_counter()
    config = ctx.config
    values = ctx.values
    particles = read_particles(ctx.path("handoff"))
    nbody = config.nbody
    progress = ctx.progress("nbody", values["nbody_time_cap"])

    def on_progress(t: float) -> None:
        """After every chunk: progress, and a requested stop (the resume starts from the last archive
        snapshot, which an uninterrupted run also passes through)."""
        progress(t)
        if ctx.stop_requested() is not None:
            log.info("nbody: stopped by %s at t = %.6g s; resuming starts from the last archive snapshot",
                     ctx.stop_requested(), t)
            raise ctx.interrupted()

    settings = dict(
        bulk_density=values["target_reference_density"],
        collision_model=nbody.collision_model,
        restitution_normal=nbody.restitution.normal,
        restitution_tangential=nbody.restitution.tangential,
        opening_angle=nbody.opening_angle,
        min_dynamical_times=nbody.stop.min_dynamical_times,
        max_orbiting_fraction=nbody.stop.max_orbiting_fraction,
        max_quiet_dynamical_times=nbody.stop.max_quiet_dynamical_times,
        max_sim_time=values["nbody_time_cap"],
        max_wall_seconds=nbody.stop.max_wall_seconds,
        archive_path=ctx.run_dir / ARCHIVE_FILE,
        seed=nbody.seed,
        progress=on_progress,
        steps_per_dynamical_time=nbody.steps_per_dynamical_time,
        collision_step_fraction=nbody.collision_step_fraction,
        box_factor=nbody.box_factor,
    )
    try:
        with ctx.stop_at_safe_points():
            try:
                result = reaccumulate(particles, **settings)
            except ArchiveMismatch as exc:
                log.info("nbody: %s: starting over", exc)
                result = reaccumulate(particles, resume=False, **settings)
    finally:
        progress.close()
    wall = time.perf_counter() - t0
    write_result(ctx.path("nbody"), result, ctx.provenance(started, wall))
    escaped_mass = float(result.escaped_mass.sum())
    final_mass = float(result.mass.sum())
    initial_mass = float(particles.mass.sum())
    counters = {"steps": result.steps}
    if result.particle_steps >= 0:  # -1: resumed from a checkpoint written before the counter existed
        counters["particle_steps"] = result.particle_steps
    log.info("nbody: %s after %.4g s simulated (%.3g t_dyn); %d particles left, %d escaped",
             result.status, result.time, result.time / result.dynamical_time, len(result),
             len(result.escaped_id))
    left_box = float(result.escaped_mass[result.escaped_reason == LEFT_BOX].sum())
    if left_box > LEFT_BOX_WARNING * initial_mass:
        log.warning("nbody: %.3g of the mass was bound but left the box (%g x the hand-off extent) and was removed; "
                    "raise nbody.box_factor if it would have come back", left_box / initial_mass, nbody.box_factor)
    if result.status == NO_PARTICLES_LEFT:
        log.warning("nbody: no particle left at the end (all escaped or removed): no remnant")
    elif result.status != "equilibrium":
        log.warning("nbody: stopped by %s before dynamical equilibrium", result.status)
    return {
        "nbody_status": result.status,
        "nbody_budget": {
            "mass_initial": initial_mass,
            "mass_final": final_mass,
            "mass_escaped": escaped_mass,
            "mass_left_box": left_box,
            "mass_lost": float(result.escaped_mass[result.escaped_reason == LOST].sum()),
            "mass_error": (final_mass + escaped_mass - initial_mass) / initial_mass if initial_mass > 0 else 0.0,
            "momentum_escaped": np.asarray(result.escaped_momentum).sum(axis=0).tolist(),
            "initial_overlapping_pairs": result.initial_overlapping_pairs,
            "initial_overlap_energy": result.initial_overlap_energy,
            "initial_unbound_mass": result.initial_unbound_mass,
            "initial_near_escape_mass": result.initial_near_escape_mass,
        },
        "stage": {"simulated_time": result.time, "dynamical_times": result.time / result.dynamical_time,
                  "particles_final": len(result), "particles_escaped": int(len(result.escaped_id)), **counters},
    }
