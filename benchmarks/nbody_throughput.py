"""Throughput of the N-body stage: particle-steps per second for each collision model.

Every configuration starts from the same particles: a uniform sphere of N equal bodies
(bulk density 2000 kg/m^3, volume filling factor 0.05) with isotropic random velocities
of 0.3 times the cloud's escape speed: collisions happen in every step while N changes
by a few per cent at most over the timed steps, so all models are timed at nearly the
same N.  Leapfrog,
tree gravity (opening angle 0.5), the time step of ``collision_time_step``.  The cases are
REBOUND's built-in ``merge`` and ``hardsphere`` (eps = 1) resolvers and the compiled
``merge``, ``conditional_merge`` and ``bounce`` resolvers of impactpipe.nbody (all with
``linetree`` collision search), plus the built-in and compiled merge with the ``tree``
search.  Each case is timed ``--repeats`` times in interleaved order and the median is
reported; ``ratio_to_builtin_merge`` is the case's seconds per particle-step over the
built-in merge's with the same search.  Rates are per second of this process's CPU time
(``time.process_time``; the PyPI REBOUND wheel is single-threaded), which other processes
on a shared machine disturb much less than the wall time; the wall-clock rate is reported
beside it (``particle_steps_per_wall_s``).

    python benchmarks/nbody_throughput.py --json [--quick]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time

import numpy as np
import rebound

from impactpipe.nbody import G, CollisionResolver, collision_time_step
from impactpipe.nbody.resolver import CTX_N_BOUNCE, CTX_N_MERGE, particle_view
from impactpipe.nbody.simulation import build_simulation

RHO = 2000.0
CASES = [("rebound_merge", "linetree"), ("merge", "linetree"), ("conditional_merge", "linetree"),
         ("bounce", "linetree"), ("rebound_hardsphere", "linetree"), ("rebound_merge", "tree"),
         ("merge", "tree")]


def cloud(n: int, seed: int = 1):
    """Positions (m), velocities (m/s), masses (kg), radii (m) of the benchmark cloud."""
    rng = np.random.default_rng(seed)
    m = np.full(n, 1e10)
    r = (3 * m / (4 * math.pi * RHO)) ** (1 / 3)
    big_r = r[0] * (n / 0.05) ** (1 / 3)
    x = rng.uniform(-1, 1, (3 * n, 3))
    x = x[np.linalg.norm(x, axis=1) < 1][:n] * big_r
    v_esc = math.sqrt(2 * G * m.sum() / big_r)
    v = rng.normal(size=(n, 3)) * 0.3 * v_esc / math.sqrt(3)
    return x, v - v.mean(axis=0), m, r, big_r


def run_case(n: int, model: str, search: str, steps: int) -> dict:
    x, v, m, r, big_r = cloud(n)
    dt = collision_time_step(m, r, v, bulk_density=RHO)
    sim = build_simulation(x, v, m, r, dt=dt, opening_angle=0.5, collision_search=search,
                           box_half_width=20 * big_r, seed=1)
    particle_view(sim)["ap"] = np.arange(n) + 1
    resolver = None
    if model == "rebound_merge":
        sim.collision_resolve = "merge"
    elif model == "rebound_hardsphere":
        sim.collision_resolve = "hardsphere"
    else:
        resolver = CollisionResolver(n, model, 0.5, 1.0, G)
        resolver.attach(sim)
    sim.steps(1)  # builds the tree
    particle_steps = 0
    start, start_cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        n_before = sim.N
        sim.steps(1)
        particle_steps += (n_before + sim.N) / 2
    cpu_seconds = time.process_time() - start_cpu
    seconds = time.perf_counter() - start
    out = {"n": n, "model": model, "search": search, "steps": steps, "seconds": seconds,
           "cpu_seconds": cpu_seconds, "particle_steps_per_s": particle_steps / cpu_seconds,
           "particle_steps_per_wall_s": particle_steps / seconds, "n_end": sim.N}
    if resolver is not None:
        out["merges"] = int(resolver.ctx[CTX_N_MERGE])
        out["bounces"] = int(resolver.ctx[CTX_N_BOUNCE])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print the results as JSON")
    ap.add_argument("--quick", action="store_true", help="N = 2000 and 5000, fewer steps")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    sizes = [(2000, 10), (5000, 5)] if args.quick else [(10000, 10), (30000, 5)]
    results = []
    for n, steps in sizes:
        runs: dict[tuple[str, str], list[dict]] = {case: [] for case in CASES}
        for rep in range(args.repeats):
            order = CASES if rep % 2 == 0 else CASES[::-1]
            for model, search in order:
                runs[(model, search)].append(run_case(n, model, search, steps))
        for (model, search), rs in runs.items():
            best = sorted(rs, key=lambda d: d["particle_steps_per_s"])[len(rs) // 2]
            best["particle_steps_per_s_all"] = [d["particle_steps_per_s"] for d in rs]
            results.append(best)
        for res in results:
            if res["n"] == n:
                base = next(d for d in results if d["n"] == n and d["model"] == "rebound_merge"
                            and d["search"] == res["search"])
                res["ratio_to_builtin_merge"] = base["particle_steps_per_s"] / res["particle_steps_per_s"]
    report = {
        "command": "python benchmarks/nbody_throughput.py --json" + (" --quick" if args.quick else "")
                   + (f" --repeats {args.repeats}" if args.repeats != 3 else ""),
        "host": platform.node(), "cpu_count": os.cpu_count(), "load_average": os.getloadavg(),
        "rebound": rebound.__version__, "results": results,
    }
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        for d in results:
            print(f"N={d['n']:6d} {d['model']:18s} {d['search']:8s} {d['particle_steps_per_s']:10.3e} "
                  f"particle-steps per CPU s  ratio {d['ratio_to_builtin_merge']:.3f}")


if __name__ == "__main__":
    main()
