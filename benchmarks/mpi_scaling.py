"""Hydro throughput on several MPI ranks: cell-updates per second of one run shared between ranks,
and what each rank exchanged, waited for and computed per step.

Run under mpiexec, one numba thread per rank, and compare the rates of the same cases at 1
and N ranks (the blocks are cut between the ranks as in ``impactpipe run --ranks N``,
:mod:`impactpipe.hydro.parallel`):

    NUMBA_NUM_THREADS=1 mpiexec -n 1 python benchmarks/mpi_scaling.py --json
    NUMBA_NUM_THREADS=1 mpiexec -n 2 python benchmarks/mpi_scaling.py --json

Cases are those of benchmarks/hydro_throughput.py: ``2d-cyl-tillotson`` (the r-z impact, 2400
blocks of 16^2), ``2d-cyl-strength`` (the same impact with GEO 'strong' strength),
``3d-two-material`` (128^3 periodic box, two ideal gases; 16^3 blocks, ``--block-cells``
sets another edge) and ``2d-ideal-gas`` (512^2, 64^2 blocks).  Each case reports its mesh
(``blocks_per_axis``, ``block_cells``, ``periodic``), the state's float64 ``components`` per
cell, its ``materials`` and whether it runs ``strength`` (what benchmarks/scaling_model.py
needs to recount the bytes exchanged).  A case that
:func:`impactpipe.hydro.parallel.distributed.unsupported` refuses on the ranks asked for
is reported with ``skipped``, the reasons, and not run; on one rank every case runs as a
single process.

As in ``impactpipe run --ranks N``, the ranks build the impact cases together, each its own
blocks (:func:`impactpipe.hydro.parallel.distributed.shared_simulation`), and rank 0 alone
builds the boxes (the others receive their blocks,
:func:`impactpipe.hydro.parallel.distributed.distribute_from_root`; ``--rank-0-builds``: the
impacts too); each case takes two steps, then ``--steps`` timed steps
between two barriers, with the ranks' traffic counters
(:class:`~impactpipe.hydro.parallel.exchange.Traffic`) reset at the start.  Per rank, per step:
``bytes_sent``, ``bytes_received`` (B), ``messages_sent``, ``allreduces``; ``wait_s`` (s in
``Waitall``), ``exchange_s`` (s in the ghost exchanges: packing, waiting, unpacking),
``allreduce_s``; and ``compute_s_per_cell_update`` = (wall - exchange - allreduce time) / (the
rank's interior cells x steps), the cost of a cell-update on one core.  Then two snapshots
(each rank computes the fields of its own blocks, rank 0 gathers them), the second timed:
``snapshot_s`` and ``gather_s`` (the first loads the snapshot kernels from numba's cache and
touches the new arrays' memory, which a run pays once, not per snapshot).  With
two or more ranks, ranks 0 and 1 also time a ping-pong (``pingpong``: the one-way latency of an
8-byte message and the bandwidth of a 16 MiB one, s and B/s).  Rank 0 prints one JSON document.

Memory per rank (B, from ``/proc/self/status``, Linux): ``setup_peak_resident_bytes``, the
largest resident set through the setup (the build of the initial state, the sharing), before
any step; ``step_peak_resident_bytes`` and ``resident_bytes``, the largest
resident set during the timed steps and the resident set after them (the peak reset before
them, ``/proc/self/clear_refs``), with ``resident_bytes_per_cell`` the latter over the rank's
interior cells; ``snapshot_peak_resident_bytes``, the largest during the two snapshots;
``released_resident_bytes``, the resident set once the Simulation is dropped and glibc has
returned its free heap to the system (``malloc_trim``: the interpreter, numpy, numba, MPI and
the loaded kernels); ``run_resident_bytes``, ``resident_bytes`` less it (what the run held),
and ``run_resident_bytes_per_cell``, that over the rank's interior cells.  Run one case per
process, with the kernels in numba's cache (a compile leaves its memory resident), for figures
that nothing before has inflated (docs/performance.md, "Memory on several ranks").
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import json
import os
import sys
import time
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hydro_throughput import build  # noqa: E402

from impactpipe.hydro.parallel.distributed import distribute_from_root, unsupported  # noqa: E402

CASES = ("2d-cyl-tillotson", "2d-cyl-strength", "3d-two-material", "2d-ideal-gas")
DEFAULT_CASES = ("2d-cyl-tillotson", "2d-cyl-strength", "3d-two-material")
#: Ping-pong message sizes (B) and round trips.
LATENCY_BYTES, BANDWIDTH_BYTES, ROUND_TRIPS = 8, 16 * 2 ** 20, 20


def resident() -> tuple[int, int]:
    """(resident set, its peak since the last :func:`reset_peak`) of this process (B): VmRSS and
    VmHWM of ``/proc/self/status``."""
    fields = {}
    with open("/proc/self/status") as status:
        for line in status:
            name, _, value = line.partition(":")
            if name in ("VmRSS", "VmHWM"):
                fields[name] = int(value.split()[0]) * 1024
    return fields["VmRSS"], fields["VmHWM"]


def reset_peak() -> None:
    """Start VmHWM again from the current resident set (``5`` to ``/proc/self/clear_refs``)."""
    with open("/proc/self/clear_refs", "w") as refs:
        refs.write("5")


def describe(case: str, sim, steps: int) -> dict:
    """The mesh and the state of ``case``'s Simulation ``sim`` (what benchmarks/scaling_model.py
    needs to recount the bytes exchanged)."""
    mesh = sim.mesh
    return {"case": case, "cells": mesh.ncells, "blocks": mesh.nblocks, "block_cells": mesh.block_cells,
            "blocks_per_axis": mesh.blocks_per_axis[:mesh.ndim].tolist(),
            "periodic": [low == "periodic" for low, _ in mesh.boundaries],
            "components": sum(array.shape[1] for array in sim.state.arrays().values()),
            "materials": sim.state.nmat, "strength": sim.strength is not None, "steps": steps}


def measure(comm, case: str, steps: int, block_cells: int | None, rank_0_builds: bool = False) -> dict:
    """Rate (cell-updates/s) and per-rank traffic of ``steps`` steps of ``case`` shared between
    the ranks of ``comm``; ``skipped`` with the reasons where the ranks cannot share it (rank 0's
    result; the others return an empty dict).  ``rank_0_builds``: rank 0 builds an impact case
    alone and shares it out, as the boxes."""
    if case.startswith("2d-cyl") and comm.size > 1 and not rank_0_builds:  # as impactpipe run builds an impact
        sim = build(case, quick=False, comm=comm)
        return measure_built(comm, case, sim, steps)
    sim = build(case, quick=False, block_cells=block_cells) if comm.rank == 0 else None
    reasons = comm.bcast(unsupported(sim.mesh, comm.size) if comm.rank == 0 and comm.size > 1 else [], root=0)
    if reasons and comm.rank != 0:
        return {}
    if reasons:
        return {**describe(case, sim, steps), "skipped": f"not shared between {comm.size} ranks in this version: "
                                                         f"{'; '.join(reasons)} (hydro.parallel.distributed.unsupported)"}
    if comm.size > 1:
        sim = distribute_from_root(sim, comm)
    return measure_built(comm, case, sim, steps)


def measure_built(comm, case: str, sim, steps: int) -> dict:
    """:func:`measure` of ``sim``, this rank's share of ``case``'s run."""
    setup_peak = resident()[1]
    result = describe(case, sim, steps)
    for _ in range(2):
        sim.step()
    comm.Barrier()
    reset_peak()
    traffic = sim.partition.traffic
    traffic.reset()
    start_updates = sim.cell_updates
    started = time.perf_counter()
    for _ in range(steps):
        sim.step()
    comm.Barrier()
    wall = time.perf_counter() - started
    resident_bytes, step_peak = resident()
    per_step = traffic.as_dict()
    reset_peak()
    sim.snapshot()
    gathered = traffic.gather_seconds
    snapshot_started = time.perf_counter()
    sim.snapshot()
    snapshot_s = time.perf_counter() - snapshot_started
    snapshot_peak = resident()[1]
    lo, hi, _ = sim.partition.blocks.indices(sim.mesh.nblocks)
    owned_cells = (hi - lo) * sim.mesh.ncells // sim.mesh.nblocks
    compute = wall - per_step["exchange_seconds"] - per_step["allreduce_seconds"]
    rank = {"blocks": hi - lo, "cells": owned_cells,
            "bytes_sent": per_step["bytes_sent"] / steps, "bytes_received": per_step["bytes_received"] / steps,
            "messages_sent": per_step["messages_sent"] / steps, "allreduces": per_step["allreduces"] / steps,
            "wait_s": per_step["wait_seconds"] / steps, "exchange_s": per_step["exchange_seconds"] / steps,
            "allreduce_s": per_step["allreduce_seconds"] / steps,
            "compute_s_per_cell_update": compute / (owned_cells * steps),
            "snapshot_s": snapshot_s, "gather_s": traffic.gather_seconds - gathered,
            "setup_peak_resident_bytes": setup_peak, "step_peak_resident_bytes": step_peak,
            "resident_bytes": resident_bytes, "resident_bytes_per_cell": resident_bytes / owned_cells,
            "snapshot_peak_resident_bytes": snapshot_peak}
    result.update(wall_s=wall, cell_updates_per_s=(sim.cell_updates - start_updates) / wall,
                  state_bytes=int(sum(array.nbytes for array in sim.state.arrays().values())))
    del sim
    gc.collect()
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    rank["released_resident_bytes"] = resident()[0]
    rank["run_resident_bytes"] = resident_bytes - rank["released_resident_bytes"]
    rank["run_resident_bytes_per_cell"] = rank["run_resident_bytes"] / owned_cells
    return {**result, "ranks": comm.gather(rank, root=0)}


def pingpong(comm) -> dict | None:
    """One-way latency (s, 8-byte messages) and bandwidth (B/s, 16 MiB messages) between ranks 0
    and 1, each the median of ROUND_TRIPS round trips; None on one rank."""
    if comm.size < 2:
        return None
    out = {}
    for key, size in (("latency_s", LATENCY_BYTES), ("bandwidth_bytes_per_s", BANDWIDTH_BYTES)):
        buffer = np.zeros(size // 8)
        times = []
        for _ in range(ROUND_TRIPS):
            comm.Barrier()
            started = time.perf_counter()
            if comm.rank == 0:
                comm.Send(buffer, dest=1)
                comm.Recv(buffer, source=1)
            elif comm.rank == 1:
                comm.Recv(buffer, source=0)
                comm.Send(buffer, dest=0)
            times.append((time.perf_counter() - started) / 2)
        one_way = float(np.median(times))
        out[key] = one_way if key == "latency_s" else size / one_way
    return comm.bcast(out, root=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", nargs="*", default=list(DEFAULT_CASES), choices=CASES)
    parser.add_argument("--steps", type=int, default=10, help="timed steps per case (default 10)")
    parser.add_argument("--block-cells", type=int, help="block edge of the box cases (default: the uniform mesh's own)")
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    parser.add_argument("--rank-0-builds", action="store_true",
                        help="rank 0 builds the impact cases alone and shares them out (by default the ranks build "
                             "them together, each its own blocks)")
    args = parser.parse_args()
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    numba.set_num_threads(1)
    results = [measure(comm, case, args.steps, args.block_cells, args.rank_0_builds) for case in args.cases]
    link = pingpong(comm)
    if comm.rank != 0:
        return
    report = {"ranks": comm.size, "load_average": os.getloadavg(), "cpu_count": os.cpu_count(), "pingpong": link,
              "results": results}
    if args.json:
        print(json.dumps(report, indent=2))
        return
    for r in results:
        if "skipped" in r:
            print(f"{r['case']}: {r['skipped']}")
            continue
        print(f"{r['case']}: {comm.size} ranks, {r['cell_updates_per_s']:.3g} cell-updates/s")
        for i, rank in enumerate(r["ranks"]):
            print(f"  rank {i}: {rank['blocks']} blocks, {rank['bytes_sent']:.3g} B and {rank['messages_sent']:g} "
                  f"messages sent per step, waiting {rank['wait_s']:.3g} s per step, "
                  f"{rank['compute_s_per_cell_update']:.3g} s per cell-update")


if __name__ == "__main__":
    main()
