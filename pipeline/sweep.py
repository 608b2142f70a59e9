"""Batch sweeps: grids of runs and Q*_D searches, on a local process pool or a Dask cluster.

A sweep file names a base config and axes (any config key, as lists or ranges).  Each
point gets its own run directory under ``<sweep>/runs``, named by its parameters and a
content hash of its config, so rerunning a sweep does only the work that is missing.
Points that differ only in the N-body or analysis sections share one hydro and
hand-off result: the first point of such a group runs them, the others adopt its files
(:func:`impactpipe.pipeline.stages.adopt_stages`).

Execution goes through a ``concurrent.futures`` executor: a process pool sized to the
cores (``backend: local``) or a Dask client (``backend: dask``, a scheduler address or a
LocalCluster).  A failed point is recorded with its error and log and retried up to
``execution.retries`` times; it never stops the other points.  With ``execution.ranks_per_run``
> 1 a worker runs its point on that many MPI ranks, through the launcher of ``impactpipe run
--ranks`` (:func:`_run_on_ranks`), and waits for them.

A sweep holds the lock of its directory and each point that of its run directory
(:mod:`impactpipe.pipeline.lock`), so a second sweep on the same directory stops at once
and no point is ever run twice at the same time.  The local pool's workers watch the
sweep process and stop when it is gone (``kill -9`` included); a worker that dies breaks the
pool, which is replaced (:class:`LocalPool`) and the points in flight run again.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import itertools
import json
import logging
import math
import multiprocessing
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

import h5py
import numpy as np
import yaml
from pydantic import Field, ValidationError, model_validator

from impactpipe import storage

from . import checks, ranks, runstore
from .config import (Config, ConfigError, Strict, _LineFinder, duplicate_keys, key_paths, load_yaml, parse_config,
                     read_yaml_text, unknown_keys)
from .derived import derive, snapshot_at, snapshot_times
from .lock import process_alive, recorded_holder, run_lock
from .stages import (RESOLVED_CONFIG_FILE, STAGES, adopt_stages, plan, read_records, read_summary, resolved_yaml,
                     stage_hashes)

log = logging.getLogger(__name__)

POINTS_FILE = "points.json"
#: The config key a sweep's ``resolution`` ladder varies.
RESOLUTION_KEY = "hydro.cells_per_projectile_radius"
QSTAR_RESOLUTION_CSV = "qstar_resolution.csv"
RESULTS_CSV = "results.csv"
RESULTS_H5 = "results.h5"
QSTAR_CSV = "qstar.csv"
REPLICATES_CSV = "replicates.csv"
RESULT_KEYS = ("Q", "Q_R", "gamma", "M_lr_over_M_T", "M_slr_over_M_T", "N_lr", "N_init")
#: Config keys a point may be replicated over: realisations of the same impact that differ only
#: in the hand-off (its seed: ring phases and velocity noise; its time) or in REBOUND's collision order.
REPLICATE_KEYS = ("handoff.seed", "handoff.time", "nbody.seed")
#: Keys a ``handoff.time`` replicate sets (:func:`handoff_time_params`).
HANDOFF_TIME_KEYS = ("hydro.end_time", "hydro.output_times")
#: Deaths of its pool worker after which a point fails instead of running again (:meth:`SweepRunner._after_worker_death`).
MAX_WORKER_DEATHS = 3


# --------------------------------------------------------------------------- sweep file


class Range(Strict):
    """Evenly spaced values: ``{start, stop, num}`` (stop included) or ``{start, stop, step}``."""

    start: float
    stop: float
    num: int | None = Field(None, ge=1)
    step: float | None = Field(None, gt=0)
    spacing: Literal["linear", "log"] = "linear"

    @model_validator(mode="after")
    def _one_of_num_step(self) -> "Range":
        if (self.num is None) == (self.step is None):
            raise ValueError("give exactly one of num or step")
        if self.spacing == "log" and (self.start <= 0 or self.stop <= 0 or self.step is not None):
            raise ValueError("log spacing needs positive start and stop and num (not step)")
        return self

    def values(self) -> list[float]:
        """The values of the range."""
        if self.spacing == "log":
            return [float(v) for v in np.geomspace(self.start, self.stop, self.num)]
        if self.num is not None:
            return [float(v) for v in np.linspace(self.start, self.stop, self.num)]
        n = int(math.floor((self.stop - self.start) / self.step + 1e-9)) + 1
        return [float(self.start + i * self.step) for i in range(n)]


class QStarSearch(Strict):
    """Bisection on M_lr/M_T = target in velocity or projectile radius, per group."""

    variable: Literal["scene.impact.velocity", "scene.projectile.radius"] = "scene.impact.velocity"
    bracket: tuple[float, float] | None = Field(None, description="initial (low, high); default from published laws")
    tolerance: float = Field(0.02, gt=0, lt=1, description="stop when (high - low) / mid is below this")
    max_rounds: int = Field(12, ge=1)
    max_expansions: int = Field(4, ge=0, description="times a bracket that does not bracket may be widened by 2x")
    target: float = Field(0.5, gt=0, lt=1)
    noise_sigmas: float = Field(2.0, ge=0, description="with replicates, stop when a midpoint's mean M_lr/M_T lies "
                                                         "within this many standard errors of the target (0: never)")

    @model_validator(mode="after")
    def _bracket_ordered(self) -> "QStarSearch":
        if self.bracket is not None and not 0 < self.bracket[0] < self.bracket[1]:
            raise ValueError(f"bracket must be (low, high) with 0 < low < high (got {self.bracket})")
        return self


class Execution(Strict):
    backend: Literal["local", "dask"] = "local"
    scheduler: str | None = Field(None, description="Dask scheduler address; none starts a LocalCluster")
    workers: int | None = Field(None, ge=1,
                                description="parallel runs; default cores // (threads_per_run * ranks_per_run)")
    threads_per_run: int = Field(1, ge=1, description="numba threads of each run (of each of its ranks)")
    ranks_per_run: int = Field(1, ge=1, description="MPI ranks that share each run's hydro stage, started by "
                                                    "the launcher (docs/sweeps.md, 'Points on several MPI ranks')")
    launcher: Literal["mpiexec", "srun"] = Field(
        "mpiexec", description="what starts a run's ranks: mpiexec (beside this Python, else on PATH) or Slurm's srun")
    launcher_options: list[str] = Field(default_factory=list,
                                        description="more arguments of the launcher, after -n N (e.g. --mpi=pmix)")
    retries: int = Field(1, ge=0, description="times a failed point is run again")

    def cores_per_run(self) -> int:
        """Cores one run keeps busy: ``threads_per_run`` numba threads on each of ``ranks_per_run`` ranks."""
        return self.threads_per_run * self.ranks_per_run

    def default_workers(self) -> int:
        """Parallel runs when ``workers`` is not set: cores // :meth:`cores_per_run`, at least 1."""
        return max(1, (os.cpu_count() or 1) // self.cores_per_run())


class SweepSpec(Strict):
    name: str = Field(min_length=1)
    base: str = Field(description="base config file, relative to the sweep file")
    output: str | None = Field(None, description="sweep directory; default sweeps/<name>")
    overrides: dict[str, Any] = Field(default_factory=dict, description="config keys set for every point")
    axes: dict[str, list[Any] | Range] = Field(default_factory=dict)
    resolution: list[Annotated[float, Field(gt=0)]] | None = Field(
        None, description="a resolution ladder, hydro.cells_per_projectile_radius of each rung: every point runs at "
                          "each, and Q*_D (qstar mode) gets a resolution error from it (qstar_resolution.csv)")
    mode: Literal["grid", "qstar"] = "grid"
    qstar: QStarSearch = Field(default_factory=QStarSearch)
    execution: Execution = Field(default_factory=Execution)
    stage_functions: dict[str, str] = Field(default_factory=dict,
                                            description="replace stages by 'package.module:function'")
    replicates: dict[str, list[Any]] = Field(
        default_factory=dict, description="run every point once per combination of these values "
                                          f"(keys: {', '.join(REPLICATE_KEYS)}) and average M_lr/M_T over them")

    @model_validator(mode="after")
    def _replicates_valid(self) -> "SweepSpec":
        for key, values in self.replicates.items():
            if key not in REPLICATE_KEYS:
                raise ValueError(f"replicates: {key} cannot be replicated (allowed: {', '.join(REPLICATE_KEYS)}; "
                                 "other keys change the impact: make them an axis)")
            if not values or len({repr(v) for v in values}) != len(values):
                raise ValueError(f"replicates: {key} needs a list of distinct values (got {values})")
            if key in self.axes or key in self.overrides:
                raise ValueError(f"replicates: {key} is also in {'axes' if key in self.axes else 'overrides'}")
        if "handoff.time" in self.replicates:
            clash = [k for k in HANDOFF_TIME_KEYS if k in self.axes or k in self.overrides]
            if clash:
                raise ValueError(f"replicates: handoff.time runs the hydro stage to the latest time with a snapshot "
                                 f"at each, so {' and '.join(clash)} cannot be set in axes or overrides")
        return self

    @model_validator(mode="after")
    def _resolution_valid(self) -> "SweepSpec":
        if self.resolution is None:
            return self
        if len(set(self.resolution)) != len(self.resolution) or len(self.resolution) < 2:
            raise ValueError(f"resolution: needs at least two distinct values (got {self.resolution})")
        if RESOLUTION_KEY in self.axes or RESOLUTION_KEY in self.overrides:
            raise ValueError(f"resolution: {RESOLUTION_KEY} is also in "
                             f"{'axes' if RESOLUTION_KEY in self.axes else 'overrides'}")
        return self

    def axis_values(self) -> dict[str, list[Any]]:
        """Each axis as a list of values; a ``resolution`` ladder is the axis of
        hydro.cells_per_projectile_radius."""
        axes = {k: (v.values() if isinstance(v, Range) else list(v)) for k, v in self.axes.items()}
        if self.resolution is not None:
            axes[RESOLUTION_KEY] = list(self.resolution)
        return axes


class SweepError(ValueError):
    """Invalid sweep file or point configs; ``messages`` holds one line per problem."""

    def __init__(self, messages: list[str]):
        self.messages = messages
        super().__init__("\n".join(messages))


@dataclass
class Sweep:
    """A validated sweep: its spec, base config text and directory."""

    spec: SweepSpec
    base_text: str
    base_path: Path
    directory: Path
    source: Path

    def config_for(self, params: dict[str, Any]) -> Config:
        """The validated config of one point (raises ConfigError)."""
        overrides = {**self.spec.overrides, **params}
        return parse_config(self.base_text, source=self.base_path, overrides=overrides)

    def snapshots(self, params: dict[str, Any]) -> list[float]:
        """Snapshot times (s) of the hydro run of the point ``params`` (with no hand-off-time settings)."""
        config = self.config_for(params)
        return snapshot_times(config, derive(config)["end_time"])

    def replicate_runs(self, point: dict[str, Any]) -> list[dict[str, Any]]:
        """The runs of one point (:func:`with_replicates`); ``handoff.time`` replicates that are
        all snapshots of the point's own hydro run share that run as it is."""
        replicates = self.spec.replicates
        snapshots = self.snapshots(point) if "handoff.time" in replicates else None
        return with_replicates(point, replicates, snapshots)


def load_sweep(path: str | Path, output: str | Path | None = None, execution: dict[str, Any] | None = None) -> Sweep:
    """Read and validate a sweep file and the base config of every grid point (raises SweepError).
    ``execution``: settings of the file's ``execution`` given elsewhere (the command line), which
    win over the file's; with ``ranks_per_run`` > 1 the points must be able to run on several
    MPI ranks (:func:`ranks_problems`)."""
    path = Path(path)
    try:
        text = read_yaml_text(path, "sweep file")
        data = load_yaml(text)
    except ConfigError as exc:
        raise SweepError(exc.messages) from None
    except yaml.YAMLError as exc:
        raise SweepError([f"{path}: not valid YAML: {exc}"]) from exc
    if not isinstance(data, dict):
        raise SweepError([f"{path}: a sweep file must be a mapping of keys"])
    if execution and isinstance(data.get("execution") or {}, dict):
        data["execution"] = {**(data.get("execution") or {}), **execution}
    root = yaml.compose(text)
    lines = _LineFinder(path, root)
    found = duplicate_keys(root, path) + [lines.format(loc, msg) for loc, msg in unknown_keys(data, SweepSpec)]
    try:
        spec = SweepSpec.model_validate(data)
    except ValidationError as exc:
        found += [lines.format(tuple(e["loc"]), e["msg"]) for e in exc.errors() if e["type"] != "extra_forbidden"]
        raise SweepError(found) from None
    if found:
        raise SweepError(found)
    known = key_paths()
    for key in list(spec.axes) + list(spec.overrides):
        pattern = re.sub(r"^materials\.[^.]+\.", "materials.<name>.", key)
        if key not in known and pattern not in known:
            where = "axes" if key in spec.axes else "overrides"
            raise SweepError([lines.format((where, key), "not a config key (see docs/config.md)")])
    base_path = (path.parent / spec.base).resolve()
    if not base_path.is_file():
        raise SweepError([lines.format(("base",), f"cannot read base config {base_path}: no such file")])
    try:
        base_text = read_yaml_text(base_path, "base config")
    except ConfigError as exc:
        raise SweepError(exc.messages) from None
    directory = Path(output or spec.output or Path("sweeps") / spec.name)
    sweep = Sweep(spec=spec, base_text=base_text, base_path=base_path, directory=directory, source=path)
    messages = []
    for params in (p for point in grid_points(sweep) for p in sweep.replicate_runs(point)):
        try:
            checks.check(sweep.config_for(params))
        except ConfigError as exc:
            label = ", ".join(f"{k}={v}" for k, v in params.items())
            messages += [f"point {label}: {m}" for m in exc.messages]
    messages += [lines.format(loc, message) for loc, message in ranks_problems(spec.execution)]
    if messages:
        raise SweepError(messages)
    return sweep


def ranks_problems(execution: Execution) -> list[tuple[tuple, str]]:
    """Why the points cannot run on ``execution.ranks_per_run`` MPI ranks, as (key path,
    message) (empty with one rank, or when they can): mpi4py or the launcher missing on this
    machine."""
    nranks = execution.ranks_per_run
    if nranks == 1:
        return []
    problems = []
    if not ranks.mpi_installed():
        problems.append((("execution", "ranks_per_run"),
                         f"{nranks} ranks per run need mpi4py and an MPI library: {ranks.INSTALL_HINT}"))
    else:
        try:
            ranks.launcher_path(execution.launcher)
        except ranks.RanksUnavailable as exc:
            problems.append((("execution", "launcher"), str(exc)))
    return problems


def grid_points(sweep: Sweep) -> list[dict[str, Any]]:
    """Parameter dicts of the grid (in qstar mode: one per group, with the bracket's low end)."""
    axes = sweep.spec.axis_values()
    if sweep.spec.mode == "qstar":
        axes.pop(sweep.spec.qstar.variable, None)
    keys = list(axes)
    points = [dict(zip(keys, combo)) for combo in itertools.product(*(axes[k] for k in keys))]
    if sweep.spec.mode == "qstar" and sweep.spec.qstar.bracket is not None:
        points = [{**p, sweep.spec.qstar.variable: sweep.spec.qstar.bracket[0]} for p in points]
    return points


def handoff_time_params(times: list[float], snapshots: list[float] | None = None) -> dict[str, Any]:
    """Hydro settings that let one hydro run serve hand-offs at each of ``times`` (s): the
    stage runs to the latest time with a snapshot at every one.  When ``snapshots`` (the
    snapshot times the point's hydro run writes without these settings) already hold every
    time, nothing is set: that hydro run serves them as it is, and a finished one is reused."""
    times = sorted(float(t) for t in times)
    if snapshots is not None and all(snapshot_at(snapshots, t) is not None for t in times):
        return {}
    return {"hydro.end_time": times[-1], "hydro.output_times": times}


def with_replicates(point: dict[str, Any], replicates: dict[str, list[Any]],
                    snapshots: list[float] | None = None) -> list[dict[str, Any]]:
    """The runs of one point: one per combination of the ``replicates`` values (the point
    itself when there are none).  ``handoff.time`` replicates also get
    :func:`handoff_time_params` (with the point's own ``snapshots``, if given), so they share
    one hydro run like a hand-off scan."""
    keys = list(replicates)
    runs = [{**point, **dict(zip(keys, combo))} for combo in itertools.product(*(replicates[k] for k in keys))]
    if "handoff.time" in replicates:
        shared = handoff_time_params(replicates["handoff.time"], snapshots)
        runs = [{**run, **shared} for run in runs]
    return runs


def point_name(params: dict[str, Any], config: Config) -> str:
    """Run-directory name: the parameters, then a content hash of the whole config."""
    digest = stage_hashes(config)[STAGES[-1]][:10]
    parts = []
    for key, value in params.items():
        text = f"{value:.6g}" if isinstance(value, float) else str(value)
        parts.append(f"{key.split('.')[-1]}={text}")
    label = re.sub(r"[^A-Za-z0-9_.=+-]", "-", "_".join(parts))[:120]
    return f"{label}-{digest}" if label else digest


# --------------------------------------------------------------------------- one point


@dataclass
class PointJob:
    """Everything a worker needs to run one point (picklable)."""

    name: str
    params: dict[str, Any]
    config: Config
    run_dir: str
    reuse_dir: str | None
    threads: int
    stage_functions: dict[str, str]
    ranks: int = 1
    launcher: str = "mpiexec"
    launcher_options: list[str] = field(default_factory=list)


@dataclass
class PointResult:
    name: str
    status: str
    summary: dict[str, Any] = field(default_factory=dict)
    error: str | None = None
    wall_seconds: float = 0.0


class PointFailed(RuntimeError):
    """A point's run raised; the message names the point, the error and its log file."""


def run_point(job: PointJob) -> PointResult:
    """Run one point in a worker: adopt shared stages, run the pipeline, log to run.log
    (:func:`impactpipe.pipeline.runstore.run_log`).  The point holds its run directory's lock
    throughout; a directory another process still holds (a worker of a sweep that was killed,
    finishing its stage) is waited for, so no point ever runs twice at the same time.  With
    ``job.ranks`` > 1 the run goes to that many MPI ranks (:func:`_run_on_ranks`)."""
    run_dir = Path(job.run_dir)
    t0 = time.perf_counter()
    if job.ranks > 1:
        summary = _run_on_ranks(job, run_dir)
    else:
        _set_threads(job.threads)
        with run_lock(run_dir, wait=True, what=f"point {job.name}"), runstore.run_log(run_dir):
            summary = _run_logged(job, run_dir)
    return PointResult(job.name, "complete", summary, None, time.perf_counter() - t0)


def _adopt_shared(job: PointJob, run_dir: Path) -> None:
    """Adopt the finished stages of the point (or donor run) this point shares them with, if any."""
    if job.reuse_dir:
        adopted = adopt_stages(run_dir, Path(job.reuse_dir), job.config)
        if adopted:
            log.info("%s: reused %s from %s", job.name, ", ".join(adopted), job.reuse_dir)


def _run_logged(job: PointJob, run_dir: Path) -> dict[str, Any]:
    """The body of :func:`run_point`, inside its run log: adopt shared stages, run the pipeline;
    a failure writes ``error.log`` and raises PointFailed."""
    from . import stages

    try:
        _adopt_shared(job, run_dir)
        return stages.run(job.config, run_dir, show_progress=False, stage_functions=job.stage_functions or None)
    except Exception as exc:
        if isinstance(exc, stages.StageInterrupted) and multiprocessing.parent_process() is not None:
            # a signal stopped the stage, which recorded itself as interrupted: the sweep is
            # being stopped (:func:`_stop_pool_workers`), so this pool worker takes no further point
            # (the run log's records are already flushed)
            log.warning("%s: interrupted; this worker stops", job.name)
            os._exit(1)
        (run_dir / "error.log").write_text(traceback.format_exc())
        raise PointFailed(f"{job.name}: {type(exc).__name__}: {exc} (log: {run_dir / 'error.log'})") from None


#: Lines of a failed launch's output that the point's error message ends with.
OUTPUT_TAIL_LINES = 12
#: Seconds between a local worker's checks that its point's ranks have exited (:func:`_wait_passing_on_stop`).
STOP_POLL = 0.1


def _run_on_ranks(job: PointJob, run_dir: Path) -> dict[str, Any]:
    """A point on ``job.ranks`` MPI ranks: holding the run directory's lock (waiting for an earlier
    holder), adopt the shared stages and write the point's config there
    (``config.resolved.yaml``, the file every run writes); then, the lock released, run
    ``impactpipe run`` of that config through the launcher (:func:`impactpipe.pipeline.ranks.
    launch_command`, ``NUMBA_NUM_THREADS`` = ``job.threads`` on each rank), whose rank 0 takes
    the lock and writes run.log as a single process would, and wait for it
    (:func:`_wait_passing_on_stop`).  Returns the run's summary.  A launch that fails writes its
    output to ``error.log`` and raises PointFailed with the end of it; a pool worker that
    passed a stop on exits once the ranks have stopped (as in :func:`_run_logged`)."""
    with run_lock(run_dir, wait=True, what=f"point {job.name}"), runstore.run_log(run_dir):
        _adopt_shared(job, run_dir)
        storage.write_text_atomic(run_dir / RESOLVED_CONFIG_FILE, resolved_yaml(job.config))
    arguments = ["run", str(run_dir / RESOLVED_CONFIG_FILE), "--out", str(run_dir), "--quiet",
                 *(f"--stage-function={stage}={function}" for stage, function in job.stage_functions.items())]
    try:
        command = ranks.launch_command(job.ranks, arguments, job.launcher, job.threads, job.launcher_options)
    except ranks.RanksUnavailable as exc:
        raise PointFailed(f"{job.name}: {exc}") from None
    with tempfile.TemporaryFile("w+") as output:
        process = subprocess.Popen(command, env=ranks.rank_environment(job.ranks, job.threads),
                                   stdin=subprocess.DEVNULL, stdout=output, stderr=subprocess.STDOUT,
                                   start_new_session=True)
        stop = _wait_passing_on_stop(process)
        output.seek(0)
        text = output.read()
    if stop is not None and multiprocessing.parent_process() is not None:
        log.warning("%s: %s passed on to its ranks, which stopped (%s); this worker stops", job.name, stop,
                    exit_text(process.returncode))
        os._exit(1)
    if process.returncode != 0:
        (run_dir / "error.log").write_text(text)
        tail = "\n".join(text.strip().splitlines()[-OUTPUT_TAIL_LINES:])
        raise PointFailed(f"{job.name}: {job.launcher} -n {job.ranks} ended with {exit_text(process.returncode)}: "
                          f"{tail} (log: {run_dir / 'error.log'})")
    return read_summary(run_dir)


def _wait_passing_on_stop(process: subprocess.Popen) -> str | None:
    """Wait for the launched ranks.  In the main thread (a local pool's worker) the first SIGINT or
    SIGTERM this process gets (the sweep stopping its workers, :func:`_stop_pool_workers`, or
    gone, :func:`_watch_sweep`) is passed on to the launcher as SIGTERM, so rank 0 ends its step,
    keeps its checkpoint and stops the run; later ones are ignored (a second would stop the
    ranks at once).  The launcher runs in a session of its own, so a Ctrl-C at the terminal
    reaches the ranks only this way.  Returns the name of the signal passed on, or None."""
    if threading.current_thread() is not threading.main_thread():
        process.wait()
        return None
    stop: list[str] = []

    def pass_on(signum, frame):
        if not stop:
            stop.append(signal.Signals(signum).name)
            process.send_signal(signal.SIGTERM)

    previous = {signum: signal.signal(signum, pass_on) for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        # not process.wait(): the kernel may hand the signal to another thread (the sweep watcher),
        # and the handler runs only once the main thread runs again, which a blocked wait never does
        while process.poll() is None:
            time.sleep(STOP_POLL)
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    return stop[0] if stop else None


def _set_threads(threads: int) -> None:
    import numba

    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


def _init_worker(threads: int, sweep_pid: int) -> None:
    """Pool-worker initializer: give numba ``threads`` threads and watch the sweep process
    ``sweep_pid`` (:func:`_watch_sweep`).

    Unpickling this function imports numba (through this module), which reads
    NUMBA_NUM_THREADS (default: all cores) at import; the config is re-read here so the
    threads numba later starts match the value that its next compile will read again
    (otherwise that compile raises "Cannot set NUMBA_NUM_THREADS to a different value").
    """
    os.environ["NUMBA_NUM_THREADS"] = str(threads)
    if "numba" in sys.modules:
        from numba.core import config

        config.reload_config()
    threading.Thread(target=_watch_sweep, args=(sweep_pid,), name="watch-sweep", daemon=True).start()


#: Seconds between a pool worker's checks that the sweep process is alive.
SWEEP_POLL = 0.5
#: Seconds an orphaned worker's stage gets to stop cleanly before the worker exits regardless.
ORPHAN_GRACE = 30.0


def _watch_sweep(sweep_pid: int) -> None:
    """Stop this pool worker once the sweep process ``sweep_pid`` is gone (killed, even with
    SIGKILL, which leaves it no chance to stop its workers): the worker is re-parented, so
    its parent pid changes.  The worker SIGTERMs itself, so a stage in flight stops as on
    a polite stop (recorded interrupted, checkpoint kept; :func:`run_point` then exits), and
    an idle worker ends; after ORPHAN_GRACE seconds it exits regardless.  Until it has exited
    it holds its point's lock, which a restarted sweep waits for."""
    while os.getppid() == sweep_pid:
        time.sleep(SWEEP_POLL)
    log.warning("the sweep process %d is gone; pool worker %d stops", sweep_pid, os.getpid())
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(ORPHAN_GRACE)
    os._exit(1)


# --------------------------------------------------------------------------- coordinator


class SweepRunner:
    """Runs the points of a sweep on an executor, with shared work, retries and resume."""

    def __init__(self, sweep: Sweep, executor: cf.Executor, progress: Any = None, own_pool: bool = False,
                 report: Callable[[str], None] | None = None):
        """``own_pool``: ``executor`` is the local pool :func:`make_executor` sized from the
        sweep's execution settings (it bounds :meth:`in_flight_limit`).  ``report`` gets one
        line when a point starts and one when it ends (for a log where no bar is shown)."""
        self.sweep = sweep
        self.executor = executor
        self.own_pool = own_pool
        self.progress = progress
        self.report = report or (lambda line: None)
        self.points: dict[str, dict[str, Any]] = {}
        self._configs: dict[str, Config] = {}
        self.runs_dir = sweep.directory / "runs"
        self.donors: dict[str, str] = {}

    # -- bookkeeping

    def _record(self, name: str, **fields_: Any) -> None:
        self.points.setdefault(name, {}).update(fields_)
        storage.write_json_atomic(self.sweep.directory / POINTS_FILE, self.points)

    def mark_interrupted(self) -> None:
        """Points still marked running when the runner stops (an interrupt, an error) did not
        finish: record them as interrupted, so ``points.json`` and ``sweep-status`` tell the truth."""
        left = [name for name, p in self.points.items() if p.get("status") == "running"]
        for name in left:
            self.points[name]["status"] = "interrupted"
        if left:
            storage.write_json_atomic(self.sweep.directory / POINTS_FILE, self.points)

    def add_point(self, params: dict[str, Any], group: str = "", replicate_of: dict[str, Any] | None = None) -> str:
        """Register a point; returns its name.  ``replicate_of``: the parameters of the point
        this run replicates (``params`` without the replicate keys)."""
        config = self.sweep.config_for(params)
        name = point_name(params, config)
        if name not in self.points:
            self.points[name] = {"params": params, "group": group, "run_dir": str(self.runs_dir / name),
                                 "hydro_hash": stage_hashes(config)["hydro"], "status": "pending",
                                 "attempts": 0, "replicate_of": params if replicate_of is None else replicate_of}
            self._configs[name] = config
        return name

    def add_replicates(self, point: dict[str, Any], group: str = "") -> list[str]:
        """Register the runs of one point (:func:`with_replicates`); returns their names."""
        return [self.add_point(run, group, point) for run in self.sweep.replicate_runs(point)]

    def add_donor(self, run_dir: str | Path) -> bool:
        """Offer a finished run from outside the sweep: points with its hydro hash adopt its hydro
        run (and its hand-off where that matches too) instead of running their own, unless a
        point of theirs has one already.  Returns False if its hydro stage is not complete."""
        record = read_records(Path(run_dir)).get("hydro", {})
        if record.get("status") != "complete" or not record.get("hash"):
            return False
        self.donors[record["hash"]] = str(Path(run_dir).resolve())
        return True

    def offer_earlier_runs(self) -> int:
        """Offer every finished hydro run already in ``runs/`` as a donor (:meth:`add_donor`):
        a point whose directory name changed (a new config key, another N-body or hand-off
        setting) still adopts the hydro run of an earlier point with the same hydro settings
        instead of running it again.  Returns how many were offered."""
        if not self.runs_dir.is_dir():
            return 0
        return sum(self.add_donor(d) for d in sorted(self.runs_dir.iterdir()) if d.is_dir())

    def _is_done(self, name: str) -> bool:
        run_dir = Path(self.points[name]["run_dir"])
        if not run_dir.is_dir():
            return False
        return all(reason.startswith("skip") for _, reason in plan(self._configs[name], run_dir))

    # -- execution

    def run_points(self, names: list[str]) -> dict[str, PointResult]:
        """Run the named points (skipping finished ones), sharing hydro + hand-off within groups."""
        results: dict[str, PointResult] = {}
        todo = []
        for name in names:
            if self._is_done(name):
                results[name] = PointResult(name, "complete", read_summary(self.points[name]["run_dir"]))
                self._record(name, status="complete", summary=_results_of(results[name].summary))
            else:
                todo.append(name)
        if self.progress is not None:
            self.progress.total = (self.progress.total or 0) + len(todo)
            self.progress.refresh()
        source_of = self._shared_sources(names)
        waiting = {n for n in todo if source_of.get(n) and source_of[n] in todo and source_of[n] != n}
        # at most in_flight_limit() jobs are handed to the executor at a time, and points whose
        # shared run just finished go first: their (cheap) downstream stages do not queue behind
        # every other hydro run, so a point's replicates finish together
        fresh = [(name, source_of.get(name), True) for name in todo if name not in waiting]
        released: list[tuple[str, str | None, bool]] = []  # (name, point it reuses, a new attempt)
        running: dict[cf.Future, tuple[str, str | None]] = {}
        limit = self.in_flight_limit()

        def finish(name: str, result: PointResult) -> None:
            results[name] = result
            if self.progress is not None:
                self.progress.update(1)
            for other in sorted(waiting):
                if source_of[other] == name:
                    waiting.discard(other)
                    reuse = name if result.status == "complete" or self._has_shared(name) else None
                    released.append((other, reuse, True))

        def collect(future: cf.Future) -> None:
            name, reuse = running.pop(future)
            result = self._collect(name, future)
            if result is None:
                released.insert(0, (name, reuse, True))
            else:
                finish(name, result)

        def replace_pool() -> None:
            exits = self.executor.replace()  # every future of the broken pool is settled now
            broken = [f for f in running if isinstance(f.exception(), BrokenProcessPool)]
            for future in [f for f in running if f not in broken]:
                collect(future)  # finished before its pool broke
            again, failed = self._after_worker_death(exits, [running.pop(f) for f in broken])
            released[:0] = [(name, reuse, False) for name, reuse in again]
            for result in failed:
                finish(result.name, result)

        def fill() -> None:
            while len(running) < limit and (released or fresh):
                item = released.pop(0) if released else fresh.pop(0)
                try:
                    running[self._submit(*item)] = item[:2]
                except BrokenProcessPool:  # a worker died since the last wait: this point did not start
                    released.insert(0, item)
                    replace_pool()

        fill()
        while running:
            done, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
            for future in done:
                if future not in running:
                    continue  # failed with its broken pool, already run again
                if isinstance(self.executor, LocalPool) and isinstance(future.exception(), BrokenProcessPool):
                    replace_pool()
                else:
                    collect(future)
            fill()
        return results

    def _after_worker_death(self, exits: dict[int, int | None], in_flight: list[tuple[str, str | None]]) -> tuple[
            list[tuple[str, str | None]], list[PointResult]]:
        """A worker of the local pool died and the pool was replaced (:meth:`LocalPool.replace`, which
        gave the old workers' ``exits``): sort the points that were in flight, (name, point it
        reuses), into (to run again, failed), and log and report the death.

        A point is not at fault for the pool breaking, so running it again spends none of its
        ``execution.retries``; it resumes from its checkpoints.  The death is counted against
        the point whose worker died, found by the process id in its run directory's lock
        (:func:`impactpipe.pipeline.lock.recorded_holder`), or against every point in flight
        when the dead worker held none (it died starting); a point counted MAX_WORKER_DEATHS
        times (one that kills its worker: a crash in compiled code, out of memory) fails."""
        deaths = {pid: code for pid, code in exits.items() if code not in POOL_STOP_EXITS}
        holders = {name: recorded_holder(self.points[name]["run_dir"]).get("pid") for name, _ in in_flight}
        culprits = {name for name, pid in holders.items() if pid in deaths}
        blamed = culprits or ({name for name, _ in in_flight} if deaths else set())
        stopped = deaths or exits
        died = ", ".join(f"{pid} ({exit_text(code)})" for pid, code in stopped.items())
        where = f"running point {', '.join(sorted(culprits))}" if culprits else "holding no point"
        log.warning("a worker of the local pool %s (process %s, %s); a new pool (replacement %d) runs the "
                    "point(s) in flight again (%d)", "died" if deaths else "stopped", died, where,
                    self.executor.replacements, len(in_flight))
        self.report(f"pool worker {'died' if deaths else 'stopped'} (process {died}, {where}): new pool started")
        again, failed = [], []
        for name, reuse in in_flight:
            count = self.points[name].get("worker_deaths", 0) + (name in blamed)
            if count < MAX_WORKER_DEATHS:
                self._record(name, status="retrying", worker_deaths=count)
                self.report(f"point {name}: running again on the new pool (deaths of its worker: {count})")
                again.append((name, reuse))
                continue
            last = exit_text(deaths[holders[name]]) if name in culprits else f"process {died}"
            message = (f"{name}: its pool worker died {count} times while running it (the last: {last}); "
                       "a point that kills its worker (a crash in compiled code, out of memory) is not run again")
            log.error("point %s failed: %s", name, message)
            self._record(name, status="failed", worker_deaths=count, error=message)
            self.report(f"point {name}: failed: {message}")
            failed.append(PointResult(name, "failed", {}, message))
        return again, failed

    def in_flight_limit(self) -> int:
        """Jobs handed to the executor at a time: ``execution.workers`` when set, else the workers
        of a local pool made from the sweep's settings (:meth:`Execution.default_workers`, as
        :func:`make_executor` sizes it); unbounded for Dask, whose scheduler queues by itself,
        and for an executor passed in without ``workers`` (its size is not known here)."""
        execution = self.sweep.spec.execution
        if execution.backend == "dask":
            return 1 << 30
        if execution.workers:
            return execution.workers
        return execution.default_workers() if self.own_pool else 1 << 30

    def _shared_sources(self, names: list[str]) -> dict[str, str]:
        """For each point, the point whose finished stages it reuses: the first of the points with
        the same hydro hash (it adopts the hydro run, and the hand-off too when that matches), or
        the directory of a donor run (:meth:`add_donor`) when no point of the group has one."""
        first: dict[str, str] = {}
        for name in names:
            first.setdefault(self.points[name]["hydro_hash"], name)
        for name in names:
            if self._has_shared(name):
                first[self.points[name]["hydro_hash"]] = name
        sources = {}
        for name in names:
            hydro = self.points[name]["hydro_hash"]
            own = first[hydro]
            sources[name] = self.donors[hydro] if hydro in self.donors and not self._has_shared(own) else own
        return sources

    def _has_shared(self, name: str) -> bool:
        records_path = Path(self.points[name]["run_dir"]) / "stages.json"
        if not records_path.is_file():
            return False
        records = json.loads(records_path.read_text())
        return records.get("hydro", {}).get("status") == "complete"

    def _submit(self, name: str, reuse: str | None, new_attempt: bool = True) -> cf.Future:
        """Hand the point to the executor; ``new_attempt`` False: it runs again after its worker
        died (:meth:`_after_worker_death`), which counts no attempt."""
        point = self.points[name]
        if reuse in self.points:
            reuse_dir = self.points[reuse]["run_dir"] if reuse != name else None
        else:
            reuse_dir = reuse  # a donor run's directory, or None
        execution = self.sweep.spec.execution
        job = PointJob(name, point["params"], self._configs[name], point["run_dir"], reuse_dir,
                       execution.threads_per_run, self.sweep.spec.stage_functions, execution.ranks_per_run,
                       execution.launcher, execution.launcher_options)
        future = self.executor.submit(run_point, job)
        self._record(name, status="running", attempts=point["attempts"] + new_attempt, error=None,
                     host=socket.gethostname(), pid=os.getpid())
        self.report(f"point {name}: {'started' if new_attempt else 'started again'} (attempt {point['attempts']})")
        return future

    def _collect(self, name: str, future: cf.Future) -> PointResult | None:
        """The point's result, or None when it failed and will be retried."""
        try:
            result = future.result()
        except Exception as exc:
            attempts = self.points[name]["attempts"]
            message = str(exc) if isinstance(exc, PointFailed) else f"{type(exc).__name__}: {exc}"
            if attempts <= self.sweep.spec.execution.retries:
                log.warning("point %s failed (attempt %d), retrying: %s", name, attempts, message)
                self._record(name, status="retrying", error=message)
                self.report(f"point {name}: failed (attempt {attempts}), will retry")
                return None
            log.error("point %s failed after %d attempts: %s", name, attempts, message)
            self._record(name, status="failed", error=message)
            self.report(f"point {name}: failed after {attempts} attempts: {message}")
            return PointResult(name, "failed", {}, message)
        self._record(name, status="complete", error=None, wall_seconds=result.wall_seconds,
                     summary=_results_of(result.summary))
        answer = result.summary.get("M_lr_over_M_T")
        self.report(f"point {name}: complete in {result.wall_seconds:.1f} s"
                    + (f", M_lr/M_T = {answer:.4g}" if isinstance(answer, (int, float)) else ""))
        return result

    # -- modes

    def run_grid(self) -> None:
        names = [name for p in grid_points(self.sweep) for name in self.add_replicates(p)]
        self.run_points(names)

    def run_qstar(self) -> list[dict[str, Any]]:
        """Bisection per group; returns one Q*_D record per group."""
        spec = self.sweep.spec.qstar
        axes = self.sweep.spec.axis_values()
        axes.pop(spec.variable, None)
        keys = list(axes)
        groups = [dict(zip(keys, combo)) for combo in itertools.product(*(axes[k] for k in keys))]
        state = []
        for group in groups:
            low, high = spec.bracket or initial_bracket(self.sweep.config_for(group), spec.variable)
            state.append({"group": group, "label": _label(group), "low": low, "high": high, "f": {}, "sem": {},
                          "rounds": 0, "expansions": 0, "status": "searching"})
        pending = {i: [s["low"], s["high"]] for i, s in enumerate(state)}
        for _ in range(spec.max_rounds + spec.max_expansions + 1):
            if not pending:
                break
            self._evaluate(state, pending)
            pending = {}
            for i, s in enumerate(state):
                if s["status"] != "searching":
                    continue
                s["rounds"] += 1
                nxt = bisection_step(s, spec)
                if nxt is not None:
                    pending[i] = nxt
        return [self._group_record(s) for s in state]

    def _evaluate(self, state: list[dict[str, Any]], pending: dict[int, list[float]]) -> None:
        """Run the pending values of each group; a value's M_lr/M_T is the mean over its
        finished replicates (NaN when none finished), and its standard error std / sqrt(n)
        (ddof 1; 0 with fewer than two) goes to the group's ``sem``."""
        variable = self.sweep.spec.qstar.variable
        names = {}
        for i, values in pending.items():
            for value in values:
                if value not in state[i]["f"]:
                    point = {**state[i]["group"], variable: value}
                    for name in self.add_replicates(point, state[i]["label"]):
                        names[name] = (i, value)
        results = self.run_points(list(names))
        answers: dict[tuple[int, float], list[float]] = {}
        for name, (i, value) in names.items():
            summary = results[name].summary if results[name].status == "complete" else {}
            answers.setdefault((i, value), []).append(summary.get("M_lr_over_M_T", float("nan")))
        for (i, value), mlr in answers.items():
            finished = [m for m in mlr if np.isfinite(m)]
            if 0 < len(finished) < len(mlr):
                log.warning("%s=%s of %s: %d of %d replicates finished; M_lr/M_T is their mean", variable, value,
                            state[i]["label"], len(finished), len(mlr))
            state[i]["f"][value] = float(np.mean(finished)) if finished else float("nan")
            state[i]["sem"][value] = float(np.std(finished, ddof=1) / math.sqrt(len(finished))) \
                if len(finished) >= 2 else 0.0

    def _group_record(self, s: dict[str, Any]) -> dict[str, Any]:
        from impactpipe.analysis.qstar import fit_qstar

        runs = [p for p in self.points.values() if p["group"] == s["label"] and p["status"] == "complete"]
        record = {**s["group"], "low": s["low"], "high": s["high"], "rounds": s["rounds"], "status": s["status"],
                  "runs": len(runs), "bisection_estimate": _interpolate(s, self.sweep.spec.qstar.target)}
        q = np.array([p["summary"].get("Q", np.nan) for p in runs], dtype=float)
        mlr = np.array([p["summary"].get("M_lr_over_M_T", np.nan) for p in runs], dtype=float)
        n_lr = np.array([p["summary"].get("N_lr", 10 ** 6) for p in runs], dtype=float)
        ok = np.isfinite(q) & np.isfinite(mlr)
        try:
            fit = fit_qstar(q[ok], mlr[ok], n_lr[ok])
            record.update({"Qstar_D": fit.qstar, "Qstar_D_uncertainty": fit.qstar_err,
                           "slope_vs_Q_over_Qstar": fit.normalized_slope, "brackets": fit.brackets,
                           "replicates_per_value": len(with_replicates({}, self.sweep.spec.replicates)),
                           "replicate_std": fit.replicate_std})
        except (ValueError, np.linalg.LinAlgError) as exc:
            record.update({"Qstar_D": float("nan"), "fit_error": str(exc)})
        record.update(handoff_time_fields(runs))
        return record


def handoff_time_fields(points: list[dict[str, Any]]) -> dict[str, Any]:
    """Fields of a Q*_D record from finished points handed off at several times (``replicates:
    handoff.time``): Q*_D fitted at each time (``Qstar_D_t<T>``), their mean and standard
    deviation (``Qstar_D_handoff_mean``, ``Qstar_D_handoff_error``, the hand-off-time error),
    the slope against the time and its error (J/kg/s) and ``handoff_status`` (plateau, trend or
    two times; :mod:`impactpipe.analysis.handoff_error`).  Empty for points of one hand-off time."""
    from impactpipe.analysis.handoff_error import fit_by_handoff_time

    times = [p["params"].get("handoff.time") for p in points]
    if None in times or len(set(times)) < 2:
        return {}
    result, problems = fit_by_handoff_time(times, *([p["summary"].get(k, default) for p in points]
                                                    for k, default in (("Q", np.nan), ("M_lr_over_M_T", np.nan),
                                                                       ("N_lr", 10 ** 6))))
    for line in problems:
        log.warning("%s", line)
    if result is None:
        return {"handoff_status": "; ".join(problems)}
    return {"Qstar_D_handoff_mean": result.mean, "Qstar_D_handoff_error": result.error,
            "Qstar_D_handoff_slope": result.slope, "Qstar_D_handoff_slope_err": result.slope_err,
            "handoff_status": result.status,
            **{f"Qstar_D_t{t:g}": q for t, q in zip(result.times, result.qstar)}}


def initial_bracket(config: Config, variable: str) -> tuple[float, float]:
    """(low, high) around the published Q*_D of the target (Benz & Asphaug 1999 basalt law).

    The law's Q*_D gives the critical velocity v = sqrt(2 Q*_D M_T / m_p) or projectile
    radius r = R_T (2 Q*_D rho_T / (rho_p v^2))^(1/3); the bracket spans a factor 2 each side.
    """
    from impactpipe.analysis.energies import benz_asphaug_1999

    from . import derived

    values = derived.derive(config)
    scene = config.scene
    qstar = float(benz_asphaug_1999(scene.target.radius, values["target_reference_density"]))
    if variable == "scene.impact.velocity":
        centre = math.sqrt(2.0 * qstar * values["target_mass"] / values["projectile_mass"])
    else:
        rho_p = values["projectile_mass"] / (4.0 / 3.0 * math.pi * scene.projectile.radius ** 3)
        centre = (2.0 * qstar * values["target_mass"] / (4.0 / 3.0 * math.pi * rho_p * scene.impact.velocity ** 2)) ** (1 / 3)
        centre = min(centre, scene.target.radius / 2.0)
    return centre / 2.0, centre * 2.0


def bisection_step(s: dict[str, Any], spec: QStarSearch) -> list[float] | None:
    """Update a group's bracket from its evaluations; return the next values to run, or None when done.

    M_lr/M_T falls as velocity or projectile radius grows, so the bracket holds
    f(low) > target > f(high).  A bracket that does not bracket is widened by 2x.  With
    replicates, a midpoint whose mean lies within ``noise_sigmas`` standard errors of the
    target cannot tell on which side the crossing is: the search stops there
    (``noise_limited``; more rounds would bisect the scatter, not the crossing).
    """
    f_low, f_high = s["f"].get(s["low"], np.nan), s["f"].get(s["high"], np.nan)
    if not (np.isfinite(f_low) and np.isfinite(f_high)):
        s["status"] = "failed: a bracket point did not finish"
        return None
    if f_low < spec.target or f_high > spec.target:
        if s["expansions"] >= spec.max_expansions:
            s["status"] = "not bracketed"
            return None
        s["expansions"] += 1
        if f_low < spec.target:
            s["low"], s["high"] = s["low"] / 2.0, s["low"]
        else:
            s["low"], s["high"] = s["high"], s["high"] * 2.0
        return [s["low"], s["high"]]
    mids = [v for v in s["f"] if s["low"] < v < s["high"] and np.isfinite(s["f"][v])]
    for v in sorted(mids):
        if s["f"][v] >= spec.target:
            s["low"] = max(s["low"], v)
        else:
            s["high"] = min(s["high"], v)
    if any(abs(s["f"][v] - spec.target) <= spec.noise_sigmas * s.get("sem", {}).get(v, 0.0) for v in mids):
        s["status"] = "noise_limited"
        return None
    width = (s["high"] - s["low"]) / (0.5 * (s["high"] + s["low"]))
    if width <= spec.tolerance:
        s["status"] = "converged"
        return None
    if s["rounds"] >= spec.max_rounds:
        s["status"] = "max_rounds"
        return None
    return [0.5 * (s["low"] + s["high"])]


def _interpolate(s: dict[str, Any], target: float) -> float:
    """Linear interpolation of the bracket ends to M_lr/M_T = target (in the swept variable)."""
    f_low, f_high = s["f"].get(s["low"], np.nan), s["f"].get(s["high"], np.nan)
    if not (np.isfinite(f_low) and np.isfinite(f_high)) or f_low == f_high:
        return float("nan")
    return float(s["low"] + (f_low - target) * (s["high"] - s["low"]) / (f_low - f_high))


def _label(params: dict[str, Any]) -> str:
    return ",".join(f"{k}={v}" for k, v in params.items()) or "all"


def _results_of(summary: dict[str, Any]) -> dict[str, Any]:
    out = {k: summary[k] for k in RESULT_KEYS if k in summary}
    out["wall_seconds"] = {k: v.get("wall_seconds") for k, v in summary.get("stages", {}).items()}
    return out


# --------------------------------------------------------------------------- tables


def write_results(sweep: Sweep, points: dict[str, dict[str, Any]]) -> None:
    """results.csv and results.h5: one row per point (parameters, results, status, wall time per stage)."""
    param_keys = sorted({k for p in points.values() for k in p["params"]})
    columns = ["name", *param_keys, "group", "status", *RESULT_KEYS, *(f"wall_{s}" for s in STAGES), "attempts", "error"]
    rows = []
    for name, p in sorted(points.items()):
        summary = p.get("summary", {})
        row = {"name": name, "group": p.get("group", ""), "status": p["status"], "attempts": p.get("attempts", 0),
               "error": p.get("error") or ""}
        row.update({k: p["params"].get(k, "") for k in param_keys})
        row.update({k: summary.get(k, "") for k in RESULT_KEYS})
        row.update({f"wall_{s}": summary.get("wall_seconds", {}).get(s, "") for s in STAGES})
        rows.append(row)
    _write_csv(sweep.directory / RESULTS_CSV, columns, rows)
    replicate_columns, replicate_rows = replicate_means(points) if sweep.spec.replicates else ([], [])
    if replicate_rows:
        _write_csv(sweep.directory / REPLICATES_CSV, replicate_columns, replicate_rows)
    with storage.atomic_path(sweep.directory / RESULTS_H5) as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["sweep"] = str(sweep.source)
            _write_columns(f, columns, rows)
            if replicate_rows:
                group = f.create_group("replicates")
                group.attrs["description"] = "one row per point: M_lr/M_T and the other results averaged over replicates"
                _write_columns(group, replicate_columns, replicate_rows)


def _write_columns(group: h5py.Group, columns: list[str], rows: list[dict[str, Any]]) -> None:
    """One dataset per column, numeric where every value is a number (blanks become NaN)."""
    for col in columns:
        values = [r[col] for r in rows]
        numeric = all(isinstance(v, (int, float)) or v == "" for v in values) and col not in ("name", "group", "point")
        data = np.array([np.nan if v == "" else v for v in values], dtype=float) if numeric \
            else np.array([str(v) for v in values], dtype=h5py.string_dtype())
        units = {"Q": "J/kg", "Q_R": "J/kg"}.get(col, "s" if col.startswith("wall_") else "dimensionless")
        storage.write_dataset(group, col, data, units)


def replicate_means(points: dict[str, dict[str, Any]]) -> tuple[list[str], list[dict[str, Any]]]:
    """(columns, rows) of the replicates table: one row per point with its replicates counted
    (``runs``, ``complete``) and each result of :data:`RESULT_KEYS` averaged over the finished
    ones; M_lr/M_T also gets its sample standard deviation (``M_lr_over_M_T_std``, ddof 1,
    blank below two runs) and the standard error of the mean (``M_lr_over_M_T_sem`` = std /
    sqrt(complete))."""
    by_point: dict[str, list[dict[str, Any]]] = {}
    for p in points.values():
        by_point.setdefault(json.dumps(p.get("replicate_of", p["params"]), sort_keys=True), []).append(p)
    param_keys = sorted({k for key in by_point for k in json.loads(key)})
    columns = ["point", *param_keys, "runs", "complete", *RESULT_KEYS, "M_lr_over_M_T_std", "M_lr_over_M_T_sem"]
    rows = []
    for key, runs in by_point.items():
        params = json.loads(key)
        done = [r["summary"] for r in runs if r["status"] == "complete" and "summary" in r]
        row: dict[str, Any] = {"point": _label(params), "runs": len(runs), "complete": len(done),
                               "M_lr_over_M_T_std": "", "M_lr_over_M_T_sem": ""}
        row.update({k: params.get(k, "") for k in param_keys})
        for k in RESULT_KEYS:
            values = [d[k] for d in done if isinstance(d.get(k), (int, float))]
            row[k] = float(np.mean(values)) if values else ""
        mlr = [d["M_lr_over_M_T"] for d in done if isinstance(d.get("M_lr_over_M_T"), (int, float))]
        if len(mlr) >= 2:
            row["M_lr_over_M_T_std"] = float(np.std(mlr, ddof=1))
            row["M_lr_over_M_T_sem"] = row["M_lr_over_M_T_std"] / math.sqrt(len(mlr))
        rows.append(row)
    rows.sort(key=lambda r: tuple((0, r[k], "") if isinstance(r[k], (int, float)) else (1, 0, str(r[k]))
                                  for k in param_keys))
    return columns, rows


def write_qstar_table(sweep: Sweep, records: list[dict[str, Any]]) -> None:
    """qstar.csv: one row per group with Q*_D, its uncertainty and the bisection state."""
    columns = sorted({k for r in records for k in r}, key=lambda k: (k not in records[0], k)) if records else []
    _write_csv(sweep.directory / QSTAR_CSV, columns, records)


def _write_csv(path: Path, columns: list[str], rows: list[dict[str, Any]]) -> None:
    import csv
    import io

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, extrasaction="ignore")
    writer.writeheader()
    writer.writerows(rows)
    storage.write_text_atomic(path, buffer.getvalue())


# --------------------------------------------------------------------------- entry points


#: Exit codes of pool workers stopped by their own pool: when one worker dies, the pool sends the
#: others SIGTERM, and a worker whose stage stopped cleanly exits with 1 (:func:`_run_logged`).
POOL_STOP_EXITS = (1, -signal.SIGTERM)


class LocalPool(cf.Executor):
    """The local backend: a spawn process pool of ``workers`` processes with ``threads`` numba
    threads each, watching the sweep process (:func:`_init_worker`), that can be replaced.

    A worker that dies (``kill -9``, a crash in compiled code, the out-of-memory killer) breaks
    a ``ProcessPoolExecutor`` for good: the futures in flight raise BrokenProcessPool, and so
    does every later submit.  :meth:`replace` shuts the broken pool down, waiting until its
    other workers have stopped, and starts a new one with the same settings; the
    :class:`SweepRunner` then runs the points that were in flight again.
    """

    def __init__(self, workers: int, threads: int):
        self.workers = workers
        self.threads = threads
        self.replacements = 0
        self._start()

    def _start(self) -> None:
        self._others = {p.pid for p in multiprocessing.active_children()}
        self._processes: dict[int, multiprocessing.process.BaseProcess] = {}
        self._pool = cf.ProcessPoolExecutor(max_workers=self.workers, mp_context=multiprocessing.get_context("spawn"),
                                            initializer=_init_worker, initargs=(self.threads, os.getpid()))

    def submit(self, fn, /, *args, **kwargs) -> cf.Future:
        future = self._pool.submit(fn, *args, **kwargs)
        # the pool starts its workers as jobs arrive: keep them, for their exit codes in replace()
        self._processes.update((p.pid, p) for p in multiprocessing.active_children() if p.pid not in self._others)
        return future

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._pool.shutdown(wait=wait, cancel_futures=cancel_futures)

    def replace(self) -> dict[int, int | None]:
        """Shut the current (broken) pool down, waiting for its workers to exit, and start a new one;
        returns the old workers' exit codes by process id (negative: killed by that signal)."""
        self._pool.shutdown(wait=True)
        exits = {pid: p.exitcode for pid, p in self._processes.items()}
        self._start()
        self.replacements += 1
        return exits


def exit_text(code: int | None) -> str:
    """A process exit code in words: ``killed by SIGKILL``, ``exit status 1``."""
    if code is None:
        return "still running"
    if code >= 0:
        return f"exit status {code}"
    try:
        return f"killed by {signal.Signals(-code).name}"
    except ValueError:
        return f"killed by signal {-code}"


def make_executor(execution: Execution) -> tuple[cf.Executor, Any]:
    """(executor, closer): a :class:`LocalPool`, or a Dask client's executor; ``execution.workers``
    workers, by default :meth:`Execution.default_workers`."""
    workers = execution.workers or execution.default_workers()
    if execution.backend == "local":
        pool = LocalPool(workers, execution.threads_per_run)
        return pool, pool.shutdown
    from distributed import Client, LocalCluster

    if execution.scheduler:
        client = Client(execution.scheduler)
        return client.get_executor(pure=False), client.close
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                           env={"NUMBA_NUM_THREADS": str(execution.threads_per_run)})
    client = Client(cluster)

    def close() -> None:
        client.close()
        cluster.close()

    return client.get_executor(pure=False), close


@contextlib.contextmanager
def _sigterm_as_interrupt():
    """While active, SIGTERM raises KeyboardInterrupt in the main thread, as Ctrl-C does, so a
    sweep stopped by ``kill`` (or a batch system's polite stop) cleans up instead of dying
    at once and leaving its pool workers running."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        raise KeyboardInterrupt(f"stopped by {signal.Signals(signum).name}")

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


#: Seconds the pool workers get after SIGTERM before they are killed.
WORKER_STOP_GRACE = 5.0


def _stop_pool_workers(executor: cf.Executor) -> None:
    """Cancel the points not started, then SIGTERM this process's pool workers: a stage in
    flight stops, records itself as interrupted (:mod:`impactpipe.pipeline.stages`) and its
    worker exits (:func:`run_point`), so the point resumes on the next run; a worker still
    alive after WORKER_STOP_GRACE seconds is killed (that point reruns too)."""
    executor.shutdown(wait=False, cancel_futures=True)
    workers = multiprocessing.active_children()
    for worker in workers:
        worker.terminate()
    deadline = time.monotonic() + WORKER_STOP_GRACE
    for worker in workers:
        worker.join(max(0.0, deadline - time.monotonic()))
    for worker in workers:
        if worker.is_alive():
            worker.kill()
            worker.join()


@contextlib.contextmanager
def pool_stopped_on_interrupt(executor: cf.Executor):
    """Around work on a local process pool: Ctrl-C, or SIGTERM to this process alone, stops the
    pool's workers too (:func:`_stop_pool_workers`) before the interrupt propagates."""
    try:
        with _sigterm_as_interrupt():
            yield
    except KeyboardInterrupt:
        _stop_pool_workers(executor)
        raise


@contextlib.contextmanager
def open_runner(sweep: Sweep, executor: cf.Executor | None, show_progress: bool, label: str,
                report: Callable[[str], None] | None = None):
    """A :class:`SweepRunner` on ``executor`` (or one made from the sweep's execution settings)
    with a progress bar, holding the sweep directory's lock (raises
    :class:`impactpipe.pipeline.lock.RunLocked` while another sweep uses it); on exit the bar
    closes, points still running are recorded as interrupted, the result tables are written
    (also after an error or an interrupt) and an executor made here shuts down.  Interrupted
    (Ctrl-C, or SIGTERM to this process alone), a local process pool made here stops its
    workers first, so no point keeps running after the sweep has gone.

    ``report`` gets a line per point start and end; by default these are logged (INFO) when
    the bar is not shown on a terminal and progress is wanted."""
    with run_lock(sweep.directory):
        close = None
        if executor is None:
            executor, close = make_executor(sweep.spec.execution)
        own_pool = close is not None and sweep.spec.execution.backend == "local"
        from tqdm import tqdm

        bar = tqdm(total=0, desc=f"{label} {sweep.spec.name}", unit="run", disable=None if show_progress else True)
        if report is None and show_progress and bar.disable:
            report = log.info
        runner = SweepRunner(sweep, executor, bar, own_pool=own_pool, report=report)
        runner.offer_earlier_runs()
        try:
            with pool_stopped_on_interrupt(executor) if own_pool else contextlib.nullcontext():
                yield runner
        finally:
            bar.close()
            runner.mark_interrupted()
            write_results(sweep, runner.points)
            if close is not None:
                close()


def donor_problems(run_dirs: list[str | Path] | tuple, wanted: set[str] | None, what: str) -> list[str]:
    """One message per ``--reuse-hydro`` run that cannot serve: no finished hydro stage, or
    (when ``wanted`` hydro hashes are given) hydro settings that match none of them."""
    messages = []
    for d in run_dirs:
        record = read_records(Path(d)).get("hydro", {})
        if record.get("status") != "complete":
            messages.append(f"--reuse-hydro {d}: no finished hydro stage there (its stages.json)")
        elif wanted is not None and record.get("hash") not in wanted:
            messages.append(f"--reuse-hydro {d}: its hydro settings match no {what}'s (a run of another config, "
                            f"or the {what}s vary a hydro key)")
    return messages


def run_sweep(sweep: Sweep, executor: cf.Executor | None = None, show_progress: bool = True,
              reuse_runs: list[str | Path] | tuple = (), report: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run a sweep to the end; returns {"points": ..., "qstar": [...]}; writes the tables.
    ``report``: see :func:`open_runner`.

    ``reuse_runs``: finished run directories whose hydro runs the points with the same hydro
    settings adopt instead of running their own (:meth:`SweepRunner.add_donor`).  They are
    checked before any work (raises SweepError): each needs a finished hydro stage and, in
    grid mode, the hydro settings of some point (a Q*_D search finds its points as it goes).
    """
    wanted = None
    if sweep.spec.mode == "grid":
        wanted = {stage_hashes(sweep.config_for(run))["hydro"] for point in grid_points(sweep)
                  for run in sweep.replicate_runs(point)}
    messages = donor_problems(reuse_runs, wanted, "point")
    if messages:
        raise SweepError(messages)
    qstar = []
    with open_runner(sweep, executor, show_progress, "sweep", report) as runner:
        storage.write_text_atomic(sweep.directory / "sweep.yaml", sweep.source.read_text())
        for run_dir in reuse_runs:
            runner.add_donor(run_dir)
        if sweep.spec.mode == "grid":
            runner.run_grid()
        else:
            qstar = runner.run_qstar()
            write_qstar_table(sweep, qstar)
    ladders = resolution_ladders(sweep, qstar if sweep.spec.mode == "qstar" else rung_fits(sweep, runner.points))
    return {"points": runner.points, "qstar": qstar, "resolution": ladders}


#: The keys whose values a Q*_D fit spans (the runs of one fit differ in these).
Q_KEYS = ("scene.impact.velocity", "scene.projectile.radius")


def rung_fits(sweep: Sweep, points: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """A grid sweep with a ``resolution`` ladder: Q*_D fitted over the finished points of each rung
    and group of the axes other than the impact speed and projectile radius (empty without one)."""
    from impactpipe.analysis.qstar import fit_qstar

    if sweep.spec.resolution is None:
        return []
    others = [k for k in sweep.spec.axis_values() if k not in Q_KEYS]
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for p in points.values():
        if p["status"] == "complete":
            groups.setdefault(tuple(p["params"].get(k) for k in others), []).append(p)
    records = []
    for key, finished in groups.items():
        record = dict(zip(others, key))
        q, mlr, n_lr = (np.array([p["summary"].get(k, np.nan) for p in finished], dtype=float)
                        for k in ("Q", "M_lr_over_M_T", "N_lr"))
        try:
            fit = fit_qstar(q, mlr, n_lr)
            record.update({"Qstar_D": fit.qstar, "Qstar_D_uncertainty": fit.qstar_err, "brackets": fit.brackets})
        except (ValueError, np.linalg.LinAlgError) as exc:
            record.update({"Qstar_D": float("nan"), "fit_error": str(exc)})
        record.update(handoff_time_fields(finished))
        records.append(record)
    return records


def resolution_ladders(sweep: Sweep, records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """With a ``resolution`` ladder in qstar mode: for each group of the other axes, Q*_D of its
    rungs and their resolution error (:func:`impactpipe.analysis.resolution_error.qstar_resolution_error`),
    written to ``qstar_resolution.csv``; one record per group (empty without a ladder)."""
    from impactpipe.analysis.resolution_error import qstar_resolution_error

    if sweep.spec.resolution is None or not records:
        return []
    others = [k for k in sweep.spec.axis_values() if k not in (RESOLUTION_KEY, sweep.spec.qstar.variable)]
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for record in records:
        groups.setdefault(tuple(record.get(k) for k in others), []).append(record)
    ladders = []
    for key, rungs in groups.items():
        fitted = [r for r in rungs if math.isfinite(r.get("Qstar_D", float("nan")))]
        row = dict(zip(others, key))
        row.update({f"Qstar_D_n{r[RESOLUTION_KEY]:g}": r.get("Qstar_D", float("nan")) for r in rungs})
        if len(fitted) < 2:
            row.update({"status": f"{len(fitted)} rung(s) with a fitted Q*_D", "summary": ""})
        else:
            ladder = qstar_resolution_error([r[RESOLUTION_KEY] for r in fitted], [r["Qstar_D"] for r in fitted],
                                            [r.get("Qstar_D_uncertainty", float("nan")) for r in fitted],
                                            brackets=[r.get("brackets", True) for r in fitted])
            finest = max(fitted, key=lambda r: r[RESOLUTION_KEY])
            if "Qstar_D_handoff_error" in finest:
                row["handoff_error"] = finest["Qstar_D_handoff_error"]
            row.update({"Qstar_D": ladder.qstar[0], "seed_error": ladder.seed_error[0],
                        "resolution_error": ladder.error, "richardson": ladder.extrapolated,
                        "observed_order": ladder.order, "last_change": ladder.last_change,
                        "richardson_low": ladder.extrapolated_range[0], "richardson_high": ladder.extrapolated_range[1],
                        "refused_draws": ladder.refused,
                        "status": ladder.status, "summary": ladder.describe()})
        ladders.append(row)
    columns = sorted({k for r in ladders for k in r}, key=lambda k: (k in ("status", "summary"), k))
    _write_csv(sweep.directory / QSTAR_RESOLUTION_CSV, columns, ladders)
    return ladders


def finished_run_dirs(directory: str | Path) -> list[str]:
    """Run directories of the sweep's finished points (``points.json``), in name order."""
    points = json.loads((Path(directory) / POINTS_FILE).read_text())
    return [p["run_dir"] for _, p in sorted(points.items()) if p["status"] == "complete"]


def sweep_status(directory: str | Path) -> dict[str, Any]:
    """Counts of points by status and the failed points' errors, from ``points.json``.  A point
    marked running whose sweep process is gone (killed before it could record the stop)
    counts as interrupted."""
    path = Path(directory) / POINTS_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{directory}: no {POINTS_FILE}; is this a sweep directory?")
    points = json.loads(path.read_text())
    counts: dict[str, int] = {}
    for p in points.values():
        status = p["status"]
        if status == "running" and not process_alive(p.get("host"), p.get("pid")):
            status = "interrupted"
        counts[status] = counts.get(status, 0) + 1
    failed = {name: p.get("error") for name, p in points.items() if p["status"] == "failed"}
    return {"total": len(points), "counts": counts, "failed": failed}
