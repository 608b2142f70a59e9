"""Elastic wave speed of porous material (chi, Collins, Melosh & Wuennemann 2011): a weak planar
pulse through a uniform porous slab against the porous wave speed chi c_s0.

Porous Tillotson basalt (alpha0 = 1.5, eps_e = -2e-3, kappa = 0.98, alpha_x = 1) moving at
-1 m/s onto a reflecting wall (1d-planar, 512 cells over the 1 m slab; strain about 1e-3 of
the elastic limit's 2e-3): the wave that brings it to rest runs into the slab at c = chi c_s0,
c_s0 the matrix's sound speed at rho_s0 and e = 0.  Per chi the table gives the front (where
the pressure crosses half its plateau value) as a speed, (x_front / t) + u, against chi c_s0,
and the median plateau pressure over 0.1-0.5 m against the acoustic rho_00 chi c_s0 u.

    python benchmarks/porous_wave_speed.py [--chi 0.5 1.0] [--cells N]
"""

from __future__ import annotations

import argparse

from impactpipe.hydro.eos import pack_eos, pressure_sound_speed
from impactpipe.hydro.problems import porous_slab
from impactpipe.hydro.problems.common import preset_material


def wave_row(chi: float, cells: int, speed: float = 1.0) -> None:
    """Run the pulse for one ``chi`` and print its row."""
    basalt = preset_material("basalt")["eos"]
    solid = pack_eos([basalt])
    c_s0 = pressure_sound_speed(solid.kind[0], solid.params[0], solid.table, basalt["rho0"], 0.0)[1] ** 0.5
    spec = {**basalt, "porosity": {"alpha0": 1.5, "eps_e": -2.0e-3, "kappa": 0.98, "alpha_x": 1.0, "chi": chi}}
    c = chi * c_s0
    rho00 = basalt["rho0"] / 1.5
    sim = porous_slab.setup(spec, speed, cells)
    sim.run(0.7 / (c - speed))
    plateau, measured = porous_slab.wave_front(sim.snapshot(), speed)
    acoustic = rho00 * c * speed
    print(f"| {chi:g} | {c_s0:.1f} | {c:.1f} | {measured:.1f} | {measured / c - 1:+.2e} | {plateau / 1e6:.4f} | "
          f"{acoustic / 1e6:.4f} | {plateau / acoustic - 1:+.2e} |")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--chi", type=float, nargs="+", default=[0.5, 1.0], help="sound speed ratios to run")
    parser.add_argument("--cells", type=int, default=512, help="cells across the 1 m slab")
    args = parser.parse_args()
    print("| chi | c_s0 (m/s) | chi c_s0 (m/s) | front speed (m/s) | error | plateau (MPa) | rho_00 c u (MPa) "
          "| error |")
    print("|---|---|---|---|---|---|---|---|")
    for chi in args.chi:
        wave_row(chi, args.cells)


if __name__ == "__main__":
    main()
