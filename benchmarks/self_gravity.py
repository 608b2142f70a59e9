"""Self-gravity in the hydro stage: accuracy of the multipole potential, a body at rest, cost.

    python benchmarks/self_gravity.py --json

1. ``sphere``: the potential of a uniform sphere (R = 1 km, centred 0.1 R off the mesh origin)
   against -G M (3 R^2 - r^2) / (2 R^3) inside and -G M / r outside: the largest relative
   error inside and outside, r-z at 64 and 3d at 32 cells per radius, order 4.
2. ``two_bodies``: a target (R) with a projectile (R / 4) touching it, r-z at 32 cells per
   radius, against the sum of the two exact potentials: mean and largest relative error in
   the target and in the projectile, per expansion order L = 0, 2, 4, 8.
3. ``hydrostatic``: the hydrostatic_body problem (a 50 km basalt sphere in equilibrium, order 4)
   over one sound-crossing time R / sqrt(A / rho0): the largest speed over v_esc in the cells at
   least half full (the surface's half-filled cells included) and inside 0.95 R, and the drift of
   E_mesh + W (W = (1/2) sum m Phi) over |W|; r-z at 32 and 64, 3d at 16 and 32 cells per radius.
4. ``cost``: one thread, ns per cell-update of the whole step and of the gravity in it (the
   step's sources) for the hydrostatic body, per order, r-z at 64 and 3d at 32 cells per radius.
"""

from __future__ import annotations

import argparse
import json
import time

import numba
import numpy as np

from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.problems import PROBLEMS
from impactpipe.hydro.problems.impact import sphere_fraction
from impactpipe.hydro.self_gravity import G, SelfGravity
from impactpipe.pipeline.presets import resolve_eos

BASALT = resolve_eos("tillotson", "basalt", {})
RHO0 = 2700.0


def body(geometry: str, cells_per_radius: int, radius: float, order: int = 4, margin_cells: int = 8):
    """The hydrostatic_body Simulation (its mesh reused for the potential checks)."""
    params = {"body": {"material": "basalt", "radius": radius}, "cells_per_radius": cells_per_radius,
              "order": order, "margin_cells": margin_cells}
    return PROBLEMS["hydrostatic_body"].setup(params, {"basalt": {"eos": BASALT}}, geometry=geometry)


def distance(mesh, centre) -> np.ndarray:
    c = mesh.cell_centers()
    if mesh.geometry == "2d-cylindrical":
        return np.sqrt(c[:, 0] ** 2 + (c[:, 1] - centre[2]) ** 2)
    return np.sqrt(sum((c[:, d] - centre[d]) ** 2 for d in range(3)))


def exact_sphere(r, radius):
    mass = 4.0 / 3.0 * np.pi * radius ** 3 * RHO0
    return np.where(r < radius, -G * mass * (3 * radius ** 2 - r ** 2) / (2 * radius ** 3), -G * mass / r)


def spheres_potential(mesh, spheres, order: int) -> np.ndarray:
    state = HydroState.empty(mesh, 1)
    fill = np.zeros((mesh.nblocks,) + mesh.interior_shape)
    for centre, radius in spheres:
        fill = np.maximum(fill, sphere_fraction(mesh, centre if mesh.geometry == "3d" else (0.0, centre[2]), radius,
                                                4))
    state.set_material(mesh, fill, 0, pack_eos([BASALT]), RHO0, np.zeros(3), specific_energy=0.0)
    gravity = SelfGravity(mesh, order=order, mirror_y=mesh.geometry == "3d")
    gravity.prepare(state, mesh)
    return gravity.potential(mesh)


def sphere_errors() -> dict:
    out = {}
    radius, centre = 1.0e3, (0.0, 0.0, 100.0)
    for geometry, cells in (("2d-cylindrical", 64), ("3d", 32)):
        mesh = body(geometry, cells, 1.3 * radius).mesh
        phi = spheres_potential(mesh, [(centre, radius)], 4)
        r = distance(mesh, centre)
        error = np.abs(phi / exact_sphere(r, radius) - 1.0)
        out[f"{geometry} {cells}"] = {"inside": float(error[r < radius].max()),
                                      "outside": float(error[(phi != 0.0) & (r > radius)].max())}
    return out


def two_body_errors() -> dict:
    target, projectile = ((0.0, 0.0, 0.0), 1.0e3), ((0.0, 0.0, 1.25e3), 0.25e3)
    mesh = body("2d-cylindrical", 32, 1.5e3).mesh
    exact = sum(exact_sphere(distance(mesh, c), radius) for c, radius in (target, projectile))
    inside_target = distance(mesh, target[0]) < target[1]
    inside_projectile = distance(mesh, projectile[0]) < projectile[1]
    out = {}
    for order in (0, 2, 4, 8):
        error = np.abs(spheres_potential(mesh, [target, projectile], order) / exact - 1.0)
        out[order] = {"target_mean": float(error[inside_target].mean()), "target_max": float(error[inside_target].max()),
                      "projectile_mean": float(error[inside_projectile].mean()),
                      "projectile_max": float(error[inside_projectile].max())}
    return out


def hydrostatic() -> dict:
    out = {}
    radius = 50.0e3
    escape = np.sqrt(8.0 * np.pi * G * RHO0 / 3.0) * radius
    crossing = radius / np.sqrt(26.7e9 / RHO0)
    for geometry, cells in (("2d-cylindrical", 32), ("2d-cylindrical", 64), ("3d", 16), ("3d", 32)):
        sim = body(geometry, cells, radius)
        mesh, state = sim.mesh, sim.state
        r = distance(mesh, (0.0, 0.0, 0.0))
        sim.step()
        start = sim.totals()["energy"] + sim.gravity.potential_energy
        fastest = inside = 0.0
        while sim.time < crossing:
            sim.step()
            rho = mesh.interior(state.arho).sum(axis=1)
            speed = np.linalg.norm(mesh.interior(state.momentum), axis=1) / np.where(rho > 0.0, rho, 1.0)
            full = rho > 0.5 * RHO0
            fastest = max(fastest, float(speed[full].max()))
            inside = max(inside, float(speed[full & (r < 0.95 * radius)].max()))
        drift = sim.totals()["energy"] + sim.gravity.potential_energy - start
        out[f"{geometry} {cells}"] = {"steps": sim.step_count, "max_speed_over_escape": fastest / escape,
                                      "inside_0.95R_over_escape": inside / escape,
                                      "energy_with_potential_drift": drift / abs(sim.gravity.potential_energy)}
    return out


def cost() -> dict:
    numba.set_num_threads(1)
    out = {}
    for geometry, cells in (("2d-cylindrical", 64), ("3d", 32)):
        for order in (0, 4, 8):
            sim = body(geometry, cells, 50.0e3, order)
            sim.step()
            sim.step()
            spent = {"sources": 0.0}
            last = [time.perf_counter()]

            def observe(event, axis, spent=spent, last=last):
                now = time.perf_counter()
                if event == "sources":
                    spent["sources"] += now - last[0]
                last[0] = now

            sim.observer = observe
            steps = 10
            started = time.perf_counter()
            for _ in range(steps):
                sim.step()
            wall = time.perf_counter() - started
            updates = steps * sim.mesh.ncells
            out[f"{geometry} {cells} L={order}"] = {"step_ns": 1e9 * wall / updates,
                                                   "gravity_ns": 1e9 * spent["sources"] / updates,
                                                   "gravity_share": spent["sources"] / wall}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    args = parser.parse_args()
    result = {"sphere": sphere_errors(), "two_bodies": two_body_errors(), "hydrostatic": hydrostatic(),
              "cost": cost()}
    print(json.dumps(result, indent=1) if args.json else result)


if __name__ == "__main__":
    main()
