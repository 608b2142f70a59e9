"""The answers of one impact on different meshes: largest remnant per hand-off seed and peak pressures.

Reads finished sweeps of the same impact whose points differ in their mesh settings (e.g.
``hydro.max_levels: [1, 4]``, ``hydro.time_stepping: per_level``) and whose replicates are
hand-off seeds, and prints per point:

- M_lr/M_T of every seed, their mean, standard deviation and standard error;
- the hydro stage's wall time (s; the replicates share one hydro run);
- the mean peak pressure (GPa) of the target's tracers whose initial distance from the impact
  point (r = 0, z = R_T in r-z; the target centred at the origin) is within +-20 % of 1, 2 and
  4 projectile radii, with the number of tracers and the standard error of that mean.

The first point given is the reference the others are compared with: the difference of the
M_lr/M_T means in units of their combined standard error, and the relative difference of each
shell's mean peak pressure.  Commands (configs in configs/sweeps/):

    impactpipe sweep configs/sweeps/case8c_mesh_20cells.yaml --out OUT/mesh
    impactpipe sweep configs/sweeps/case8c_per_level_20cells.yaml --out OUT/per_level
    python benchmarks/amr_answers.py OUT/mesh OUT/per_level [--json]
"""

import argparse
import json
from pathlib import Path

import numpy as np
import yaml

from impactpipe.hydro.output.io import read_tracers

SHELLS = (1.0, 2.0, 4.0)
SHELL_HALF_WIDTH = 0.2


def _points(sweep_dir: Path) -> dict[str, list[dict]]:
    """Finished replicates of ``sweep_dir`` grouped by their point (the non-replicate parameters)."""
    points = json.loads((sweep_dir / "points.json").read_text())
    groups: dict[str, list[dict]] = {}
    for entry in points.values():
        if entry["status"] != "complete":
            continue
        key = json.dumps(entry.get("replicate_of") or {}, sort_keys=True)
        groups.setdefault(f"{sweep_dir.name} {key}", []).append(entry)
    return groups


def _run_path(sweep_dir: Path, entry: dict) -> Path:
    """The run directory of a points.json entry (stored relative to where the sweep ran)."""
    run = Path(entry["run_dir"])
    return run if run.is_absolute() else sweep_dir / "runs" / run.name


def shell_pressures(hydro_h5: Path, target_radius: float, projectile_radius: float) -> list[dict]:
    """Mean peak pressure (Pa), its standard error and the count of the target tracers in each shell."""
    tracers = read_tracers(hydro_h5)
    start = tracers.initial_position
    in_target = np.linalg.norm(start, axis=1) <= target_radius
    distance = np.hypot(start[:, 0], start[:, 1] - target_radius)
    shells = []
    for radii in SHELLS:
        ring = in_target & (np.abs(distance / (radii * projectile_radius) - 1.0) <= SHELL_HALF_WIDTH)
        peaks = tracers.peak_pressure[ring]
        shells.append({"radii": radii, "count": int(ring.sum()), "mean": float(np.mean(peaks)),
                       "stderr": float(np.std(peaks, ddof=1) / np.sqrt(peaks.size))})
    return shells


def point_answers(sweep_dir: Path, name: str, entries: list[dict]) -> dict:
    """M_lr/M_T per seed and the shells' peak pressures of one point."""
    entries = sorted(entries, key=lambda e: e["params"].get("handoff.seed", 0))
    remnant = np.array([e["summary"]["M_lr_over_M_T"] for e in entries])
    run = _run_path(sweep_dir, entries[0])
    config = yaml.safe_load((run / "config.resolved.yaml").read_text())
    scene = config["scene"]
    hydro_seconds = max(e["summary"]["wall_seconds"]["hydro"] for e in entries)
    return {
        "point": name,
        "seeds": [e["params"].get("handoff.seed") for e in entries],
        "M_lr_over_M_T": remnant.tolist(),
        "mean": float(remnant.mean()),
        "std": float(remnant.std(ddof=1)) if remnant.size > 1 else 0.0,
        "stderr": float(remnant.std(ddof=1) / np.sqrt(remnant.size)) if remnant.size > 1 else 0.0,
        "hydro_wall_seconds": hydro_seconds,
        "shells": shell_pressures(run / "hydro.h5", scene["target"]["radius"], scene["projectile"]["radius"]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sweeps", nargs="+", type=Path, help="finished sweep directories")
    parser.add_argument("--json", action="store_true", help="print the answers as JSON")
    args = parser.parse_args()
    answers = [point_answers(sweep, name, entries)
               for sweep in args.sweeps for name, entries in sorted(_points(sweep).items())]
    reference = answers[0]
    for answer in answers:
        combined = np.hypot(answer["stderr"], reference["stderr"])
        answer["sigmas_from_reference"] = (float((answer["mean"] - reference["mean"]) / combined)
                                           if combined > 0 else 0.0)
        for shell, ref in zip(answer["shells"], reference["shells"]):
            shell["relative_to_reference"] = shell["mean"] / ref["mean"] - 1.0
    if args.json:
        print(json.dumps(answers, indent=2))
        return
    for answer in answers:
        seeds = " ".join(f"{value:.3f}" for value in answer["M_lr_over_M_T"])
        print(f"{answer['point']}: M_lr/M_T {answer['mean']:.3f} +- {answer['stderr']:.3f} "
              f"(std {answer['std']:.3f}; seeds {seeds}; {answer['sigmas_from_reference']:+.2f} sigma from the "
              f"first point), hydro {answer['hydro_wall_seconds']:.0f} s")
        for shell in answer["shells"]:
            print(f"    {shell['radii']:.0f} R_P: {shell['count']} tracers, peak pressure {shell['mean'] / 1e9:.3f} "
                  f"+- {shell['stderr'] / 1e9:.3f} GPa ({100 * shell['relative_to_reference']:+.1f} %)")


if __name__ == "__main__":
    main()
