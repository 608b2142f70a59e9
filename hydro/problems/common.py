"""Helpers shared by the problem setups: material lists, parameter merging, presets, the adaptive mesh."""

from __future__ import annotations

from importlib import resources

import yaml

from impactpipe.hydro.amr.regrid import refine_initial, rule_from_config
from impactpipe.hydro.eos import SPECIFIC_HEAT_DEFAULTS, pack_eos
from impactpipe.hydro.mesh.blocks import DEFAULT_BLOCK_CELLS, BlockMesh
from impactpipe.hydro.output.snapshot import GEOMETRY_DIMENSIONS
from impactpipe.hydro.parallel.distributed import shared_simulation
from impactpipe.hydro.solver import Simulation
from impactpipe.hydro.mesh.state import HydroState


def material_list(materials: dict[str, dict], used: list[str]):
    """Names, resolved EOS specs and packed EOS of the materials in ``used`` (first-use order).

    ``materials`` maps a material name to its resolved spec ``{"eos": {...}}``; a porous material's
    ``porosity`` block (:mod:`impactpipe.hydro.eos.porosity`) goes into its EOS spec.
    """
    names: list[str] = []
    for name in used:
        if name not in materials:
            raise KeyError(f"material {name!r} is not defined (known: {sorted(materials)})")
        if name not in names:
            names.append(name)
    specs = [dict(materials[name]["eos"]) for name in names]
    for name, spec in zip(names, specs):
        if materials[name].get("porosity"):
            spec["porosity"] = dict(materials[name]["porosity"])
    return names, specs, pack_eos(specs)


def new_simulation(mesh: BlockMesh, names: list[str], specs: list[dict], state: HydroState, cfl: float,
                   tensile_strength=None, strength=None, refinement=None, gravity=None, partition=None) -> Simulation:
    """A :class:`Simulation` over ``state`` with the given materials (``strength``: one resolved spec each;
    ``refinement``: the :class:`~impactpipe.hydro.amr.regrid.RefinementRule` of an adaptive mesh;
    ``gravity``: the scene's gravity object or None; ``partition``: this MPI rank's blocks, whose
    rows alone ``state`` holds, or None)."""
    return Simulation(mesh, names, specs, state, cfl=cfl, tensile_strength=tensile_strength, strength=strength,
                      refinement=refinement, gravity=gravity, partition=partition)


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


#: What every problem's ``setup`` takes for its mesh's levels where a call leaves them out: ``levels``
#: (1: uniform; the config's ``hydro.max_levels``) and ``refinement`` (the ``hydro.refinement`` keys of
#: :class:`~impactpipe.hydro.amr.regrid.RefinementRule`; None: its defaults).
ADAPTIVE_DEFAULTS = {"levels": 1, "refinement": None}


def root_cell_multiple(block_cells: int, levels: int) -> int:
    """Finest cells along a root block's edge, block_cells 2^(levels - 1): a multiple of it makes whole root blocks."""
    return int(block_cells) * 2 ** (int(levels) - 1)


def adaptive_mesh(geometry: str, lo, hi, cells, boundaries, block_cells: int | None, levels: int) -> BlockMesh:
    """The root level of a mesh of ``levels`` levels over the box [``lo``, ``hi``] (m), nothing refined yet.

    ``cells`` (one per used axis) counts cells of the finest level, dx = (hi - lo) / cells, so a
    problem's resolution keys mean the same with any number of levels; the root level has
    cells / 2^(levels - 1) cells per axis.  Raises ValueError unless every count is a whole number
    of root blocks (:func:`root_cell_multiple`).  One level is the uniform mesh of ``cells``, whose
    block edge without ``block_cells`` is :func:`impactpipe.hydro.mesh.blocks.uniform_block_cells`.
    """
    ndim = GEOMETRY_DIMENSIONS[geometry]
    bc = int(block_cells or DEFAULT_BLOCK_CELLS[ndim])
    multiple = root_cell_multiple(bc, levels)
    scale = multiple // bc
    cells = [int(n) for n in cells]
    if any(n % multiple for n in cells):
        raise ValueError(f"cells: {cells} finest cells per axis are not whole root blocks of {levels} levels; "
                         f"each must be a multiple of block_cells x 2^(levels - 1) = {bc} x {scale} = {multiple}")
    # one level without a block size: the uniform mesh's own default (blocks.uniform_block_cells)
    edge = bc if block_cells or levels > 1 else None
    return BlockMesh.uniform(geometry, lo, hi, [n // scale for n in cells], boundaries, edge, max_level=int(levels) - 1)


def tube_mesh(geometry: str, length: float, cells: int, ends, block_cells: int | None, levels: int) -> BlockMesh:
    """Root level of the mesh of a tube along x: ``cells`` finest cells over ``length`` (m), ``ends``
    the (low, high) boundary kinds along x, and in 2d-planar / 3d one root block of periodic cells
    across (block_cells 2^(levels - 1) finest cells, so the finest cells are cubes)."""
    ndim = GEOMETRY_DIMENSIONS[geometry]
    across = root_cell_multiple(block_cells or DEFAULT_BLOCK_CELLS[ndim], levels)
    dx = length / cells
    return adaptive_mesh(geometry, [0.0] * ndim, [length] + [across * dx] * (ndim - 1), [cells] + [across] * (ndim - 1),
                         [ends] + [("periodic", "periodic")] * (ndim - 1), block_cells, levels)


def adaptive_simulation(mesh: BlockMesh, initial_state, names: list[str], specs: list[dict], cfl: float,
                        refinement: dict | None, wanted_level=None, comm=None, **options) -> Simulation:
    """The Simulation of a problem on ``mesh`` (:func:`adaptive_mesh`), refined where its initial state asks.

    ``initial_state(mesh, blocks)`` sets the problem's :class:`HydroState` on the blocks
    ``blocks`` (a slice) of a mesh; ``refinement`` is the ``hydro.refinement`` mapping;
    ``options`` go to :func:`new_simulation` (``tensile_strength``, ``strength``, ``gravity``).
    The mesh refines from its root level where the refinement rule flags the initial state
    (and to ``wanted_level``), the state being set again on each finer mesh
    (:func:`impactpipe.hydro.amr.regrid.refine_initial`).  With ``comm`` (collective) the ranks
    build each mesh's run together, each its own blocks
    (:func:`~impactpipe.hydro.parallel.distributed.shared_simulation`; the flags are the
    ranks' together), and the Simulation returned is this rank's share.
    """
    rule = rule_from_config(refinement)

    def build(m: BlockMesh) -> Simulation:
        if comm is None:
            return new_simulation(m, names, specs, initial_state(m, slice(None)), cfl, refinement=rule, **options)
        return shared_simulation(comm, m, initial_state, lambda state, partition: new_simulation(
            m, names, specs, state, cfl, refinement=rule, partition=partition, **options))

    return refine_initial(mesh, build, wanted_level)
