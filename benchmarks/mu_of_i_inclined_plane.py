"""The mu(I) friction against the steady uniform (Bagnold) flow down an inclined plane, over resolutions.

Builds the scene of ``hydro/problems/inclined_plane.py``: a layer h = 10 d thick (d = 0.53 mm,
the glass beads of Jop, Forterre & Pouliquen 2006: mu_s = tan 20.9 deg, mu_2 = tan 32.76 deg,
I0 = 0.279) on a rough plane inclined at ``--slope`` (deg), periodic along the slope, with
``--cells`` cells across h, its compressibility rho0 |g| h / K = ``--compressibility``, its
Poisson ratio ``--poisson`` (the shear modulus G = 3 K (1 - 2 nu) / (2 (1 + nu))) and the
hourglass viscosity ``--hourglass`` C (``--face-shear`` instead: the face shear stress).  It runs
to ``--end`` tau (tau = sqrt(h / g)) and prints one row per resolution: the relative L2 error
sqrt(sum (u - u_exact)^2 / sum u_exact^2) over the layer's cell rows of the velocity profile
averaged over the last ``--average`` tau (sampled every tau) and at the end, the largest
error over the surface velocity of the exact profile, the mean velocity and the velocity of the
top row against the exact ones, and t_1%: the first sample from which the mean velocity stays
within 1 % of its average over the last ``--average`` tau (the time to steady state).

    python benchmarks/mu_of_i_inclined_plane.py --cells 8 16 32 --end 100 --json results.json

docs/validation.md, "mu(I) friction on an inclined plane".
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from impactpipe.hydro.problems import inclined_plane

#: The glass beads of Jop, Forterre & Pouliquen (2006): mu_s, mu_2 (tan 20.9 and 32.76 deg), I0, d (m).
MU_S = math.tan(math.radians(20.9))
MU_2 = math.tan(math.radians(32.76))
I0 = 0.279
GRAIN_DIAMETER = 0.53e-3
#: Layer thickness h in grain diameters.
THICKNESS_GRAINS = 10.0
GRAVITY = 9.81


def run(slope_deg: float, cells: int, end: float, average: float, compressibility: float, hourglass: float,
        face_shear: bool, cfl: float, poisson: float = 0.3) -> dict:
    """One layer to ``end`` tau; returns the row's numbers (velocities in m/s, times in tau)."""
    h = THICKNESS_GRAINS * GRAIN_DIAMETER
    slope = math.radians(slope_deg)
    material = inclined_plane.granular_material(math.sqrt(GRAVITY * h / compressibility), MU_S, MU_2, I0,
                                                GRAIN_DIAMETER, poisson=poisson)
    sim = inclined_plane.setup(material, slope, h, cells, GRAVITY, cfl, hourglass, face_shear)
    tau = math.sqrt(h / GRAVITY)
    started = time.perf_counter()
    times, profiles = [], []
    for k in range(1, int(round(end)) + 1):
        sim.run(k * tau)
        z, u = inclined_plane.velocity_profile(sim.snapshot(), h)
        times.append(sim.time / tau)
        profiles.append(u)
    profiles = np.asarray(profiles)
    exact = inclined_plane.bagnold_velocity(z, h, slope, GRAVITY, MU_S, MU_2, I0, GRAIN_DIAMETER)
    window = np.asarray(times) > end - average - 1e-9
    steady = profiles[window].mean(axis=0)
    means = profiles.mean(axis=1)
    settled = np.abs(means / steady.mean() - 1.0) <= 0.01
    first = int(np.flatnonzero(~settled).max()) + 1 if not settled.all() else 0
    surface = float(inclined_plane.bagnold_velocity(h, h, slope, GRAVITY, MU_S, MU_2, I0, GRAIN_DIAMETER))

    def l2(u):
        return float(np.sqrt(((u - exact) ** 2).sum() / (exact ** 2).sum()))

    return {"slope_deg": slope_deg, "cells": cells, "compressibility": compressibility, "poisson": poisson,
            "hourglass": hourglass,
            "face_shear": face_shear, "cfl": cfl, "end_tau": end, "average_tau": average,
            "inertial_number": inclined_plane.slope_inertial_number(slope, MU_S, MU_2, I0),
            "l2_averaged": l2(steady), "l2_end": l2(profiles[-1]),
            "max_error_over_surface": float(np.abs(steady - exact).max() / surface),
            "mean_velocity": float(steady.mean()), "mean_velocity_exact": float(exact.mean()),
            "top_row_velocity": float(steady[-1]), "top_row_velocity_exact": float(exact[-1]),
            "settled_tau": times[first] if first < len(times) else float("nan"),
            "z": z.tolist(), "velocity": steady.tolist(), "velocity_exact": exact.tolist(),
            "wall_s": time.perf_counter() - started}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--slope", type=float, default=25.0, help="inclination theta (deg)")
    parser.add_argument("--cells", type=int, nargs="+", default=[8, 16, 32], help="cells across the layer")
    parser.add_argument("--end", type=float, default=100.0, help="end time in tau = sqrt(h / g)")
    parser.add_argument("--average", type=float, default=20.0, help="the profile is averaged over the last AVERAGE tau")
    parser.add_argument("--compressibility", type=float, default=1.0e-2, help="rho0 |g| h / K (-)")
    parser.add_argument("--poisson", type=float, default=0.3, help="Poisson ratio nu (-)")
    parser.add_argument("--hourglass", type=float, default=0.1, help="hourglass viscosity coefficient C (0: none)")
    parser.add_argument("--face-shear", action="store_true", help="with the face shear stress")
    parser.add_argument("--cfl", type=float, default=0.4)
    parser.add_argument("--json", type=Path, default=None, help="write the rows (with the profiles) to this file")
    args = parser.parse_args()
    print("| cells across h | L2 error, averaged | L2 error at the end | max error / u_s | mean u (exact) m/s "
          "| top row u (exact) m/s | t_1% (tau) |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for cells in args.cells:
        r = run(args.slope, cells, args.end, args.average, args.compressibility, args.hourglass, args.face_shear,
                args.cfl, args.poisson)
        rows.append(r)
        print(f"| {cells} | {r['l2_averaged']:.4f} | {r['l2_end']:.4f} | {r['max_error_over_surface']:.4f} | "
              f"{r['mean_velocity']:.4f} ({r['mean_velocity_exact']:.4f}) | {r['top_row_velocity']:.4f} "
              f"({r['top_row_velocity_exact']:.4f}) | {r['settled_tau']:.0f} |", flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
