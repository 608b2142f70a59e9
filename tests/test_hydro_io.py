"""Snapshot files, checkpoints and failure handling."""

import h5py
import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS, HydroFailure, Simulation, append_snapshot, read_snapshot

GAS = {"gas": {"eos": {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}}}


def _sedov(cells=32):
    return PROBLEMS["sedov"].setup({"cells": cells}, GAS, geometry="2d-cylindrical")


def test_snapshot_round_trip_with_units(tmp_path):
    sim = _sedov()
    path = tmp_path / "hydro.h5"
    snaps = []

    def write(snap):
        snaps.append(snap)
        with h5py.File(path, "a") as fh:
            append_snapshot(fh, snap)

    sim.run(0.02, output_times=(0.01, 0.02), on_output=write)
    assert [s.time for s in snaps] == [0.01, 0.02]
    first = read_snapshot(path, 0)
    last = read_snapshot(path)
    assert first.time == 0.01 and last.time == 0.02
    for name in ("partial_density", "volume_fraction", "velocity", "pressure", "temperature", "block_lo"):
        np.testing.assert_array_equal(getattr(last, name), getattr(snaps[1], name))
    assert last.geometry == "2d-cylindrical" and last.material_names == ["gas"]
    with h5py.File(path, "r") as fh:
        grp = fh["snapshots/0001"]
        assert all("units" in grp[name].attrs for name in grp)
        assert grp["pressure"].attrs["units"] == "Pa"
    # the snapshot's masses are the simulation's
    assert last.block_masses().sum() == pytest.approx(sim.totals()["mass"], rel=1e-13)
    with pytest.raises(IndexError):
        read_snapshot(path, 5)


def test_checkpoint_continues_bit_for_bit(tmp_path):
    sim = _sedov()
    sim.run(0.01)
    sim.save_checkpoint(tmp_path / "ckpt.h5")
    sim.run(0.02)
    restored = Simulation.from_checkpoint(tmp_path / "ckpt.h5")
    assert restored.time == 0.01
    restored.run(0.02)
    assert restored.step_count == sim.step_count
    np.testing.assert_array_equal(restored.state.energy, sim.state.energy)
    np.testing.assert_array_equal(restored.state.momentum, sim.state.momentum)
    assert restored.totals()["outflow_energy"] == sim.totals()["outflow_energy"]


def test_large_arrays_are_stored_compressed_and_read_back_exactly(tmp_path):
    """Snapshot fields and checkpoint state of 64 KiB and more are deflated after a byte shuffle;
    small arrays stay plain; both read back bit for bit."""
    sim = _sedov(cells=128)
    snap = sim.snapshot()
    with h5py.File(tmp_path / "hydro.h5", "a") as fh:
        append_snapshot(fh, snap)
    sim.save_checkpoint(tmp_path / "ckpt.h5")
    with h5py.File(tmp_path / "hydro.h5", "r") as fh:
        grp = fh["snapshots/0000"]
        assert grp["partial_density"].compression == "gzip" and grp["partial_density"].shuffle
        assert grp["block_level"].compression is None
    with h5py.File(tmp_path / "ckpt.h5", "r") as fh:
        assert fh["state/energy"].compression == "gzip"
    np.testing.assert_array_equal(read_snapshot(tmp_path / "hydro.h5").partial_density, snap.partial_density)
    np.testing.assert_array_equal(Simulation.from_checkpoint(tmp_path / "ckpt.h5").state.energy, sim.state.energy)


def test_nan_raises_hydro_failure_and_last_good_state_is_kept():
    sim = _sedov()
    sim.run(0.005)
    good = sim.mesh.interior(sim.state.energy).copy()
    time, steps = sim.time, sim.step_count
    interior = sim.mesh.interior(sim.state.arhoe)
    interior[3, 0, 5, 7, 0] = np.nan
    sim.state_changed()  # the restore goes back to the state with the NaN, not to the solver's own
    with pytest.raises(HydroFailure) as info:
        sim.step()
    failure = info.value
    assert failure.time == time and failure.block >= 0 and failure.cell is not None
    assert "before" in failure.state
    sim.restore_last_good()
    assert sim.time == time and sim.step_count == steps
    assert np.isnan(sim.mesh.interior(sim.state.arhoe)[3, 0, 5, 7, 0])
    np.testing.assert_array_equal(np.nan_to_num(sim.mesh.interior(sim.state.energy)), np.nan_to_num(good))


def test_progress_and_max_steps():
    sim = _sedov()
    times = []
    steps = sim.run(1.0, progress=times.append, max_steps=5)
    assert steps == 5 and len(times) == 5 and times == sorted(times)
    assert sim.cell_updates == 5 * sim.mesh.ncells
