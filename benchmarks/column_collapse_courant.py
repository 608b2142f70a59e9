"""Granular column collapse against the Courant number: run-out, height and rest time.

Builds the scene of configs/column_collapse.yaml (a = 1, 16 cells per height, cohesionless GEO with
tan 25 deg friction) at each Courant number, bypassing the scene's cfl
limit, and prints the deposit every ``--every`` tau and, per Courant number, the first time
the kinetic energy falls below 1e-3 of its peak (docs/validation.md, "Granular column
collapse").  With three or more Courant numbers it ends with the Richardson estimate
(:func:`impactpipe.pipeline.convergence.richardson`, the time step as the step size) of
the final deposit's centroid, run-out and height.

    python benchmarks/column_collapse_courant.py --cfl 0.4 0.2 0.1 --end 12 [--config CONFIG]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from pathlib import Path

from impactpipe.hydro.problems import column_collapse
from impactpipe.pipeline.config import load_config
from impactpipe.pipeline.convergence import richardson

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "column_collapse.yaml"


def run(config_path: Path, cfl: float, end: float, every: float) -> dict:
    """Run the scene at Courant number ``cfl`` to ``end`` tau, printing a row every ``every`` tau;
    returns the final deposit in units of L0 (run-out L_f - L0, height, centroid)."""
    config = load_config(config_path)
    scene = config.scene.model_dump(exclude={"problem", "geometry"})
    sim = column_collapse.setup(scene, config.resolved_materials(), block_cells=config.hydro.block_cells,
                                cfl=min(cfl, column_collapse.MAX_CFL))
    sim.cfl = cfl  # past the scene's limit on purpose: that limit is what this script measures
    height, width = scene["height"], scene["width"]
    tau = math.sqrt(height / scene["gravity"])
    peak, rest, started = 0.0, None, time.perf_counter()
    for k in range(1, int(round(end / every)) + 1):
        sim.run(k * every * tau)
        snap = sim.snapshot()
        energy = column_collapse.kinetic_energy(snap)
        peak = max(peak, energy)
        deposit = column_collapse.deposit(snap)
        if rest is None and energy < 1e-3 * peak:
            rest = sim.time / tau
        print(f"cfl {cfl:g}  t/tau {sim.time / tau:6.2f}  steps {sim.step_count:7d}  KE/peak {energy / peak:.2e}  "
              f"runout {(deposit['runout'] - width) / width:.3f}  height {deposit['height'] / width:.3f}  "
              f"centroid {deposit['centroid'] / width:.4f}  "
              f"wall {time.perf_counter() - started:.0f} s", flush=True)
    print(f"cfl {cfl:g}: KE below 1e-3 of its peak from {rest} tau; laws: run-out "
          f"{column_collapse.scaling_runout(height / width):.3g}, height {column_collapse.scaling_height(height / width):.3g}")
    return {"runout": (deposit["runout"] - width) / width, "height": deposit["height"] / width,
            "centroid": deposit["centroid"] / width}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cfl", type=float, nargs="+", default=[0.4, 0.2, 0.1])
    parser.add_argument("--end", type=float, default=12.0, help="end time in tau = sqrt(H0 / g)")
    parser.add_argument("--every", type=float, default=1.0, help="row interval in tau")
    parser.add_argument("--config", type=Path, default=CONFIG,
                        help="a column_collapse config (default configs/column_collapse.yaml)")
    args = parser.parse_args()
    finals = [run(args.config, cfl, args.end, args.every) for cfl in args.cfl]
    if len(finals) >= 3:
        for answer in ("centroid", "runout", "height"):
            fit = richardson(np.array(args.cfl), np.array([f[answer] for f in finals]))
            text = f"{fit.value:.4f} (observed order {fit.order:.2f})" if fit.ok else fit.status
            print(f"{answer} at {args.end:g} tau, extrapolated to zero time step: {text}")


if __name__ == "__main__":
    main()
