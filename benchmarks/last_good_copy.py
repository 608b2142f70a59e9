"""The last-good copy alone: numpy's strided copy of the interior cells against the parallel
kernel :func:`impactpipe.hydro.mesh.state.copy_interior`, in ns per interior cell.

On the full-size meshes of benchmarks/hydro_throughput.py (2d-ideal-gas, 2d-cyl-strength,
3d-two-material), with 1 and 2 numba threads, ten copies of every state field per timing,
three alternating repeats (docs/performance.md; the solver uses the kernel with two or more
threads and numpy on one):

    NUMBA_NUM_THREADS=2 python benchmarks/last_good_copy.py
"""

import sys
import time
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hydro_throughput import build  # noqa: E402

from impactpipe.hydro.mesh.state import copy_interior  # noqa: E402

CASES = ("2d-ideal-gas", "2d-cyl-strength", "3d-two-material")
COPIES = 10
REPEATS = 3


def main() -> None:
    for case in CASES:
        sim = build(case, quick=False)
        state, mesh = sim.state, sim.mesh
        gx, gy, gz = (int(g) for g in mesh.ghost)
        good = {name: mesh.interior(arr).copy() for name, arr in state.arrays().items()}

        def with_numpy():
            for name, arr in state.arrays().items():
                np.copyto(good[name], mesh.interior(arr))

        def with_kernel():
            for name, arr in state.arrays().items():
                copy_interior(arr, good[name], gx, gy, gz)

        for threads in (1, 2):
            if threads > numba.config.NUMBA_NUM_THREADS:
                continue
            numba.set_num_threads(threads)
            with_kernel()
            times = {"numpy": [], "kernel": []}
            for _ in range(REPEATS):
                for name, copy in (("numpy", with_numpy), ("kernel", with_kernel)):
                    t0 = time.perf_counter()
                    for _ in range(COPIES):
                        copy()
                    times[name].append((time.perf_counter() - t0) / COPIES / mesh.ncells * 1e9)
            print(f"{case:16s} {threads} thread(s): " + "   ".join(
                f"{name} {', '.join(f'{t:.1f}' for t in ts)}" for name, ts in times.items()) + "  ns per cell")


if __name__ == "__main__":
    main()
