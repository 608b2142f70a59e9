"""The blocks' scalar stamps (hydro/mesh/scalar_stamps.py): a step's ghost fill skips the
transported scalars of a slab whose source block has not changed them since they were copied.
A run must be the same bit for bit with the stamps as without them, ghosts included, also after
a restore of the last-good copy and after an announced change to the state from outside."""

import numpy as np
import pytest

from impactpipe.hydro.mesh.scalar_stamps import ScalarStamps
from impactpipe.hydro.solver import Simulation

from test_scalar_clear_record import strength_impact


def slabs_held(sim, axis: int) -> int:
    """The same-level and domain-face slabs along ``axis`` whose scalars the next fill along it
    skips because their source block kept its stamp (the record's own skips aside)."""
    mesh, stamps = sim.mesh, sim._stamps
    held = 0
    for side in range(2):
        nbr = mesh.neighbor[:, axis, side]
        src = np.where(nbr >= 0, nbr, np.arange(mesh.nblocks))
        same = (nbr < 0) | (mesh.neighbor_level[:, axis, side] == 0)
        held += int((same & (stamps.ghost[:, axis, side] == stamps.block[src])).sum())
    return held


def assert_same_run(mine: Simulation, theirs: Simulation) -> None:
    """The two runs' clocks, states (ghosts included, in bits) and counters are the same."""
    assert mine.time == theirs.time and mine.step_count == theirs.step_count
    for name, values in mine.state.arrays().items():
        assert values.tobytes() == theirs.state.arrays()[name].tobytes(), name
    for a, b in zip(mine._counter_arrays(), theirs._counter_arrays()):
        assert a.tobytes() == b.tobytes()


def without_stamps(monkeypatch) -> None:
    monkeypatch.setattr(Simulation, "_keeps_scalar_stamps", lambda self: False)


@pytest.mark.parametrize("physics", ["strength", "fracture"])
def test_a_run_with_scalar_stamps_equals_one_without_them_bit_for_bit(physics, monkeypatch):
    stamped = strength_impact(physics)
    assert stamped._keeps_scalar_stamps()
    held = 0
    for _ in range(30):
        held += slabs_held(stamped, 0 if stamped.step_count % 2 == 0 else 1)
        stamped.step()
    if physics == "fracture":
        # the flaws keep every block holding material from the record's skips: the stamps skip them
        assert held > stamped.mesh.nblocks, "slabs of blocks at rest kept their scalars"
    without_stamps(monkeypatch)
    plain = strength_impact(physics)
    for _ in range(30):
        plain.step()
    assert_same_run(stamped, plain)


def test_a_run_restored_from_its_last_good_copy_equals_one_without_stamps(monkeypatch):
    stamped = strength_impact("fracture")
    for _ in range(12):
        stamped.step()
    stamped.restore_last_good()  # takes the steps since the copy again
    for _ in range(6):
        stamped.step()
    without_stamps(monkeypatch)
    plain = strength_impact("fracture")
    for _ in range(12):
        plain.step()
    plain.restore_last_good()
    for _ in range(6):
        plain.step()
    assert_same_run(stamped, plain)


def test_an_announced_change_of_the_scalars_reaches_the_ghosts(monkeypatch):
    """Flaws changed from outside in blocks at rest (stamps kept through the last step) reach their
    neighbours' ghosts once state_changed() says so: the run equals one without stamps."""

    def changed_run(kept=None):
        sim = strength_impact("fracture", cells=16)
        for _ in range(7):
            sim.step()
        before = sim._stamps.block.copy()
        sim.step()
        st, nq = sim.state, sim.strength.nq
        flaws = [k * nq + j for k in range(st.nmat) for j in range(sim.strength.ns + 1, nq - 1)]
        interior = sim.mesh.interior(st.arhoq)
        if kept is None:
            kept = np.flatnonzero((sim._stamps.block == before) & (interior[:, flaws] != 0.0).any(axis=(1, 2, 3, 4)))
            assert kept.size > 0, "some blocks holding flaws kept their stamps"
        interior[kept[:, None], flaws] *= 1.5
        sim.state_changed()
        for _ in range(4):
            sim.step()
        return sim, kept

    stamped, kept = changed_run()
    without_stamps(monkeypatch)
    assert_same_run(stamped, changed_run(kept)[0])


def test_forget_makes_every_ghost_stamp_unknown():
    stamps = ScalarStamps(5)
    stamps.ghost[:] = 3
    stamps.forget()
    assert stamps.ghost.shape == (5, 3, 2) and (stamps.ghost == -1).all()
    assert stamps.block.shape == (5,) and (stamps.block == 0).all()
