"""Seconds numba spends compiling each kernel for the first two steps of a small impact.

Records numba's ``numba:compile`` events while a 1 km basalt target hit by a 100 m basalt
projectile at 1 km/s (4 cells per projectile radius, 8-cell blocks, no strength) takes two
steps, and prints the slowest compilations.  Kernels already in the numba cache load
instead of compiling, so delete the caches first for a cold start:

    find . -name "*.nbi" -delete; find . -name "*.nbc" -delete
    python benchmarks/compile_times.py
"""

import time

from numba.core import event

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.problems.common import preset_material

SHOWN = 10


def main() -> None:
    materials = {"basalt": preset_material("basalt")}
    with event.install_recorder("numba:compile") as recorder:
        sim = PROBLEMS["impact"].setup({"target": {"material": "basalt", "radius": 1000.0},
                                        "projectile": {"material": "basalt", "radius": 100.0, "velocity": 1000.0},
                                        "cells_per_projectile_radius": 4}, materials, block_cells=8)
        t0 = time.perf_counter()
        sim.step()
        sim.step()
        wall = time.perf_counter() - t0
    started = {}
    durations = []
    for stamp, ev in recorder.buffer:
        key = (str(ev.data["dispatcher"]), str(ev.data["args"]))
        if ev.is_start:
            started[key] = stamp
        elif key in started:
            durations.append((stamp - started.pop(key), key[0]))
    print(f"two steps: {wall:.1f} s of wall time")
    for seconds, name in sorted(durations, reverse=True)[:SHOWN]:
        print(f"{seconds:7.1f} s  {name}")


if __name__ == "__main__":
    main()
