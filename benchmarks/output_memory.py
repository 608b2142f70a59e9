"""What a snapshot and a checkpoint cost each MPI rank in memory, written together (parallel HDF5)
or gathered on rank 0.

Runs the r-z impact with strength and 60 tracers (tests/configs/mpi/impact_strength.yaml at
``--cells`` cells per projectile radius, 16^2 blocks) on ``--ranks`` ranks, one thread each:
rank 0 builds it and shares it out (:func:`~impactpipe.hydro.parallel.distributed.distribute_from_root`),
the ranks take 3 steps, then write one snapshot (appended to a working file, as the hydro stage
does) and one checkpoint, first gathered on rank 0 (``IMPACTPIPE_PARALLEL_HDF5=0``), then
together (only where h5py was built with parallel HDF5).  Prints JSON: per way and rank, how
much the peak resident set (VmHWM) grew over the resident set before the two outputs, the
bytes of the whole state and of the rank's own blocks' rows of it.

    python benchmarks/output_memory.py [--ranks 3] [--cells 24]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import h5py
import yaml

from impactpipe.hydro.parallel.distributed import PARALLEL_HDF5_VARIABLE
from impactpipe.pipeline import ranks

CONFIG = Path(__file__).resolve().parent.parent / "tests" / "configs" / "mpi" / "impact_strength.yaml"

#: Argument 1: the config, which rank 0 builds; 3 steps on the ranks, then a snapshot appended to
#: OUT.work.h5 and a checkpoint OUT.checkpoint.h5 (argument 2), as the hydro stage writes them;
#: writes to OUT.rankR.json the growth of the rank's peak resident set (B) over the two outputs,
#: the bytes of the whole state and of this rank's rows of it, and which way the ranks wrote.
OUTPUTS = """
import gc, json, sys
from impactpipe.hydro.parallel.distributed import distribute_from_root
from impactpipe.pipeline import derived, load_config, ranks
from impactpipe.pipeline.adapters.hydro import _append, add_tracers, build_simulation
def resident(name):
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) * 1024 for line in status if line.startswith(name + ":"))
comm = ranks.join_world()
sim = None
if comm.rank == 0:
    config = load_config(sys.argv[1])
    values = derived.derive(config)
    sim = build_simulation(config, values)
    add_tracers(sim, config, float(values["end_time"]))
sim = distribute_from_root(sim, comm)
for _ in range(3):
    sim.step()
gc.collect()
with open("/proc/self/clear_refs", "w") as refs:
    refs.write("5")
before = resident("VmRSS")
_append(sys.argv[2] + ".work.h5", sim.snapshot(), sim.partition)
sim.save_checkpoint(sys.argv[2] + ".checkpoint.h5")
part = sim.partition
whole = sum(array.nbytes for array in sim.state.arrays().values())
with open(f"{sys.argv[2]}.rank{comm.rank}.json", "w") as out:
    out.write(json.dumps({"grown": resident("VmHWM") - before, "whole": whole, "together": part.writes_together,
                          "own": whole * (part.hi - part.lo) // part.nblocks}))
"""


def scene(directory: Path, cells: int) -> Path:
    """The config of the measured scene, written into ``directory``."""
    config = yaml.safe_load(CONFIG.read_text())
    config["hydro"].update(cells_per_projectile_radius=cells, block_cells=16)
    config["hydro"]["tracers"] = {"enabled": True, "count": 60, "history_interval": 0.01}
    path = directory / f"impact_strength_{cells}cells.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


def write_outputs(config: Path, out: Path, together: bool, nranks: int = 3) -> list[dict]:
    """The per-rank records of OUTPUTS on ``nranks`` ranks (files OUT.work.h5, OUT.checkpoint.h5)."""
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", PARALLEL_HDF5_VARIABLE: "1" if together else "0"}
    result = subprocess.run([ranks.mpiexec_path(), "-n", str(nranks), sys.executable, "-c", OUTPUTS, str(config),
                             str(out)], env=env, capture_output=True, text=True, timeout=900)
    if result.returncode != 0:
        raise RuntimeError(result.stderr)
    counted = [json.loads(Path(f"{out}.rank{rank}.json").read_text()) for rank in range(nranks)]
    if any(c["together"] != together for c in counted):
        raise RuntimeError("the ranks did not write the way asked for")
    return counted


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ranks", type=int, default=3)
    parser.add_argument("--cells", type=int, default=24, help="cells per projectile radius")
    args = parser.parse_args()
    ways = [False, True] if h5py.get_config().mpi else [False]
    report = {"ranks": args.ranks, "cells_per_projectile_radius": args.cells, "parallel_hdf5": h5py.get_config().mpi}
    with tempfile.TemporaryDirectory() as directory:
        config = scene(Path(directory), args.cells)
        for together in ways:
            counted = write_outputs(config, Path(directory) / ("together" if together else "gathered"), together,
                                    args.ranks)
            report["whole_state_bytes"] = counted[0]["whole"]
            report["together" if together else "gathered"] = [
                {"rank": r, "grown_bytes": c["grown"], "own_state_bytes": c["own"],
                 "grown_over_whole_state": round(c["grown"] / c["whole"], 3)} for r, c in enumerate(counted)]
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
