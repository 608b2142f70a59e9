"""The hand-off stage\'s adapter: the last hydro snapshot becomes N-body particles in handoff.h5."""

from __future__ import annotations

import logging
import time
from typing import Any

import h5py
import numpy as np

from impactpipe.hydro.output.io import read_snapshot, read_tracers
from impactpipe.hydro.problems.impact import PROJECTILE_MATERIAL
from impactpipe import storage
from impactpipe.handoff.mirror import mirror_across_y0
from impactpipe.handoff.moments import target_kinetic_energy
from impactpipe.handoff.spheres import blocks_to_spheres
from impactpipe.handoff.store import write_particles

from .. import derived
from ..fragments import intact_fragment_labels
from ..stages import StageContext


log = logging.getLogger(__name__)

def porous_materials(materials: dict[str, dict[str, Any]], names: list[str]) -> np.ndarray:
    """(M,) booleans: which of the snapshot's materials ``names`` are porous (a resolved ``porosity``
    block with alpha0 > 1; an impact's projectile is named "<material> (projectile)" when target
    and projectile share their material, hydro/problems/impact.py)."""
    out = []
    for name in names:
        block = materials.get(name.removesuffix(" (projectile)"), {}).get("porosity")
        out.append(bool(block) and float(block["alpha0"]) > 1.0)
    return np.array(out, dtype=bool)


def run_handoff_stage(ctx: StageContext) -> dict[str, Any]:
    """Hand off the final hydro snapshot of ``ctx.run_dir``; returns the summary entries."""
    started = storage.utc_now()
    t0 = time.perf_counter()
    config = ctx.config
    values = ctx.values
    hydro_path = ctx.path("hydro")
    snapshot = read_snapshot(hydro_path, index=snapshot_index(hydro_path, config.handoff.time))
    tracers = read_tracers(hydro_path)
    with h5py.File(hydro_path, "r") as f:
        mass_left = float(f["budget"].attrs["mass_left_mesh"])
        mesh_mass_initial = float(f["budget"].attrs["mass_initial"])
    projectile_index = PROJECTILE_MATERIAL if config.scene.problem == "impact" else None
    # A half-domain 3d run computed y >= 0 only: the hand-off mirrors it, and the masses it
    # refers to are the full body's (twice the run's).
    halves = 2.0 if values["domain"]["half_domain"] else 1.0
    mirror = values["domain"]["half_domain"]
    intact_label = None
    intact = config.handoff.intact_fragments
    if intact.enabled:
        if mirror:
            snapshot, tracers = mirror_across_y0(snapshot, tracers)
            mirror = False
        intact_label = intact_fragment_labels(snapshot, intact.min_fill, intact.max_damage)
    particles, budget = blocks_to_spheres(
        snapshot,
        tracers,
        target_bulk_density=values["target_reference_density"],
        total_mass=halves * mesh_mass_initial,
        escape_speed=values["escape_speed"],
        projectile_material_index=projectile_index,
        porous_materials=porous_materials(config.resolved_materials(), snapshot.material_names),
        min_density_fraction=config.handoff.min_density_fraction,
        min_mass_fraction=config.handoff.min_mass_fraction,
        velocity_noise=config.handoff.velocity_noise,
        seed=config.handoff.seed,
        mass_left_mesh=halves * mass_left,
        mirror_y0=mirror,
        block_edge=values.get("handoff_block_edge"),
        intact_label=intact_label,
    )
    target_energy = None
    if config.scene.problem == "impact":
        whole = mirror_across_y0(snapshot)[0] if mirror else snapshot
        target_energy = target_kinetic_energy(whole, config.scene.target.radius)
    if len(particles) == 0:
        raise RuntimeError(f"hand-off at t = {snapshot.time:.6g} s produced no particle "
                           f"(mesh mass {budget.mesh_mass:.4g} kg, all blocks below the mass floor)")
    attrs = ctx.provenance(started, time.perf_counter() - t0)
    attrs["handoff_time"] = str(snapshot.time)
    write_particles(ctx.path("handoff"), particles, budget, attrs)
    log.info("handoff: %d particles from %d blocks at t = %.4g s; %.3g kg dropped", len(particles),
             budget.n_blocks, snapshot.time, budget.dropped_mass)
    return {"N_init": len(particles), "handoff_time": float(snapshot.time), "handoff_budget": budget.to_summary(),
            "target_kinetic_energy": target_energy}


def snapshot_index(hydro_path, time: float | None) -> int:
    """Index of the hydro snapshot at ``time`` (s); the last one when ``time`` is None."""
    if time is None:
        return -1
    with h5py.File(hydro_path, "r") as f:
        names = sorted(f["snapshots"])
        times = [float(f["snapshots"][name].attrs["time"]) for name in names]
    index = derived.snapshot_at(times, time)
    if index is not None:
        return index
    raise ValueError(f"handoff.time = {time:g} s: no hydro snapshot at that time (snapshots at "
                     f"{', '.join(f'{t:.6g}' for t in times)} s)")
