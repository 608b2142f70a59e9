"""Noh implosion: stable to the end, shocked plateau and wall heating against the exact solution."""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.exact.noh import noh_shock_speed, noh_solution

GAS = {"gas": {"eos": {"model": "ideal_gas", "gamma": 5.0 / 3.0, "cv": 718.0}}}


@pytest.mark.parametrize("geometry, nu, cells", [("1d-planar", 1, 200), ("2d-cylindrical", 3, 64)])
def test_noh_runs_and_matches_plateau(geometry, nu, cells):
    end_time = 0.6
    sim = PROBLEMS["noh"].setup({"cells": cells, "end_time": end_time}, GAS, geometry=geometry)
    sim.run(end_time)
    snap = sim.snapshot()
    r = np.sqrt((snap.centers**2).sum(axis=1))
    rho = snap.density.reshape(-1)
    rho_exact, _, _ = noh_solution(r, end_time, 5.0 / 3.0, nu)
    shock = noh_shock_speed(5.0 / 3.0, 1.0) * end_time
    plateau = (r > 0.4 * shock) & (r < 0.8 * shock)
    error = np.abs(rho[plateau] / rho_exact[plateau] - 1.0)
    # r-z spherical case: the zero-gradient outer boundary misses the (1 + u0 t / r)^2 growth
    # of the inflow density, so the plateau is looser at 64 cells
    assert np.median(error) < (0.02 if nu == 1 else 0.15)
    # wall heating: a density deficit next to the origin (measured, documented in docs/hydro.md)
    centre = r < 2.5 * sim.mesh.min_cell_size()
    deficit = 1.0 - rho[centre].mean() / rho_exact[centre].mean()
    assert 0.0 < deficit < 0.6
    # the cold inflow (e / u^2 ~ 1e-6) needs internal-energy floors; they add a negligible energy
    assert sim.floor_amounts["energy_added_by_floors"] < 1e-6 * sim.totals()["energy_with_outflow"]
