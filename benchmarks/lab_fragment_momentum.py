"""Where the laboratory impact's momentum goes: the target's and its largest fragment's, per snapshot.

For each snapshot of a 3d half-domain run of the laboratory impact (configs/lab/), mirrored
into the whole body as `impactpipe fragments` does, prints the target material's mass-weighted
momentum P_T (kg m/s; its y component is 0 by symmetry), that over the projectile's
momentum m_P V (the momentum transferred; m_P V from the first snapshot), and the largest
fragment (cells with damage below ``--max-damage`` and fill >= 0.5): its mass over M_T, its
velocity (m/s) and its share of P_T's z component.

    python benchmarks/lab_fragment_momentum.py RUN_DIR [--max-damage 0.5] [--json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from impactpipe.handoff.mirror import mirror_across_y0
from impactpipe.hydro.output.lookup import find_snapshot, hydro_file, snapshot_times
from impactpipe.pipeline.fragments import body_cells, snapshot_fragments

TARGET, PROJECTILE = 0, 1


def body_momentum(whole, material: int) -> tuple[float, np.ndarray]:
    """(mass (kg), momentum (3,) (kg m/s)) of ``material`` on a whole (mirrored) snapshot."""
    cells = body_cells(whole, [material])
    return float(cells["mass"].sum()), (cells["mass"][:, None] * cells["velocity"]).sum(axis=0)


def rows(run_dir: Path, max_damage: float) -> list[dict]:
    """One dict per snapshot after the first (the quantities of the module docstring)."""
    first, _ = find_snapshot(run_dir, index=0)
    _, projectile_momentum = body_momentum(mirror_across_y0(first)[0], PROJECTILE)
    _, target_start = body_momentum(mirror_across_y0(first)[0], TARGET)
    impact = float(np.linalg.norm(projectile_momentum + target_start))
    out = []
    for index in range(1, snapshot_times(hydro_file(run_dir)).size):
        snapshot, _ = find_snapshot(run_dir, index=index)
        whole = mirror_across_y0(snapshot)[0]
        target_mass, target_momentum = body_momentum(whole, TARGET)
        fragments = snapshot_fragments(snapshot, [TARGET], True, 0.5, max_damage)
        largest = int(np.argmax(fragments.mass)) if len(fragments.mass) else -1
        row = {"time_s": snapshot.time, "target_momentum": target_momentum.tolist(),
               "transferred": float(np.linalg.norm(target_momentum)) / impact}
        if largest >= 0:
            velocity = fragments.velocity[largest]
            row.update({"largest_fraction": float(fragments.mass[largest]) / target_mass,
                        "largest_velocity": velocity.tolist(), "largest_speed": float(np.linalg.norm(velocity)),
                        "largest_share_of_z_momentum": float(fragments.mass[largest] * velocity[2] / target_momentum[2])})
        out.append(row)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--max-damage", type=float, default=0.5)
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    args = parser.parse_args()
    table = rows(args.run_dir, args.max_damage)
    if args.json:
        print(json.dumps({"run_dir": str(args.run_dir), "max_damage": args.max_damage, "rows": table}, indent=2))
        return
    for row in table:
        px, _, pz = row["target_momentum"]
        line = f"t = {row['time_s'] * 1e6:6.1f} us: P_T = ({px:+.4f}, {pz:+.4f}) kg m/s, {row['transferred']:.3f} m_P V"
        if "largest_fraction" in row:
            vx, _, vz = row["largest_velocity"]
            line += (f"; largest fragment {row['largest_fraction']:.3f} M_T at ({vx:+.3f}, {vz:+.3f}) m/s, "
                     f"{row['largest_speed']:.3f} m/s, {row['largest_share_of_z_momentum']:.3f} of P_T,z")
        print(line)


if __name__ == "__main__":
    main()
