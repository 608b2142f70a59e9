"""The momentum and energy an impact scene starts with, against the projectile's.

Builds the hydro stage's initial state of an impact config at each ``--cells`` per
projectile radius (the config's mesh otherwise: levels, blocks, half domain) and prints

    |P| / (m_P V)  and  E / (m_P V^2 / 2)

with P the state's momentum (kg m/s), E its total energy (J), m_P the projectile's mass on
the mesh (kg) and V the impact speed (m/s).  Both are 1 when the state carries exactly the
projectile's momentum and kinetic energy (a cold target: e = 0; a self-gravitating one adds
its thermal energy to E).  The cells the two spheres share at the contact point take the
sum of the bodies' momenta (:meth:`impactpipe.hydro.mesh.state.HydroState.set_material`);
where they moved at the projectile's velocity instead, the target material in them added
its momentum and kinetic energy to the impact: run this script against such a version to
see by how much (docs/validation.md, "The initial contact").

    python benchmarks/contact_momentum.py configs/lab/basalt_sphere_nylon_k1e36_count1e5_2cells.yaml --cells 1 2 4 [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from impactpipe.pipeline.adapters.hydro import build_simulation
from impactpipe.pipeline.config import load_config
from impactpipe.pipeline.derived import derive

PROJECTILE = 1


def contact_ratios(config_path: str, cells: float) -> dict:
    """|P| / (m_P V) and E / (m_P V^2 / 2) of the initial state at ``cells`` per projectile radius."""
    config = load_config(config_path, overrides={"hydro.cells_per_projectile_radius": cells})
    sim = build_simulation(config, derive(config))
    totals = sim.totals()
    speed = float(config.scene.impact.velocity)
    m_p = float(totals["material_mass"][PROJECTILE])
    return {"cells_per_projectile_radius": cells, "projectile_mass_kg": m_p,
            "momentum_ratio": float(np.linalg.norm(totals["momentum"]) / (m_p * speed)),
            "energy_ratio": float(totals["energy"] / (0.5 * m_p * speed ** 2))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("config", help="an impact config")
    parser.add_argument("--cells", type=float, nargs="+", required=True, help="cells per projectile radius")
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    args = parser.parse_args()
    rows = [contact_ratios(args.config, cells) for cells in args.cells]
    if args.json:
        print(json.dumps({"config": args.config, "rows": rows}, indent=2))
        return
    for row in rows:
        print(f"{row['cells_per_projectile_radius']:g} cells per projectile radius: |P| / (m_P V) = "
              f"{row['momentum_ratio']:.6f}, E / (m_P V^2 / 2) = {row['energy_ratio']:.6f}")


if __name__ == "__main__":
    main()
