"""How fast the target moves, snapshot by snapshot: when an impact sets its bulk velocities.

For each snapshot of a 2d-cylindrical impact's `hydro.h5` (target centred at the origin),
prints the mass-weighted rms speed in shells of the original target radius (``--radius``)
in the frame that moves with the mesh's axial centre-of-mass velocity, the kinetic energy
of the material within the target radius and of all the material on the mesh (J), the mass
fraction within the target radius moving faster than ``--speed`` (m/s, default 12: the
10 km basalt target's surface escape speed), the failed fraction of the mass (damage 1) and
the fraction of that failed mass carrying no deviatoric stress (von Mises stress below
1e4 Pa).  ``--axis INDEX`` prints instead the profile along the symmetry axis (cells within
150 m of it) of that snapshot: axial and radial velocity, pressure, density, damage:

    python benchmarks/target_speed_history.py RUN_DIR/hydro.h5 --radius 1e4 [--every 2]
    python benchmarks/target_speed_history.py RUN_DIR/hydro.h5 --radius 1e4 --axis 1

(docs/validation.md, "Why case 8b is low").
"""

import argparse

import h5py
import numpy as np

from impactpipe.hydro import read_snapshot

SHELLS = ((0.0, 0.5), (0.5, 0.75), (0.75, 1.0), (1.0, np.inf))
#: Von Mises stress (Pa) below which failed material counts as carrying no deviatoric stress.
NO_STRESS = 1.0e4
#: Half-width (m) of the column of cells next to the axis that ``--axis`` prints.
AXIS_BAND = 150.0
#: Rows ``--axis`` prints.
AXIS_ROWS = 30


def axis_profile(path: str, index: int) -> None:
    """Print the cells within AXIS_BAND of the symmetry axis of snapshot ``index``, top to bottom."""
    snap = read_snapshot(path, index=index)
    f = snap.fields
    on_axis = np.flatnonzero((snap.centers[:, 0] < AXIS_BAND) & (f["density"] > 100.0))
    on_axis = on_axis[np.argsort(-snap.centers[on_axis, 1])]
    print(f"t = {snap.time:g} s: z (m) | v_z (m/s) | v_r (m/s) | p (Pa) | rho (kg/m^3) | damage")
    for i in on_axis[::max(1, on_axis.size // AXIS_ROWS)]:
        damage = f["damage"][i] if "damage" in f else float("nan")
        print(f"{snap.centers[i, 1]:8.0f} | {f['velocity'][i, 1]:8.2f} | {f['velocity'][i, 0]:7.2f} | "
              f"{f['pressure'][i]:10.3e} | {f['density'][i]:6.0f} | {damage:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("path")
    parser.add_argument("--radius", type=float, required=True, help="target radius (m)")
    parser.add_argument("--speed", type=float, default=12.0, help="speed threshold (m/s)")
    parser.add_argument("--every", type=int, default=1, help="every n-th snapshot")
    parser.add_argument("--axis", type=int, default=None, metavar="INDEX",
                        help="print the profile along the axis of snapshot INDEX instead")
    args = parser.parse_args()
    if args.axis is not None:
        axis_profile(args.path, args.axis)
        return
    with h5py.File(args.path, "r") as fh:
        count = len(fh["snapshots"])
    print("t (s) | rms speed (m/s) in r / R_T " + ", ".join(f"[{lo:g}, {hi:g})" for lo, hi in SHELLS)
          + f" | K within R_T, K on the mesh (J) | mass within R_T faster than {args.speed:g} m/s | failed"
          + " | of it without deviatoric stress")
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
        failed = unstressed = float("nan")
        if damage is not None:
            broken = (damage >= 0.99) & (snap.fields["density"] > 1000.0)
            failed = mass[broken].sum() / mass.sum()
            if broken.any():
                unstressed = mass[broken & (snap.fields["von_mises_stress"] < NO_STRESS)].sum() / mass[broken].sum()
        print(f"{snap.time:6.2f} | " + " ".join(f"{v:7.2f}" for v in rms)
              + f" | {0.5 * (mass * speed2)[inside].sum():.3e} {0.5 * (mass * speed2).sum():.3e}"
              + f" | {fast:.3f} | {failed:.3f} | {unstressed:.3f}")


if __name__ == "__main__":
    main()
