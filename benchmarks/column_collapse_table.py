"""Granular column collapse over aspect ratios, friction angles, Courant numbers and resolutions.

Builds the scene of configs/column_collapse.yaml (its material and floor) with the cohesion
``--cohesion`` (Pa), mu_i = tan(phi) for each ``--phi`` (deg), the width L0 = H0 / a for each
aspect ratio ``--aspect``, each Courant number ``--cfl`` (past the scene's limit on purpose) and
each ``--cells`` per H0, runs it to ``--end`` tau (tau = sqrt(H0 / g)) and prints one row per
run: the kinetic energy at the end over its peak (sampled every tau / 4), how long the front
has been still (within STILL_FRONT_CELLS of a cell of where it stopped), the run-out
(L_f - L0) / L0 and height H_f / L0 against the laws (docs/validation.md, "Granular column
collapse"), and the deposit's centroid.

    python benchmarks/column_collapse_table.py --aspect 0.5 1 3.2 6 --phi 25 --cfl 0.2 --cells 16 --end 10

``--hourglass 0`` and ``--no-surface-layer`` take the scene back to the scheme without them;
``--settling`` switches on the void settling (``scene.settling``, hydro/scheme/settling.py);
``--face-shear`` the face shear stress (``scene.face_shear``, hydro/strength/face_shear.py);
``--mu-of-I MU_2 I0 D`` gives the material the GEO model's mu(I) friction (``mu_2``,
``inertial_number_I0``, ``grain_diameter`` D in m; mu_s = tan(phi); docs/strength.md, "mu(I)
friction").
``--room R`` lengthens the mesh to R run-outs of the law beyond the column (a deposit that
reaches the far edge grows the mesh, up to 4 times its first length, then stops the run with an
error; hydro/problems/column_collapse.py).
``--dilation`` adds two columns at the end: the share of the mass in partly filled cells (fill
below DILATED_FILL) and the share at a pressure below rho0 |g| dx / 2 (the surface-layer pressure
of a full surface cell, Pa): material that holds void or next to no pressure, which a
cohesionless material's strength does not hold beyond its surface-layer pressure
(docs/validation.md, "Why the run-out grows with resolution").
``--fronts`` adds the run-out (L_f - L0) / L0 with L_f where the thickness falls below
0.01, 0.02, 0.05 and 0.1 H0 (a threshold fixed in physical units, not in cells) and where the
cumulative volume from the wall reaches 90 %, 95 % and 99 % of the deposit's
(``column_collapse.front_at_thickness``, ``front_by_volume``; docs/validation.md, "The front
against a threshold fixed in H0").  ``--save DIR`` writes, per run,
DIR/profiles_a<a>_phi<phi>_cfl<cfl>_n<cells>.npz: the thickness profiles h(x) (m) at every
tau / 4 (``time`` in tau, ``x``, ``thickness``, ``dx``, ``height`` H0, ``width`` L0).
``--plot DIR`` writes, per run, DIR/profile_a<a>_phi<phi>_cfl<cfl>_n<cells>.png: the deposit's
thickness h(x) / L0 at t = tau and at the end against x / L0, with the laws' run-out L_f and
height H_f marked.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from impactpipe.hydro.problems import column_collapse  # noqa: E402
from impactpipe.pipeline.config import load_config  # noqa: E402

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "column_collapse.yaml"

#: A cell filled less than this counts as partly filled in the ``--dilation`` columns.
DILATED_FILL = 0.99
#: The front counts as still while it stays within this many cell sizes of where it stopped (a
#: front that crosses no cell boundary still changes by round-off, of order 1e-8 L0).
STILL_FRONT_CELLS = 0.01


def run(aspect: float, phi: float, cfl: float, cells: int, end: float, cohesion: float, hourglass: float,
        surface_layer: bool, plot: Path | None = None, room: float | None = None, settling: bool = False,
        face_shear: bool = False, save: Path | None = None, mu_of_i: list[float] | None = None) -> dict:
    """One collapse; returns the row's numbers (lengths in units of L0, times in tau)."""
    config = load_config(CONFIG)
    scene = config.scene.model_dump(exclude={"problem", "geometry"})
    scene.update(width=scene["height"] / aspect, cells_per_height=cells, hourglass=hourglass, settling=settling,
                 face_shear=face_shear)
    if room is not None:
        scene["room"] = room
    materials = config.resolved_materials()
    strength = materials[scene["material"]]["strength"]
    strength.update(Y0=cohesion, mu_i=math.tan(math.radians(phi)))
    if mu_of_i is not None:
        strength.update(mu_2=mu_of_i[0], inertial_number_I0=mu_of_i[1], grain_diameter=mu_of_i[2])
    sim = column_collapse.setup(scene, materials, block_cells=config.hydro.block_cells,
                                cfl=min(cfl, column_collapse.MAX_CFL))
    sim.cfl = cfl
    if not surface_layer:
        sim.strength.surface_gravity = None
    height, width = scene["height"], scene["width"]
    tau = math.sqrt(height / scene["gravity"])
    peak, front, still_since, started, profiles = 0.0, None, 0.0, time.perf_counter(), {}
    times, thicknesses = [], []
    for k in range(1, int(round(4 * end)) + 1):
        sim.run(k * tau / 4)
        snap = sim.snapshot()
        energy = column_collapse.kinetic_energy(snap)
        peak = max(peak, energy)
        deposit = column_collapse.deposit(snap)
        if k == 4:
            profiles["t = tau"] = deposit
        times.append(sim.time / tau)
        thicknesses.append(deposit["thickness"])
        if front is None or abs(deposit["runout"] - front) > STILL_FRONT_CELLS * deposit["dx"]:
            front, still_since = deposit["runout"], sim.time / tau
    if plot is not None:
        profiles[f"t = {sim.time / tau:g} tau"] = deposit
        _plot_profiles(plot / f"profile_a{aspect:g}_phi{phi:g}_cfl{cfl:g}_n{cells}.png", profiles, width, aspect)
    if save is not None:
        save.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(save / f"profiles_a{aspect:g}_phi{phi:g}_cfl{cfl:g}_n{cells}.npz",
                            time=np.asarray(times), x=deposit["x"], thickness=np.asarray(thicknesses),
                            dx=deposit["dx"], height=height, width=width)
    fronts = {f"h{share:g}H0": (column_collapse.front_at_thickness(deposit, share * height) - width) / width
              for share in column_collapse.FRONT_THICKNESS_H0}
    fronts.update({f"v{share:g}": (column_collapse.front_by_volume(deposit, share) - width) / width
                   for share in column_collapse.FRONT_VOLUME_SHARES})
    mass = snap.partial_density.sum(axis=1)
    fill = snap.volume_fraction.sum(axis=1)
    rho0 = float(mass.max())  # the densest cell, within 1e-3 of the reference density (kg/m^3)
    unloaded = snap.pressure < 0.5 * rho0 * scene["gravity"] * height / cells
    return {"a": aspect, "phi": phi, "cfl": cfl, "cells": cells, "ke": energy / peak,
            "partly_filled": float(mass[fill < DILATED_FILL].sum() / mass.sum()),
            "unloaded": float(mass[unloaded & (mass > 0.0)].sum() / mass.sum()),
            "still": sim.time / tau - still_since, "runout": (deposit["runout"] - width) / width,
            "height": deposit["height"] / width, "centroid": deposit["centroid"] / width,
            "law_runout": column_collapse.scaling_runout(aspect), "law_height": column_collapse.scaling_height(aspect),
            "fronts": fronts, "wall": time.perf_counter() - started}


def _plot_profiles(path: Path, profiles: dict, width: float, aspect: float) -> None:
    """The thickness profiles h(x) / L0 against x / L0, the laws' L_f and H_f marked, into ``path``."""
    fig, ax = plt.subplots(figsize=(7, 3))
    for label, deposit in profiles.items():
        ax.step(deposit["x"] / width, deposit["thickness"] / width, where="mid", label=label)
    ax.axvline(1.0 + column_collapse.scaling_runout(aspect), color="k", ls="--", label="law: L_f")
    ax.axhline(column_collapse.scaling_height(aspect), color="k", ls=":", label="law: H_f")
    ax.set_xlabel("x / L0")
    ax.set_ylabel("h / L0")
    ax.set_title(f"column collapse, a = {aspect:g}")
    ax.legend(fontsize="small")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100, bbox_inches="tight")
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--aspect", type=float, nargs="+", default=[1.0])
    parser.add_argument("--phi", type=float, nargs="+", default=[25.0], help="friction angle, mu_i = tan(phi) (deg)")
    parser.add_argument("--cfl", type=float, nargs="+", default=[0.2])
    parser.add_argument("--cells", type=int, nargs="+", default=[16], help="cells per H0")
    parser.add_argument("--end", type=float, default=10.0, help="end time in tau = sqrt(H0 / g)")
    parser.add_argument("--cohesion", type=float, default=0.0, help="Y0 (Pa)")
    parser.add_argument("--hourglass", type=float, default=column_collapse.HOURGLASS_COEFFICIENT,
                        help="scene.hourglass, the hourglass viscosity coefficient")
    parser.add_argument("--no-surface-layer", action="store_true",
                        help="without the surface-layer pressure of the yield strength (as before it existed)")
    parser.add_argument("--settling", action="store_true",
                        help="with the void settling (scene.settling: true, hydro/scheme/settling.py)")
    parser.add_argument("--face-shear", action="store_true",
                        help="with the face shear stress (scene.face_shear: true, hydro/strength/face_shear.py)")
    parser.add_argument("--mu-of-I", type=float, nargs=3, default=None, metavar=("MU_2", "I0", "D"),
                        help="the mu(I) friction: mu_2, inertial_number_I0 and grain_diameter (m); mu_s = tan(phi)")
    parser.add_argument("--plot", type=Path, default=None, help="folder for the thickness profile plots")
    parser.add_argument("--room", type=float, default=None,
                        help="scene.room: mesh length beyond the column in run-outs of the law (the config's if omitted)")
    parser.add_argument("--dilation", action="store_true",
                        help="add the mass shares in partly filled cells and at a pressure below rho0 |g| dx / 2")
    parser.add_argument("--fronts", action="store_true",
                        help="add the run-out at thicknesses fixed as fractions of H0 and at shares of the volume")
    parser.add_argument("--save", type=Path, default=None,
                        help="folder for the thickness profiles h(x) at every tau / 4 (one .npz per run)")
    args = parser.parse_args()
    extra = " partly filled | p < rho0 g dx / 2 |" if args.dilation else ""
    names = ([f"run-out h >= {share:g} H0" for share in column_collapse.FRONT_THICKNESS_H0]
             + [f"run-out {share:.0%} of volume" for share in column_collapse.FRONT_VOLUME_SHARES])
    if args.fronts:
        extra += "".join(f" {name} |" for name in names)
    print("| a | phi | cfl | cells/H0 | KE/peak at end | front still for | run-out (law) | height (law) | centroid |" + extra)
    print("|---|---|---|---|---|---|---|---|---|" + "---|" * extra.count("|"))
    for aspect in args.aspect:
        for phi in args.phi:
            for cfl in args.cfl:
                for cells in args.cells:
                    r = run(aspect, phi, cfl, cells, args.end, args.cohesion, args.hourglass,
                            not args.no_surface_layer, args.plot, args.room, args.settling,
                            args.face_shear, args.save, args.mu_of_I)
                    print(f"| {r['a']:g} | {r['phi']:g} | {r['cfl']:g} | {r['cells']} | {r['ke']:.1e} | "
                          f"{r['still']:.2f} tau | {r['runout']:.3f} ({r['law_runout']:.3g}, "
                          f"{r['runout'] / r['law_runout'] - 1:+.0%}) | {r['height']:.3f} ({r['law_height']:.3g}, "
                          f"{r['height'] / r['law_height'] - 1:+.0%}) | {r['centroid']:.4f} |"
                          + (f" {r['partly_filled']:.3f} | {r['unloaded']:.3f} |" if args.dilation else "")
                          + ("".join(f" {value:.3f} |" for value in r["fronts"].values()) if args.fronts else ""),
                          flush=True)


if __name__ == "__main__":
    main()
