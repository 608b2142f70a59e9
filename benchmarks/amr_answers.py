"""The answers of one impact on different meshes: largest remnant per hand-off seed and peak pressures.

Reads finished sweeps of the same impact whose points differ in their mesh settings (e.g.
``hydro.max_levels: [1, 4]``, ``hydro.time_stepping: per_level``) and whose replicates are
hand-off seeds, and prints per point:

- M_lr/M_T of every seed, their mean, standard deviation and standard error;
- the hydro stage's wall time (s; the replicates share one hydro run);
- the mean peak pressure (GPa) of the target's tracers whose initial distance from the impact
  point (r = 0, z = R_T in r-z; the target centred at the origin) is within +-20 % of 1, 2 and
  4 projectile radii, with the number of tracers and the standard error of that mean;
- the share of the target's mass beyond 90 deg from the impact point (the far hemisphere) in
  blocks of the finest level, one level coarser, and coarser still, at every snapshot (r-z);
- the median speed (m/s) at the hydro end time of the target's tracers in six sectors of their
  initial angle from the impact point seen from the target's centre (0-30 deg: under the
  impact, 150-180 deg: the antipode), in the frame of the whole system's centre of mass
  (initial momentum / initial mass from the hydro budget, which no outflow changes).

The first point given is the reference the others are compared with: the difference of the
M_lr/M_T means in units of their combined standard error, the relative difference of each
shell's mean peak pressure, and per sector the median of the tracers' speed differences (the
same tracers, matched by id, when both runs placed the same ones).  Commands (configs in
configs/sweeps/):

    impactpipe sweep configs/sweeps/case8c_mesh_20cells.yaml --out OUT/mesh
    impactpipe sweep configs/sweeps/case8c_per_level_20cells.yaml --out OUT/per_level
    python benchmarks/amr_answers.py OUT/mesh OUT/per_level [--json]
"""

import argparse
import json
from pathlib import Path

import h5py
import numpy as np
import yaml

from impactpipe.hydro.output.io import read_tracers

SHELLS = (1.0, 2.0, 4.0)
SHELL_HALF_WIDTH = 0.2
#: Sectors of the tracers' initial angle from the impact point, seen from the target's centre (deg).
SECTOR_WIDTH = 30


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


def sector_speeds(hydro_h5: Path, target_radius: float) -> dict:
    """The target tracers' speeds at the hydro end time in the frame of the system's centre of
    mass, by sector of their initial angle from the impact point: {"edges" deg, "count",
    "median" m/s per sector, and per tracer "id", "sector" (-1 outside the target), "speed"}."""
    tracers = read_tracers(hydro_h5)
    with h5py.File(hydro_h5, "r") as fh:
        budget = fh["budget"].attrs
        frame = np.array([budget[f"momentum_{axis}_initial"] for axis in "xyz"]) / budget["mass_initial"]
    start = tracers.initial_position
    in_target = np.linalg.norm(start, axis=1) <= target_radius
    angle = np.degrees(np.arctan2(np.hypot(start[:, 0], start[:, 2]), start[:, 1]))
    sector = np.where(in_target, np.minimum(angle // SECTOR_WIDTH, 180 // SECTOR_WIDTH - 1), -1).astype(int)
    speed = np.linalg.norm(tracers.velocity - frame, axis=1)
    sectors = range(180 // SECTOR_WIDTH)
    return {"edges": [SECTOR_WIDTH * k for k in sectors],
            "count": [int((sector == k).sum()) for k in sectors],
            "median": [float(np.median(speed[sector == k])) if (sector == k).any() else float("nan") for k in sectors],
            "id": tracers.id, "sector": sector, "speed": speed, "start": start}


def far_hemisphere_levels(hydro_h5: Path) -> list[dict]:
    """Per snapshot of an r-z run: its time (s) and the shares of the target's mass (material 0)
    beyond 90 deg from the impact point (z < 0, the target centred at the origin, the impact at
    +z) in blocks of the finest level, one level coarser and coarser still (the finest level:
    the finest any snapshot holds); empty for a run not in r-z."""
    out = []
    with h5py.File(hydro_h5, "r") as fh:
        snapshots = [fh["snapshots"][key] for key in sorted(fh["snapshots"])]
        if not snapshots or snapshots[0].attrs["geometry"] != "2d-cylindrical":
            return out
        finest = max(int(snap["block_level"][()].max()) for snap in snapshots)
        for snap in snapshots:
            lo, hi, level = snap["block_lo"][()], snap["block_hi"][()], snap["block_level"][()]
            density = snap["partial_density"][:, 0, :, :, 0]
            nx, nz = density.shape[1:]
            dr, dz = (hi[:, 0] - lo[:, 0]) / nx, (hi[:, 1] - lo[:, 1]) / nz
            r = lo[:, 0, None, None] + (np.arange(nx)[None, :, None] + 0.5) * dr[:, None, None]
            z = lo[:, 1, None, None] + (np.arange(nz)[None, None, :] + 0.5) * dz[:, None, None]
            mass = np.where(z < 0.0, density * 2.0 * np.pi * r * (dr * dz)[:, None, None], 0.0).sum(axis=(1, 2))
            total = mass.sum()
            shares = [mass[level == finest].sum(), mass[level == finest - 1].sum(), mass[level < finest - 1].sum()]
            out.append({"time": float(snap.attrs["time"]),
                        "shares": [float(x / total) if total > 0 else 0.0 for x in shares]})
    return out


def speed_differences(sectors: dict, reference: dict) -> list[float] | None:
    """Per sector the median of the tracers' speed differences from the ``reference`` run's same
    tracers (:func:`sector_speeds`), or None when the two runs did not place the same tracers."""
    if not np.array_equal(sectors["id"], reference["id"]) or not np.allclose(sectors["start"], reference["start"]):
        return None
    difference = sectors["speed"] - reference["speed"]
    return [float(np.median(difference[reference["sector"] == k])) if count else float("nan")
            for k, count in enumerate(reference["count"])]


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
        "sectors": sector_speeds(run / "hydro.h5", scene["target"]["radius"]),
        "far_hemisphere_levels": far_hemisphere_levels(run / "hydro.h5"),
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
        answer["sectors"]["difference"] = speed_differences(answer["sectors"], reference["sectors"])
    for answer in answers:
        for key in ("id", "sector", "speed", "start"):
            del answer["sectors"][key]
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
        sectors = answer["sectors"]
        difference = sectors["difference"] or [float("nan")] * len(sectors["edges"])
        print("    tracer speed in the centre-of-mass frame, median per sector (m/s; difference from the first "
              "point's same tracers):")
        for edge, count, median, delta in zip(sectors["edges"], sectors["count"], sectors["median"], difference):
            print(f"    {edge:3d}-{edge + SECTOR_WIDTH:3d} deg: {count:4d} tracers, {median:7.3f} ({delta:+.3f})")
        if answer["far_hemisphere_levels"]:
            print("    far hemisphere's target mass on the finest level / one coarser / coarser still, per snapshot:")
            print("    " + "  ".join(f"{row['time']:.1f} s " + "/".join(f"{x:.2f}" for x in row["shares"])
                                    for row in answer["far_hemisphere_levels"]))


if __name__ == "__main__":
    main()
