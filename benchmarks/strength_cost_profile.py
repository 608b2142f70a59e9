"""Per-kernel time of the hydro step with and without strength (the cost of strength, by part).

Builds the cases of benchmarks/hydro_throughput.py (the --quick meshes, or the full ones with
--full), takes 2 warm-up steps and --settle more (default 0: the steps right after first
contact, when most of the target has not yet felt the shock; later in a run, once the target
carries stress, the stress update costs more; each case prints the step and time where its
profile starts and, with strength, the share of the cells with mass that carry a deviatoric
stress), then profiles --steps steps of each case with cProfile (each numba kernel call is
one Python-level call, so its time is the kernel's) and prints each case's kernels by their
own time in ns per cell-update, then the ratio of the totals
(docs/strength.md, "Cost").  The cases alternate --repeats times.  The clock is the process's
CPU time: on a shared machine other jobs stretch the wall-clock time of a step, much less
its CPU time.

    NUMBA_NUM_THREADS=1 python benchmarks/strength_cost_profile.py --full
    NUMBA_NUM_THREADS=1 python benchmarks/strength_cost_profile.py 2d-cyl-tillotson 2d-cyl-strength
    NUMBA_NUM_THREADS=1 python benchmarks/strength_cost_profile.py --full --settle 400
"""

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hydro_throughput import build  # noqa: E402

WARMUP_STEPS = 2
SHOWN = 12


def profile_steps(sim, steps: int) -> tuple[float, dict[str, float]]:
    """(total, {function: own time}) of ``steps`` steps of ``sim`` in ns per cell-update (CPU time)."""
    profile = cProfile.Profile(time.process_time)
    before = sim.cell_updates
    profile.enable()
    for _ in range(steps):
        sim.step()
    profile.disable()
    updates = sim.cell_updates - before
    own: dict[str, float] = {}
    for (_, _, name), (_, _, tottime, _, _) in pstats.Stats(profile).stats.items():
        own[name] = own.get(name, 0.0) + tottime / updates * 1e9
    return sum(own.values()), own


def stressed_share(sim) -> float:
    """Share of the interior cells with mass (sum_k alpha_k rho_k > 0) where some material's
    deviatoric stress is not 0 (``sim`` with strength)."""
    arho = sim.mesh.interior(sim.state.arho)
    arhoq = sim.mesh.interior(sim.state.arhoq)
    nq, ns = sim.strength.nq, sim.strength.ns
    stress = [nq * k + j for k in range(sim.state.nmat) for j in range(ns)]
    stressed = (arhoq[:, stress] != 0.0).any(axis=1)
    mass = arho.sum(axis=1) > 0.0
    return float((stressed & mass).sum() / max(int(mass.sum()), 1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("cases", nargs="*", default=["2d-cyl-tillotson", "2d-cyl-strength"])
    parser.add_argument("--full", action="store_true", help="the full-size meshes (default: --quick ones)")
    parser.add_argument("--steps", type=int, default=20, help="profiled steps per repeat (default 20)")
    parser.add_argument("--repeats", type=int, default=3, help="alternating repeats (default 3)")
    parser.add_argument("--settle", type=int, default=0,
                        help="untimed steps after the warm-up, to profile a later window of the run (default 0)")
    args = parser.parse_args()
    sims = {case: build(case, quick=not args.full) for case in args.cases}
    for case, sim in sims.items():
        for _ in range(WARMUP_STEPS + args.settle):
            sim.step()
        share = "" if sim.strength is None else f", stressed share of the cells with mass {stressed_share(sim):.3f}"
        print(f"{case}: profiled from step {sim.step_count}, t = {sim.time:.4g} s{share}")
    results = {case: [] for case in args.cases}
    for _ in range(args.repeats):
        for case, sim in sims.items():
            results[case].append(profile_steps(sim, args.steps))
    for case, runs in results.items():
        print(f"{case}: ns per cell-update (CPU time), one column per repeat")
        print(f"  {'total':32s}" + "".join(f"{total:8.1f}" for total, _ in runs))
        names = sorted(runs[0][1], key=lambda name: -runs[0][1][name])[:SHOWN]
        for name in names:
            print(f"  {name[:32]:32s}" + "".join(f"{own.get(name, 0.0):8.1f}" for _, own in runs))
    if len(args.cases) == 2:
        first, second = (results[case] for case in args.cases)
        ratios = [b[0] / a[0] for a, b in zip(first, second)]
        print(f"{args.cases[1]} / {args.cases[0]}:" + "".join(f" {r:.3f}" for r in ratios))


if __name__ == "__main__":
    main()
