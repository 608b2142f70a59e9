"""Steps an impact's hydro stage takes to its end (hand-off) time on a uniform mesh, at coarse
resolutions: the step count the scaling model (benchmarks/scaling_model.py) extrapolates to a
fine mesh.  The CFL step is dt = C dx / max(|u| + c) (s), so at the same signal speeds the step
count would grow as the cells per projectile radius n; a finer mesh resolves faster flow at the
contact, and the model fits steps ~ n^p through the two finest runs.

    python benchmarks/handoff_steps.py configs/reference/case8c.yaml --cells-per-radius 5 10 --json

Each run is the config's scene with ``hydro.max_levels: 1`` (uniform: what MPI ranks share in
this version), tracers off, ``hydro.cells_per_projectile_radius`` set, advanced from t = 0 to
the derived end time without snapshots.  Prints the config, and per resolution the mesh
(cells, blocks, block edge), the end time (s), the steps and the wall time (s).
"""

from __future__ import annotations

import argparse
import json
import time

from impactpipe.pipeline import derived, load_config
from impactpipe.pipeline.adapters.hydro import build_simulation


def count_steps(path: str, cells_per_radius: float) -> dict:
    """Steps of the uniform-mesh hydro stage of the config at ``path`` at ``cells_per_radius``."""
    config = load_config(path, overrides={"hydro.max_levels": 1, "hydro.tracers.enabled": False,
                                          "hydro.cells_per_projectile_radius": cells_per_radius})
    values = derived.derive(config)
    sim = build_simulation(config, values)
    started = time.perf_counter()
    steps = sim.run(float(values["end_time"]))
    return {"cells_per_projectile_radius": cells_per_radius, "cells": sim.mesh.ncells, "blocks": sim.mesh.nblocks,
            "block_cells": sim.mesh.block_cells, "end_time": float(values["end_time"]), "steps": steps,
            "wall_s": time.perf_counter() - started}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("config")
    parser.add_argument("--cells-per-radius", type=float, nargs="+", required=True,
                        help="hydro.cells_per_projectile_radius of each run")
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    args = parser.parse_args()
    runs = [count_steps(args.config, n) for n in args.cells_per_radius]
    if args.json:
        print(json.dumps({"config": args.config, "runs": runs}, indent=2))
        return
    for run in runs:
        print(f"{args.config} at {run['cells_per_projectile_radius']:g} cells per projectile radius: "
              f"{run['cells']} cells, {run['steps']} steps to {run['end_time']:.4g} s ({run['wall_s']:.1f} s)")


if __name__ == "__main__":
    main()
