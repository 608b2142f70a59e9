"""Load: a sweep of shortened quickstart points on 2 workers, its pool workers killed at random.

Writes a sweep file: base configs/quickstart.yaml cut short as in tests/test_stop_resume.py
(hydro.end_time 0.12 s, nbody.stop.min_dynamical_times 5), one axis of POINTS impact speeds
evenly from 200 to 300 m/s (so no two points share a hydro run), 2 workers of 1 thread each.
Runs it clean (``impactpipe sweep FILE --out DIR``) and times it, then runs it into a second
directory while a seeded random generator kills (SIGKILL) a randomly chosen pool worker of
the sweep KILLS times, at a random moment in each of KILLS equal parts of the first 80 % of
the clean sweep's wall time (spread so, kills do not pile up on one point: a point whose
worker dies 3 times fails by design, docs/sweeps.md); should the sweep itself exit
non-zero (it should not), the same command runs again.  Then it checks, point by point against the clean sweep:

- the point is complete (points.json) and every stage complete in its stages.json;
- its run.log is that of one writer at a time (the run directory's lock): no stage
  finished ("<stage>: done") twice, every "done" follows its own stage's start with no
  other stage started in between, and no stage started over a "previous attempt running";
- summary.json is equal entry by entry (wall times, dates, paths and the source commit aside);
- every dataset of hydro.h5, handoff.h5 and nbody.h5 is equal bit for bit.

Prints both sweeps' wall times and the kills; exits 1 on any mismatch:

    python benchmarks/sweep_kill_load.py [--points 100] [--kills 10] [--seed 2025] [--out DIR]
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import yaml

ROOT = Path(__file__).resolve().parent.parent
QUICKSTART = ROOT / "configs" / "quickstart.yaml"
OVERRIDES = {"hydro.end_time": 0.12, "nbody.stop.min_dynamical_times": 5}
STAGES = ("hydro", "handoff", "nbody", "analysis")
FILES = ("hydro.h5", "handoff.h5", "nbody.h5")
#: summary.json entries that legitimately differ between two runs of the same config (and the
#: source commit, which a commit made while the benchmark runs changes).
VOLATILE = {"wall_seconds", "run_dir", "started", "finished", "git_commit"}
#: A stage's lines in run.log: "<time> INFO impactpipe.pipeline.stages: <stage>: <what>".
STAGE_LINE = re.compile(r" impactpipe\.pipeline\.stages: (%s): (.*)$" % "|".join(STAGES))


def write_sweep(path: Path, points: int) -> None:
    spec = {"name": "kill-load", "base": str(QUICKSTART), "overrides": OVERRIDES,
            "axes": {"scene.impact.velocity": [float(v) for v in np.linspace(200.0, 300.0, points)]},
            "execution": {"backend": "local", "workers": 2, "threads_per_run": 1}}
    path.write_text(yaml.safe_dump(spec, sort_keys=False))


def sweep_command(sweep_file: Path, out: Path) -> list[str]:
    return [str(Path(sys.executable).parent / "impactpipe"), "sweep", str(sweep_file), "--out", str(out)]


def pool_workers(sweep_pid: int) -> list[int]:
    """The sweep process's pool workers: its children started by multiprocessing's spawn
    (not its resource tracker)."""
    pids = []
    for task in Path(f"/proc/{sweep_pid}/task").glob("*"):
        try:
            pids += [int(p) for p in (task / "children").read_text().split()]
        except OSError:
            continue
    workers = []
    for pid in sorted(set(pids)):
        try:
            if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes():
                workers.append(pid)
        except OSError:
            continue
    return workers


def killer(proc: subprocess.Popen, moments: list[float], rng: np.random.Generator, kills: list[tuple]) -> None:
    """At each moment (s after the start) SIGKILL one of the sweep's pool workers, chosen by ``rng``."""
    t0 = time.monotonic()
    for moment in moments:
        while time.monotonic() - t0 < moment and proc.poll() is None:
            time.sleep(0.05)
        while proc.poll() is None:
            workers = pool_workers(proc.pid)
            if workers:
                pid = int(rng.choice(workers))
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    continue  # it exited meanwhile: choose again
                kills.append((time.monotonic() - t0, pid))
                print(f"  kill {len(kills)}: worker {pid} at {kills[-1][0]:.1f} s", flush=True)
                break
            time.sleep(0.05)  # between pools: wait for the new workers


def run_sweep(sweep_file: Path, out: Path, moments: list[float] = (), seed: int = 0) -> tuple[float, list, int]:
    """Run the sweep (again while it exits non-zero, three times at most); returns (wall s, kills, runs)."""
    kills: list[tuple] = []
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    for attempt in range(1, 4):
        with open(out.parent / f"{out.name}.log", "a") as log:
            proc = subprocess.Popen(sweep_command(sweep_file, out), stdout=log, stderr=subprocess.STDOUT)
            thread = threading.Thread(target=killer, args=(proc, moments[len(kills):], rng, kills))
            thread.start()
            code = proc.wait()
            thread.join()
        if code == 0:
            return time.perf_counter() - t0, kills, attempt
        print(f"  the sweep exited with status {code}; running it again", flush=True)
    return time.perf_counter() - t0, kills, attempt


def stable(entries):
    if isinstance(entries, dict):
        return {k: stable(v) for k, v in entries.items() if k not in VOLATILE}
    return entries


def datasets(path: Path) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    return out


def log_problems(run_log: Path) -> list[str]:
    """What in a run.log shows a stage finished twice or two writers at once (empty: none)."""
    problems = []
    done = collections.Counter()
    started = None
    for line in run_log.read_text().splitlines():
        match = STAGE_LINE.search(line)
        if not match:
            continue
        stage, what = match.groups()
        if what.startswith("done in"):
            if started != stage:
                problems.append(f"{stage}: done without its start just before")
            done[stage] += 1
            started = None
        elif what == "up to date":
            started = None
        else:
            if what == "previous attempt running":
                problems.append(f"{stage}: started while another process ran it")
            started = stage
    problems += [f"{stage}: done {n} times" for stage, n in done.items() if n > 1]
    return problems


def compare(clean: Path, killed: Path) -> list[str]:
    """Mismatches between the killed sweep's points and the clean sweep's, one line each."""
    problems = []
    want = json.loads((clean / "points.json").read_text())
    got = json.loads((killed / "points.json").read_text())
    if sorted(got) != sorted(want):
        return [f"points differ: {sorted(set(got) ^ set(want))}"]
    for name in sorted(want):
        a, b = Path(want[name]["run_dir"]), Path(got[name]["run_dir"])
        if want[name]["status"] != "complete" or got[name]["status"] != "complete":
            problems.append(f"{name}: status {want[name]['status']} (clean), {got[name]['status']} (killed)")
            continue
        records = json.loads((b / "stages.json").read_text())
        problems += [f"{name}: {s} not complete" for s in STAGES if records.get(s, {}).get("status") != "complete"]
        problems += [f"{name}: {p}" for p in log_problems(b / "run.log")]
        summary_a = stable(json.loads((a / "summary.json").read_text()))
        summary_b = stable(json.loads((b / "summary.json").read_text()))
        problems += [f"{name}: summary.json {k} differs" for k in sorted(set(summary_a) | set(summary_b))
                     if summary_a.get(k) != summary_b.get(k)]
        for file in FILES:
            da, db = datasets(a / file), datasets(b / file)
            if sorted(da) != sorted(db):
                problems.append(f"{name}: {file} has other datasets")
                continue
            problems += [f"{name}: {file}:{k} differs" for k in da
                         if not np.array_equal(da[k], db[k], equal_nan=da[k].dtype.kind == "f")]
    return problems


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100)
    parser.add_argument("--kills", type=int, default=10)
    parser.add_argument("--seed", type=int, default=2025)
    parser.add_argument("--out", type=Path, help="working directory (default: a temporary one, removed at the end)")
    options = parser.parse_args()
    work = options.out or Path(tempfile.mkdtemp(prefix="sweep-kill-load-"))
    work.mkdir(parents=True, exist_ok=True)
    sweep_file = work / "kill-load.sweep.yaml"
    write_sweep(sweep_file, options.points)
    print(f"{options.points} points, 2 workers; clean sweep ...", flush=True)
    clean_wall, _, clean_runs = run_sweep(sweep_file, work / "clean")
    print(f"clean sweep: {clean_wall:.0f} s", flush=True)
    rng = np.random.default_rng(options.seed)
    span = 0.8 * clean_wall / options.kills
    moments = [span * (k + u) for k, u in enumerate(rng.random(options.kills))]
    print(f"sweep with {options.kills} kills ...", flush=True)
    killed_wall, kills, runs = run_sweep(sweep_file, work / "killed", moments, options.seed + 1)
    print(f"sweep with kills: {killed_wall:.0f} s, {len(kills)} workers killed, the sweep command run {runs} time(s)")
    problems = compare(work / "clean", work / "killed")
    if clean_runs != 1:
        problems.append(f"the clean sweep needed {clean_runs} runs")
    if len(kills) != options.kills:
        problems.append(f"{len(kills)} kills made of {options.kills} (the sweep ended first)")
    for line in problems:
        print("MISMATCH", line)
    print("every point complete, run once at a time, identical to the clean sweep" if not problems
          else f"{len(problems)} mismatches (files kept in {work})")
    if not problems and options.out is None:
        shutil.rmtree(work)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
