"""The run configuration: a YAML file in SI units, validated before any work starts.

The schema is a tree of pydantic models with ``extra="forbid"``.  :func:`load_config`
parses the YAML, checks every key (unknown keys get a did-you-mean), every type and
every value, resolves material presets, and raises :class:`ConfigError` carrying one
line per problem in the form ``config.yaml:12: hydro.cfl: must be <= 1 (got 1.5)``.
Every key is documented in docs/config.md.
"""

from __future__ import annotations

import difflib
import re
import types
import typing
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, create_model, field_validator, model_validator

from impactpipe.hydro.amr.regrid import RefinementRule
from impactpipe.hydro.problems import PROBLEMS, column_collapse
from impactpipe.hydro.problems.parameters import Parameter, Record
from impactpipe.hydro.strength.parameters import check_inertial_friction, has_yield

from . import presets

STAGES = ("hydro", "handoff", "nbody", "analysis")


class YamlLoader(yaml.SafeLoader):
    """SafeLoader that reads floats as YAML 1.2 does: ``1e3`` and ``10.0e3`` are numbers, not strings."""


YamlLoader.yaml_implicit_resolvers = {
    key: [(tag, rx) for tag, rx in resolvers if tag != "tag:yaml.org,2002:float"]
    for key, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
YamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.X,
    ),
    list("-+0123456789."),
)


def load_yaml(text: str) -> Any:
    """Parse YAML text with :class:`YamlLoader`."""
    return yaml.load(text, Loader=YamlLoader)


class ConfigError(ValueError):
    """Invalid configuration; ``messages`` holds one line per problem."""

    def __init__(self, messages: list[str]):
        self.messages = messages
        super().__init__("\n".join(messages))


class Strict(BaseModel):
    """Base model: unknown keys are errors, values are validated on assignment."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)


# --------------------------------------------------------------------------- materials


class IdealGasEOS(Strict):
    model: Literal["ideal_gas"]
    gamma: float = Field(1.4, gt=1.0, description="adiabatic index")
    cv: float | None = Field(None, gt=0, description="specific heat at constant volume (J/kg/K)")


class TillotsonEOS(Strict):
    model: Literal["tillotson"]
    preset: str | None = None
    rho0: float | None = Field(None, gt=0)
    A: float | None = Field(None, gt=0)
    B: float | None = None
    E0: float | None = Field(None, gt=0)
    E_iv: float | None = Field(None, ge=0)
    E_cv: float | None = Field(None, ge=0)
    a: float | None = None
    b: float | None = None
    alpha: float | None = Field(None, ge=0)
    beta: float | None = Field(None, ge=0)
    rho_iv: float | None = Field(None, ge=0)
    cv: float | None = Field(None, gt=0)

    @model_validator(mode="after")
    def _energies_ordered(self) -> "TillotsonEOS":
        if self.E_iv is not None and self.E_cv is not None and self.E_cv <= self.E_iv:
            raise ValueError(f"E_cv must be larger than E_iv (got E_iv={self.E_iv:g}, E_cv={self.E_cv:g})")
        return self


class MieGruneisenEOS(Strict):
    model: Literal["mie_gruneisen"]
    preset: str | None = None
    rho0: float | None = Field(None, gt=0)
    c0: float | None = Field(None, gt=0)
    s: float | None = Field(None, ge=0)
    gamma0: float | None = Field(None, ge=0)
    cv: float | None = Field(None, gt=0)


class TableEOS(Strict):
    model: Literal["table"]
    path: str = Field(description="SESAME-style text table; relative paths are relative to the config file")
    cv: float | None = Field(None, gt=0)


EOSSpec = Annotated[Union[IdealGasEOS, TillotsonEOS, MieGruneisenEOS, TableEOS], Field(discriminator="model")]


class DamageSpec(Strict):
    model: Literal["instant", "grady_kipp"] = "instant"
    preset: str | None = None
    weibull_m: float | None = Field(None, gt=0, description="Weibull exponent m of the flaw law n = k eps^m")
    weibull_k: float | None = Field(None, gt=0, description="Weibull coefficient k of the flaw law (m^-3)")
    young_modulus: float | None = Field(None, gt=0, description="Young's modulus for the tensile strain (Pa)")
    flaw_seed: int | None = Field(None, ge=0, description="seed of the material's flaw draw")
    flaw_count: int | None = Field(None, ge=1, description="flaws drawn for the material (default N ln N)")
    flaw_cross_section: float | None = Field(None, gt=0, description="area a 1-D mesh stands for in the draw (m^2)")
    active_flaw_limit: bool | None = Field(None, description="damage at most the fraction of a cell's flaws that "
                                                             "are active, D <= n_act / n_tot (default true)")


class StrengthSpec(Strict):
    model: Literal["none", "von_mises", "geo", "rock"] = "none"
    preset: str | None = None
    Y0: float | None = Field(None, ge=0, description="cohesion, yield strength at zero pressure (Pa)")
    Y_M: float | None = Field(None, ge=0, description="von Mises limit of the intact curve (Pa)")
    Y_T: float | None = Field(None, ge=0, description="tensile strength (Pa)")
    Y_c: float | None = Field(None, ge=0, description="damaged cohesion (Pa)")
    mu_i: float | None = Field(None, ge=0, description="intact coefficient of internal friction")
    mu_d: float | None = Field(None, ge=0, description="damaged coefficient of friction")
    poisson: float | None = Field(None, gt=-1.0, lt=0.5, description="Poisson's ratio")
    shear_modulus: float | None = Field(None, gt=0, description="constant shear modulus (Pa)")
    yield_strength: float | None = Field(None, ge=0, description="von Mises yield strength (Pa)")
    T_melt: float | None = Field(None, gt=0, description="melting temperature (K)")
    xi: float | None = Field(None, ge=0, description="thermal softening parameter")
    P_bd: float | None = Field(None, ge=0, description="brittle-ductile transition pressure (Pa)")
    P_bp: float | None = Field(None, ge=0, description="brittle-plastic transition pressure (Pa)")
    initial_damage: float | None = Field(None, ge=0, le=1, description="damage D at t = 0 (rock model)")
    mu_2: float | None = Field(None, ge=0, description="mu(I) friction (geo model): the friction coefficient "
                                                     "as I -> infinity, >= mu_i (mu_s)")
    inertial_number_I0: float | None = Field(None, gt=0, description="mu(I) friction (geo model): the inertial "
                                                                     "number I0 of mu = (mu_s + mu_2) / 2")
    grain_diameter: float | None = Field(None, gt=0, description="mu(I) friction (geo model): the grain "
                                                                 "diameter d of I = gamma_dot d / sqrt(P / rho_s) (m)")
    damage: DamageSpec | None = Field(None, description="tensile damage: a grady_kipp block, or the name of a "
                                                        "grady_kipp preset; instant failure at Y_T if absent")

    @field_validator("damage", mode="before")
    @classmethod
    def _damage_preset_name(cls, value: Any) -> Any:
        """``damage: basalt`` stands for ``{model: grady_kipp, preset: basalt}``."""
        return _damage_block(value) if isinstance(value, str) else value

    @model_validator(mode="after")
    def _inertial_friction(self) -> "StrengthSpec":
        """The mu(I) keys: all three or none, for the geo model only, mu_2 >= mu_i where both are given."""
        check_inertial_friction(self.model_dump())
        return self


class PorositySpec(Strict):
    """Epsilon-alpha compaction of a porous material (:mod:`impactpipe.hydro.eos.porosity`)."""

    preset: str | None = None
    alpha0: float | None = Field(None, ge=1, description="initial distension rho_solid / rho (1: no pores)")
    eps_e: float | None = Field(None, le=0, description="volumetric strain where compaction starts (-)")
    kappa: float | None = Field(None, gt=0, description="exponential compaction rate (-)")
    alpha_x: float | None = Field(None, ge=1, description="distension where compaction turns to the power law (-)")
    chi: float | None = Field(None, gt=0, le=1, description="elastic wave speed of the unstrained porous material over "
                                                           "the matrix's (-, Collins et al. 2011; 1: the matrix's)")


class Material(Strict):
    eos: EOSSpec
    strength: StrengthSpec = Field(default_factory=StrengthSpec)
    porosity: PorositySpec | None = Field(None, description="epsilon-alpha porosity: a block, or a preset name")

    @field_validator("porosity", mode="before")
    @classmethod
    def _porosity_preset_name(cls, value: Any) -> Any:
        """``porosity: basalt`` stands for ``{preset: basalt}``."""
        return {"preset": value} if isinstance(value, str) else value


# --------------------------------------------------------------------------- scene
#
# Each problem module of impactpipe.hydro.problems declares its scene's parameters
# (``PARAMETERS``: default, type, bounds, units); the scene models below are built from
# them, so the config and the library cannot disagree on a key, a default or a bound.


Geometry = Literal["auto", "1d-planar", "2d-planar", "2d-cylindrical", "3d"]

#: The problem a scene without ``problem`` is read as (by the unknown-key check).
DEFAULT_PROBLEM = "impact"


def _description(param: Parameter | Record) -> str | None:
    """The schema's description of a declared parameter: its meaning and units."""
    units = getattr(param, "units", "")
    if param.description and units:
        return f"{param.description} ({units})"
    return param.description or units or None


def _field(param: Parameter | Record) -> tuple[Any, Any]:
    """(annotation, Field) of a declared parameter."""
    if isinstance(param, Record):
        model = _record_model(param)
        if param.required:
            return model, Field(description=_description(param))
        return model | None, Field(None, description=_description(param))
    default = ... if param.required else param.default
    return param.kind, Field(default, description=_description(param), **param.bounds())


#: (model, declared fields) by record name, so records of one kind (both sides of a shock
#: tube) share a model.
_RECORD_MODELS: dict[str, tuple[type[Strict], dict[str, Parameter]]] = {}


def _record_model(record: Record) -> type[Strict]:
    """The model of a record kind (e.g. ``FluidState``), built on first use."""
    if record.name not in _RECORD_MODELS:
        model = create_model(record.name, __base__=Strict, __module__=__name__,
                             **{key: _field(p) for key, p in record.fields.items()})
        _RECORD_MODELS[record.name] = (_register(model), record.fields)
    model, fields = _RECORD_MODELS[record.name]
    if fields != record.fields:
        raise TypeError(f"record {record.name} is declared with two different sets of fields")
    return model


def _register(model: type[Strict]) -> type[Strict]:
    """Make a built model a name of this module, so configs pickle (sweep workers receive them)."""
    globals()[model.__name__] = model
    return model


def _cross_checks(check: Any) -> Any:
    """A model validator raising the problem module's ``check_parameters`` messages."""

    def validate(self: Strict) -> Strict:
        messages = check(self.model_dump())
        if messages:
            raise ValueError("; ".join(messages))
        return self

    return model_validator(mode="after")(validate)


def scene_model(name: str, problem: Any) -> type[Strict]:
    """The scene model of problem ``name`` from its module's ``PARAMETERS`` (e.g. ``ShockTubeScene``)."""
    fields: dict[str, Any] = {
        "problem": (Literal[name], name if name == DEFAULT_PROBLEM else ...),
        "geometry": (Geometry, "auto"),
    }
    fields.update({key: _field(param) for key, param in problem.PARAMETERS.items()})
    check = getattr(problem, "check_parameters", None)
    validators = {"_cross_checks": _cross_checks(check)} if check is not None else None
    title = "".join(part.capitalize() for part in name.split("_")) + "Scene"
    return _register(create_model(title, __base__=Strict, __module__=__name__, __validators__=validators,
                                  **fields))


#: The scene model of each problem, by name.
SCENES: dict[str, type[Strict]] = {name: scene_model(name, module) for name, module in PROBLEMS.items()}

Scene = Annotated[Union[tuple(SCENES.values())], Field(discriminator="problem")]


# --------------------------------------------------------------------------- stages


class RefinementBox(Strict):
    lo: list[float] = Field(description="lower corner (m), one value per used axis")
    hi: list[float] = Field(description="upper corner (m), one value per used axis")
    level: int = Field(ge=0, description="refine every block overlapping the box to at least this level")

    @model_validator(mode="after")
    def _ordered(self) -> "RefinementBox":
        if len(self.lo) != len(self.hi) or any(h <= lo for lo, h in zip(self.lo, self.hi)):
            raise ValueError(f"lo = {self.lo} and hi = {self.hi} must have the same length with hi > lo on every axis")
        return self


class Refinement(Strict):
    """``hydro.refinement``: when and where an adaptive mesh refines (impactpipe.hydro.amr.regrid.RefinementRule)."""

    interval: int = Field(RefinementRule.interval, ge=1, description="steps between regrids")
    interfaces: Literal["all", "active", "off"] = Field(
        RefinementRule.interfaces, description="refine at material interfaces and free surfaces: everywhere to the "
                                               "finest level (all), there only where they move or are loaded and one "
                                               "level coarser where quiet (active), or not (off)")
    pressure_jump: float | None = Field(RefinementRule.pressure_jump, gt=0, lt=1,
                                        description="relative pressure jump across a cell that refines (null: off)")
    density_jump: float | None = Field(RefinementRule.density_jump, gt=0, lt=1,
                                       description="relative density jump across a cell that refines (null: off)")
    pressure_floor: float = Field(RefinementRule.pressure_floor, gt=0, lt=1,
                                  description="pressure floor of the jump indicator, fraction of the largest |p|")
    activity_floor: float | None = Field(RefinementRule.activity_floor, gt=0, lt=1,
                                         description="activity threshold of interfaces: active, fraction of the "
                                                     "largest |p| and speed (null: pressure_floor)")
    buffer: Literal["block", "reach"] = Field(
        RefinementRule.buffer, description="neighbours refined with a block holding a pressure or density jump: all "
                                           "(block) or those across the faces the jump lies within a regrid's wave "
                                           "travel of (reach)")
    boxes: list[RefinementBox] = Field(default_factory=list)
    material_depth: int | None = Field(RefinementRule.material_depth, ge=0,
                                       description="levels below the finest that a block holding material may "
                                                   "coarsen to (null: any)")

    @field_validator("interfaces", mode="before")
    @classmethod
    def _unquoted_off(cls, value: Any) -> Any:
        """YAML 1.1 reads an unquoted ``off`` as false; it means the mode ``off``."""
        return "off" if value is False else value


class Tracers(Strict):
    enabled: bool | Literal["auto"] = "auto"
    count: int = Field(900, ge=0)
    history_interval: float | None = Field(None, gt=0, description="s between recorded trajectory points")


class Hydro(Strict):
    cells_per_projectile_radius: float = Field(20.0, gt=0)
    block_cells: int | None = Field(None, ge=4, le=64, description="cells per block edge; default: impacts and adaptive meshes 16 in 2D, 8 in 3D, uniform meshes up to 64 in 2D and 16 in 3D")
    max_levels: int | Literal["auto"] = "auto"
    refinement: Refinement = Field(default_factory=Refinement)
    time_stepping: Literal["global", "per_level"] = Field(
        "global", description="global: one time step (the finest cells' CFL step) for every level; per_level: "
                              "level l steps dt_0 / 2^l with flux registers at level faces (one rank, no strength, "
                              "gravity or porosity yet)")
    cfl: float = Field(0.4, gt=0, le=1)
    end_time: float | Literal["auto"] = "auto"
    output_times: list[float] | None = None
    output_interval: float | None = Field(None, gt=0)
    checkpoint_wall_seconds: float = Field(300.0, gt=0, description="wall seconds between checkpoints")
    tracers: Tracers = Field(default_factory=Tracers)
    self_gravity: bool | Literal["auto"] = "auto"

    @field_validator("max_levels")
    @classmethod
    def _levels_positive(cls, v: Any) -> Any:
        if v != "auto" and v < 1:
            raise ValueError(f"must be 'auto' or an integer >= 1 (got {v})")
        return v

    @field_validator("end_time")
    @classmethod
    def _end_time_positive(cls, v: Any) -> Any:
        if v != "auto" and v <= 0:
            raise ValueError(f"must be 'auto' or a time > 0 s (got {v})")
        return v

    @field_validator("output_times")
    @classmethod
    def _times_sorted(cls, v: list[float] | None) -> list[float] | None:
        if v is not None and (any(t < 0 for t in v) or sorted(v) != v):
            raise ValueError(f"must be non-negative and increasing (got {v})")
        return v


class IntactFragments(Strict):
    enabled: bool = Field(False, description="make each intact fragment larger than a block one N-body sphere")
    max_damage: float = Field(0.99, gt=0, le=1, description="cells at or above this damage are broken")
    min_fill: float = Field(0.5, gt=0, le=1, description="least volume fraction of material in a fragment's cell")


class Handoff(Strict):
    time: float | None = Field(None, gt=0, description="hand-off time (s): the hydro snapshot at this time; "
                                                       "default the end of the hydro stage")
    min_density_fraction: float = Field(0.75, gt=0, le=1)
    min_mass_fraction: float = Field(4.0e-7, ge=0, lt=1)
    velocity_noise: float = Field(0.01, ge=0, description="fraction of the target's escape speed")
    seed: int = 1
    particle_resolution: float | None = Field(
        None, gt=0, description="cells per projectile radius of the blocks that become spheres (impact scenes): "
                                "leaf blocks finer than that are merged into their ancestor blocks first, so the "
                                "N-body particles are those of a coarser mesh; hydro.cells_per_projectile_radius "
                                "divided by a power of two; default the leaf blocks as they are")
    intact_fragments: IntactFragments = Field(default_factory=IntactFragments)
    window: list[float] | None = Field(
        None, description="hand-off window (s): two or more increasing hand-off times, after ~4 target "
                          "sound-crossing times, over which `impactpipe convergence` averages M_lr/M_T by default "
                          "(one hydro run to the last of them, a hand-off and N-body run at each); their mean is "
                          "the answer and their spread the hand-off-time error")

    @field_validator("window")
    @classmethod
    def _window_increasing(cls, v: list[float] | None) -> list[float] | None:
        if v is not None and (len(v) < 2 or any(t <= 0 for t in v) or sorted(set(v)) != v):
            raise ValueError(f"must be two or more increasing times > 0 s (got {v})")
        return v


class Restitution(Strict):
    normal: float = Field(0.5, ge=0, le=1)
    tangential: float = Field(1.0, ge=0, le=1)


class Stop(Strict):
    min_dynamical_times: float = Field(50.0, ge=0)
    max_orbiting_fraction: float = Field(0.1, gt=0, le=1)
    max_quiet_dynamical_times: float = Field(
        200.0, gt=0, description="stop (status stable_orbits) when mass keeps orbiting the largest remnant but "
                                 "the particle count and the orbiting mass have not changed for this many t_dyn")
    max_time: float | None = Field(None, gt=0, description="simulated-time cap (s)")
    max_dynamical_times: float = Field(
        2000.0, gt=0, description="simulated-time cap in t_dyn (status time_cap): a guard against runs that never "
                                  "settle; equilibrium usually comes within 50-100 t_dyn")
    max_wall_seconds: float | None = Field(None, gt=0, description="wall-clock cap (s)")


class NBody(Strict):
    collision_model: Literal["merge", "conditional_merge", "bounce"] = "merge"
    restitution: Restitution = Field(default_factory=Restitution)
    opening_angle: float = Field(0.5, gt=0, le=2.0)
    steps_per_dynamical_time: float = Field(
        100.0, gt=0, description="time-step rule, orbit term: dt <= t_dyn / steps_per_dynamical_time, "
                                 "t_dyn = 1/sqrt(G rho_bulk) (s)")
    collision_step_fraction: float = Field(
        0.5, gt=0, le=1, description="time-step rule, collision term: dt <= collision_step_fraction r_min / "
                                     "v_rel_max (m over m/s); <= 1 so a head-on pair cannot skip its overlap")
    stop: Stop = Field(default_factory=Stop)
    box_factor: float = Field(
        10.0, gt=1, description="half-width of REBOUND's root box over the hand-off cloud's extent: bound particles "
                                "beyond 0.9 of it are removed (nbody_budget.mass_left_box); raise it when that mass "
                                "is not negligible")
    seed: int = 1


class Analysis(Strict):
    plots: bool = True


class Config(Strict):
    name: str = Field(min_length=1)
    output: str | None = Field(None, description="run directory; default runs/<name>; --out overrides")
    scene: Scene
    materials: dict[str, Material] = Field(default_factory=dict)
    hydro: Hydro = Field(default_factory=Hydro)
    handoff: Handoff = Field(default_factory=Handoff)
    nbody: NBody = Field(default_factory=NBody)
    analysis: Analysis = Field(default_factory=Analysis)

    #: Directory of the YAML file; table paths are resolved against it.
    _source_dir: Path = Path(".")
    #: The YAML file and its text, so checks made after loading can name a key's line.
    _source: Path = Path("<config>")
    _source_text: str = ""

    def resolved_materials(self) -> dict[str, dict[str, Any]]:
        """Each material's complete EOS and strength parameters (presets applied)."""
        out = {}
        for name, mat in self.materials.items():
            eos = mat.eos.model_dump(exclude={"model", "preset"})
            if mat.eos.model == "table":
                eos["path"] = str((self._source_dir / mat.eos.path).resolve())
            strength = presets.resolve_strength(
                mat.strength.model, mat.strength.preset,
                mat.strength.model_dump(exclude={"model", "preset", "damage"}))
            if mat.strength.damage is not None:
                strength["damage"] = presets.resolve_damage(_damage_block(mat.strength.damage))
            out[name] = {
                "eos": presets.resolve_eos(mat.eos.model, getattr(mat.eos, "preset", None), eos),
                "strength": strength,
            }
            if mat.porosity is not None:
                out[name]["porosity"] = presets.resolve_porosity(mat.porosity.model_dump(exclude_none=True))
        return out

    def scene_materials(self) -> list[str]:
        """Names of the materials the scene uses, in order of appearance."""
        return _scene_material_refs(self.scene.model_dump())


def _damage_block(damage: Any) -> dict[str, Any]:
    """A strength spec's ``damage`` as a block: a preset name stands for ``{model: grady_kipp, preset: name}``."""
    if isinstance(damage, str):
        return {"model": "grady_kipp", "preset": damage}
    if isinstance(damage, BaseModel):
        return damage.model_dump(exclude_none=True)
    return dict(damage)


def _scene_material_refs(scene: dict[str, Any]) -> list[str]:
    names: list[str] = []
    for value in scene.values():
        if isinstance(value, dict) and "material" in value:
            if value["material"] not in names:
                names.append(value["material"])
    return names


# --------------------------------------------------------------------------- loading


def load_config(path: str | Path, overrides: dict[str, Any] | None = None) -> Config:
    """Read, validate and resolve a config file.

    ``overrides`` maps dotted key paths (``"hydro.cfl"``) to values applied before
    validation (the sweep and convergence commands use this).  Raises ConfigError.

    Example (from the repository's root)::

        >>> from impactpipe.pipeline import load_config
        >>> config = load_config("configs/quickstart.yaml", overrides={"scene.impact.velocity": 300.0})
        >>> config.scene.target.radius, config.scene.impact.velocity
        (1000.0, 300.0)
    """
    return parse_config(read_yaml_text(path, "config"), source=path, overrides=overrides)


def read_yaml_text(path: str | Path, what: str = "config") -> str:
    """The text of a YAML file; unreadable or not UTF-8, raises ConfigError naming the line."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError([f"{path}: cannot read {what}: {exc.strerror}"]) from exc
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        text = data.decode("utf-8", errors="replace")
        key = _key_at_line(text, line)
        raise ConfigError([f"{path}:{line}: {key}: not UTF-8 text: byte 0x{data[exc.start]:02x} at column {column} "
                           f"(save the file as UTF-8)"]) from None


def _key_at_line(text: str, line: int) -> str:
    """The dotted key whose entry starts at or last before ``line`` (1-based), or ``<root>``."""
    try:
        root = yaml.compose(text)
    except yaml.YAMLError:
        return "<root>"
    best: tuple[int, str] = (-1, "<root>")

    def walk(node: yaml.Node, prefix: str) -> None:
        nonlocal best
        if isinstance(node, yaml.MappingNode):
            for key_node, value_node in node.value:
                dotted = f"{prefix}{key_node.value}"
                if best[0] < key_node.start_mark.line + 1 <= line:
                    best = (key_node.start_mark.line + 1, dotted)
                walk(value_node, dotted + ".")

    if root is not None:
        walk(root, "")
    return best[1]


def duplicate_keys(root: yaml.Node | None, source: str | Path) -> list[str]:
    """One ``file:line: key: message`` line per key given twice in the same mapping (YAML keeps the
    last silently)."""
    found: list[str] = []

    def walk(node: yaml.Node, prefix: str) -> None:
        if isinstance(node, yaml.MappingNode):
            first: dict[str, int] = {}
            for key_node, value_node in node.value:
                dotted = f"{prefix}{key_node.value}"
                line = key_node.start_mark.line + 1
                if key_node.value in first:
                    found.append(f"{source}:{line}: {dotted}: duplicate key (first given at line "
                                 f"{first[key_node.value]}); give it once")
                else:
                    first[key_node.value] = line
                walk(value_node, dotted + ".")
        elif isinstance(node, yaml.SequenceNode):
            for i, item in enumerate(node.value):
                walk(item, f"{prefix[:-1]}[{i}].")

    if root is not None:
        walk(root, "")
    return found


def parse_config(text: str, source: str | Path = "<config>", overrides: dict[str, Any] | None = None) -> Config:
    """Validate YAML text as a config; see :func:`load_config`."""
    source = Path(source)
    try:
        data = load_yaml(text)
        root = yaml.compose(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{source}:{mark.line + 1}" if mark else str(source)
        raise ConfigError([f"{where}: not valid YAML: {getattr(exc, 'problem', exc)}"]) from exc
    if not isinstance(data, dict):
        raise ConfigError([f"{source}: the config must be a mapping of keys, got {type(data).__name__}"])
    for dotted, value in (overrides or {}).items():
        set_dotted(data, dotted, value)
    lines = _LineFinder(source, root)
    duplicates = duplicate_keys(root, source)
    found = unknown_keys(data, Config) + semantic_errors(data, source.parent)
    try:
        config = Config.model_validate(data)
    except ValidationError as exc:
        for err in exc.errors():
            if err["type"] != "extra_forbidden":
                found.append((_error_loc(err), _describe(err)))
    else:
        config._source_dir = source.parent.resolve()
        config._source, config._source_text = source, text
    if found or duplicates:
        messages: list[str] = list(duplicates)
        for loc, msg in found:
            line = lines.format(loc, msg)
            if line not in messages:
                messages.append(line)
        raise ConfigError(messages)
    return config


def _error_loc(err: dict[str, Any]) -> tuple:
    loc = _clean_loc(err["loc"])
    if err["type"] in ("union_tag_invalid", "union_tag_not_found"):
        loc = loc + (err["ctx"]["discriminator"].strip("'"),)
    return loc


def set_dotted(data: dict[str, Any], dotted: str, value: Any) -> None:
    """Set ``data[a][b][c] = value`` for ``dotted = "a.b.c"``, creating mappings on the way."""
    keys = dotted.split(".")
    node = data
    for key in keys[:-1]:
        node = node.setdefault(key, {})
        if not isinstance(node, dict):
            raise ConfigError([f"{dotted}: cannot set a key below a non-mapping value"])
    node[keys[-1]] = value


#: Scenes whose setup starts a porous material at its bulk density rho_s0 / alpha0 (docs/eos.md, "Porosity").
POROUS_PROBLEMS = ("impact", "planar_impact", "hydrostatic_body")


def semantic_errors(data: dict[str, Any], source_dir: Path) -> list[tuple[tuple, str]]:
    """Cross-field checks on the raw config mapping: materials, presets, table files, sizes.

    Works on the raw data so these problems are reported together with the schema errors.
    """
    errors: list[tuple[tuple, str]] = []
    materials = data.get("materials") or {}
    materials = materials if isinstance(materials, dict) else {}
    defined = sorted(str(k) for k in materials)
    scene = data.get("scene") if isinstance(data.get("scene"), dict) else {}
    for key, value in scene.items():
        if isinstance(value, dict) and isinstance(value.get("material"), str):
            name = value["material"]
            if name not in materials:
                allowed = ", ".join(defined) if defined else "none defined"
                errors.append((("scene", key, "material"),
                               f"'{name}' is not defined under materials (defined: {allowed}){_did_you_mean(name, defined)}"))
    if isinstance(scene.get("material"), str) and scene["material"] not in materials:
        allowed = ", ".join(defined) if defined else "none defined"
        errors.append((("scene", "material"), f"'{scene['material']}' is not defined under materials "
                                              f"(defined: {allowed}){_did_you_mean(scene['material'], defined)}"))
    hydro = data.get("hydro") if isinstance(data.get("hydro"), dict) else {}
    if scene.get("problem") == "column_collapse":
        cfl = hydro.get("cfl", Hydro.model_fields["cfl"].default)
        if isinstance(cfl, (int, float)) and cfl > column_collapse.MAX_CFL:
            errors.append((("hydro", "cfl"), f"must be <= {column_collapse.MAX_CFL:g} for the column_collapse scene "
                                             f"(got {cfl:g}): the deposit's "
                                             f"independence of the time step is measured up to there "
                                             f"(docs/validation.md, granular column collapse)"))
    if scene.get("problem", "impact") != "impact":
        errors.extend(_impact_only_errors(str(scene.get("problem")), hydro))
    if scene.get("problem", "impact") == "impact":
        rt = (scene.get("target") or {}).get("radius") if isinstance(scene.get("target"), dict) else None
        rp = (scene.get("projectile") or {}).get("radius") if isinstance(scene.get("projectile"), dict) else None
        if isinstance(rt, (int, float)) and isinstance(rp, (int, float)) and rt > 0 and rp > rt:
            errors.append((("scene", "projectile", "radius"),
                           f"must not exceed scene.target.radius = {rt:g} m for an impact (got {rp:g})"))
    for name, mat in materials.items():
        if not isinstance(mat, dict):
            continue
        errors.extend(_material_errors(str(name), mat, source_dir))
        problem = scene.get("problem", "impact")
        if mat.get("porosity") is not None and problem not in POROUS_PROBLEMS:
            errors.append((("materials", name, "porosity"),
                           f"the {problem} scene does not start porous materials at their bulk density; porosity "
                           f"runs in the {' and '.join(POROUS_PROBLEMS)} scenes"))
    handoff = data.get("handoff") if isinstance(data.get("handoff"), dict) else {}
    intact = handoff.get("intact_fragments") if isinstance(handoff.get("intact_fragments"), dict) else {}
    if intact.get("enabled") is True and not any(
            isinstance(m, dict) and isinstance(m.get("strength"), dict)
            and m["strength"].get("model", "none") != "none" for m in materials.values()):
        errors.append((("handoff", "intact_fragments", "enabled"),
                       "needs a material with strength: fragments are cells whose damage stays below "
                       "max_damage, and only a strength model computes damage"))
    return errors


def _impact_only_errors(problem: str, hydro: dict[str, Any]) -> list[tuple[tuple, str]]:
    """``hydro`` keys set for a scene other than an impact, which would be ignored there."""
    errors: list[tuple[tuple, str]] = []
    if hydro.get("end_time", "auto") != "auto":
        errors.append((("hydro", "end_time"), f"applies to impact scenes only; the {problem} scene runs "
                                              f"to scene.end_time, so this value would be ignored: remove it and "
                                              f"set scene.end_time"))
    if "cells_per_projectile_radius" in hydro:
        errors.append((("hydro", "cells_per_projectile_radius"),
                       f"applies to impact scenes only; the {problem} scene sets its own resolution in its "
                       f"scene keys, so this value would be ignored: remove it"))
    if hydro.get("self_gravity", "auto") != "auto":
        errors.append((("hydro", "self_gravity"),
                       f"applies to impact scenes only; the {problem} scene decides its own gravity "
                       f"(docs/config.md, its scene table), so this value would be ignored: remove it"))
    tracers = hydro.get("tracers") if isinstance(hydro.get("tracers"), dict) else {}
    if tracers.get("enabled", "auto") is True:
        errors.append((("hydro", "tracers", "enabled"),
                       f"tracers are placed for impact scenes only; the {problem} scene has none: "
                       f"remove it or set it to auto"))
    return errors


def _material_errors(name: str, mat: dict[str, Any], source_dir: Path) -> list[tuple[tuple, str]]:
    errors: list[tuple[tuple, str]] = []
    eos = mat.get("eos") if isinstance(mat.get("eos"), dict) else {}
    model = eos.get("model")
    preset = eos.get("preset")
    if model in ("tillotson", "mie_gruneisen"):
        choices = presets.eos_presets(model)
        if preset is not None and preset not in choices:
            errors.append((("materials", name, "eos", "preset"),
                           f"unknown {model} preset '{preset}' (allowed: {', '.join(choices)}){_did_you_mean(str(preset), choices)}"))
        else:
            try:
                presets.resolve_eos(model, preset, {k: v for k, v in eos.items() if k not in ("model", "preset")})
            except KeyError as exc:
                errors.append((("materials", name, "eos"), f"missing parameter {exc.args[0]} (give it or name a preset)"))
    if model == "table" and isinstance(eos.get("path"), str):
        table = source_dir / eos["path"]
        if not table.is_file():
            errors.append((("materials", name, "eos", "path"), f"table file not found: {table}"))
    strength = mat.get("strength") if isinstance(mat.get("strength"), dict) else {}
    smodel = strength.get("model", "none")
    spreset = strength.get("preset")
    if smodel in ("geo", "rock", "von_mises"):
        choices = presets.strength_presets(smodel)
        if spreset is not None and spreset not in choices:
            allowed = ", ".join(choices) if choices else f"no presets exist for model {smodel}"
            errors.append((("materials", name, "strength", "preset"),
                           f"unknown {smodel} preset '{spreset}' (allowed: {allowed}){_did_you_mean(str(spreset), choices)}"))
        else:
            try:
                presets.resolve_strength(smodel, spreset,
                                         {k: v for k, v in strength.items() if k not in ("model", "preset")})
            except KeyError as exc:
                errors.append((("materials", name, "strength"),
                               f"missing parameter {exc.args[0]} for model {smodel} (give it or name a preset)"))
    if strength.get("damage") is not None:
        errors.extend(_damage_errors(name, strength))
    porosity = mat.get("porosity")
    if isinstance(porosity, (dict, str)):
        errors.extend(_porosity_errors(name, {"preset": porosity} if isinstance(porosity, str) else porosity))
    return errors


def _porosity_errors(name: str, porosity: dict[str, Any]) -> list[tuple[tuple, str]]:
    """Errors of a material's ``porosity`` block: unknown preset, missing parameters, alpha_x above
    alpha0."""
    loc = ("materials", name, "porosity")
    preset = porosity.get("preset")
    choices = presets.porosity_presets()
    if preset is not None and preset not in choices:
        return [(loc + ("preset",), f"unknown porosity preset '{preset}' (allowed: {', '.join(choices)})"
                                    f"{_did_you_mean(str(preset), choices)}")]
    try:
        resolved = presets.resolve_porosity(porosity)
    except KeyError as exc:
        return [(loc, f"missing parameter {exc.args[0]} (give it or name a preset)")]
    except (TypeError, ValueError):
        return []  # a value of the wrong type: the schema reports it
    if resolved["alpha0"] < 1.0 or resolved["alpha_x"] < 1.0:
        return []  # out of range: the schema reports it
    if resolved["alpha_x"] > resolved["alpha0"]:
        return [(loc + ("alpha_x",), f"must be <= alpha0 = {resolved['alpha0']:g} (got {resolved['alpha_x']:g}): "
                                     f"compaction runs from alpha0 down through alpha_x to 1")]
    return []


def _damage_errors(name: str, strength: dict[str, Any]) -> list[tuple[tuple, str]]:
    """Errors of a strength spec's ``damage`` (a block or a preset name): unknown preset, missing
    Weibull parameters, Grady-Kipp on a material without a yield strength or without Y_T."""
    loc = ("materials", name, "strength", "damage")
    damage = strength["damage"]
    if not isinstance(damage, (str, dict)):
        return []
    block = _damage_block(damage)
    if block.get("model", "instant") != "grady_kipp" or set(block) - set(DamageSpec.model_fields):
        return []
    choices = presets.damage_presets("grady_kipp")
    preset = block.get("preset")
    if preset is not None and preset not in choices:
        return [(loc if isinstance(damage, str) else loc + ("preset",),
                 f"unknown grady_kipp preset '{preset}' (allowed: {', '.join(choices)}){_did_you_mean(str(preset), choices)}")]
    try:
        presets.resolve_damage(block)
    except KeyError as exc:
        return [(loc, f"missing parameter {exc.args[0]} for model grady_kipp (give it or name a preset)")]
    smodel = strength.get("model", "none")
    try:
        resolved = presets.resolve_strength(smodel, strength.get("preset"),
                                            {k: v for k, v in strength.items() if k not in ("model", "preset", "damage")})
    except (KeyError, TypeError):
        return []
    if not has_yield(resolved):
        return [(loc, f"grady_kipp needs a strength model with a yield strength (model is {smodel}): "
                      f"give the material a von_mises, geo or rock strength, or remove damage")]
    if not resolved.get("Y_T", 0.0) > 0.0:
        return [(loc, "grady_kipp needs strength.Y_T > 0, the most tension the intact material holds "
                      "(where its yield curve closes); fracture usually relieves the tension well below it")]
    return []


# --------------------------------------------------------------------------- error reporting


def unknown_keys(data: Any, model: type[BaseModel], loc: tuple = ()) -> list[tuple[tuple, str]]:
    """Keys in ``data`` that ``model`` does not define, with did-you-mean suggestions."""
    if not isinstance(data, dict):
        return []
    errors = []
    fields = model.model_fields
    for key, value in data.items():
        if key not in fields:
            allowed = sorted(fields)
            errors.append(
                (loc + (key,), f"unknown key{_did_you_mean(str(key), allowed)} (allowed: {', '.join(allowed)})")
            )
            continue
        for sub in _submodels(fields[key].annotation, value):
            if isinstance(value, dict) and sub[0] == "model":
                errors.extend(unknown_keys(value, sub[1], loc + (key,)))
            elif isinstance(value, dict) and sub[0] == "mapping":
                for name, item in value.items():
                    errors.extend(unknown_keys(item, sub[1], loc + (key, name)))
    return errors


def _submodels(annotation: Any, value: Any) -> list[tuple[str, type[BaseModel]]]:
    """The model classes that validate ``value`` under ``annotation`` (unions resolved by tag)."""
    origin = typing.get_origin(annotation)
    if origin is Annotated:
        return _submodels(typing.get_args(annotation)[0], value)
    if origin in (Union, types.UnionType):
        candidates = [a for a in typing.get_args(annotation) if isinstance(a, type) and issubclass(a, BaseModel)]
        if len(candidates) == 1:
            return [("model", candidates[0])]
        if isinstance(value, dict):
            for cand in candidates:
                for tag in ("problem", "model"):
                    field = cand.model_fields.get(tag)
                    if field is not None and value.get(tag, field.default) in typing.get_args(field.annotation):
                        return [("model", cand)]
        return []
    if origin is dict:
        item = typing.get_args(annotation)[1]
        if isinstance(item, type) and issubclass(item, BaseModel):
            return [("mapping", item)]
        return []
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [("model", annotation)]
    return []


def _clean_loc(loc: tuple) -> tuple:
    """Drop the tag pydantic inserts after a discriminated union (``scene.impact.target`` -> ``scene.target``)."""
    out: list = []
    skip_next = False
    for part in loc:
        if skip_next:
            skip_next = False
            continue
        out.append(part)
        path = tuple(out)
        if path == ("scene",) or (len(path) == 3 and path[0] == "materials" and path[2] == "eos"):
            skip_next = True
    return tuple(out)


def _describe(err: dict[str, Any]) -> str:
    kind = err["type"]
    ctx = err.get("ctx", {})
    got = err.get("input")
    got_text = f" (got {got!r})" if not isinstance(got, dict) else ""
    if kind == "missing":
        return "required key is missing"
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        op = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<", "less_than_equal": "<="}[kind]
        bound = list(ctx.values())[0]
        bound_text = f"{bound:g}" if isinstance(bound, (int, float)) else str(bound)
        return f"must be {op} {bound_text}{got_text}"
    if kind == "literal_error":
        return f"must be one of {ctx.get('expected')}{got_text}"
    if kind == "union_tag_invalid":
        tags = [t.strip(" '") for t in str(ctx.get("expected_tags", "")).split(",")]
        return f"unknown value '{ctx.get('tag')}' (allowed: {', '.join(tags)}){_did_you_mean(str(ctx.get('tag')), tags)}"
    if kind == "union_tag_not_found":
        return "required key is missing (it selects the kind of this entry)"
    if kind == "value_error":
        return str(ctx.get("error", err["msg"]))
    return f"{err['msg'].lower()}{got_text}"


def _did_you_mean(word: str, choices: list[str]) -> str:
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


class _LineFinder:
    """Maps a key path to its line in the YAML source using the composed node tree."""

    def __init__(self, source: Path, root: yaml.Node | None):
        self.source = source
        self.root = root

    def line(self, loc: tuple) -> int | None:
        node = self.root
        line = None
        for part in loc:
            if isinstance(node, yaml.MappingNode):
                for key_node, value_node in node.value:
                    if key_node.value == str(part):
                        line = key_node.start_mark.line + 1
                        node = value_node
                        break
                else:
                    return line
            elif isinstance(node, yaml.SequenceNode) and isinstance(part, int) and part < len(node.value):
                node = node.value[part]
                line = node.start_mark.line + 1
            else:
                return line
        return line

    def format(self, loc: tuple, message: str) -> str:
        key = ".".join(str(p) for p in loc) or "<root>"
        line = self.line(loc)
        where = f"{self.source}:{line}" if line else f"{self.source}"
        return f"{where}: {key}: {message}"


def key_paths(model: type[BaseModel] = Config, prefix: str = "") -> list[str]:
    """Every dotted key path the schema accepts (``materials.<name>.eos.A``, ``scene.left.density``...)."""
    paths: list[str] = []
    for name, field in model.model_fields.items():
        path = f"{prefix}{name}"
        paths.append(path)
        annotation = field.annotation
        mapping = typing.get_origin(annotation) is dict
        for sub in _model_classes(annotation):
            paths.extend(key_paths(sub, path + (".<name>." if mapping else ".")))
    return sorted(set(paths))


def _model_classes(annotation: Any) -> list[type[BaseModel]]:
    origin = typing.get_origin(annotation)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    if origin is Annotated:
        return _model_classes(typing.get_args(annotation)[0])
    if origin in (Union, types.UnionType, dict):
        return [m for arg in typing.get_args(annotation) for m in _model_classes(arg)]
    return []
