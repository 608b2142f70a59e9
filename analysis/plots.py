"""Publication figures (matplotlib, Agg backend, SI units on labelled axes).

Each figure has a builder ``*_figure(...) -> matplotlib.figure.Figure`` (no pyplot
state; tests inspect the plotted data) and a writer ``plot_*(path, ...) -> Path``
that saves it atomically (format from the file suffix: .png, .pdf, .svg) and
releases it.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib import colors as mcolors
from matplotlib.figure import Figure

from impactpipe.storage import atomic_path

from .fragments import LaboratoryFragmentation, cumulative_number
from .qstar import QStarFit

matplotlib.use("Agg")

AXIS_NAMES = ("x", "y", "z")
DPI = 200


def save_figure(fig: Figure, path: str | os.PathLike) -> Path:
    """Save ``fig`` to ``path`` atomically; the format comes from the suffix."""
    target = Path(path)
    fmt = target.suffix.lstrip(".").lower() or "png"
    with atomic_path(target) as tmp:
        fig.savefig(tmp, format=fmt, dpi=DPI)
    return target


def cumulative_pressure_figure(curves: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> Figure:
    """Fraction of mass shocked to at least P against peak pressure P.

    Args:
        curves: label -> (pressure ascending (Pa), fraction) as returned by
            :func:`impactpipe.analysis.cumulative_mass_fraction`; pressures <= 0 are
            not drawn (log axis).
    """
    fig = Figure(figsize=(5.0, 3.8), layout="constrained")
    ax = fig.add_subplot()
    for label, (pressure, fraction) in curves.items():
        pressure = np.asarray(pressure, dtype=float)
        keep = pressure > 0
        ax.step(pressure[keep], np.asarray(fraction)[keep], where="post", label=label)
    ax.set_xscale("log")
    ax.set_ylim(0.0, 1.02)
    ax.set_xlabel("Peak shock pressure $P$ (Pa)")
    ax.set_ylabel(r"Mass fraction shocked to $\geq P$")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(frameon=False, fontsize="small")
    return fig


def plot_cumulative_pressure(path, curves) -> Path:
    """Write :func:`cumulative_pressure_figure` to ``path``."""
    return save_figure(cumulative_pressure_figure(curves), path)


def origin_figure(origin_position, peak_pressure, *, axes: tuple[int, int] = (0, 2),
                  slab_half_width: float | None = None, axis_names: tuple[str, str, str] = AXIS_NAMES) -> Figure:
    """Pre-impact positions of material, coloured by log10 peak pressure.

    Left: cross-section in the plane of coordinates ``axes`` (default x-z, the
    plane containing the impact axis z), showing particles within
    ``slab_half_width`` (m) of the plane through the origin along the remaining
    coordinate (all particles when None, i.e. a projection; 2d-cylindrical
    hand-offs have all origins in that plane).  Right: 3D scatter of all
    particles.  Particles without a finite positive peak pressure are not drawn.

    Args:
        origin_position: (N, 3) pre-impact positions (m), hydro mesh coordinates.
        peak_pressure: (N,) peak pressures (Pa).
        axis_names: labels of the three mesh coordinates (("r", "z", "-") for 2d-cylindrical).
    """
    pos = np.asarray(origin_position, dtype=float)
    p = np.asarray(peak_pressure, dtype=float)
    ok = np.isfinite(p) & (p > 0) & np.all(np.isfinite(pos), axis=1)
    pos, logp = pos[ok], np.log10(p[ok])
    h, v = axes
    other = 3 - h - v
    in_slab = np.ones(pos.shape[0], dtype=bool) if slab_half_width is None else np.abs(pos[:, other]) <= slab_half_width
    norm = mcolors.Normalize(vmin=logp.min(), vmax=logp.max()) if logp.size else None
    fig = Figure(figsize=(9.5, 4.2), layout="constrained")
    ax2 = fig.add_subplot(1, 2, 1)
    sc = ax2.scatter(pos[in_slab, h] / 1e3, pos[in_slab, v] / 1e3, c=logp[in_slab], s=4, cmap="inferno",
                     norm=norm, linewidths=0)
    ax2.set_aspect("equal")
    ax2.set_xlabel(f"Pre-impact {axis_names[h]} (km)")
    ax2.set_ylabel(f"Pre-impact {axis_names[v]} (km)")
    title = "projection" if slab_half_width is None else f"|{AXIS_NAMES[other]}| <= {slab_half_width / 1e3:g} km"
    ax2.set_title(f"Cross-section ({title})", fontsize="medium")
    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    ax3.scatter(pos[:, 0] / 1e3, pos[:, 1] / 1e3, pos[:, 2] / 1e3, c=logp, s=2, cmap="inferno", norm=norm,
                linewidths=0)
    ax3.set_aspect("equal")
    ax3.set_xlabel("x (km)")
    ax3.set_ylabel("y (km)")
    ax3.set_zlabel("z (km)")
    fig.colorbar(sc, ax=[ax2, ax3], label=r"$\log_{10}$ peak pressure (Pa)", shrink=0.85)
    return fig


def plot_origin_positions(path, origin_position, peak_pressure, **kwargs) -> Path:
    """Write :func:`origin_figure` to ``path``."""
    return save_figure(origin_figure(origin_position, peak_pressure, **kwargs), path)


def speed_ratio(velocity, mass, escape_speed: float, frame_velocity=None) -> np.ndarray:
    """|v - v_frame| / v_esc per particle; the frame defaults to the mass-weighted mean velocity."""
    vel = np.asarray(velocity, dtype=float)
    m = np.asarray(mass, dtype=float)
    frame = (m[:, None] * vel).sum(axis=0) / m.sum() if frame_velocity is None else np.asarray(frame_velocity)
    return np.linalg.norm(vel - frame, axis=1) / escape_speed


def velocity_distribution_figure(velocity, mass, escape_speed: float, *, frame_velocity=None,
                                 bins: int = 40) -> Figure:
    """Mass fraction per logarithmic bin of speed / escape speed at hand-off.

    Speeds are measured in ``frame_velocity`` (default: the centre-of-mass frame of
    all particles).  Bars sum to the mass fraction with speed > 0; the dashed line
    marks v = v_esc.

    Args:
        velocity: (N, 3) particle velocities (m/s).
        mass: (N,) particle masses (kg).
        escape_speed: reference escape speed (m/s), e.g. of the target.
        bins: number of logarithmic bins.
    """
    m = np.asarray(mass, dtype=float)
    ratio = speed_ratio(velocity, m, escape_speed, frame_velocity)
    pos = ratio > 0
    edges = np.logspace(np.log10(ratio[pos].min()), np.log10(ratio[pos].max()), bins + 1)
    fig = Figure(figsize=(5.0, 3.8), layout="constrained")
    ax = fig.add_subplot()
    fraction, _ = np.histogram(ratio[pos], bins=edges, weights=m[pos] / m.sum())
    ax.stairs(fraction, edges, fill=True, alpha=0.8, edgecolor="k", linewidth=0.6)
    ax.axvline(1.0, color="k", linestyle="--", linewidth=1.0)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(r"Speed / $v_\mathrm{esc}$")
    ax.set_ylabel("Mass fraction per bin")
    return fig


def plot_velocity_distribution(path, velocity, mass, escape_speed, **kwargs) -> Path:
    """Write :func:`velocity_distribution_figure` to ``path``."""
    return save_figure(velocity_distribution_figure(velocity, mass, escape_speed, **kwargs), path)


def qstar_figure(Q, mlr_over_mt, n_lr, fit: QStarFit, *, target_radius: float | None = None,
                 comparisons: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None) -> Figure:
    """Q*_D fit figure.

    Left: M_lr/M_T against Q (J/kg): fitted runs (filled: resolved, open:
    N_lr below the resolution threshold), runs left out (grey crosses), the fitted
    line, Q*_D with its bootstrap 16-84% band, and at each Q with two or more runs
    (replicates: hand-off seeds or times) their mean with an error bar of one sample
    standard deviation (ddof 1).  When ``comparisons`` and
    ``target_radius`` are given, a right panel shows Q*_D against target radius
    (log-log) for each comparison law (label -> (radius (m), Q*_D (J/kg)), e.g.
    from :func:`impactpipe.analysis.energies.comparison_laws`) with this fit as a
    point with error bar.
    """
    q = np.asarray(Q, dtype=float)
    y = np.asarray(mlr_over_mt, dtype=float)
    n = np.asarray(n_lr)
    two = comparisons is not None and target_radius is not None
    fig = Figure(figsize=(9.5 if two else 5.0, 3.8), layout="constrained")
    ax = fig.add_subplot(1, 2 if two else 1, 1)
    resolved = fit.used & (n >= fit.n_lr_resolved)
    under = fit.used & ~resolved
    ax.plot(q[resolved], y[resolved], "o", color="C0", label=f"fitted, $N_{{lr}} \\geq {fit.n_lr_resolved}$")
    ax.plot(q[under], y[under], "o", mfc="none", color="C0",
            label=f"fitted, $N_{{lr}} < {fit.n_lr_resolved}$ (weight {fit.underresolved_weight:g})")
    ax.plot(q[~fit.used], y[~fit.used], "x", color="0.5", label=f"not fitted ($M_{{lr}}/M_T \\leq {fit.min_mlr:g}$)")
    values, group, counts = np.unique(q, return_inverse=True, return_counts=True)
    repeated = counts >= 2
    if repeated.any():
        means = np.bincount(group, weights=y) / counts
        squares = np.bincount(group, weights=(y - means[group]) ** 2)
        std = np.sqrt(squares[repeated] / (counts[repeated] - 1))
        ax.errorbar(values[repeated], means[repeated], yerr=std, fmt="D", color="k", markersize=4, capsize=3,
                    zorder=3, label="mean $\\pm$ std of the runs at one $Q$")
    q_line = np.linspace(0.0, max(q.max(), fit.qstar) * 1.1, 200)
    ax.plot(q_line, fit.predict(q_line), "-", color="C1",
            label=f"fit: slope vs $Q/Q^*_D$ = {fit.normalized_slope:.2f}")
    lo, hi = fit.qstar_interval
    if np.isfinite(lo) and np.isfinite(hi):
        ax.axvspan(lo, hi, color="C1", alpha=0.2, linewidth=0)
    ax.axvline(fit.qstar, color="C1", linestyle="--", linewidth=1.0,
               label=f"$Q^*_D$ = {fit.qstar:.3g} $\\pm$ {fit.qstar_err:.2g} J/kg")
    ax.axhline(0.5, color="k", linewidth=0.5)
    ax.set_xlim(0.0, q_line[-1])
    ax.set_ylim(0.0, 1.0)
    ax.set_xlabel("Specific impact energy $Q$ (J/kg)")
    ax.set_ylabel("$M_{lr}/M_T$")
    ax.legend(frameon=False, fontsize="x-small")
    if two:
        ax_r = fig.add_subplot(1, 2, 2)
        for label, (radius, qd) in comparisons.items():
            ax_r.plot(np.asarray(radius) / 1e3, qd, label=label)
        ax_r.errorbar([target_radius / 1e3], [fit.qstar], yerr=[[fit.qstar_err], [fit.qstar_err]], fmt="o",
                      color="k", label="this work")
        ax_r.set_xscale("log")
        ax_r.set_yscale("log")
        ax_r.set_xlabel("Target radius $R_T$ (km)")
        ax_r.set_ylabel("$Q^*_D$ (J/kg)")
        ax_r.legend(frameon=False, fontsize="x-small")
    return fig


def plot_qstar(path, Q, mlr_over_mt, n_lr, fit: QStarFit, **kwargs) -> Path:
    """Write :func:`qstar_figure` to ``path``."""
    return save_figure(qstar_figure(Q, mlr_over_mt, n_lr, fit, **kwargs), path)


def fragments_figure(mass_fraction, speed, experiment: LaboratoryFragmentation | None = None) -> Figure:
    """Fragments of one body: (left) cumulative number N(>= m) against m / M_T, (right) speed
    against m / M_T, with a laboratory experiment's largest fragment and speed law beside them.

    Args:
        mass_fraction: (F,) fragment masses over the target's mass M_T (-).
        speed: (F,) fragment speeds (m/s).
        experiment: measured fragments to draw (the largest fragment as a star, the speed law
            V(m / M_T) as a dashed line), or None.
    """
    fraction = np.asarray(mass_fraction, dtype=float)
    speed = np.asarray(speed, dtype=float)
    ordered, number = cumulative_number(fraction)
    fig = Figure(figsize=(9.0, 3.8), layout="constrained")
    ax_n = fig.add_subplot(1, 2, 1)
    ax_n.step(ordered, number, where="post", label="this run")
    ax_n.set_xscale("log")
    ax_n.set_yscale("log")
    ax_n.set_xlabel(r"$m / M_T$")
    ax_n.set_ylabel(r"$N(\geq m)$")
    ax_v = fig.add_subplot(1, 2, 2)
    ax_v.scatter(fraction, np.maximum(speed, 1e-30), s=8, label="this run")
    ax_v.set_xscale("log")
    ax_v.set_yscale("log")
    ax_v.set_xlabel(r"$m / M_T$")
    ax_v.set_ylabel("speed (m/s)")
    if experiment is not None:
        ax_n.plot([experiment.largest_fraction], [1], "k*", markersize=10, label=experiment.reference)
        span = np.logspace(np.log10(max(fraction.min(initial=1.0), 1e-6)), 0.0, 50)
        ax_v.plot(span, experiment.fragment_speed(span), "k--", label=f"{experiment.reference}: fit")
        ax_v.plot([experiment.largest_fraction], [experiment.largest_speed], "k*", markersize=10,
                  label=f"{experiment.reference}: largest")
    ax_n.legend(fontsize=7)
    ax_v.legend(fontsize=7)
    return fig


def plot_fragments(path, mass_fraction, speed, **kwargs) -> Path:
    """Write :func:`fragments_figure` to ``path``."""
    return save_figure(fragments_figure(mass_fraction, speed, **kwargs), path)
