"""Hydro throughput: cell-updates per second (one cell advanced one full step) and memory.

Cases:
  2d-ideal-gas       2d-planar periodic box, one ideal gas, smooth flow (512^2; --quick 256^2)
  2d-cyl-tillotson   2d-cylindrical two-material Tillotson impact with void: the `impact`
                     problem (250 m basalt projectile at 2 km/s on a 1 km basalt target),
                     timed from first contact (~544 x 784 cells; --quick ~144 x 208)
  2d-cyl-strength    the same impact with GEO 'strong' strength in both bodies (the cost of
                     strength is the ratio of its rate to 2d-cyl-tillotson's; the ratio is
                     reported as strength_cost_ratio)
  2d-cyl-fracture    the same impact with GEO 'strong' strength and Grady-Kipp fracture
                     (the basalt Weibull preset) in both bodies (its rate over
                     2d-cyl-strength's, instant failure, is reported as fracture_cost_ratio)
  3d-two-material    3d periodic box, two ideal gases (a dense sphere), 128^3 (--quick 48^3)

The box cases take a uniform mesh's default blocks (64^2 and 16^3 at full size, 32^2 and 8^3
with --quick; --block-cells sets another edge); the impacts keep 16^2 blocks, their hand-off
particles.

Each case runs with 1 and 2 numba threads after a warm-up step (kernels come from the
numba cache) and ``--settle N`` more untimed steps (default 0: the impacts are timed from
first contact, when most of the target has not yet felt the shock; with N of a few hundred
the window lies later in the run, when the target carries stress), then two more steps
traced for memory, then the timed steps, untraced.  Memory: peak bytes of
traced allocations (tracemalloc, numpy arrays of the state, its last-good copy, scratch and
snapshots) per interior cell: ``peak_bytes_per_cell`` over the whole measurement, the setup
of the initial state included, and ``step_peak_bytes_per_cell`` over the two traced steps alone
(what a long run holds).

With ``--reference SCRIPT`` a reference kernel (a script that takes the mesh size N and prints
``cell-updates/s: X``, such as a naive one-stage PLM + HLLC kernel on an N^2 box) runs right
before each measurement with the same number of threads (NUMBA_NUM_THREADS), and each result
carries ``reference_cell_updates_per_s`` and ``ratio_to_reference``: a ratio taken in one job
is the figure to compare between machines and runs, not the absolute rate.

    python benchmarks/hydro_throughput.py --json [--quick] [--steps N] [--settle N] [--reference SCRIPT]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
import tracemalloc

import numba
import numpy as np

from impactpipe.hydro import PROBLEMS, BlockMesh, HydroState, Simulation
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.problems.common import preset_material
from impactpipe.pipeline.presets import resolve_damage, resolve_strength

GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}
HEAVY = {"model": "ideal_gas", "gamma": 1.6, "cv": 300.0}

#: Steps traced for the memory held while stepping, before the timed (untraced) steps.
MEMORY_STEPS = 2


def _smooth_box(geometry, cells, block_cells, nmat, swap_axes=False):
    """The box cases' smooth periodic flow; ``swap_axes``: the same flow with x and y exchanged
    (its density and velocity fields mirrored in the diagonal), for benchmarks/sweep_axes.py."""
    ndim = len(cells)
    mesh = BlockMesh.uniform(geometry, [0.0] * ndim, [1.0] * ndim, cells, [("periodic", "periodic")] * ndim,
                             block_cells)
    specs = [GAS, HEAVY][:nmat]
    eos = pack_eos(specs)
    c = mesh.cell_centers()
    x, y = (c[:, 1], c[:, 0]) if swap_axes else (c[:, 0], c[:, 1])
    state = HydroState.empty(mesh, nmat)
    rho = 1.0 + 0.3 * np.sin(2 * np.pi * x) * np.cos(2 * np.pi * y)
    along_x, along_y = 0.3 + 0.2 * np.sin(2 * np.pi * y), -0.1 + 0.2 * np.cos(2 * np.pi * x)
    if swap_axes:
        along_x, along_y = along_y, along_x
    vel = np.stack([along_x, along_y, np.zeros_like(x)], axis=1)
    del along_x, along_y
    state.set_material(mesh, 1.0, 0, eos, rho, vel, pressure=1.0)
    if nmat == 2:
        sphere = ((c - 0.5) ** 2).sum(axis=1) < 0.06
        state.set_material(mesh, sphere.astype(float), 1, eos, 20.0 * rho, vel, pressure=1.0)
    return Simulation(mesh, ["gas", "heavy"][:nmat], specs, state)


def build(case: str, quick: bool, block_cells: int | None = None, comm=None) -> Simulation:
    """The Simulation of a benchmark case; ``block_cells`` replaces the box cases' block edge (by
    default the mesh's own, :func:`impactpipe.hydro.mesh.blocks.uniform_block_cells`: 64 for the 2D
    box at 512^2 and 32 at 256^2, 16 for the 3D box at 128^3 and 8 at 48^3); ``comm``: the MPI
    ranks that build an impact case together, each its own blocks, as ``impactpipe run`` does
    (collective; this rank's share of the run)."""
    if case == "2d-ideal-gas":
        n = 256 if quick else 512
        return _smooth_box("2d-planar", [n, n], block_cells, 1)
    if case in ("2d-cyl-tillotson", "2d-cyl-strength", "2d-cyl-fracture"):
        materials = {"basalt": preset_material("basalt")}
        if case != "2d-cyl-tillotson":
            materials["basalt"]["strength"] = resolve_strength("geo", "strong", {})
        if case == "2d-cyl-fracture":
            materials["basalt"]["strength"]["damage"] = resolve_damage({"model": "grady_kipp", "preset": "basalt"})
        params = {"target": {"material": "basalt", "radius": 1000.0},
                  "projectile": {"material": "basalt", "radius": 250.0, "velocity": 2000.0},
                  "cells_per_projectile_radius": 25 if quick else 100}
        return PROBLEMS["impact"].setup(params, materials, comm=comm)
    if case == "3d-two-material":
        n = 48 if quick else 128
        return _smooth_box("3d", [n, n, n], block_cells, 2)
    raise ValueError(f"unknown case {case!r}")


def measure(case: str, quick: bool, steps: int, threads: int, block_cells: int | None = None,
            settle: int = 0) -> dict:
    """Cell-updates per second of ``steps`` steps with ``threads`` numba threads, after a warm-up
    step, ``settle`` untimed steps and MEMORY_STEPS traced ones.  Memory is traced (tracemalloc)
    from the construction through the traced steps only: tracing every allocation slows the
    Python side of a step, so the timed steps run untraced, like the reference kernel."""
    numba.set_num_threads(threads)
    tracemalloc.start()
    sim = build(case, quick, block_cells)
    for _ in range(1 + settle):
        sim.step()
    _, setup_peak = tracemalloc.get_traced_memory()
    tracemalloc.reset_peak()
    for _ in range(MEMORY_STEPS):
        sim.step()
    _, step_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    start_updates = sim.cell_updates
    t0 = time.perf_counter()
    for _ in range(steps):
        sim.step()
    wall = time.perf_counter() - t0
    return {
        "case": case,
        "threads": threads,
        "cells": sim.mesh.ncells,
        "blocks": sim.mesh.nblocks,
        "steps": steps,
        "settle_steps": settle,
        "time_s": sim.time,
        "wall_s": wall,
        "cell_updates_per_s": (sim.cell_updates - start_updates) / wall,
        "peak_bytes_per_cell": max(setup_peak, step_peak) / sim.mesh.ncells,
        "step_peak_bytes_per_cell": step_peak / sim.mesh.ncells,
        "floors": sim.floor_counts,
    }


def reference_rate(script: str, size: int, threads: int) -> float:
    """Cell-updates/s printed by the reference kernel ``script`` at size N = ``size`` on ``threads`` threads."""
    env = {**os.environ, "NUMBA_NUM_THREADS": str(threads)}
    out = subprocess.run([sys.executable, script, str(size)], env=env, capture_output=True, text=True, check=True)
    match = re.search(r"cell-updates/s:\s*([0-9.eE+-]+)", out.stdout)
    if match is None:
        raise RuntimeError(f"{script} printed no 'cell-updates/s: X': {out.stdout!r}")
    return float(match.group(1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    parser.add_argument("--quick", action="store_true", help="smaller meshes")
    parser.add_argument("--steps", type=int, default=10, help="timed steps per case (default 10)")
    parser.add_argument("--settle", type=int, default=0,
                        help="untimed steps after the warm-up step, to time a later window of the run (default 0)")
    parser.add_argument("--cases", nargs="*",
                        default=["2d-ideal-gas", "2d-cyl-tillotson", "2d-cyl-strength", "3d-two-material"],
                        help="cases to run (also 2d-cyl-fracture)")
    parser.add_argument("--reference", metavar="SCRIPT", help="reference kernel run before each measurement")
    parser.add_argument("--reference-size", type=int, default=512, help="its mesh size N (default 512)")
    parser.add_argument("--block-cells", type=int, help="block edge of the box cases (default: the uniform mesh's own)")
    args = parser.parse_args()
    results = []
    for case in args.cases:
        for threads in (1, 2):
            if threads > numba.config.NUMBA_NUM_THREADS:
                continue
            reference = reference_rate(args.reference, args.reference_size, threads) if args.reference else None
            result = measure(case, args.quick, args.steps, threads, args.block_cells, args.settle)
            if reference is not None:
                result["reference_cell_updates_per_s"] = reference
                result["ratio_to_reference"] = result["cell_updates_per_s"] / reference
            results.append(result)
    for case in args.cases:
        rates = {r["threads"]: r["cell_updates_per_s"] for r in results if r["case"] == case}
        if 1 in rates and 2 in rates:
            for r in results:
                if r["case"] == case and r["threads"] == 2:
                    r["speedup_2_threads"] = rates[2] / rates[1]
    plain = {r["threads"]: r["cell_updates_per_s"] for r in results if r["case"] == "2d-cyl-tillotson"}
    instant = {r["threads"]: r["cell_updates_per_s"] for r in results if r["case"] == "2d-cyl-strength"}
    for r in results:
        if r["case"] == "2d-cyl-strength" and r["threads"] in plain:
            r["strength_cost_ratio"] = plain[r["threads"]] / r["cell_updates_per_s"]
        if r["case"] == "2d-cyl-fracture" and r["threads"] in instant:
            r["fracture_cost_ratio"] = instant[r["threads"]] / r["cell_updates_per_s"]
    report = {"load_average": os.getloadavg(), "cpu_count": os.cpu_count(), "results": results}
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        for r in results:
            ratio = f"  {r['ratio_to_reference']:.2f}x the reference" if "ratio_to_reference" in r else ""
            print(f"{r['case']:18s} threads={r['threads']} cells={r['cells']:9d} "
                  f"{r['cell_updates_per_s']:.3e} cell-updates/s  {r['peak_bytes_per_cell']:.0f} B/cell{ratio}")


if __name__ == "__main__":
    main()
