"""Hydro throughput on several MPI ranks: cell-updates per second of one run shared between ranks.

Run under mpiexec, one numba thread per rank, and compare the rates of the same cases at 1
and N ranks (the blocks are cut between the ranks as in ``impactpipe run --ranks N``,
:mod:`impactpipe.hydro.parallel`):

    NUMBA_NUM_THREADS=1 mpiexec -n 1 python benchmarks/mpi_scaling.py --json
    NUMBA_NUM_THREADS=1 mpiexec -n 2 python benchmarks/mpi_scaling.py --json

Cases are those of benchmarks/hydro_throughput.py that the ranks can share in this version
(uniform meshes without strength): ``2d-ideal-gas`` (512^2, 64 blocks) and
``2d-cyl-tillotson`` (the r-z impact, 2400 blocks of 16^2).  Each takes one step, is shared
between the ranks, takes one more step, then ``--steps`` timed steps between two barriers.
Rank 0 prints one JSON document: the rank count, and per case the cell-updates per second,
the wall time and the blocks of each rank.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numba

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hydro_throughput import build  # noqa: E402

from impactpipe.hydro.parallel.distributed import distribute  # noqa: E402

CASES = ("2d-ideal-gas", "2d-cyl-tillotson")


def measure(comm, case: str, steps: int) -> dict:
    """Rate (cell-updates/s) of ``steps`` steps of ``case`` shared between the ranks of ``comm``."""
    sim = build(case, quick=False)
    sim.step()
    if comm.size > 1:
        distribute(sim, comm)
    sim.step()
    comm.Barrier()
    start_updates = sim.cell_updates
    started = time.perf_counter()
    for _ in range(steps):
        sim.step()
    comm.Barrier()
    wall = time.perf_counter() - started
    owned = comm.gather(sim.partition.blocks.indices(sim.mesh.nblocks)[:2], root=0)
    return {"case": case, "cells": sim.mesh.ncells, "steps": steps, "wall_s": wall,
            "cell_updates_per_s": (sim.cell_updates - start_updates) / wall,
            "blocks_per_rank": None if owned is None else [hi - lo for lo, hi in owned]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", nargs="*", default=list(CASES), choices=CASES)
    parser.add_argument("--steps", type=int, default=10, help="timed steps per case (default 10)")
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    args = parser.parse_args()
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    numba.set_num_threads(1)
    results = [measure(comm, case, args.steps) for case in args.cases]
    if comm.rank != 0:
        return
    if args.json:
        print(json.dumps({"ranks": comm.size, "results": results}, indent=2))
    else:
        for r in results:
            print(f"{r['case']}: {comm.size} ranks, {r['cell_updates_per_s']:.3g} cell-updates/s, "
                  f"blocks per rank {r['blocks_per_rank']}")


if __name__ == "__main__":
    main()
