"""Porous-material verification table: the hydro stage's shocked states against the exact
porous Hugoniot and the two-wave solution (``impactpipe.hydro.exact.porous``).

Hugoniot: porous Tillotson basalt (Benz & Asphaug 1999 preset; eps_e = -1e-5, kappa = 0.98,
alpha_x = 1) of alpha0 = 1.2 and 2.0 moving at -u_p onto a reflecting wall (1d-planar, 384 cells
over the 1 m slab): the steady shock leaves it at rest with particle velocity u_p.  u_p is chosen
so that the exact shocked pressure is 1, 5, 20 and 50 GPa; the table gives the median pressure
and density over the shocked plateau (0.15-0.8 of the way from the wall to the front) against
the exact state, the distension behind the shock, and the energy error net of the floors.

Two waves: alpha0 = 1.5 with eps_e = -2e-3 at u_p = 150 m/s (512 cells): where the pressure
crosses half of the precursor's pressure and half-way between the precursor's and the final
pressure, against U t of the exact precursor and compaction wave.

    python benchmarks/porous_hugoniot.py [--cells N]
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.optimize import brentq

from impactpipe.hydro import BlockMesh, HydroState, Simulation
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.exact import porous_hugoniot, two_wave_speeds
from impactpipe.hydro.problems.common import preset_material

BASALT = preset_material("basalt")["eos"]


def wall_run(spec, speed, cells, end_of):
    """Run the slab onto the wall to ``end_of`` (s) and return (simulation, energy error net of floors)."""
    alpha0 = spec["porosity"]["alpha0"]
    mesh = BlockMesh.uniform("1d-planar", [0.0], [1.25], [cells * 5 // 4], [("reflecting", "outflow")])
    state = HydroState.empty(mesh, 1)
    x = mesh.cell_centers()[:, 0]
    state.set_material(mesh, (x < 1.0).astype(float), 0, pack_eos([spec]), spec["rho0"] / alpha0,
                       np.array([-speed, 0.0, 0.0]), specific_energy=0.0)
    sim = Simulation(mesh, ["porous_basalt"], [spec], state)
    before = sim.totals()
    sim.run(end_of)
    after = sim.totals()
    added = sim.floor_amounts["energy_added_by_floors"] - sim.floor_amounts["energy_removed_by_void_cleanup"]
    return sim, (after["energy_with_outflow"] - before["energy"] - added) / before["energy"]


def hugoniot_rows(cells):
    print("| alpha0 | u_p (m/s) | P exact (GPa) | P error | rho exact (kg/m^3) | rho error | alpha behind | "
          "energy error |")
    print("|---|---|---|---|---|---|---|---|")
    for alpha0 in (1.2, 2.0):
        spec = {**BASALT, "porosity": {"alpha0": alpha0, "eps_e": -1.0e-5, "kappa": 0.98, "alpha_x": 1.0}}
        for target in (1.0e9, 5.0e9, 20.0e9, 50.0e9):
            speed = brentq(lambda u: porous_hugoniot(spec, u)[0] - target, 10.0, 2.0e4, rtol=1e-8)
            p_exact, rho_exact, alpha_exact = porous_hugoniot(spec, speed)
            shock = speed * rho_exact / (rho_exact - spec["rho0"] / alpha0)
            end = 0.6 / shock
            sim, energy_error = wall_run(spec, speed, cells, end)
            snap = sim.snapshot()
            x = snap.centers[:, 0]
            front = (shock - speed) * end
            plateau = (x > 0.15 * front) & (x < 0.8 * front)
            p = np.median(snap.pressure.reshape(-1)[plateau])
            rho = np.median(snap.density.reshape(-1)[plateau])
            alpha = np.median(snap.extra["distension"].reshape(-1)[plateau])
            print(f"| {alpha0:g} | {speed:.1f} | {p_exact / 1e9:.4g} | {p / p_exact - 1:+.2e} | {rho_exact:.1f} | "
                  f"{rho / rho_exact - 1:+.2e} | {alpha:.4f} (exact {alpha_exact:.4f}) | {energy_error:+.1e} |")


def two_wave_row(cells):
    speed = 150.0
    spec = {**BASALT, "porosity": {"alpha0": 1.5, "eps_e": -2.0e-3, "kappa": 0.98, "alpha_x": 1.0}}
    u1, u2, p1, p2 = two_wave_speeds(spec, speed)
    end = 0.7 / (u1 - speed)
    sim, _ = wall_run(spec, speed, cells, end)
    snap = sim.snapshot()
    x = snap.centers[:, 0]
    p = snap.pressure.reshape(-1)
    dx = sim.mesh.min_cell_size()
    precursor = x[np.flatnonzero(p > 0.5 * p1).max()]
    compaction = x[np.flatnonzero(p > 0.5 * (p1 + p2)).max()]
    print(f"\ntwo waves (u_p = {speed:g} m/s, {cells} cells): precursor U_1 = {u1:.1f} m/s, P_1 = {p1 / 1e6:.2f} MPa, "
          f"front at {precursor:.4f} m vs {(u1 - speed) * end:.4f} m ({(precursor - (u1 - speed) * end) / dx:+.1f} "
          f"cells); compaction U_2 = {u2:.1f} m/s, P_2 = {p2 / 1e6:.1f} MPa, front at {compaction:.4f} m vs "
          f"{(u2 - speed) * end:.4f} m ({(compaction - (u2 - speed) * end) / dx:+.1f} cells)")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cells", type=int, default=384, help="cells across the 1 m slab (Hugoniot runs)")
    args = parser.parse_args()
    hugoniot_rows(args.cells)
    two_wave_row(512)


if __name__ == "__main__":
    main()
