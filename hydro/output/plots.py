"""Figures of hydro snapshots: field slices with block outlines, line plots in 1D.

2D geometries show the (x, y) or (r, z) plane, with 2d-cylindrical runs mirrored about
the axis (the usual figure of an axisymmetric impact); 3d snapshots show the y = 0
plane (the impact plane, which is the symmetry plane of a half-domain run).  Each
block is drawn with its own cell grid, so every refinement level shows, and the block
outlines are drawn on top.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm, Normalize  # noqa: E402

from impactpipe.storage import atomic_path  # noqa: E402

from .snapshot import Snapshot  # noqa: E402

#: Fields that can be plotted: snapshot attribute or derived quantity -> (label, units, log scale).
FIELDS = {
    "density": ("density", "kg m$^{-3}$", False),
    "pressure": ("pressure", "Pa", True),
    "temperature": ("temperature", "K", True),
    "specific_internal_energy": ("specific internal energy", "J kg$^{-1}$", True),
    "sound_speed": ("sound speed", "m s$^{-1}$", False),
    "speed": ("speed", "m s$^{-1}$", True),
    "volume_fraction": ("material volume fraction (sum)", "", False),
}


def block_field(snapshot: Snapshot, field: str) -> np.ndarray:
    """(NB, nx, ny, nz) values of ``field`` (a key of :data:`FIELDS`)."""
    if field == "density":
        return snapshot.density
    if field == "speed":
        return np.sqrt((snapshot.velocity ** 2).sum(axis=1))
    if field == "volume_fraction":
        return snapshot.volume_fraction.sum(axis=1)
    if field not in FIELDS:
        raise ValueError(f"unknown field {field!r}; choose one of {', '.join(FIELDS)}")
    return getattr(snapshot, field)


def slice_figure(snapshot: Snapshot, field: str, outlines: bool = True):
    """A matplotlib Figure of ``field`` on the snapshot's plane (see the module docstring)."""
    label, units, log = FIELDS[field] if field in FIELDS else (field, "", False)
    values = block_field(snapshot, field)
    fig, ax = plt.subplots(figsize=(7.0, 6.0), constrained_layout=True)
    if snapshot.ndim == 1:
        x = snapshot.block_cell_centers()[:, 0, :, 0, 0].reshape(-1)
        order = np.argsort(x)
        ax.plot(x[order], values[:, :, 0, 0].reshape(-1)[order], "-", lw=1.2)
        ax.set_xlabel("x (m)")
        ax.set_ylabel(f"{label} ({units})" if units else label)
        if log:
            ax.set_yscale("symlog")
        ax.set_title(f"t = {snapshot.time:.4g} s")
        return fig
    axis_a, axis_b, planes = _plane(snapshot)
    finite = np.concatenate([values[b][planes[b]].ravel() for b in range(values.shape[0])]) if len(values) else []
    finite = np.asarray(finite)
    positive = finite[np.isfinite(finite) & (finite > 0)]
    if log and positive.size:
        norm = LogNorm(vmin=max(positive.min(), positive.max() * 1e-8), vmax=positive.max())
    else:
        good = finite[np.isfinite(finite)]
        norm = Normalize(vmin=good.min() if good.size else 0.0, vmax=good.max() if good.size else 1.0)
    mirror = snapshot.geometry == "2d-cylindrical"
    mesh = None
    for b in range(values.shape[0]):
        if planes[b] is None:
            continue
        ea = snapshot.cell_edges(axis_a)[b]
        eb = snapshot.cell_edges(axis_b)[b]
        data = values[b][planes[b]]
        data = np.where(data > 0, data, np.nan) if log else data
        for sign in ((1.0, -1.0) if mirror else (1.0,)):
            mesh = ax.pcolormesh(sign * ea, eb, data.T, norm=norm, cmap="viridis", shading="flat")
            if outlines:
                lo_a, hi_a = sign * ea[0], sign * ea[-1]
                ax.plot([lo_a, hi_a, hi_a, lo_a, lo_a], [eb[0], eb[0], eb[-1], eb[-1], eb[0]],
                        color="white", lw=0.3, alpha=0.7)
    names = {"2d-cylindrical": ("r (m)", "z (m)"), "2d-planar": ("x (m)", "y (m)"), "3d": ("x (m)", "z (m)")}
    ax.set_xlabel(names[snapshot.geometry][0])
    ax.set_ylabel(names[snapshot.geometry][1])
    ax.set_aspect("equal")
    where = " (y = 0 plane)" if snapshot.geometry == "3d" else ""
    ax.set_title(f"{label}, t = {snapshot.time:.4g} s{where}")
    if mesh is not None:
        fig.colorbar(mesh, ax=ax, label=f"{label} ({units})" if units else label)
    return fig


def _plane(snapshot: Snapshot):
    """(axis_a, axis_b, per-block index selecting the plotted plane or None)."""
    nb = snapshot.block_lo.shape[0]
    if snapshot.ndim == 2:
        return 0, 1, [(slice(None), slice(None), 0)] * nb
    planes = []
    edges = snapshot.cell_edges(1)
    for b in range(nb):
        inside = np.nonzero((edges[b, :-1] <= 0.0) & (edges[b, 1:] > 0.0))[0]
        planes.append((slice(None), int(inside[0]), slice(None)) if inside.size else None)
    if all(p is None for p in planes):
        lowest = snapshot.block_lo[:, 1].min()
        planes = [(slice(None), 0, slice(None)) if snapshot.block_lo[b, 1] == lowest else None for b in range(nb)]
    return 0, 2, planes


def plot_snapshot(path: str | Path, snapshot: Snapshot, field: str, outlines: bool = True) -> Path:
    """Write the slice figure of ``field`` to ``path`` (PNG or PDF by suffix), atomically."""
    path = Path(path)
    fig = slice_figure(snapshot, field, outlines)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=150, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path


def axis_ray(tracers, impact_point: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """(distance from the impact point (m), peak pressure (Pa)) of the target tracers on the
    ray closest to the symmetry axis (2d-cylindrical tracer layout of place_on_rays)."""
    r0 = tracers.initial_position[:, 0]
    z0 = tracers.initial_position[:, 1]
    dz = impact_point[1] - z0
    angle = np.arctan2(r0 - impact_point[0], dz)
    target = (tracers.material == 0) & np.isfinite(tracers.peak_pressure)
    if not target.any():
        raise ValueError("no target tracer with a recorded peak pressure")
    first = angle[target].min()
    on_ray = target & (angle <= first * (1 + 1e-6) + 1e-12)
    distance = np.hypot(r0[on_ray] - impact_point[0], dz[on_ray])
    order = np.argsort(distance)
    return distance[order], tracers.peak_pressure[on_ray][order]


def plot_peak_pressure_along_axis_ray(path: str | Path, tracers, impact_point: tuple[float, float]) -> float:
    """Log-log figure of peak pressure against distance along the axis ray; returns the
    least-squares power-law exponent d ln P / d ln r over the ray's far half."""
    distance, peak = axis_ray(tracers, impact_point)
    far = distance >= np.median(distance)
    good = far & (peak > 0)
    slope = float(np.polyfit(np.log(distance[good]), np.log(peak[good]), 1)[0]) if good.sum() >= 2 else float("nan")
    fig, ax = plt.subplots(figsize=(6.0, 4.5), constrained_layout=True)
    ax.loglog(distance, peak, "o-", ms=3, lw=1)
    ax.set_xlabel("distance from the impact point (m)")
    ax.set_ylabel("peak pressure (Pa)")
    ax.set_title(f"tracers on the axis ray; far-half slope {slope:.2f}")
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=150, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return slope
