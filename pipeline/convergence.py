"""Convergence ladders: the answers of a run against what they cost, with a Richardson estimate.

A *ladder* varies one config key over a list of values (``--vary KEY=V1,V2,...``) with
every other key at its value in the base config; several ladders run together.  The
rungs go through the sweep machinery (:class:`impactpipe.pipeline.sweep.SweepRunner`),
so they run on a process pool or a Dask cluster, resume after a kill, share the hydro
run between rungs that differ only downstream (an opening-angle or hand-off-time
ladder runs the hydro once) and run a rung common to two ladders once.

For each rung the answers are

- M_lr/M_T and N_lr (``summary.json`` of the analysis stage),
- the hand-off mass fractions on escape orbits (``unbound_at_handoff``) and at 0.6-1 times
  their escape speed (``near_escape_at_handoff``) at the start of the N-body stage
  (``nbody_budget``): the velocity field that M_lr/M_T is decided from, without the
  reaccumulation's scatter (docs/accuracy.md, "What in the hand-off moves M_lr/M_T"),
- the kinetic energy (J) of the material within one target radius of the centre of mass at
  the hand-off, in its centre-of-mass frame (``target_kinetic_energy`` of the hand-off stage,
  :func:`impactpipe.handoff.moments.target_kinetic_energy`): the hydro answer the
  reaccumulation amplifies, which converges where M_lr/M_T may not yet,
- the peak shock pressure (Pa) at fixed depths below the impact point, in projectile
  radii, read from the tracers of the ray next to the symmetry axis in ``hydro.h5``
  (interpolated linearly in log P against log distance; NaN outside the ray),

and the costs are the wall seconds of each stage, the hydro steps and cell-updates
(``summary.json``) and the N-body steps and particle-steps when the N-body stage
records them (``stages.nbody.steps``, ``stages.nbody.particle_steps``; blank otherwise).
A rung that adopted another rung's hydro run reports that run's hydro cost: the cost of
the rung run on its own.

Richardson extrapolation (:func:`impactpipe.analysis.richardson.richardson`) applies to keys with a known step size h
(h -> 0 is the converged limit, :data:`STEP_SIZE`): with the three finest rungs
h1 < h2 < h3 and answers f1, f2, f3, the model f = f* + C h^p gives

    (f3 - f2) / (f2 - f1) = r21^p (r32^p - 1) / (r21^p - 1),   r21 = h2/h1, r32 = h3/h2,

solved for the observed order p (p = ln((f3 - f2)/(f2 - f1)) / ln r for a constant
ratio r), then f* = f1 + (f1 - f2) / (r21^p - 1), and each rung's error estimate is
f_i - f*.  With fewer than three rungs, answers that do not change monotonically,
differences that do not shrink with refinement, or an observed order below
:data:`impactpipe.analysis.richardson.MIN_ORDER`, no value is extrapolated and the table says why.
"""

from __future__ import annotations

import concurrent.futures as cf
import csv
import io
import logging
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import yaml

from impactpipe import storage
from impactpipe.analysis.richardson import RESAMPLING_DRAWS, Extrapolation, resampled_richardson, richardson

from . import checks
from .config import ConfigError, key_paths
from .stages import STAGES, read_records, stage_hashes
from .sweep import Sweep, SweepSpec, donor_problems, handoff_time_params, open_runner, with_replicates

log = logging.getLogger(__name__)

SPEC_FILE = "convergence.yaml"
TABLE_FILE = "convergence.csv"
RICHARDSON_FILE = "richardson.csv"
JSON_FILE = "convergence.json"

#: Keys with a known discretisation step size h(value); h -> 0 is the converged limit.
STEP_SIZE: dict[str, tuple[str, Any]] = {
    "hydro.cells_per_projectile_radius": ("1 / value (finest cell size in projectile radii)", lambda v: 1.0 / v),
    "hydro.cfl": ("value (Courant number: hydro time step)", lambda v: v),
    "handoff.particle_resolution": ("1 / value (N-body particle size: hand-off block edge in block_cells "
                                    "projectile radii)", lambda v: 1.0 / v),
    "nbody.opening_angle": ("value (Barnes-Hut opening angle, rad)", lambda v: v),
    # the N-body time step is min(t_dyn / n, f r_min / v_rel_max) (docs/nbody.md): each key sets
    # one term, which is the step size wherever that term is the smaller one
    "nbody.steps_per_dynamical_time": ("1 / value (N-body time step in t_dyn where the orbit term binds)",
                                       lambda v: 1.0 / v),
    "nbody.collision_step_fraction": ("value (N-body time step in r_min / v_rel_max where the collision "
                                      "term binds)", lambda v: v),
}
#: Default depths of the peak-pressure answers, in projectile radii below the impact point.
DEFAULT_DEPTHS = (1.0, 2.0, 4.0)
#: Default tolerance on M_lr/M_T for the cheapest acceptable rung.
DEFAULT_TOLERANCE = 0.05
#: Cost columns: name -> (units, how to read it from a summary).
COSTS = {
    "wall_total": "s",
    "wall_hydro": "s",
    "wall_handoff": "s",
    "wall_nbody": "s",
    "wall_analysis": "s",
    "hydro_steps": "steps",
    "cell_updates": "cell-updates",
    "nbody_steps": "steps",
    "particle_steps": "particle-steps",
}
#: The costs drawn against the answers in the figures (when a ladder records them).
FIGURE_COSTS = ("wall_total", "cell_updates", "particle_steps")


class LadderError(ValueError):
    """Invalid ladder arguments; ``messages`` holds one line per problem (nothing has run)."""

    def __init__(self, messages: list[str]):
        self.messages = messages
        super().__init__("\n".join(messages))


# --------------------------------------------------------------------------- arguments


def parse_vary(texts: list[str] | tuple[str, ...]) -> dict[str, list[Any]]:
    """``["KEY=V1,V2,..."]`` -> ``{KEY: [V1, V2, ...]}``; values are YAML scalars (1, 0.5, auto).

    Raises LadderError for a malformed argument, a repeated key or a ladder of fewer than
    two distinct values.
    """
    ladders: dict[str, list[Any]] = {}
    messages = []
    for text in texts:
        key, sep, values_text = text.partition("=")
        key = key.strip()
        if not sep or not key or not values_text.strip():
            messages.append(f"--vary: expected KEY=V1,V2,... (got {text!r})")
            continue
        try:
            values = [yaml.safe_load(v.strip()) for v in values_text.split(",") if v.strip()]
        except yaml.YAMLError:
            messages.append(f"--vary {key}: cannot read the values {values_text!r}")
            continue
        if key in ladders:
            messages.append(f"--vary {key}: given twice")
        elif len(set(map(repr, values))) < 2 or len(set(map(repr, values))) != len(values):
            messages.append(f"--vary {key}: a ladder needs at least two distinct values (got {values_text!r})")
        else:
            ladders[key] = values
    if messages:
        raise LadderError(messages)
    return ladders


def parse_floats(text: str, option: str) -> list[float]:
    """``"1,2,4"`` -> ``[1.0, 2.0, 4.0]`` (all > 0), or LadderError naming ``option``."""
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise LadderError([f"{option}: expected comma-separated numbers (got {text!r})"]) from None
    if not values or any(not (v > 0 and math.isfinite(v)) for v in values):
        raise LadderError([f"{option}: expected numbers > 0 (got {text!r})"])
    return values


# --------------------------------------------------------------------------- Richardson


@dataclass
class Uncertainty:
    """How the seed scatter of a ladder's rung means carries into its Richardson estimate.

    Attributes:
        draws: resamplings of the rung means.
        refused: share of the draws that Richardson refused (non-monotone, order below
            ``MIN_ORDER``, ...).
        low, median, high: 16th, 50th and 84th percentiles of f* over the accepted draws.
        within: per rung (input order), the share of all draws in which the rung's mean lies
            within the tolerance of that draw's f* (a refused draw counts as not within).
        next_value: the answer projected one refinement beyond the finest rung from the
            unperturbed means, f* + (f1 - f*) / r21^p (NaN when they do not extrapolate).
        next_within: share of all draws in which that draw's projection lies within the
            tolerance of its f*.
    """

    draws: int
    refused: float
    low: float
    median: float
    high: float
    within: np.ndarray
    next_value: float
    next_within: float

    def as_dict(self, values: list[Any]) -> dict[str, Any]:
        """JSON form, ``within`` keyed by the rungs' ladder values."""
        return {"draws": self.draws, "refused": self.refused, "f_star_16": self.low, "f_star_50": self.median,
                "f_star_84": self.high, "within_tolerance": {str(v): float(w) for v, w in zip(values, self.within)},
                "next_refinement": self.next_value, "next_refinement_within_tolerance": self.next_within}


def _next_refinement(h: np.ndarray, f: np.ndarray, ext: Extrapolation) -> float:
    """f* + (f1 - f*) / r21^p: the answer of one more refinement by r21 (NaN unless ``ext.ok``)."""
    if not ext.ok:
        return float("nan")
    finest = int(np.nanargmin(np.where(np.isfinite(f), h, np.nan)))
    return float(ext.value + (f[finest] - ext.value) / ext.ratios[0] ** ext.order)


def richardson_uncertainty(h: np.ndarray, f: np.ndarray, sem: np.ndarray, tolerance: float,
                           draws: int = RESAMPLING_DRAWS, seed: int = 0) -> Uncertainty | None:
    """Richardson f* and the cheapest-rung test under the rungs' standard errors.

    Each draw replaces every rung's mean f_i by f_i + sem_i x N(0, 1) (the rungs' hand-offs
    are independent runs) and extrapolates (:func:`resampled_richardson`).  Returns None unless every
    rung with an answer has a finite, positive standard error (``--seeds`` or several hand-off
    times).  Deterministic for a given ``seed``.
    """
    h = np.asarray(h, dtype=float)
    f = np.asarray(f, dtype=float)
    sem = np.asarray(sem, dtype=float)
    good = np.isfinite(f) & np.isfinite(h)
    if good.sum() < 3 or not (np.isfinite(sem[good]).all() and (sem[good] > 0).all()):
        return None
    within = np.zeros(h.size)
    next_within = 0
    values = []
    for sample, ext in resampled_richardson(h, np.where(good, f, np.nan), sem, draws, seed):
        if not ext.ok:
            continue
        values.append(ext.value)
        within += np.abs(sample - ext.value) <= tolerance
        next_within += abs(_next_refinement(h, sample, ext) - ext.value) <= tolerance
    low, median, high = (np.percentile(values, (16, 50, 84)) if values else (float("nan"),) * 3)
    return Uncertainty(draws=draws, refused=1.0 - len(values) / draws, low=float(low), median=float(median),
                       high=float(high), within=within / draws,
                       next_value=_next_refinement(h, f, richardson(h, f)), next_within=next_within / draws)


def uncertainty_text(key: str, values: list[Any], unc: Uncertainty, tolerance: float) -> str:
    """One line: the 68 % range of f* and each rung's (and the next refinement's) chance of lying within tolerance."""
    rungs = ", ".join(f"{v}: {w:.2f}" for v, w in zip(values, unc.within))
    projected = (f"{unc.next_value:.4g} projected, " if math.isfinite(unc.next_value)
                 else "no projection from the means themselves, ")
    return (f"{key}: M_lr/M_T f* from {unc.draws} resamplings of the rung means within their sem: "
            f"68 % in [{unc.low:.4g}, {unc.high:.4g}] (median {unc.median:.4g}, {unc.refused:.0%} refused); "
            f"share within +-{tolerance:g} of f*: {rungs}; one refinement beyond the finest rung: "
            f"{projected}within in {unc.next_within:.2f}")


def cheapest_within(h: np.ndarray, f: np.ndarray, reference: float, tolerance: float) -> int | None:
    """Index of the coarsest rung (largest h) such that it and every finer rung lie within
    ``tolerance`` of ``reference``; None when there is none or the reference is not finite."""
    h = np.asarray(h, dtype=float)
    f = np.asarray(f, dtype=float)
    if not math.isfinite(reference):
        return None
    order = [i for i in np.argsort(h) if math.isfinite(f[i])]
    best = None
    for i in order:  # finest first
        if abs(f[i] - reference) > tolerance:
            break
        best = int(i)
    return best


# --------------------------------------------------------------------------- answers


def peak_pressure_at_depths(hydro_path: str | Path, target_radius: float, depths_m: list[float]) -> np.ndarray:
    """Peak pressure (Pa) at distances ``depths_m`` (m) below the impact point (0, R_T) along the
    tracer ray next to the symmetry axis; log-log interpolation between tracers, NaN outside
    the ray, without tracers, or when ``hydro_path`` is not an HDF5 file (stand-in stages)."""
    from impactpipe.hydro.output.io import read_tracers
    from impactpipe.hydro.output.plots import axis_ray

    out = np.full(len(depths_m), np.nan)
    if not h5py.is_hdf5(hydro_path):
        return out
    tracers = read_tracers(hydro_path)
    if tracers is None:
        return out
    try:
        distance, peak = axis_ray(tracers, impact_point=(0.0, target_radius))
    except ValueError:
        return out
    ok = (distance > 0) & (peak > 0)
    if ok.sum() < 2:
        return out
    x, y = np.log(distance[ok]), np.log(peak[ok])
    for k, depth in enumerate(depths_m):
        if x[0] <= math.log(depth) <= x[-1]:
            out[k] = math.exp(np.interp(math.log(depth), x, y))
    return out


def costs_of(summary: dict[str, Any]) -> dict[str, float]:
    """The cost columns of :data:`COSTS` from a run's summary (NaN where not recorded)."""
    stages = summary.get("stages", {})
    walls = {s: float(stages.get(s, {}).get("wall_seconds", np.nan)) for s in STAGES}
    out = {f"wall_{s}": walls[s] for s in STAGES}
    out["wall_total"] = float(sum(walls.values()))
    out["hydro_steps"] = float(stages.get("hydro", {}).get("steps", np.nan))
    out["cell_updates"] = float(stages.get("hydro", {}).get("cell_updates", np.nan))
    out["nbody_steps"] = float(stages.get("nbody", {}).get("steps", np.nan))
    out["particle_steps"] = float(stages.get("nbody", {}).get("particle_steps", np.nan))
    return out


# --------------------------------------------------------------------------- the ladder


@dataclass
class Rung:
    ladder: str
    value: Any
    name: str
    params: dict[str, Any]
    step: float = float("nan")
    status: str = "pending"
    error: str = ""
    hydro_from: str = ""
    answers: dict[str, float] = field(default_factory=dict)
    costs: dict[str, float] = field(default_factory=dict)
    point_params: list[dict[str, Any]] = field(default_factory=list)
    names: list[str] = field(default_factory=list)
    samples: list[float] = field(default_factory=list)

    @property
    def spread(self) -> float:
        """max - min of M_lr/M_T over the rung's hand-offs (NaN with fewer than two)."""
        good = [v for v in self.samples if math.isfinite(v)]
        return max(good) - min(good) if len(good) > 1 else float("nan")

    @property
    def sem(self) -> float:
        """Standard error of the rung's mean M_lr/M_T, std (ddof 1) / sqrt(n) over its hand-offs
        (NaN with fewer than two)."""
        good = [v for v in self.samples if math.isfinite(v)]
        return float(np.std(good, ddof=1) / math.sqrt(len(good))) if len(good) > 1 else float("nan")


#: Hand-off answers: mass fractions from the N-body stage's t = 0 diagnostics (summary ``nbody_budget``).
HANDOFF_ANSWERS = {"unbound_at_handoff": "initial_unbound_mass", "near_escape_at_handoff": "initial_near_escape_mass"}


def _answer_names(depths: list[float]) -> list[str]:
    return ["M_lr_over_M_T", "N_lr", *HANDOFF_ANSWERS, "target_kinetic_energy",
            *(f"peak_pressure_at_{d:g}Rp" for d in depths)]


def _rung_params(sweep: Sweep, key: str, value: Any, values: list[Any]) -> dict[str, Any]:
    """Config overrides of one rung; a hand-off-time ladder also runs the hydro to its latest
    time with a snapshot at every rung, unless the config's own snapshots hold them all (the
    hydro run is shared by the whole ladder either way)."""
    params = {key: value}
    if key == "handoff.time":
        params.update(handoff_time_params(values, sweep.snapshots({})))
    return params


def window_times(window: list[float], ladders: dict[str, list[Any]]) -> list[float] | None:
    """The hand-off times of a ladder run from the config's ``handoff.window`` (s): the window,
    or None (a single hand-off at ``handoff.time``) where a ladder varies a key the window sets
    (the hand-off time, the hydro end or snapshot times, the window itself); that is logged."""
    clash = [k for k in ("handoff.time", "handoff.window", "hydro.end_time", "hydro.output_times") if k in ladders]
    if clash:
        log.warning("handoff.window %s not used: the %s ladder sets the hand-off times", window, clash[0])
        return None
    log.info("handing off at the config's handoff.window: %s s", ", ".join(f"{t:g}" for t in window))
    return list(window)


def _rung_points(sweep: Sweep, params: dict[str, Any], handoff_times: list[float] | None,
                 seeds: int | None = None) -> list[dict[str, Any]]:
    """The runs of one rung: the rung itself, or one run per combination of the hand-off times
    (``handoff_times``: the hydro run goes to the latest time with a snapshot at each, as in a
    hand-off scan, unless its own snapshots hold them all) and of the hand-off seeds
    1..``seeds``; all of them share one hydro run."""
    replicates: dict[str, list[Any]] = {}
    if handoff_times:
        replicates["handoff.time"] = sorted(handoff_times)
    if seeds and seeds > 1:
        replicates["handoff.seed"] = list(range(1, seeds + 1))
    snapshots = sweep.snapshots(params) if handoff_times else None
    return with_replicates(params, replicates, snapshots)


def plan_ladders(config_path: str | Path, ladders: dict[str, list[Any]], out_dir: str | Path,
                 execution: dict[str, Any] | None = None,
                 stage_functions: dict[str, str] | None = None,
                 handoff_times: list[float] | None = None, seeds: int | None = None) -> tuple[Sweep, list[Rung]]:
    """Validate every rung's config (before any work) and return the sweep and its rungs.

    With ``handoff_times`` and ``seeds`` each rung is run once per hand-off time and seed
    (:func:`_rung_points`).
    Raises LadderError naming the key, the value and what is allowed.
    """
    config_path = Path(config_path).resolve()
    out = Path(out_dir)
    try:
        base_text = config_path.read_text()
    except OSError as exc:
        raise LadderError([f"{config_path}: cannot read config: {exc.strerror}"]) from None
    spec = SweepSpec.model_validate({
        "name": f"{config_path.stem}-convergence", "base": str(config_path), "output": str(out),
        "execution": execution or {}, "stage_functions": stage_functions or {},
    })
    sweep = Sweep(spec=spec, base_text=base_text, base_path=config_path, directory=out, source=out / SPEC_FILE)
    try:
        problem = sweep.config_for({}).scene.problem
    except ConfigError as exc:
        raise LadderError(exc.messages) from None
    if problem != "impact":
        raise LadderError([f"{config_path}: scene.problem must be impact for a convergence ladder (got {problem})"])
    known = set(key_paths())
    messages: list[str] = []
    rungs: list[Rung] = []
    if handoff_times and "handoff.time" in ladders:
        raise LadderError(["--handoff-times: not with a handoff.time ladder (that ladder is the hand-off scan)"])
    if handoff_times and len(set(handoff_times)) != len(handoff_times):
        raise LadderError([f"--handoff-times: the times must be distinct (got {handoff_times})"])
    if seeds is not None and seeds < 1:
        raise LadderError([f"--seeds: must be >= 1 (got {seeds})"])
    if seeds and seeds > 1 and "handoff.seed" in ladders:
        raise LadderError(["--seeds: not with a handoff.seed ladder (the option sets it)"])
    clash = [k for k in ("hydro.end_time", "hydro.output_times") if handoff_times and k in ladders]
    if clash:
        raise LadderError([f"--handoff-times: not with a {k} ladder (the option sets it)" for k in clash])
    for key, values in ladders.items():
        pattern = re.sub(r"^materials\.[^.]+\.", "materials.<name>.", key)
        if key not in known and pattern not in known:
            messages.append(f"--vary {key}: not a config key (see docs/config.md)")
            continue
        if key in STEP_SIZE and not all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0
                                        for v in values):
            messages.append(f"--vary {key}: values must be numbers > 0 (got {values})")
            continue
        for value in values:
            try:
                params = _rung_params(sweep, key, value, values)
                points = _rung_points(sweep, params, handoff_times, seeds)
            except ConfigError as exc:
                messages += [f"--vary {key}={value}: {m}" for m in exc.messages]
                continue
            bad = False
            for point in points:
                try:
                    checks.check(sweep.config_for(point))
                except ConfigError as exc:
                    messages += [f"--vary {key}={value}: {m}" for m in exc.messages]
                    bad = True
                    break
            if bad:
                continue
            step = float(STEP_SIZE[key][1](value)) if key in STEP_SIZE else float("nan")
            rungs.append(Rung(ladder=key, value=value, name="", params=params, step=step, point_params=points))
    if messages:
        raise LadderError(list(dict.fromkeys(messages)))
    return sweep, rungs


def run_ladders(config_path: str | Path, ladders: dict[str, list[Any]], out_dir: str | Path,
                depths: list[float] = DEFAULT_DEPTHS, tolerance: float = DEFAULT_TOLERANCE,
                executor: cf.Executor | None = None, execution: dict[str, Any] | None = None,
                stage_functions: dict[str, str] | None = None, show_progress: bool = True,
                handoff_times: list[float] | None = None, seeds: int | None = None,
                reuse_runs: list[str | Path] | tuple = ()) -> dict[str, Any]:
    """Run the ladders and write the table, the Richardson table, a JSON record and one figure per ladder.

    Args:
        config_path: base config (an impact).
        ladders: {config key: values}; each ladder varies its key with the others at the base values.
        out_dir: directory of the sweep (``runs/``, ``points.json``, ``results.csv``) and the outputs.
        depths: depths of the peak-pressure answers, in projectile radii below the impact point.
        tolerance: the cheapest rung within this of the extrapolated M_lr/M_T is reported.
        executor: a concurrent.futures executor; default from ``execution`` (sweep ``execution`` keys).
        stage_functions: replace stage functions (``{"nbody": "pkg.mod:func"}``; for tests).
        handoff_times: hand off each rung at each of these times (s) from one hydro run, and take
            the mean M_lr/M_T and N_lr over them as the rung's answers (their max - min is
            reported as ``M_lr_over_M_T_spread``): the reaccumulation's scatter between
            neighbouring hand-off times is then averaged out of the ladder.
        seeds: hand off each rung with the seeds 1..``seeds`` (ring phases and velocity noise) and
            average the same way; the standard error of each rung's mean M_lr/M_T is reported
            (``M_lr_over_M_T_sem``).  With ``handoff_times`` every time gets every seed.
        reuse_runs: finished run directories (``impactpipe run`` or a sweep's ``runs/<point>``)
            whose hydro runs the rungs with the same hydro settings adopt instead of running
            their own (:meth:`impactpipe.pipeline.sweep.SweepRunner.add_donor`).

    Returns:
        {"rungs": [Rung], "richardson": {ladder: {answer: Extrapolation}}, "cheapest": {ladder: rung index or
        None}, "files": [paths written]}.
    """
    sweep, rungs = plan_ladders(config_path, ladders, out_dir, execution, stage_functions, handoff_times, seeds)
    wanted = {stage_hashes(sweep.config_for(p))["hydro"] for r in rungs for p in r.point_params}
    messages = donor_problems(reuse_runs, wanted, "rung")
    if messages:
        raise LadderError(messages)
    out = sweep.directory
    out.mkdir(parents=True, exist_ok=True)
    storage.write_text_atomic(sweep.source, yaml.safe_dump(
        {**sweep.spec.model_dump(mode="json", exclude_none=True), "ladders": ladders,
         "depths_in_projectile_radii": list(depths), "handoff_times": handoff_times, "seeds": seeds},
        sort_keys=False))
    with open_runner(sweep, executor, show_progress, "convergence") as runner:
        for run_dir in reuse_runs:
            runner.add_donor(run_dir)
        by_digest: dict[str, str] = {}
        for rung in rungs:
            for params in rung.point_params:
                digest = stage_hashes(sweep.config_for(params))[STAGES[-1]]
                if digest not in by_digest:
                    by_digest[digest] = runner.add_point(params, group=rung.ladder)
                rung.names.append(by_digest[digest])
            rung.name = rung.names[0]
        results = runner.run_points(sorted(set(by_digest.values())))
    base = sweep.config_for({})
    for rung in rungs:
        _fill(rung, [results[n] for n in rung.names], [runner.points[n] for n in rung.names], sweep, depths)
    answers = _answer_names(depths)
    extrapolations: dict[str, dict[str, Extrapolation]] = {}
    cheapest: dict[str, int | None] = {}
    reference: dict[str, tuple[str, float]] = {}
    uncertainty: dict[str, Uncertainty | None] = {}
    for key in ladders:
        ladder = [r for r in rungs if r.ladder == key]
        h = np.array([r.step for r in ladder])
        extrapolations[key] = {}
        for name in answers:
            if name == "N_lr":
                continue  # the particle count grows with resolution; it measures resolution, not an answer to converge
            f = np.array([r.answers.get(name, np.nan) for r in ladder])
            if key in STEP_SIZE:
                extrapolations[key][name] = richardson(h, f)
            else:
                extrapolations[key][name] = Extrapolation(
                    f"{key} has no step size: no extrapolation (changes between rungs are listed)",
                    errors=np.full(len(ladder), np.nan))
        mlr = extrapolations[key]["M_lr_over_M_T"]
        f_mlr = np.array([r.answers.get("M_lr_over_M_T", np.nan) for r in ladder])
        reference[key] = _tolerance_reference(key, h, f_mlr, mlr)
        cheapest[key] = cheapest_within(h, f_mlr, reference[key][1], tolerance)
        if key in STEP_SIZE:
            uncertainty[key] = richardson_uncertainty(h, f_mlr, np.array([r.sem for r in ladder]), tolerance)
    files = _write_outputs(out, rungs, ladders, extrapolations, cheapest, reference, answers, tolerance, base,
                           sorted(handoff_times) if handoff_times else None, uncertainty)
    return {"rungs": rungs, "richardson": extrapolations, "cheapest": cheapest, "reference": reference,
            "uncertainty": uncertainty, "files": files}


def _tolerance_reference(key: str, h: np.ndarray, f: np.ndarray, mlr: Extrapolation) -> tuple[str, float]:
    """What the cheapest rung is measured against: ("extrapolated", the Richardson value), or,
    when there is none, ("finest rung", its M_lr/M_T) for a ladder with a step size and at
    least two answers, else ("none", NaN)."""
    if mlr.ok:
        return "extrapolated", float(mlr.value)
    finite = np.flatnonzero(np.isfinite(f) & np.isfinite(h))
    if key in STEP_SIZE and finite.size >= 2:
        return "finest rung", float(f[finite[np.argmin(h[finite])]])
    return "none", float("nan")


def _cheapest_text(key: str, ladder: list, index: int | None, reference: tuple[str, float], mlr: Extrapolation,
                   tolerance: float) -> str:
    """One line: the cheapest rung within ``tolerance`` and what it was measured against."""
    basis, value = reference
    if index is None and basis == "extrapolated":
        return (f"{key}: no rung within +-{tolerance:g} of the extrapolated M_lr/M_T {value:.4g} "
                f"(observed order {mlr.order:.3g})")
    if index is None:
        return f"{key}: no rung shown within +-{tolerance:g} of a converged M_lr/M_T ({mlr.status})"
    if basis == "extrapolated":
        return (f"{key}: cheapest rung within +-{tolerance:g} of the extrapolated M_lr/M_T {value:.4g}: "
                f"{key} = {ladder[index].value}")
    return (f"{key}: no extrapolation ({mlr.status}); cheapest rung within +-{tolerance:g} of the finest rung's "
            f"M_lr/M_T {value:.4g}: {key} = {ladder[index].value}")


#: Costs of the hydro stage, which a rung's runs share; the other costs add up over its runs.
HYDRO_COSTS = ("wall_hydro", "hydro_steps", "cell_updates")


def _fill(rung: Rung, results: list[Any], points: list[dict[str, Any]], sweep: Sweep, depths: list[float]) -> None:
    """Status, answers and costs of one rung from its finished (or failed) runs.

    One run per hand-off time (``--handoff-times``) or one run: M_lr/M_T and N_lr are the
    means over the runs (``samples`` keeps each M_lr/M_T), the peak pressures come from the
    shared hydro run, the hydro costs are that run's and the downstream costs their sum.
    """
    failed = [r for r in results if r.status != "complete"]
    rung.status = failed[0].status if failed else "complete"
    rung.error = "; ".join(r.error for r in failed if r.error)
    if failed:
        return
    summaries = [r.summary for r in results]
    rung.samples = [float(s.get("M_lr_over_M_T", np.nan)) for s in summaries]
    rung.answers["M_lr_over_M_T"] = float(np.mean(rung.samples))
    rung.answers["N_lr"] = float(np.mean([float(s.get("N_lr", np.nan)) for s in summaries]))
    for answer, key in HANDOFF_ANSWERS.items():
        rung.answers[answer] = float(np.mean([_handoff_fraction(s, key) for s in summaries]))
    rung.answers["target_kinetic_energy"] = float(np.mean([_number(s.get("target_kinetic_energy")) for s in summaries]))
    config = sweep.config_for(rung.params)
    r_p, r_t = config.scene.projectile.radius, config.scene.target.radius
    run_dir = Path(points[0]["run_dir"])
    pressures = peak_pressure_at_depths(run_dir / "hydro.h5", r_t, [d * r_p for d in depths])
    for d, p in zip(depths, pressures):
        rung.answers[f"peak_pressure_at_{d:g}Rp"] = float(p)
    costs = [costs_of(s) for s in summaries]
    rung.costs = {c: (costs[0].get(c, np.nan) if c in HYDRO_COSTS else float(sum(x.get(c, np.nan) for x in costs)))
                  for c in COSTS if c != "wall_total"}
    rung.costs["wall_total"] = float(sum(v for c, v in rung.costs.items() if c.startswith("wall_")))
    reused = read_records(run_dir).get("hydro", {}).get("reused_from")
    rung.hydro_from = Path(reused).name if reused else ""


def _number(value: Any) -> float:
    """``value`` as a float; NaN for None (a summary entry that is missing or was not computed)."""
    return float("nan") if value is None else float(value)


def _handoff_fraction(summary: dict[str, Any], key: str) -> float:
    """``nbody_budget[key]`` over the hand-off's particle mass (NaN when either is missing)."""
    mass = summary.get("handoff_budget", {}).get("particle_mass", np.nan)
    value = summary.get("nbody_budget", {}).get(key, np.nan)
    return float(value) / float(mass) if mass and math.isfinite(float(mass)) else float("nan")


# --------------------------------------------------------------------------- outputs


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.6g}"
    return str(value)


def _csv(columns: list[str], rows: list[dict[str, Any]], comments: list[str]) -> str:
    buffer = io.StringIO()
    for line in comments:
        buffer.write(f"# {line}\n")
    writer = csv.DictWriter(buffer, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    writer.writerows([{k: _fmt(v) for k, v in row.items()} for row in rows])
    return buffer.getvalue()


def rung_rows(rungs: list[Rung], extrapolations: dict[str, dict[str, Extrapolation]],
              answers: list[str]) -> list[dict[str, Any]]:
    """One table row per rung: value, step size, status, answers, error estimates, changes, costs."""
    rows = []
    for key in dict.fromkeys(r.ladder for r in rungs):
        ladder = [r for r in rungs if r.ladder == key]
        order = np.argsort([r.step for r in ladder]) if key in STEP_SIZE else np.arange(len(ladder))
        for position, i in enumerate(order):
            rung = ladder[i]
            row: dict[str, Any] = {"ladder": key, "value": rung.value, "step_size": rung.step, "status": rung.status,
                                   "run": rung.name, "hydro_from": rung.hydro_from, "error": rung.error,
                                   "M_lr_over_M_T_spread": rung.spread, "M_lr_over_M_T_sem": rung.sem,
                                   "handoffs": len(rung.samples)}
            for name in answers:
                row[name] = rung.answers.get(name, float("nan"))
                ext = extrapolations[key].get(name)
                if ext is not None:
                    row[f"{name}_error_estimate"] = float(ext.errors[i]) if ext.ok else float("nan")
                    finer = ladder[order[position - 1]] if position > 0 else None
                    row[f"{name}_change_from_previous"] = (row[name] - finer.answers.get(name, float("nan"))
                                                           if finer is not None else float("nan"))
            row.update({c: rung.costs.get(c, float("nan")) for c in COSTS})
            rows.append(row)
    return rows


def _write_outputs(out: Path, rungs: list[Rung], ladders: dict[str, list[Any]],
                   extrapolations: dict[str, dict[str, Extrapolation]], cheapest: dict[str, int | None],
                   reference: dict[str, tuple[str, float]], answers: list[str], tolerance: float,
                   base: Any, handoff_times: list[float] | None,
                   uncertainty: dict[str, Uncertainty | None]) -> list[Path]:
    rows = rung_rows(rungs, extrapolations, answers)
    extra = [f"{a}_{s}" for a in answers if a != "N_lr" for s in ("error_estimate", "change_from_previous")]
    columns = ["ladder", "value", "step_size", "status", *answers, "M_lr_over_M_T_spread", "M_lr_over_M_T_sem",
               "handoffs", *extra, *COSTS,
               "run", "hydro_from", "error"]
    comments = [f"convergence ladders of {base.name}; answers in SI (pressures Pa), costs: "
                 + ", ".join(f"{c} ({u})" for c, u in COSTS.items()),
                 "rows of a ladder with a step size run from the finest rung; *_error_estimate = answer - "
                 "Richardson value; *_change_from_previous = answer - answer of the row above",
                 "a rung that reused another rung's hydro run (hydro_from) reports that run's hydro cost",
                 "M_lr_over_M_T and N_lr are means over the rung's hand-offs (handoffs: hand-off times x seeds); "
                 "M_lr_over_M_T_spread = their max - min, M_lr_over_M_T_sem = std / sqrt(handoffs)"]
    for key, index in cheapest.items():
        ladder = [r for r in rungs if r.ladder == key]
        comments.append(_cheapest_text(key, ladder, index, reference[key], extrapolations[key]["M_lr_over_M_T"],
                                       tolerance))
        if uncertainty.get(key) is not None:
            comments.append(uncertainty_text(key, [r.value for r in ladder], uncertainty[key], tolerance))
    files = [out / TABLE_FILE, out / RICHARDSON_FILE, out / JSON_FILE]
    storage.write_text_atomic(out / TABLE_FILE, _csv(columns, rows, comments))
    rich_rows = []
    for key, by_answer in extrapolations.items():
        for name, ext in by_answer.items():
            rich_rows.append({"ladder": key, "answer": name, "status": ext.status, "order": ext.order,
                              "ratio_r21": ext.ratios[0], "ratio_r32": ext.ratios[1], "extrapolated": ext.value,
                              "step_size": STEP_SIZE[key][0] if key in STEP_SIZE else ""})
    storage.write_text_atomic(out / RICHARDSON_FILE, _csv(
        ["ladder", "answer", "status", "order", "ratio_r21", "ratio_r32", "extrapolated", "step_size"], rich_rows,
        ["Richardson estimate f = f* + C h^p from the three finest rungs of each ladder"]))
    storage.write_json_atomic(out / JSON_FILE, {
        "base": base.name, "ladders": ladders, "tolerance": tolerance,
        "handoff_times": handoff_times,
        "rows": rows, "richardson": rich_rows,
        "cheapest_within_tolerance": {k: (None if i is None else [r for r in rungs if r.ladder == k][i].value)
                                      for k, i in cheapest.items()},
        "cheapest_measured_against": {k: (None if cheapest[k] is None else {"basis": b, "M_lr_over_M_T": v})
                                      for k, (b, v) in reference.items()},
        "richardson_uncertainty": {k: (None if u is None else u.as_dict([r.value for r in rungs if r.ladder == k]))
                                   for k, u in uncertainty.items()},
    })
    for key in ladders:
        path = out / f"convergence_{key.split('.')[-1]}.png"
        _figure(path, [r for r in rows if r["ladder"] == key], key, answers, extrapolations[key], tolerance)
        files.append(path)
    return files


def _figure(path: Path, rows: list[dict[str, Any]], key: str, answers: list[str],
            extrapolations: dict[str, Extrapolation], tolerance: float) -> None:
    """Answers (rows: M_lr/M_T with the hand-off fractions, peak pressures, N_lr) against the ladder
    value (first column) and each recorded cost (further columns); rungs are joined in the order
    of the ladder value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    numeric = all(isinstance(r["value"], (int, float)) and not isinstance(r["value"], bool) for r in rows)
    if numeric:
        rows = sorted(rows, key=lambda r: r["value"])
    costs = [c for c in FIGURE_COSTS if any(math.isfinite(r[c]) and r[c] > 0 for r in rows)]
    columns = ["value", *costs]
    pressures = [a for a in answers if a.startswith("peak_pressure")]
    fig, axes = plt.subplots(4, len(columns), figsize=(4.2 * len(columns), 12.0), squeeze=False,
                             constrained_layout=True)
    for col, column in enumerate(columns):
        if column == "value":
            x = np.array([r["value"] if numeric else i for i, r in enumerate(rows)], dtype=float)
        else:
            x = np.array([r[column] for r in rows], dtype=float)
        shown = np.isfinite(x) & ((x > 0) | (column == "value"))
        ax = axes[0, col]
        y = np.array([r["M_lr_over_M_T"] for r in rows], dtype=float)
        sem = np.array([r["M_lr_over_M_T_sem"] for r in rows], dtype=float)
        if np.isfinite(sem[shown]).any():
            ax.errorbar(x[shown], y[shown], yerr=np.nan_to_num(sem[shown]), fmt="o-", capsize=3,
                        label="rungs (mean +- standard error)")
        else:
            ax.plot(x[shown], y[shown], "o-", label="rungs")
        ext = extrapolations["M_lr_over_M_T"]
        if ext.ok:
            ax.axhline(ext.value, color="k", ls="--", lw=1, label=f"Richardson {ext.value:.4g} (p = {ext.order:.2g})")
            ax.axhspan(ext.value - tolerance, ext.value + tolerance, color="grey", alpha=0.2,
                       label=f"+-{tolerance:g}")
        if column != "value":
            for xi, yi, r, s in zip(x, y, rows, shown):
                if s and math.isfinite(yi):
                    ax.annotate(_fmt(r["value"]), (xi, yi), textcoords="offset points", xytext=(4, 4), fontsize=8)
        for name, label in (("unbound_at_handoff", "hand-off: on escape orbits"),
                            ("near_escape_at_handoff", "hand-off: 0.6-1 x escape speed")):
            yh = np.array([r[name] for r in rows], dtype=float)
            if np.isfinite(yh[shown]).any():
                ax.plot(x[shown], yh[shown], "s:", markersize=4, label=label)
        ax.set_ylabel("M_lr / M_T, mass fractions")
        ax.legend(fontsize=7)
        ax = axes[1, col]
        for name in pressures:
            yp = np.array([r[name] for r in rows], dtype=float)
            ok = shown & np.isfinite(yp) & (yp > 0)
            if ok.any():
                (line,) = ax.plot(x[ok], yp[ok], "o-", label=name.replace("peak_pressure_at_", "depth "))
                if extrapolations[name].ok and extrapolations[name].value > 0:
                    ax.axhline(extrapolations[name].value, color=line.get_color(), ls="--", lw=1)
        if ax.lines:
            ax.set_yscale("log")
            ax.legend(fontsize=7)
        ax.set_ylabel("peak pressure (Pa)")
        ax = axes[2, col]
        yk = np.array([r["target_kinetic_energy"] for r in rows], dtype=float)
        ok = shown & np.isfinite(yk)
        if ok.any():
            ax.plot(x[ok], yk[ok], "o-")
            if extrapolations["target_kinetic_energy"].ok:
                ext_k = extrapolations["target_kinetic_energy"]
                ax.axhline(ext_k.value, color="k", ls="--", lw=1,
                           label=f"Richardson {ext_k.value:.4g} J (p = {ext_k.order:.2g})")
                ax.legend(fontsize=7)
        ax.set_ylabel("target kinetic energy at hand-off (J)")
        ax = axes[3, col]
        yn = np.array([r["N_lr"] for r in rows], dtype=float)
        ax.plot(x[shown], yn[shown], "o-")
        if np.any(yn[shown] > 0):
            ax.set_yscale("log")
        ax.set_ylabel("N_lr")
        ax.set_xlabel(key if column == "value" else f"{column} ({COSTS[column]})")
        for row_axes in axes[:, col]:
            if column != "value":
                row_axes.set_xscale("log")
                row_axes.xaxis.set_minor_formatter(NullFormatter())
            elif not numeric:
                row_axes.set_xticks(x, [str(r["value"]) for r in rows])
            elif key in STEP_SIZE:
                row_axes.set_xscale("log")
    fig.suptitle(f"ladder in {key}: answers against the value and the cost of each rung", fontsize=10)
    with storage.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=150, format="png")
    plt.close(fig)


def format_table(result: dict[str, Any], depths: list[float], tolerance: float) -> list[str]:
    """Lines of a terminal summary: per ladder, each rung's answers and costs, then the Richardson lines."""
    lines = []
    answers = _answer_names(depths)
    rows = rung_rows(result["rungs"], result["richardson"], answers)
    for key, by_answer in result["richardson"].items():
        lines.append(f"{key}:")
        ladder_rows = [r for r in rows if r["ladder"] == key]
        spread = any(r["handoffs"] > 1 for r in ladder_rows)
        head = f"  {'value':>8} {'M_lr/M_T':>9} " + (f"{'sem':>7} {'spread':>7} " if spread else "") + f"{'N_lr':>7} " \
            + f"{'unbound':>8} {'near-esc':>8} {'K_T (J)':>11} " + " ".join(
            f"{'P(' + format(d, 'g') + 'Rp) Pa':>13}" for d in depths) + f" {'wall s':>8} {'cell-upd':>10} {'status'}"
        lines.append(head)
        for row in ladder_rows:
            lines.append(f"  {_fmt(row['value']):>8} {_fmt(row['M_lr_over_M_T']):>9} "
                         + (f"{_fmt(row['M_lr_over_M_T_sem']):>7.7} {_fmt(row['M_lr_over_M_T_spread']):>7.7} "
                            if spread else "") + f"{_fmt(row['N_lr']):>7} "
                         + f"{_fmt(row['unbound_at_handoff']):>8.8} {_fmt(row['near_escape_at_handoff']):>8.8} "
                         + f"{_fmt(row['target_kinetic_energy']):>11} "
                         + " ".join(f"{_fmt(row[f'peak_pressure_at_{d:g}Rp']):>13}" for d in depths)
                         + f" {_fmt(row['wall_total']):>8} {_fmt(row['cell_updates']):>10} {row['status']}")
        for name, ext in by_answer.items():
            text = (f"{ext.value:.4g} (order {ext.order:.3g})" if ext.ok else ext.status)
            lines.append(f"  Richardson {name}: {text}")
        index = result["cheapest"][key]
        ladder = [r for r in result["rungs"] if r.ladder == key]
        lines.append("  " + _cheapest_text(key, ladder, index, result["reference"][key],
                                           by_answer["M_lr_over_M_T"], tolerance))
        if result["uncertainty"].get(key) is not None:
            lines.append("  " + uncertainty_text(key, [r.value for r in ladder], result["uncertainty"][key],
                                                 tolerance))
    return lines
