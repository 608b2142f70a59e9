"""Helpers shared by the problem setups: material lists, parameter merging, presets."""

from __future__ import annotations

from importlib import resources

import yaml

from impactpipe.hydro.eos import SPECIFIC_HEAT_DEFAULTS, pack_eos
from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.solver import Simulation
from impactpipe.hydro.mesh.state import HydroState


def material_list(materials: dict[str, dict], used: list[str]):
    """Names, resolved EOS specs and packed EOS of the materials in ``used`` (first-use order).

    ``materials`` maps a material name to its resolved spec ``{"eos": {...}}``.
    """
    names: list[str] = []
    for name in used:
        if name not in materials:
            raise KeyError(f"material {name!r} is not defined (known: {sorted(materials)})")
        if name not in names:
            names.append(name)
    specs = [dict(materials[name]["eos"]) for name in names]
    return names, specs, pack_eos(specs)


def new_simulation(mesh: BlockMesh, names: list[str], specs: list[dict], state: HydroState, cfl: float,
                   tensile_strength=None, strength=None, refinement=None) -> Simulation:
    """A :class:`Simulation` over ``state`` with the given materials (``strength``: one resolved spec each;
    ``refinement``: the :class:`~impactpipe.hydro.amr.regrid.RefinementRule` of an adaptive mesh)."""
    return Simulation(mesh, names, specs, state, cfl=cfl, tensile_strength=tensile_strength, strength=strength,
                      refinement=refinement)


def tensile_strengths(materials: dict[str, dict], used: list[str]) -> list[float]:
    """Tensile strength Y_T (Pa) of each material in ``used``: its strength model's Y_T, else 0."""
    return [float(materials[name].get("strength", {}).get("Y_T", 0.0)) for name in used]


def strength_specs(materials: dict[str, dict], used: list[str]) -> list[dict | None]:
    """Resolved strength spec of each material in ``used`` (None where it has none)."""
    return [materials[name].get("strength") for name in used]


def merged(defaults: dict, params: dict) -> dict:
    """``defaults`` updated by ``params`` (one level deep for nested dicts); unknown keys raise."""
    unknown = set(params) - set(defaults)
    if unknown:
        raise KeyError(f"unknown problem parameters {sorted(unknown)}; known: {sorted(defaults)}")
    out = {}
    for key, value in defaults.items():
        if isinstance(value, dict) and isinstance(params.get(key), dict):
            out[key] = {**value, **params[key]}
        else:
            out[key] = params.get(key, value)
    return out


def preset_material(name: str, model: str = "tillotson") -> dict:
    """Resolved material spec ``{"eos": {...}}`` for a preset of pipeline/data/materials.yaml.

    For tests, benchmarks and examples; runs resolve presets through the config layer.
    The specific heat is :data:`impactpipe.hydro.eos.SPECIFIC_HEAT_DEFAULTS` of the preset.
    """
    presets = yaml.safe_load(resources.files("impactpipe.pipeline").joinpath("data/materials.yaml").read_text())
    values = {key: float(value) for key, value in presets[model][name].items()}
    return {"eos": {"model": model, **values, "cv": SPECIFIC_HEAT_DEFAULTS[name]}}


def check_geometry(problem: str, supported: tuple[str, ...], geometry: str) -> None:
    """Raise ValueError unless ``geometry`` is one the problem supports."""
    if geometry not in supported:
        raise ValueError(f"{problem} runs in {', '.join(supported)} (got {geometry})")
