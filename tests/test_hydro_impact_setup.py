"""The `impact` problem setup: two touching spheres in r-z with void around."""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.problems.common import preset_material

MATERIALS = {"basalt": preset_material("basalt"), "iron": preset_material("iron")}


@pytest.mark.parametrize("projectile", ["basalt", "iron"])
def test_impact_setup_masses_and_velocity(projectile):
    params = {"target": {"material": "basalt", "radius": 500.0},
              "projectile": {"material": projectile, "radius": 100.0, "velocity": 2000.0},
              "cells_per_projectile_radius": 10}
    sim = PROBLEMS["impact"].setup(params, MATERIALS)
    assert sim.mesh.geometry == "2d-cylindrical"
    totals = sim.totals()
    rho_p = MATERIALS[projectile]["eos"]["rho0"]
    m_target = 4.0 / 3.0 * np.pi * 500.0**3 * 2700.0
    m_projectile = 4.0 / 3.0 * np.pi * 100.0**3 * rho_p
    assert totals["material_mass"][0] == pytest.approx(m_target, rel=0.01)
    assert totals["material_mass"][1] == pytest.approx(m_projectile, rel=0.02)
    # every cell holding projectile material moves with the projectile (target material in
    # the few shared cells at the contact point included), the rest is at rest
    snap = sim.snapshot()
    cell_mass = snap.partial_density.sum(axis=1) * snap.block_cell_volumes()
    moving = snap.volume_fraction[:, 1] > 0.0
    assert totals["momentum"][1] == pytest.approx(-2000.0 * cell_mass[moving].sum(), rel=1e-12)
    assert sim.material_names[1].startswith(projectile)
    # void around the bodies: the domain corner is empty
    assert snap.volume_fraction.sum(axis=1).min() == 0.0


def test_bodies_at_rest_stay_at_rest_next_to_void():
    params = {"target": {"material": "basalt", "radius": 500.0},
              "projectile": {"material": "basalt", "radius": 100.0, "velocity": 0.0},
              "cells_per_projectile_radius": 10}
    sim = PROBLEMS["impact"].setup(params, MATERIALS)
    start = sim.totals()
    sim.run(1.0, max_steps=200)
    snap = sim.snapshot()
    filled = snap.volume_fraction.sum(axis=1) > 1e-6
    assert np.abs(snap.velocity[:, :2].transpose(1, 0, 2, 3, 4)[:, filled]).max() < 1e-6
    assert np.abs(snap.pressure).max() < 1e-3
    assert np.allclose(sim.totals()["material_mass"], start["material_mass"], rtol=1e-12)
