"""The admissibility rules that let dilute, hot and tensile material run (docs/hydro.md, case 8c)."""

import numba
import numpy as np
import pytest

from impactpipe.hydro.eos import pack_eos, reference_density
from impactpipe.hydro.scheme.mixture import DISTENDED_FRACTION, material_state
from impactpipe.hydro.problems import PROBLEMS
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.scheme.timestep import allocate_rate_work, max_signal_rate
from impactpipe.hydro.eos import pressure_sound_speed

BASALT = preset_material("basalt")["eos"]


def basalt_state(rho, e, tensile_strength=1.0e5):
    eos = pack_eos([BASALT])
    return material_state(1.0, rho, rho * e, eos.kind[0], eos.params[0], eos.table, np.zeros(2), tensile_strength)


def test_intact_material_holds_its_tensile_strength():
    rho = 0.9 * BASALT["rho0"]
    eos = pack_eos([BASALT])
    p_eos = pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, rho, 0.0)[0]
    present, _, _, p, *_, limited = basalt_state(rho, 0.0)
    assert p_eos < -1.0e5 and limited and p == -1.0e5


def test_distended_material_holds_no_tension():
    """Below DISTENDED_FRACTION rho0 the solid's Y_T no longer applies: p_k >= 0."""
    rho = 0.99 * DISTENDED_FRACTION * BASALT["rho0"]
    present, _, _, p, *_, limited = basalt_state(rho, 0.0)
    assert limited and p == 0.0
    present, _, _, p, *_ = basalt_state(1.0e-3, 0.0)
    assert p == 0.0


def test_a_trace_material_does_not_set_the_time_step():
    """A 1e-10 volume fraction holding a round-off energy (e ~ 3e14 J/kg) beside a full cell
    of basalt: the signal speed is the mixture's, so the rate is basalt's c / dx."""
    eos = pack_eos([BASALT, BASALT])
    shape = (1, 2, 1, 1, 1)
    alpha = np.zeros(shape)
    arho = np.zeros(shape)
    arhoe = np.zeros(shape)
    alpha[0, 0] = 1.0
    arho[0, 0] = BASALT["rho0"]
    alpha[0, 1] = 1.004e-10
    arho[0, 1] = 9.75e-13
    arhoe[0, 1] = 301.0
    mom = np.zeros((1, 3, 1, 1, 1))
    out = np.zeros(1)
    dx = np.ones((1, 3))
    max_signal_rate(alpha, arho, arhoe, mom, dx, eos.kind, eos.params, eos.table, np.zeros((2, 2)), 1,
                    allocate_rate_work(numba.config.NUMBA_NUM_THREADS, (1, 1, 1)), out)
    c_basalt = np.sqrt(pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, BASALT["rho0"], 0.0)[1])
    assert out[0] == pytest.approx(c_basalt, rel=1e-6)


@pytest.mark.parametrize("velocity", [20.0e3, 30.0e3])
def test_vaporising_impact_runs_and_keeps_its_energy_budget(velocity):
    """A 20-30 km/s impact (Tillotson hot expanded branch) runs and its energy budget closes:
    mesh + outflow + counted removals within 2 % of the initial energy."""
    sim = PROBLEMS["impact"].setup(
        {"target": {"material": "basalt", "radius": 1000.0},
         "projectile": {"material": "basalt", "radius": 100.0, "velocity": velocity},
         "cells_per_projectile_radius": 2, "end_time": 0.1},
        {"basalt": preset_material("basalt")}, block_cells=8)
    start = sim.totals()
    sim.run(0.05)
    end = sim.totals()
    amounts = sim.floor_amounts
    counted = (amounts["energy_removed_by_void_cleanup"] + amounts["energy_removed_by_velocity_limit"]
               + amounts["energy_removed_by_energy_limit"] - amounts["energy_added_by_floors"])
    error = (end["energy"] + end["outflow_energy"] + counted - start["energy"]) / start["energy"]
    assert abs(error) < 1e-9, "every change of the total energy is counted"
    assert abs(counted) < 0.02 * start["energy"], "the counted fixes stay small"
    assert end["outflow_mass"] > 0.0, "vapour leaves the mesh and is counted"
