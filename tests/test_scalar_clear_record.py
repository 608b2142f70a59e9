"""The record of blocks whose transported scalars are +0.0 (hydro/mesh/last_good.py,
`scalar_clear_blocks`): the ghost fills, the sweeps and the last-good copy skip those blocks'
scalars, and a run must be the same bit for bit with the record as without it."""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.solver import Simulation
from impactpipe.pipeline.presets import resolve_damage, resolve_strength


def strength_impact(fracture: bool):
    """A basalt impact with GEO strength (and Grady-Kipp fracture) in r-z, coarse: right after
    contact most blocks hold material without stress, and their scalars are +0.0."""
    materials = {"basalt": preset_material("basalt")}
    materials["basalt"]["strength"] = resolve_strength("geo", "strong", {})
    if fracture:
        materials["basalt"]["strength"]["damage"] = resolve_damage({"model": "grady_kipp", "preset": "basalt"})
    params = {"target": {"material": "basalt", "radius": 1000.0},
              "projectile": {"material": "basalt", "radius": 250.0, "velocity": 2000.0},
              "cells_per_projectile_radius": 8}
    return PROBLEMS["impact"].setup(params, materials)


@pytest.mark.parametrize("fracture", [False, True])
def test_a_run_with_the_record_of_clear_blocks_equals_one_without_it_bit_for_bit(fracture, monkeypatch):
    with_record = strength_impact(fracture)
    assert with_record._records_clear_scalars()
    recorded = 0
    for _ in range(30):
        with_record.step()
        recorded += int(with_record._scalars_clear.sum())
    assert recorded > 0, "some blocks were clear, so the record skipped work"

    monkeypatch.setattr(Simulation, "_records_clear_scalars", lambda self: False)
    without = strength_impact(fracture)
    for _ in range(30):
        without.step()

    assert with_record.time == without.time and with_record.step_count == without.step_count
    for name, values in with_record.state.arrays().items():
        interior = with_record.mesh.interior
        assert np.array_equal(interior(values), interior(without.state.arrays()[name])), name
    for mine, theirs in zip(with_record._counter_arrays(), without._counter_arrays()):
        assert np.array_equal(mine, theirs)
    for name, copy in with_record._good.items():
        assert np.array_equal(copy, without._good[name]), f"last-good {name}"
