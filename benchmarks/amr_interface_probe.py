"""Where a moving interface loses pressure equilibrium: max |p - 1| across each sweep, reflux and regrid.

The scene of tests/test_hydro_amr.py::test_moving_interface_crosses_level_boundaries_at_uniform_pressure_and_velocity
(a disc 1e3 times denser than the gas around it, advected diagonally through a periodic box
at p = 1), on the adaptive mesh (32^2 root cells, 2 more levels) or, with ``--uniform``, on
the uniform 128^2 mesh of its finest cells.  Each call of ``sweep``, ``reflux`` and
``Simulation.regrid`` is wrapped: max |p - 1| over the mesh before and after it, and the
increases are summed per operation; the largest increase of max |sum_k alpha_k - 1| (how
far a call leaves cells over- or under-full) is kept per operation; ``--every N`` also prints
max |p - 1|, max |u - u0| and the heavy material's max |p_k - 1| in the cells it fills
1e-4 to 0.1 of every N steps (docs/hydro.md, "Moving interfaces across level
faces"):

    NUMBA_NUM_THREADS=1 python benchmarks/amr_interface_probe.py --steps 1600 --every 100 [--uniform]
"""

import argparse

import numpy as np

import impactpipe.hydro.solver as solver
from impactpipe.hydro import BlockMesh, HydroState, Simulation
from impactpipe.hydro.amr.regrid import RefinementRule
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.mesh.blocks import GHOST

GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}
HEAVY = {"model": "ideal_gas", "gamma": 1.6, "cv": 300.0}
VELOCITY = np.array([1.0, 0.5, 0.0])


def build(uniform: bool) -> Simulation:
    """The test's disc scene, adaptive (32^2, max level 2) or uniform at the finest cells (128^2)."""
    periodic = [("periodic", "periodic")] * 2
    if uniform:
        mesh = BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [128, 128], periodic, 8)
    else:
        mesh = BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [32, 32], periodic, 8, max_level=2)
    eos = pack_eos([GAS, HEAVY])
    state = HydroState.empty(mesh, 2)
    c = mesh.cell_centers()
    u0 = VELOCITY
    state.set_material(mesh, 1.0, 0, eos, 1.0, u0, pressure=1.0)
    disc = (((c[:, 0] - 0.3) ** 2 + (c[:, 1] - 0.3) ** 2) < 0.02).astype(float)
    state.set_material(mesh, disc, 1, eos, 1000.0, u0, pressure=1.0)
    refinement = None if uniform else RefinementRule(interval=2)
    return Simulation(mesh, ["gas", "heavy"], [GAS, HEAVY], state, refinement=refinement)


def wisp_pressure_error(sim: Simulation) -> float:
    """max |p_k - 1| of the heavy material, p_k = (gamma - 1) (alpha rho e)_k / alpha_k, over the
    cells it fills 1e-4 to 0.1 of (the wisps at the disc's edge); 0 when there are none."""
    inner = (slice(None), 1, slice(GHOST, -GHOST), slice(GHOST, -GHOST), slice(None))
    alpha, energy = sim.state.alpha[inner], sim.state.arhoe[inner]
    wisps = (alpha > 1e-4) & (alpha < 0.1)
    if not wisps.any():
        return 0.0
    return float(np.abs((HEAVY["gamma"] - 1.0) * energy[wisps] / alpha[wisps] - 1.0).max())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--uniform", action="store_true", help="uniform 128^2 mesh instead of the adaptive one")
    parser.add_argument("--every", type=int, default=0, help="print max |p - 1| and |u - u0| every N steps")
    args = parser.parse_args()
    sim = build(args.uniform)
    increase = {"sweep": 0.0, "reflux": 0.0, "regrid": 0.0}
    fill_jump = {"sweep": 0.0, "reflux": 0.0, "regrid": 0.0}

    def error() -> float:
        return float(np.abs(sim.snapshot().pressure - 1.0).max())

    def fill_error() -> float:
        return float(np.abs(sim.snapshot().volume_fraction.sum(axis=1) - 1.0).max())

    def wrapped(name, function):
        def call(*a, **k):
            before, fill_before = error(), fill_error()
            out = function(*a, **k)
            increase[name] += max(error() - before, 0.0)
            fill_jump[name] = max(fill_jump[name], fill_error() - fill_before)
            return out
        return call

    solver.sweep = wrapped("sweep", solver.sweep)
    solver.reflux = wrapped("reflux", solver.reflux)
    Simulation.regrid = wrapped("regrid", Simulation.regrid)
    for step in range(1, args.steps + 1):
        sim.step()
        if args.every and step % args.every == 0:
            velocity = sim.snapshot().fields["velocity"]
            print(f"step {step} t = {sim.time:.3f}: max |p - 1| = {error():.1e}, "
                  f"max |u - u0| = {np.abs(velocity - VELOCITY[:2]).max():.1e}, "
                  f"wisps: max |p_heavy - 1| = {wisp_pressure_error(sim):.1e}")
    print(f"{'uniform 128^2' if args.uniform else 'adaptive'}: after {args.steps} steps max |p - 1| = {error():.3e}")
    print("summed increases of max |p - 1| by operation:", {k: f"{v:.2e}" for k, v in increase.items()})
    print("largest increase of max |sum_k alpha_k - 1| in one call, by operation:",
          {k: f"{v:.2e}" for k, v in fill_jump.items()})
    print("floors:", {k: v for k, v in sim.floor_counts.items() if v})


if __name__ == "__main__":
    main()
