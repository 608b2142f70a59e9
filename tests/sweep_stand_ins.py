"""Stand-in stages for sweep tests: instant, with a synthetic M_lr/M_T(Q) law and a call log.

Each stage writes its output file and then appends "<run name> <stage>" to
``<runs dir>/calls.log``, so a test can count how often each stage of each point finished.
"""

import math
import os
import signal
import time

from impactpipe.storage import atomic_path

#: Q*_D of the synthetic law (J/kg): M_lr/M_T = 1 - 0.5 Q / QSTAR.
QSTAR = 1790.0
#: Scale of the seed-dependent offset of ``noisy_analysis``.
REPLICATE_NOISE = 0.03
#: A hydro stand-in fails for this impact speed (m/s), to test failure isolation.
FAILING_VELOCITY = 666.0
#: ``fatal_hydro`` kills its own process (SIGKILL) at this impact speed (m/s), as a crash would.
FATAL_VELOCITY = 999.0


def _finish(ctx, stage):
    with atomic_path(ctx.path(stage)) as tmp:
        tmp.write_text(stage)
    with open(ctx.run_dir.parent / "calls.log", "a") as log:
        log.write(f"{ctx.run_dir.name} {stage}\n")


def hydro(ctx):
    if ctx.config.scene.impact.velocity == FAILING_VELOCITY:
        raise RuntimeError(f"synthetic failure at {FAILING_VELOCITY} m/s")
    _finish(ctx, "hydro")
    return {}


def handoff(ctx):
    _finish(ctx, "handoff")
    return {} if ctx.config.handoff.time is None else {"handoff_time": ctx.config.handoff.time}


def nbody(ctx):
    _finish(ctx, "nbody")
    return {}


def analysis(ctx):
    scene = ctx.config.scene
    q = 0.5 * (scene.projectile.radius / scene.target.radius) ** 3 * scene.impact.velocity ** 2
    _finish(ctx, "analysis")
    return {"Q": q, "M_lr_over_M_T": max(0.0, 1.0 - 0.5 * q / QSTAR), "N_lr": 5000}


def noisy_analysis(ctx):
    """``analysis`` with a seed-dependent offset of M_lr/M_T: REPLICATE_NOISE * ((4 seed) mod 5 - 2),
    which takes the values 2, 1, 0, -1, -2 times REPLICATE_NOISE for handoff.seed 1..5
    (mean 0, sample standard deviation REPLICATE_NOISE sqrt(2.5))."""
    result = analysis(ctx)
    result["M_lr_over_M_T"] += REPLICATE_NOISE * ((4 * ctx.config.handoff.seed) % 5 - 2)
    return result


#: Q*_D of ``resolved_analysis`` at n cells per projectile radius: QSTAR (1 + RESOLUTION_C / n^2).
RESOLUTION_C = 4.0


def resolved_analysis(ctx):
    """``analysis`` whose Q*_D converges at second order in the cell size:
    QSTAR (1 + RESOLUTION_C / n^2) at n = hydro.cells_per_projectile_radius."""
    result = analysis(ctx)
    qstar = QSTAR * (1.0 + RESOLUTION_C / ctx.config.hydro.cells_per_projectile_radius ** 2)
    result["M_lr_over_M_T"] = max(0.0, 1.0 - 0.5 * result["Q"] / qstar)
    return result


#: Q*_D of ``timed_analysis`` handed off at t seconds: QSTAR (1 + HANDOFF_TIME_C t).
HANDOFF_TIME_C = 0.01


def timed_analysis(ctx):
    """``analysis`` whose Q*_D grows linearly with the hand-off time t = handoff.time (s):
    QSTAR (1 + HANDOFF_TIME_C t)."""
    result = analysis(ctx)
    qstar = QSTAR * (1.0 + HANDOFF_TIME_C * ctx.config.handoff.time)
    result["M_lr_over_M_T"] = max(0.0, 1.0 - 0.5 * result["Q"] / qstar)
    return result


def slow_analysis(ctx):
    time.sleep(0.3)
    return analysis(ctx)


def hanging_hydro(ctx):
    """A hydro stage that writes its process id to ``<runs dir>/<run name>.pid`` and then
    takes a minute, so a test can stop a sweep while it runs."""
    (ctx.run_dir.parent / f"{ctx.run_dir.name}.pid").write_text(str(os.getpid()))
    for _ in range(1200):
        time.sleep(0.05)
    return hydro(ctx)


#: Seconds ``paced_hydro`` waits after every step.
STEP_PACE = 0.5


def paced_hydro(ctx):
    """The real hydro stage, waiting STEP_PACE seconds after every step, when it also writes its
    process id to ``<runs dir>/<run name>.pid``, so a test can stop a sweep while the stage
    steps (on several MPI ranks: the id of rank 0, which decides when the run stops)."""
    from impactpipe.pipeline.adapters.hydro import run_hydro_stage

    pid_file = ctx.run_dir.parent / f"{ctx.run_dir.name}.pid"
    asked = ctx.stop_requested

    def paced():
        pid_file.write_text(str(os.getpid()))
        time.sleep(STEP_PACE)
        return asked()

    ctx.stop_requested = paced
    return run_hydro_stage(ctx)


def held_hydro(ctx):
    """A hydro stage that writes its process id to ``<runs dir>/<run name>.pid`` and then waits
    until ``<runs dir>/release`` exists (a minute at most), so a test can kill the pool workers
    while they run it."""
    (ctx.run_dir.parent / f"{ctx.run_dir.name}.pid").write_text(str(os.getpid()))
    for _ in range(1200):
        if (ctx.run_dir.parent / "release").exists():
            break
        time.sleep(0.05)
    return hydro(ctx)


def fatal_hydro(ctx):
    """``hydro``, except that at FATAL_VELOCITY it kills its own process, as a segfault would."""
    if ctx.config.scene.impact.velocity == FATAL_VELOCITY:
        os.kill(os.getpid(), signal.SIGKILL)
    return hydro(ctx)


STAGES = {s: f"sweep_stand_ins:{s}" for s in ("hydro", "handoff", "nbody", "analysis")}
#: Stages whose M_lr/M_T depends on handoff.seed (``noisy_analysis``).
NOISY_STAGES = {**STAGES, "analysis": "sweep_stand_ins:noisy_analysis"}
#: Stages whose Q*_D depends on the resolution (``resolved_analysis``).
RESOLVED_STAGES = {**STAGES, "analysis": "sweep_stand_ins:resolved_analysis"}
#: Stages whose Q*_D depends on the hand-off time (``timed_analysis``).
TIMED_STAGES = {**STAGES, "analysis": "sweep_stand_ins:timed_analysis"}
#: Stages whose analysis takes 0.3 s, so a sweep can be killed while points are still running.
SLOW_STAGES = {**STAGES, "analysis": "sweep_stand_ins:slow_analysis"}
#: Stages whose hydro takes a minute (``hanging_hydro``).
HANGING_STAGES = {**STAGES, "hydro": "sweep_stand_ins:hanging_hydro"}
#: The real stages, with a hydro stage paced to STEP_PACE seconds a step (``paced_hydro``).
PACED_STAGES = {"hydro": "sweep_stand_ins:paced_hydro"}
#: Stages whose hydro waits for a release file (``held_hydro``).
HELD_STAGES = {**STAGES, "hydro": "sweep_stand_ins:held_hydro"}
#: Stages whose hydro kills its process at FATAL_VELOCITY (``fatal_hydro``).
FATAL_STAGES = {**STAGES, "hydro": "sweep_stand_ins:fatal_hydro"}


def critical_velocity(target_radius, projectile_radius):
    """Speed at which the synthetic law gives M_lr/M_T = 0.5 (m/s)."""
    return math.sqrt(2.0 * QSTAR / (projectile_radius / target_radius) ** 3)
