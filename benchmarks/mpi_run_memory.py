"""The peak memory of each MPI rank through a whole hydro stage of ``impactpipe run``.

Runs the hydro stage of the r-z impact with GEO strength and 60 tracers
(tests/configs/mpi/impact_strength.yaml at ``--cells`` cells per projectile radius, 16^2
blocks, to 0.05 s, one snapshot on the way) under ``mpiexec -n N`` for each N of ``--ranks``,
one numba thread per rank: the ranks build the run together, step it, write its snapshots
and checkpoint, and sum its totals.  Where h5py was built with parallel HDF5 each N runs twice,
the outputs written by the ranks together and gathered on rank 0
(``IMPACTPIPE_PARALLEL_HDF5=0``); otherwise gathered only.  Prints JSON: per run, each rank's
peak resident set (VmHWM, B) when it exits, and the run's steps; the scene's cells, blocks and
whole state (B, ghosts included).

    python benchmarks/mpi_run_memory.py [--ranks 1 2 4] [--cells 48]
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

from impactpipe.hydro.parallel.distributed import PARALLEL_HDF5_VARIABLE
from impactpipe.pipeline import derived, load_config, ranks
from impactpipe.pipeline.adapters.hydro import build_simulation

sys.path.insert(0, str(Path(__file__).resolve().parent))
from output_memory import scene  # noqa: E402  (the same scene)

#: ``impactpipe`` with the remaining arguments, which writes the peak resident set of its rank
#: (MPICH's PMI_RANK) to $PEAKS.rankR.json when it exits.
RECORDED = """
import atexit, json, os, sys
from impactpipe.pipeline.cli import main
def record():
    with open("/proc/self/status") as status:
        peak = next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmHWM:"))
    with open(f"{os.environ['PEAKS']}.rank{os.environ.get('PMI_RANK', '0')}.json", "w") as out:
        out.write(json.dumps({"peak_resident_bytes": peak}))
atexit.register(record)
sys.argv = ["impactpipe", *sys.argv[1:]]
main()
"""


def run(config: Path, out: Path, nranks: int, together: bool) -> dict:
    """The hydro stage of ``config`` on ``nranks`` ranks into ``out``: each rank's peak."""
    peaks = out.parent / f"{out.name}.peaks"
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", PARALLEL_HDF5_VARIABLE: "1" if together else "0",
           "PEAKS": str(peaks)}
    result = subprocess.run([ranks.mpiexec_path(), "-n", str(nranks), sys.executable, "-c", RECORDED, "run",
                             str(config), "--out", str(out), "--stage", "hydro", "-q"], env=env, capture_output=True,
                            text=True, timeout=3600)
    if result.returncode != 0:
        raise RuntimeError(result.stderr)
    with h5py.File(out / "hydro.h5", "r") as f:
        steps = int(f.attrs["steps"])
    return {"ranks": nranks, "together": together, "steps": steps,
            "peak_resident_bytes": [json.loads(Path(f"{peaks}.rank{r}.json").read_text())["peak_resident_bytes"]
                                    for r in range(nranks)]}


def state_size(config: Path) -> dict:
    """Cells, blocks and the bytes of the whole state (ghosts included) of ``config``'s run at t = 0."""
    loaded = load_config(config)
    sim = build_simulation(loaded, derived.derive(loaded))
    return {"cells": sim.mesh.ncells, "blocks": sim.mesh.nblocks,
            "state_bytes": sum(array.nbytes for array in sim.state.arrays().values())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--cells", type=int, default=48, help="cells per projectile radius")
    args = parser.parse_args()
    ways = [True, False] if h5py.get_config().mpi else [False]
    report = {"cells_per_projectile_radius": args.cells, "parallel_hdf5": bool(h5py.get_config().mpi), "runs": []}
    with tempfile.TemporaryDirectory() as directory:
        config = scene(Path(directory), args.cells)
        report.update(state_size(config))
        for nranks in args.ranks:
            for together in ways if nranks > 1 else ways[:1]:
                report["runs"].append(run(config, Path(directory) / f"run{nranks}{together}", nranks, together))
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
