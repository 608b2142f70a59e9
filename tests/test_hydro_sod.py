"""Sod's shock tube against the exact Riemann solution (ideal gas, gamma = 1.4)."""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.exact.riemann import exact_riemann

GAS = {"gas": {"eos": {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}}}
LEFT = (1.0, 0.0, 1.0)
RIGHT = (0.125, 0.0, 0.1)
T_END = 0.2


def _l1_density_error(cells, geometry="1d-planar"):
    sim = PROBLEMS["shock_tube"].setup({"cells": cells}, GAS, geometry=geometry)
    sim.run(T_END)
    snap = sim.snapshot()
    x = snap.centers[:, 0]
    rho_exact, _, _ = exact_riemann(x, T_END, 0.5, LEFT, RIGHT, 1.4)
    err = np.abs(snap.density.reshape(-1) - rho_exact).mean() / (LEFT[0] - RIGHT[0])
    return err, snap


def test_sod_1d_l1_error_and_convergence():
    err200, _ = _l1_density_error(200)
    err400, _ = _l1_density_error(400)
    assert err400 < 0.01
    order = np.log2(err200 / err400)
    assert 0.7 < order < 1.3


def test_sod_along_x_in_2d_matches_1d_and_is_uniform_across():
    err, snap = _l1_density_error(400, "2d-planar")
    assert err < 0.01
    rho = snap.density  # (NB, nx, ny, 1): every row across y identical
    assert np.abs(rho - rho[:, :, :1]).max() < 1e-12
    assert np.abs(snap.velocity[:, 1]).max() < 1e-12


@pytest.mark.parametrize("geometry", ["1d-planar", "3d"])
def test_sod_outflow_counters_balance(geometry):
    sim = PROBLEMS["shock_tube"].setup({"cells": 64, "length": 0.4, "interface": 0.2}, GAS, geometry=geometry)
    start = sim.totals()
    sim.run(0.2)  # waves leave through both ends
    end = sim.totals()
    assert end["outflow_mass"] != 0.0
    assert end["mass_with_outflow"] == pytest.approx(start["mass"], rel=1e-13)
    assert end["energy_with_outflow"] == pytest.approx(start["energy"], rel=1e-13)
    assert abs(end["momentum_with_outflow"][0] - start["momentum"][0]) < 1e-13 * start["energy"]
