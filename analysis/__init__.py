"""Analysis of collision runs: remnants, impact energies, Q*_D, shock histories, figures."""

from .energies import (
    SizeLawFit,
    benz_asphaug_1999,
    comparison_laws,
    escape_speed,
    fit_qstar_size_law,
    impact_energy,
    leinhardt_stewart_2012_qrd,
    leinhardt_stewart_2012_qstar_d,
    mass_ratio,
    reduced_impact_energy,
    scale_qstar_to_velocity,
    sphere_mass,
)
from .handoff_error import HandoffTimeError, fit_by_handoff_time, qstar_handoff_error, write_handoff_table
from .io import AnalysisData, read_analysis, write_analysis
from .plots import (
    plot_cumulative_pressure,
    plot_origin_positions,
    plot_qstar,
    plot_velocity_distribution,
)
from .provenance import MassFractionCurve, cumulative_mass_fraction, provenance_owner, shock_history
from .qstar import QStarFit, fit_qstar, write_qstar_table
from .remnants import Remnant, RemnantResult, find_remnants, touching_groups
from .resolution_error import ResolutionError, qstar_resolution_error, write_resolution_table
from .richardson import Extrapolation, richardson

__all__ = [
    "AnalysisData",
    "Extrapolation",
    "HandoffTimeError",
    "MassFractionCurve",
    "QStarFit",
    "Remnant",
    "RemnantResult",
    "ResolutionError",
    "SizeLawFit",
    "benz_asphaug_1999",
    "comparison_laws",
    "cumulative_mass_fraction",
    "escape_speed",
    "find_remnants",
    "fit_by_handoff_time",
    "fit_qstar",
    "fit_qstar_size_law",
    "impact_energy",
    "leinhardt_stewart_2012_qrd",
    "leinhardt_stewart_2012_qstar_d",
    "mass_ratio",
    "plot_cumulative_pressure",
    "plot_origin_positions",
    "plot_qstar",
    "plot_velocity_distribution",
    "provenance_owner",
    "qstar_handoff_error",
    "qstar_resolution_error",
    "read_analysis",
    "reduced_impact_energy",
    "richardson",
    "scale_qstar_to_velocity",
    "shock_history",
    "sphere_mass",
    "touching_groups",
    "write_analysis",
    "write_handoff_table",
    "write_qstar_table",
    "write_resolution_table",
]
