"""The record of void blocks and of blocks whose transported scalars are +0.0
(hydro/mesh/last_good.py, `RECORD_VOID`, `scalar_clear_blocks`): the ghost fills, the sweeps
and the last-good copy skip what those blocks hold, and a run must be the same bit for bit with
the record as without it, ghosts included."""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.mesh.last_good import RECORD_CLEAR, RECORD_VOID
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.solver import Simulation
from impactpipe.pipeline.presets import resolve_damage, resolve_strength


def strength_impact(physics: str):
    """A basalt impact in r-z, coarse, without strength, with GEO strength, or with Grady-Kipp
    fracture as well: about half of its blocks are void, and right after contact most blocks
    with material hold no stress (their scalars are +0.0 with strength alone)."""
    materials = {"basalt": preset_material("basalt")}
    if physics != "hydro":
        materials["basalt"]["strength"] = resolve_strength("geo", "strong", {})
    if physics == "fracture":
        materials["basalt"]["strength"]["damage"] = resolve_damage({"model": "grady_kipp", "preset": "basalt"})
    params = {"target": {"material": "basalt", "radius": 1000.0},
              "projectile": {"material": "basalt", "radius": 250.0, "velocity": 2000.0},
              "cells_per_projectile_radius": 8}
    return PROBLEMS["impact"].setup(params, materials)


@pytest.mark.parametrize("physics", ["hydro", "strength", "fracture"])
def test_a_run_with_the_record_of_clear_blocks_equals_one_without_it_bit_for_bit(physics, monkeypatch):
    with_record = strength_impact(physics)
    assert with_record._keeps_block_record()
    void, clear = 0, 0
    for _ in range(30):
        with_record.step()
        void += int((with_record._scalars_clear == RECORD_VOID).sum())
        clear += int((with_record._scalars_clear == RECORD_CLEAR).sum())
    assert void > 0, "some blocks stayed void, so the ghost fills skipped their slabs"
    if physics == "strength":
        assert clear > 0, "some blocks were clear, so the record skipped their scalars"

    monkeypatch.setattr(Simulation, "_keeps_block_record", lambda self: False)
    without = strength_impact(physics)
    for _ in range(30):
        without.step()

    assert with_record.time == without.time and with_record.step_count == without.step_count
    for name, values in with_record.state.arrays().items():
        # ghosts included, in bits: a skipped copy would have written what the slab held
        assert values.tobytes() == without.state.arrays()[name].tobytes(), name
    for mine, theirs in zip(with_record._counter_arrays(), without._counter_arrays()):
        assert np.array_equal(mine, theirs)
    for name, copy in with_record._good.items():
        assert np.array_equal(copy, without._good[name]), f"last-good {name}"


@pytest.mark.parametrize("physics", ["strength", "fracture"])
def test_velocities_kept_for_the_blocks_the_first_kick_passed_over_equal_new_ones_bit_for_bit(physics, monkeypatch):
    """The stress update finds the velocities again only where the first half kick moved the
    momentum (MaterialStrength.update, ``kicked_only``); a run that finds them everywhere again
    is the same bit for bit."""
    from impactpipe.hydro.strength.model import MaterialStrength

    kept = strength_impact(physics)
    quiet = 0
    for _ in range(20):
        kept.step()
        quiet += int(kept.strength._quiet.sum())
    assert quiet > 0, "some blocks were passed over"

    update = MaterialStrength.update
    monkeypatch.setattr(MaterialStrength, "update",
                        lambda self, *args, kicked_only=False, **kw: update(self, *args, kicked_only=False, **kw))
    found = strength_impact(physics)
    for _ in range(20):
        found.step()
    assert kept.time == found.time
    for name, values in kept.state.arrays().items():
        assert values.tobytes() == found.state.arrays()[name].tobytes(), name
    assert kept.strength.work.tobytes() == found.strength.work.tobytes()
