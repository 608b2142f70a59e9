"""Tracers with the step per level against the global step on the hydro-only impact.

The impact of benchmarks/amr_time_stepping.py (basalt Tillotson without strength, R_T = 1 km,
R_P = 100 m at 3 km/s, 2d-cylindrical, ``--cells`` per projectile radius, 4 levels) carries
the scene's 900 tracers (30 rays from the impact point and a projectile grid,
:func:`impactpipe.hydro.problems.impact.tracer_positions`) to ``--end`` (s) three ways: the
global step, per_level (the tracers move once per root step and record their peaks after every
substep of the level holding them, hydro/amr/subcycle.py) and per_level with the peaks recorded
at the root steps' ends only (``Tracers.level_substep`` switched off, to show what the substep
records bring).  After a short warm-up of every mode (kernels compiled) it prints per mode the
wall seconds, the steps, the tracers' hook seconds (before_step, after_step, level_substep) per
root step and per simulated second, and against the global run, over the tracers whose global
peak pressure exceeds 0.1 GPa: the median, 90th percentile and largest relative difference of
the peak pressure, the fraction within 10 %, the median signed difference, the mean peak
pressure of the target tracers 1, 2 and 4 projectile radii from the impact point (within
+-20 %), and the largest and median distance between the positions:

    NUMBA_NUM_THREADS=1 python benchmarks/per_level_tracers.py --end 0.3
"""

import argparse
import time

import numpy as np

from impactpipe.hydro.problems import PROBLEMS
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.problems.impact import tracer_positions
from impactpipe.hydro.tracers.motion import Tracers

R_T, R_P = 1.0e3, 1.0e2
HOOKS = ("before_step", "after_step", "level_substep")


def impact(mode: str, cells: float, end: float, substeps: bool = True):
    """The impact (module docstring) with its tracers, stepped by ``mode``; ``substeps`` False
    leaves out the per-level substep peak records.  Returns (sim, hook seconds dict)."""
    sim = PROBLEMS["impact"].setup({"cells_per_projectile_radius": cells, "levels": 4, "end_time": end},
                                   {"basalt": preset_material("basalt")}, geometry="2d-cylindrical")
    positions, materials = tracer_positions("2d-cylindrical", R_T, R_P, 900)
    tracers = Tracers(positions[:, :2], materials)
    seconds = dict.fromkeys(HOOKS, 0.0)

    def timed(name, hook):
        def call(*args):
            started = time.perf_counter()
            hook(*args)
            seconds[name] += time.perf_counter() - started
        return call

    for name in HOOKS:
        hook = getattr(tracers, name)
        setattr(tracers, name, timed(name, hook if substeps or name != "level_substep" else lambda *a: None))
    sim.tracers = tracers
    sim.time_stepping = mode
    return sim, seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=float, default=8.0, help="cells per projectile radius")
    parser.add_argument("--end", type=float, default=0.3)
    parser.add_argument("--warm-up", type=float, default=0.01)
    args = parser.parse_args()
    modes = (("global", True), ("per_level", True), ("per_level", False))
    for mode, substeps in modes:
        impact(mode, args.cells, args.warm_up, substeps)[0].run(args.warm_up)
    runs = {}
    for mode, substeps in modes:
        sim, seconds = impact(mode, args.cells, args.end, substeps)
        started = time.perf_counter()
        sim.run(args.end)
        wall = time.perf_counter() - started
        runs[mode, substeps] = sim
        hooks = sum(seconds.values())
        print(f"{mode:9s} substep peaks {str(substeps):5s} wall {wall:6.2f} s  steps {sim.step_count:4d} "
              f"(retaken {sim.level_step_retakes})  tracer hooks {hooks:.3f} s = {1e3 * hooks / sim.step_count:.2f} ms "
              f"per step, {hooks / sim.time:.3f} s per simulated s  ("
              + ", ".join(f"{name} {value:.3f} s" for name, value in seconds.items()) + ")", flush=True)
    glob = runs["global", True].tracers
    distance = np.hypot(glob.initial_position[:, 0], glob.initial_position[:, 1] - R_T)
    for key in modes[1:]:
        tr = runs[key].tracers
        ok = np.isfinite(tr.peak_pressure) & (glob.peak_pressure > 1.0e8)
        ratio = tr.peak_pressure[ok] / glob.peak_pressure[ok] - 1.0
        rel = np.abs(ratio)
        gap = np.hypot(*(tr.position[:, :2] - glob.position[:, :2]).T)
        shells = []
        for radii in (1, 2, 4):
            ring = (glob.material == 0) & (np.abs(distance / (radii * R_P) - 1.0) <= 0.2)
            shells.append(f"{radii} R_P ({ring.sum()}): {np.mean(tr.peak_pressure[ring]) / 1e9:.3f} against "
                          f"{np.mean(glob.peak_pressure[ring]) / 1e9:.3f} GPa")
        print(f"per_level substep peaks {str(key[1]):5s} against global: {ok.sum()} tracers, |dp|/p median "
              f"{np.median(rel):.4f} p90 {np.quantile(rel, 0.9):.4f} max {rel.max():.3f}, within 10 % "
              f"{np.mean(rel < 0.1):.4f}, median signed {np.median(ratio):+.4f}; " + "; ".join(shells)
              + f"; position gap max {gap.max():.2f} m median {np.median(gap):.3f} m", flush=True)


if __name__ == "__main__":
    main()
