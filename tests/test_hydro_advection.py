"""Smooth advection (second order) and material interfaces carried at uniform velocity and pressure."""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.problems import advection
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.problems.interface_advection import interface_width

GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}
MATERIALS = {"gas": {"eos": GAS}, "heavy": {"eos": GAS}, "light": {"eos": dict(GAS, gamma=1.67)},
             "basalt": preset_material("basalt"), "iron": preset_material("iron")}


def _advection_error(cells):
    sim = PROBLEMS["advection"].setup({"cells": cells}, MATERIALS)
    sim.run(1.0)
    snap = sim.snapshot()
    x = snap.centers[:, 0]
    dx = 1.0 / cells
    k = 2.0 * np.pi
    exact = 1.0 + 0.2 * (np.cos(k * (x - 0.5 * dx)) - np.cos(k * (x + 0.5 * dx))) / (k * dx)
    return np.abs(snap.density.reshape(-1) - exact).mean()


def test_smooth_advection_is_second_order():
    errors = [_advection_error(n) for n in (64, 128)]
    assert errors[1] < 5e-4
    assert np.log2(errors[0] / errors[1]) > 1.8


def test_advection_exact_density_helper():
    p = advection.merged(advection.DEFAULTS, {})
    assert advection.exact_density(p, np.array([0.25]), 1.0)[0] == pytest.approx(1.2)


@pytest.mark.parametrize(
    "inner, outer, pressure, velocity",
    [
        ({"material": "heavy", "density": 1000.0}, {"material": "light", "density": 1.0}, 1.0, 1.0),
        ({"material": "iron", "density": 7800.0}, {"material": "basalt", "density": 2700.0}, 0.0, 1000.0),
        ({"material": "basalt", "density": 2700.0}, None, 0.0, 1000.0),
    ],
    ids=["ideal-gas-ratio-1e3", "tillotson-iron-basalt", "tillotson-basalt-void"],
)
def test_interface_keeps_uniform_velocity_and_pressure(inner, outer, pressure, velocity):
    end_time = 0.37 / velocity  # a non-aligned position: the interface sits inside a cell
    params = {"inner": inner, "outer": outer, "pressure": pressure, "velocity": velocity, "end_time": end_time}
    sim = PROBLEMS["interface_advection"].setup(params, MATERIALS)
    start = sim.totals()
    sim.run(end_time)
    snap = sim.snapshot()
    filled = snap.volume_fraction.sum(axis=1) > 1e-6
    u = snap.velocity[:, 0][filled]
    assert np.abs(u / velocity - 1.0).max() < 1e-8
    assert np.abs(snap.velocity[:, 1:]).max() == 0.0
    # pressure relative to the stiffness of the materials present (rho c^2)
    stiffness = (snap.density * snap.sound_speed**2)[filled].max()
    assert np.abs(snap.pressure[filled] - pressure).max() < 1e-8 * stiffness
    # the slab material's density stays at its initial value in every cell holding it
    alpha = snap.volume_fraction[:, 0]
    held = alpha > 1e-3
    assert np.abs(snap.partial_density[:, 0][held] / alpha[held] / inner["density"] - 1.0).max() < 1e-8
    assert interface_width(sim) <= 2.0
    end = sim.totals()
    assert np.allclose(end["material_mass"], start["material_mass"], rtol=1e-12)
