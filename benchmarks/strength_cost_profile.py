"""Per-kernel time of the hydro step with and without strength (the cost of strength, by part).

Builds the cases of benchmarks/hydro_throughput.py (the --quick meshes, or the full ones with
--full), takes 2 warm-up steps, then profiles --steps steps of each case with cProfile (each
numba kernel call is one Python-level call, so its time is the kernel's) and prints each
case's kernels by their own time in ns per cell-update, then the ratio of the totals
(docs/strength.md, "Cost").  The cases alternate --repeats times.  The clock is the process's
CPU time: on a shared machine other jobs stretch the wall-clock time of a step, much less
its CPU time.

    NUMBA_NUM_THREADS=1 python benchmarks/strength_cost_profile.py --full
    NUMBA_NUM_THREADS=1 python benchmarks/strength_cost_profile.py 2d-cyl-tillotson 2d-cyl-strength
"""

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("cases", nargs="*", default=["2d-cyl-tillotson", "2d-cyl-strength"])
    parser.add_argument("--full", action="store_true", help="the full-size meshes (default: --quick ones)")
    parser.add_argument("--steps", type=int, default=20, help="profiled steps per repeat (default 20)")
    parser.add_argument("--repeats", type=int, default=3, help="alternating repeats (default 3)")
    args = parser.parse_args()
    sims = {case: build(case, quick=not args.full) for case in args.cases}
    for sim in sims.values():
        for _ in range(WARMUP_STEPS):
            sim.step()
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
