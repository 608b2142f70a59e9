"""The largest remnant of finished impact runs handed off with spheres of one size, many seeds.

The hand-off makes one sphere per leaf block (docs/handoff.md), so runs on different meshes
start their N-body stage from spheres of different sizes, and the remnant depends on them as
well as on the hydro state.  This script hands off the hydro stage of each point of the given
finished sweeps again with ``handoff.particle_resolution`` set so that every sphere comes from
a block of edge at least ``--sphere-edge`` (m; leaf blocks narrower than that are merged into
their ancestors), for ``--seeds`` hand-off seeds, and prints M_lr/M_T per point: its mean, standard deviation and
standard error over the seeds, and the difference from the first run's mean in units of the
combined standard error.  The hydro stage is adopted, not run again (``impactpipe sweep
--reuse-hydro``); each point's new sweep goes to ``--out``/<sweep>_<n>.

    impactpipe sweep configs/sweeps/case8c_per_level_20cells.yaml --out OUT/per_level
    impactpipe sweep configs/sweeps/case8c_per_level_reach_20cells.yaml --out OUT/reach
    python benchmarks/amr_remnant_spheres.py OUT/per_level OUT/reach --sphere-edge 1328 --seeds 20 \\
        --out OUT/spheres [--json]

A point's mesh must have a level whose blocks are that wide (``particle_resolution`` is the run's
cells per projectile radius over a power of two); a uniform mesh has no coarser level.
"""

import argparse
import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import yaml

#: Where the sweep files of this study live: their ``base`` is relative to it.
SWEEPS = Path(__file__).resolve().parent.parent / "configs" / "sweeps"


def particle_resolution(run: Path, config: dict, edge: float) -> float:
    """``handoff.particle_resolution`` (cells per projectile radius) whose blocks are ``edge`` (m)
    wide, with the run's cells per block edge read from its hydro output."""
    with h5py.File(run / "hydro.h5", "r") as fh:
        block_cells = fh["snapshots"][sorted(fh["snapshots"])[0]]["partial_density"].shape[2]
    return block_cells * config["scene"]["projectile"]["radius"] / edge


def remnants(sweep_dir: Path, point: dict, edge: float, seeds: int, out: Path) -> dict:
    """M_lr/M_T of the hydro stage of the finished ``point`` (a points.json entry) of
    ``sweep_dir`` handed off with blocks ``edge`` (m) wide, one per seed: a sweep of the same
    base and overrides (the sweep file's ``base`` read relative to configs/sweeps/, where the
    sweeps of this study live), the point's own parameters and the particle resolution,
    adopting the point's hydro stage."""
    run = Path(point["run_dir"])
    run = run if run.is_absolute() else sweep_dir / "runs" / run.name
    original = yaml.safe_load((sweep_dir / "sweep.yaml").read_text())
    config = yaml.safe_load((run / "config.resolved.yaml").read_text())
    overrides = dict(original.get("overrides") or {})
    overrides.update(point.get("replicate_of") or {})
    overrides["handoff.particle_resolution"] = particle_resolution(run, config, edge)
    out.mkdir(parents=True, exist_ok=True)
    sweep = {"name": f"spheres_{sweep_dir.name}", "base": str((SWEEPS / original["base"]).resolve()),
             "output": str(out), "overrides": overrides,
             "replicates": {"handoff.seed": list(range(1, seeds + 1))},
             "execution": {"backend": "local", "workers": 1, "threads_per_run": 1}}
    sweep_file = out / "sweep_spheres.yaml"
    sweep_file.write_text(yaml.safe_dump(sweep, sort_keys=False))
    subprocess.run([sys.executable, "-m", "impactpipe.pipeline.cli", "sweep", str(sweep_file), "--out", str(out),
                    "--reuse-hydro", str(run), "--quiet"], check=True, stdout=subprocess.DEVNULL)
    points = json.loads((out / "points.json").read_text())
    done = [entry["summary"] for entry in points.values() if entry["status"] == "complete"]
    values = np.array([summary["M_lr_over_M_T"] for summary in done])
    return {"sweep": sweep_dir.name, "point": point.get("replicate_of") or {}, "M_lr_over_M_T": values.tolist(),
            "mean": float(values.mean()), "std": float(values.std(ddof=1)),
            "stderr": float(values.std(ddof=1) / np.sqrt(values.size)), "spheres": done[0]["N_init"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sweeps", nargs="+", type=Path, help="finished sweep directories (their sweep files in "
                                                                  "configs/sweeps/)")
    parser.add_argument("--sphere-edge", type=float, required=True, help="m: the narrowest block that becomes a sphere")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--out", type=Path, required=True, help="directory for the hand-off sweeps")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    results = []
    for sweep_dir in args.sweeps:
        groups: dict[str, dict] = {}
        for entry in json.loads((sweep_dir / "points.json").read_text()).values():
            if entry["status"] == "complete":
                groups.setdefault(json.dumps(entry.get("replicate_of") or {}, sort_keys=True), entry)
        for key, point in sorted(groups.items()):
            name = f"{sweep_dir.name}_{len(results)}"
            results.append(remnants(sweep_dir, point, args.sphere_edge, args.seeds, args.out / name))
    reference = results[0]
    for result in results:
        combined = np.hypot(result["stderr"], reference["stderr"])
        result["sigmas_from_reference"] = float((result["mean"] - reference["mean"]) / combined) if combined else 0.0
    if args.json:
        print(json.dumps(results, indent=2))
        return
    for result in results:
        difference = result["mean"] - reference["mean"]
        print(f"{result['sweep']} {json.dumps(result['point'])}: M_lr/M_T {result['mean']:.3f} "
              f"+- {result['stderr']:.3f} (std {result['std']:.3f}, {len(result['M_lr_over_M_T'])} seeds, "
              f"{result['spheres']} spheres; {difference:+.3f}, {result['sigmas_from_reference']:+.2f} sigma "
              f"from the first)")


if __name__ == "__main__":
    main()
