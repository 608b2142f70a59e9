"""Problem setups: ``PROBLEMS[name]`` is a module with ``PARAMETERS``, ``DEFAULTS`` and
``setup(params, materials, **hydro_options) -> Simulation``.

``PARAMETERS`` declares the parameters of the problem's scene (default, type, bounds, units;
:mod:`impactpipe.hydro.problems.parameters`), from which the config schema is built;
``DEFAULTS`` holds what ``setup`` takes for the parameters a call leaves out.  A module may
define ``check_parameters(params) -> list[str]``, cross checks beyond each parameter's
bounds.  ``materials`` maps a material name to its resolved spec ``{"eos": {...}}``;
``hydro_options`` are ``block_cells``, ``cfl`` and ``geometry`` where the problem allows a
choice.  Unknown parameter keys raise ``KeyError``.

Every ``setup`` also takes ``levels`` (1: uniform) and ``refinement`` (the ``hydro.refinement``
keys) in ``params``, from :data:`~impactpipe.hydro.problems.common.ADAPTIVE_DEFAULTS`: its
resolution keys count cells of the finest level and, with ``levels`` > 1, the mesh is adaptive
(:func:`~impactpipe.hydro.problems.common.adaptive_mesh`), refined at t = 0 where the
refinement rule flags the initial state (the impact: where the bodies' surfaces are).
"""

from impactpipe.hydro.problems import (
    advection,
    column_collapse,
    hydrostatic_body,
    impact,
    interface_advection,
    noh,
    planar_impact,
    sedov,
    shock_tube,
)

#: The problems by name, the impact (a run's default scene) first.
PROBLEMS = {
    "impact": impact,
    "shock_tube": shock_tube,
    "sedov": sedov,
    "planar_impact": planar_impact,
    "advection": advection,
    "noh": noh,
    "interface_advection": interface_advection,
    "column_collapse": column_collapse,
    "hydrostatic_body": hydrostatic_body,
}

__all__ = ["PROBLEMS"]
