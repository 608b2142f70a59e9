"""Cost of a hydro step with the sweep's plain-pencil path and with the general path only.

Builds each case of benchmarks/hydro_throughput.py (--quick meshes), takes 2 warm-up steps,
then times STEPS steps with ``Simulation.plain_pencils`` on and STEPS with it off, from the
same state, REPEATS times alternating; prints the median nanoseconds per cell and step of
each path, their ratio, and whether the two paths left the same state (they must: bit for
bit, tests/test_hydro_plain_pencils.py).  One thread unless NUMBA_NUM_THREADS says otherwise:

    NUMBA_NUM_THREADS=1 python benchmarks/sweep_paths.py [CASE ...]
"""

import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hydro_throughput import build  # noqa: E402

STEPS = 10
REPEATS = 5
FIELDS = ("alpha", "arho", "arhoe", "arhoq", "momentum", "energy")


def timed(case: str, plain: bool) -> tuple[float, list]:
    """ns per cell and step of STEPS steps, and the final state's fields."""
    sim = build(case, quick=True)
    for _ in range(2):
        sim.step()
    sim.plain_pencils = plain
    t0 = time.perf_counter()
    for _ in range(STEPS):
        sim.step()
    wall = time.perf_counter() - t0
    return wall / STEPS / sim.mesh.ncells * 1e9, [getattr(sim.state, f).copy() for f in FIELDS]


def main() -> None:
    cases = sys.argv[1:] or ["2d-ideal-gas", "2d-cyl-tillotson", "2d-cyl-strength", "3d-two-material"]
    for case in cases:
        runs = {True: [], False: []}
        states = {}
        for _ in range(REPEATS):
            for plain in (True, False):
                ns, state = timed(case, plain)
                runs[plain].append(ns)
                states[plain] = state
        same = all(np.array_equal(a, b) for a, b in zip(states[True], states[False]))
        fast = statistics.median(runs[True])
        general = statistics.median(runs[False])
        print(f"{case:18s} plain path {fast:7.1f} ns/cell/step   general path {general:7.1f}   "
              f"ratio {general / fast:.2f}   same state: {same}")


if __name__ == "__main__":
    main()
