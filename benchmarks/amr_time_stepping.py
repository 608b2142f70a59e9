"""Wall time and cell-updates of the global step and of the step per level on an adaptive mesh.

The 2d-cylindrical Sedov blast of benchmarks/amr_ghost_profile.py (one ideal gas, 256 finest
cells per axis, 3 levels) runs from t = 0 to ``--end`` (s) with ``hydro.time_stepping`` global
and per_level, after a short run of both (``--warm-up`` s) so that every kernel is compiled;
prints, per mode, the wall seconds of the run, root steps, cell-updates (each level's cells
once per substep of its own), the regrids' share of the wall time, the density L1 error
against the exact solution (docs/hydro.md, "Time step"), the mass the floors added, the root
steps taken again (``level_step_retakes``), the budget's unaccounted mass and energy (relative,
the floors counted) and, for the impacts, the budget's z momentum error (relative to the
projectile's momentum), the signed z momentum the void cleanup and the small-cell velocity limit
removed (same scale) and the z momentum unaccounted once they are taken back.
``--scene impact`` runs instead the hydro-only impact of docs/hydro.md (basalt Tillotson
without strength, R_T = 1 km, R_P = 100 m, 8 cells per projectile radius or
``--cells-per-projectile-radius``, 4 levels, 2d-cylindrical) to ``--end`` 1 s and prints no L1 error; ``--scene strength_impact`` the
same impact with GEO ``weak`` strength (docs/hydro.md, "Time step"):

    NUMBA_NUM_THREADS=1 python benchmarks/amr_time_stepping.py
    NUMBA_NUM_THREADS=1 python benchmarks/amr_time_stepping.py --scene impact --end 1.0
    NUMBA_NUM_THREADS=1 python benchmarks/amr_time_stepping.py --scene strength_impact --end 0.3
"""

import argparse
import time

import numpy as np

from impactpipe.hydro.budget import conservation_budget
from impactpipe.hydro.exact.sedov import sedov_solution
from impactpipe.hydro.problems import PROBLEMS
from impactpipe.hydro.problems.common import preset_material
from impactpipe.pipeline.presets import resolve_strength

GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 717.5}


def sedov(cells: int, mode: str):
    """The Sedov Simulation on 3 levels at ``cells`` finest cells per axis, stepped by ``mode``."""
    sim = PROBLEMS["sedov"].setup({"cells": cells, "end_time": 1.0, "deposit_cells": 3.5, "levels": 3},
                                  {"gas": {"eos": GAS}}, geometry="2d-cylindrical")
    sim.time_stepping = mode
    return sim


def impact(mode: str, strength: bool = False, cells: int = 8):
    """The hydro-only impact (module docstring) on 4 levels at ``cells`` per projectile radius,
    stepped by ``mode``; with GEO ``weak`` strength when ``strength``."""
    basalt = preset_material("basalt")
    if strength:
        basalt["strength"] = resolve_strength("geo", "weak", {})
    sim = PROBLEMS["impact"].setup({"cells_per_projectile_radius": cells, "levels": 4, "end_time": 1.0},
                                   {"basalt": basalt}, geometry="2d-cylindrical")
    sim.time_stepping = mode
    return sim


def density_l1(sim) -> float:
    """Volume-weighted mean |rho - rho_exact| (kg/m^3) against the exact Sedov solution (E = 1 J, rho = 1)."""
    snap = sim.snapshot()
    radius = np.sqrt((snap.centers ** 2).sum(axis=1))
    exact = sedov_solution(1.4, 3).profiles(radius, sim.time, 1.0, 1.0)[0]
    return float((np.abs(snap.density.reshape(-1) - exact) * snap.volumes).sum() / snap.volumes.sum())


def removed(sim, initial: dict, by: str) -> float:
    """The z momentum (kg m/s, signed: the ``y`` component in 2d-cylindrical) that the floor ``by``
    (``void_cleanup`` or ``velocity_limit``) took off the mesh, over the budget's scale (the
    initial sum of |rho u| V, here the projectile's momentum)."""
    return sim.floor_amounts[f"momentum_y_removed_by_{by}"] / initial["momentum_magnitude"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", choices=("sedov", "impact", "strength_impact"), default="sedov")
    parser.add_argument("--cells", type=int, default=256, help="Sedov's finest cells per axis")
    parser.add_argument("--end", type=float, default=0.05)
    parser.add_argument("--cells-per-projectile-radius", type=int, default=8, help="the impacts' resolution")
    parser.add_argument("--warm-up", type=float, default=0.002)
    args = parser.parse_args()
    radius_cells = args.cells_per_projectile_radius
    builders = {"sedov": lambda mode: sedov(args.cells, mode), "impact": lambda mode: impact(mode, cells=radius_cells),
                "strength_impact": lambda mode: impact(mode, strength=True, cells=radius_cells)}
    build = builders[args.scene]
    for mode in ("global", "per_level"):
        build(mode).run(args.warm_up)
    for mode in ("global", "per_level"):
        sim = build(mode)
        initial = sim.totals()
        started = time.perf_counter()
        sim.run(args.end)
        wall = time.perf_counter() - started
        budget = conservation_budget(initial, sim.totals(), sim.floor_amounts)
        print(f"{mode:9s} wall {wall:7.2f} s  root steps {sim.step_count:5d}  cell-updates {sim.cell_updates:.4e}  "
              f"({sim.cell_updates / wall:.3e} /s)  regrids {sim.regrid_seconds:5.2f} s  "
              f"blocks per level {np.bincount(sim.mesh.block_level, minlength=3).tolist()}  "
              + (f"density L1 {density_l1(sim):.4e}  " if args.scene == "sedov" else "")
              + f"floor mass {sim.floor_amounts['mass_added_by_floors']:.2e} kg  retaken {sim.level_step_retakes}  "
              f"unaccounted mass {budget['mass_unaccounted']:.1e} energy {budget['energy_unaccounted']:.1e}"
              + (f"  z momentum error {budget['momentum_y_error']:.4e} (removed by the void cleanup "
                 f"{removed(sim, initial, 'void_cleanup'):.4e}, by the velocity limit "
                 f"{removed(sim, initial, 'velocity_limit'):.4e}) unaccounted {budget['momentum_y_unaccounted']:.1e}"
                 if args.scene != "sedov" else ""),
              flush=True)


if __name__ == "__main__":
    main()
