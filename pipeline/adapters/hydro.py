"""The hydro stage's adapter: set up the config's scene, run it to the hand-off time, write hydro.h5.

Snapshots are appended to a working file (``.hydro.work.h5``) as the run goes; a restart
checkpoint (``hydro.checkpoint.h5``) is written every ``hydro.checkpoint_wall_seconds``.
At the end the working file gets its provenance and is renamed to ``hydro.h5``, so a
``hydro.h5`` that exists is always complete.  A run that is interrupted resumes from the
checkpoint when its config hash is unchanged.  A run that fails (NaN, negative density,
time-step collapse) writes its last good state to the checkpoint and raises.

On several MPI ranks (:mod:`impactpipe.pipeline.ranks`) rank 0 runs this stage as above and
sends the other ranks its order, and no rank ever holds the whole state where the ranks write
their outputs together (parallel HDF5): the ranks build a new run together, each its own
blocks (:func:`impactpipe.hydro.parallel.distributed.shared_simulation`), a resumed run is
read from the checkpoint by every rank, each its own blocks (:meth:`Simulation.from_checkpoint`),
and at the end the ranks sum the totals together and send rank 0 only the per-block counters
(:func:`impactpipe.hydro.parallel.distributed.collect_counters`).  Rank 0 decides after
every step whether a checkpoint is due or a stop was asked for, and the others follow.
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

from impactpipe import storage
from impactpipe.hydro.budget import conservation_budget
from impactpipe.hydro.output.io import append_snapshot, write_tracers
from impactpipe.hydro.parallel.distributed import PARALLEL_HDF5_VARIABLE, collect_counters
from impactpipe.hydro.problems import PROBLEMS, impact
from impactpipe.hydro.self_gravity import DEFAULT_ORDER
from impactpipe.hydro.solver import HydroFailure, Simulation
from impactpipe.hydro.tracers.motion import Tracers

from .. import derived, ranks
from ..stages import StageContext

log = logging.getLogger(__name__)


class HydroStageFailure(RuntimeError):
    """The hydro run failed; the message says where and when and where the last good state is."""


class _StoppedByRankZero(Exception):
    """Rank 0 stopped the shared hydro run at the end of a step (a signal asked it to)."""


WORK_FILE = ".hydro.work.h5"
CHECKPOINT_FILE = "hydro.checkpoint.h5"
def problem_parameters(config, values: dict[str, Any]) -> dict[str, Any]:
    """The scene as the parameters of its problem module's ``setup``.

    A verification problem's scene keys are its ``setup``'s (both are the module's
    ``PARAMETERS``); the impact scene's are translated, with the resolved mesh values.  Every
    scene gets the mesh's ``levels`` (resolved ``hydro.max_levels``) and ``refinement``.
    """
    scene = config.scene
    mesh = {"levels": values["levels"], "refinement": config.hydro.refinement.model_dump()}
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
            "self_gravity": bool(values["self_gravity"]),
            **mesh,
        }
    return {**scene.model_dump(exclude={"problem", "geometry"}), **mesh}


def build_simulation(config, values: dict[str, Any], comm=None) -> Simulation:
    """The Simulation of the config's scene, at t = 0; with ``comm`` (collective) this rank's
    share of the run the ranks build together, each its own blocks."""
    materials = config.resolved_materials()
    if config.scene.problem == "impact":
        for mat in materials.values():
            if mat["eos"]["model"] != "table":
                mat["eos"]["T_ref"] = config.scene.temperature
    options: dict[str, Any] = {"cfl": config.hydro.cfl, "geometry": values["geometry"]}
    if config.hydro.block_cells is not None:
        options["block_cells"] = config.hydro.block_cells
    if comm is not None:
        options["comm"] = comm
    sim = PROBLEMS[config.scene.problem].setup(problem_parameters(config, values), materials, **options)
    sim.time_stepping = config.hydro.time_stepping
    sim.check_time_stepping()
    return sim


def too_many_ranks(config, values: dict[str, Any], nranks: int) -> str | None:
    """Why ``nranks`` ranks cannot share the hydro stage's mesh at t = 0 (more ranks than
    blocks, or ``hydro.time_stepping: per_level`` or ``scene.settling``, which run on one process), or None.  The
    root blocks are counted from the derived domain; the initial mesh (whose refinement adds
    blocks) is built only when they are fewer than the ranks."""
    if nranks <= 1:
        return None
    if config.hydro.time_stepping == "per_level":
        return (f"--ranks {nranks}: hydro.time_stepping per_level runs the hydro stage on one process in this "
                f"version; use --ranks 1 or hydro.time_stepping global")
    if getattr(config.scene, "settling", False):
        return (f"--ranks {nranks}: scene.settling (void settling) runs the hydro stage on one process in this "
                f"version; use --ranks 1 or scene.settling: false")
    domain = values.get("domain")
    if domain:
        per_root = domain["block_cells"] * 2 ** (int(values["levels"]) - 1)
        roots = 1
        for cells in domain["cells"]:
            roots *= max(int(cells) // per_root, 1)
        if roots >= nranks:
            return None
    blocks = build_simulation(config, values).mesh.nblocks
    if blocks >= nranks:
        return None
    return (f"--ranks {nranks}: more ranks ({nranks}) than blocks ({blocks}) in the hydro mesh at t = 0; "
            f"use at most {blocks} ranks or a finer mesh")


def add_tracers(sim: Simulation, config, end_time: float) -> None:
    """Place the impact scene's tracers (:func:`impactpipe.hydro.problems.impact.tracer_positions`)."""
    scene = config.scene
    positions, materials = impact.tracer_positions(sim.mesh.geometry, scene.target.radius, scene.projectile.radius,
                                                   config.hydro.tracers.count, scene.full_domain)
    sim.tracers = Tracers(positions, materials, history_interval=config.hydro.tracers.history_interval,
                          end_time=end_time)


def run_hydro_stage(ctx: StageContext) -> dict[str, Any]:
    """Run the hydro stage for ``ctx.config``; returns its summary entries."""
    started = storage.utc_now()
    t_wall = time.perf_counter()
    config = ctx.config
    values = ctx.values
    coarse = derived.resolution_warnings(config)
    for message in coarse:
        log.warning("hydro: %s", message)
    end_time = float(values["end_time"])
    work = ctx.run_dir / WORK_FILE
    checkpoint = ctx.run_dir / CHECKPOINT_FILE
    if values.get("self_gravity"):
        log.info("hydro: self-gravity on, multipole expansion of order %d about the centre of mass (%s)",
                 DEFAULT_ORDER, values["self_gravity_rule"])
    comm = ranks.world()
    initial = _resumable(config, work, checkpoint, ctx.stage_hash)
    if initial is not None:
        with h5py.File(checkpoint, "r") as f:
            t_resume = float(f.attrs["time"])
        times = [t for t in derived.snapshot_times(config, end_time) if t > t_resume]
        if comm is not None:
            ranks.send_order({"checkpoint": str(checkpoint), "work": str(work), "end_time": end_time, "times": times,
                              "resume": True})
        sim = Simulation.from_checkpoint(checkpoint, comm)
        _trim_snapshots(work, sim.time)
        log.info("hydro: resuming from checkpoint at t = %.6g s (step %d)", sim.time, sim.step_count)
    else:
        times = [t for t in derived.snapshot_times(config, end_time) if t > 0.0]
        if comm is not None:
            ranks.send_order({"checkpoint": str(checkpoint), "work": str(work), "end_time": end_time,
                              "times": times, "resume": False, "config": config, "values": values})
        sim, initial = _start(config, values, work, checkpoint, ctx.stage_hash, comm)
        _append(work, sim.snapshot(), sim.partition)
    if comm is not None:
        if sim.partition.writes_together:
            log.info("hydro: snapshots and checkpoints written by every rank together, each its own blocks, "
                     "into one file (parallel HDF5, h5py's mpio driver)")
        elif h5py.get_config().mpi:
            log.info("hydro: snapshots and checkpoints gathered to rank 0, which writes them (h5py has "
                     "parallel HDF5, not used: %s=0)", PARALLEL_HDF5_VARIABLE)
        else:
            log.info("hydro: snapshots and checkpoints gathered to rank 0, which writes them (h5py is built "
                     "without parallel HDF5)")
    progress = ctx.progress("hydro", end_time)
    last_checkpoint = [time.perf_counter()]
    stopped = []

    def on_progress(t: float) -> None:
        """After every step (a whole state): progress, periodic checkpoints, a requested stop."""
        progress(t)
        stop = ctx.stop_requested()
        due = stop is not None or time.perf_counter() - last_checkpoint[0] >= config.hydro.checkpoint_wall_seconds
        due, stop = sim.partition.agree((due, stop))
        if due:
            sim.save_checkpoint(checkpoint)
            last_checkpoint[0] = time.perf_counter()
        if stop is not None:
            log.info("hydro: stopped by %s at t = %.6g s (step %d); checkpoint kept for the resume", stop, sim.time,
                     sim.step_count)
            stopped.append(stop)
            raise ctx.interrupted()

    try:
        with ctx.stop_at_safe_points():
            sim.run(end_time, output_times=times, on_output=lambda snap: _append(work, snap, sim.partition),
                    progress=on_progress)
    except HydroFailure as exc:
        sim.restore_last_good()
        sim.save_checkpoint(checkpoint)
        log.error("hydro failure: %s; cell state: %s", exc, exc.state)
        raise HydroStageFailure(f"{exc}; the last good state (t = {sim.time:.6g} s) is kept in {checkpoint}") from exc
    except BaseException as exc:
        if comm is not None and not stopped:  # the other ranks wait in a step for rank 0
            ranks.abort(comm, f"the hydro stage failed: {type(exc).__name__}: {exc}")
        raise
    finally:
        progress.close()
    totals = sim.totals()
    collect_counters(sim)
    wall = time.perf_counter() - t_wall
    budget = conservation_budget(initial, totals, sim.floor_amounts, sim.gravity.work if sim.gravity is not None else 0.0)
    if hasattr(sim.gravity, "potential_energy"):
        budget["gravitational_potential_energy"] = sim.gravity.potential_energy
        log.info("hydro: self-gravity did %.6g J of work; the potential energy of the mass is %.6g J",
                 sim.gravity.work, sim.gravity.potential_energy)
    with h5py.File(work, "a") as f:
        storage.write_provenance(f, ctx.provenance(started, wall))
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


def follow_hydro_stage(comm) -> int:
    """A rank other than 0: take part in rank 0's hydro stage, if it runs one; returns the exit status.

    The simulation is a new one that the ranks build together, each its own blocks
    (:func:`~impactpipe.hydro.parallel.distributed.shared_simulation`), or the checkpoint's, of
    which it reads its own blocks (:meth:`Simulation.from_checkpoint`); it runs to the same
    times; snapshots, checkpoints and totals are collective, and rank 0
    writes what the ranks do not write together.  0 when the stage finished (or did not run),
    1 after a hydro failure, 2 when the run cannot be shared, 130 when rank 0 stopped it.
    """
    order = ranks.wait_for_order(comm)
    if order is None:
        return 0
    checkpoint = Path(order["checkpoint"])
    try:
        if order["resume"]:
            sim = Simulation.from_checkpoint(checkpoint, comm)
        else:
            sim = _new_run(order["config"], order["values"], comm)
            sim.totals()
            _append(Path(order["work"]), sim.snapshot(), sim.partition)
    except ValueError:
        return 2

    def follow(t: float) -> None:
        due, stop = sim.partition.agree(None)
        if due:
            sim.save_checkpoint(checkpoint)
        if stop is not None:
            raise _StoppedByRankZero(stop)

    try:
        sim.run(order["end_time"], output_times=order["times"],
                on_output=lambda snapshot: _append(Path(order["work"]), snapshot, sim.partition), progress=follow)
    except HydroFailure:
        sim.restore_last_good()
        sim.save_checkpoint(checkpoint)
        return 1
    except _StoppedByRankZero:
        return 130
    sim.totals()
    collect_counters(sim)
    return 0


def _append(work: Path, snapshot, partition) -> None:
    """Append ``snapshot`` to the working file: the process that writes alone, or, where the
    ranks of ``partition`` write together, every rank its own blocks' rows."""
    if partition.writes_together or partition.is_root:
        with partition.output_file(work, "a") as f:
            append_snapshot(f, snapshot, partition.blocks if partition.writes_together else None)


INITIAL_KEYS = ("mass", "energy", "momentum")


def _resumable(config, work: Path, checkpoint: Path, stage_hash: str) -> dict | None:
    """The initial totals of the run that ``checkpoint`` resumes (the working file's), or None
    where there is no checkpoint of the same config to resume (or the scene cannot resume)."""
    if not (checkpoint.is_file() and work.is_file()):
        return None
    with h5py.File(work, "r") as f:
        if f.attrs.get("stage_hash") != stage_hash:
            return None
        initial = {key: f.attrs[f"initial_{key}"] for key in INITIAL_KEYS}
    if not getattr(PROBLEMS[config.scene.problem], "RESUMABLE", True):
        log.info("hydro: the %s scene restarts from t = 0 (its checkpoints do not carry all of its setup)",
                 config.scene.problem)
        return None
    return initial


def _start(config, values, work: Path, checkpoint: Path, stage_hash: str, comm=None):
    """(simulation, initial totals) of a new run at t = 0 (:func:`_new_run`; collective with
    ``comm``); an earlier run's checkpoint and working file are removed, the new working file
    holds the stage hash and the initial totals."""
    checkpoint.unlink(missing_ok=True)
    work.unlink(missing_ok=True)
    sim = _new_run(config, values, comm)
    initial = sim.totals()
    with h5py.File(work, "w") as f:
        f.attrs["stage_hash"] = stage_hash
        for key in INITIAL_KEYS:
            f.attrs[f"initial_{key}"] = initial[key]
    return sim, initial


def _new_run(config, values, comm=None) -> Simulation:
    """The config's run at t = 0 with its tracers: built by this process, or with ``comm`` by
    the ranks together, each its own blocks (collective)."""
    sim = build_simulation(config, values, comm)
    if values["tracers"]:
        add_tracers(sim, config, float(values["end_time"]))
    return sim


def _trim_snapshots(work: Path, t_resume: float) -> None:
    """Drop working-file snapshots later than the checkpoint (they are recomputed)."""
    with h5py.File(work, "a") as f:
        group = f.require_group("snapshots")
        for name in list(group):
            if float(group[name].attrs["time"]) > t_resume:
                del group[name]
