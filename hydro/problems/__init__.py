"""Problem setups: ``PROBLEMS[name]`` is a module with ``DEFAULTS`` and
``setup(params, materials, **hydro_options) -> Simulation``.

``materials`` maps a material name to its resolved spec ``{"eos": {...}}``;
``hydro_options`` are ``block_cells``, ``cfl`` and ``geometry`` where the problem allows a
choice.  Unknown parameter keys raise ``KeyError``.
"""

from impactpipe.hydro.problems import (
    advection,
    column_collapse,
    impact,
    interface_advection,
    noh,
    planar_impact,
    sedov,
    shock_tube,
)

PROBLEMS = {
    "shock_tube": shock_tube,
    "sedov": sedov,
    "planar_impact": planar_impact,
    "advection": advection,
    "noh": noh,
    "interface_advection": interface_advection,
    "impact": impact,
    "column_collapse": column_collapse,
}

__all__ = ["PROBLEMS"]
