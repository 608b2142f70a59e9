"""Figures are written with the intended data; analysis.h5 round trip with units."""

import h5py
import numpy as np
import pytest

from impactpipe.analysis import (
    comparison_laws,
    cumulative_mass_fraction,
    find_remnants,
    fit_qstar,
    plot_cumulative_pressure,
    plot_origin_positions,
    plot_qstar,
    plot_velocity_distribution,
    read_analysis,
    write_analysis,
)
from impactpipe.analysis.plots import (
    cumulative_pressure_figure,
    origin_figure,
    qstar_figure,
    speed_ratio,
    velocity_distribution_figure,
)

PNG = b"\x89PNG\r\n\x1a\n"


def assert_png(path):
    data = path.read_bytes()
    assert data[:8] == PNG and len(data) > 5000


def test_cumulative_pressure_figure(tmp_path):
    p = np.array([1e8, 1e9, 1e9, 1e10])
    m = np.array([1.0, 1.0, 2.0, 4.0])
    curve = cumulative_mass_fraction(p, m)
    fig = cumulative_pressure_figure({"all": curve})
    ax = fig.axes[0]
    assert ax.get_xscale() == "log"
    np.testing.assert_allclose(ax.lines[0].get_xdata(), [1e8, 1e9, 1e10])
    np.testing.assert_allclose(ax.lines[0].get_ydata(), [1.0, 7 / 8, 4 / 8])
    assert "Pa" in ax.get_xlabel()
    assert_png(plot_cumulative_pressure(tmp_path / "cum.png", {"all": curve, "largest": curve}))


def test_origin_figure_cross_section_and_colours(tmp_path):
    rng = np.random.default_rng(0)
    pos = rng.uniform(-1e4, 1e4, (400, 3))
    p = 10 ** rng.uniform(8, 10, 400)
    fig = origin_figure(pos, p, slab_half_width=2e3)
    ax2d = fig.axes[0]
    sel = np.abs(pos[:, 1]) <= 2e3
    offsets = ax2d.collections[0].get_offsets()
    np.testing.assert_allclose(offsets, pos[sel][:, [0, 2]] / 1e3)
    np.testing.assert_allclose(ax2d.collections[0].get_array(), np.log10(p[sel]))
    assert ax2d.get_xlabel() == "Pre-impact x (km)"
    assert_png(plot_origin_positions(tmp_path / "origin.png", pos, p))


def test_velocity_distribution(tmp_path):
    vel = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 10.0, 0], [0, -10.0, 0]])
    mass = np.array([1.0, 1.0, 3.0, 3.0])
    np.testing.assert_allclose(speed_ratio(vel, mass, 2.0), [0.5, 0.5, 5.0, 5.0])
    fig = velocity_distribution_figure(vel, mass, 2.0, bins=4)
    values, edges = fig.axes[0].patches[0].get_data()[:2]
    assert values.sum() == pytest.approx(1.0)
    assert values[0] == pytest.approx(0.25) and values[-1] == pytest.approx(0.75)
    np.testing.assert_allclose(edges[[0, -1]], [0.5, 5.0])
    assert_png(plot_velocity_distribution(tmp_path / "vel.png", vel, mass, 2.0))


def test_qstar_figure(tmp_path):
    q = np.linspace(500.0, 2800.0, 6)
    y = 1.0 - 0.5 * q / 1790.0
    y[-1] = 0.05
    n_lr = np.array([1500, 1500, 900, 400, 150, 90])
    fit = fit_qstar(q, y, n_lr, n_bootstrap=100)
    radius = np.logspace(2, 5, 30)
    laws = comparison_laws(radius, 2700.0, 0.083**3)
    fig = qstar_figure(q, y, n_lr, fit, target_radius=1e4, comparisons={k: (radius, v) for k, v in laws.items()})
    ax = fig.axes[0]
    line = next(ln for ln in ax.lines if ln.get_label().startswith("fit"))
    np.testing.assert_allclose(line.get_ydata(), fit.predict(line.get_xdata()))
    np.testing.assert_allclose(ax.lines[2].get_xdata(), q[~fit.used])
    assert len(fig.axes[1].lines) >= 3
    assert_png(plot_qstar(tmp_path / "qstar.png", q, y, n_lr, fit))
    pdf = plot_qstar(tmp_path / "qstar.pdf", q, y, n_lr, fit)
    assert pdf.read_bytes()[:4] == b"%PDF"


def test_qstar_figure_shows_the_mean_and_scatter_of_replicates(tmp_path):
    q = np.repeat([800.0, 1600.0, 2400.0], [3, 1, 2])
    y = np.array([0.70, 0.80, 0.75, 0.52, 0.30, 0.20])
    fit = fit_qstar(q, y, np.full(6, 1000), n_bootstrap=50)
    (bars,) = qstar_figure(q, y, np.full(6, 1000), fit).axes[0].containers
    marker = bars.lines[0]
    np.testing.assert_allclose(marker.get_xdata(), [800.0, 2400.0])
    np.testing.assert_allclose(marker.get_ydata(), [0.75, 0.25])
    (segments,) = bars.lines[2]
    half = [abs(seg[1, 1] - seg[0, 1]) / 2.0 for seg in segments.get_segments()]
    np.testing.assert_allclose(half, [0.05, np.sqrt(0.005)])
    assert qstar_figure(q[[0, 3, 4]], y[[0, 3, 4]], np.full(3, 1000),
                        fit_qstar(q[[0, 3, 4]], y[[0, 3, 4]], np.full(3, 1000), n_bootstrap=20)).axes[0].containers == []


def test_analysis_h5_round_trip(tmp_path):
    pos = np.array([[0.0, 0, 0], [100.0, 0, 0], [5e4, 0, 0]])
    res = find_remnants(np.full(3, 1e9), np.full(3, 50.0), pos, np.zeros((3, 3)), target_mass=2e9)
    q = np.array([800.0, 1600.0, 2400.0])
    fit = fit_qstar(q, [0.8, 0.55, 0.3], [500, 500, 500], n_bootstrap=50)
    path = write_analysis(tmp_path / "analysis.h5", {"remnants": res.as_datasets(), "qstar": fit.as_datasets()},
                          attrs={"git_commit": "abc"})
    with h5py.File(path) as fh:
        names = []
        fh.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
        assert names and all("units" in fh[n].attrs for n in names)
    data = read_analysis(path)
    assert data.attrs["git_commit"] == "abc"
    assert float(data["remnants/mlr_over_mt"]) == pytest.approx(1.0)
    assert data.units["remnants/mass"] == "kg"
    assert data.units["qstar/qstar"] == "J/kg"
    assert data["remnants/mode"] == "aggregate"
    off, members = data["remnants/members_offset"], data["remnants/members"]
    np.testing.assert_array_equal(members[off[0]:off[1]], [0, 1])
    assert float(data["qstar/qstar"]) == pytest.approx(fit.qstar)


def test_write_analysis_requires_units(tmp_path):
    with pytest.raises(TypeError, match="units"):
        write_analysis(tmp_path / "a.h5", {"mass": np.ones(3)})
    assert not (tmp_path / "a.h5").exists()
