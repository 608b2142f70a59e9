"""Planar Tillotson impacts against the impedance-matching solution."""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.exact.impedance import planar_impact_state
from impactpipe.hydro.problems.common import preset_material

MATERIALS = {"basalt": preset_material("basalt"), "iron": preset_material("iron")}


@pytest.mark.parametrize("flyer", ["basalt", "iron"])
def test_planar_impact_shocked_state(flyer):
    velocity = 2000.0
    end_time = 1.0e-4
    params = {"flyer": {"material": flyer, "velocity": velocity}, "target": {"material": "basalt"},
              "cells": 400, "end_time": end_time}
    sim = PROBLEMS["planar_impact"].setup(params, MATERIALS)
    start = sim.totals()
    sim.run(end_time)
    exact = planar_impact_state(MATERIALS[flyer]["eos"], MATERIALS["basalt"]["eos"], velocity)
    snap = sim.snapshot()
    x = snap.centers[:, 0]
    dx = x[1] - x[0]
    # plateau between the two shocks, away from the contact's mixed cells
    contact = exact.particle_velocity * end_time
    reach_target = (exact.target.shock_velocity - exact.particle_velocity) * end_time
    reach_flyer = (exact.flyer.shock_velocity - (velocity - exact.particle_velocity)) * end_time
    plateau = (x > contact - 0.6 * reach_flyer) & (x < contact + 0.6 * reach_target) & (np.abs(x - contact) > 3 * dx)
    assert plateau.sum() > 30
    pressure = snap.pressure.reshape(-1)[plateau]
    u = snap.velocity[:, 0].reshape(-1)[plateau]
    assert np.abs(pressure / exact.pressure - 1.0).max() < 0.02
    assert np.abs(u / exact.particle_velocity - 1.0).max() < 0.02
    end = sim.totals()
    assert np.allclose(end["material_mass"], start["material_mass"], rtol=1e-12)
    assert end["momentum"][0] == pytest.approx(start["momentum"][0], rel=1e-12)
