"""Where the fast mass of a hand-off sits: speed fractions by distance from the centre of mass.

For each `handoff.h5` given, prints the fraction of the hand-off mass whose speed relative
to the centre of mass exceeds the escape speed from the mass enclosed within its radius
(sqrt(2 G M(<r) / r)), the fractions above 12, 30 and 100 m/s, per radius shell (in
units of ``--radius``, the target radius) the shell's mass fraction and the fraction of it
faster than 12 m/s, and for the particles within 0.5, 0.75 and 1 target radius their kinetic
energy in their own centre-of-mass frame over their mutual potential energy, K / |W| (direct
sum; a body with K > |W| cannot stay together without losing energy in collisions;
docs/validation.md, case 8), and the mass fractions by speed over the escape speed from all
the other particles (``diagnostics.escape_speed_ratio``, the ratio behind the N-body stage's
``initial_unbound_mass`` and ``initial_near_escape_mass``; bins ESCAPE_BINS; mass just below
1 is bound particle by particle but close to escaping,
docs/accuracy.md, "What in the hand-off moves M_lr/M_T").  When the run's ``nbody.h5``
sits next to the ``handoff.h5``, also the mass fraction on escape orbits at t = 0
(``initial_unbound_mass``) and the fraction that had escaped by ESCAPE_TIMES dynamical
times and at the end:

    python benchmarks/handoff_speeds.py RUN_DIR/handoff.h5 [...] --radius 1e4
"""

import argparse
from pathlib import Path

import h5py
import numpy as np
from scipy.constants import G

from impactpipe.nbody.diagnostics import escape_speed_ratio, potential_energy

SHELLS = ((0.0, 0.5), (0.5, 1.0), (1.0, 2.0), (2.0, np.inf))
VIRIAL_RADII = (0.5, 0.75, 1.0)
ESCAPE_BINS = (0.0, 0.4, 0.6, 0.8, 1.0, 2.0, np.inf)
ESCAPE_TIMES = (1.0, 3.0, 10.0)


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
        ratio = escape_speed_ratio(x, u, m)
        print("  speed / escape speed: " + ", ".join(
            f"[{lo:g}, {hi:g}) {m[(ratio >= lo) & (ratio < hi)].sum() / total:.3f}"
            for lo, hi in zip(ESCAPE_BINS[:-1], ESCAPE_BINS[1:])))
        nbody = Path(path).with_name("nbody.h5")
        if nbody.is_file():
            with h5py.File(nbody, "r") as fh:
                t = fh["diagnostics/time"][()] / fh.attrs["dynamical_time"]
                escaped = fh["diagnostics/escaped_mass"][()]
                unbound = fh.attrs["initial_unbound_mass"]
            by_time = [f"{escaped[np.searchsorted(t, tt, side='right') - 1] / total:.3f} by {tt:g}"
                       for tt in ESCAPE_TIMES if tt <= t[-1]]
            print(f"  N-body: on escape orbits at t = 0 {unbound / total:.3f}; escaped "
                  + ", ".join(by_time) + f" t_dyn, {escaped[-1] / total:.3f} at the end ({t[-1]:.3g} t_dyn)")


if __name__ == "__main__":
    main()
