"""Where the fast mass of a hand-off sits: speed fractions by distance from the centre of mass.

For each `handoff.h5` given, prints the fraction of the hand-off mass whose speed relative
to the centre of mass exceeds the escape speed from the mass enclosed within its radius
(sqrt(2 G M(<r) / r)), the fractions above 12, 30 and 100 m/s, per radius shell (in
units of ``--radius``, the target radius) the shell's mass fraction and the fraction of it
faster than 12 m/s, and for the particles within 0.5, 0.75 and 1 target radius their kinetic
energy in their own centre-of-mass frame over their mutual potential energy, K / |W| (direct
sum; a body with K > |W| cannot stay together without losing energy in collisions;
docs/validation.md, case 8):

    python benchmarks/handoff_speeds.py RUN_DIR/handoff.h5 [...] --radius 1e4
"""

import argparse

import h5py
import numpy as np

from impactpipe.nbody.diagnostics import potential_energy

G = 6.674e-11
SHELLS = ((0.0, 0.5), (0.5, 1.0), (1.0, 2.0), (2.0, np.inf))
VIRIAL_RADII = (0.5, 0.75, 1.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+")
    parser.add_argument("--radius", type=float, required=True, help="target radius (m)")
    args = parser.parse_args()
    for path in args.paths:
        with h5py.File(path, "r") as fh:
            m = fh["particles/mass"][()]
            x = fh["particles/position"][()]
            u = fh["particles/velocity"][()]
        total = m.sum()
        r = np.linalg.norm(x - (m[:, None] * x).sum(0) / total, axis=1)
        speed = np.linalg.norm(u - (m[:, None] * u).sum(0) / total, axis=1)
        order = np.argsort(r)
        enclosed = np.empty_like(m)
        enclosed[order] = np.cumsum(m[order])
        escape = np.sqrt(2.0 * G * enclosed / np.maximum(r, 1.0))
        print(f"{path}: {m.size} particles, {total:.4g} kg; faster than the escape speed of the enclosed mass "
              f"{m[speed > escape].sum() / total:.3f}; > 12, 30, 100 m/s: "
              + ", ".join(f"{m[speed > v].sum() / total:.3f}" for v in (12.0, 30.0, 100.0)))
        for lo, hi in SHELLS:
            shell = (r >= lo * args.radius) & (r < hi * args.radius)
            mass = m[shell].sum()
            fast = m[shell & (speed > 12.0)].sum() / mass if mass > 0 else 0.0
            print(f"  r / R_T in [{lo:g}, {hi:g}): mass fraction {mass / total:.3f}, of it faster than 12 m/s {fast:.3f}")
        for radius in VIRIAL_RADII:
            inside = r < radius * args.radius
            mi = m[inside]
            vi = u[inside] - (mi[:, None] * u[inside]).sum(0) / mi.sum()
            kinetic = 0.5 * (mi * (vi ** 2).sum(axis=1)).sum()
            potential = potential_energy(np.ascontiguousarray(x[inside]), np.ascontiguousarray(mi), G)
            print(f"  within {radius:g} R_T: mass fraction {mi.sum() / total:.3f}, "
                  f"K / |W| {kinetic / abs(potential):.2f}")


if __name__ == "__main__":
    main()
