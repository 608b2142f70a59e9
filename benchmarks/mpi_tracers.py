"""Extra cost per step of tracers on several MPI ranks: the messages the ranks exchange for them.

Run under mpiexec, one numba thread per rank:

    NUMBA_NUM_THREADS=1 mpiexec -n 2 python benchmarks/mpi_tracers.py --json

The r-z impact of benchmarks/hydro_throughput.py (``2d-cyl-tillotson``: 100 cells per
projectile radius, 2400 blocks of 16^2; ``--quick``: 25, 150 blocks) with the impact scene's
900 tracers, built on rank 0 and shared between the ranks before the first step
(:func:`impactpipe.hydro.parallel.distributed.distribute_from_root`); each rank then holds the
tracers in its own blocks.  On several ranks the tracers add per step one exchange of the
cells within one cell of each rank's blocks (:meth:`BlockRanges.share_neighbourhood`) and two
hand-overs of the tracers that moved into another rank's blocks (after the predictor and after
the corrector; :meth:`BlockRanges.hand_over`, counted in the partition's traffic).  Rank 0
prints the wall time of a step with tracers and without them (``--steps`` steps each, between
barriers), the hand-overs per step (the tracers sent, summed over the ranks, and rank 0's wall
time inside them), the neighbourhood exchange timed alone and, for scale, the ghost fills of
one step with their strip exchanges (``--repeats`` times each, the mean).
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
    traffic = sim.partition.traffic
    traffic.reset()
    with_tracers = step_seconds(comm, sim, steps)
    handovers = traffic.handovers / steps
    handed_over = comm.allreduce(traffic.items_handed_over) / steps
    handover_seconds = traffic.handover_seconds / steps
    held = comm.allgather(len(sim.tracers))
    neighbourhood = message_seconds(comm, repeats, lambda: sim.partition.share_neighbourhood(sim.state))
    ghost_fills = message_seconds(comm, repeats, lambda: [sim.partition.fill_ghosts(sim.state, sim.mesh, axis)
                                                          for axis in range(sim.mesh.ndim)])
    sim.tracers = None
    without_tracers = step_seconds(comm, sim, steps)
    return {"cells": sim.mesh.ncells, "blocks": sim.mesh.nblocks, "tracers": sum(held), "tracers_per_rank": held,
            "steps": steps, "step_with_tracers_s": with_tracers, "step_without_tracers_s": without_tracers,
            "handovers_per_step": handovers, "tracers_handed_over_per_step": handed_over,
            "handover_s_per_step": handover_seconds, "neighbourhood_exchange_s": neighbourhood,
            "ghost_fills_s": ghost_fills}


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
              f"{result['step_without_tracers_s'] * 1e3:.3g} ms without; {result['handovers_per_step']:.3g} hand-overs "
              f"per step ({result['tracers_handed_over_per_step']:.3g} tracers, "
              f"{result['handover_s_per_step'] * 1e6:.3g} us); neighbourhood exchange "
              f"{result['neighbourhood_exchange_s'] * 1e6:.3g} us; ghost fills of a step {result['ghost_fills_s'] * 1e6:.3g} us")


if __name__ == "__main__":
    main()
