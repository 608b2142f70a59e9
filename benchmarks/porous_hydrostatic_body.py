"""A porous body in hydrostatic equilibrium under its own gravity stays at rest, unstrained.

    python benchmarks/porous_hydrostatic_body.py --json

The hydrostatic_body problem with a porous Tillotson-basalt sphere (R = 50 km, distension
alpha_0 = 1.5, bulk density rho_s0 / alpha_0 = 1800 kg/m^3, self-gravity of order 4), r-z, over
one sound-crossing time R / c_s0 (c_s0 = sqrt(A / rho_s0), the matrix's sound speed, 15.9 s).  Its
exact solution is its initial state: bulk density rho_s0 / alpha_0, distension alpha_0 and the
lithostatic pressure p(r) = (2 pi / 3) G rho^2 (R^2 - r^2), the porous pressure
P_s(alpha_0 rho, e) / alpha_0 of the internal energy e the setup solves for.  Per compaction
parameter set (strengthless, and the `basalt` preset with GEO `weak` strength) and resolution
(cells per radius):

- ``initial_pressure_error``: the largest |P / alpha_k - p(r)| over the central pressure p(0) in
  the cells holding the body at t = 0 (P the cell pressure, volume-fraction weighted, alpha_k the
  body's volume fraction);
- ``max_speed_over_escape``, ``inside_0.95R_over_escape``: the largest speed over the escape speed
  v_esc = R sqrt(8 pi G rho / 3) in the cells at least half full, and those inside 0.95 R;
- ``max_distension_change``: the largest |alpha - alpha_0| / alpha_0 in those cells at any step,
  and ``inside_0.95R_distension_change`` inside 0.95 R;
- ``energy_with_potential_drift``: the drift of E_mesh + W over |W| (W = (1/2) sum m Phi).

``cold`` (per parameter set, no run): what the body's centre would need to carry p(0) cold,
on its compaction curve at e = 0 instead of through thermal pressure at zero strain: the porous
pressure at the elastic limit, P_s(alpha_0 rho_00 exp(-eps_e), 0) / alpha_0 (Pa), and the strain
eps_v where P_s(alpha(eps_v) rho_00 exp(-eps_v), 0) / alpha(eps_v) = p(0), with its alpha and the
relative rise of the bulk density exp(-eps_v) - 1; ``central_energy``, the e (J/kg) of the
thermal start at the centre, P_s(rho_s0, e) = alpha_0 p(0).
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from scipy.optimize import brentq

from impactpipe.hydro.eos import energy_from_pressure, pack_eos, pressure_sound_speed
from impactpipe.hydro.eos.porosity import distension_of_strain, distension_slot, pack_porosity
from impactpipe.hydro.problems import PROBLEMS
from impactpipe.hydro.problems.impact import lithostatic_pressure
from impactpipe.hydro.self_gravity import G
from impactpipe.pipeline.presets import resolve_eos, resolve_porosity, resolve_strength

BASALT = resolve_eos("tillotson", "basalt", {})
RHO_SOLID = 2700.0
ALPHA0 = 1.5
RADIUS = 50.0e3
#: Compaction parameter sets: the `basalt` preset (Raducan et al. 2019's published iSALE inputs)
#: and the set written out in configs/porous/case9_porous.yaml.
POROSITY = {
    "basalt preset": resolve_porosity({"preset": "basalt", "alpha0": ALPHA0}),
    "case9_porous": {"alpha0": ALPHA0, "eps_e": -1.0e-5, "kappa": 0.98, "alpha_x": 1.0},
}
#: The bodies at rest: each parameter set strengthless, and the `basalt` preset with the GEO
#: `weak` strength of configs/large_body/porous.yaml.
BODIES = {
    **{name: {"porosity": porosity} for name, porosity in POROSITY.items()},
    "basalt preset, GEO weak": {"porosity": POROSITY["basalt preset"],
                                "strength": resolve_strength("geo", "weak", {})},
}


def porous_body(material: dict, cells_per_radius: int):
    """The hydrostatic_body Simulation of a porous basalt sphere (module docstring); ``material``
    the porous material's ``porosity`` and optional ``strength``."""
    params = {"body": {"material": "porous_basalt", "radius": RADIUS}, "cells_per_radius": cells_per_radius}
    return PROBLEMS["hydrostatic_body"].setup(params, {"porous_basalt": {"eos": BASALT, **material}})


def radius_of_cells(mesh) -> np.ndarray:
    """Distance (m) of each cell centre from the origin, (NB, nx, ny, nz)."""
    return np.sqrt((mesh.cell_centers() ** 2).sum(axis=1))


def initial_pressure_error(sim) -> float:
    """max |P / alpha_k - p(r)| / p(0) over the body's cells at t = 0."""
    snap = sim.snapshot()
    fill = snap.volume_fraction[:, 0]
    body = fill > 0.0
    rho = RHO_SOLID / ALPHA0
    exact = lithostatic_pressure(rho, RADIUS, radius_of_cells(sim.mesh))
    error = np.abs(snap.pressure[body] / fill[body] - exact[body])
    return float(error.max() / lithostatic_pressure(rho, RADIUS, 0.0))


def at_rest(material: dict, cells_per_radius: int) -> dict:
    """The measures of the module docstring for one body of :data:`BODIES` and resolution."""
    sim = porous_body(material, cells_per_radius)
    pressure_error = initial_pressure_error(sim)
    mesh, state = sim.mesh, sim.state
    rho0 = RHO_SOLID / ALPHA0
    escape = np.sqrt(8.0 * np.pi * G * rho0 / 3.0) * RADIUS
    crossing = RADIUS / np.sqrt(26.7e9 / RHO_SOLID)
    r = radius_of_cells(mesh)
    sim.step()
    start = sim.totals()["energy"] + sim.gravity.potential_energy
    fastest = inside = change = change_inside = 0.0
    slot = distension_slot(state.arhoq.shape[1])
    while sim.time < crossing:
        sim.step()
        rho = mesh.interior(state.arho).sum(axis=1)
        full = rho > 0.5 * rho0
        deep = full & (r < 0.95 * RADIUS)
        speed = np.linalg.norm(mesh.interior(state.momentum), axis=1) / np.where(rho > 0.0, rho, 1.0)
        distension = mesh.interior(state.arhoq)[:, slot] / np.where(rho > 0.0, rho, 1.0)
        fastest = max(fastest, float(speed[full].max()))
        inside = max(inside, float(speed[deep].max()))
        change = max(change, float(np.abs(distension[full] / ALPHA0 - 1.0).max()))
        change_inside = max(change_inside, float(np.abs(distension[deep] / ALPHA0 - 1.0).max()))
    drift = sim.totals()["energy"] + sim.gravity.potential_energy - start
    return {"steps": sim.step_count, "initial_pressure_error": pressure_error,
            "max_speed_over_escape": fastest / escape, "inside_0.95R_over_escape": inside / escape,
            "max_distension_change": change, "inside_0.95R_distension_change": change_inside,
            "energy_with_potential_drift": drift / abs(sim.gravity.potential_energy)}


def cold(porosity: dict) -> dict:
    """The body's centre carrying p(0) cold, on its compaction curve (module docstring)."""
    spec = {**BASALT, "porosity": porosity}
    eos = pack_eos([spec])
    row = pack_porosity([spec], eos)[0]
    rho00 = RHO_SOLID / ALPHA0
    central = float(lithostatic_pressure(rho00, RADIUS, 0.0))

    def cold_pressure(strain):
        alpha = distension_of_strain(row, strain)
        matrix_density = alpha * rho00 * np.exp(-strain)
        return pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, matrix_density, 0.0)[0] / alpha

    strain = brentq(lambda x: cold_pressure(x) - central, -0.3, porosity["eps_e"])
    return {"central_pressure": central, "elastic_limit_pressure": cold_pressure(porosity["eps_e"]),
            "strain": strain, "distension": distension_of_strain(row, strain),
            "bulk_density_rise": float(np.expm1(-strain)),
            "central_energy": energy_from_pressure(eos.kind[0], eos.params[0], eos.table, RHO_SOLID,
                                                   ALPHA0 * central)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    parser.add_argument("--cells", type=int, nargs="+", default=[32, 64], help="cells per radius")
    args = parser.parse_args()
    result = {f"{name}, r-z {cells}": at_rest(material, cells)
              for name, material in BODIES.items() for cells in args.cells}
    result.update({f"{name}, cold": cold(porosity) for name, porosity in POROSITY.items()})
    print(json.dumps(result, indent=1) if args.json else result)


if __name__ == "__main__":
    main()
