"""The cost of each ghost-fill exchange of a step on several MPI ranks, call by call.

    NUMBA_NUM_THREADS=1 mpiexec -n 2 python benchmarks/exchange_calls.py --case 2d-cyl-strength --steps 30

Builds a case of benchmarks/hydro_throughput.py on rank 0 and shares it between the ranks as
benchmarks/mpi_scaling.py does, takes two steps, then times ``--steps`` steps and records, after each
exchange completes (:func:`impactpipe.hydro.parallel.exchange.finish_strips`, wrapped here),
what the rank's :class:`~impactpipe.hydro.parallel.exchange.Traffic` gained since the previous
one: exchange - Waitall (s: starting the requests, packing, unpacking and the Python around
them), the time in ``Waitall``, messages and bytes sent.  The exchanges of a step come in a
fixed order (a uniform mesh posts and finishes one at a time), so each call's costs are
reported per position in the step: the median over the steps (a call preempted on a shared
machine does not move it), and the sum of the medians per step.  The fixed cost of a
message is what is left of a call's exchange - Waitall beyond its packing and unpacking.
Rank 0 prints one JSON document: per rank, per call, ``exchange_minus_wait_s``, ``wait_s``
(medians), ``messages``, ``bytes_sent``; and ``exchange_minus_wait_s_per_step``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hydro_throughput import build  # noqa: E402

import impactpipe.hydro.parallel.distributed as distributed  # noqa: E402
from impactpipe.hydro.parallel import exchange  # noqa: E402

CASES = ("2d-cyl-tillotson", "2d-cyl-strength", "3d-two-material", "2d-ideal-gas")


def record_calls(traffic, calls: list) -> None:
    """Append to ``calls``, after every exchange completes, the counters of ``traffic`` it added
    (exchange - Waitall (s), Waitall (s), messages and bytes sent)."""
    finish = exchange.finish_strips
    last = np.zeros(4)

    def finish_and_record(pending):
        finish(pending)
        now = np.array([traffic.exchange_seconds - traffic.wait_seconds, traffic.wait_seconds,
                        traffic.messages_sent, traffic.bytes_sent])
        calls.append(now - last)
        last[:] = now

    exchange.finish_strips = finish_and_record
    distributed.finish_strips = finish_and_record


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--case", default="2d-cyl-strength", choices=CASES)
    parser.add_argument("--steps", type=int, default=30, help="timed steps (default 30)")
    parser.add_argument("--block-cells", type=int, help="block edge of the box cases (default: the mesh's own)")
    args = parser.parse_args()
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    numba.set_num_threads(1)
    sim = build(args.case, quick=False, block_cells=None if args.case.startswith("2d-cyl") else args.block_cells) \
        if comm.rank == 0 else None
    sim = distributed.distribute_from_root(sim, comm)
    sim.step()
    sim.step()
    calls: list = []
    record_calls(sim.partition.traffic, calls)
    comm.Barrier()
    sim.partition.traffic.reset()
    calls.clear()
    for _ in range(args.steps):
        sim.step()
    comm.Barrier()
    per_step = np.array(calls).reshape(args.steps, len(calls) // args.steps, 4)
    medians = np.median(per_step, axis=0)
    rank = {"calls": [{"exchange_minus_wait_s": float(m[0]), "wait_s": float(m[1]), "messages": int(per_step[0, i, 2]),
                       "bytes_sent": int(per_step[0, i, 3])} for i, m in enumerate(medians)],
            "exchange_minus_wait_s_per_step": float(medians[:, 0].sum())}
    ranks = comm.gather(rank, root=0)
    if comm.rank == 0:
        print(json.dumps({"case": args.case, "ranks": ranks, "steps": args.steps, "load_average": os.getloadavg()},
                         indent=2))


if __name__ == "__main__":
    main()
