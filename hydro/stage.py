"""The hydro stage of the pipeline: set up the scene, run it to the hand-off time, write hydro.h5.

Snapshots are appended to a working file (``.hydro.work.h5``) as the run goes; a restart
checkpoint (``hydro.checkpoint.h5``) is written every ``hydro.checkpoint_wall_seconds``.
At the end the working file gets its provenance and is renamed to ``hydro.h5``, so a
``hydro.h5`` that exists is always complete.  A run that is interrupted resumes from the
checkpoint when its config hash is unchanged.  A run that fails (NaN, negative density,
time-step collapse) writes its last good state to the checkpoint and raises.
"""

from __future__ import annotations

import logging
import os
import time
from typing import Any

import h5py
import numpy as np

from impactpipe.pipeline import derived, runstore
from impactpipe.pipeline.stages import StageContext

from .io import write_snapshot
from .problems import PROBLEMS
from .solver import HydroFailure, Simulation

log = logging.getLogger(__name__)

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


def build_simulation(config, values: dict[str, Any]) -> Simulation:
    """The Simulation of the config's scene, at t = 0."""
    scene = config.scene
    materials = config.resolved_materials()
    if scene.problem == "impact":
        for mat in materials.values():
            mat["eos"].setdefault("T_ref", scene.temperature)
    params = scene.model_dump(exclude={"problem", "geometry"})
    options: dict[str, Any] = {"cfl": config.hydro.cfl, "geometry": values["geometry"]}
    if config.hydro.block_cells is not None:
        options["block_cells"] = config.hydro.block_cells
    if scene.problem == "impact":
        options["cells_per_projectile_radius"] = config.hydro.cells_per_projectile_radius
        options["end_time"] = values["end_time"]
    return PROBLEMS[scene.problem].setup(params, materials, **options)


def run_hydro_stage(ctx: StageContext) -> dict[str, Any]:
    """Run the hydro stage for ``ctx.config``; returns its summary entries."""
    started = runstore.utc_now()
    t_wall = time.perf_counter()
    config = ctx.config
    values = derived.derive(config)
    end_time = float(values["end_time"])
    work = ctx.run_dir / WORK_FILE
    checkpoint = ctx.run_dir / CHECKPOINT_FILE
    sim, written = _resume_or_start(config, values, work, checkpoint, ctx.stage_hash)
    initial = sim.initial_totals
    times = [t for t in output_times(config, end_time) if t > sim.time or (t == 0.0 and 0.0 not in written)]
    progress = ctx.progress("hydro", end_time)
    last_checkpoint = [time.perf_counter()]

    def on_output(snapshot) -> None:
        with h5py.File(work, "a") as f:
            write_snapshot(f.require_group("snapshots"), snapshot)
            f.flush()

    def on_progress(t: float) -> None:
        progress(t)
        if time.perf_counter() - last_checkpoint[0] >= config.hydro.checkpoint_wall_seconds:
            _write_checkpoint(sim, checkpoint, ctx.stage_hash)
            last_checkpoint[0] = time.perf_counter()

    try:
        sim.run(end_time, output_times=times, on_output=on_output, progress=on_progress)
    except HydroFailure:
        sim.restore_last_good()
        _write_checkpoint(sim, checkpoint, ctx.stage_hash)
        log.error("hydro failed; last good state (t = %.6g s) written to %s", sim.time, checkpoint)
        raise
    except BaseException:
        _write_checkpoint(sim, checkpoint, ctx.stage_hash)
        raise
    finally:
        progress.close()
    wall = time.perf_counter() - t_wall
    final = sim.totals()
    budget = conservation_budget(initial, final)
    with h5py.File(work, "a") as f:
        runstore.write_provenance(f, ctx.provenance(started, wall))
        f.attrs["stage_hash"] = ctx.stage_hash
        group = f.require_group("budget")
        for key, value in budget.items():
            group.attrs[key] = value
        f.attrs["cell_updates"] = sim.cell_updates
        f.attrs["steps"] = sim.step_count
    os.replace(work, ctx.path("hydro"))
    checkpoint.unlink(missing_ok=True)
    log.info("hydro: %d steps, %.3g cell-updates, %.3g cell-updates/s", sim.step_count, sim.cell_updates,
             sim.cell_updates / max(wall, 1e-9))
    return {
        "handoff_time": end_time if config.scene.problem == "impact" else None,
        "hydro_budget": budget,
        "stage": {"steps": sim.step_count, "cell_updates": sim.cell_updates, "floors": sim.floor_counts()},
    }


def conservation_budget(initial: dict[str, Any], final: dict[str, Any]) -> dict[str, float]:
    """Mass, momentum and energy: at the start, on the mesh at the end, and what left it (SI).

    ``*_error`` is (mesh + left) - initial relative to the initial value (energy: relative
    to the initial total energy), the round-off the scheme must keep.
    """
    out: dict[str, float] = {}
    for key in ("mass", "energy"):
        out[f"{key}_initial"] = float(initial[key])
        out[f"{key}_on_mesh"] = float(final[key])
        out[f"{key}_left_mesh"] = float(final[f"{key}_outflow"])
        scale = abs(initial[key]) or 1.0
        out[f"{key}_error"] = float((final[key] + final[f"{key}_outflow"] - initial[key]) / scale)
    for axis, name in enumerate("xyz"):
        out[f"momentum_{name}_initial"] = float(initial["momentum"][axis])
        out[f"momentum_{name}_on_mesh"] = float(final["momentum"][axis])
        out[f"momentum_{name}_left_mesh"] = float(final["momentum_outflow"][axis])
    return out


def _write_checkpoint(sim: Simulation, path, stage_hash: str) -> None:
    sim.save_checkpoint(path, attrs={"stage_hash": stage_hash})


def _resume_or_start(config, values, work, checkpoint, stage_hash: str) -> tuple[Simulation, set[float]]:
    """Resume from a checkpoint of the same config, or start at t = 0 with a fresh working file."""
    if checkpoint.is_file() and work.is_file():
        with h5py.File(checkpoint, "r") as f:
            same = f.attrs.get("stage_hash") == stage_hash
        if same:
            sim = Simulation.from_checkpoint(checkpoint)
            written = _trim_snapshots(work, sim.time)
            log.info("hydro: resuming from checkpoint at t = %.6g s (step %d)", sim.time, sim.step_count)
            return sim, written
    checkpoint.unlink(missing_ok=True)
    work.unlink(missing_ok=True)
    return build_simulation(config, values), set()


def _trim_snapshots(work, t_resume: float) -> set[float]:
    """Drop working-file snapshots later than the checkpoint; return the times kept."""
    kept = set()
    with h5py.File(work, "a") as f:
        group = f.require_group("snapshots")
        for name in list(group):
            t = float(group[name].attrs["time"])
            if t > t_resume:
                del group[name]
            else:
                kept.add(t)
    return kept
