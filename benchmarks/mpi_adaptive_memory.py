"""Memory per rank of an adaptive run shared between MPI ranks, through its regrids.

Run under mpiexec, one numba thread per rank, with the kernels in numba's cache:

    NUMBA_NUM_THREADS=1 mpiexec -n N python benchmarks/mpi_adaptive_memory.py --json   # N = 1, 2, 4

The scene is the adaptive r-z impact of tests/configs/mpi/impact_adaptive.yaml (basalt with GEO
strength and Grady-Kipp fracture, self-gravity, three levels, a regrid every 2 steps) on a
finer mesh (``--cells-per-radius`` cells across the projectile's radius at the finest level,
``--block-cells``), without tracers.  Rank 0 alone builds it and shares it out
(:func:`impactpipe.hydro.parallel.distributed.distribute_from_root`, as ``impactpipe run
--ranks N`` does); then ``--steps`` steps.  Per rank (B, ``/proc/self/status``):
``setup_peak_resident_bytes``, the largest resident set through the build and the sharing;
``step_peak_resident_bytes``, the largest through the steps (the peak reset after the
sharing, ``/proc/self/clear_refs``), and ``resident_bytes`` after them; ``blocks``, the blocks
it owns at the end.  Rank 0 prints one JSON document with the mesh at the end (``blocks``,
``cells``), the bytes of its whole state (``state_bytes``), the regrids and the blocks they
refined and coarsened.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mpi_scaling import reset_peak, resident  # noqa: E402

from impactpipe.hydro.parallel.distributed import distribute_from_root  # noqa: E402
from impactpipe.pipeline import derived, load_config  # noqa: E402

CONFIG = "tests/configs/mpi/impact_adaptive.yaml"


def build(cells_per_radius: int, block_cells: int):
    """The adaptive impact's Simulation (``CONFIG`` on the finer mesh, no tracers)."""
    from impactpipe.pipeline.adapters.hydro import build_simulation

    config = load_config(CONFIG, overrides={"hydro.cells_per_projectile_radius": cells_per_radius,
                                            "hydro.block_cells": block_cells, "hydro.tracers.enabled": False})
    return build_simulation(config, derived.derive(config))


def measure(comm, cells_per_radius: int, block_cells: int, steps: int) -> dict | None:
    """The per-rank memory of ``steps`` steps of the adaptive impact shared between the ranks of
    ``comm``; rank 0's result (None on the others)."""
    sim = build(cells_per_radius, block_cells) if comm.rank == 0 else None
    if comm.size > 1:
        sim = distribute_from_root(sim, comm)
    setup_peak = resident()[1]
    comm.Barrier()
    reset_peak()
    for _ in range(steps):
        sim.step()
    comm.Barrier()
    resident_bytes, step_peak = resident()
    lo, hi, _ = sim.partition.blocks.indices(sim.mesh.nblocks)
    rank = {"blocks": hi - lo, "setup_peak_resident_bytes": setup_peak, "step_peak_resident_bytes": step_peak,
            "resident_bytes": resident_bytes}
    ranks = comm.gather(rank, root=0)
    if comm.rank != 0:
        return None
    return {"ranks_count": comm.size, "blocks": sim.mesh.nblocks, "cells": sim.mesh.ncells,
            "block_cells": sim.mesh.block_cells, "steps": steps,
            "state_bytes": int(sum(array.nbytes for array in sim.state.arrays().values())),
            "regrids": sim.regrids, "blocks_refined": sim.blocks_refined, "blocks_coarsened": sim.blocks_coarsened,
            "ranks": ranks}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cells-per-radius", type=int, default=32,
                        help="cells across the projectile's radius (default 32)")
    parser.add_argument("--block-cells", type=int, default=16, help="block edge in cells (default 16)")
    parser.add_argument("--steps", type=int, default=8, help="steps (default 8: four regrids)")
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    args = parser.parse_args()
    from mpi4py import MPI

    result = measure(MPI.COMM_WORLD, args.cells_per_radius, args.block_cells, args.steps)
    if result is not None:
        json.dump(result, sys.stdout, indent=None if args.json else 2)
        sys.stdout.write("\n")


if __name__ == "__main__":
    main()
