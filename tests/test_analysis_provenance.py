"""Cumulative peak-pressure distributions and the final-to-hand-off provenance map."""

import numpy as np
import pytest

from impactpipe.analysis import cumulative_mass_fraction, find_remnants, provenance_owner, shock_history


def test_cumulative_fraction_hand_built():
    # masses 1, 2, 3, 4 kg at 1, 2, 2, 3 GPa (+ one particle without a pressure)
    p = np.array([2e9, 1e9, 3e9, 2e9, np.nan])
    m = np.array([2.0, 1.0, 4.0, 3.0, 100.0])
    pressure, fraction = cumulative_mass_fraction(p, m)
    np.testing.assert_array_equal(pressure, [1e9, 2e9, 3e9])
    # >= 1 GPa: all 10 kg; >= 2 GPa: 9 kg; >= 3 GPa: 4 kg
    np.testing.assert_allclose(fraction, [1.0, 0.9, 0.4])


def test_cumulative_fraction_is_mass_weighted_and_monotone():
    rng = np.random.default_rng(2)
    p = 10 ** rng.uniform(8, 11, 500)
    m = rng.uniform(0.5, 2.0, 500)
    pressure, fraction = cumulative_mass_fraction(p, m)
    assert fraction[0] == 1.0
    assert np.all(np.diff(pressure) > 0)
    assert np.all(np.diff(fraction) <= 0)
    # F at the median-by-mass pressure is the mass fraction above it, not the count fraction
    k = 250
    assert fraction[k] == pytest.approx(m[p >= pressure[k]].sum() / m.sum())
    # doubling one particle's mass changes F accordingly
    m2 = m.copy()
    top = np.argmax(p)
    m2[top] *= 2
    _, f2 = cumulative_mass_fraction(p, m2)
    assert f2[-1] == pytest.approx(m2[top] / m2.sum())


def test_provenance_owner_inverts_csr():
    offset = [0, 2, 3, 3, 5]
    members = [10, 12, 11, 14, 15]
    owner = provenance_owner(offset, members, [10, 11, 12, 13, 14, 15, 16])
    np.testing.assert_array_equal(owner, [0, 1, 0, -1, 3, 3, -1])
    with pytest.raises(ValueError, match="not hand-off ids"):
        provenance_owner([0, 1], [99], [10, 11])
    with pytest.raises(ValueError, match="more than one"):
        provenance_owner([0, 1, 2], [10, 10], [10, 11])
    with pytest.raises(ValueError, match="members_offset"):
        provenance_owner([0, 3], [10, 11], [10, 11])


def test_shock_history_splits():
    # final state: a 27-particle clump at the origin and a 8-particle clump far away, receding
    r = 50.0
    g = np.arange(3) * 2 * r
    big = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3) - 2 * r
    small = np.stack(np.meshgrid(g[:2], g[:2], g[:2], indexing="ij"), -1).reshape(-1, 3) + [1e5, 0, 0]
    final_pos = np.vstack([big, small])
    nf = len(final_pos)
    vel = np.zeros((nf, 3))
    vel[27:, 0] = 10.0
    mass_f = np.full(nf, 1.4e9)
    rem = find_remnants(mass_f, np.full(nf, r), final_pos, vel)
    assert rem.largest.n_particles == 27 and rem.second_largest.n_particles == 8
    # hand-off: two hand-off particles per final particle plus 5 escaped ones
    nh = 2 * nf + 5
    ids = np.arange(1, nh + 1)
    members = ids[: 2 * nf]
    offset = np.arange(0, 2 * nf + 1, 2)
    owner = provenance_owner(offset, members, ids)
    rng = np.random.default_rng(0)
    mass_h = rng.uniform(1, 2, nh)
    p_h = 10 ** rng.uniform(8, 10, nh)
    curves = shock_history(p_h, mass_h, owner, rem, final_pos)
    in_lr = owner[: 2 * nf] < 27
    assert curves["all"].mass == pytest.approx(mass_h.sum())
    assert curves["largest"].mass == pytest.approx(mass_h[: 2 * nf][in_lr].sum())
    assert curves["second_largest"].mass == pytest.approx(mass_h[54 : 2 * nf].sum())
    # interior: 0.75 R_bulk = 0.75 (27 r^3 / 0.64)^(1/3) = 130.5 m, which holds the centre
    # (0 m) and the 6 face particles (100 m) but not edges (141 m) or corners (173 m)
    r_bulk = rem.largest.bulk_radius
    assert 0.75 * r_bulk == pytest.approx(0.75 * r * (27 / 0.64) ** (1 / 3))
    d = np.linalg.norm(big - rem.largest.com, axis=1)
    inner = d < 0.75 * r_bulk
    assert inner.sum() == 7
    inner_h = np.repeat(inner, 2)
    assert curves["largest_interior"].mass == pytest.approx(mass_h[:54][inner_h].sum())
    assert curves["largest_interior"].mass + curves["largest_exterior"].mass == pytest.approx(
        curves["largest"].mass)
    for curve in curves.values():
        assert curve.fraction[0] == pytest.approx(1.0)
        assert np.all(np.diff(curve.fraction) <= 0)
