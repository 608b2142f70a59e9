"""Where an adaptive cell-update's time goes: per-phase CPU time of the reference impact.

Runs the hydro stage of a config (default configs/reference/case8c.yaml) with the adaptive
mesh to ``--end-time`` (default: the config's hydro end time), then ``--uniform-steps`` steps
of the uniform mesh at the finest cell (as :mod:`benchmarks.amr_reference`), with a CPU-time
timer (``time.process_time``) around each phase's calls, and reports per phase the seconds and
the ns per cell-update of both runs:

- sweeps: the directional sweeps (:func:`~impactpipe.hydro.scheme.directional.sweep`);
- same-level ghosts: the state's ghosts copied from same-level neighbours and domain faces
  (on the uniform mesh every ghost fill);
- coarse/fine ghosts: the restriction and the prolongation of the state's ghosts at level
  faces, and the time blend (the gather, blend and put back of the coarse cells the
  prolongation reads at the substep's time);
- registers and reflux: the flux registers and the coarse cells' corrections;
- strength: the strength step's kernels (velocities, stress update, kicks), its work-array
  ghosts counted apart as strength ghosts;
- tracers, regrid, time step (signal speeds), last-good copy;
- Python: what is left of the run's CPU time (the interpreter between the kernels, numba's
  dispatch, the numpy glue);

and the CPU-time ratio of the uniform run extrapolated to the adaptive run's finest steps (as
:mod:`benchmarks.amr_reference` extrapolates its wall time) to the adaptive run; beside it, the
ratio of cell-updates and two bounds: the CPU-time ratio the adaptive run would reach if the
phases only a hierarchy has (:data:`HIERARCHY`: the coarse/fine ghosts, registers and reflux,
regrids) cost nothing, and if everything but its sweeps and strength step did.  The
extrapolation takes the uniform mesh's cost per step from its first steps after contact,
when most of its cells are void and cheap; ``--uniform-to-end`` runs the uniform mesh to the
same end time instead and gives the ratio of the two whole runs' CPU times.

Times are exclusive: a phase nested in another (a ghost fill inside the strength step) counts
for itself only.  The timers cost about a microsecond per call.

    NUMBA_NUM_THREADS=1 python benchmarks/amr_profile.py [--cells-per-projectile-radius 10]
        [--end-time T] [--uniform-steps N | --uniform-to-end] [--time-stepping per_level|global]
        [--interfaces all|active|off] [--override KEY=VALUE ...] [--json]
"""

from __future__ import annotations

import json
import time

import numpy as np

import impactpipe.hydro.amr.subcycle as subcycle
import impactpipe.hydro.parallel.distributed as distributed
import impactpipe.hydro.solver as solver
import impactpipe.hydro.strength.model as strength_model
import impactpipe.hydro.tracers.motion as motion
from amr_reference import _simulation, mesh_arguments, overrides_of

#: (module or class, attribute, phase) of every timed call.
TIMED = (
    (subcycle, "sweep", "sweeps"),
    (solver, "sweep", "sweeps"),
    (subcycle, "fill_state_ghost_slabs_of", "same-level ghosts"),
    (distributed.WholeMesh, "start_ghosts", "same-level ghosts"),
    (solver.Simulation, "restore_last_good", "retakes"),
    (subcycle, "restrict_ghosts", "coarse/fine restriction"),
    (subcycle, "restrict_state_ghosts", "coarse/fine restriction"),
    (subcycle, "prolong_state_ghosts", "coarse/fine prolongation"),
    (subcycle, "gather_cells", "coarse/fine time blend"),
    (subcycle, "blend_cells", "coarse/fine time blend"),
    (subcycle, "put_cells", "coarse/fine time blend"),
    (subcycle, "register_fluxes", "registers and reflux"),
    (subcycle, "reflux_register", "registers and reflux"),
    (solver, "reflux", "registers and reflux"),
    (subcycle.LevelStepper, "_strength_step", "strength"),
    (solver.Simulation, "_momentum_sources", "strength"),
    (solver.Simulation, "_check_momentum", "strength"),
    (strength_model.MaterialStrength, "_start_work_ghosts", "strength ghosts"),
    (strength_model.MaterialStrength, "_finish_work_ghosts", "strength ghosts"),
    (strength_model.MaterialStrength, "_flip_wall_ghosts", "strength ghosts"),
    (motion.Tracers, "before_step", "tracers"),
    (motion.Tracers, "after_step", "tracers"),
    (motion.Tracers, "level_substep", "tracers"),
    (solver.Simulation, "regrid", "regrid"),
    (solver.Simulation, "stable_dt", "time step"),
    (solver, "level_time_step", "time step"),
    (solver.Simulation, "_save_good", "last-good copy"),
)

#: The phases a uniform mesh does not have.
HIERARCHY = ("coarse/fine restriction", "coarse/fine prolongation", "coarse/fine time blend", "registers and reflux",
             "regrid")

PHASES = ("sweeps", "same-level ghosts", "coarse/fine restriction", "coarse/fine prolongation",
          "coarse/fine time blend", "registers and reflux", "strength", "strength ghosts",
          "tracers", "regrid", "time step", "last-good copy", "retakes", "Python")


class PhaseTimers:
    """Exclusive CPU seconds per phase: each timed call's time less that of the timed calls inside it."""

    def __init__(self):
        self.seconds = dict.fromkeys(PHASES, 0.0)
        self.calls = dict.fromkeys(PHASES, 0)
        self._inner = [0.0]

    def wrap(self, function, phase: str):
        def timed(*args, **kwargs):
            self._inner.append(0.0)
            started = time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                spent = time.process_time() - started
                inner = self._inner.pop()
                self.seconds[phase] += spent - inner
                self.calls[phase] += 1
                self._inner[-1] += spent
        return timed

    def install(self) -> list:
        """Replace every :data:`TIMED` attribute by its timed wrapper (those the code has: the
        list names the kernels of earlier versions too); returns what to put back."""
        saved = []
        for owner, name, phase in TIMED:
            if name not in owner.__dict__:
                continue
            original = owner.__dict__[name]
            saved.append((owner, name, original))
            setattr(owner, name, self.wrap(original, phase))
        return saved

    def reset(self) -> None:
        self.seconds = dict.fromkeys(PHASES, 0.0)
        self.calls = dict.fromkeys(PHASES, 0)
        self._inner = [0.0]


def _timed_run(timers: PhaseTimers, advance) -> float:
    """CPU seconds of ``advance()``, what the timed phases leave of them counted as Python."""
    timers.reset()
    started = time.process_time()
    advance()
    total = time.process_time() - started
    timers.seconds["Python"] = total - sum(v for k, v in timers.seconds.items() if k != "Python")
    return total


def run(config_path: str, end_time: float | None, uniform_steps: int, time_stepping: str,
        cells: int | None, interfaces: str | None = None, uniform_to_end: bool = False,
        overrides: dict | None = None) -> dict:
    """The per-phase table of the module docstring as a dict; ``overrides`` (dotted config keys) apply to
    the adaptive run."""
    timers = PhaseTimers()
    saved = timers.install()
    try:
        sim, values = _simulation(config_path, None, time_stepping, cells, interfaces, overrides)
        end = float(end_time or values["end_time"])
        total = _timed_run(timers, lambda: sim.run(end))
        adaptive = {"cpu_seconds": total, "cell_updates": int(sim.cell_updates), "steps": sim.step_count,
                    "blocks_per_level_at_end": np.bincount(sim.mesh.block_level).tolist(),
                    "seconds": dict(timers.seconds), "calls": dict(timers.calls)}
        result = {"config": config_path, "end_time": end, "time_stepping": time_stepping, "adaptive": adaptive}
        if uniform_to_end:
            uniform_sim, _ = _simulation(config_path, 1, "global", cells)
            total = _timed_run(timers, lambda: uniform_sim.run(end))
            result["uniform"] = {"cpu_seconds": total, "cell_updates": int(uniform_sim.cell_updates),
                                 "steps": uniform_sim.step_count, "seconds": dict(timers.seconds),
                                 "calls": dict(timers.calls)}
            result["cpu_time_ratio"] = total / adaptive["cpu_seconds"]
            result["cell_update_ratio"] = uniform_sim.cell_updates / adaptive["cell_updates"]
        elif uniform_steps:
            uniform_sim, _ = _simulation(config_path, 1, "global", cells)
            uniform_sim.step()

            def steps():
                for _ in range(uniform_steps):
                    uniform_sim.step()
            total = _timed_run(timers, steps)
            result["uniform"] = {"cpu_seconds": total, "cell_updates": uniform_steps * uniform_sim.mesh.ncells,
                                 "steps": uniform_steps, "seconds": dict(timers.seconds),
                                 "calls": dict(timers.calls)}
            finest_steps = sim.step_count * (2 ** (int(values["levels"]) - 1) if time_stepping == "per_level" else 1)
            result["cpu_time_ratio"] = total / uniform_steps * finest_steps / adaptive["cpu_seconds"]
            result["cell_update_ratio"] = finest_steps * uniform_sim.mesh.ncells / adaptive["cell_updates"]
        if "cpu_time_ratio" in result:
            hierarchy = sum(adaptive["seconds"][phase] for phase in HIERARCHY)
            uniform_seconds = result["cpu_time_ratio"] * adaptive["cpu_seconds"]
            result["cpu_time_ratio_without_hierarchy"] = uniform_seconds / (adaptive["cpu_seconds"] - hierarchy)
            result["cpu_time_ratio_sweeps_and_strength"] = uniform_seconds / (adaptive["seconds"]["sweeps"]
                                                                              + adaptive["seconds"]["strength"])
    finally:
        for owner, name, original in saved:
            setattr(owner, name, original)
    return result


def main() -> None:
    parser = mesh_arguments(__doc__.splitlines()[0], 20, "per_level")
    parser.add_argument("--uniform-to-end", action="store_true",
                        help="run the uniform mesh to the end time (no extrapolation; overrides --uniform-steps)")
    args = parser.parse_args()
    result = run(args.config, args.end_time, args.uniform_steps, args.time_stepping, args.cells_per_projectile_radius,
                 args.interfaces, args.uniform_to_end, overrides_of(args))
    if args.json:
        print(json.dumps(result, indent=2))
        return
    runs = [name for name in ("adaptive", "uniform") if name in result]
    print(f"{'phase':24s}" + "".join(f"{name + ' s':>14s}{'ns/update':>11s}" for name in runs))
    for phase in PHASES + ("total",):
        row = f"{phase:24s}"
        for name in runs:
            r = result[name]
            seconds = r["cpu_seconds"] if phase == "total" else r["seconds"][phase]
            row += f"{seconds:14.2f}{1e9 * seconds / r['cell_updates']:11.0f}"
        print(row)
    for name in runs:
        r = result[name]
        print(f"{name}: {r['steps']} steps, {r['cell_updates']:.3e} cell-updates, {r['cpu_seconds']:.1f} s CPU")
    if "cpu_time_ratio" in result:
        how = "run to the end" if args.uniform_to_end else "extrapolated to the adaptive run's finest steps"
        print(f"uniform {how} / adaptive, CPU time: {result['cpu_time_ratio']:.2f}x; cell-updates: "
              f"{result['cell_update_ratio']:.2f}x")
        print(f"bounds, CPU time: without the hierarchy's own phases "
              f"{result['cpu_time_ratio_without_hierarchy']:.2f}x, the sweeps and strength step alone "
              f"{result['cpu_time_ratio_sweeps_and_strength']:.2f}x")


if __name__ == "__main__":
    main()
