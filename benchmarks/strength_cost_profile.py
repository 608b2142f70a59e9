"""Per-kernel time of the hydro step with and without strength (the cost of strength, by part).

Builds a case of benchmarks/hydro_throughput.py (--quick meshes), takes 2 warm-up steps,
then profiles 20 steps with cProfile (each numba kernel call is one Python-level call, so
its time is the kernel's) and prints the kernels by their own time (docs/strength.md, "Cost"):

    NUMBA_NUM_THREADS=1 python benchmarks/strength_cost_profile.py 2d-cyl-strength
    NUMBA_NUM_THREADS=1 python benchmarks/strength_cost_profile.py 2d-cyl-tillotson
"""

import cProfile
import pstats
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hydro_throughput import build  # noqa: E402

WARMUP_STEPS = 2
PROFILED_STEPS = 20


def main() -> None:
    case = sys.argv[1] if len(sys.argv) > 1 else "2d-cyl-strength"
    sim = build(case, quick=True)
    for _ in range(WARMUP_STEPS):
        sim.step()
    profile = cProfile.Profile()
    profile.enable()
    for _ in range(PROFILED_STEPS):
        sim.step()
    profile.disable()
    pstats.Stats(profile).sort_stats("tottime").print_stats(14)


if __name__ == "__main__":
    main()
