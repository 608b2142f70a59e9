"""How much M_lr/M_T moves when the hand-off's velocities are scaled: the N-body stage's
sensitivity to the kinetic energy the hydro stage hands over.

For a finished run (its ``hydro.h5`` and ``config.resolved.yaml``), each hand-off seed and
each scale s of ``--scales``: the hand-off of that seed (``handoff.seed``; the config's
``handoff.particle_resolution`` applies) with every particle velocity replaced by

    v_i' = v_cm + s (v_i - v_cm)        (v_cm the particles' centre-of-mass velocity, m/s),

which multiplies the kinetic energy in the centre-of-mass frame by s^2 and keeps the
momentum, then the N-body and analysis stages.  Prints per scale the mean M_lr/M_T over the
seeds with its standard error, and the slope d(M_lr/M_T) / d ln K between the smallest and
largest scale (K = s^2 K_0).  With a Richardson estimate of the hydro stage's kinetic energy
at the hand-off (``benchmarks/target_speed_history.py`` on a resolution ladder), the slope
turns the remaining kinetic-energy error of a rung into an M_lr/M_T error
(docs/accuracy.md, "Why M_lr/M_T does not converge while the target's motion does").

    NUMBA_NUM_THREADS=1 python benchmarks/handoff_velocity_sensitivity.py RUN_DIR \
        --scales 0.96,1,1.04 --seeds 5 --out DIR [--particle-resolution 20]

Every (seed, scale) run lives in ``DIR/seed=<n>_scale=<s>`` (the hydro run hard-linked) and
is skipped when its analysis already finished, so an interrupted call resumes.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import h5py
import numpy as np

from impactpipe.handoff.store import read_budget, read_particles, write_particles
from impactpipe.pipeline import stages
from impactpipe.pipeline.config import load_config


def scale_velocities(path: Path, scale: float) -> None:
    """Rewrite ``path`` (a handoff.h5) with v_i' = v_cm + scale (v_i - v_cm); the scale goes into its attributes."""
    particles = read_particles(path)
    budget = read_budget(path)
    with h5py.File(path, "r") as fh:
        attrs = dict(fh.attrs)
    m = particles.mass
    v_cm = (m[:, None] * particles.velocity).sum(axis=0) / m.sum()
    particles.velocity = v_cm + scale * (particles.velocity - v_cm)
    attrs["velocity_scale"] = float(scale)
    write_particles(path, particles, budget, attrs)


def run_one(source: Path, out: Path, overrides: dict, scale: float) -> float:
    """M_lr/M_T of one seed at one velocity scale (resumes a finished run)."""
    config = load_config(source / stages.RESOLVED_CONFIG_FILE, overrides=overrides)
    records = stages.read_records(out)
    if records.get("analysis", {}).get("status") == "complete":
        return float(stages.read_summary(out)["M_lr_over_M_T"])
    if records.get("handoff", {}).get("status") != "complete":
        stages.adopt_stages(out, source, config)
        stages.run(config, out, stages=["hydro", "handoff"], show_progress=False)
    handoff = out / stages.STAGE_FILES["handoff"]
    with h5py.File(handoff, "r") as fh:
        scaled = "velocity_scale" in fh.attrs
    if not scaled:
        scale_velocities(handoff, scale)
    return float(stages.run(config, out, from_stage="nbody", show_progress=False)["M_lr_over_M_T"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--scales", required=True, help="comma-separated velocity scales, e.g. 0.96,1,1.04")
    parser.add_argument("--seeds", type=int, default=5, help="hand-off seeds 1..N")
    parser.add_argument("--particle-resolution", type=float, default=None,
                        help="handoff.particle_resolution of the hand-offs (default: the run's)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    scales = [float(s) for s in args.scales.split(",")]
    rows = {}
    for scale in scales:
        values = []
        for seed in range(1, args.seeds + 1):
            overrides = {"handoff.seed": seed}
            if args.particle_resolution is not None:
                overrides["handoff.particle_resolution"] = args.particle_resolution
            values.append(run_one(args.run_dir, args.out / f"seed={seed}_scale={scale:g}", overrides, scale))
        mean = float(np.mean(values))
        sem = float(np.std(values, ddof=1) / math.sqrt(len(values))) if len(values) > 1 else float("nan")
        rows[scale] = (mean, sem, values)
        print(f"scale {scale:g} (K x {scale * scale:.4g}): M_lr/M_T {mean:.4f} +- {sem:.4f} "
              f"(seeds: {', '.join(f'{v:.3f}' for v in values)})", flush=True)
    lo, hi = min(scales), max(scales)
    slope = (rows[hi][0] - rows[lo][0]) / (2.0 * math.log(hi / lo))
    slope_err = math.hypot(rows[hi][1], rows[lo][1]) / (2.0 * math.log(hi / lo))
    print(f"d(M_lr/M_T) / d ln K = {slope:.3f} +- {slope_err:.3f} (scales {lo:g} to {hi:g})")
    (args.out / "sensitivity.json").write_text(json.dumps(
        {"run_dir": str(args.run_dir), "scales": {f"{s:g}": {"mean": m, "sem": e, "values": v}
                                                  for s, (m, e, v) in rows.items()},
         "dlnK_slope": slope, "dlnK_slope_err": slope_err}, indent=2))


if __name__ == "__main__":
    main()
