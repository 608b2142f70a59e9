"""The last-good state (hydro/solver.py ``restore_last_good``): the state is copied every
LAST_GOOD_INTERVAL steps, and a restore copies it back and takes the steps since again.  After a
restore every array, counter, tracer record and the clock must be those of the start of the last
step, bit for bit, at every distance from the last copy."""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS, BlockMesh, HydroState, Simulation
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.problems import column_collapse
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.solver import LAST_GOOD_INTERVAL
from impactpipe.hydro.tracers.motion import Tracers
from impactpipe.pipeline.presets import resolve_damage, resolve_strength

GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}


def gas_box() -> Simulation:
    mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [1.0, 1.0], [32, 32], [("periodic", "periodic")] * 2, 16)
    eos = pack_eos([GAS])
    c = mesh.cell_centers()
    state = HydroState.empty(mesh, 1)
    rho = 1.0 + 0.3 * np.sin(2 * np.pi * c[:, 0]) * np.cos(2 * np.pi * c[:, 1])
    vel = np.stack([0.3 + 0.2 * np.sin(2 * np.pi * c[:, 1]), -0.1 + 0.2 * np.cos(2 * np.pi * c[:, 0]),
                    np.zeros_like(c[:, 0])], axis=1)
    state.set_material(mesh, 1.0, 0, eos, rho, vel, pressure=1.0)
    return Simulation(mesh, ["gas"], [GAS], state)


def fracturing_impact() -> Simulation:
    """A coarse basalt impact in r-z with GEO strength, Grady-Kipp fracture and tracers with a history."""
    basalt = preset_material("basalt")
    basalt["strength"] = resolve_strength("geo", "strong", {})
    basalt["strength"]["damage"] = resolve_damage({"model": "grady_kipp", "preset": "basalt"})
    params = {"target": {"material": "basalt", "radius": 1000.0},
              "projectile": {"material": "basalt", "radius": 250.0, "velocity": 2000.0},
              "cells_per_projectile_radius": 6}
    sim = PROBLEMS["impact"].setup(params, {"basalt": basalt})
    rng = np.random.default_rng(5)
    radius = 1000.0 * np.sqrt(rng.uniform(0.0, 1.0, 200))
    angle = rng.uniform(-np.pi / 2, np.pi / 2, 200)
    sim.tracers = Tracers(np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1),
                          np.zeros(200, dtype=int), history_interval=2.0e-3, end_time=1.0)
    return sim


def collapsing_column() -> Simulation:
    """A granular column under gravity: strength, a gravity kick and its work, a frictional floor."""
    sand = preset_material("basalt")
    sand["strength"] = {"model": "geo", "Y0": 0.0, "Y_M": 1.0e12, "Y_T": 0.0, "mu_i": float(np.tan(np.radians(25.0))),
                        "poisson": 0.3, "T_melt": 1474.0, "xi": 1.2}
    return column_collapse.setup({"material": "sand", "height": 1.0, "width": 1.0, "cells_per_height": 8},
                                 {"sand": sand}, cfl=0.4)


SCENES = {"gas box": gas_box, "fracturing impact with tracers": fracturing_impact, "column": collapsing_column}


def everything(sim: Simulation) -> dict:
    """The interior cells of the state (the ghosts are filled before each use), the counters, the
    clock and the tracers' records, as bytes."""
    out = {name: np.ascontiguousarray(sim.mesh.interior(arr)).tobytes() for name, arr in sim.state.arrays().items()}
    out.update({f"counter {k}": a.tobytes() for k, a in enumerate(sim._counter_arrays())})
    out["clock"] = np.array([sim.time, sim.step_count, sim.cell_updates, sim.last_dt]).tobytes()
    if sim.gravity is not None:
        out["gravity work"] = np.float64(sim.gravity.work).tobytes()
    if sim.tracers is not None:
        for name in sim.tracers._MUTABLE:
            out[f"tracers {name}"] = getattr(sim.tracers, name).tobytes()
        out["tracer history"] = np.array([sim.tracers.history_count, sim.tracers.history_next]).tobytes()
    return out


@pytest.mark.parametrize("scene", SCENES)
def test_a_restore_gives_the_start_of_the_last_step_bit_for_bit_at_every_distance_from_the_copy(scene):
    sim = SCENES[scene]()
    assert sim._last_good_interval() == LAST_GOOD_INTERVAL > 1
    expected = [everything(sim)]
    for _ in range(LAST_GOOD_INTERVAL + 3):
        sim.step()
        expected.append(everything(sim))
    # from a copy one step back, from copies taken 2 .. LAST_GOOD_INTERVAL steps back
    for back in (LAST_GOOD_INTERVAL + 3, LAST_GOOD_INTERVAL, 2, 1):
        twin = SCENES[scene]()
        for _ in range(back):
            twin.step()
        twin.restore_last_good()
        assert twin.step_count == back - 1
        got = everything(twin)
        assert got.keys() == expected[back - 1].keys()
        for key in got:
            assert got[key] == expected[back - 1][key], (back, key)


def test_a_restore_after_an_output_time_lands_where_the_run_landed():
    """run() sets the clock to each output time it lands on; the steps taken again do too."""
    sim = gas_box()
    probe = gas_box()
    probe.run(np.inf, max_steps=3)
    output = 0.5 * (probe.time + probe._replay[1][1])  # inside the third step: it is shortened to land there
    sim.run(np.inf, output_times=[output], max_steps=5)
    reference = gas_box()
    reference.run(np.inf, output_times=[output], max_steps=4)
    sim.restore_last_good()
    assert everything(sim) == everything(reference)


def test_the_copy_is_taken_every_step_where_a_step_is_taken_again_from_it():
    sim = gas_box()
    sim.time_stepping = "per_level"
    assert sim._last_good_interval() == 1


def test_a_restore_forgets_the_strength_work_of_the_steps_it_undoes():
    """The steps taken again pass over the blocks still void after their sweeps without a look
    (strength.update.cell_velocity_and_stress): their work arrays must hold what those steps
    left there, zeros, not what the steps undone wrote (a block void at the copy may have
    filled since).  Stand-in for those: ones in every void block's work arrays."""
    reference = fracturing_impact()
    for _ in range(4):
        reference.step()
    sim = fracturing_impact()
    for _ in range(5):
        sim.step()
    void = sim._void_now != 0
    assert void.any()
    sim.strength.work[void] = 1.0
    sim.restore_last_good()
    assert everything(sim) == everything(reference)
