"""VTKHDF export of snapshots for ParaView: file layout, cell geometry, read-back with VTK, CLI."""

import json

import h5py
import numpy as np
import pytest
from amr_snapshots import LEAF_SETS, handmade_snapshot, sedov_run
from click.testing import CliRunner

from impactpipe.hydro.output import export
from impactpipe.hydro.output.export import write_vtkhdf
from impactpipe.pipeline.cli import main


def read_cells(path):
    """(corner coordinates (NC, corners, 3), CellData dict) of a written file."""
    with h5py.File(path, "r") as fh:
        root = fh["VTKHDF"]
        points = root["Points"][()]
        offsets = root["Offsets"][()]
        connectivity = root["Connectivity"][()]
        corners = offsets[1] - offsets[0]
        assert (np.diff(offsets) == corners).all()
        cells = {name: ds[()] for name, ds in root["CellData"].items()}
        return points[connectivity.reshape(-1, corners)], cells


@pytest.mark.parametrize("geometry", sorted(LEAF_SETS))
def test_vtkhdf_layout_and_units(tmp_path, geometry):
    snapshot = handmade_snapshot(geometry)
    path = write_vtkhdf(snapshot, tmp_path / "snap.vtkhdf", {"git_commit": "abc"})
    n_cells = snapshot.volumes.size
    with h5py.File(path, "r") as fh:
        root = fh["VTKHDF"]
        assert root.attrs["Type"] == b"UnstructuredGrid" and list(root.attrs["Version"]) == [1, 0]
        corners = 2 ** snapshot.ndim
        assert root["NumberOfCells"][()].tolist() == [n_cells]
        assert root["NumberOfConnectivityIds"][()].tolist() == [n_cells * corners]
        assert root["NumberOfPoints"][()].tolist() == [len(root["Points"])]
        assert set(root["Types"][()].tolist()) == {{1: 3, 2: 9, 3: 12}[snapshot.ndim]}
        cells = root["CellData"]
        assert cells["density"].attrs["units"] == "kg/m**3" and cells["pressure"].attrs["units"] == "Pa"
        assert cells["velocity"].shape == (n_cells, 3) and cells["velocity"].attrs["units"] == "m/s"
        assert cells["volume_fraction_basalt_projectile"].attrs["units"] == "dimensionless"
        assert cells["temperature"].attrs["units"] == "K" and "damage" in cells
        assert sorted(cells["level"][()].tolist()) == sorted(np.repeat(snapshot.block_level,
                                                                       n_cells // len(snapshot.block_level)))
        assert root["FieldData/time"][()].tolist() == [1.25]
        meta = fh["impactpipe"].attrs
        assert meta["time"] == 1.25 and meta["geometry"] == geometry and meta["git_commit"] == "abc"
        assert json.loads(meta["material_names"]) == ["basalt", "basalt (projectile)"]
        assert json.loads(meta["field_units"])["specific_internal_energy"] == "J/kg"


@pytest.mark.parametrize("geometry", sorted(LEAF_SETS))
def test_cells_sit_where_the_snapshot_cells_are(tmp_path, geometry):
    snapshot = handmade_snapshot(geometry)
    corners, cells = read_cells(write_vtkhdf(snapshot, tmp_path / "snap.vtkhdf"))
    ndim = snapshot.ndim
    centres = corners.mean(axis=1)[:, :ndim]
    widths = corners.max(axis=1) - corners.min(axis=1)
    assert (widths[:, ndim:] == 0).all()  # cells lie in the x(-y) plane / on the x axis
    # every leaf cell once, with its own size and values
    written = np.lexsort(centres.T)
    leaves = np.lexsort(snapshot.centers.T)
    np.testing.assert_allclose(centres[written], snapshot.centers[leaves], rtol=1e-14, atol=1e-14)
    size = np.repeat(snapshot.cell_size[:, :ndim], snapshot.volumes.size // len(snapshot.block_level), axis=0)
    np.testing.assert_allclose(np.sort(np.prod(widths[:, :ndim], axis=1)), np.sort(np.prod(size, axis=1)), rtol=1e-14)
    fields = snapshot.fields
    np.testing.assert_array_equal(cells["density"][written], fields["density"][leaves])
    np.testing.assert_array_equal(cells["velocity"][written, :ndim], fields["velocity"][leaves])
    np.testing.assert_array_equal(cells["partial_density_basalt"][written], fields["partial_density"][leaves, 0])


def test_cells_share_their_corner_points(tmp_path):
    snapshot = handmade_snapshot("2d-planar")  # 2 x 2 blocks of 4 x 4 cells, one split into 4 blocks
    path = write_vtkhdf(snapshot, tmp_path / "snap.vtkhdf")
    with h5py.File(path, "r") as fh:
        points = fh["VTKHDF/Points"][()]
    assert len(np.unique(points, axis=0)) == len(points)
    # the 9 x 9 points of the level-0 cells, plus the refined block's 9 x 9 less its 5 x 5 coarse ones
    assert len(points) == 9 * 9 + (9 * 9 - 5 * 5)


def test_failed_write_leaves_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "snap.vtkhdf"
    path.write_bytes(b"old")

    def broken(snapshot):
        raise RuntimeError("interrupted")

    monkeypatch.setattr(export, "cell_fields", broken)
    with pytest.raises(RuntimeError):
        write_vtkhdf(handmade_snapshot("2d-planar"), path)
    assert path.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["snap.vtkhdf"]


@pytest.mark.parametrize("geometry", sorted(LEAF_SETS))
def test_vtk_reads_the_leaf_cells_and_their_mass(tmp_path, geometry):
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    snapshot = handmade_snapshot(geometry)
    reader = vtk.vtkHDFReader()
    reader.SetFileName(str(write_vtkhdf(snapshot, tmp_path / "snap.vtkhdf")))
    reader.Update()
    grid = reader.GetOutputDataObject(0)
    assert grid.IsA("vtkUnstructuredGrid") and grid.GetNumberOfCells() == snapshot.volumes.size
    sizes = vtk.vtkCellSizeFilter()
    sizes.SetInputData(grid)
    sizes.Update()
    measure_name = {1: "Length", 2: "Area", 3: "Volume"}[snapshot.ndim]
    measure = vtk_to_numpy(sizes.GetOutput().GetCellData().GetArray(measure_name))
    density = vtk_to_numpy(grid.GetCellData().GetArray("density"))
    if geometry == "2d-cylindrical":  # an annulus of section A at radius r_c has volume 2 pi r_c A
        centres = vtk.vtkCellCenters()
        centres.SetInputData(grid)
        centres.Update()
        measure = measure * 2 * np.pi * vtk_to_numpy(centres.GetOutput().GetPoints().GetData())[:, 0]
    assert (density * measure).sum() == pytest.approx(snapshot.block_masses().sum(), rel=1e-12)
    assert grid.GetCellData().GetArray("velocity").GetNumberOfComponents() == 3
    assert grid.GetFieldData().GetArray("time").GetValue(0) == 1.25


def test_export_command_writes_the_chosen_snapshots(tmp_path):
    snapshots = sedov_run(tmp_path / "run")
    runner = CliRunner()
    result = runner.invoke(main, ["export", str(tmp_path / "run"), "--time", "0.009"])
    assert result.exit_code == 0, result.output
    written = tmp_path / "run" / "export" / "hydro_0001.vtkhdf"
    assert f"wrote {written}" in result.output
    with h5py.File(written, "r") as fh:
        assert fh["impactpipe"].attrs["time"] == snapshots[1].time
        assert fh["VTKHDF/NumberOfCells"][0] == snapshots[1].volumes.size
        assert fh["impactpipe"].attrs["snapshot_index"] == "1"
    result = runner.invoke(main, ["export", str(tmp_path / "run"), "--out", str(tmp_path / "last.vtkhdf")])
    assert result.exit_code == 0, result.output
    with h5py.File(tmp_path / "last.vtkhdf", "r") as fh:
        assert fh["impactpipe"].attrs["time"] == snapshots[-1].time
    result = runner.invoke(main, ["export", str(tmp_path / "run"), "--all"])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in (tmp_path / "run" / "export").iterdir()) == [
        "hydro_0000.vtkhdf", "hydro_0001.vtkhdf", "hydro_0002.vtkhdf"]


def test_export_command_refuses_bad_requests(tmp_path):
    runner = CliRunner()
    result = runner.invoke(main, ["export", str(tmp_path)])
    assert result.exit_code == 2 and "no hydro.h5" in result.output
    result = runner.invoke(main, ["export", str(tmp_path), "--all", "--time", "1"])
    assert result.exit_code == 2 and "--all" in result.output
    result = runner.invoke(main, ["export", str(tmp_path), "--format", "xdmf"])
    assert result.exit_code == 2
