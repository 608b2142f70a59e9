"""benchmarks/remnant_capture.py: the fates of hand-off particles on a hand-made run."""

import importlib.util
from pathlib import Path

import h5py
import numpy as np
from scipy.constants import G

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("remnant_capture", ROOT / "benchmarks" / "remnant_capture.py")
rc = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rc)



def _write_run(run: Path):
    """A 1e15 kg body at rest (id 1), a 1e12 kg particle at rest 10 km away (id 2, bound), a
    1e12 kg particle at 5 m/s 10 km away on the other side (id 3, unbound: v_esc = 3.66 m/s),
    a 1e12 kg particle at rest 20 km away (id 4, bound) and a 2e12 kg particle at 1 m/s 30 km
    away (id 5, bound: v_esc = 2.11 m/s).  The N-body result keeps 1 and 2; 3 escaped merged
    with 4, and 5 escaped alone."""
    run.mkdir()
    mass = np.array([1e15, 1e12, 1e12, 1e12, 2e12])
    position = np.array([[0, 0, 0], [1e4, 0, 0], [-1e4, 0, 0], [0, 2e4, 0], [0, 0, 3e4]], float)
    velocity = np.array([[0, 0, 0], [0, 0, 0], [-5.0, 0, 0], [0, 0, 0], [0, 0, 1.0]], float)
    with h5py.File(run / "handoff.h5", "w") as f:
        p = f.create_group("particles")
        p["id"], p["mass"], p["position"], p["velocity"] = np.arange(1, 6), mass, position, velocity
    with h5py.File(run / "nbody.h5", "w") as f:
        f["members"] = np.array([1, 2])
        f["escaped_members"] = np.array([3, 4, 5])
        f["escaped_members_offset"] = np.array([0, 2, 3])
    return mass


def test_bound_mass_carried_off_by_an_unbound_fragment_is_counted_as_such(tmp_path):
    runs = tmp_path / "ladder" / "runs"
    runs.mkdir(parents=True)
    mass = _write_run(runs / "cells_per_projectile_radius=10_seed=1-abc")
    m, ratio, kept, carried, alone, (kinetic, radial) = rc.particle_fates(runs / "cells_per_projectile_radius=10_seed=1-abc")
    assert np.array_equal(kept, [True, True, False, False, False])
    assert ratio[2] > 1.0 > ratio[3] and ratio[1] < 1.0 and ratio[4] < 1.0
    np.testing.assert_allclose(ratio[2], 5.0 / np.sqrt(2 * G * (1e15 + 2e12) / 1e4), rtol=2e-3)
    assert carried == mass[3] and alone == mass[4]
    # the bound particles' motion in the frame of the whole set (V = 3e12 kg m/s along z and
    # -5e12 along x, over the total mass)
    total = mass.sum()
    frame_x = (mass[:, None] * np.array([[0, 0, 0], [1e4, 0, 0], [-1e4, 0, 0], [0, 2e4, 0], [0, 0, 3e4]])).sum(0) / total
    frame_v = np.array([-5e12, 0.0, 2e12]) / total
    velocity = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 1.0]]) - frame_v
    offset = np.array([[0, 0, 0], [1e4, 0, 0], [0, 2e4, 0], [0, 0, 3e4]]) - frame_x
    bound_mass = mass[[0, 1, 3, 4]]
    np.testing.assert_allclose(kinetic, 0.5 * (bound_mass * (velocity ** 2).sum(1)).sum(), rtol=1e-12)
    radial = (velocity * offset).sum(1) / np.linalg.norm(offset, axis=1)
    np.testing.assert_allclose(rc.particle_fates(runs / "cells_per_projectile_radius=10_seed=1-abc")[5][1],
                               (bound_mass * radial).sum() / bound_mass.sum(), rtol=1e-12)
    table = rc.rung_table(tmp_path / "ladder").splitlines()
    row = table[1].split()
    assert len(table) == 2 and row[:3] == ["10", "1", f"{(total - mass[2]) / total:.3f}"]
    assert row[3] == f"{(mass[0] + mass[1]) / total:.3f}"
    assert row[6:9] == [f"{mass[3] / total:.3f}", "/", f"{mass[4] / total:.3f}"]
    # runs of a ladder handed off at several times: one row per value and time
    _write_run(runs / "cells_per_projectile_radius=10_time=14_seed=1-def")
    _write_run(runs / "cells_per_projectile_radius=10_time=14_seed=2-ghi")
    # the hydro keys a hand-off-time ladder sets follow the seed in the name
    _write_run(runs / "cells_per_projectile_radius=10_time=14_seed=3_end_time=15_output_times=-14.0--15.0--jkl")
    table = rc.rung_table(tmp_path / "ladder").splitlines()
    assert [line.split()[:2] for line in table[1:]] == [["10", "1"], ["10/14", "3"]]
