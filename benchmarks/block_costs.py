"""Cost of a block's step by what it holds: void, full of material, or both (the weights MPI ranks cut by).

The MPI ranks share the blocks by an estimated cost per block
(:mod:`impactpipe.hydro.parallel.decomposition`): ``MATERIAL_CELL_COST`` per interior cell
holding material, ``VOID_CELL_COST`` per void cell, ``MIXED_BLOCK_CELL_COST`` more per cell of
a block holding both.  This measures what they cost: it builds a case
of benchmarks/hydro_throughput.py, takes two steps, sorts the blocks into void (no cell with
material), full (every cell) and mixed, and times on one thread the per-block kernels of a step
on copies of each class's blocks: the time-step kernel and the two sweeps, and with strength
the stress step's kernels (cell velocities and stress, two kicks, velocities, stress update).
Ghost fills are left out (they cost the same for every block).  Prints ns per cell-update of
each class and the ratio full / void:

    NUMBA_NUM_THREADS=1 python benchmarks/block_costs.py --cases 2d-cyl-tillotson 2d-cyl-strength --json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from hydro_throughput import build  # noqa: E402

from impactpipe.hydro.mesh.boundary import NO_RECORD  # noqa: E402
from impactpipe.hydro.mesh.scalar_stamps import NO_STAMPS  # noqa: E402
from impactpipe.hydro.scheme.directional import sweep  # noqa: E402
from impactpipe.hydro.scheme.timestep import PHI_VOID, max_signal_rate  # noqa: E402
from impactpipe.hydro.strength.divergence import apply_stress_divergence  # noqa: E402
from impactpipe.hydro.strength.update import cell_velocities, cell_velocity_and_stress, update_stress  # noqa: E402

REPEATS = 5


def classes(sim) -> dict[str, np.ndarray]:
    """Block indices of the void, full and mixed blocks (by interior cells with phi >= PHI_VOID)."""
    phi = sim.mesh.interior(sim.state.alpha).sum(axis=1).reshape(sim.mesh.nblocks, -1)
    material = (phi >= PHI_VOID).sum(axis=1)
    cells = phi.shape[1]
    return {"void": np.flatnonzero(material == 0), "full": np.flatnonzero(material == cells),
            "mixed": np.flatnonzero((material > 0) & (material < cells))}


def block_step_seconds(sim, blocks: np.ndarray, dt: float) -> float:
    """Best of REPEATS wall times of the per-block kernels of one step on copies of ``blocks``."""
    st, mesh, eos = sim.state, sim.mesh, sim.eos
    best = np.inf
    for _ in range(REPEATS):
        alpha, arho, arhoe, arhoq, mom, energy = (a[blocks].copy() for a in (st.alpha, st.arho, st.arhoe, st.arhoq,
                                                                          st.momentum, st.energy))
        lo, dx, nbr, nlev = (mesh.block_lo[blocks], mesh.block_dx[blocks], mesh.neighbor[blocks],
                             mesh.neighbor_level[blocks])
        rates = np.zeros(len(blocks))
        counters = [c[blocks].copy() for c in (sim.boundary, sim.floors, sim.amounts, sim._failure)]
        counters.append(sim._face_flux[blocks].copy() if len(sim._face_flux) else sim._face_flux)
        work = None if sim.strength is None else sim.strength.work[blocks].copy()
        started = time.perf_counter()
        max_signal_rate(alpha, arho, arhoe, mom, dx, eos.kind, eos.params, eos.table, sim.shear_modulus, mesh.ndim,
                        sim._rate_work, rates)
        for axis in range(mesh.ndim):
            sweep(axis, dt, mesh.geometry_code, alpha, arho, arhoe, arhoq, mom, energy, lo, dx, nbr, nlev, eos.kind,
                  eos.params, eos.table, sim.shear_modulus, sim.tensile_strength, sim._scratch, *counters,
                  sim.plain_pencils, np.arange(len(blocks)), NO_RECORD, NO_RECORD, NO_STAMPS[0],
                  sim._sweep_grady_kipp, sim._sweep_porosity, sim.bulk_pressure_predictor)
        if work is not None:
            strength = sim.strength
            a = strength.arrays
            rho0 = strength._reference_densities(eos)
            face = strength.face_flux[:, blocks].copy() if strength.face_flux.shape[1] else strength.face_flux
            gravity = np.zeros(0) if strength.surface_gravity is None else strength.surface_gravity
            copies = np.arange(len(blocks), dtype=np.int64)
            holds, has_mass, stressed = (np.zeros(len(blocks), dtype=np.uint8) for _ in range(3))
            cell_velocity_and_stress(alpha, arho, arhoq, mom, rho0, a.model, strength.ns, work, copies, holds,
                                     has_mass, stressed, np.zeros(0, dtype=np.uint8))
            apply_stress_divergence(dt / 2, mesh.geometry_code, mesh.ndim, mom, energy, lo, dx, nbr, nlev, work,
                                    counters[0], face, 3 * strength.nmat, copies, stressed)
            cell_velocities(arho, mom, work, copies, np.zeros(0, dtype=np.uint8))
            update_stress(dt, mesh.geometry_code, mesh.ndim, alpha, arho, arhoe, arhoq, lo, dx, eos.kind, eos.params,
                          eos.table, rho0, a.model, a.params, a.shear, a.tensile_strength, work,
                          strength.counts[blocks].copy(), strength.amounts[blocks].copy(), copies,
                          strength.damage.model, strength.damage.params, gravity, strength._porosity_rows, has_mass,
                          stressed, strength.face is not None, np.zeros(0, dtype=np.uint8), NO_STAMPS[0])
            apply_stress_divergence(dt / 2, mesh.geometry_code, mesh.ndim, mom, energy, lo, dx, nbr, nlev, work,
                                    counters[0], face, 3 * strength.nmat, copies, stressed)
        best = min(best, time.perf_counter() - started)
    return best


def measure(case: str) -> dict:
    """ns per cell-update of each block class of ``case`` and the full / void ratio."""
    sim = build(case, quick=False)
    for _ in range(2):
        sim.step()
    dt = sim.last_dt
    cells = int(np.prod(sim.mesh.interior_shape))
    out = {"case": case, "blocks": {}, "ns_per_cell_update": {}}
    for name, blocks in classes(sim).items():
        out["blocks"][name] = int(len(blocks))
        if len(blocks):
            block_step_seconds(sim, blocks[:1], dt)  # compile
            out["ns_per_cell_update"][name] = 1e9 * block_step_seconds(sim, blocks, dt) / (len(blocks) * cells)
    ns = out["ns_per_cell_update"]
    if ns.get("void"):
        out["full_over_void"] = ns["full"] / ns["void"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", nargs="*", default=["2d-cyl-tillotson", "2d-cyl-strength"],
                        choices=["2d-cyl-tillotson", "2d-cyl-strength"])
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    args = parser.parse_args()
    numba.set_num_threads(1)
    results = [measure(case) for case in args.cases]
    if args.json:
        print(json.dumps({"results": results}, indent=2))
    else:
        for r in results:
            print(r["case"], r["blocks"], {k: round(v, 1) for k, v in r["ns_per_cell_update"].items()},
                  f"full/void {r.get('full_over_void', float('nan')):.2f}")


if __name__ == "__main__":
    main()
