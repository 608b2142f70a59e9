"""Per-kernel time of an adaptive hydro run: the cost of the coarse/fine ghost transfers.

A 2d-cylindrical Sedov blast (one ideal gas, 256 finest cells per axis, 3 levels) runs to
t = 0.01, then t = 0.01 to 0.05 (2487 steps) under cProfile (each numba kernel call is one
Python-level call, so its time is the kernel's); prints the wall time and the kernels by
their own time (docs/performance.md, "Adaptive mesh"):

    NUMBA_NUM_THREADS=2 python benchmarks/amr_ghost_profile.py
"""

import cProfile
import pstats
import time

from impactpipe.hydro.problems import PROBLEMS

GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 717.5}


def main() -> None:
    sim = PROBLEMS["sedov"].setup({"cells": 256, "end_time": 0.1, "deposit_cells": 3.5, "levels": 3},
                                  {"gas": {"eos": GAS}}, geometry="2d-cylindrical")
    sim.run(0.01)
    profile = cProfile.Profile()
    t0 = time.perf_counter()
    profile.enable()
    sim.run(0.05)
    profile.disable()
    print(f"wall {time.perf_counter() - t0:.2f} s, {sim.step_count} steps, {sim.regrids} regrids")
    pstats.Stats(profile).sort_stats("tottime").print_stats(12)


if __name__ == "__main__":
    main()
