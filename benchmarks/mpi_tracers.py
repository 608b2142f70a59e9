"""Extra cost per step of tracers on several MPI ranks: the messages the ranks exchange for them.

Run under mpiexec, one numba thread per rank:

    NUMBA_NUM_THREADS=1 mpiexec -n 2 python benchmarks/mpi_tracers.py --json

The r-z impact of benchmarks/hydro_throughput.py (``2d-cyl-tillotson``: 100 cells per
projectile radius, 2400 blocks of 16^2; ``--quick``: 25, 150 blocks) with the impact scene's
900 tracers, built on rank 0 and shared between the ranks before the first step
(:func:`impactpipe.hydro.parallel.distributed.distribute_from_root`).  On several ranks the tracers add
per step one exchange of the cells within one cell of each rank's blocks
(:meth:`BlockRanges.share_neighbourhood`) and three gathers of the sampled rows (v_n, v_{n+1},
the peaks; :meth:`BlockRanges.gather_tracers`).  Rank 0 prints the wall time of a step with
tracers and without them (``--steps`` steps each, between barriers), of the tracers' messages
timed alone and, for scale, of the ghost fills of one step with their strip exchanges
(``--repeats`` times each, the mean).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hydro_throughput import build  # noqa: E402

from impactpipe.hydro.parallel.distributed import distribute_from_root  # noqa: E402
from impactpipe.hydro.problems.impact import tracer_positions  # noqa: E402
from impactpipe.hydro.tracers.motion import Tracers  # noqa: E402

#: Tracers of the impact scene (the config's default hydro.tracers.count).
TRACERS = 900


def step_seconds(comm, sim, steps: int) -> float:
    """Mean wall seconds of ``steps`` steps of ``sim``, between two barriers."""
    comm.Barrier()
    started = time.perf_counter()
    for _ in range(steps):
        sim.step()
    comm.Barrier()
    return (time.perf_counter() - started) / steps


def message_seconds(comm, repeats: int, message) -> float:
    """Mean wall seconds of ``message()`` over ``repeats`` calls, between two barriers."""
    comm.Barrier()
    started = time.perf_counter()
    for _ in range(repeats):
        message()
    comm.Barrier()
    return (time.perf_counter() - started) / repeats


def measure(comm, quick: bool, steps: int, repeats: int) -> dict:
    """Per-step wall seconds of the r-z impact with and without tracers, and of the tracers' messages."""
    sim = None
    if comm.rank == 0:
        sim = build("2d-cyl-tillotson", quick)
        positions, materials = tracer_positions(sim.mesh.geometry, 1000.0, 250.0, TRACERS)
        sim.tracers = Tracers(positions, materials)
    if comm.size > 1:
        sim = distribute_from_root(sim, comm)
    sim.step()
    sim.step()
    with_tracers = step_seconds(comm, sim, steps)
    tracers = sim.tracers
    owner = np.empty(len(tracers), dtype=np.int64)
    sim.partition.block_owners(tracers.owning_block, owner)
    rows = [np.zeros((len(tracers), 3)), np.zeros((len(tracers), 3)), np.zeros(len(tracers)),
            np.zeros(len(tracers)), np.zeros(len(tracers))]
    neighbourhood = message_seconds(comm, repeats, lambda: sim.partition.share_neighbourhood(sim.state))
    gathers = message_seconds(comm, repeats, lambda: (sim.partition.gather_tracers(owner, rows[:1]),
                                                      sim.partition.gather_tracers(owner, rows[1:2]),
                                                      sim.partition.gather_tracers(owner, rows[2:])))
    ghost_fills = message_seconds(comm, repeats, lambda: [sim.partition.fill_ghosts(sim.state, sim.mesh, axis)
                                                          for axis in range(sim.mesh.ndim)])
    sim.tracers = None
    without_tracers = step_seconds(comm, sim, steps)
    return {"cells": sim.mesh.ncells, "blocks": sim.mesh.nblocks, "tracers": len(tracers), "steps": steps,
            "step_with_tracers_s": with_tracers, "step_without_tracers_s": without_tracers,
            "neighbourhood_exchange_s": neighbourhood, "three_gathers_s": gathers, "ghost_fills_s": ghost_fills}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="25 cells per projectile radius instead of 100")
    parser.add_argument("--steps", type=int, default=10, help="timed steps with and without tracers (default 10)")
    parser.add_argument("--repeats", type=int, default=200, help="timed calls of each message (default 200)")
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    args = parser.parse_args()
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    numba.set_num_threads(1)
    result = measure(comm, args.quick, args.steps, args.repeats)
    if comm.rank != 0:
        return
    if args.json:
        print(json.dumps({"ranks": comm.size, **result}, indent=2))
    else:
        print(f"{comm.size} ranks, {result['blocks']} blocks, {result['tracers']} tracers: step "
              f"{result['step_with_tracers_s'] * 1e3:.3g} ms with tracers, "
              f"{result['step_without_tracers_s'] * 1e3:.3g} ms without; neighbourhood exchange {result['neighbourhood_exchange_s'] * 1e6:.3g} us, three gathers "
              f"{result['three_gathers_s'] * 1e6:.3g} us; ghost fills of a step {result['ghost_fills_s'] * 1e6:.3g} us")


if __name__ == "__main__":
    main()
