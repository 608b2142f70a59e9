"""The record of void blocks and of blocks whose transported scalars are +0.0
(hydro/mesh/last_good.py, `RECORD_VOID`, `scalar_clear_blocks`): the ghost fills, the sweeps
and the last-good copy skip what those blocks hold, and a run must be the same bit for bit with
the record as without it, ghosts included."""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.mesh.last_good import NONE_KNOWN, RECORD_CLEAR, RECORD_VOID, scalar_clear_blocks
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.solver import Simulation
from impactpipe.pipeline.presets import resolve_damage, resolve_strength


def strength_impact(physics: str, cells: int = 8):
    """A basalt impact in r-z, coarse (``cells`` per projectile radius), without strength, with
    GEO strength, or with Grady-Kipp fracture as well: about half of its blocks are void, and
    right after contact most blocks with material hold no stress (their scalars are +0.0 with
    strength alone)."""
    materials = {"basalt": preset_material("basalt")}
    if physics != "hydro":
        materials["basalt"]["strength"] = resolve_strength("geo", "strong", {})
    if physics == "fracture":
        materials["basalt"]["strength"]["damage"] = resolve_damage({"model": "grady_kipp", "preset": "basalt"})
    params = {"target": {"material": "basalt", "radius": 1000.0},
              "projectile": {"material": "basalt", "radius": 250.0, "velocity": 2000.0},
              "cells_per_projectile_radius": cells}
    return PROBLEMS["impact"].setup(params, materials)


def resting_blocks(sim) -> int:
    """The blocks holding material that the stress step of a Grady-Kipp scene passes over now: at
    rest and unstressed, their flaws aside (hydro/strength/update.py, ``_strength_scalars_clear``)."""
    from impactpipe.hydro.strength import update

    st, strength = sim.state, sim.strength
    arrays = strength.arrays
    rho0 = strength._reference_densities(sim.eos)
    count = 0
    for b in np.flatnonzero(strength.has_mass):
        count += bool(update._rests_unstressed(strength.work, st.alpha, st.arho, st.arhoe, strength.amounts, b,
                                               sim.mesh.ndim, arrays.model, sim.eos.kind, sim.eos.params, rho0,
                                               arrays.tensile_strength)
                      and update._strength_scalars_clear(st.arhoq, strength.work, st.alpha, st.arho, b,
                                                         strength.ns, arrays.model))
    return count


def test_the_hint_of_a_non_zero_column_leaves_the_record_as_it_is():
    """scalar_clear_blocks tests a block's hinted column first: the record is the one without
    hints whatever they are (none, stale, pointing at a zero column), -0.0 counts as not zero, and
    each block found not clear is left a hint of a column holding something."""
    rng = np.random.default_rng(7)
    nb, nc = 40, 6
    arhoq = np.zeros((nb, nc, 6, 6, 1))
    for b in range(nb):
        kind = b % 4
        if kind == 1:
            arhoq[b, rng.integers(nc), rng.integers(6), rng.integers(6), 0] = rng.normal()
        elif kind == 2:
            arhoq[b, rng.integers(nc), rng.integers(6), rng.integers(6), 0] = -0.0
        elif kind == 3:
            arhoq[b, rng.integers(nc)] = 1.0
    void = np.zeros(nb, dtype=np.uint8)
    void[::7] = 1
    bits = arhoq.view(np.int64)
    expected = np.array([1 if void[b] or not bits[b].any() else 0 for b in range(nb)], dtype=np.uint8)
    for hint in (np.full(nb, -1), rng.integers(-1, nc, nb)):
        hint = hint.astype(np.int64)
        clear = np.full(nb, 9, dtype=np.uint8)
        scalar_clear_blocks(bits, void, 0, nb, clear, hint, NONE_KNOWN)
        assert np.array_equal(clear, expected)
        for b in np.flatnonzero(clear == 0):
            assert bits[b, hint[b]].any()
        again = np.full(nb, 9, dtype=np.uint8)
        scalar_clear_blocks(bits, void, 0, nb, again, hint, NONE_KNOWN)
        assert np.array_equal(again, expected)


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
    if physics == "fracture":
        assert resting_blocks(with_record) > 0, "the stress step passed over some blocks at rest despite their flaws"

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


def test_a_fracture_block_passes_as_clear_with_flaws_alone():
    """``_strength_scalars_clear``: a Grady-Kipp block whose stress, plastic strain and damage are
    +0.0 passes whatever its flaws; a stress, a -0.0 damage, or a flaw left in a void cell or of an
    absent material (which the stress step would clear) does not."""
    from impactpipe.hydro.strength import update
    from impactpipe.hydro.strength.parameters import GEO

    ns, nq, nmat = 4, update.scalar_slots(2, True), 2
    model = np.array([GEO, GEO], dtype=np.int64)

    def block():
        alpha = np.zeros((1, nmat, 6, 6, 1))
        alpha[0, 0] = 1.0
        arho = 2700.0 * alpha
        arhoq = np.zeros((1, nmat * nq, 6, 6, 1))
        arhoq[0, ns + 1:ns + 1 + update.NFLAW] = 1.0e20 * arho[0, 0]
        work = np.zeros((1, update.NWORK, 6, 6, 1))
        work[0, update.WK_PHI] = 1.0
        return alpha, arho, arhoq, work

    def clear(alpha, arho, arhoq, work):
        return update._strength_scalars_clear(arhoq, work, alpha, arho, 0, ns, model)

    assert clear(*block())
    for slot, value in ((0, 1.0), (ns, 1.0e-9), (nq - 1, -0.0)):
        alpha, arho, arhoq, work = block()
        arhoq[0, slot, 3, 2, 0] = value
        assert not clear(alpha, arho, arhoq, work), slot
    alpha, arho, arhoq, work = block()
    arhoq[0, nq + ns + 1, 2, 2, 0] = 1.0
    assert not clear(alpha, arho, arhoq, work), "a flaw of the absent material"
    alpha, arho, arhoq, work = block()
    work[0, update.WK_PHI, 2, 3, 0] = 0.0
    assert not clear(alpha, arho, arhoq, work), "flaws in a void cell"


@pytest.mark.parametrize("physics", ["hydro", "strength", "fracture"])
def test_void_blocks_known_from_the_last_sweep_equal_a_look_at_every_block_bit_for_bit(physics, monkeypatch):
    """The void test takes the blocks the last step's sweeps left void as void without a look
    (Simulation._void_after, void_blocks' ``known``): the records and the run are those of a test
    that looks at every block, bit for bit, ghosts included."""
    known = strength_impact(physics)
    taken = 0
    for _ in range(30):
        taken += int(known._void_after.sum())
        known.step()
    assert taken > 0, "some blocks were known void from the step before"

    monkeypatch.setattr(Simulation, "_keeps_void_record", lambda self: False)
    looked = strength_impact(physics)
    for _ in range(30):
        looked.step()
        assert not looked._void_after.any()
    assert known.time == looked.time
    for name, values in known.state.arrays().items():
        assert values.tobytes() == looked.state.arrays()[name].tobytes(), name
    for mine, theirs in zip(known._counter_arrays(), looked._counter_arrays()):
        assert np.array_equal(mine, theirs)
    assert np.array_equal(known._void_now, looked._void_now)
    assert np.array_equal(known._scalars_clear, looked._scalars_clear)


def test_material_put_into_a_known_void_block_from_outside_is_seen_once_announced(monkeypatch):
    """A block the last step left void, filled from outside with a copy of a block of the target
    and announced with state_changed(): the next void test looks at it (a run whose void test
    looks at every block gives the same state, bit for bit)."""

    def filled_run(pair=None):
        sim = strength_impact("strength")
        for _ in range(6):
            sim.step()
        if pair is None:
            # a void block among void blocks, and the block of the bodies that moves fastest
            mesh, st = sim.mesh, sim.state
            nbr = mesh.neighbor.reshape(mesh.nblocks, -1)
            alone = [b for b in np.flatnonzero(sim._void_after)
                     if all(sim._void_after[n] for n in nbr[b] if n >= 0)]
            full = (mesh.interior(st.arho) > 0.0).all(axis=(2, 3, 4)).any(axis=1)
            speed = np.abs(mesh.interior(st.momentum)).max(axis=(1, 2, 3, 4))
            pair = (int(alone[0]), int(np.argmax(np.where(full, speed, -1.0))))
        void, full = pair
        for values in sim.state.arrays().values():
            interior = sim.mesh.interior(values)
            interior[void] = interior[full]
        sim.state_changed()
        for _ in range(3):
            sim.step()
        return sim, pair

    known, pair = filled_run()
    monkeypatch.setattr(Simulation, "_keeps_void_record", lambda self: False)
    looked, _ = filled_run(pair)
    for name, values in known.state.arrays().items():
        assert values.tobytes() == looked.state.arrays()[name].tobytes(), name


@pytest.mark.parametrize("physics", ["strength", "fracture"])
def test_clear_blocks_known_from_the_last_step_equal_a_look_at_every_block_bit_for_bit(physics, monkeypatch):
    """The clear-block record takes the blocks the last step's sweeps left clear and the stress
    update passed over as clear without a look (Simulation._clear_after, scalar_clear_blocks'
    ``known``): the records and the run are those of a look at every block, bit for bit."""
    from impactpipe.hydro import solver

    known = strength_impact(physics)
    taken = 0
    records = []
    for _ in range(30):
        taken += int(known._clear_after.sum())
        known.step()
        records.append(known._scalars_clear.copy())
    assert taken > 0, "some blocks were known clear from the step before"

    monkeypatch.setattr(solver, "scalar_clear_blocks", lambda arhoq, void, lo, hi, clear, hint, _: scalar_clear_blocks(
        arhoq, void, lo, hi, clear, hint, NONE_KNOWN))
    looked = strength_impact(physics)
    for step in range(30):
        looked.step()
        assert np.array_equal(records[step], looked._scalars_clear), step
    for name, values in known.state.arrays().items():
        assert values.tobytes() == looked.state.arrays()[name].tobytes(), name
    for mine, theirs in zip(known._counter_arrays(), looked._counter_arrays()):
        assert np.array_equal(mine, theirs)
