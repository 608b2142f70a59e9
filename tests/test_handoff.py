"""Hand-off from synthetic hydro snapshots: conservation, geometry, floors, noise, tracers, I/O."""

from __future__ import annotations

from dataclasses import fields

import h5py
import numpy as np
from scipy.constants import G
import pytest
import rebound

from impactpipe.handoff import HandoffBudget, ParticleSet, blocks_to_spheres, read_particles, write_particles
from impactpipe.handoff.budget import BUDGET_UNITS
from impactpipe.handoff.particles import PARTICLE_UNITS
from impactpipe.handoff.moments import block_moments, merge_fine_blocks, target_kinetic_energy
from impactpipe.handoff.spheres import ring_sphere_count
from impactpipe.handoff.store import read_budget
from impactpipe.hydro.output.snapshot import Snapshot, TracerSet

RHO = 2700.0  # target bulk density of the synthetic bodies (kg/m^3)


# ---------------------------------------------------------------------------- builders


def block_grid(lo, hi, counts):
    """(NB, 3) corners of a regular grid of blocks between ``lo`` and ``hi`` (3-vectors).

    A count of 0 marks an unused axis (one layer of zero extent).
    """
    lo, hi, counts = np.asarray(lo, float), np.asarray(hi, float), np.asarray(counts)
    index = np.stack(np.meshgrid(*[np.arange(max(c, 1)) for c in counts], indexing="ij"), axis=-1).reshape(-1, 3)
    size = np.where(counts > 0, (hi - lo) / np.maximum(counts, 1), 0.0)
    block_lo = lo + index * size
    return block_lo, block_lo + size


def refine(block_lo, block_hi, level, select, ndim):
    """Split the selected blocks in two along each of the first ``ndim`` axes."""
    keep = ~select
    out_lo, out_hi, out_level = [block_lo[keep]], [block_hi[keep]], [level[keep]]
    half = 0.5 * (block_hi[select] - block_lo[select])
    for offset in np.stack(np.meshgrid(*[[0, 1]] * ndim, indexing="ij"), axis=-1).reshape(-1, ndim):
        shift = np.zeros(3)
        shift[:ndim] = offset
        child_lo = block_lo[select] + shift * half
        out_lo.append(child_lo)
        out_hi.append(child_lo + np.where(np.arange(3) < ndim, half, 0.0))
        out_level.append(level[select] + 1)
    return np.concatenate(out_lo), np.concatenate(out_hi), np.concatenate(out_level)


def make_snapshot(geometry, block_lo, block_hi, level, cells, material_density, occupancy,
                  velocity=None, sub=3):
    """A Snapshot whose volume fractions sample ``occupancy`` on sub x sub (x sub) points per cell.

    occupancy(x, y, z) -> (M, ...) fraction of each material at the points (mesh coordinates);
    partial density = alpha_k * material_density[k]; velocity(x, y, z) -> (3, ...) at cell
    centres (zeros if None).  In 2d-cylindrical the samples are weighted by r.
    """
    ndim = 3 if geometry == "3d" else 2
    nb = block_lo.shape[0]
    shape = tuple(cells[a] if a < ndim else 1 for a in range(3))
    snap = Snapshot(
        time=10.0, geometry=geometry, material_names=[f"m{k}" for k in range(len(material_density))],
        block_lo=block_lo, block_hi=block_hi, block_level=np.asarray(level, dtype=np.int64),
        block_id=1000 + np.arange(nb, dtype=np.int64),
        partial_density=np.zeros((nb, len(material_density)) + shape),
        volume_fraction=np.zeros((nb, len(material_density)) + shape),
        velocity=np.zeros((nb, 3) + shape), specific_internal_energy=np.zeros((nb,) + shape),
        pressure=np.zeros((nb,) + shape), temperature=np.zeros((nb,) + shape),
        sound_speed=np.ones((nb,) + shape),
    )
    samples = []
    for axis in range(3):
        edges = snap.cell_edges(axis)
        s = sub if axis < ndim else 1
        frac = (np.arange(s) + 0.5) / s
        pts = edges[:, :-1, None] + (edges[:, 1:] - edges[:, :-1])[:, :, None] * frac  # (NB, n, s)
        bshape = [nb, 1, 1, 1, 1, 1, 1]
        bshape[1 + 2 * axis], bshape[2 + 2 * axis] = pts.shape[1], s
        samples.append(pts.reshape(bshape))
    x, y, z = np.broadcast_arrays(*samples)
    weight = x if geometry == "2d-cylindrical" else np.ones_like(x)
    occ = occupancy(x, y, z)
    alpha = (occ * weight).sum(axis=(3, 5, 7)) / weight.sum(axis=(2, 4, 6))[None]
    snap.volume_fraction = np.moveaxis(alpha, 0, 1)
    snap.partial_density = snap.volume_fraction * np.asarray(material_density, float)[None, :, None, None, None]
    if velocity is not None:
        c = snap.block_cell_centers()
        snap.velocity = np.moveaxis(velocity(c[:, 0], c[:, 1], c[:, 2]), 0, 1)
    return snap


def sphere_occupancy(radius, centre, geometry):
    """One material filling the ball |x - centre| <= radius (2d-cylindrical: r, z mesh axes)."""
    def occupancy(x, y, z):
        if geometry == "3d":
            d2 = (x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2
        else:
            d2 = x**2 + (y - centre[2]) ** 2
        return (d2 <= radius**2).astype(float)[None]
    return occupancy


def uniform_sphere(geometry, radius=1000.0, centre=(0.0, 0.0, 150.0)):
    """A static ball of density RHO on a two-level mesh refined where its surface crosses blocks.

    The block grid is shifted off the ball's centre so that the cut surface blocks are not
    symmetric about it.
    """
    centre = np.asarray(centre, float)
    shift = np.array([0.1, -0.07, 0.13]) * radius
    if geometry == "3d":
        ndim, cells, sub = 3, (4, 4, 4), 3
        lo, hi = block_grid(centre - 1.2 * radius + shift, centre + 1.2 * radius + shift, (10, 10, 10))
    else:
        ndim, cells, sub = 2, (8, 8, 1), 4
        lo, hi = block_grid([0.0, centre[2] - 1.2 * radius + shift[2], 0.0],
                            [1.2 * radius, centre[2] + 1.2 * radius + shift[2], 0.0], (5, 10, 0))
    level = np.zeros(lo.shape[0], dtype=np.int64)
    mesh_centre = centre if geometry == "3d" else np.array([0.0, centre[2], 0.0])
    nearest = np.clip(mesh_centre, lo, hi) - mesh_centre
    farthest = np.maximum(np.abs(lo - mesh_centre), np.abs(hi - mesh_centre))
    crosses = (np.linalg.norm(nearest, axis=1) < radius) & (np.linalg.norm(farthest, axis=1) > radius)
    lo, hi, level = refine(lo, hi, level, crosses, ndim)
    return make_snapshot(geometry, lo, hi, level, cells, [RHO], sphere_occupancy(radius, centre, geometry), sub=sub)


def handoff(snap, tracers=None, **kwargs):
    """blocks_to_spheres with the test bodies' defaults."""
    args = dict(target_bulk_density=RHO, total_mass=snap.block_masses().sum(), escape_speed=1.0)
    args.update(kwargs)
    return blocks_to_spheres(snap, tracers, **args)


def random_flow_snapshot(geometry, seed=7):
    """Two materials with random partial densities and velocities on a two-level mesh.

    Some blocks hold only traces of material (below the default mass floor), some none.
    In 2d-cylindrical the mesh touches the axis and has blocks whose mass sits in the
    innermost cell column only.
    """
    rng = np.random.default_rng(seed)
    if geometry == "3d":
        ndim, cells = 3, (4, 4, 4)
        lo, hi = block_grid([-400.0, -400.0, -400.0], [400.0, 400.0, 400.0], (4, 4, 4))
    else:
        ndim, cells = 2, (6, 6, 1)
        lo, hi = block_grid([0.0, -600.0, 0.0], [600.0, 600.0, 0.0], (3, 6, 0))
    level = np.zeros(lo.shape[0], dtype=np.int64)
    lo, hi, level = refine(lo, hi, level, rng.random(lo.shape[0]) < 0.4, ndim)
    snap = make_snapshot(geometry, lo, hi, level, cells, [RHO, 7800.0], lambda x, y, z: np.zeros((2,) + x.shape), sub=1)
    shape = snap.partial_density.shape
    snap.partial_density = rng.uniform(0.0, 1.0, shape) * np.array([RHO, 7800.0])[None, :, None, None, None]
    nb = shape[0]
    traces = rng.random(nb) < 0.15
    snap.partial_density[traces] *= 1e-9
    snap.partial_density[rng.random(nb) < 0.1] = 0.0
    if geometry == "2d-cylindrical":
        axis_blocks = np.flatnonzero(snap.block_lo[:, 0] == 0.0)
        snap.partial_density[axis_blocks[:3], :, 1:] = 0.0  # mass in the innermost column only
    drift = np.array([50.0, -80.0, 120.0])[None, :, None, None, None]
    snap.velocity = rng.normal(0.0, 300.0, snap.velocity.shape) + drift
    if geometry == "2d-cylindrical":
        snap.velocity[:, 2] = 0.0
    return snap


def direct_mesh_sums(snap):
    """Mass, momentum (mesh components) and kinetic energy summed cell by cell, independently."""
    ndim = snap.ndim
    m = snap.partial_density.sum(axis=1) * snap.block_cell_volumes()
    v = snap.velocity[:, :ndim]
    return m.sum(), (m[:, None] * v).sum(axis=(0, 2, 3, 4)), 0.5 * (m * (v**2).sum(axis=1)).sum()


def mass_moments(particles):
    """Total mass, centre of mass (3,) and radius of gyration of point masses."""
    m = particles.mass
    com = (m[:, None] * particles.position).sum(axis=0) / m.sum()
    rg = np.sqrt((m * ((particles.position - com) ** 2).sum(axis=1)).sum() / m.sum())
    return m.sum(), com, rg


# ---------------------------------------------------------------------------- conservation


def test_3d_mass_and_momentum_conserved():
    snap = random_flow_snapshot("3d")
    mesh_mass, mesh_momentum, mesh_ke = direct_mesh_sums(snap)
    particles, budget = handoff(snap, total_mass=mesh_mass, escape_speed=0.0)
    assert budget.dropped_count > 0 and budget.dropped_mass > 0.0
    assert budget.mesh_mass == pytest.approx(mesh_mass, rel=1e-12)
    assert particles.mass.sum() + budget.dropped_mass == pytest.approx(mesh_mass, rel=1e-12)
    momentum_scale = (snap.partial_density.sum(axis=1) * snap.block_cell_volumes()
                      * np.linalg.norm(snap.velocity, axis=1)).sum()
    particle_momentum = (particles.mass[:, None] * particles.velocity).sum(axis=0)
    np.testing.assert_allclose(particle_momentum + budget.dropped_momentum, mesh_momentum,
                               rtol=0, atol=1e-12 * momentum_scale)
    np.testing.assert_allclose(budget.mesh_momentum, mesh_momentum, rtol=0, atol=1e-12 * momentum_scale)
    # Block by block: each particle carries exactly its block's mass and momentum.
    block_mass = snap.block_masses().sum(axis=1)
    index = np.searchsorted(snap.block_id, particles.source_block)
    np.testing.assert_allclose(particles.mass, block_mass[index], rtol=1e-12)
    cell_mass = snap.partial_density.sum(axis=1) * snap.block_cell_volumes()
    com = (cell_mass[:, None] * snap.block_cell_centers()).sum(axis=(2, 3, 4))[index] / particles.mass[:, None]
    np.testing.assert_allclose(particles.position, com, rtol=0, atol=1e-12 * 400.0)
    block_momentum = (cell_mass[:, None] * snap.velocity).sum(axis=(2, 3, 4))[index]
    np.testing.assert_allclose(particles.mass[:, None] * particles.velocity, block_momentum,
                               rtol=0, atol=1e-12 * momentum_scale)
    # Radius: inscribed in the cube of the smallest edge, shrunk to the density floor if lighter.
    inscribed = 0.5 * (snap.block_hi - snap.block_lo)[index].min(axis=1)
    floor_radius = np.cbrt(3.0 * particles.mass / (4.0 * np.pi * 0.75 * RHO))
    np.testing.assert_allclose(particles.radius, np.minimum(inscribed, floor_radius), rtol=1e-12)
    # Kinetic energy: the particles carry at most the mesh's (dispersion inside blocks is lost).
    assert budget.mesh_kinetic_energy == pytest.approx(mesh_ke, rel=1e-12)
    assert budget.unresolved_kinetic_energy >= -1e-12 * mesh_ke
    assert abs(budget.mass_residual) <= 1e-12 * mesh_mass


def test_2d_cylindrical_mass_axial_and_radial_momentum_conserved():
    snap = random_flow_snapshot("2d-cylindrical")
    mesh_mass, mesh_momentum, mesh_ke = direct_mesh_sums(snap)  # (P_r, P_z)
    particles, budget = handoff(snap, total_mass=mesh_mass, escape_speed=0.0)
    assert budget.dropped_count > 0
    assert particles.mass.sum() + budget.dropped_mass == pytest.approx(mesh_mass, rel=1e-12)

    m, v, x = particles.mass, particles.velocity, particles.position
    cell_mass = snap.partial_density.sum(axis=1) * snap.block_cell_volumes()
    scale = (cell_mass * np.linalg.norm(snap.velocity, axis=1)).sum()
    p_z = (m * v[:, 2]).sum()
    assert abs(p_z + budget.dropped_momentum[2] - mesh_momentum[1]) <= 1e-12 * scale
    e_r = x[:, :2] / np.hypot(x[:, 0], x[:, 1])[:, None]
    p_r = (m * (v[:, :2] * e_r).sum(axis=1)).sum()
    assert abs(p_r + budget.dropped_radial_momentum - mesh_momentum[0]) <= 1e-12 * scale
    assert budget.particle_radial_momentum == pytest.approx(p_r, rel=1e-12)
    # Radial momenta cancel as vectors: no transverse momentum appears.
    assert np.all(np.abs((m[:, None] * v[:, :2]).sum(axis=0)) <= 1e-12 * scale)
    np.testing.assert_array_equal(budget.mesh_momentum[:2], 0.0)
    assert budget.mesh_momentum[2] == pytest.approx(mesh_momentum[1], rel=1e-12)

    # Ring by ring: the spheres of a block carry its mass, P_z and P_r exactly.
    nb = snap.block_id.size
    index = np.searchsorted(snap.block_id, particles.source_block)
    ring_mass = np.bincount(index, weights=m, minlength=nb)
    ring_pz = np.bincount(index, weights=m * v[:, 2], minlength=nb)
    ring_pr = np.bincount(index, weights=m * (v[:, :2] * e_r).sum(axis=1), minlength=nb)
    block_mass = cell_mass.sum(axis=(1, 2, 3))
    block_pr = (cell_mass * snap.velocity[:, 0]).sum(axis=(1, 2, 3))
    block_pz = (cell_mass * snap.velocity[:, 1]).sum(axis=(1, 2, 3))
    made = np.unique(index)
    np.testing.assert_allclose(ring_mass[made], block_mass[made], rtol=1e-12)
    np.testing.assert_allclose(ring_pz[made], block_pz[made], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(ring_pr[made], block_pr[made], rtol=0, atol=1e-12 * scale)
    # Rings sit at the mass-weighted radial centroid rbar and mean height zbar of their block.
    edges = snap.cell_edges(0)
    r_cell = (2.0 / 3.0) * (edges[:, 1:] ** 3 - edges[:, :-1] ** 3) / (edges[:, 1:] ** 2 - edges[:, :-1] ** 2)
    rbar = (cell_mass * r_cell[:, :, None, None]).sum(axis=(1, 2, 3)) / np.where(block_mass > 0, block_mass, 1.0)
    zbar = (cell_mass * snap.block_cell_centers()[:, 1]).sum(axis=(1, 2, 3)) / np.where(block_mass > 0, block_mass, 1.0)
    np.testing.assert_allclose(np.hypot(x[:, 0], x[:, 1]), rbar[index], rtol=1e-12)
    np.testing.assert_allclose(x[:, 2], zbar[index], rtol=0, atol=1e-12 * 600.0)
    # Every sphere of a ring has the same mass.
    np.testing.assert_allclose(m, block_mass[index] / np.bincount(index, minlength=nb)[index], rtol=1e-12)
    assert budget.unresolved_kinetic_energy >= -1e-12 * mesh_ke


@pytest.mark.parametrize("geometry", ["3d", "2d-cylindrical"])
def test_velocity_noise_amplitude_and_seed(geometry):
    snap = random_flow_snapshot(geometry)
    escape = 25.0
    quiet, quiet_budget = handoff(snap, escape_speed=escape, velocity_noise=0.0, seed=3)
    noisy, budget = handoff(snap, escape_speed=escape, velocity_noise=0.01, seed=3)
    np.testing.assert_array_equal(noisy.position, quiet.position)  # same seed, same ring phases
    kick = noisy.velocity - quiet.velocity
    np.testing.assert_allclose(np.linalg.norm(kick, axis=1), 0.01 * escape, rtol=1e-9)
    assert budget.noise_speed == pytest.approx(0.25)
    # Isotropic: the mean direction is within 5 sigma of zero (sigma = 1/sqrt(3N) per component).
    unit = kick / np.linalg.norm(kick, axis=1)[:, None]
    assert np.all(np.abs(unit.mean(axis=0)) < 5.0 / np.sqrt(3.0 * len(noisy)))
    # Momentum before the noise is untouched; the budget reports what the noise added.
    np.testing.assert_array_equal(budget.particle_momentum, quiet_budget.particle_momentum)
    np.testing.assert_allclose(budget.noise_momentum, (noisy.mass[:, None] * kick).sum(axis=0),
                               rtol=1e-9, atol=1e-9 * (noisy.mass * 0.25).sum())
    ke = 0.5 * (noisy.mass * (noisy.velocity**2).sum(axis=1)).sum()
    assert budget.particle_kinetic_energy_with_noise == pytest.approx(ke, rel=1e-12)
    assert budget.noise_kinetic_energy == pytest.approx(ke - quiet_budget.particle_kinetic_energy, rel=1e-9)

    again, _ = handoff(snap, escape_speed=escape, seed=3)
    other, _ = handoff(snap, escape_speed=escape, seed=4)
    for f in fields(ParticleSet):
        np.testing.assert_array_equal(getattr(again, f.name), getattr(noisy, f.name))
    assert not np.array_equal(other.velocity, noisy.velocity)


# ---------------------------------------------------------------------------- geometry


@pytest.mark.parametrize("geometry", ["3d", "2d-cylindrical"])
def test_uniform_sphere_mass_centre_and_gyration(geometry):
    radius = 1000.0
    centre = np.array([0.0, 0.0, 150.0]) if geometry == "2d-cylindrical" else np.array([120.0, -80.0, 150.0])
    snap = uniform_sphere(geometry, radius, centre)
    true_mass = 4.0 / 3.0 * np.pi * radius**3 * RHO
    particles, budget = handoff(snap, total_mass=true_mass)
    mass, com, rg = mass_moments(particles)
    assert mass == pytest.approx(true_mass, rel=0.02)
    assert np.linalg.norm(com - centre) < 0.02 * radius
    assert rg == pytest.approx(np.sqrt(0.6) * radius, rel=0.02)
    density = particles.mass / (4.0 / 3.0 * np.pi * particles.radius**3)
    assert np.all(density >= 0.75 * RHO * (1.0 - 1e-12))
    assert budget.radius_shrunk_count > 0  # surface blocks hit the floor
    # Full blocks: the inscribed sphere holds the block's mass, so the density is 6/pi RHO.
    full = snap.volume_fraction[:, 0].min(axis=(1, 2, 3)) == 1.0
    index = np.searchsorted(snap.block_id, particles.source_block)
    if geometry == "3d":
        np.testing.assert_allclose(density[full[index]], 6.0 / np.pi * RHO, rtol=1e-12)
    assert np.all(particles.radius <= 0.5 * (snap.block_hi - snap.block_lo)[index, : snap.ndim].min(axis=1))


def test_uniform_sphere_2d_and_3d_agree():
    """The same ball handed off from 2d-cylindrical and from 3d: mass, centre, gyration within 2 %."""
    radius = 1000.0
    centre = np.array([0.0, 0.0, 150.0])
    results = []
    for geometry in ("2d-cylindrical", "3d"):
        snap = uniform_sphere(geometry, radius, centre)
        particles, _ = handoff(snap, total_mass=4.0 / 3.0 * np.pi * radius**3 * RHO)
        results.append(mass_moments(particles))
    (m2, c2, g2), (m3, c3, g3) = results
    assert m2 == pytest.approx(m3, rel=0.02)
    assert np.linalg.norm(c2 - c3) < 0.02 * radius
    assert g2 == pytest.approx(g3, rel=0.02)


def test_ring_sphere_count_rule():
    rbar = np.array([0.1, 1.0, 2.0, 10.0, 1000.0])
    count = ring_sphere_count(rbar, np.ones(5))
    np.testing.assert_array_equal(count, [2, 2, 6, 31, 3141])
    # Neighbours on a ring never overlap unless the ring is narrower than a sphere radius (n = 2).
    wide = count > 2
    assert np.all(2.0 * rbar[wide] * np.sin(np.pi / count[wide]) >= 2.0 - 1e-12)
    assert np.all(2.0 * rbar[wide] * np.sin(np.pi / (count[wide] + 1)) < 2.0)


def test_2d_axis_blocks_give_distinct_positions_off_axis():
    snap = random_flow_snapshot("2d-cylindrical")
    particles, _ = handoff(snap, min_mass_fraction=0.0)
    on_axis_blocks = snap.block_id[snap.block_lo[:, 0] == 0.0]
    assert np.isin(particles.source_block, on_axis_blocks).sum() > 0
    assert np.all(np.hypot(particles.position[:, 0], particles.position[:, 1]) > 0.0)
    assert np.unique(particles.position, axis=0).shape[0] == len(particles)
    # REBOUND's tree accepts them all (it raises for two particles at one point).
    sim = rebound.Simulation()
    sim.G = G
    sim.gravity = "tree"
    sim.collision = "none"
    sim.root_size = 4.0 * np.abs(particles.position).max()
    for m, x, v in zip(particles.mass, particles.position, particles.velocity):
        sim.add(m=m, x=x[0], y=x[1], z=x[2], vx=v[0], vy=v[1], vz=v[2])
    sim.integrator = "leapfrog"
    sim.dt = 1e-3
    sim.integrate(2e-3)
    assert sim.N == len(particles)


def test_rings_have_random_phases():
    snap = uniform_sphere("2d-cylindrical")
    particles, _ = handoff(snap)
    first = np.unique(particles.source_block, return_index=True)[1]
    phase = np.arctan2(particles.position[first, 1], particles.position[first, 0])
    assert np.unique(np.round(phase, 12)).size == phase.size


# ---------------------------------------------------------------------------- floors


def trace_block_snapshot():
    """Two 3d blocks: one full of material, one with 1e-6 of one cell's mass in one cell."""
    lo = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]])
    snap = make_snapshot("3d", lo, lo + 100.0, [0, 0], (2, 2, 2), [RHO], lambda x, y, z: np.ones((1,) + x.shape))
    snap.partial_density[1] = 0.0
    snap.partial_density[1, 0, 0, 0, 0] = 1e-6 * RHO
    snap.velocity[1] = 40.0
    return snap


def test_trace_block_is_dropped_and_reported():
    snap = trace_block_snapshot()
    trace_mass = 1e-6 * RHO * 50.0**3
    particles, budget = handoff(snap)
    assert len(particles) == 1 and particles.source_block[0] == snap.block_id[0]
    assert budget.dropped_count == 1
    assert budget.dropped_mass == pytest.approx(trace_mass, rel=1e-12)
    np.testing.assert_allclose(budget.dropped_momentum, 40.0 * trace_mass, rtol=1e-12)
    assert budget.dropped_kinetic_energy == pytest.approx(0.5 * trace_mass * 3 * 40.0**2, rel=1e-12)


def test_trace_block_above_mass_floor_is_shrunk_not_lightened():
    snap = trace_block_snapshot()
    trace_mass = 1e-6 * RHO * 50.0**3
    particles, budget = handoff(snap, min_mass_fraction=0.0)
    assert len(particles) == 2 and budget.dropped_count == 0
    light = particles.source_block == snap.block_id[1]
    assert particles.mass[light][0] == pytest.approx(trace_mass, rel=1e-12)  # mass unchanged
    density = particles.mass / (4.0 / 3.0 * np.pi * particles.radius**3)
    assert density[light][0] == pytest.approx(0.75 * RHO, rel=1e-12)
    assert particles.radius[light][0] < 1.0  # not a 50 m sphere
    assert particles.radius[~light][0] == pytest.approx(50.0)  # full block: inscribed sphere
    assert budget.radius_shrunk_count == 1


def test_overlaps_reported_for_shifted_centre_of_mass():
    # A full block beside a block filled on its half towards A: B's centre of mass sits 75 m
    # from A's, its density (0.5 x 6/pi RHO) is above the floor, so the radii stay 50 m.
    lo = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]])
    snap = make_snapshot("3d", lo, lo + 100.0, [0, 0, 0], (2, 2, 2), [RHO],
                         lambda x, y, z: np.where(x < 150.0, 1.0, 0.0)[None])
    particles, budget = handoff(snap)
    np.testing.assert_allclose(particles.radius, 50.0)
    assert budget.overlapping_pairs == 1  # A-C touch, B-C are farther apart than 100 m
    assert budget.deepest_overlap == pytest.approx(0.25, rel=1e-12)


def test_block_moments_do_not_depend_on_chunking():
    snap = random_flow_snapshot("2d-cylindrical")
    whole, chunked = block_moments(snap), block_moments(snap, chunk=5)
    for name in ("material_mass", "mass", "centre", "momentum", "kinetic_energy", "min_edge"):
        np.testing.assert_allclose(getattr(chunked, name), getattr(whole, name), rtol=1e-14, atol=0)


# ---------------------------------------------------------------------------- merged blocks


def split_blocks(snap, select):
    """The same fields on a mesh where the selected blocks are split into 2^ndim children
    (and those children's first one split once more): every fine cell takes the value of the
    coarse cell it lies in, so the fine mesh holds exactly the coarse one's mass and momentum."""
    ndim = snap.ndim
    n = snap.partial_density.shape[2]
    arrays = ("partial_density", "volume_fraction", "velocity", "specific_internal_energy", "pressure",
              "temperature", "sound_speed")

    def children(lo, hi, level, values, depth):
        """Blocks of the parent (lo, hi) split ``depth`` more times in its first child."""
        out = []
        half = 0.5 * (hi - lo)
        for offset in np.stack(np.meshgrid(*[[0, 1]] * ndim, indexing="ij"), axis=-1).reshape(-1, ndim):
            shift = np.zeros(3)
            shift[:ndim] = offset * half[:ndim]
            c_lo, c_hi = lo + shift, lo + shift + np.where(np.arange(3) < ndim, half, 0.0)
            index = [slice(None)] * 3
            for a in range(ndim):
                index[a] = (offset[a] * n + np.arange(n)) // 2
            grid = np.ix_(*[np.atleast_1d(i) if isinstance(i, np.ndarray) else np.arange(1) for i in index])
            child = {k: v[(slice(None),) + grid] if v.ndim == 4 else v[grid] for k, v in values.items()}
            if depth > 1 and not offset.any():
                out.extend(children(c_lo, c_hi, level + 1, child, depth - 1))
            else:
                out.append((c_lo, c_hi, level + 1, child))
        return out

    blocks = []
    for b in range(snap.block_lo.shape[0]):
        values = {k: getattr(snap, k)[b] for k in arrays}
        if select[b]:
            blocks.extend(children(snap.block_lo[b], snap.block_hi[b], snap.block_level[b], values, 2))
        else:
            blocks.append((snap.block_lo[b], snap.block_hi[b], snap.block_level[b], values))
    return Snapshot(
        time=snap.time, geometry=snap.geometry, material_names=snap.material_names,
        block_lo=np.array([b[0] for b in blocks]), block_hi=np.array([b[1] for b in blocks]),
        block_level=np.array([b[2] for b in blocks], dtype=np.int64),
        block_id=np.arange(len(blocks), dtype=np.int64),
        **{k: np.array([b[3][k] for b in blocks]) for k in arrays},
    )


@pytest.mark.parametrize("geometry", ["3d", "2d-cylindrical"])
def test_merged_fine_blocks_are_the_coarse_mesh_blocks(geometry):
    """Blocks split one and two levels below a coarse mesh, merged back to the coarse edge,
    have the coarse blocks' mass, material masses, centre of mass, momentum and cell kinetic
    energy (the radial centroids of fine annuli add up to the coarse annulus's)."""
    coarse = random_flow_snapshot(geometry, seed=3)
    keep = coarse.block_level == 0
    coarse = Snapshot(**{f.name: (getattr(coarse, f.name)[keep] if isinstance(getattr(coarse, f.name), np.ndarray)
                                  else getattr(coarse, f.name)) for f in fields(Snapshot)})
    select = np.random.default_rng(5).random(coarse.block_lo.shape[0]) < 0.5
    fine = split_blocks(coarse, select)
    edge = float((coarse.block_hi - coarse.block_lo)[0, 0])
    assert fine.block_lo.shape[0] > coarse.block_lo.shape[0] and (fine.block_level == 2).any()
    merged = merge_fine_blocks(block_moments(fine), fine.ndim, edge)
    want = block_moments(coarse)
    order_m = np.lexsort(merged.lo.T[::-1])
    order_w = np.lexsort(want.lo.T[::-1])
    assert merged.mass.size == want.mass.size
    for name in ("lo", "hi", "min_edge", "level"):
        np.testing.assert_allclose(getattr(merged, name)[order_m], getattr(want, name)[order_w], rtol=1e-12)
    scale = {"material_mass": want.mass.max(), "mass": want.mass.max(), "centre": edge,
             "momentum": np.abs(want.momentum).max(), "kinetic_energy": want.kinetic_energy.max()}
    for name, size in scale.items():
        np.testing.assert_allclose(getattr(merged, name)[order_m], getattr(want, name)[order_w], rtol=0,
                                   atol=1e-12 * size)


def test_hand_off_from_merged_blocks_conserves_and_reports():
    snap = uniform_sphere("2d-cylindrical")
    edges = np.unique((snap.block_hi - snap.block_lo)[:, 0])
    assert edges.size == 2
    plain, plain_budget = handoff(snap)
    particles, budget = handoff(snap, block_edge=float(edges[1]))
    assert budget.sphere_blocks < plain_budget.sphere_blocks == snap.block_lo.shape[0] == budget.n_blocks
    assert budget.block_edge == edges[1] and plain_budget.block_edge is None
    assert len(particles) < len(plain)
    assert particles.radius.max() <= 0.5 * edges[1] and particles.radius.max() > 0.5 * edges[0]
    assert abs(budget.mass_residual) <= 1e-12 * budget.mesh_mass
    np.testing.assert_allclose(budget.particle_momentum + budget.dropped_momentum, budget.mesh_momentum,
                               atol=1e-9 * budget.mesh_mass)
    assert budget.unresolved_kinetic_energy >= -1e-9 * budget.mesh_kinetic_energy
    np.testing.assert_array_equal(particles.source_level, 0)


@pytest.mark.parametrize("geometry", ["3d", "2d-cylindrical"])
def test_target_kinetic_energy_of_a_homologously_expanding_ball(geometry):
    """A ball expanding homologously, v = c (x - x0) + V, has K = (2 pi / 5) rho c^2 R^5 within
    its radius in its centre-of-mass frame (the drift V removed), and 1/32 of it within R / 2."""
    radius, rate, drift = 1000.0, 0.01, np.array([0.0, 0.0, 40.0])
    snap = uniform_sphere(geometry)
    centre = np.array([0.0, 150.0, 0.0]) if geometry == "2d-cylindrical" else np.array([0.0, 0.0, 150.0])
    mesh_drift = np.array([0.0, 40.0, 0.0]) if geometry == "2d-cylindrical" else drift
    c = snap.block_cell_centers()
    snap.velocity = rate * (c - centre[None, :, None, None, None]) + mesh_drift[None, :, None, None, None]
    if geometry == "2d-cylindrical":
        snap.velocity[:, 2] = 0.0
    exact = 2.0 * np.pi / 5.0 * RHO * rate**2 * radius**5
    assert target_kinetic_energy(snap, 1.5 * radius) == pytest.approx(exact, rel=0.01)
    assert target_kinetic_energy(snap, 0.5 * radius) == pytest.approx(exact / 32.0, rel=0.05)
    assert target_kinetic_energy(snap, 1.5 * radius, chunk=7) == pytest.approx(
        target_kinetic_energy(snap, 1.5 * radius), rel=1e-12)


def test_merging_to_an_edge_no_ancestor_has_is_refused():
    moments = block_moments(uniform_sphere("3d"))
    edge = float(moments.min_edge.min())
    with pytest.raises(ValueError, match="not a power-of-two multiple"):
        merge_fine_blocks(moments, 3, 1.5 * edge)
    assert merge_fine_blocks(moments, 3, edge) is moments


# ---------------------------------------------------------------------------- tracers


def tracer_set(position, material, peak_pressure, initial_position, exited):
    n = len(material)
    return TracerSet(
        id=np.arange(n, dtype=np.int64), material=np.asarray(material),
        initial_position=np.asarray(initial_position, float),
        position=np.asarray(position, float), velocity=np.zeros((n, 3)), peak_pressure=np.asarray(peak_pressure, float),
        peak_pressure_time=np.zeros(n), peak_temperature=np.zeros(n), exited=np.asarray(exited, bool),
        exit_time=np.where(exited, 1.0, np.nan),
    )


def test_tracer_association_peak_pressure_and_nearest_fill():
    # A: level 0, edge 2; B, C, D: level 1, edge 1.  A holds target (3000) and projectile (1000).
    lo = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0], [2.0, 1.0, 0.0]])
    hi = lo + np.array([[2.0, 2.0, 2.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, 1.0]])
    snap = make_snapshot("3d", lo, hi, [0, 1, 1, 1], (2, 2, 2), [3000.0, 1000.0],
                         lambda x, y, z: np.stack([np.ones_like(x), np.where(x < 2.0, 1.0, 0.0)]))
    tracers = tracer_set(
        position=[[0.5, 0.5, 0.5], [1.5, 1.5, 1.5], [0.2, 1.8, 1.0],   # A
                  [2.5, 0.5, 0.5], [2.0, 0.5, 0.5],                    # B (second on the A|B face)
                  [3.5, 0.5, 0.5],                                     # C
                  [3.5, 0.6, 0.5],                                     # exited (sits in C)
                  [9.0, 9.0, 9.0]],                                    # in no block
        material=[0, 1, 0, 0, 0, 0, 0, 0],
        peak_pressure=[1e9, 3e9, 2e9, 5e9, 7e9, 2e9, 9e9, 9e9],
        initial_position=[[10.0, 0, 0], [20.0, 0, 0], [16.0, 0, 0], [1, 2, 3], [3, 4, 5], [7, 7, 7],
                          [0, 0, 0], [0, 0, 0]],
        exited=[False] * 6 + [True, False],
    )
    particles, budget = handoff(snap, tracers, total_mass=1e6, projectile_material_index=1)
    by_block = {int(b): i for i, b in enumerate(particles.source_block)}
    a, b, c, d = (by_block[int(i)] for i in snap.block_id)
    np.testing.assert_array_equal(particles.tracer_count[[a, b, c, d]], [3, 2, 1, 0])
    assert particles.peak_pressure_mean[a] == pytest.approx(2e9)
    assert particles.peak_pressure_max[a] == 3e9
    assert particles.peak_pressure_mean[b] == pytest.approx(6e9)
    assert particles.peak_pressure_max[b] == 7e9
    # Origin: target mass 3x projectile mass; two target tracers share 3/4, the projectile one 1/4.
    assert particles.origin_position[a, 0] == pytest.approx((1.5 * 10.0 + 1.5 * 16.0 + 1.0 * 20.0) / 4.0)
    np.testing.assert_allclose(particles.origin_position[b], [2.0, 3.0, 4.0])
    assert particles.projectile_fraction[a] == pytest.approx(0.25)
    assert particles.projectile_fraction[b] == 0.0
    np.testing.assert_array_equal(particles.source_level[[a, b]], [0, 1])
    # D has no tracer: its two nearest particles with tracers are B (1 m away) and C (1.41 m).
    assert particles.peak_pressure_mean[d] == pytest.approx(0.5 * (6e9 + 2e9))
    assert np.isnan(particles.peak_pressure_max[d]) and np.all(np.isnan(particles.origin_position[d]))
    assert (budget.tracers_total, budget.tracers_used, budget.tracers_exited, budget.tracers_outside) == (8, 6, 1, 1)


def test_2d_ring_spheres_share_their_block_tracers():
    snap = uniform_sphere("2d-cylindrical")
    centre = 0.5 * (snap.block_lo + snap.block_hi)
    tracers = tracer_set(position=centre, material=np.zeros(len(centre), int),
                         peak_pressure=np.arange(len(centre), dtype=float) * 1e8,
                         initial_position=centre, exited=np.zeros(len(centre), bool))
    particles, budget = handoff(snap, tracers)
    index = np.searchsorted(snap.block_id, particles.source_block)
    np.testing.assert_array_equal(particles.tracer_count, 1)
    np.testing.assert_array_equal(particles.peak_pressure_mean, index * 1e8)
    assert budget.tracers_used + budget.tracers_in_dropped == len(centre)


# ---------------------------------------------------------------------------- I/O


def test_write_read_round_trip(tmp_path):
    snap = random_flow_snapshot("2d-cylindrical")
    centre = 0.5 * (snap.block_lo + snap.block_hi)[::3]
    tracers = tracer_set(position=centre, material=np.ones(len(centre), int), peak_pressure=np.full(len(centre), 4e9),
                         initial_position=centre, exited=np.zeros(len(centre), bool))
    particles, budget = handoff(snap, tracers, projectile_material_index=1, mass_left_mesh=123.0)
    path = tmp_path / "handoff.h5"
    write_particles(path, particles, budget, {"git_commit": "abc", "start_time": "now"})
    back = read_particles(path)
    for f in fields(ParticleSet):
        original, restored = getattr(particles, f.name), getattr(back, f.name)
        assert restored.dtype == original.dtype
        np.testing.assert_array_equal(restored, original)
    budget_back = read_budget(path)
    assert isinstance(budget_back, HandoffBudget)
    assert budget_back.to_summary() == budget.to_summary()
    assert budget_back.mass_left_mesh == 123.0
    with h5py.File(path, "r") as h5:
        assert h5.attrs["git_commit"] == "abc"
        for name in PARTICLE_UNITS:
            assert h5["particles"][name].attrs["units"] == PARTICLE_UNITS[name]
        for name in h5["budget"]:
            assert h5["budget"][name].attrs["units"] == BUDGET_UNITS[name]
    assert not [p for p in tmp_path.iterdir() if p.name != "handoff.h5"]  # no temporary left


def test_3d_budget_round_trip_and_summary_types(tmp_path):
    particles, budget = handoff(trace_block_snapshot())
    path = tmp_path / "handoff.h5"
    write_particles(path, particles, budget, {})
    back = read_budget(path)
    assert back.mesh_radial_momentum is None and back.mass_left_mesh is None
    summary = back.to_summary()
    assert summary == budget.to_summary()
    for key, value in summary.items():
        assert value is None or type(value) in (float, int, str, list), key
        if isinstance(value, list):
            assert len(value) == 3 and all(type(x) is float for x in value)


def test_a_hand_off_file_without_the_distension_reads_it_as_unknown(tmp_path):
    """Files written before particles carried their distension: read as NaN (unknown), the rest as written."""
    particles, budget = handoff(trace_block_snapshot())
    assert (particles.distension == 1.0).all()  # no porous material
    path = tmp_path / "handoff.h5"
    write_particles(path, particles, budget, {})
    with h5py.File(path, "r+") as h5:
        del h5["particles"]["distension"]
    back = read_particles(path)
    assert back.distension.shape == particles.mass.shape and np.isnan(back.distension).all()
    np.testing.assert_array_equal(back.mass, particles.mass)


def test_units_mismatch_is_refused(tmp_path):
    particles, budget = handoff(trace_block_snapshot())
    path = tmp_path / "handoff.h5"
    write_particles(path, particles, budget, {})
    with h5py.File(path, "r+") as h5:
        h5["particles"]["mass"].attrs["units"] = "g"
    with pytest.raises(ValueError, match="units"):
        read_particles(path)


def test_rejects_unsupported_geometry_and_bad_arguments():
    snap = trace_block_snapshot()
    with pytest.raises(ValueError, match="total_mass"):
        handoff(snap, total_mass=0.0)
    with pytest.raises(ValueError, match="projectile_material_index"):
        handoff(snap, projectile_material_index=1)
    snap.geometry = "2d-planar"
    with pytest.raises(ValueError, match="geometry"):
        handoff(snap)
