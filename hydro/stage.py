"""The hydro stage of the pipeline: set up the scene, run it to the hand-off time, write hydro.h5.

Snapshots are appended to a working file (``.hydro.work.h5``) as the run goes; a restart
checkpoint (``hydro.checkpoint.h5``) is written every ``hydro.checkpoint_wall_seconds``.
At the end the working file gets its provenance and is renamed to ``hydro.h5``, so a
``hydro.h5`` that exists is always complete.  A run that is interrupted resumes from the
checkpoint when its config hash is unchanged.  A run that fails (NaN, negative density,
time-step collapse) writes its last good state to the checkpoint and raises.
"""

from __future__ import annotations

import json
import logging
import os
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from impactpipe.pipeline import derived, runstore
from impactpipe.pipeline.stages import StageContext

from .io import append_snapshot, write_tracers
from .problems import PROBLEMS
from .solver import HydroFailure, Simulation
from .tracers import Tracers, place_on_grid, place_on_rays

log = logging.getLogger(__name__)


class HydroStageFailure(RuntimeError):
    """The hydro run failed; the message says where and when and where the last good state is."""

WORK_FILE = ".hydro.work.h5"
CHECKPOINT_FILE = "hydro.checkpoint.h5"
#: Snapshots written when the config names no output times: this many, evenly spaced, plus t = 0.
DEFAULT_SNAPSHOTS = 10


def output_times(config, end_time: float) -> list[float]:
    """Snapshot times (s): ``hydro.output_times``, or every ``hydro.output_interval``, or 10 evenly spaced."""
    hydro = config.hydro
    if hydro.output_times is not None:
        times = [t for t in hydro.output_times if t <= end_time]
    elif hydro.output_interval is not None:
        times = list(np.arange(0.0, end_time, hydro.output_interval))
    else:
        times = list(np.linspace(0.0, end_time, DEFAULT_SNAPSHOTS + 1)[:-1])
    return sorted(set(times) | {end_time})


def problem_parameters(config, values: dict[str, Any]) -> dict[str, Any]:
    """The scene as the keyword parameters of its problem module's ``setup``."""
    scene = config.scene
    if scene.problem == "impact":
        return {
            "target": {"material": scene.target.material, "radius": scene.target.radius},
            "projectile": {"material": scene.projectile.material, "radius": scene.projectile.radius,
                           "velocity": scene.impact.velocity},
            "angle": scene.impact.angle,
            "full_domain": scene.full_domain,
            "cells_per_projectile_radius": config.hydro.cells_per_projectile_radius,
            "margin": values["domain"]["margin"],
            "end_time": values["end_time"],
            "levels": values["levels"],
            "refinement": config.hydro.refinement.model_dump(),
        }
    params = scene.model_dump(exclude={"problem", "geometry"})
    if scene.problem == "interface_advection" and params["outer"] is None:
        params["outer"] = {"material": "", "density": 0.0}
    known = PROBLEMS[scene.problem].DEFAULTS
    return {key: value for key, value in params.items() if key in known}


def build_simulation(config, values: dict[str, Any]) -> Simulation:
    """The Simulation of the config's scene, at t = 0."""
    materials = config.resolved_materials()
    if config.scene.problem == "impact":
        for mat in materials.values():
            if mat["eos"]["model"] != "table":
                mat["eos"]["T_ref"] = config.scene.temperature
    options: dict[str, Any] = {"cfl": config.hydro.cfl, "geometry": values["geometry"]}
    if config.hydro.block_cells is not None:
        options["block_cells"] = config.hydro.block_cells
    return PROBLEMS[config.scene.problem].setup(problem_parameters(config, values), materials, **options)


#: Rays of the 2d-cylindrical tracer layout (the count per ray is hydro.tracers.count / rays).
TRACER_RAYS = 30


def tracers_enabled(config) -> tuple[bool, str]:
    """(on, why) for tracers: auto turns them on for impacts, whose analysis needs peak pressures."""
    setting = config.hydro.tracers.enabled
    if setting != "auto":
        return bool(setting), "set in the config"
    if config.scene.problem == "impact":
        return True, "auto: on for impacts (peak pressures for the shock histories of the analysis)"
    return False, f"auto: off for the {config.scene.problem} verification problem"


def tracer_grid_spacing(target_radius: float, count: int) -> float:
    """Lattice spacing h (m) of the 3d tracer grid: the whole target holds about ``count`` tracers.

    h = (V_T / count)^(1/3), V_T = (4 pi / 3) R_T^3.
    """
    return (4.0 * np.pi / 3.0 * target_radius ** 3 / count) ** (1.0 / 3.0)


def add_tracers(sim: Simulation, config, end_time: float) -> None:
    """Place the impact scene's tracers.

    2d-cylindrical: rays from the impact point plus a projectile grid (:func:`place_on_rays`).
    3d: cubic lattices filling both bodies (:func:`place_on_grid`), spacing
    :func:`tracer_grid_spacing` in the target and min(h, R_P / 4) in the projectile; a
    half-domain run (mirror plane y = 0) keeps the lattice points with y > 0 (none lies on
    y = 0), and the hand-off mirrors them with the mesh.
    """
    scene = config.scene
    r_t, r_p = scene.target.radius, scene.projectile.radius
    count = config.hydro.tracers.count
    if sim.mesh.geometry == "3d":
        positions, materials = place_on_grid((0.0, 0.0, 0.0), r_t, (0.0, 0.0, r_t + r_p), r_p,
                                             tracer_grid_spacing(r_t, max(count, 1)))
        if not scene.full_domain:
            half = positions[:, 1] > 0.0
            positions, materials = positions[half], materials[half]
    else:
        rays = min(TRACER_RAYS, max(1, count))
        positions, materials = place_on_rays((0.0, r_t), r_t, 0.0, n_rays=rays, count=max(count, rays),
                                             projectile_radius=r_p, projectile_center_z=r_t + r_p)
    sim.tracers = Tracers(positions, materials, history_interval=config.hydro.tracers.history_interval,
                          end_time=end_time)


def run_hydro_stage(ctx: StageContext) -> dict[str, Any]:
    """Run the hydro stage for ``ctx.config``; returns its summary entries."""
    started = runstore.utc_now()
    t_wall = time.perf_counter()
    config = ctx.config
    values = derived.derive(config)
    coarse = derived.resolution_warnings(config)
    for message in coarse:
        log.warning("hydro: %s", message)
    end_time = float(values["end_time"])
    work = ctx.run_dir / WORK_FILE
    checkpoint = ctx.run_dir / CHECKPOINT_FILE
    sim, initial = _resume_or_start(config, values, work, checkpoint, ctx.stage_hash)
    times = [t for t in output_times(config, end_time) if t > sim.time]
    if sim.time == 0.0 and sim.step_count == 0:
        _append(work, sim.snapshot())
    progress = ctx.progress("hydro", end_time)
    last_checkpoint = [time.perf_counter()]

    def on_progress(t: float) -> None:
        progress(t)
        if time.perf_counter() - last_checkpoint[0] >= config.hydro.checkpoint_wall_seconds:
            sim.save_checkpoint(checkpoint)
            last_checkpoint[0] = time.perf_counter()

    try:
        sim.run(end_time, output_times=times, on_output=lambda snap: _append(work, snap), progress=on_progress)
    except HydroFailure as exc:
        sim.restore_last_good()
        sim.save_checkpoint(checkpoint)
        log.error("hydro failure: %s; cell state: %s", exc, exc.state)
        raise HydroStageFailure(f"{exc}; the last good state (t = {sim.time:.6g} s) is kept in {checkpoint}") from exc
    except BaseException:
        sim.save_checkpoint(checkpoint)
        raise
    finally:
        progress.close()
    wall = time.perf_counter() - t_wall
    budget = conservation_budget(initial, sim.totals(), sim.floor_amounts,
                                 sim.gravity.work if sim.gravity is not None else 0.0)
    with h5py.File(work, "a") as f:
        runstore.write_provenance(f, ctx.provenance(started, wall))
        group = f.require_group("budget")
        for key, value in budget.items():
            group.attrs[key] = value
        f.attrs["cell_updates"] = sim.cell_updates
        f.attrs["steps"] = sim.step_count
        f.attrs["floor_counts"] = json.dumps(sim.floor_counts)
        if sim.tracers is not None:
            write_tracers(f, sim.tracers)
    os.replace(work, ctx.path("hydro"))
    checkpoint.unlink(missing_ok=True)
    log.info("hydro: %d steps, %.3g cell-updates, %.3g cell-updates/s", sim.step_count, sim.cell_updates,
             sim.cell_updates / max(wall, 1e-9))
    warnings = derived.physics_warnings(values)
    for message in warnings:
        log.warning("hydro: %s", message)
    tracer_summary = ({"count": len(sim.tracers.to_tracer_set()),
                       "exited": int(sim.tracers.to_tracer_set().exited.sum())} if sim.tracers is not None else None)
    return {
        "tracers": tracer_summary,
        "physics_not_modelled": warnings,
        "resolution_warnings": coarse,
        "hydro_budget": budget,
        "stage": {"steps": sim.step_count, "cell_updates": sim.cell_updates, "floors": sim.floor_counts},
    }


#: Floor amounts that change the mesh totals, with the sign of their change (added +1, removed -1).
COUNTED_CHANGES = {
    "mass": (("mass_added_by_floors", 1.0), ("mass_removed_by_void_cleanup", -1.0)),
    "energy": (("energy_added_by_floors", 1.0), ("energy_removed_by_void_cleanup", -1.0),
               ("energy_removed_by_velocity_limit", -1.0), ("energy_removed_by_energy_limit", -1.0)),
}


def conservation_budget(initial: dict[str, Any], final: dict[str, Any], floors: dict[str, float],
                        gravity_work: float = 0.0) -> dict[str, float]:
    """Mass, momentum and energy: at the start, on the mesh at the end, what left it, what floors changed (SI).

    ``*_error`` is (mesh + left - initial - added) relative to the initial value: what the
    scheme failed to conserve, floors included; ``added`` is the work done by external
    gravity for the energy (``energy_added_by_gravity``, J; :mod:`impactpipe.hydro.gravity`)
    and 0 for the mass.  A run starting with zero energy is measured against the gravity work.
    ``*_unaccounted`` is the same with every counted change of the floors (``floors``, the
    solver's ``floor_amounts``; :data:`COUNTED_CHANGES`) taken back: zero up to round-off
    when nothing changed the totals uncounted.
    """
    out: dict[str, float] = {"energy_added_by_gravity": float(gravity_work)}
    for key in ("mass", "energy"):
        added = gravity_work if key == "energy" else 0.0
        out[f"{key}_initial"] = float(initial[key])
        out[f"{key}_on_mesh"] = float(final[key])
        out[f"{key}_left_mesh"] = float(final[f"outflow_{key}"])
        scale = abs(float(initial[key])) or abs(added) or 1.0
        change = final[key] + final[f"outflow_{key}"] - initial[key] - added
        out[f"{key}_error"] = float(change / scale)
        counted = sum(sign * floors.get(name, 0.0) for name, sign in COUNTED_CHANGES[key])
        out[f"{key}_unaccounted"] = float((change - counted) / scale)
    for axis, name in enumerate("xyz"):
        out[f"momentum_{name}_initial"] = float(initial["momentum"][axis])
        out[f"momentum_{name}_on_mesh"] = float(final["momentum"][axis])
        out[f"momentum_{name}_left_mesh"] = float(final["outflow_momentum"][axis])
    out.update({f"floor_{key}": float(value) for key, value in floors.items()})
    return out


def _append(work: Path, snapshot) -> None:
    with h5py.File(work, "a") as f:
        append_snapshot(f, snapshot)


INITIAL_KEYS = ("mass", "energy", "momentum")


def _resume_or_start(config, values, work: Path, checkpoint: Path, stage_hash: str):
    """(simulation, initial totals): resumed from a checkpoint of the same config, or new at t = 0."""
    if checkpoint.is_file() and work.is_file():
        with h5py.File(work, "r") as f:
            same = f.attrs.get("stage_hash") == stage_hash
            initial = {key: f.attrs[f"initial_{key}"] for key in INITIAL_KEYS} if same else None
        if same and not getattr(PROBLEMS[config.scene.problem], "RESUMABLE", True):
            log.info("hydro: the %s scene restarts from t = 0 (its checkpoints do not carry external gravity)",
                     config.scene.problem)
            same = False
        if same:
            sim = Simulation.from_checkpoint(checkpoint)
            _trim_snapshots(work, sim.time)
            log.info("hydro: resuming from checkpoint at t = %.6g s (step %d)", sim.time, sim.step_count)
            return sim, initial
    checkpoint.unlink(missing_ok=True)
    work.unlink(missing_ok=True)
    sim = build_simulation(config, values)
    if tracers_enabled(config)[0]:
        if config.scene.problem != "impact":
            raise ValueError("hydro.tracers.enabled: tracers are placed for impact scenes only in this version")
        add_tracers(sim, config, float(values["end_time"]))
    initial = sim.totals()
    with h5py.File(work, "w") as f:
        f.attrs["stage_hash"] = stage_hash
        for key in INITIAL_KEYS:
            f.attrs[f"initial_{key}"] = initial[key]
    return sim, initial


def _trim_snapshots(work: Path, t_resume: float) -> None:
    """Drop working-file snapshots later than the checkpoint (they are recomputed)."""
    with h5py.File(work, "a") as f:
        group = f.require_group("snapshots")
        for name in list(group):
            if float(group[name].attrs["time"]) > t_resume:
                del group[name]
