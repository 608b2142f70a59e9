"""The cost of one directional sweep along each axis, alone: ns per cell of the sweep kernel.

Builds a case of benchmarks/hydro_throughput.py, takes one step (kernels from numba's cache),
then times ``Simulation._sweep`` along each axis over every block, ``--calls`` calls per
repeat, and prints the best repeat per axis.  The calls advance the state by a thousandth of
the step each, so the state stays what the step left.  Along x a 2D block's pencils run across
its rows (stride nx of the C-ordered fields), along y along them (stride 1): the difference
between the axes is the cost of the strided pencils.

With ``--swap-axes`` the gas box's flow is mirrored in the diagonal (x and y exchanged): what
each axis costs because of the flow then moves to the other axis, what it costs because of the
memory layout stays.

    NUMBA_NUM_THREADS=1 python benchmarks/sweep_axes.py [--case 2d-ideal-gas] [--quick] [--block-cells 16] [--swap-axes]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numba
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from hydro_throughput import _smooth_box, build  # noqa: E402

from impactpipe.hydro.mesh.boundary import NO_RECORD  # noqa: E402


def sweep_costs(case: str, quick: bool, calls: int, repeats: int, block_cells: int | None = None,
                swap_axes: bool = False) -> dict[int, float]:
    """Best ns per cell of one sweep along each axis over ``repeats`` repeats of ``calls`` calls."""
    if swap_axes:
        if case != "2d-ideal-gas":
            raise SystemExit("--swap-axes is for the 2d-ideal-gas case")
        n = 256 if quick else 512
        sim = _smooth_box("2d-planar", [n, n], block_cells, 1, swap_axes=True)
    else:
        sim = build(case, quick, block_cells)
    sim.step()
    blocks = np.arange(sim.mesh.nblocks, dtype=np.int64)
    dt = 1.0e-3 * sim.last_dt
    best = {}
    for axis in range(sim.mesh.ndim):
        sim._sweep(axis, dt, blocks, NO_RECORD, NO_RECORD)
        for _ in range(repeats):
            started = time.perf_counter()
            for _ in range(calls):
                sim._sweep(axis, dt, blocks, NO_RECORD, NO_RECORD)
            cost = (time.perf_counter() - started) / calls / sim.mesh.ncells * 1e9
            best[axis] = min(best.get(axis, np.inf), cost)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--case", default="2d-ideal-gas")
    parser.add_argument("--quick", action="store_true", help="the smaller mesh")
    parser.add_argument("--calls", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--block-cells", type=int, default=None, help="block edge of the box cases")
    parser.add_argument("--swap-axes", action="store_true", help="the gas box's flow with x and y exchanged")
    args = parser.parse_args()
    costs = sweep_costs(args.case, args.quick, args.calls, args.repeats, args.block_cells, args.swap_axes)
    print(f"{args.case}{' (axes swapped)' if args.swap_axes else ''} ({numba.get_num_threads()} thread(s)): "
          + ", ".join(f"{'xyz'[axis]} {cost:.1f}" for axis, cost in costs.items()) + " ns per cell")


if __name__ == "__main__":
    main()
