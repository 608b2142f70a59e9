"""Granular column collapse against the Courant number: run-out, height and rest time.

Builds the scene of configs/column_collapse.yaml (a = 1, 16 cells per height, GEO with
tan 25 deg friction and Y0 = 2e5 Pa) at each Courant number, bypassing the scene's cfl
limit, and prints the deposit every ``--every`` tau and, per Courant number, the first time
the kinetic energy falls below 1e-3 of its peak (docs/validation.md, "Granular column
collapse").

    python benchmarks/column_collapse_courant.py --cfl 0.4 0.2 0.1 --end 12
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from impactpipe.hydro.problems import column_collapse
from impactpipe.pipeline.config import load_config

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "column_collapse.yaml"


def run(cfl: float, end: float, every: float) -> None:
    """Run the scene at Courant number ``cfl`` to ``end`` tau, printing a row every ``every`` tau."""
    config = load_config(CONFIG)
    scene = {key: value for key, value in config.scene.model_dump().items() if key in column_collapse.DEFAULTS}
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
              f"wall {time.perf_counter() - started:.0f} s", flush=True)
    print(f"cfl {cfl:g}: KE below 1e-3 of its peak from {rest} tau; laws: run-out "
          f"{column_collapse.scaling_runout(height / width):.3g}, height {column_collapse.scaling_height(height / width):.3g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cfl", type=float, nargs="+", default=[0.4, 0.2, 0.1])
    parser.add_argument("--end", type=float, default=12.0, help="end time in tau = sqrt(H0 / g)")
    parser.add_argument("--every", type=float, default=1.0, help="row interval in tau")
    args = parser.parse_args()
    for cfl in args.cfl:
        run(cfl, args.end, args.every)


if __name__ == "__main__":
    main()
