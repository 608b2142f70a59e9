"""Wall time and cell-updates of the global step and of the step per level on an adaptive mesh.

The 2d-cylindrical Sedov blast of benchmarks/amr_ghost_profile.py (one ideal gas, 256 finest
cells per axis, 3 levels) runs from t = 0 to ``--end`` (s) with ``hydro.time_stepping`` global
and per_level, after a short run of both (``--warm-up`` s) so that every kernel is compiled;
prints, per mode, the wall seconds of the run, root steps, cell-updates (each level's cells
once per substep of its own), the regrids' share of the wall time and the density L1 error
against the exact solution (docs/hydro.md, "Time step"):

    NUMBA_NUM_THREADS=1 python benchmarks/amr_time_stepping.py
"""

import argparse
import time

import numpy as np

from impactpipe.hydro.exact.sedov import sedov_solution
from impactpipe.hydro.problems import PROBLEMS

GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 717.5}


def sedov(cells: int, mode: str):
    """The Sedov Simulation on 3 levels at ``cells`` finest cells per axis, stepped by ``mode``."""
    sim = PROBLEMS["sedov"].setup({"cells": cells, "end_time": 1.0, "deposit_cells": 3.5, "levels": 3},
                                  {"gas": {"eos": GAS}}, geometry="2d-cylindrical")
    sim.time_stepping = mode
    return sim


def density_l1(sim) -> float:
    """Volume-weighted mean |rho - rho_exact| (kg/m^3) against the exact Sedov solution (E = 1 J, rho = 1)."""
    snap = sim.snapshot()
    radius = np.sqrt((snap.centers ** 2).sum(axis=1))
    exact = sedov_solution(1.4, 3).profiles(radius, sim.time, 1.0, 1.0)[0]
    return float((np.abs(snap.density.reshape(-1) - exact) * snap.volumes).sum() / snap.volumes.sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=256)
    parser.add_argument("--end", type=float, default=0.05)
    parser.add_argument("--warm-up", type=float, default=0.002)
    args = parser.parse_args()
    for mode in ("global", "per_level"):
        sedov(args.cells, mode).run(args.warm_up)
    for mode in ("global", "per_level"):
        sim = sedov(args.cells, mode)
        started = time.perf_counter()
        sim.run(args.end)
        wall = time.perf_counter() - started
        print(f"{mode:9s} wall {wall:7.2f} s  root steps {sim.step_count:5d}  cell-updates {sim.cell_updates:.4e}  "
              f"({sim.cell_updates / wall:.3e} /s)  regrids {sim.regrid_seconds:5.2f} s  "
              f"blocks per level {np.bincount(sim.mesh.block_level, minlength=3).tolist()}  "
              f"density L1 {density_l1(sim):.4e}  floor mass {sim.floor_amounts['mass_added_by_floors']:.2e} kg",
              flush=True)


if __name__ == "__main__":
    main()
