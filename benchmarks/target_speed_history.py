"""How fast the target moves, snapshot by snapshot: when an impact sets its bulk velocities.

For each snapshot of a 2d-cylindrical impact's `hydro.h5` (target centred at the origin),
prints the mass-weighted rms speed in shells of the original target radius (``--radius``)
in the frame that moves with the mesh's axial centre-of-mass velocity, the kinetic energy
of the material within the target radius and of all the material on the mesh (J), the mass
fraction within the target radius moving faster than ``--speed`` (m/s, default 12: the
10 km basalt target's surface escape speed) and the failed fraction of the mass (damage 1):

    python benchmarks/target_speed_history.py RUN_DIR/hydro.h5 --radius 1e4 [--every 2]

(docs/validation.md, "Why case 8b is low").
"""

import argparse

import h5py
import numpy as np

from impactpipe.hydro import read_snapshot

SHELLS = ((0.0, 0.5), (0.5, 0.75), (0.75, 1.0), (1.0, np.inf))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("path")
    parser.add_argument("--radius", type=float, required=True, help="target radius (m)")
    parser.add_argument("--speed", type=float, default=12.0, help="speed threshold (m/s)")
    parser.add_argument("--every", type=int, default=1, help="every n-th snapshot")
    args = parser.parse_args()
    with h5py.File(args.path, "r") as fh:
        count = len(fh["snapshots"])
    print("t (s) | rms speed (m/s) in r / R_T " + ", ".join(f"[{lo:g}, {hi:g})" for lo, hi in SHELLS)
          + f" | K within R_T, K on the mesh (J) | mass within R_T faster than {args.speed:g} m/s | failed")
    for index in range(0, count, args.every):
        snap = read_snapshot(args.path, index=index)
        mass = snap.fields["density"] * snap.volumes
        velocity = snap.fields["velocity"].copy()
        velocity[:, 1] -= (mass * velocity[:, 1]).sum() / mass.sum()
        speed2 = (velocity ** 2).sum(axis=1)
        r = np.hypot(snap.centers[:, 0], snap.centers[:, 1])
        rms = []
        for lo, hi in SHELLS:
            shell = (r >= lo * args.radius) & (r < hi * args.radius)
            rms.append(np.sqrt(np.average(speed2[shell], weights=mass[shell])) if mass[shell].sum() > 0 else 0.0)
        inside = r < args.radius
        fast = mass[inside & (speed2 > args.speed ** 2)].sum() / mass.sum()
        damage = snap.fields.get("damage")
        failed = mass[damage >= 0.99].sum() / mass.sum() if damage is not None else float("nan")
        print(f"{snap.time:6.2f} | " + " ".join(f"{v:7.2f}" for v in rms)
              + f" | {0.5 * (mass * speed2)[inside].sum():.3e} {0.5 * (mass * speed2).sum():.3e}"
              + f" | {fast:.3f} | {failed:.3f}")


if __name__ == "__main__":
    main()
