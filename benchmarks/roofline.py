"""Roofline of the hydro step: the bytes a step must move against this machine's memory bandwidth.

Two measurements in one job:

1. Memory bandwidth (bytes/s) of a numba STREAM triad a[i] = b[i] + s c[i] over three arrays
   of ``--stream-mb`` MiB each (far beyond the caches), counted as 24 bytes per element (two
   reads, one write; the STREAM convention, no write-allocate), best of 5, with 1 and 2 threads.

2. Per case of benchmarks/hydro_throughput.py (``--quick`` meshes by default), the time of each
   phase of a step (``Simulation.observer`` events: regrid, time step, last-good copy, ghost
   fills, sweeps, reflux, strength and gravity sources) over ``--steps`` steps, and the
   compulsory traffic of a step per interior cell: with S the bytes of the state fields
   (alpha, arho, arhoe, arhoq, momentum, energy) per interior cell, padded cells included,
   and S_i the same without the ghost cells,

       B = S (2 ndim + 1) + 2 S_i / K

   -- each of the ndim sweeps reads and writes the state once, the time-step kernel reads it
   once, the last-good copy reads and writes its interior cells once every K steps
   (``Simulation._last_good_interval()``: 8 on a uniform mesh, 1 on an adaptive one; ghost fills and the
   sweeps' scratch are left out: they are cache-resident or small).  The bandwidth ceiling is then
   R_max = bandwidth / B cell-updates/s, and ``roofline_fraction`` = measured rate / R_max:
   near 1 a step is limited by memory traffic, far below 1 by arithmetic and latency.

    NUMBA_NUM_THREADS=2 python benchmarks/roofline.py [--full] [--cases CASE ...] [--json]
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import sys
import time
from pathlib import Path

import numba
import numpy as np
from numba import njit, prange

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hydro_throughput import build  # noqa: E402

from impactpipe.hydro.mesh.state import FIELDS  # noqa: E402

#: Bytes per element of the triad a = b + s c: read b and c, write a.
TRIAD_BYTES = 24
CASES = ["2d-ideal-gas", "2d-cyl-tillotson", "2d-cyl-strength", "3d-two-material"]
#: Booking of the time spent in the wrapped methods, taken off the event that follows them
#: (the first "ghosts" of a step).
PREVIOUS = "ghosts (wrapped calls)"


@njit(cache=True, parallel=True)
def triad(a, b, c, s):
    """a[i] = b[i] + s c[i] over all i (prange)."""
    for i in prange(a.size):
        a[i] = b[i] + s * c[i]


def stream_bandwidth(megabytes: float, threads: int, repeats: int = 5) -> float:
    """Best triad bandwidth (bytes/s) with ``threads`` numba threads."""
    numba.set_num_threads(threads)
    n = int(megabytes * 2**20 / 8)
    a, b, c = np.zeros(n), np.ones(n), np.full(n, 2.0)
    triad(a, b, c, 3.0)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        triad(a, b, c, 3.0)
        best = min(best, time.perf_counter() - t0)
    return TRIAD_BYTES * n / best


def state_bytes_per_cell(sim) -> float:
    """S: bytes of the state fields per interior cell (padded ghost cells included)."""
    return sum(getattr(sim.state, name).nbytes for name in FIELDS) / sim.mesh.ncells


def interior_bytes_per_cell(sim) -> float:
    """S_i: bytes of the state fields per interior cell, ghost cells left out (the last-good copy)."""
    return sum(sim.mesh.interior(getattr(sim.state, name)).nbytes for name in FIELDS) / sim.mesh.ncells


def phase_times(case: str, quick: bool, steps: int, threads: int) -> dict:
    """Seconds per phase over ``steps`` steps after one warm-up step, and the step's totals."""
    numba.set_num_threads(threads)
    sim = build(case, quick)
    sim.step()
    spent = collections.Counter()
    mark = [0.0]

    def observe(event: str, axis: int) -> None:
        now = time.perf_counter()
        spent[event] += now - mark[0]
        mark[0] = now

    def timed(name: str, method):
        """``method`` of this Simulation, its time booked under ``name`` (not under the next event)."""
        def call(*args):
            t0 = time.perf_counter()
            result = method(*args)
            now = time.perf_counter()
            spent[name] += now - t0
            spent[PREVIOUS] -= now - t0
            return result
        return call

    # the time step and the last-good copy run between the "regrid" event and the first
    # ghost fill: time them where they run, inside the step
    sim.stable_dt = timed("time step", sim.stable_dt)
    sim._save_good = timed("last-good copy", sim._save_good)
    sim.observer = observe
    start = sim.cell_updates
    t0 = time.perf_counter()
    for _ in range(steps):
        mark[0] = time.perf_counter()
        sim.step()
        spent["after last event"] += time.perf_counter() - mark[0]
    wall = time.perf_counter() - t0
    spent["ghosts"] += spent.pop(PREVIOUS, 0.0)
    updates = sim.cell_updates - start
    return {"sim": sim, "wall": wall, "updates": updates, "spent": dict(spent)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--full", action="store_true", help="the full meshes of hydro_throughput.py")
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--stream-mb", type=float, default=256.0, help="MiB per triad array (default 256)")
    parser.add_argument("--cases", nargs="*", default=CASES)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    threads = [t for t in (1, 2) if t <= numba.config.NUMBA_NUM_THREADS]
    bandwidth = {t: stream_bandwidth(args.stream_mb, t) for t in threads}
    rows = []
    for case in args.cases:
        for t in threads:
            run = phase_times(case, not args.full, args.steps, t)
            sim = run["sim"]
            s = state_bytes_per_cell(sim)
            b = s * (2 * sim.mesh.ndim + 1) + 2 * interior_bytes_per_cell(sim) / sim._last_good_interval()
            rate = run["updates"] / run["wall"]
            ceiling = bandwidth[t] / b
            rows.append({
                "case": case, "threads": t, "cells": sim.mesh.ncells,
                "cell_updates_per_s": rate, "ns_per_cell_update": 1e9 / rate,
                "state_bytes_per_cell": s, "compulsory_bytes_per_cell_update": b,
                "bandwidth_bytes_per_s": bandwidth[t], "bandwidth_ceiling_cell_updates_per_s": ceiling,
                "roofline_fraction": rate / ceiling,
                "phase_ns_per_cell_update": {k: 1e9 * v / run["updates"] for k, v in sorted(run["spent"].items())},
            })
    report = {"load_average": os.getloadavg(), "cpu_count": os.cpu_count(),
              "stream_bandwidth_bytes_per_s": bandwidth, "results": rows}
    if args.json:
        print(json.dumps(report, indent=2))
        return
    for t, bw in bandwidth.items():
        print(f"triad bandwidth, {t} thread(s): {bw / 1e9:.1f} GB/s")
    for r in rows:
        print(f"{r['case']:17s} threads={r['threads']} {r['cell_updates_per_s']:.3g} cell-updates/s "
              f"({r['ns_per_cell_update']:.0f} ns)  B = {r['compulsory_bytes_per_cell_update']:.0f} bytes  "
              f"ceiling {r['bandwidth_ceiling_cell_updates_per_s']:.3g}/s  fraction {r['roofline_fraction']:.3f}")
        phases = ", ".join(f"{k} {v:.0f}" for k, v in r["phase_ns_per_cell_update"].items() if v >= 0.5)
        print(f"{'':17s} ns per cell-update: {phases}")


if __name__ == "__main__":
    main()
