"""Fragment finder: connected intact cells, their masses, speeds and shapes; `impactpipe fragments`."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from impactpipe.analysis.fragments import (
    NAKAMURA_FUJIWARA_1991,
    face_neighbours,
    find_fragments,
    intact_cells,
)
from impactpipe.handoff import read_particles
from impactpipe.handoff.mirror import mirror_across_y0
from impactpipe.hydro.output.io import append_snapshot
from impactpipe.hydro.output.snapshot import Snapshot
from impactpipe.pipeline.cli import main
from impactpipe.pipeline.config import load_config
from impactpipe.pipeline.fragments import intact_fragment_labels, snapshot_fragments
from impactpipe.pipeline.stages import resolved_yaml
from impactpipe.storage import write_text_atomic
from test_impact_3d import TINY


def grid(shape, width=1.0):
    """Centres (N, 3) and widths (N, 3) of a uniform grid of ``shape`` cells (unused axes: one cell)."""
    axes = [(np.arange(n) + 0.5) * width for n in shape] + [np.zeros(1)] * (3 - len(shape))
    mesh = np.meshgrid(*axes, indexing="ij")
    center = np.stack([m.ravel() for m in mesh], axis=1)
    w = np.zeros(3)
    w[:len(shape)] = width
    return center, np.tile(w, (center.shape[0], 1))


def test_separate_bodies_are_separate_fragments_with_their_mass_and_velocity():
    center, width = grid((12, 6, 6))
    x = center[:, 0]
    intact = (x < 4.0) | (x > 7.0)  # two slabs of 4 and 5 cells, an empty gap of 3 cells between
    mass = np.where(x < 4.0, 2.0, 1.0)
    velocity = np.zeros((len(x), 3))
    velocity[:, 0] = np.where(x < 4.0, -1.0, 3.0)
    frags = find_fragments(center, width, mass, velocity, intact, 3)
    assert frags.count == 2
    np.testing.assert_allclose(frags.mass, [2.0 * 4 * 36, 1.0 * 5 * 36])
    np.testing.assert_allclose(frags.velocity[:, 0], [-1.0, 3.0])
    np.testing.assert_allclose(frags.center[:, 0], [2.0, 9.5])
    assert (frags.label[~intact] == -1).all()
    assert set(frags.label[x < 4.0]) == {0}


def test_a_broken_layer_splits_a_bar():
    center, width = grid((20, 3))
    damage = np.where(np.abs(center[:, 0] - 7.5) < 0.6, 1.0, 0.0)  # the column of cells at x = 7.5
    intact = intact_cells(np.ones(len(damage)), damage)
    frags = find_fragments(center, width, np.ones(len(damage)), np.zeros((len(damage), 3)), intact, 2)
    np.testing.assert_array_equal(frags.cells, [12 * 3, 7 * 3])


def test_cells_touching_at_a_corner_only_are_not_joined():
    center = np.array([[0.5, 0.5, 0.0], [1.5, 1.5, 0.0], [1.5, 0.5, 0.0]])
    width = np.tile([1.0, 1.0, 0.0], (3, 1))
    i, j = face_neighbours(center[:2], width[:2], 2)
    assert i.size == 0
    i, j = face_neighbours(center, width, 2)
    assert sorted(zip(i.tolist(), j.tolist())) == [(0, 2), (1, 2)]


def test_cells_join_across_a_coarse_fine_face_but_not_at_its_corner():
    # a coarse cell of width 2 on [0, 2]^2; fine cells of width 1 beside its face x = 2 and one
    # beyond its corner (2, 2)
    center = np.array([[1.0, 1.0, 0.0], [2.5, 0.5, 0.0], [2.5, 1.5, 0.0], [2.5, 2.5, 0.0], [3.5, 3.5, 0.0]])
    width = np.array([[2.0, 2.0, 0.0]] + [[1.0, 1.0, 0.0]] * 4)
    i, j = face_neighbours(center, width, 2)
    pairs = sorted(tuple(sorted(p)) for p in zip(i.tolist(), j.tolist()))
    assert pairs == [(0, 1), (0, 2), (1, 2), (2, 3)]
    frags = find_fragments(center, width, np.ones(5), np.zeros((5, 3)), np.ones(5, dtype=bool), 2)
    np.testing.assert_array_equal(frags.cells, [4, 1])


@pytest.mark.parametrize("ndim, axes", [(3, (3.0, 2.0, 1.0)), (2, (4.0, 1.5))])
def test_shape_is_the_ellipsoid_of_the_cells(ndim, axes):
    """A uniform ellipsoid (ellipse) on a grid of 0.1 m cells: semi-axes within 1 %."""
    h = 0.1
    shape = tuple(int(round(2 * a / h)) + 2 for a in axes)
    center, width = grid(shape, h)
    offset = center[:, :ndim] - np.asarray([(n * h) / 2 for n in shape])
    inside = ((offset / np.asarray(axes)) ** 2).sum(axis=1) <= 1.0
    frags = find_fragments(center, width, np.ones(len(inside)), np.zeros((len(inside), 3)), inside, ndim)
    assert frags.count == 1
    np.testing.assert_allclose(frags.semi_axes[0, :ndim], sorted(axes, reverse=True), rtol=0.01)
    assert (frags.semi_axes[0, ndim:] == 0.0).all()


def test_intact_cells_need_material_and_less_than_full_damage():
    keep = intact_cells(np.array([1.0, 0.4, 1.0, 1.0]), np.array([0.0, 0.0, 0.99, 0.5]))
    np.testing.assert_array_equal(keep, [True, False, False, True])
    with pytest.raises(ValueError, match="max_damage"):
        intact_cells(np.ones(1), np.zeros(1), max_damage=1.5)


def half_domain_snapshot(time=0.0, damage_plane=None):
    """A 3d half-domain (y >= 0) snapshot of two 4^3 blocks of basalt (2700 kg/m^3, 1 m cells)
    moving at (1, 2, 3) m/s; cells with x in ``damage_plane`` (lo, hi) are fully damaged."""
    lo = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0]])
    hi = lo + 4.0
    shape = (2, 1, 4, 4, 4)
    velocity = np.zeros((2, 3, 4, 4, 4))
    velocity[:, 0], velocity[:, 1], velocity[:, 2] = 1.0, 2.0, 3.0
    snap = Snapshot(time=time, geometry="3d", material_names=["basalt"], block_lo=lo, block_hi=hi,
                    block_level=np.zeros(2, dtype=np.int64), block_id=np.arange(2), partial_density=np.full(shape, 2700.0),
                    volume_fraction=np.ones(shape), velocity=velocity, specific_internal_energy=np.zeros((2, 4, 4, 4)),
                    pressure=np.zeros((2, 4, 4, 4)), temperature=np.zeros((2, 4, 4, 4)),
                    sound_speed=np.zeros((2, 4, 4, 4)), extra={"damage": np.zeros((2, 4, 4, 4))})
    if damage_plane is not None:
        x = snap.block_cell_centers()[:, 0]
        snap.extra["damage"] = np.where((x > damage_plane[0]) & (x < damage_plane[1]), 1.0, 0.0)
    return snap


def test_a_half_domain_fragment_is_joined_with_its_mirror_image():
    snap = half_domain_snapshot()
    frags = snapshot_fragments(snap, [0], half_domain=True, min_fill=0.5, max_damage=0.99)
    assert frags.count == 1
    np.testing.assert_allclose(frags.mass, [2 * 2700.0 * 128])
    np.testing.assert_allclose(frags.velocity[0], [1.0, 0.0, 3.0], atol=1e-12)
    broken = snapshot_fragments(half_domain_snapshot(damage_plane=(3.0, 5.0)), [0], True, 0.5, 0.99)
    np.testing.assert_allclose(broken.mass, [2 * 2700.0 * 48] * 2)


#: The small 45-degree 3d impact of test_impact_3d with GEO strength (a run with a damage field).
TINY_STRENGTH = TINY.replace("    eos: {model: tillotson, preset: basalt}\n",
                             "    eos: {model: tillotson, preset: basalt}\n    strength: {model: geo, preset: weak}\n")


def test_fragments_command_prints_writes_and_plots(tmp_path):
    config_path = tmp_path / "tiny.yaml"
    config_path.write_text(TINY_STRENGTH)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    write_text_atomic(run_dir / "config.resolved.yaml", resolved_yaml(load_config(config_path)))
    with h5py.File(run_dir / "hydro.h5", "w") as fh:
        append_snapshot(fh, half_domain_snapshot())
        append_snapshot(fh, half_domain_snapshot(time=0.2, damage_plane=(5.0, 6.0)))
    result = CliRunner().invoke(main, ["fragments", str(run_dir), "--experiment", "nakamura-fujiwara"])
    assert result.exit_code == 0, result.output
    assert "2 fragments of basalt" in result.output
    lines = [line.split() for line in result.output.splitlines() if line.lstrip()[:2] in ("1 ", "2 ")]
    assert [float(line[1]) for line in lines] == pytest.approx([5 / 8, 2 / 8])
    assert NAKAMURA_FUJIWARA_1991.reference in result.output
    assert (run_dir / "plots" / "fragments.png").is_file()
    with h5py.File(run_dir / "fragments.h5", "r") as fh:
        assert fh["fragments/mass"].attrs["units"] == "kg"
        np.testing.assert_allclose(fh["fragments/mass_fraction"][()], [5 / 8, 2 / 8])
        assert "config" in " ".join(fh.attrs.keys())
    early = CliRunner().invoke(main, ["fragments", str(run_dir), "--time", "0"])
    assert "1 fragment of basalt" in early.output
    wrong = CliRunner().invoke(main, ["fragments", str(run_dir), "--material", "ice"])
    assert wrong.exit_code == 2 and "material ice not in the run" in wrong.output


def test_hand_off_labels_only_fragments_larger_than_a_block():
    snap = mirror_across_y0(half_domain_snapshot(damage_plane=(5.0, 6.0)))[0]
    label = intact_fragment_labels(snap, min_fill=0.5, max_damage=0.99)
    assert label.shape == snap.pressure.shape
    # x < 5: 5 x 8 x 4 = 160 cells, more than a 4^3 block; x > 6: 2 x 8 x 4 = 64, one block's worth.
    x = snap.block_cell_centers()[:, 0]
    np.testing.assert_array_equal(label, np.where(x < 5.0, 0, -1))


#: The quickstart impact with GEO strength on a small mesh, run to its hand-off with intact fragments as bodies.
INTACT_RUN = """name: intact
scene:
  problem: impact
  target:     {material: basalt, radius: 1.0e3}
  projectile: {material: basalt, radius: 1.0e2}
  impact:     {velocity: 250.0, angle: 90}
materials:
  basalt:
    eos: {model: tillotson, preset: basalt}
    strength: {model: geo, preset: strong}
hydro:
  cells_per_projectile_radius: 2
  block_cells: 4
  end_time: 0.3
  tracers: {enabled: false}
handoff: {intact_fragments: {enabled: true}}
nbody:
  collision_model: merge
  stop: {min_dynamical_times: 5, max_orbiting_fraction: 0.1}
"""


def test_a_run_hands_off_its_intact_fragments_as_single_spheres(tmp_path):
    config_path = tmp_path / "intact.yaml"
    config_path.write_text(INTACT_RUN)
    result = CliRunner().invoke(main, ["run", str(config_path), "--out", str(tmp_path / "run"), "-q"])
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    budget = summary["handoff_budget"]
    assert budget["intact_bodies"] >= 1
    particles = read_particles(tmp_path / "run" / "handoff.h5")
    bodies = particles.source_block == -1
    assert bodies.sum() == budget["intact_bodies"]
    assert particles.mass[bodies].sum() == pytest.approx(budget["intact_mass"], rel=1e-12)
    np.testing.assert_array_equal(particles.position[bodies, :2], 0.0)
    assert abs(budget["mass_residual"]) <= 1e-12 * budget["mesh_mass"]


def test_intact_fragments_need_a_material_with_strength(tmp_path):
    config_path = tmp_path / "intact.yaml"
    config_path.write_text(INTACT_RUN.replace("    strength: {model: geo, preset: strong}\n", ""))
    result = CliRunner().invoke(main, ["validate", str(config_path)])
    assert result.exit_code == 2
    assert "handoff.intact_fragments.enabled: needs a material with strength" in result.output
