"""Moving head-on impacts in 2d-cylindrical run stably and conserve mass, with every fix counted."""

import numpy as np
import pytest

from impactpipe.hydro.problems import PROBLEMS
from impactpipe.hydro.problems.common import preset_material


def impact(velocity, strength=None):
    materials = {"basalt": preset_material("basalt")}
    if strength is not None:
        materials["basalt"]["strength"] = strength
    return PROBLEMS["impact"].setup(
        {"target": {"material": "basalt", "radius": 1000.0},
         "projectile": {"material": "basalt", "radius": 100.0, "velocity": velocity},
         "cells_per_projectile_radius": 4, "end_time": 1.0}, materials, block_cells=8)


@pytest.mark.parametrize("velocity", [10.0, 1000.0, 5000.0])
def test_impact_runs_and_conserves_mass(velocity):
    sim = impact(velocity)
    start = sim.totals()
    sim.run(0.2)
    end = sim.totals()
    snap = sim.snapshot()
    assert sim.time == pytest.approx(0.2)
    assert np.isfinite(snap.pressure).all() and np.isfinite(snap.velocity).all()
    removed = sim.floor_amounts["mass_removed_by_void_cleanup"] - sim.floor_amounts["mass_added_by_floors"]
    mass_error = (end["mass"] + end["outflow_mass"] + removed - start["mass"]) / start["mass"]
    assert abs(mass_error) < 1e-12
    assert sim.floor_amounts["mass_removed_by_void_cleanup"] < 1e-12 * start["mass"], "only round-off residue"
    speed = np.sqrt((snap.velocity ** 2).sum(axis=1))
    assert speed.max() <= 1.5 * velocity, "no material may outrun the impact by far"
    assert (snap.density >= 0).all() and (snap.specific_internal_energy >= 0).all()


def test_axial_momentum_is_conserved():
    sim = impact(1000.0)
    start = sim.totals()
    sim.run(0.1)
    end = sim.totals()
    counted = (sim.floor_amounts["momentum_removed_by_velocity_limit"]
               + sim.floor_amounts["momentum_removed_by_void_cleanup"])
    pz0 = start["momentum"][1]
    assert abs(end["momentum"][1] + end["outflow_momentum"][1] - pz0) <= 1e-9 * abs(pz0) + counted
    assert counted < 0.01 * abs(pz0), "the small-cell fixes may not touch more than 1% of the momentum"


def test_tensile_limit_opens_void_instead_of_stretching():
    """A strengthless target (Y_T = 0) never holds tension: no material pressure below 0."""
    sim = impact(1000.0)
    sim.run(0.3)
    assert sim.floor_counts["tensile_limit"] > 0
    snap = sim.snapshot()
    rho_k = np.where(snap.volume_fraction > 1e-3, snap.partial_density / np.maximum(snap.volume_fraction, 1e-300),
                     np.nan)
    assert np.nanmin(rho_k) > 0.5 * 2700.0, "no material may be diluted to a fraction of its density"


def test_tensile_strength_is_held():
    """With Y_T = 1 MPa the target carries tension down to -Y_T, and no further."""
    sim = impact(1000.0, strength={"model": "geo", "Y_T": 1.0e6})
    assert list(sim.tensile_strength) == [1.0e6, 1.0e6]
    sim.run(0.3)
    assert sim.snapshot().pressure.min() >= -1.0e6 * (1 + 1e-9)
