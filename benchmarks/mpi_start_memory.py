"""What starting a run costs each MPI rank in memory: built by rank 0 and shared out, or by the
ranks together, each its own blocks; read from a checkpoint by rank 0 and shared out, or by the
ranks together.

Runs the r-z impact with GEO strength (tests/configs/mpi/impact_strength.yaml at ``--cells``
cells per projectile radius, 16^2 blocks) on ``--ranks`` ranks, one thread each, with glibc's
mmap threshold fixed (``MALLOC_MMAP_THRESHOLD_=131072``: freed arrays go back to the system, so
each start's growth is its own).  Prints JSON: per rank, how much the peak resident set (VmHWM)
grew over each of the four starts, and the bytes of the whole state.

    python benchmarks/mpi_start_memory.py [--ranks 3] [--cells 24]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

from impactpipe.pipeline import ranks

CONFIG = Path(__file__).resolve().parent.parent / "tests" / "configs" / "mpi" / "impact_strength.yaml"

#: Arguments 1 and 2: a small config and the same scene on a finer mesh, 3: OUT.  For each, the
#: run starts four ways: rank 0 builds it and shares it out, the ranks build it together (each
#: its own blocks), rank 0 reads the ranks' checkpoint of it and shares it out, the ranks read
#: it together (each its own blocks); the small run first, so that the kernels are loaded
#: before the measurement.  Writes, per rank, to OUT.rankR.json: how much the peak resident
#: set (VmHWM, B) grew over the resident set before each start of the fine run, and the bytes
#: of its whole state.
STARTS = """
import gc, json, sys
from impactpipe.hydro.parallel.distributed import distribute_from_root
from impactpipe.hydro.solver import Simulation
from impactpipe.pipeline import derived, load_config, ranks
from impactpipe.pipeline.adapters.hydro import build_simulation
def resident(name):
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) * 1024 for line in status if line.startswith(name + ":"))
def grown(start):
    gc.collect()
    with open("/proc/self/clear_refs", "w") as refs:
        refs.write("5")
    before = resident("VmRSS")
    start()
    return resident("VmHWM") - before
comm = ranks.join_world()
checkpoint = sys.argv[3] + ".checkpoint.h5"
for path in sys.argv[1:3]:
    config = load_config(path)
    values = derived.derive(config)
    sim = build_simulation(config, values, comm)
    sim.save_checkpoint(checkpoint)
    whole = sum(array.nbytes for array in sim.state.arrays().values())
    del sim
    out = {"whole": whole,
           "rank_0_builds": grown(lambda: distribute_from_root(build_simulation(config, values)
                                                                if comm.rank == 0 else None, comm)),
           "built_together": grown(lambda: build_simulation(config, values, comm)),
           "rank_0_reads": grown(lambda: distribute_from_root(Simulation.from_checkpoint(checkpoint)
                                                               if comm.rank == 0 else None, comm)),
           "read_together": grown(lambda: Simulation.from_checkpoint(checkpoint, comm))}
with open(f"{sys.argv[3]}.rank{comm.rank}.json", "w") as out_file:
    out_file.write(json.dumps(out))
"""


def start_peaks(directory: Path, cells: int, nranks: int) -> list[dict]:
    """The per-rank records of STARTS on ``nranks`` ranks, the fine run at ``cells`` cells per
    projectile radius (the small one at 2), its files in ``directory``."""
    config = yaml.safe_load(CONFIG.read_text())
    paths = []
    for name, n, block in (("small", 2, 4), ("fine", cells, 16)):
        config["hydro"].update(cells_per_projectile_radius=n, block_cells=block)
        paths.append(directory / f"impact_strength_{name}.yaml")
        paths[-1].write_text(yaml.safe_dump(config))
    out = directory / "starts"
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", "MALLOC_MMAP_THRESHOLD_": "131072"}
    result = subprocess.run([ranks.mpiexec_path(), "-n", str(nranks), sys.executable, "-c", STARTS, *map(str, paths),
                             str(out)], env=env, capture_output=True, text=True, timeout=600)
    if result.returncode != 0:
        raise RuntimeError(result.stderr)
    return [json.loads(Path(f"{out}.rank{rank}.json").read_text()) for rank in range(nranks)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ranks", type=int, default=3)
    parser.add_argument("--cells", type=int, default=24, help="cells per projectile radius")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as directory:
        counted = start_peaks(Path(directory), args.cells, args.ranks)
    print(json.dumps({"ranks": args.ranks, "cells_per_projectile_radius": args.cells,
                      "whole_state_bytes": counted[0]["whole"],
                      "grown_bytes": [{key: value for key, value in c.items() if key != "whole"} for c in counted]},
                     indent=2))


if __name__ == "__main__":
    main()
