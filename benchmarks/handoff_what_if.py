"""What the N-body stage answers in the hand-off: rerun finished runs from altered hand-off particles.

Copies each finished run directory RUN (its config, stage records, hydro and hand-off files)
into ``--out``/NAME, alters the copied hand-off particles (``handoff.h5``) in one way, reruns
the N-body and analysis stages (as ``impactpipe run ... --from nbody``) and prints M_lr/M_T of
the original and the altered run:

- ``--drift T``: every particle moves ballistically for T seconds, x -> x + v T (no gravity,
  no collisions): the state a hand-off T seconds later would have if the hydro stage between
  the two times were free flight;
- ``--radius-scale F``: every radius times F (a denser packing of the same masses);
- ``--no-overlap``: the radii of the spheres that overlap at hand-off shrink until every pair
  at most touches (each particle takes the smallest factor d / (r_i + r_j) of its pairs,
  repeated until none overlaps); the others keep theirs.

Masses and velocities are never changed.  For example, the 14-s hand-offs of a case 9a
hand-off-time ladder drifted to 20 s:

    python benchmarks/handoff_what_if.py --drift 6 --out runs/drift6 runs/case9a_20cells-convergence/runs/time=14_seed=*
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
from pathlib import Path

import h5py
import numpy as np
from scipy.spatial import cKDTree

from impactpipe.pipeline import load_config, run as run_pipeline

#: Files a rerun from the N-body stage needs besides the hydro file (hard-linked where the file
#: system allows, else copied).
COPIED = ("config.resolved.yaml", "stages.json", "handoff.h5")
#: Most rounds of :func:`remove_overlaps`.
OVERLAP_ROUNDS = 100


def remove_overlaps(position: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Radii (m) with every overlapping pair shrunk to touching: r_i -> r_i min_j d_ij / (r_i + r_j)
    over the pairs of i with d_ij < r_i + r_j, repeated until no pair overlaps."""
    r = radius.copy()
    pairs = cKDTree(position).query_pairs(2.0 * r.max(), output_type="ndarray")
    d = np.linalg.norm(position[pairs[:, 0]] - position[pairs[:, 1]], axis=1)
    for _ in range(OVERLAP_ROUNDS):
        ratio = d / (r[pairs[:, 0]] + r[pairs[:, 1]])
        over = ratio < 1.0
        if not over.any():
            return r
        scale = np.ones_like(r)
        np.minimum.at(scale, pairs[over, 0], ratio[over])
        np.minimum.at(scale, pairs[over, 1], ratio[over])
        r *= scale
    raise RuntimeError(f"overlaps left after {OVERLAP_ROUNDS} rounds")


def alter(path: Path, drift: float | None, radius_scale: float | None, no_overlap: bool) -> None:
    """Apply the chosen change to the particles of the hand-off file ``path`` in place."""
    with h5py.File(path, "r+") as f:
        p = f["particles"]
        if drift is not None:
            p["position"][...] = p["position"][:] + drift * p["velocity"][:]
        if radius_scale is not None:
            p["radius"][...] = radius_scale * p["radius"][:]
        if no_overlap:
            p["radius"][...] = remove_overlaps(p["position"][:], p["radius"][:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path, help="finished run directories")
    parser.add_argument("--out", type=Path, required=True, help="directory of the altered copies")
    change = parser.add_mutually_exclusive_group(required=True)
    change.add_argument("--drift", type=float, help="free flight of every particle for this many seconds")
    change.add_argument("--radius-scale", type=float, help="multiply every radius by this factor")
    change.add_argument("--no-overlap", action="store_true", help="shrink overlapping spheres to touching")
    args = parser.parse_args()
    if args.radius_scale is not None and not args.radius_scale > 0.0:
        parser.error(f"--radius-scale must be > 0 (got {args.radius_scale})")
    missing = [str(run) for run in args.runs if not all((run / name).is_file() for name in (*COPIED, "hydro.h5"))]
    if missing:
        parser.error("not finished runs (no hydro.h5, handoff.h5, stages.json or config.resolved.yaml): "
                     + ", ".join(missing))
    for run in args.runs:
        copy = args.out / run.name
        if copy.exists():
            shutil.rmtree(copy)
        copy.mkdir(parents=True)
        for name in COPIED:
            shutil.copy2(run / name, copy / name)
        try:
            os.link(run / "hydro.h5", copy / "hydro.h5")
        except OSError:
            shutil.copy2(run / "hydro.h5", copy / "hydro.h5")
        alter(copy / "handoff.h5", args.drift, args.radius_scale, args.no_overlap)
        run_pipeline(load_config(copy / "config.resolved.yaml"), copy, from_stage="nbody", show_progress=False)
        before = json.loads((run / "summary.json").read_text())["M_lr_over_M_T"]
        after = json.loads((copy / "summary.json").read_text())["M_lr_over_M_T"]
        print(f"{run.name}  M_lr/M_T {before:.3f} -> {after:.3f}", flush=True)


if __name__ == "__main__":
    main()
