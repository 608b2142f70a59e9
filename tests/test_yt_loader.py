"""Snapshots in yt: the completed block hierarchy, geometry, units, fields and totals."""

import numpy as np
import pytest
import yt
from amr_snapshots import LEAF_SETS, handmade_snapshot, refine_block, sedov_run

from impactpipe.hydro.output.hierarchy import complete_hierarchy
from impactpipe.hydro.output.snapshot import Snapshot
from impactpipe.hydro.output.yt_loader import load, to_yt

yt.set_log_level(40)


def hierarchy_cell_volumes(hierarchy):
    """(NG, nx, ny, nz) physical cell volumes of every block of a hierarchy (m^3)."""
    probe = Snapshot(time=0.0, geometry=hierarchy.geometry, material_names=[], block_lo=hierarchy.lo,
                     block_hi=hierarchy.hi, block_level=hierarchy.level, block_id=hierarchy.level,
                     partial_density=np.zeros((len(hierarchy.level), 0) + hierarchy.cells_per_block),
                     volume_fraction=None, velocity=None, specific_internal_energy=None, pressure=None,
                     temperature=None, sound_speed=None)
    return probe.block_cell_volumes()


@pytest.mark.parametrize("geometry", sorted(LEAF_SETS))
def test_every_level_holds_the_mass_momentum_and_energy_of_the_leaves(geometry):
    snapshot = handmade_snapshot(geometry)
    hierarchy = complete_hierarchy(snapshot)
    fields = {f.name: f.values for f in hierarchy.fields}
    volume = hierarchy_cell_volumes(hierarchy)
    mass = fields["density"] * volume
    leaf_mass = snapshot.block_masses().sum()
    leaf_momentum = (snapshot.density * snapshot.velocity[:, 0] * snapshot.block_cell_volumes()).sum()
    leaf_energy = (snapshot.density * snapshot.specific_internal_energy * snapshot.block_cell_volumes()).sum()
    first_velocity = "velocity_r" if geometry == "2d-cylindrical" else "velocity_x"
    assert hierarchy.is_leaf.sum() == len(snapshot.block_level) and not hierarchy.is_leaf.all()
    momentum_scale = (snapshot.density * np.abs(snapshot.velocity[:, 0]) * snapshot.block_cell_volumes()).sum()
    for level in range(int(hierarchy.level.max()) + 1):
        # the blocks of this level and the leaves of coarser levels tile the domain once
        layer = (hierarchy.level == level) | (hierarchy.is_leaf & (hierarchy.level < level))
        assert mass[layer].sum() == pytest.approx(leaf_mass, rel=1e-12)
        assert (mass * fields[first_velocity])[layer].sum() == pytest.approx(leaf_momentum, abs=1e-12 * momentum_scale)
        assert (mass * fields["specific_internal_energy"])[layer].sum() == pytest.approx(leaf_energy, rel=1e-12)
        assert all(np.isfinite(values[layer]).all() for values in fields.values())
    leaves = hierarchy.leaf_index[hierarchy.is_leaf]
    np.testing.assert_array_equal(fields["pressure"][hierarchy.is_leaf], snapshot.pressure[leaves])


def test_incomplete_refinement_and_odd_blocks_are_refused():
    snapshot = handmade_snapshot("2d-planar")
    fine = np.nonzero(snapshot.block_level == 1)[0]
    keep = np.setdiff1d(np.arange(len(snapshot.block_level)), fine[:1])
    missing_child = Snapshot(**{**snapshot.__dict__, **{
        name: getattr(snapshot, name)[keep] for name in (
            "block_lo", "block_hi", "block_level", "block_id", "partial_density", "volume_fraction", "velocity",
            "specific_internal_energy", "pressure", "temperature", "sound_speed")}, "extra": {}})
    with pytest.raises(ValueError, match="3 of its 4 children"):
        complete_hierarchy(missing_child)
    with pytest.raises(ValueError, match="even number of cells"):
        complete_hierarchy(handmade_snapshot("2d-planar", cells=3))


@pytest.mark.parametrize("geometry", sorted(LEAF_SETS))
def test_yt_totals_equal_the_snapshot_totals(geometry):
    snapshot = handmade_snapshot(geometry)
    ds = to_yt(snapshot)
    ad = ds.all_data()
    mass = snapshot.block_masses().sum()
    assert ad["gas", "cell_volume"].size == snapshot.volumes.size  # each leaf cell once
    assert float(ad["gas", "cell_volume"].sum().to("m**3")) == pytest.approx(snapshot.volumes.sum(), rel=1e-12)
    assert float(ad.quantities.total_quantity(("gas", "mass")).to("kg")) == pytest.approx(mass, rel=1e-12)
    coarse = ds.covering_grid(0, ds.domain_left_edge, ds.domain_dimensions)  # the rebuilt level 0
    assert float(coarse["gas", "mass"].sum().to("kg")) == pytest.approx(mass, rel=1e-12)


def test_cylindrical_geometry_units_and_cell_values():
    snapshot = handmade_snapshot("2d-cylindrical")
    ds = to_yt(snapshot)
    assert ds.geometry == "cylindrical" and tuple(ds.coordinates.axis_order) == ("r", "z", "theta")
    assert float(ds.current_time.to("s")) == 1.25 and str(ds.length_unit.units) == "m"
    assert float(ds.domain_right_edge[2]) == pytest.approx(2 * np.pi)
    assert ds.parameters["material_fields"] == ["basalt", "basalt_projectile"]
    ad = ds.all_data()
    units = {"density": "kg/m**3", "pressure": "Pa", "velocity_r": "m/s", "velocity_z": "m/s", "temperature": "K",
             "specific_thermal_energy": "J/kg", "sound_speed": "m/s", "partial_density_basalt": "kg/m**3",
             "volume_fraction_basalt_projectile": "dimensionless", "damage": "dimensionless"}
    for name, unit in units.items():
        assert ad["gas", name].units == yt.units.Unit(unit), name
    # the leaf cells in yt are the snapshot's cells, at the same places
    yt_order = np.lexsort((ad["index", "z"].d, ad["index", "r"].d))
    centers = snapshot.centers
    order = np.lexsort((centers[:, 1], centers[:, 0]))
    np.testing.assert_allclose(ad["index", "r"].d[yt_order], centers[order, 0], rtol=1e-14)
    fields = snapshot.fields
    for yt_name, values in [("density", fields["density"]), ("velocity_z", fields["velocity"][:, 1]),
                            ("sound_speed", fields["sound_speed"]),  # the EOS's, not yt's ideal-gas one
                            ("specific_thermal_energy", fields["specific_internal_energy"]),
                            ("volume_fraction_basalt_projectile", fields["volume_fraction"][:, 1])]:
        np.testing.assert_array_equal(ad["gas", yt_name].d[yt_order], values[order], err_msg=yt_name)


def test_refined_real_snapshot_loads_with_its_mass(tmp_path):
    uniform = sedov_run(tmp_path)[-1]
    snapshot = uniform
    for _ in range(2):  # refine the block at the origin twice: levels 0, 1, 2
        corner = np.nonzero((snapshot.block_lo[:, :2] == 0.0).all(axis=1)
                            & (snapshot.block_level == snapshot.block_level.max()))[0][0]
        snapshot = refine_block(snapshot, corner)
    assert set(snapshot.block_level.tolist()) == {0, 1, 2}
    ds = to_yt(snapshot)
    mass = snapshot.block_masses().sum()
    assert mass == pytest.approx(uniform.block_masses().sum(), rel=1e-13)
    assert float(ds.all_data().quantities.total_quantity(("gas", "mass")).to("kg")) == pytest.approx(mass, rel=1e-12)
    # averaging the injected children gives back the uniform snapshot's cells
    coarse = ds.covering_grid(0, ds.domain_left_edge, ds.domain_dimensions)
    cell = np.floor((uniform.centers - uniform.block_lo.min(axis=0)[:2]) / uniform.cell_size[0, :2]).astype(int)
    for name in ("density", "pressure", "velocity_z"):
        expected = uniform.fields["velocity"][:, 1] if name == "velocity_z" else uniform.fields[name]
        np.testing.assert_allclose(coarse["gas", name].d[cell[:, 0], cell[:, 1], 0], expected, rtol=1e-12,
                                   atol=1e-12 * np.abs(expected).max(), err_msg=name)


def test_load_picks_snapshots_by_time_and_index(tmp_path):
    snapshots = sedov_run(tmp_path)
    by_time = load(tmp_path, time=0.009)
    assert float(by_time.current_time.to("s")) == snapshots[1].time
    assert float(load(tmp_path / "hydro.h5", index=0).current_time) == snapshots[0].time
    last = load(tmp_path)
    assert float(last.current_time) == snapshots[-1].time
    assert float(last.all_data().quantities.total_quantity(("gas", "mass")).to("kg")) == pytest.approx(
        snapshots[-1].block_masses().sum(), rel=1e-12)
    with pytest.raises(ValueError, match="not both"):
        load(tmp_path, time=0.01, index=0)
    with pytest.raises(IndexError):
        load(tmp_path, index=3)
