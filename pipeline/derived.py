"""Values the pipeline derives from a config, each with the rule that chose it.

``impactpipe validate`` prints these, the stages use them, and the run store records
them, so every automatic choice is visible and can be overridden in the config.
"""

from __future__ import annotations

import inspect
import math
from typing import Any

import numpy as np
from scipy.constants import G

from impactpipe.hydro.eos import pack_eos, pressure_sound_speed, reference_density
from impactpipe.hydro.eos.porosity import initial_distension
from impactpipe.hydro.mesh.blocks import DEFAULT_BLOCK_CELLS
from impactpipe.hydro.problems import PROBLEMS, impact
from impactpipe.hydro.problems.common import root_cell_multiple
from impactpipe.hydro.output.snapshot import GEOMETRY_DIMENSIONS
from impactpipe.nbody.simulation import dynamical_time

from .config import Config

#: Hand-off time in target sound-crossing times (R_T / c), method.md section 3.
CROSSING_TIMES_TO_HANDOFF = 4.0
#: Self-gravity (auto) needs the target's central pressure above this multiple of its tensile strength...
SELF_GRAVITY_STRENGTH_FACTOR = 10.0
#: ...and gravity to add more than this fraction of the escape speed during the hydro stage: the
#: 50 km target of configs/large_body.yaml (3.9 %) has a Q*_D 28 % higher with it than without
#: (docs/validation.md); the 10 km reference cases (0.7-1.2 %) stay without it, as the reference study ran them.
SELF_GRAVITY_VELOCITY_FRACTION = 0.02


def reference_state(material: dict[str, Any]) -> tuple[float, float]:
    """(rho0, bulk sound speed at rho0 and zero internal energy) of a resolved material (SI).

    A porous material (``porosity`` block) has the bulk density rho_s0 / alpha0 of its unstrained
    pores and the sound speed of its solid at rho_s0 (:mod:`impactpipe.hydro.eos.porosity`)."""
    arrays = pack_eos([material["eos"]])
    rho0 = reference_density(arrays.kind[0], arrays.params[0], arrays.table)
    _, c2, _ = pressure_sound_speed(arrays.kind[0], arrays.params[0], arrays.table, rho0, 0.0)
    return float(rho0) / initial_distension(material), float(math.sqrt(c2))


def porosity_choice(materials: dict[str, dict[str, Any]]) -> tuple[bool, str]:
    """(on, why) for porosity: on when some material has alpha0 > 1 (:mod:`impactpipe.hydro.eos.porosity`)."""
    porous = {name: float(mat["porosity"]["alpha0"]) for name, mat in materials.items()
              if mat.get("porosity") and float(mat["porosity"]["alpha0"]) > 1.0}
    if not porous:
        return False, "off: no material has a porosity block with alpha0 > 1"
    listed = ", ".join(f"{name} alpha0 = {alpha0:g}" for name, alpha0 in porous.items())
    return True, (f"on: {listed} > 1 (epsilon-alpha compaction; the distension rides with the material as a "
                  f"transported scalar)")


def geometry(config: Config) -> tuple[str, str]:
    """(geometry, why) for the scene."""
    scene = config.scene
    if scene.geometry != "auto":
        return scene.geometry, "set in the config"
    if scene.problem == "impact":
        if scene.impact.angle == 90.0:
            return "2d-cylindrical", "head-on impact (angle 90) is axisymmetric"
        return "3d", f"oblique impact (angle {scene.impact.angle:g}) needs 3d"
    default = inspect.signature(PROBLEMS[scene.problem].setup).parameters["geometry"].default
    return default, f"default of the {scene.problem} problem"


def tracers_enabled(config: Config) -> tuple[bool, str]:
    """(on, why) for tracers: auto turns them on for impacts, whose analysis needs peak pressures."""
    setting = config.hydro.tracers.enabled
    if setting != "auto":
        return bool(setting), "set in the config"
    if config.scene.problem == "impact":
        return True, "auto: on for impacts (peak pressures for the shock histories of the analysis)"
    return False, f"auto: off for the {config.scene.problem} verification problem"


def central_pressure(rho: float, radius: float) -> float:
    """Lithostatic pressure at the centre of a uniform self-gravitating sphere (Pa).

    P_c = (2 pi / 3) G rho^2 R^2 (:func:`impactpipe.hydro.problems.impact.lithostatic_pressure` at r = 0).
    """
    return float(impact.lithostatic_pressure(rho, radius, 0.0))


def hydrostatic_initial_state(rho: float, radius: float, alpha0: float) -> str:
    """The sentence ``validate`` prints for a target that starts in hydrostatic equilibrium:
    bulk density ``rho`` (kg/m^3), ``radius`` R (m), distension ``alpha0`` (-; 1 without pores)."""
    pressure = (f"lithostatic pressure (2 pi / 3) G rho^2 (R^2 - r^2), {central_pressure(rho, radius):.3g} Pa at "
                f"the centre")
    if alpha0 == 1.0:
        return f"target in hydrostatic equilibrium under its own gravity: {pressure} (self-gravity on)"
    return (f"porous target in hydrostatic equilibrium under its own gravity: bulk density rho = rho_s0 / alpha0 = "
            f"{rho:.6g} kg/m^3 and distension alpha0 = {alpha0:g} everywhere, unstrained (the epsilon-alpha model "
            f"compacts with volumetric strain, and a body at rest has none), with the internal energy e that makes "
            f"the porous pressure P_s(alpha0 rho, e) / alpha0 the {pressure}: the matrix carries alpha0 times the "
            f"overburden through its thermal pressure (docs/eos.md, \"Self-gravity on a porous body\"; "
            f"self-gravity on)")


def derive(config: Config) -> dict[str, Any]:
    """All derived values of a config, each with the rule that produced it (SI units)."""
    geom, why = geometry(config)
    out: dict[str, Any] = {"geometry": geom, "geometry_rule": why}
    materials = config.resolved_materials()
    out["strength"] = {name: strength_choice(mat["strength"]) for name, mat in materials.items()}
    out["porosity"], out["porosity_rule"] = porosity_choice(materials)
    out["tracers"], out["tracers_rule"] = tracers_enabled(config)
    out["levels"], out["levels_rule"] = mesh_levels(config, geom)
    interval = config.hydro.refinement.interval
    if config.hydro.time_stepping == "per_level":
        regrids = (f"every {max(1, interval // 2 ** (out['levels'] - 1))} root steps; a time step per level "
                   f"(level l steps dt_0 / 2^l)")
    else:
        regrids = f"every {interval} steps"
    out["mesh"] = ("uniform, one level at the finest cell size" if out["levels"] == 1 else
                   f"adaptive, {out['levels']} levels (root cells 2^{out['levels'] - 1} finest cells), "
                   f"refining at {refinement_summary(config.hydro.refinement)} {regrids}")
    if config.scene.problem != "impact":
        out["end_time"] = config.scene.end_time
        return out
    scene = config.scene
    rho_t, c_t = reference_state(materials[scene.target.material])
    rho_p, _ = reference_state(materials[scene.projectile.material])
    m_t = 4.0 / 3.0 * math.pi * scene.target.radius ** 3 * rho_t
    m_p = 4.0 / 3.0 * math.pi * scene.projectile.radius ** 3 * rho_p
    crossing = scene.target.radius / c_t
    out.update({
        "target_mass": m_t,
        "projectile_mass": m_p,
        "target_reference_density": rho_t,
        "target_sound_speed": c_t,
        "sound_crossing_time": crossing,
        "escape_speed": math.sqrt(2.0 * G * m_t / scene.target.radius),
        "Q": 0.5 * m_p * scene.impact.velocity ** 2 / m_t,
        "finest_cell_size": scene.projectile.radius / config.hydro.cells_per_projectile_radius,
    })
    if config.hydro.end_time == "auto":
        out["end_time"] = CROSSING_TIMES_TO_HANDOFF * crossing
        out["end_time_rule"] = f"auto: {CROSSING_TIMES_TO_HANDOFF:g} target sound-crossing times R_T / c = " \
                               f"{CROSSING_TIMES_TO_HANDOFF:g} x {crossing:.4g} s"
    else:
        out["end_time"] = config.hydro.end_time
        out["end_time_rule"] = "set in the config"
    alpha_t = initial_distension(materials[scene.target.material])
    out["self_gravity"], out["self_gravity_rule"] = self_gravity_choice(
        config.hydro.self_gravity, rho_t, scene.target.radius, materials[scene.target.material]["strength"],
        c_t, out["end_time"], alpha_t)
    out["initial_state"] = (hydrostatic_initial_state(rho_t, scene.target.radius, alpha_t) if out["self_gravity"]
                            else "both bodies at their reference density and p = 0 (self-gravity off)")
    out["domain"] = impact_domain(config, geom, m_t + m_p, out["end_time"])
    if out["domain"] is not None:
        out["handoff_block_edge"], out["handoff_block_edge_rule"] = handoff_block_edge(
            config, out["domain"]["block_cells"])
    out["nbody_dynamical_time"] = dynamical_time(rho_t)
    out["nbody_time_cap"], out["nbody_time_cap_rule"] = nbody_time_cap(config.nbody.stop, out["nbody_dynamical_time"])
    return out


def handoff_block_edge(config: Config, block_cells: int) -> tuple[float | None, str]:
    """(edge, rule): the smallest block edge the hand-off makes spheres from (m), n_b R_P / n_h with
    n_b cells per block edge and n_h = ``handoff.particle_resolution`` (None: the leaf blocks,
    whose finest edge is n_b R_P / hydro.cells_per_projectile_radius)."""
    r_p = config.scene.projectile.radius
    n_h = config.handoff.particle_resolution
    finest = block_cells * r_p / config.hydro.cells_per_projectile_radius
    if n_h is None:
        return None, f"auto: one sphere per leaf block (finest blocks {block_cells} x R_P / " \
                     f"hydro.cells_per_projectile_radius = {finest:.4g} m)"
    edge = block_cells * r_p / n_h
    return edge, f"handoff.particle_resolution = {n_h:g}: leaf blocks narrower than {block_cells} x R_P / " \
                 f"{n_h:g} = {edge:.4g} m are merged into their ancestors first (finest blocks {finest:.4g} m)"


def nbody_time_cap(stop, t_dyn: float) -> tuple[float, str]:
    """(cap, rule): the N-body stage's simulated-time cap (s), the smaller of ``stop.max_time``
    (s, if set) and ``stop.max_dynamical_times`` t_dyn (t_dyn = 1 / sqrt(G rho_T), s)."""
    cap = stop.max_dynamical_times * t_dyn
    rule = f"nbody.stop.max_dynamical_times x t_dyn = {stop.max_dynamical_times:g} x {t_dyn:.4g} s"
    if stop.max_time is not None and stop.max_time < cap:
        return stop.max_time, "nbody.stop.max_time (set in the config; smaller than " + rule + ")"
    return cap, rule


def mesh_levels(config: Config, geom: str) -> tuple[int, str]:
    """Number of refinement levels of the hydro mesh and the rule that gave it.

    ``hydro.max_levels: auto`` for an impact: levels = 1 + floor(log2(R_T / (n_b dx))), dx the
    finest cell (R_P / cells_per_projectile_radius) and n_b the cells per block edge, so a
    root block is at most one target radius wide; the finest level then holds the bodies'
    surfaces and the shocks, the coarsest the quiet interior and the void.  Other scenes run
    one level on auto (a verification scene's resolution keys give the uniform mesh it is
    checked at); any scene refines adaptively with an integer, its resolution keys then
    counting cells of the finest level.
    """
    chosen = config.hydro.max_levels
    if chosen != "auto":
        return int(chosen), "set in the config"
    if config.scene.problem != "impact":
        return 1, (f"auto: one level for the {config.scene.problem} scene (uniform at its resolution keys); "
                   f"set hydro.max_levels to refine adaptively")
    scene = config.scene
    block = config.hydro.block_cells or DEFAULT_BLOCK_CELLS[GEOMETRY_DIMENSIONS.get(geom, 2)]
    dx = scene.projectile.radius / config.hydro.cells_per_projectile_radius
    ratio = scene.target.radius / (block * dx)
    levels = 1 + max(0, int(math.floor(math.log2(ratio)))) if ratio >= 1.0 else 1
    return levels, (f"auto: 1 + floor(log2(R_T / (block_cells dx))) = 1 + floor(log2({scene.target.radius:g} m / "
                    f"({block} x {dx:.4g} m))) = {levels}")


def refinement_summary(refinement) -> str:
    """The enabled refinement criteria in words."""
    parts = []
    if refinement.interfaces != "off":
        parts.append(f"interfaces and free surfaces ({refinement.interfaces})")
    if refinement.pressure_jump is not None:
        parts.append(f"pressure jumps > {refinement.pressure_jump:g}")
    if refinement.density_jump is not None:
        parts.append(f"density jumps > {refinement.density_jump:g}")
    if refinement.boxes:
        parts.append(f"{len(refinement.boxes)} box(es)")
    if refinement.material_depth is not None:
        parts.append(f"material within {refinement.material_depth} level(s) of the finest")
    return ", ".join(parts) if parts else "user boxes only (no criterion enabled)"


def impact_domain(config: Config, geom: str, total_mass: float, end_time: float) -> dict[str, Any] | None:
    """The impact mesh box (m) and the margin rule behind it; None for a geometry the impact cannot use.

    The mesh extends beyond the target (and above the projectile) by

        margin = max(scene.domain_margin, v_esc t_end / R_T)   target radii,

    v_esc = sqrt(2 G (M_T + M_P) / R_T) the escape speed of the two bodies together and
    t_end the hydro end time (the latest hand-off time).  Without self-gravity in the hydro
    stage material moves at most v t_end from the target's surface, so everything slower than
    the escape speed (all that can reaccumulate) is still on the mesh at hand-off; faster
    material may leave through the outflow faces and is counted there (hydro budget
    ``*_left_mesh``).  The box itself is :func:`impactpipe.hydro.problems.impact.domain`.
    """
    if geom not in impact.GEOMETRIES:
        return None
    scene = config.scene
    v_esc = math.sqrt(2.0 * G * total_mass / scene.target.radius)
    needed = v_esc * end_time / scene.target.radius
    margin = max(scene.domain_margin, needed)
    which = "scene.domain_margin" if margin == scene.domain_margin else "v_esc t_end / R_T"
    levels, _ = mesh_levels(config, geom)
    box = impact.domain(geom, scene.target.radius, scene.projectile.radius, config.hydro.cells_per_projectile_radius,
                        margin, config.hydro.block_cells, scene.full_domain, levels)
    cells = [int(n) for n in box["cells"]]
    return {
        "margin": margin,
        "margin_rule": f"max(scene.domain_margin = {scene.domain_margin:g}, v_esc t_end / R_T = {v_esc:.4g} m/s x "
                       f"{end_time:.4g} s / {scene.target.radius:g} m = {needed:.4g}) = {margin:.4g} target radii "
                       f"({which}); material faster than v_esc may leave and is counted as outflow",
        "lo": [float(x) for x in box["lo"]],
        "hi": [float(x) for x in box["hi"]],
        "cells": cells,
        "total_cells": int(np.prod(cells)),
        "block_cells": int(box["block_cells"]),
        "boundaries": [list(pair) for pair in box["boundaries"]],
        "symmetry": box["symmetry"],
        "half_domain": bool(box["half_domain"]),
    }


def strength_choice(strength: dict[str, Any]) -> dict[str, Any]:
    """Whether a material needs the strength kernels, and why."""
    model = strength["model"]
    if model == "none":
        return {"enabled": False, "rule": "strength.model is none"}
    if model == "von_mises":
        enabled = strength["yield_strength"] > 0
    else:
        enabled = strength["Y0"] > 0 or strength["Y_M"] > 0
    if not enabled:
        return {"enabled": False, "rule": f"{model} yield strength is zero everywhere (hydro preset): no strength kernel"}
    return {"enabled": True, "rule": f"{model} model with non-zero yield strength: elastic-plastic stress, "
                                     f"tensile failure at Y_T = {strength.get('Y_T', 0.0):.3g} Pa (docs/strength.md)"}


#: Below this many cells per projectile radius an impact is under-resolved: the quickstart's
#: peak pressure at 2 R_P is 52 % above the 4-cell value at 2 cells, 12 % below it at 8
#: (docs/accuracy.md, "Quickstart ladders").
MIN_CELLS_PER_PROJECTILE_RADIUS = 4.0


def resolution_warnings(config) -> list[str]:
    """Resolutions too coarse to trust, one line each (empty for scenes without a projectile)."""
    cells = config.hydro.cells_per_projectile_radius
    if config.scene.problem != "impact" or cells >= MIN_CELLS_PER_PROJECTILE_RADIUS:
        return []
    return [f"hydro.cells_per_projectile_radius: {cells:g} ({2 * cells:g} cells across the projectile) is "
            f"under-resolved: below {MIN_CELLS_PER_PROJECTILE_RADIUS:g} the peak pressures are tens of per cent off "
            f"(docs/accuracy.md); the method uses 20"]


def time_stepping_warnings(config) -> list[str]:
    """``hydro.time_stepping: per_level`` on an impact, which validates (without Grady-Kipp
    fracture, gravity or porosity) but is not yet sound there at every resolution: one line."""
    if config.hydro.time_stepping != "per_level" or config.scene.problem != "impact":
        return []
    return ["hydro.time_stepping: per_level on an impact is not yet sound at every resolution: at 10 cells per "
            "projectile radius one reflux in the ejecta spray adds 2e5 kg through the floors, against 5e-7 kg "
            "with the global step (docs/hydro.md, \"Adaptive mesh\"); use global for results"]


def physics_warnings(values: dict[str, Any]) -> list[str]:
    """Physics a config asks for that this version does not model, one line each."""
    return [f"materials.{name}.strength: {choice['warning']}"
            for name, choice in values.get("strength", {}).items() if "warning" in choice]


def self_gravity_choice(setting: bool | str, rho: float, radius: float, strength: dict[str, Any],
                        sound_speed: float, end_time: float, alpha0: float = 1.0) -> tuple[bool, str]:
    """(on, rule) for self-gravity in the hydro stage; ``rho`` the target's bulk density (kg/m^3),
    ``alpha0`` its distension (-, 1 without pores).

    Auto turns it on only when both hold (method.md section 2: for 2-50 km bodies it is
    negligible in the shock phase):
    (a) the central pressure P_c = (2 pi / 3) G rho^2 R^2 exceeds SELF_GRAVITY_STRENGTH_FACTOR
        times the bulk tensile strength Y_T / alpha0 (Y_T the matrix's, 0 without a strength
        model; a porous material holds its matrix's tension spread over the bulk, docs/strength.md),
        so gravity, not strength, holds the fractured body together;
    (b) the velocity surface gravity adds over the hydro stage, g t_end with
        g = (4 pi / 3) G rho R, exceeds SELF_GRAVITY_VELOCITY_FRACTION of the escape speed.
    """
    p_c = central_pressure(rho, radius)
    y_t = float(strength.get("Y_T", 0.0)) / alpha0
    g = 4.0 * math.pi / 3.0 * G * rho * radius
    v_esc = math.sqrt(2.0 * g * radius)
    dv = g * end_time
    bulk = "" if alpha0 == 1.0 else f" / alpha0 (porous target, alpha0 = {alpha0:g}, bulk density {rho:.6g} kg/m^3)"
    numbers = (f"central pressure {p_c:.3g} Pa vs {SELF_GRAVITY_STRENGTH_FACTOR:g} Y_T{bulk} = "
               f"{SELF_GRAVITY_STRENGTH_FACTOR * y_t:.3g} Pa; gravity adds g t_end = {dv:.3g} m/s vs "
               f"{SELF_GRAVITY_VELOCITY_FRACTION:g} v_esc = {SELF_GRAVITY_VELOCITY_FRACTION * v_esc:.3g} m/s")
    if setting != "auto":
        return bool(setting), f"set in the config ({numbers})"
    on = p_c > SELF_GRAVITY_STRENGTH_FACTOR * y_t and dv > SELF_GRAVITY_VELOCITY_FRACTION * v_esc
    return on, f"auto: {'on' if on else 'off'} ({numbers})"


def as_plain(values: dict[str, Any]) -> dict[str, Any]:
    """``values`` with numpy scalars turned into Python numbers (for YAML/JSON output)."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        if isinstance(value, dict):
            out[key] = as_plain(value)
        elif isinstance(value, np.generic):
            out[key] = value.item()
        else:
            out[key] = value
    return out


#: Snapshots written when the config names no output times: this many, evenly spaced, plus t = 0.
DEFAULT_SNAPSHOTS = 10


def snapshot_times(config: Config, end_time: float) -> list[float]:
    """Hydro snapshot times (s): ``hydro.output_times``, or every ``hydro.output_interval``, or
    DEFAULT_SNAPSHOTS evenly spaced from 0; always with the end time ``end_time``."""
    hydro = config.hydro
    if hydro.output_times is not None:
        times = [t for t in hydro.output_times if t <= end_time]
    elif hydro.output_interval is not None:
        times = list(np.arange(0.0, end_time, hydro.output_interval))
    else:
        times = list(np.linspace(0.0, end_time, DEFAULT_SNAPSHOTS + 1)[:-1])
    return sorted({float(t) for t in times} | {float(end_time)})


#: Relative tolerance within which a requested time (s) is a snapshot time.
SNAPSHOT_TIME_TOLERANCE = 1e-9


def snapshot_at(times, time: float) -> int | None:
    """Index of the first of ``times`` (s) within SNAPSHOT_TIME_TOLERANCE x ``time`` of ``time``, or None."""
    for index, t in enumerate(times):
        if abs(t - time) <= SNAPSHOT_TIME_TOLERANCE * max(abs(time), 1e-300):
            return index
    return None


def capability_errors(config: Config, values: dict[str, Any]) -> list[str]:
    """Requests this version cannot carry out, as ``key: message`` lines (checked before any work)."""
    errors = []
    if config.scene.problem not in PROBLEMS:
        errors.append(f"scene.problem: '{config.scene.problem}' has no hydro setup in this version "
                      f"(available: {', '.join(sorted(PROBLEMS))})")
    problem = PROBLEMS[config.scene.problem] if config.scene.problem in PROBLEMS else None
    if problem is not None and config.scene.problem != "impact" and values["geometry"] not in problem.GEOMETRIES:
        errors.append(f"scene.geometry: the {config.scene.problem} problem runs in {', '.join(problem.GEOMETRIES)} "
                      f"(got {values['geometry']})")
    levels = values.get("levels", 1)
    cells = getattr(config.scene, "cells", None)
    if cells is not None and values["geometry"] in GEOMETRY_DIMENSIONS:
        block = config.hydro.block_cells or DEFAULT_BLOCK_CELLS[GEOMETRY_DIMENSIONS[values["geometry"]]]
        errors.extend(_cells_errors(cells, block, levels))
    if config.scene.problem == "impact":
        errors.extend(_impact_geometry_errors(config.scene, values["geometry"]))
    t_handoff = config.handoff.time
    if t_handoff is not None:
        times = snapshot_times(config, values["end_time"])
        if snapshot_at(times, t_handoff) is None:
            errors.append(f"handoff.time: {t_handoff:g} s has no hydro snapshot; the snapshots are at "
                          f"{', '.join(f'{t:.6g}' for t in times)} s (hydro.output_times, hydro.output_interval "
                          f"or, by default, {DEFAULT_SNAPSHOTS} evenly spaced up to the end time)")
    errors.extend(_particle_resolution_errors(config, values))
    if levels > 1:
        block = config.hydro.block_cells or DEFAULT_BLOCK_CELLS[GEOMETRY_DIMENSIONS.get(values["geometry"], 2)]
        if block % 4:
            errors.append(f"hydro.block_cells: {block} cells per block edge on an adaptive mesh ({levels} levels); "
                          f"refinement splits blocks in halves and tracers need quarters: use a multiple of 4")
    errors.extend(_time_stepping_errors(config, values))
    if getattr(config.scene, "settling", False) and levels > 1:
        errors.append(f"scene.settling: void settling runs on a mesh of one level; hydro.max_levels resolves "
                      f"to {levels}: set hydro.max_levels: 1 or scene.settling: false")
    ndim = GEOMETRY_DIMENSIONS.get(values["geometry"], 0)
    for i, box in enumerate(config.hydro.refinement.boxes):
        if ndim and len(box.lo) != ndim:
            errors.append(f"hydro.refinement.boxes[{i}]: lo and hi need {ndim} values for {values['geometry']} "
                          f"(got {len(box.lo)})")
        if box.level > levels - 1:
            errors.append(f"hydro.refinement.boxes[{i}].level: {box.level} is finer than the finest level "
                          f"{levels - 1} (hydro.max_levels resolves to {levels}); use 0 to {levels - 1}")
    return errors


#: The scenes whose hydro stage always has gravity, and which.
SCENE_GRAVITY = {"column_collapse": "external gravity (the column_collapse scene)",
                 "hydrostatic_body": "self-gravity (the hydrostatic_body scene)"}


def _time_stepping_errors(config: Config, values: dict[str, Any]) -> list[str]:
    """``hydro.time_stepping: per_level`` with physics its level recursion does not carry yet
    (impactpipe.hydro.amr.subcycle): Grady-Kipp fracture, gravity, porosity."""
    if config.hydro.time_stepping != "per_level":
        return []
    missing = [f"grady_kipp fracture ({name})" for name, mat in config.resolved_materials().items()
               if values.get("strength", {}).get(name, {}).get("enabled")
               and ((mat["strength"] or {}).get("damage") or {}).get("model") == "grady_kipp"]
    if config.scene.problem in SCENE_GRAVITY:
        missing.append(SCENE_GRAVITY[config.scene.problem])
    if values.get("self_gravity"):
        missing.append("self-gravity (hydro.self_gravity)")
    if values.get("porosity"):
        missing.append("porosity")
    if not missing:
        return []
    return [f"hydro.time_stepping: per_level does not support {', '.join(missing)} yet; use global"]


def _cells_errors(cells: int, block: int, levels: int) -> list[str]:
    """``scene.cells`` (finest cells along an axis) that is not a whole number of root blocks, as a
    ``key: message`` line: a multiple of ``block`` cells times 2^(levels - 1)."""
    multiple = root_cell_multiple(block, levels)
    if cells % multiple == 0:
        return []
    if levels == 1:
        return [f"scene.cells: {cells} is not a multiple of the block size {block} (hydro.block_cells); "
                f"use a multiple of {block}"]
    return [f"scene.cells: {cells} is not a multiple of {multiple}, the block size {block} (hydro.block_cells) "
            f"times 2^({levels} - 1): scene.cells counts cells of the finest of {levels} levels (hydro.max_levels) "
            f"and the root level holds whole blocks; use a multiple of {multiple} or fewer levels"]


def _particle_resolution_errors(config: Config, values: dict[str, Any]) -> list[str]:
    """``handoff.particle_resolution`` that names no block level of the mesh, as ``key: message`` lines."""
    n_h = config.handoff.particle_resolution
    if n_h is None:
        return []
    if config.scene.problem != "impact":
        return [f"handoff.particle_resolution: {n_h:g} applies to impact scenes only (it is in cells per "
                f"projectile radius; scene.problem is {config.scene.problem}); remove it"]
    cells = config.hydro.cells_per_projectile_radius
    levels = values.get("levels", 1)
    allowed = ", ".join(f"{cells / 2 ** k:g}" for k in range(levels))
    ratio = cells / n_h
    k = round(math.log2(ratio)) if ratio > 0 else -1
    if k < 0 or abs(2.0 ** k - ratio) > 1e-9 * ratio or k > levels - 1:
        return [f"handoff.particle_resolution: {n_h:g} is not the resolution of a block level of this mesh "
                f"(hydro.cells_per_projectile_radius {cells:g} over a power of two, down to the root level of "
                f"{levels} levels); use one of {allowed}"]
    return []


def _impact_geometry_errors(scene, geom: str) -> list[str]:
    """An impact scene's geometry, angle and full_domain that do not fit together, as ``key: message`` lines."""
    if geom not in impact.GEOMETRIES:
        return [f"scene.geometry: an impact runs in {', '.join(impact.GEOMETRIES)} (got {geom}); "
                f"use auto (2d-cylindrical for angle 90, 3d otherwise)"]
    errors = []
    if geom == "2d-cylindrical" and scene.impact.angle != 90.0:
        errors.append(f"scene.impact.angle: {scene.impact.angle:g} is oblique, which 2d-cylindrical cannot represent "
                      f"(head-on only, angle 90); set scene.geometry to 3d or auto")
    if scene.full_domain and geom != "3d":
        errors.append(f"scene.full_domain: true applies to 3d impacts only (geometry is {geom}, which uses "
                      f"the symmetry axis); remove it or set scene.geometry to 3d")
    return errors
