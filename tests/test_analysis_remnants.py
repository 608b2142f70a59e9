"""Remnant finder on constructed particle sets with known answers."""

import numpy as np
from scipy.constants import G
import pytest

from impactpipe.analysis import find_remnants, touching_groups

RHO = 2700.0
R = 50.0
M = 4.0 / 3.0 * np.pi * RHO * R**3  # one grain, kg


def cubic_clump(n_side, centre, spacing=2 * R):
    """n_side^3 grains on a simple cubic lattice of the given spacing (touching at 2R)."""
    g = np.arange(n_side) * spacing
    x = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    return x - x.mean(axis=0) + np.asarray(centre, dtype=float)


def hcp_ball(n_cells, radius_cut):
    """Grains of radius R on a hexagonal close-packed lattice (touching), inside a ball."""
    pts = []
    for k in range(-n_cells, n_cells + 1):
        for j in range(-n_cells, n_cells + 1):
            for i in range(-n_cells, n_cells + 1):
                x = 2 * R * (i + 0.5 * (j % 2)) + R * (k % 2)
                y = np.sqrt(3.0) * R * j + R / np.sqrt(3.0) * (k % 2)
                z = 2 * R * np.sqrt(2.0 / 3.0) * k
                pts.append((x, y, z))
    pts = np.array(pts)
    return pts[np.linalg.norm(pts, axis=1) <= radius_cut]


def test_touching_groups_links_only_touching_spheres():
    pos = np.array([[0, 0, 0], [2 * R, 0, 0], [4 * R + 1.0, 0, 0], [1e4, 0, 0]], dtype=float)
    labels = touching_groups(pos, np.full(4, R), link_factor=1.0)
    assert labels[0] == labels[1]
    assert len({labels[1], labels[2], labels[3]}) == 3
    # a large sphere touches small ones in another radius class
    pos = np.array([[0, 0, 0], [10 * R + R, 0, 0], [0, 10 * R + R + 0.5, 0]], dtype=float)
    labels = touching_groups(pos, np.array([10 * R, R, R]))
    assert labels[0] == labels[1] != labels[2]


def test_two_separated_clumps_have_known_masses():
    a = cubic_clump(5, [0, 0, 0])
    b = cubic_clump(3, [2e4, 0, 0])
    pos = np.vstack([a, b])
    vel = np.zeros_like(pos)
    vel[len(a):, 0] = 5.0  # clump B recedes far above the mutual escape speed (~0.3 m/s)
    n = len(pos)
    m_t = 125 * M
    res = find_remnants(np.full(n, M), np.full(n, R), pos, vel, target_mass=m_t)
    lr, slr = res.largest, res.second_largest
    assert lr.n_particles == 125 and slr.n_particles == 27
    assert lr.mass == pytest.approx(125 * M, rel=1e-12)
    assert slr.mass == pytest.approx(27 * M, rel=1e-12)
    np.testing.assert_array_equal(lr.members, np.arange(125))
    np.testing.assert_array_equal(slr.members, np.arange(125, 152))
    assert res.mlr_over_mt == pytest.approx(1.0)
    assert res.mslr_over_mt == pytest.approx(27 / 125)
    assert lr.bound_mass == pytest.approx(lr.mass)  # B is not bound to A
    np.testing.assert_allclose(slr.velocity, [5.0, 0, 0])
    np.testing.assert_allclose(lr.com, [0, 0, 0], atol=1e-9)
    assert np.all(res.label[:125] == 0) and np.all(res.label[125:] == 1)


def test_bound_satellite_and_fast_particle():
    clump = cubic_clump(5, [0, 0, 0])
    m_clump = 125 * M
    r_sat = 2000.0
    v_circ = np.sqrt(G * m_clump / r_sat)
    sat_bound = [r_sat, 0, 0]
    sat_free = [0, r_sat, 0]
    fast = [0, 0, clump[:, 2].max() + 2 * R]  # sits on top of the clump, touching it
    pos = np.vstack([clump, sat_bound, sat_free, fast])
    vel = np.zeros_like(pos)
    vel[125] = [0, 0.5 * v_circ, 0]  # elliptic orbit: bound
    vel[126] = [1.5 * v_circ, 0, 0]  # above escape speed sqrt(2) v_circ: unbound
    vel[127] = [0, 0, 10.0]  # ~35 times the clump's escape speed
    n = len(pos)
    res = find_remnants(np.full(n, M), np.full(n, R), pos, vel, target_mass=m_clump)
    lr = res.largest
    # the fast particle touched the clump (same friends-of-friends group) but is unbound
    assert touching_groups(pos, np.full(n, R))[127] == touching_groups(pos, np.full(n, R))[0]
    np.testing.assert_array_equal(lr.members, np.arange(125))
    # the satellite does not touch: not a member of the aggregate, but bound to it
    np.testing.assert_array_equal(lr.bound_members, np.arange(126))
    assert lr.bound_mass == pytest.approx(126 * M)
    assert res.mlr_over_mt == pytest.approx(1.0)
    assert res.converged


@pytest.mark.parametrize("factor, bound", [(0.95, True), (1.05, False)])
def test_two_touching_spheres_bound_below_mutual_escape_speed(factor, bound):
    pos = np.array([[-R, 0, 0], [R, 0, 0]])
    v_esc = np.sqrt(2 * G * 2 * M / (2 * R))
    u = factor * v_esc  # relative speed, separating
    vel = np.array([[-u / 2, 0, 0], [u / 2, 0, 0]])
    res = find_remnants(np.full(2, M), np.full(2, R), pos, vel)
    assert res.largest.n_particles == (2 if bound else 1)


def test_rubble_pile_gives_total_mass_and_spin():
    pos = hcp_ball(5, 7.5 * R)
    n = len(pos)
    assert n > 100
    omega = np.array([0.0, 0.0, 2 * np.pi / 20000.0])  # 20000 s period, far below breakup
    vel = np.cross(omega, pos)
    res = find_remnants(np.full(n, M), np.full(n, R), pos, vel, link_factor=1.0 + 1e-9, target_mass=n * M,
                        packing_fraction=0.64)
    lr = res.largest
    assert lr.n_particles == n and len(res.remnants) == 1
    assert lr.mass == pytest.approx(n * M)
    assert lr.spin_period == pytest.approx(20000.0, rel=1e-9)
    np.testing.assert_allclose(lr.angular_velocity, omega, atol=1e-15)
    assert lr.bulk_radius == pytest.approx((n * R**3 / 0.64) ** (1 / 3))
    assert lr.bulk_density == pytest.approx(0.64 * RHO)
    assert lr.extent == pytest.approx(np.linalg.norm(pos - pos.mean(axis=0), axis=1).max() + R)


def test_merge_mode_largest_particle_plus_bound():
    m_big, r_big = 1000 * M, 10 * R
    v_circ = np.sqrt(G * m_big / (5 * r_big))
    pos = np.array([
        [0, 0, 0],                 # 0 big particle
        [5 * r_big, 0, 0],         # 1 orbiting, bound
        [0, -5 * r_big, 0],        # 2 escaping
        [3e4, 0, 0],               # 3 second body, receding fast
        [3e4, 6 * R, 0],           # 4 grain orbiting the second body
    ], dtype=float)
    vel = np.zeros_like(pos)
    vel[1] = [0, 0.7 * v_circ, 0]
    vel[2] = [0, -3 * v_circ, 0]
    vel[3] = [20.0, 0, 0]
    v_circ2 = np.sqrt(G * 50 * M / (6 * R))
    vel[4] = [20.0 - 0.5 * v_circ2, 0, 0]
    mass = np.array([m_big, M, M, 50 * M, M])
    radius = np.array([r_big, R, R, 50 ** (1 / 3) * R, R])
    res = find_remnants(mass, radius, pos, vel, mode="merge", target_mass=m_big)
    np.testing.assert_array_equal(res.largest.members, [0, 1])
    np.testing.assert_array_equal(res.second_largest.members, [3, 4])
    assert res.largest.mass == pytest.approx(1001 * M)
    assert res.mlr_over_mt == pytest.approx(1.001)
    assert res.mslr_over_mt == pytest.approx(0.051)


def test_invalid_arguments_raise():
    with pytest.raises(ValueError, match="mode"):
        find_remnants(np.ones(1), np.ones(1), np.zeros((1, 3)), np.zeros((1, 3)), mode="fof")
    with pytest.raises(ValueError, match="positive"):
        find_remnants(np.zeros(1), np.ones(1), np.zeros((1, 3)), np.zeros((1, 3)))
