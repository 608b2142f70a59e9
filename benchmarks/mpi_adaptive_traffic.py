"""What the ranks of an adaptive run exchange and wait for, per step, in the regrids, in the
sweeps' ghost fills and in the stress step's.

Run under mpiexec, one numba thread per rank, with the kernels in numba's cache:

    NUMBA_NUM_THREADS=1 mpiexec -n 2 python benchmarks/mpi_adaptive_traffic.py --json

The scene is the adaptive r-z impact of benchmarks/mpi_adaptive_memory.py (tests/configs/mpi/
impact_adaptive.yaml: basalt with GEO strength and Grady-Kipp fracture, self-gravity, three
levels, a regrid every 2 steps) at ``--cells-per-radius`` and ``--block-cells``, without
tracers, rank 0 building it and sharing it out.  After ``--warmup`` steps, ``--steps`` steps
between two barriers.  Each rank splits its traffic counters
(:class:`~impactpipe.hydro.parallel.exchange.Traffic`) and its wall time between three parts
of a step, through the Simulation's ``observer``: ``regrid`` (from the end of the step before
to after the regrid: the regrids, whose first ghost layer's fills exchange, and the step's
end), ``sweeps`` (from there to the last reflux: the state's ghost fills, the sweeps, the
refluxes) and ``stress`` (from there to the end of the momentum sources: the stress step's
fills of its work arrays and its kernels, self-gravity).  Per rank and step, for each part:
``messages_sent``, ``exchanges``,
``bytes_sent`` (B), ``exchange_s`` (s in the exchanges: packing, waiting, unpacking),
``wait_s`` (s of it in ``Waitall``) and ``wall_s``; and the step's ``wall_s``.  Rank 0 prints
one JSON document.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mpi_adaptive_memory import build  # noqa: E402

from impactpipe.hydro.parallel.distributed import distribute_from_root  # noqa: E402

#: The counters of a part of a step.
COUNTERS = ("messages_sent", "exchanges", "bytes_sent", "exchange_seconds", "wait_seconds")


class PartClock:
    """An observer of a Simulation's step (``sim.observer``) that adds the traffic counters and
    wall time of each part (``regrid``, ``sweeps``, ``stress``) to ``totals``, from a mark set
    when it is made."""

    def __init__(self, traffic, ndim: int):
        self.traffic = traffic
        self.ndim = ndim
        self.totals = {part: dict.fromkeys(COUNTERS + ("wall_seconds",), 0.0)
                       for part in ("regrid", "sweeps", "stress")}
        self.reflux_seen = 0
        self.mark = self._now()

    def __call__(self, event: str, axis: int) -> None:
        if event == "regrid":
            self.reflux_seen = 0
            self._close("regrid")
        elif event == "reflux":
            self.reflux_seen += 1
            if self.reflux_seen == self.ndim:
                self._close("sweeps")
        elif event == "sources":
            self._close("stress")

    def _now(self) -> dict:
        """The counters and the clock now."""
        return {**{name: getattr(self.traffic, name) for name in COUNTERS}, "wall_seconds": time.perf_counter()}

    def _close(self, part: str) -> None:
        """Add what passed since the last mark to ``part`` and mark now."""
        now = self._now()
        for name, value in now.items():
            self.totals[part][name] += value - self.mark[name]
        self.mark = now


def measure(comm, cells_per_radius: int, block_cells: int, warmup: int, steps: int) -> dict | None:
    """The per-rank traffic of ``steps`` steps (after ``warmup``) of the adaptive impact shared
    between the ranks of ``comm``; rank 0's result (None on the others)."""
    sim = build(cells_per_radius, block_cells) if comm.rank == 0 else None
    sim = distribute_from_root(sim, comm)
    for _ in range(warmup):
        sim.step()
    comm.Barrier()
    clock = PartClock(sim.partition.traffic, sim.mesh.ndim)
    sim.observer = clock
    started = time.perf_counter()
    for _ in range(steps):
        sim.step()
    comm.Barrier()
    wall = time.perf_counter() - started
    lo, hi, _ = sim.partition.blocks.indices(sim.mesh.nblocks)
    rank = {"blocks": hi - lo, "wall_s": wall / steps}
    for part, totals in clock.totals.items():
        rank[part] = {name.replace("_seconds", "_s"): value / steps for name, value in totals.items()}
    ranks = comm.gather(rank, root=0)
    if comm.rank != 0:
        return None
    return {"ranks_count": comm.size, "blocks": sim.mesh.nblocks, "cells": sim.mesh.ncells,
            "block_cells": sim.mesh.block_cells, "warmup": warmup, "steps": steps, "regrids": sim.regrids,
            "ranks": ranks}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cells-per-radius", type=int, default=64,
                        help="cells across the projectile's radius (default 64)")
    parser.add_argument("--block-cells", type=int, default=16, help="block edge in cells (default 16)")
    parser.add_argument("--warmup", type=int, default=2, help="steps before the timed ones (default 2)")
    parser.add_argument("--steps", type=int, default=8, help="timed steps (default 8: four regrids)")
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    args = parser.parse_args()
    from mpi4py import MPI

    result = measure(MPI.COMM_WORLD, args.cells_per_radius, args.block_cells, args.warmup, args.steps)
    if result is not None:
        json.dump(result, sys.stdout, indent=None if args.json else 2)
        sys.stdout.write("\n")


if __name__ == "__main__":
    main()
