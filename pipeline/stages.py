"""Stage orchestration: decide what runs, run it, record it, resume it.

A run directory holds one file per stage (``hydro.h5``, ``handoff.h5``, ``nbody.h5``,
``analysis.h5``), ``config.resolved.yaml``, ``summary.json`` and ``stages.json``, the
record of each finished stage with the content hash of the config sections it depends
on.  A stage is skipped when its file exists and its hash is unchanged; changing a
section reruns the stage that reads it and every stage after it.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import json
import logging
import os
import shutil
import signal
import socket
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from impactpipe import storage

from . import checks, derived
from .config import STAGES, Config
from .lock import process_alive, run_lock
from .progress import StageProgress, compile_notice

log = logging.getLogger(__name__)

#: Config sections each stage reads (besides everything the stages before it read).
STAGE_SECTIONS: dict[str, tuple[str, ...]] = {
    "hydro": ("scene", "materials", "hydro"),
    "handoff": ("handoff",),
    "nbody": ("nbody",),
    "analysis": ("analysis",),
}
STAGE_FILES = {"hydro": "hydro.h5", "handoff": "handoff.h5", "nbody": "nbody.h5", "analysis": "analysis.h5"}
STAGE_FUNCTIONS = {
    "hydro": "impactpipe.pipeline.adapters.hydro:run_hydro_stage",
    "handoff": "impactpipe.pipeline.adapters.handoff:run_handoff_stage",
    "nbody": "impactpipe.pipeline.adapters.nbody:run_nbody_stage",
    "analysis": "impactpipe.pipeline.adapters.analysis:run_analysis_stage",
}
RECORD_FILE = "stages.json"
SUMMARY_FILE = "summary.json"
RESOLVED_CONFIG_FILE = "config.resolved.yaml"


class StageInterrupted(Exception):
    """SIGINT or SIGTERM arrived while a stage ran; its output was not completed."""


@dataclass
class StageContext:
    """What a stage adapter gets: the validated config, its derived values
    (:func:`impactpipe.pipeline.derived.derive`, computed once per run), the run directory
    and helpers."""

    config: Config
    values: dict[str, Any]
    run_dir: Path
    show_progress: bool = True
    summary: dict[str, Any] = field(default_factory=dict)
    stage_hash: str = ""
    signals: "StopSignals | None" = None

    @contextlib.contextmanager
    def stop_at_safe_points(self) -> Iterator[None]:
        """Within the block SIGINT and SIGTERM only ask the stage to stop: it calls
        :meth:`stop_requested` at its safe points (a step boundary), writes its checkpoint
        there and raises :meth:`interrupted`.  A second signal before that stops at once."""
        if self.signals is None:
            yield
            return
        with self.signals.deferred():
            yield

    def stop_requested(self) -> str | None:
        """The name of the signal that asked the stage to stop, or None."""
        return self.signals.pending if self.signals is not None else None

    def interrupted(self) -> StageInterrupted:
        """The exception a stage raises at the safe point where it honours a stop request."""
        return StageInterrupted(f"stopped by {self.stop_requested()}")

    def path(self, stage: str) -> Path:
        """The output file of ``stage`` in the run directory."""
        return self.run_dir / STAGE_FILES[stage]

    def progress(self, stage: str, total: float | None) -> StageProgress:
        """A progress reporter for ``stage`` that will reach simulated time ``total`` (s)."""
        return StageProgress(stage, total, bar=self.show_progress)

    def provenance(self, started: str, wall_seconds: float) -> dict[str, str]:
        """Provenance attributes for a stage's output file."""
        return storage.provenance(resolved_yaml(self.config), started, wall_seconds)


def resolved_dict(config: Config) -> dict[str, Any]:
    """The config with every default filled and every preset parameter written out, as plain data.

    The result is itself a valid config that describes the same run (same stage hashes).
    """
    data = config.model_dump(mode="json", exclude_none=True)
    for name, resolved in config.resolved_materials().items():
        for part in ("eos", "strength", "porosity"):
            if part in resolved:
                data["materials"][name][part].update(resolved[part])
    return data


def resolved_yaml(config: Config) -> str:
    """:func:`resolved_dict` as YAML text."""
    return yaml.safe_dump(resolved_dict(config), sort_keys=False)


def applicable_stages(config: Config) -> tuple[str, ...]:
    """Stages a scene needs: an impact runs all four; a verification problem runs hydro only."""
    return STAGES if config.scene.problem == "impact" else ("hydro",)


def stage_hashes(config: Config) -> dict[str, str]:
    """Content hash per stage, chained so a change upstream changes every hash downstream.
    ``handoff.window`` is left out: it tells the convergence tool where to hand off, not a stage
    what to compute; so is ``handoff.intact_fragments`` while it is off."""
    data = config.model_dump(mode="json")
    data["handoff"].pop("window")
    if not data["handoff"]["intact_fragments"]["enabled"]:
        data["handoff"].pop("intact_fragments")  # off: the hash of runs made before the key existed
    data["materials"] = config.resolved_materials()
    hashes: dict[str, str] = {}
    previous = ""
    for stage in STAGES:
        sections = {key: data.get(key) for key in STAGE_SECTIONS[stage]}
        digest = hashlib.sha256((previous + json.dumps(sections, sort_keys=True)).encode()).hexdigest()[:16]
        hashes[stage] = digest
        previous = digest
    return hashes


def read_records(run_dir: Path) -> dict[str, Any]:
    """The stage records of a run directory (empty if none)."""
    path = run_dir / RECORD_FILE
    if not path.is_file():
        return {}
    return json.loads(path.read_text())


def read_summary(run_dir: str | Path) -> dict[str, Any]:
    """The ``summary.json`` of a run directory."""
    return json.loads((Path(run_dir) / SUMMARY_FILE).read_text())


def load_stage_function(stage: str, overrides: dict[str, str] | None = None) -> Callable[[StageContext], dict[str, Any]]:
    """Import the stage function for ``stage``: ``overrides[stage]`` or :data:`STAGE_FUNCTIONS`.

    Both name functions as ``"package.module:function"``.
    """
    module, name = ((overrides or {}).get(stage) or STAGE_FUNCTIONS[stage]).split(":")
    return getattr(importlib.import_module(module), name)


def adopt_stages(run_dir: Path, source_dir: Path, config: Config) -> list[str]:
    """Reuse the finished stages of ``source_dir`` whose hashes match ``config`` (shared work).

    The outputs are hard-linked (copied where links are impossible) into ``run_dir``
    and their records copied, marked ``reused_from``.  Stops at the first stage that
    does not match, since every later hash depends on it.  A new ``run_dir`` gets the
    source's summary entries of the adopted stages only (each stage lists its entries in
    ``stages.<stage>.summary_keys``), so the source's later answers (M_lr/M_T...) never
    stand in for the run's own; a source written before stages listed their entries gives
    its whole summary, which the run's own stages overwrite as they finish.  Returns the
    adopted stages.
    """
    hashes = stage_hashes(config)
    source_records = read_records(source_dir)
    records = read_records(run_dir)
    adopted = []
    for stage in applicable_stages(config):
        rec = source_records.get(stage, {})
        source_file = source_dir / STAGE_FILES[stage]
        if rec.get("status") != "complete" or rec.get("hash") != hashes[stage] or not source_file.is_file():
            break
        if records.get(stage, {}).get("hash") == hashes[stage] and (run_dir / STAGE_FILES[stage]).is_file():
            continue
        target = run_dir / STAGE_FILES[stage]
        with storage.atomic_path(target) as tmp:
            tmp.unlink()
            try:
                os.link(source_file, tmp)
            except OSError:
                shutil.copyfile(source_file, tmp)
        records[stage] = {**rec, "reused_from": str(source_dir.resolve())}
        adopted.append(stage)
    if adopted:
        run_dir.mkdir(parents=True, exist_ok=True)
        storage.write_json_atomic(run_dir / RECORD_FILE, records)
        summary_path = run_dir / SUMMARY_FILE
        source_summary = source_dir / SUMMARY_FILE
        if source_summary.is_file() and not summary_path.is_file():
            summary = _adopted_summary(json.loads(source_summary.read_text()), adopted)
            summary["run_dir"] = str(run_dir.resolve())
            storage.write_json_atomic(summary_path, summary)
    return adopted


def _adopted_summary(source: dict[str, Any], adopted: list[str]) -> dict[str, Any]:
    """The part of a source run's summary that its ``adopted`` stages wrote (see :func:`adopt_stages`)."""
    entries = source.get("stages", {})
    listed = [entries.get(stage, {}).get("summary_keys") for stage in entries]
    summary = dict(source)
    if all(keys is not None for keys in listed):
        written = {key for stage in entries for key in entries[stage]["summary_keys"]}
        kept = {key for stage in adopted for key in entries.get(stage, {}).get("summary_keys", [])}
        summary = {key: value for key, value in source.items() if key not in written or key in kept}
    summary["stages"] = {k: v for k, v in entries.items() if k in adopted}
    return summary


#: What a stage record without a ``version`` field was written by (the field came with 0.2.1).
UNRECORDED_VERSION = "0.2.0 or earlier"
#: The phrase of a plan reason whose stage record comes from another impactpipe version.
OTHER_VERSION = "written by impactpipe"


def plan(config: Config, run_dir: Path, stages: Iterable[str] | None = None,
         from_stage: str | None = None, force: bool = False) -> list[tuple[str, str]]:
    """(stage, reason) for every applicable stage: reason is 'run: ...' or 'skip: ...'."""
    wanted = applicable_stages(config)
    selected = tuple(stages) if stages is not None else wanted
    for stage in selected:
        if stage not in wanted:
            raise ValueError(f"stage '{stage}' does not apply to scene.problem = {config.scene.problem} "
                             f"(stages: {', '.join(wanted)})")
    if from_stage is not None and from_stage not in wanted:
        raise ValueError(f"--from {from_stage}: not a stage of this run (stages: {', '.join(wanted)})")
    records = read_records(run_dir)
    hashes = stage_hashes(config)
    version = storage.package_versions()["impactpipe"]
    out: list[tuple[str, str]] = []
    upstream_reran = False
    for stage in wanted:
        if stage not in selected:
            continue
        rec = records.get(stage, {})
        written = rec.get("version", UNRECORDED_VERSION)
        output = run_dir / STAGE_FILES[stage]
        if force:
            reason = "run: --force"
        elif from_stage is not None and wanted.index(stage) >= wanted.index(from_stage):
            reason = f"run: --from {from_stage}"
        elif upstream_reran:
            reason = "run: an earlier stage reran"
        elif rec.get("status") != "complete" or not output.is_file():
            reason = "run: not finished before" if not rec else f"run: previous attempt {attempt_status(rec)}"
        elif rec.get("hash") != hashes[stage]:
            reason = "run: its config sections changed"
        elif written != version:
            reason = (f"skip: up to date, but {OTHER_VERSION} {written} (this is {version}); "
                      f"`--from {stage}` reruns it with this version")
        else:
            reason = "skip: up to date"
        if reason.startswith("run: previous attempt") and written != version:
            reason += (f"; its checkpoint was {OTHER_VERSION} {written} (this is {version}), so the "
                       f"resumed stage mixes two versions: `--from {stage}` starts it over")
        if reason.startswith("run"):
            upstream_reran = True
        out.append((stage, reason))
    return out


def run(config: Config, out_dir: str | Path | None = None, stages: Iterable[str] | None = None,
        from_stage: str | None = None, force: bool = False, show_progress: bool = True,
        stage_functions: dict[str, str] | None = None) -> dict[str, Any]:
    """Run the pipeline for ``config`` into ``out_dir`` (default: ``config.output`` or runs/<name>).

    Finished stages whose config sections are unchanged are skipped; ``from_stage``
    reruns from that stage on; ``force`` reruns everything.  Returns the summary.
    ``stage_functions`` replaces stage functions by others (``{"nbody": "pkg.mod:func"}``).
    Raises StageInterrupted on SIGINT/SIGTERM (outputs of the interrupted stage are not
    written; its checkpoint, if it keeps one, remains for the next run).  Before anything is
    written the config passes the checks of ``impactpipe validate`` (:func:`impactpipe.pipeline.
    checks.check`, raises ConfigError) and the run takes the directory's lock
    (:func:`impactpipe.pipeline.lock.run_lock`: raises RunLocked while another process writes it).

    Example: the quickstart impact through all four stages (the other examples read its
    files)::

        >>> from impactpipe.pipeline import load_config, run
        >>> summary = run(load_config("configs/quickstart.yaml"), "runs/quickstart", show_progress=False)
        >>> sorted(summary["stages"])
        ['analysis', 'handoff', 'hydro', 'nbody']
        >>> 0.5 < summary["M_lr_over_M_T"] < 1.0
        True
    """
    run_dir = Path(out_dir or config.output or Path("runs") / config.name)
    checks.check(config)
    with run_lock(run_dir):
        return _run_locked(config, run_dir, stages, from_stage, force, show_progress, stage_functions)


def _run_locked(config: Config, run_dir: Path, stages: Iterable[str] | None, from_stage: str | None, force: bool,
                show_progress: bool, stage_functions: dict[str, str] | None) -> dict[str, Any]:
    """The body of :func:`run`, holding the run directory's lock."""
    run_dir.mkdir(parents=True, exist_ok=True)
    storage.write_text_atomic(run_dir / RESOLVED_CONFIG_FILE, resolved_yaml(config))
    hashes = stage_hashes(config)
    records = read_records(run_dir)
    left_running = [rec for rec in records.values() if rec.get("status") == "running"]
    for rec in left_running:  # its writer is gone, since this run holds the lock
        rec["status"] = "interrupted"
    if left_running:
        storage.write_json_atomic(run_dir / RECORD_FILE, records)
    summary_path = run_dir / SUMMARY_FILE
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
    summary.update({"name": config.name, "problem": config.scene.problem, "run_dir": str(run_dir.resolve()),
                    "versions": storage.package_versions(), "git_commit": storage.SOURCE_COMMIT})
    summary.setdefault("stages", {})
    signals = StopSignals()
    ctx = StageContext(config=config, values=derived.derive(config), run_dir=run_dir, show_progress=show_progress,
                       summary=summary, signals=signals)
    with signals:
        for stage, reason in plan(config, run_dir, stages, from_stage, force):
            mixed = OTHER_VERSION in reason
            if reason.startswith("skip"):
                log.log(logging.WARNING if mixed else logging.INFO, "%s: %s", stage, reason[6:])
                continue
            log.log(logging.WARNING if mixed else logging.INFO, "%s: %s", stage, reason[5:])
            _invalidate_after(stage, records)
            records[stage] = {"status": "running", "hash": hashes[stage], "started": storage.utc_now(),
                              "host": socket.gethostname(), "pid": os.getpid(),
                              "version": summary["versions"]["impactpipe"]}
            storage.write_json_atomic(run_dir / RECORD_FILE, records)
            ctx.stage_hash = hashes[stage]
            t0 = time.perf_counter()
            try:
                with compile_notice():
                    result = load_stage_function(stage, stage_functions)(ctx)
            except StageInterrupted:
                records[stage]["status"] = "interrupted"
                storage.write_json_atomic(run_dir / RECORD_FILE, records)
                raise
            except Exception as exc:
                records[stage]["status"] = "failed"
                records[stage]["error"] = f"{type(exc).__name__}: {exc}"
                storage.write_json_atomic(run_dir / RECORD_FILE, records)
                raise
            wall = time.perf_counter() - t0
            records[stage].update({"status": "complete", "wall_seconds": wall, "finished": storage.utc_now()})
            summary["stages"][stage] = {"wall_seconds": wall, **result.pop("stage", {}), "summary_keys": sorted(result)}
            summary.update(result)
            # The summary first: a stage recorded complete always has its entries in summary.json
            # (a kill between the two writes reruns the stage, which writes the same entries).
            storage.write_json_atomic(summary_path, summary)
            storage.write_json_atomic(run_dir / RECORD_FILE, records)
            log.info("%s: done in %.1f s -> %s", stage, wall, run_dir / STAGE_FILES[stage])
    return summary


def attempt_status(record: dict[str, Any]) -> str:
    """A stage record's status, ``interrupted`` for one still marked running whose process is gone
    (killed, or the machine stopped: :func:`impactpipe.pipeline.lock.process_alive`)."""
    status = record.get("status", "incomplete")
    if status == "running" and not process_alive(record.get("host"), record.get("pid")):
        return "interrupted"
    return status


def _invalidate_after(stage: str, records: dict[str, Any]) -> None:
    for later in STAGES[STAGES.index(stage):]:
        records.pop(later, None)


class StopSignals:
    """Context manager turning SIGINT and SIGTERM into StageInterrupted for a clean stop.

    Outside :meth:`deferred` the first signal raises at once.  Inside it (a stage that
    stops only at its safe points, :meth:`StageContext.stop_at_safe_points`) the first
    signal is only recorded in ``pending``; the stage polls it at every step boundary, where
    its state is whole, writes its checkpoint and raises, so a resumed run continues from
    exactly the state an uninterrupted run passes through.  A second signal while the stop
    is pending raises at once (the stage then keeps its last periodic checkpoint).  Once a
    StageInterrupted is under way, further signals are logged and ignored, so they cannot
    abort the interrupted stage's record write (a sweep's pool SIGTERMs its workers again
    once one of them has exited).
    """

    def __init__(self) -> None:
        self.pending: str | None = None
        self._deferring = False
        self._raised = False

    def __enter__(self) -> "StopSignals":
        self._old = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                self._old[sig] = signal.signal(sig, self._handler)
            except ValueError:
                pass
        return self

    @contextlib.contextmanager
    def deferred(self) -> Iterator[None]:
        """Within the block a first signal is recorded in ``pending`` instead of raising."""
        self._deferring = True
        try:
            yield
        finally:
            self._deferring = False

    def _handler(self, signum: int, frame: Any) -> None:
        name = signal.Signals(signum).name
        if self._raised:
            log.warning("%s ignored: already stopping after an earlier signal (SIGKILL stops at once)", name)
            return
        if self._deferring and self.pending is None:
            self.pending = name
            log.warning("%s: stopping at the end of the current step (send it again to stop at once, keeping "
                        "the last periodic checkpoint)", name)
            return
        self._raised = True
        raise StageInterrupted(f"stopped by {name}")

    def __exit__(self, *exc: Any) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
