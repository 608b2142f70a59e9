"""The analysis stage\'s adapter: remnants, impact energies, shock histories, figures.

Reads ``handoff.h5`` and ``nbody.h5``, writes ``analysis.h5`` and (with
``analysis.plots``) PNG figures into ``plots/``; returns the summary entries
(Q, Q_R, gamma, M_lr/M_T, M_slr/M_T, N_lr and the largest remnant's properties).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from impactpipe.handoff.store import read_particles
from impactpipe.nbody.result import read_result
from impactpipe import storage
from impactpipe.analysis.energies import impact_energy, mass_ratio, reduced_impact_energy
from impactpipe.analysis.io import write_analysis
from impactpipe.analysis.plots import plot_cumulative_pressure, plot_origin_positions, plot_velocity_distribution
from impactpipe.analysis.provenance import provenance_owner, shock_history
from impactpipe.analysis.remnants import find_remnants

from ..stages import StageContext


log = logging.getLogger(__name__)

PLOTS_DIR = "plots"


def run_analysis_stage(ctx: StageContext) -> dict[str, Any]:
    """Analyse the run in ``ctx.run_dir``; returns the summary entries."""
    started = storage.utc_now()
    t0 = time.perf_counter()
    config = ctx.config
    values = ctx.values
    particles = read_particles(ctx.path("handoff"))
    result = read_result(ctx.path("nbody"))
    m_t, m_p = values["target_mass"], values["projectile_mass"]
    v_i = config.scene.impact.velocity
    mode = "merge" if config.nbody.collision_model == "merge" else "aggregate"
    remnants = find_remnants(result.mass, result.radius, result.position, result.velocity,
                             mode=mode, target_mass=m_t)
    energies = {
        "Q": float(impact_energy(m_p, m_t, v_i)),
        "Q_R": float(reduced_impact_energy(m_p, m_t, v_i)),
        "gamma": float(mass_ratio(m_p, m_t)),
    }
    content: dict[str, Any] = {
        "energies": {
            "Q": (energies["Q"], "J/kg", "0.5 m_p v^2 / M_T"),
            "Q_R": (energies["Q_R"], "J/kg", "0.5 M_T m_p v^2 / (M_T + m_p)^2"),
            "gamma": (energies["gamma"], "dimensionless", "m_p / M_T"),
        },
        "remnants": remnants.as_datasets(),
    }
    owner = provenance_owner(result.members_offset, result.members, particles.id)
    has_pressure = np.isfinite(particles.peak_pressure_mean).any()
    curves = {}
    if has_pressure:
        curves = shock_history(particles.peak_pressure_mean, particles.mass, owner, remnants, result.position)
        content["shock_history"] = {name: curve.as_datasets() for name, curve in curves.items()}
    else:
        log.info("analysis: no tracer peak pressures in the hand-off; shock histories skipped")
    if config.analysis.plots:
        _figures(ctx.run_dir / PLOTS_DIR, particles, owner, remnants, curves, values, config)
    write_analysis(ctx.path("analysis"), content, ctx.provenance(started, time.perf_counter() - t0))
    largest, second = remnants.largest, remnants.second_largest
    summary = {
        **energies,
        "M_lr_over_M_T": float(remnants.mlr_over_mt),
        "M_slr_over_M_T": float(remnants.mslr_over_mt),
        "N_lr": int(_handoff_count(owner, largest.members) if largest is not None else 0),
        "N_slr": int(_handoff_count(owner, second.members) if second is not None else 0),
    }
    if largest is not None:
        summary["largest_remnant"] = {
            "mass": float(largest.mass), "bulk_radius": float(largest.bulk_radius),
            "bulk_density": float(largest.bulk_density), "spin_period": float(largest.spin_period),
            "final_particles": int(largest.n_particles),
        }
    log.info("analysis: M_lr/M_T = %.4g (N_lr = %d), M_slr/M_T = %.4g, Q = %.4g J/kg",
             summary["M_lr_over_M_T"], summary["N_lr"], summary["M_slr_over_M_T"], energies["Q"])
    return summary


def _handoff_count(owner: np.ndarray, final_members: np.ndarray) -> int:
    """Hand-off particles whose material ends in the given final particles (N_lr of the method)."""
    return int(np.isin(owner, final_members).sum())


def _figures(directory: Path, particles, owner, remnants, curves, values, config) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    plot_velocity_distribution(directory / "handoff_velocity.png", particles.velocity, particles.mass,
                               values["escape_speed"])
    if curves:
        plot_cumulative_pressure(directory / "peak_pressure_cumulative.png",
                                 {name: (c.pressure, c.fraction) for name, c in curves.items()})
    largest = remnants.largest
    if largest is not None and np.isfinite(particles.peak_pressure_mean).any():
        in_lr = np.isin(owner, largest.members)
        cylindrical = values["geometry"] == "2d-cylindrical"
        plot_origin_positions(directory / "largest_remnant_origins.png", particles.origin_position[in_lr],
                              particles.peak_pressure_mean[in_lr], axes=(0, 1) if cylindrical else (0, 2),
                              axis_names=("r", "z", "-") if cylindrical else ("x", "y", "z"))
