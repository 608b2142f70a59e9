"""Adaptive mesh on the reference impact: cell-updates and wall time against a uniform mesh.

Runs the hydro stage of a config (default configs/reference/case8c.yaml: 10 km basalt
target, 0.83 km projectile at 1.9 km/s, GEO 'weak' strength, 20 cells per projectile
radius, 2d-cylindrical) to its end time with the adaptive mesh of ``hydro.max_levels``
(auto: 4 levels), then a uniform mesh at the finest cell size for ``--uniform-steps``
steps, and reports

- the adaptive run: steps, total cell-updates, wall seconds, seconds spent regridding (and
  the share of the wall time), blocks per level at the end, the mass and energy errors
  (mesh + outflow against the start, the floors' amounts not counted), the budget of
  :func:`~impactpipe.hydro.budget.conservation_budget` (the same with the floors' amounts
  counted: what stays unaccounted) and the floors' amounts themselves;
- the uniform run extrapolated to the same number of steps: its cells x the adaptive run's
  steps (both meshes share the finest cell, so the CFL step is set by the same cells), and
  its wall time per step x those steps.  With ``--time-stepping per_level`` (the adaptive run's
  levels subcycle, docs/hydro.md) the adaptive run's steps are root steps, each 2^(levels - 1)
  finest substeps, and the uniform run is extrapolated to as many finest substeps;
- the ratio of cell-updates (the issue's goal: at least 10) and of wall time.

    python benchmarks/amr_reference.py --json [--config PATH] [--end-time T] [--uniform-steps N]
                                       [--time-stepping global|per_level] [--interfaces all|active|off]
                                       [--override KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import json
import time

import numba
import numpy as np
import yaml

from impactpipe.hydro.budget import conservation_budget
from impactpipe.pipeline.adapters.hydro import build_simulation
from impactpipe.pipeline.config import load_config
from impactpipe.pipeline.derived import derive


def _simulation(config_path: str, levels, time_stepping: str = "global", cells: int | None = None,
                interfaces: str | None = None, overrides: dict | None = None):
    config = load_config(config_path, overrides=overrides or None)
    config.hydro.time_stepping = time_stepping
    if interfaces is not None:
        config.hydro.refinement.interfaces = interfaces
    if cells is not None:
        config.hydro.cells_per_projectile_radius = cells
    if levels is not None:
        config.hydro.max_levels = levels
    values = derive(config)
    return build_simulation(config, values), values


def run(config_path: str, end_time: float | None, uniform_steps: int, time_stepping: str = "global",
        cells: int | None = None, interfaces: str | None = None, overrides: dict | None = None) -> dict:
    """The measurements of the module docstring, as a dict (no uniform run when ``uniform_steps`` is 0);
    ``overrides`` (dotted config keys) apply to the adaptive run."""
    sim, values = _simulation(config_path, None, time_stepping, cells, interfaces, overrides)
    end = float(end_time or values["end_time"])
    start = sim.totals()
    started = time.perf_counter()
    sim.run(end)
    wall = time.perf_counter() - started
    done = sim.totals()
    finest_steps = sim.step_count * (2 ** int(values["levels"] - 1) if time_stepping == "per_level" else 1)
    adaptive = {
        "levels": int(values["levels"]),
        "time_stepping": time_stepping,
        "interfaces": sim.refinement.interfaces,
        "steps": sim.step_count,
        "finest_steps": finest_steps,
        "level_step_retakes": int(sim.level_step_retakes),
        "cell_updates": int(sim.cell_updates),
        "wall_seconds": wall,
        "regrid_seconds": sim.regrid_seconds,
        "regrid_share": sim.regrid_seconds / wall,
        "regrids": sim.regrids,
        "blocks_refined": sim.blocks_refined,
        "blocks_coarsened": sim.blocks_coarsened,
        "blocks_per_level_at_end": np.bincount(sim.mesh.block_level).tolist(),
        "cells_at_end": sim.mesh.ncells,
        "mass_error": (done["mass_with_outflow"] - start["mass"]) / start["mass"],
        "energy_error": (done["energy_with_outflow"] - start["energy"]) / start["energy"],
        "budget": conservation_budget(start, done, sim.floor_amounts),
        "floor_amounts": sim.floor_amounts,
    }
    if uniform_steps == 0:
        return {"config": config_path, "end_time": end, "threads": numba.config.NUMBA_NUM_THREADS,
                "adaptive": adaptive}
    uniform_sim, _ = _simulation(config_path, 1, "global", cells)
    uniform_sim.step()
    started = time.perf_counter()
    for _ in range(uniform_steps):
        uniform_sim.step()
    per_step = (time.perf_counter() - started) / uniform_steps
    uniform = {
        "cells": uniform_sim.mesh.ncells,
        "measured_steps": uniform_steps,
        "wall_seconds_per_step": per_step,
        "cell_updates_extrapolated": int(uniform_sim.mesh.ncells * finest_steps),
        "wall_seconds_extrapolated": per_step * finest_steps,
    }
    return {
        "config": config_path,
        "end_time": end,
        "threads": numba.config.NUMBA_NUM_THREADS,
        "adaptive": adaptive,
        "uniform": uniform,
        "cell_update_ratio": uniform["cell_updates_extrapolated"] / adaptive["cell_updates"],
        "wall_time_ratio": uniform["wall_seconds_extrapolated"] / wall,
    }


def mesh_arguments(description: str, uniform_steps: int, time_stepping: str) -> argparse.ArgumentParser:
    """The command line of this benchmark and of amr_profile.py (their defaults differ)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--config", default="configs/reference/case8c.yaml")
    parser.add_argument("--end-time", type=float, default=None, help="s (default: the config's hydro end time)")
    parser.add_argument("--uniform-steps", type=int, default=uniform_steps, help="0: no uniform run")
    parser.add_argument("--cells-per-projectile-radius", type=int, default=None,
                        help="override the config's hydro.cells_per_projectile_radius")
    parser.add_argument("--time-stepping", choices=["global", "per_level"], default=time_stepping,
                        help="the adaptive run's hydro.time_stepping (the uniform run has one level either way)")
    parser.add_argument("--interfaces", choices=["all", "active", "off"], default=None,
                        help="override the adaptive run's hydro.refinement.interfaces")
    parser.add_argument("--override", action="append", default=[], metavar="KEY=VALUE",
                        help="set a config key of the adaptive run (dotted, value read as YAML), e.g. "
                             "hydro.refinement.pressure_floor=0.01; repeatable")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    return parser


def overrides_of(args: argparse.Namespace) -> dict:
    """The ``--override`` options as {dotted key: value}."""
    return {key: yaml.safe_load(value) for key, value in (o.split("=", 1) for o in args.override)}


def main() -> None:
    args = mesh_arguments(__doc__.splitlines()[0], 50, "global").parse_args()
    result = run(args.config, args.end_time, args.uniform_steps, args.time_stepping, args.cells_per_projectile_radius,
                 args.interfaces, overrides_of(args))
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        a, u = result["adaptive"], result.get("uniform")
        print(f"adaptive ({a['levels']} levels, {a['time_stepping']}): {a['steps']} steps ({a['finest_steps']} finest), {a['cell_updates']:.3e} cell-updates, "
              f"{a['wall_seconds']:.0f} s ({a['regrid_share']:.1%} regridding)")
        print(f"energy error {a['energy_error']:+.3%} (what the floors' amounts leave unaccounted: "
              f"{a['budget']['energy_unaccounted']:.1e})")
        if u is not None:
            print(f"uniform (extrapolated): {u['cell_updates_extrapolated']:.3e} cell-updates, "
                  f"{u['wall_seconds_extrapolated']:.0f} s")
            print(f"ratios: cell-updates {result['cell_update_ratio']:.1f}x, wall {result['wall_time_ratio']:.1f}x")


if __name__ == "__main__":
    main()
