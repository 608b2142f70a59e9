"""Intact fragments made single spheres at the hand-off (handoff/bodies.py)."""

from __future__ import annotations

import numpy as np
import pytest

from impactpipe.handoff.bodies import split_intact_bodies
from test_handoff import RHO, direct_mesh_sums, handoff, random_flow_snapshot


def label_ball(snap, centre, radius):
    """Fragment 0: the cells whose centres lie within ``radius`` of ``centre`` (mesh coordinates)."""
    c = snap.block_cell_centers()
    d2 = sum((c[:, a] - centre[a]) ** 2 for a in range(snap.ndim))
    return np.where(d2 <= radius**2, 0, -1)


def cell_sums(snap, cells):
    """Mass, centre of mass (mesh components) and momentum of the selected cells, independently."""
    ndim = snap.ndim
    m = (snap.partial_density.sum(axis=1) * snap.block_cell_volumes())[cells]
    x = np.moveaxis(snap.block_cell_centers()[:, :ndim], 1, -1)[cells]
    v = np.moveaxis(snap.velocity[:, :ndim], 1, -1)[cells]
    return m.sum(), (m[:, None] * x).sum(axis=0) / m.sum(), (m[:, None] * v).sum(axis=0)


def test_3d_fragment_is_one_sphere_and_the_budget_still_closes():
    snap = random_flow_snapshot("3d")
    label = label_ball(snap, (50.0, -30.0, 20.0), 250.0)
    mesh_mass, mesh_momentum, mesh_ke = direct_mesh_sums(snap)
    plain, plain_budget = handoff(snap, total_mass=mesh_mass, escape_speed=0.0)
    particles, budget = handoff(snap, total_mass=mesh_mass, escape_speed=0.0, intact_label=label)
    m, com, p = cell_sums(snap, label == 0)
    body = particles.source_block == -1
    assert body.sum() == 1 and budget.intact_bodies == 1
    assert particles.mass[body][0] == pytest.approx(m, rel=1e-12)
    assert budget.intact_mass == pytest.approx(m, rel=1e-12)
    np.testing.assert_allclose(particles.position[body][0], com, rtol=0, atol=1e-9 * 400.0)
    np.testing.assert_allclose(particles.mass[body][0] * particles.velocity[body][0], p, rtol=1e-12)
    assert particles.radius[body][0] == pytest.approx(np.cbrt(3.0 * m / (4.0 * np.pi * RHO)), rel=1e-12)
    # The fragment's cells left their blocks, whose spheres carry the rest; nothing is lost.
    assert particles.mass.sum() + budget.dropped_mass == pytest.approx(mesh_mass, rel=1e-12)
    assert budget.mesh_mass == pytest.approx(mesh_mass, rel=1e-12)
    scale = (snap.partial_density.sum(axis=1) * snap.block_cell_volumes() * np.linalg.norm(snap.velocity, axis=1)).sum()
    total_p = (particles.mass[:, None] * particles.velocity).sum(axis=0) + budget.dropped_momentum
    np.testing.assert_allclose(total_p, mesh_momentum, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(budget.mesh_momentum, mesh_momentum, rtol=0, atol=1e-12 * scale)
    assert budget.mesh_kinetic_energy == pytest.approx(mesh_ke, rel=1e-12)
    # One sphere moving with the fragment's mean velocity carries less kinetic energy than its cells.
    assert budget.unresolved_kinetic_energy > plain_budget.unresolved_kinetic_energy
    cell_ke = 0.5 * ((snap.partial_density.sum(axis=1) * snap.block_cell_volumes())[label == 0]
                     * (np.moveaxis(snap.velocity, 1, -1)[label == 0] ** 2).sum(axis=1)).sum()
    assert budget.intact_internal_kinetic_energy == pytest.approx(cell_ke - 0.5 * (p**2).sum() / m, rel=1e-9)


def test_2d_fragment_on_the_axis_is_one_sphere_on_the_axis_and_a_ring_stays_with_its_blocks():
    snap = random_flow_snapshot("2d-cylindrical")
    on_axis = label_ball(snap, (0.0, 100.0), 220.0)
    ring = label_ball(snap, (450.0, -350.0), 120.0)
    label = np.where(on_axis == 0, 0, np.where(ring == 0, 1, -1))
    mesh_mass, mesh_momentum, _ = direct_mesh_sums(snap)  # (P_r, P_z)
    particles, budget = handoff(snap, total_mass=mesh_mass, escape_speed=0.0, intact_label=label)
    assert budget.intact_bodies == 1 and budget.intact_rings_left == 1
    body = particles.source_block == -1
    m, _, p = cell_sums(snap, label == 0)
    assert particles.mass[body][0] == pytest.approx(m, rel=1e-12)
    np.testing.assert_array_equal(particles.position[body][0, :2], 0.0)
    np.testing.assert_array_equal(particles.velocity[body][0, :2], 0.0)
    assert particles.mass[body][0] * particles.velocity[body][0, 2] == pytest.approx(p[1], rel=1e-12)
    # Mass, P_z and the scalar radial momentum close, the body's P_r reported apart.
    scale = (snap.partial_density.sum(axis=1) * snap.block_cell_volumes() * np.linalg.norm(snap.velocity, axis=1)).sum()
    assert particles.mass.sum() + budget.dropped_mass == pytest.approx(mesh_mass, rel=1e-12)
    p_z = (particles.mass * particles.velocity[:, 2]).sum() + budget.dropped_momentum[2]
    assert abs(p_z - mesh_momentum[1]) <= 1e-12 * scale
    assert budget.intact_radial_momentum == pytest.approx(p[0], rel=1e-12)
    closed = budget.particle_radial_momentum + budget.dropped_radial_momentum + budget.intact_radial_momentum
    assert abs(closed - mesh_momentum[0]) <= 1e-12 * scale


def test_labels_must_match_the_cells_and_a_mirrored_run_is_labelled_after_mirroring():
    snap = random_flow_snapshot("3d")
    with pytest.raises(ValueError, match="cell shape"):
        split_intact_bodies(snap, np.zeros(3, dtype=int), RHO)
    with pytest.raises(ValueError, match="mirror it first"):
        handoff(snap, intact_label=np.full(snap.pressure.shape, -1), mirror_y0=True)
