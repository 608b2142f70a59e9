"""Run the reference cases 8a-c and 9a-b and set the results next to the published values.

The published values are those of the development cases in shared/reference/method.md,
section 6 (basalt, 10 km target, 0.83 km projectile, head-on):

- M_lr/M_T per run (8a 0.05, 8b 0.29, 8c 0.76, 9a 0.40, 9b 0.81);
- case 8: Q*_D = 1.79 (+-0.06) x 10^3 J/kg, critical speed 2.50 +- 0.04 km/s (perfect merging);
  case 9 (two runs): Q*_D ~ 8.5 x 10^2 J/kg, critical speed ~ 1.7 km/s;
- the slope of M_lr/M_T against Q/Q*_D, about -0.5 (-0.48 +- 0.02 in the reference study);
- case 8c: M_lr/M_T levels off for hand-off times of 10-15 s.

Each case family (8: 8a-c, 9: 9a-b) runs as one sweep over the impact speed through the
sweep machinery (``impactpipe.pipeline.sweep``; process pool or Dask, resumable), case 8
with ``--models`` also over the N-body collision model (perfect merging, conditional
merging, bouncing with eps_n = 0.5; by default perfect merging only), sharing one hydro
run per speed.  Q*_D comes from the weighted fit of
the analysis (``impactpipe.analysis.qstar.fit_qstar``) over the perfect-merging runs of
each family (and, for case 8, per collision model).  The hand-off-time plateau of case 8c
is a hand-off scan (``impactpipe.pipeline.handoff_scan``): one hydro run to the latest
time, handed off at each time.

One run per case carries the method's scatter of M_lr/M_T (a standard deviation of about
0.05 for case 8c from the hand-off seed alone, docs/accuracy.md).  ``--seeds N``
runs every case N times with ``handoff.seed`` 1..N (a sweep's ``replicates``: one hydro
run per speed); the tables then give each case's mean and standard deviation, and every
seed enters the Q*_D fit, so its bootstrap error contains that scatter.

Writes ``validation.json`` and ``validation.md`` into ``--out`` and prints the tables.

    python benchmarks/validate_reference.py                      # the real thing (hours)
    python benchmarks/validate_reference.py --quick --cells-per-projectile-radius 4   # smoke run (minutes)

``--quick`` shortens the N-body stage (``nbody.stop.min_dynamical_times`` 10 instead of 50)
and, without ``--cells-per-projectile-radius``, runs at 4 cells per projectile radius; its
numbers exercise the machinery and are not a validation.
Exit status: 0 when every run finished, 1 when a run failed, 2 for bad arguments.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import contextlib
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from impactpipe.analysis.qstar import fit_qstar, plus_minus
from impactpipe import storage
from impactpipe.pipeline.config import ConfigError, load_config
from impactpipe.pipeline.handoff_scan import handoff_scan
from impactpipe.pipeline.stages import read_records, resolved_dict, resolved_yaml
from impactpipe.pipeline.sweep import (Execution, SweepError, load_sweep, make_executor, pool_stopped_on_interrupt,
                                      run_sweep)

REFERENCE_DIR = Path(__file__).resolve().parent.parent / "configs" / "reference"
CASES = ("8a", "8b", "8c", "9a", "9b")
MODELS = ("merge", "conditional_merge", "bounce")
#: method.md section 6: per run M_lr/M_T, N_lr, N_init and the impact speed (m/s).
PUBLISHED_RUNS = {
    "8a": {"velocity": 3700.0, "mlr_over_mt": 0.05, "n_lr": 140, "n_init": 25940, "note": "under-resolved"},
    "8b": {"velocity": 2800.0, "mlr_over_mt": 0.29, "n_lr": 228, "n_init": 14538, "note": ""},
    "8c": {"velocity": 1900.0, "mlr_over_mt": 0.76, "n_lr": 1350, "n_init": 8020, "note": ""},
    "9a": {"velocity": 1900.0, "mlr_over_mt": 0.40, "n_lr": 1119, "n_init": 5491, "note": ""},
    "9b": {"velocity": 1000.0, "mlr_over_mt": 0.81, "n_lr": 1112, "n_init": 7141, "note": ""},
}
#: method.md section 6: Q*_D (J/kg) and critical speed (m/s) per family, with uncertainties where given.
PUBLISHED_QSTAR = {
    "8": {"qstar": 1.79e3, "qstar_err": 0.06e3, "velocity": 2.50e3, "velocity_err": 0.04e3},
    "9": {"qstar": 8.5e2, "qstar_err": float("nan"), "velocity": 1.7e3, "velocity_err": float("nan")},
}
PUBLISHED_SLOPE, PUBLISHED_SLOPE_ERR = -0.48, 0.02
PUBLISHED_PLATEAU = (10.0, 15.0)
HANDOFF_TIMES = (4.0, 6.0, 8.0, 10.0, 12.0, 15.0)
QUICK_CELLS = 4.0
QUICK_MIN_DYNAMICAL_TIMES = 10.0
BOUNCE_RESTITUTION = 0.5


class UsageError(ValueError):
    """Bad command-line input; the message names the option, the value and what is allowed."""


# --------------------------------------------------------------------------- arguments


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", default=",".join(CASES), help="comma-separated subset of " + ",".join(CASES))
    parser.add_argument("--models", default="merge",
                        help="collision models for case 8 (merge is always run; default merge only, since the "
                             "others take hours at 20 cells per projectile radius): " + ",".join(MODELS))
    parser.add_argument("--cells-per-projectile-radius", type=float, default=None,
                        help="hydro resolution (default: the configs' 20; 4 with --quick)")
    parser.add_argument("--quick", action="store_true",
                        help=f"smoke run: N-body to {QUICK_MIN_DYNAMICAL_TIMES:g} dynamical times, "
                             f"{QUICK_CELLS:g} cells per projectile radius unless given")
    parser.add_argument("--handoff-times", default=",".join(f"{t:g}" for t in HANDOFF_TIMES),
                        help="hand-off scan times of case 8c (s); 'none' skips the scan")
    parser.add_argument("--seeds", type=int, default=1,
                        help="hand-off seeds (ring phases and velocity noise) per run (handoff.seed 1..N, "
                             "one hydro run per speed); M_lr/M_T is then given as mean +- standard deviation "
                             "(default 1)")
    parser.add_argument("--out", default="runs/validate_reference", help="output directory")
    parser.add_argument("--backend", choices=("local", "dask"), default="local")
    parser.add_argument("--scheduler", default=None, help="Dask scheduler address (implies --backend dask)")
    parser.add_argument("--workers", type=int, default=None, help="parallel runs (default: cores)")
    parser.add_argument("--threads-per-run", type=int, default=1, help="numba threads per run")
    return parser.parse_args(argv)


def options_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """Checked options (raises UsageError naming the option, the value and the allowed values)."""
    cases = [c.strip() for c in args.cases.split(",") if c.strip()]
    bad = [c for c in cases if c not in CASES]
    if bad or not cases:
        raise UsageError(f"--cases: unknown case(s) {', '.join(bad) or '(none given)'} (allowed: {', '.join(CASES)})")
    models = [m.strip() for m in args.models.split(",") if m.strip()]
    bad = [m for m in models if m not in MODELS]
    if bad:
        raise UsageError(f"--models: unknown model(s) {', '.join(bad)} (allowed: {', '.join(MODELS)})")
    cells = args.cells_per_projectile_radius
    if cells is not None and not cells > 0:
        raise UsageError(f"--cells-per-projectile-radius: must be > 0 (got {cells:g})")
    if args.handoff_times.strip().lower() == "none":
        times: list[float] = []
    else:
        try:
            times = sorted(float(t) for t in args.handoff_times.split(",") if t.strip())
        except ValueError:
            raise UsageError(f"--handoff-times: expected comma-separated seconds or 'none' "
                             f"(got {args.handoff_times!r})") from None
        if not times or times[0] <= 0:
            raise UsageError(f"--handoff-times: expected times > 0 s (got {args.handoff_times!r})")
    for name in ("seeds", "workers", "threads_per_run"):
        value = getattr(args, name)
        if value is not None and value < 1:
            raise UsageError(f"--{name.replace('_', '-')}: must be >= 1 (got {value})")
    if cells is None and args.quick:
        cells = QUICK_CELLS
    return {"cases": cases, "models": ["merge", *[m for m in models if m != "merge"]], "cells": cells,
            "quick": args.quick, "handoff_times": times, "seeds": args.seeds, "out": Path(args.out),
            "execution": {"backend": "dask" if args.scheduler else args.backend, "scheduler": args.scheduler,
                          "workers": args.workers, "threads_per_run": args.threads_per_run}}


# --------------------------------------------------------------------------- plan


def overrides_for(options: dict[str, Any]) -> dict[str, Any]:
    """Config overrides common to every run: resolution and the quick N-body stop."""
    out: dict[str, Any] = {}
    if options["cells"] is not None:
        out["hydro.cells_per_projectile_radius"] = float(options["cells"])
    if options["quick"]:
        out["nbody.stop.min_dynamical_times"] = QUICK_MIN_DYNAMICAL_TIMES
    return out


def family_sweeps(options: dict[str, Any], stage_functions: dict[str, str] | None = None) -> list[dict[str, Any]]:
    """One sweep spec per case family (8, 9): the family's first case file as base, its speeds as an axis.

    The cases of a family must differ only in name, output and impact speed (checked).
    """
    families: dict[str, list[str]] = {}
    for case in options["cases"]:
        families.setdefault(case[0], []).append(case)
    specs = []
    common = overrides_for(options)
    for family, cases in families.items():
        base_path = REFERENCE_DIR / f"case{cases[0]}.yaml"
        base = load_config(base_path)
        velocities = []
        for case in cases:
            config = load_config(REFERENCE_DIR / f"case{case}.yaml")
            moved = resolved_dict(load_config(base_path, overrides={"scene.impact.velocity":
                                                                     config.scene.impact.velocity}))
            mine = resolved_dict(config)
            for key in ("name", "output"):
                moved.pop(key, None)
                mine.pop(key, None)
            if moved != mine:
                raise UsageError(f"case{case}.yaml differs from case{cases[0]}.yaml in more than the impact speed; "
                                 f"family {family} cannot run as one sweep")
            if config.scene.impact.velocity != PUBLISHED_RUNS[case]["velocity"]:
                raise UsageError(f"case{case}.yaml: impact speed {config.scene.impact.velocity:g} m/s is not the "
                                 f"published {PUBLISHED_RUNS[case]['velocity']:g} m/s")
            velocities.append(float(config.scene.impact.velocity))
        axes: dict[str, Any] = {"scene.impact.velocity": velocities}
        overrides = dict(common)
        if family == "8" and len(options["models"]) > 1:
            axes["nbody.collision_model"] = options["models"]
            if "bounce" in options["models"]:
                overrides["nbody.restitution.normal"] = BOUNCE_RESTITUTION
        spec = {"name": f"case{family}", "base": str(base_path), "output": str(options["out"] / f"case{family}"),
                "overrides": overrides, "axes": axes, "execution": options["execution"],
                "stage_functions": stage_functions or {}}
        if options["seeds"] > 1:
            spec["replicates"] = {"handoff.seed": list(range(1, options["seeds"] + 1))}
        specs.append({"family": family, "cases": dict(zip(velocities, cases)), "spec": spec, "name": base.name})
    return specs


# --------------------------------------------------------------------------- run


def run_validation(options: dict[str, Any], executor: cf.Executor | None = None,
                   stage_functions: dict[str, str] | None = None) -> dict[str, Any]:
    """Run the cases and the scan; return the report (also written as validation.json / validation.md)."""
    t0 = time.perf_counter()
    out: Path = options["out"]
    plans = family_sweeps(options, stage_functions)
    sweeps = []
    for plan in plans:  # validate every point of every sweep before any work
        path = out / f"case{plan['family']}.sweep.yaml"
        out.mkdir(parents=True, exist_ok=True)
        storage.write_text_atomic(path, yaml.safe_dump(plan["spec"], sort_keys=False))
        sweeps.append(load_sweep(path))
    scan_config = None
    if options["handoff_times"] and "8c" in options["cases"]:
        config = load_config(REFERENCE_DIR / "case8c.yaml", overrides=overrides_for(options))
        scan_config = out / "case8c-scan.yaml"
        storage.write_text_atomic(scan_config, resolved_yaml(config))
    close = None
    guard = contextlib.nullcontext()
    if executor is None:
        execution = Execution(**options["execution"])
        executor, close = make_executor(execution)
        if execution.backend == "local":
            guard = pool_stopped_on_interrupt(executor)
    try:
        with guard:
            points: dict[str, dict[str, Any]] = {}
            for plan, sweep in zip(plans, sweeps):
                result = run_sweep(sweep, executor=executor, show_progress=False)
                for name, point in result["points"].items():
                    points[name] = {**point, "case": plan["cases"][float(point["params"]["scene.impact.velocity"])]}
            scan = None
            if scan_config is not None:
                scan = handoff_scan(scan_config, options["handoff_times"], out / "case8c-handoff-scan",
                                    executor=executor, show_progress=False)
    finally:
        if close is not None:
            close()
    report = build_report(options, points, scan, time.perf_counter() - t0)
    storage.write_json_atomic(out / "validation.json", report)
    storage.write_text_atomic(out / "validation.md", "\n".join(format_report(report)) + "\n")
    return report


def _run_wall(point: dict[str, Any]) -> float:
    """Wall seconds of the stages this point ran itself (stages adopted from another point excluded)."""
    records = read_records(Path(point["run_dir"]))
    return float(sum(r.get("wall_seconds", 0.0) for r in records.values()
                     if r.get("status") == "complete" and "reused_from" not in r))


def build_report(options: dict[str, Any], points: dict[str, dict[str, Any]], scan: dict[str, Any] | None,
                 wall: float) -> dict[str, Any]:
    """The comparison with the published values, as plain data."""
    runs = []
    for point in points.values():
        v = float(point["params"]["scene.impact.velocity"])
        case = point["case"]
        summary = point.get("summary", {})
        published = PUBLISHED_RUNS[case]
        mlr = summary.get("M_lr_over_M_T", float("nan"))
        full = _full_summary(point)
        runs.append({
            "case": case, "velocity": v, "model": point["params"].get("nbody.collision_model", "merge"),
            "seed": int(point["params"].get("handoff.seed", 1)),
            "status": point["status"], "error": point.get("error") or "",
            "M_lr_over_M_T": mlr, "published_M_lr_over_M_T": published["mlr_over_mt"],
            "difference": mlr - published["mlr_over_mt"],
            "N_lr": summary.get("N_lr", float("nan")), "published_N_lr": published["n_lr"],
            "N_init": summary.get("N_init", full.get("N_init", float("nan"))), "published_N_init": published["n_init"],
            "Q": summary.get("Q", float("nan")), "published_note": published["note"],
            "physics_not_modelled": full.get("physics_not_modelled", []),
            "wall_seconds_own_stages": _run_wall(point),
        })
    runs.sort(key=lambda r: (r["case"], MODELS.index(r["model"]), r["seed"]))
    cases = case_means(runs)
    fits = []
    for family in sorted({r["case"][0] for r in runs}):
        for model in options["models"] if family == "8" else ["merge"]:
            fits.append(_fit(family, model, [r for r in runs if r["case"][0] == family and r["model"] == model]))
    models = []
    for case in sorted({r["case"] for r in cases if r["case"][0] == "8"}):
        merge = next((r for r in cases if r["case"] == case and r["model"] == "merge"), None)
        for r in cases:
            if r["case"] == case and r["model"] != "merge" and merge is not None:
                models.append({"case": case, "model": r["model"], "M_lr_over_M_T": r["M_lr_over_M_T"],
                               "merge_M_lr_over_M_T": merge["M_lr_over_M_T"],
                               "change_from_merge": r["M_lr_over_M_T"] - merge["M_lr_over_M_T"]})
    plateau = None
    if scan is not None:
        t, mlr = np.asarray(scan["times"], dtype=float), np.asarray(scan["mlr_over_mt"], dtype=float)
        window = (t >= PUBLISHED_PLATEAU[0]) & (t <= PUBLISHED_PLATEAU[1]) & np.isfinite(mlr)
        plateau = {
            "times": t.tolist(), "M_lr_over_M_T": mlr.tolist(),
            "late_from": float(scan["late_from"]), "late_slope_per_s": float(scan["slope"]),
            "late_slope_err_per_s": float(scan["slope_err"]),
            "published_window_s": list(PUBLISHED_PLATEAU),
            "window_mean": float(mlr[window].mean()) if window.any() else float("nan"),
            "window_range": float(np.ptp(mlr[window])) if window.any() else float("nan"),
            "window_slope_per_s": (float(np.polyfit(t[window], mlr[window], 1)[0]) if window.sum() >= 2
                                   else float("nan")),
            "failed": [float(ti) for ti, mi in zip(t, mlr) if not math.isfinite(mi)],
        }
    execution = Execution(**options["execution"])
    workers = execution.workers or max(1, (os.cpu_count() or 1) // execution.threads_per_run)
    return {
        "settings": {"cases": options["cases"], "models": options["models"], "quick": options["quick"],
                     "cells_per_projectile_radius": options["cells"] if options["cells"] is not None else "configs",
                     "handoff_times": options["handoff_times"], "seeds": options["seeds"],
                     "restitution_normal_bounce": BOUNCE_RESTITUTION},
        "runs": runs, "cases": cases, "qstar": fits, "collision_models": models, "handoff_plateau": plateau,
        "cost": {"wall_seconds": wall, "backend": execution.backend, "workers": workers,
                 "threads_per_run": execution.threads_per_run, "cores_used": workers * execution.threads_per_run,
                 "machine_cores": os.cpu_count(),
                 "run_wall_seconds_total": float(sum(r["wall_seconds_own_stages"] for r in runs))},
    }


def case_means(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One record per case and collision model: M_lr/M_T, N_lr and N_init averaged over its seeds
    (finished runs), the sample standard deviation of M_lr/M_T (ddof 1; NaN for one seed), the
    difference of the mean from the published value, and the status of the worst run."""
    out = []
    for key in dict.fromkeys((r["case"], r["model"]) for r in runs):
        group = [r for r in runs if (r["case"], r["model"]) == key]
        done = [r for r in group if r["status"] == "complete" and math.isfinite(r["M_lr_over_M_T"])]
        mlr = np.array([r["M_lr_over_M_T"] for r in done])
        mean = float(mlr.mean()) if mlr.size else float("nan")
        failed = [r for r in group if r["status"] != "complete"]
        first = group[0]
        out.append({
            "case": key[0], "model": key[1], "velocity": first["velocity"], "seeds": len(group),
            "complete": len(done), "M_lr_over_M_T": mean,
            "M_lr_over_M_T_std": float(mlr.std(ddof=1)) if mlr.size >= 2 else float("nan"),
            "published_M_lr_over_M_T": first["published_M_lr_over_M_T"],
            "difference": mean - first["published_M_lr_over_M_T"],
            "N_lr": float(np.mean([r["N_lr"] for r in done])) if done else float("nan"),
            "published_N_lr": first["published_N_lr"],
            "N_init": float(np.mean([r["N_init"] for r in done])) if done else float("nan"),
            "published_N_init": first["published_N_init"], "published_note": first["published_note"],
            "status": failed[0]["status"] if failed else "complete",
            "error": failed[0]["error"] if failed else "",
            "wall_seconds_own_stages": float(sum(r["wall_seconds_own_stages"] for r in group)),
        })
    return out


def _full_summary(point: dict[str, Any]) -> dict[str, Any]:
    path = Path(point["run_dir"]) / "summary.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def _fit(family: str, model: str, runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Q*_D, critical speed and normalised slope of one family and collision model, with the published values."""
    published = PUBLISHED_QSTAR[family]
    record: dict[str, Any] = {"family": family, "model": model, "published_qstar": published["qstar"],
                              "published_qstar_err": published["qstar_err"],
                              "published_velocity": published["velocity"],
                              "published_velocity_err": published["velocity_err"],
                              "published_slope": PUBLISHED_SLOPE, "published_slope_err": PUBLISHED_SLOPE_ERR}
    done = [r for r in runs if r["status"] == "complete" and math.isfinite(r["M_lr_over_M_T"])]
    record["runs"] = len(done)
    try:
        fit = fit_qstar([r["Q"] for r in done], [r["M_lr_over_M_T"] for r in done], [r["N_lr"] for r in done],
                        velocity=[r["velocity"] for r in done])
    except ValueError as exc:
        record.update({"qstar": float("nan"), "fit_error": str(exc)})
        return record
    record.update({"qstar": fit.qstar, "qstar_err": fit.qstar_err, "velocity": fit.critical_velocity,
                   "velocity_err": fit.critical_velocity_err, "slope": fit.normalized_slope,
                   "slope_err": fit.normalized_slope_err, "brackets": bool(fit.brackets),
                   "fitted_runs": int(np.sum(fit.used)), "replicate_std": fit.replicate_std})
    return record


# --------------------------------------------------------------------------- report


def _g(value: Any, digits: int = 3) -> str:
    if isinstance(value, (float, int)) and not isinstance(value, bool):
        return "-" if not math.isfinite(value) else f"{value:.{digits}g}"
    return str(value)


def format_report(report: dict[str, Any]) -> list[str]:
    """The report as Markdown lines."""
    s = report["settings"]
    lines = ["# Reference cases 8 and 9: this pipeline next to method.md section 6", "",
             f"cases {', '.join(s['cases'])}; collision models (case 8) {', '.join(s['models'])}; "
             f"cells per projectile radius {s['cells_per_projectile_radius']}; quick {s['quick']}; "
             f"hand-off seeds per run {s['seeds']}", ""]
    not_modelled = sorted({m for r in report["runs"] for m in r["physics_not_modelled"]})
    if not_modelled:
        lines += ["Physics not modelled in these runs (summary.json):", *[f"- {m}" for m in not_modelled], ""]
    lines += ["## M_lr/M_T per run", ""]
    if s["seeds"] > 1:
        lines += [f"Each case ran with hand-off seeds 1-{s['seeds']} from one hydro run: M_lr/M_T is the mean "
                  "+- the standard deviation over the seeds (n finished), N_lr and N_init are means, the difference "
                  "is the mean's.", ""]
    lines += ["| case | v (m/s) | model | M_lr/M_T | published | difference | N_lr (published) | "
              "N_init (published) | status | wall s |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in report["cases"]:
        mlr = _g(r["M_lr_over_M_T"]) if r["seeds"] == 1 else \
            f"{plus_minus(r['M_lr_over_M_T'], r['M_lr_over_M_T_std'])} (n {r['complete']})"
        lines.append(f"| {r['case']} | {r['velocity']:.0f} | {r['model']} | {mlr} | "
                     f"{r['published_M_lr_over_M_T']:g}{' (' + r['published_note'] + ')' if r['published_note'] else ''}"
                     f" | {_g(r['difference'], 2)} | {_g(r['N_lr'])} ({r['published_N_lr']}) | "
                     f"{_g(r['N_init'])} ({r['published_N_init']}) | {r['status']}"
                     f"{': ' + r['error'] if r['error'] else ''} | {_g(r['wall_seconds_own_stages'])} |")
    lines += ["", "## Q*_D, critical speed, slope against Q/Q*_D", "",
              "| family | model | runs | Q*_D (J/kg) | published | v* (km/s) | published | slope | published |",
              "|---|---|---|---|---|---|---|---|---|"]
    for f in report["qstar"]:
        pub_q = f"{f['published_qstar']:.3g}" + (f" +- {f['published_qstar_err']:.2g}"
                                                  if math.isfinite(f["published_qstar_err"]) else " (approx.)")
        pub_v = f"{f['published_velocity'] / 1e3:.3g}" + (f" +- {f['published_velocity_err'] / 1e3:.2g}"
                                                          if math.isfinite(f["published_velocity_err"]) else " (approx.)")
        pub_s = f"{f['published_slope']:g} +- {f['published_slope_err']:g}"
        if not math.isfinite(f["qstar"]):
            lines.append(f"| {f['family']} | {f['model']} | {f['runs']} | no fit: {f.get('fit_error', '')} | {pub_q} | "
                         f"- | {pub_v} | - | {pub_s} |")
            continue
        note = "" if f["brackets"] else " (extrapolated: runs do not bracket 0.5)"
        lines.append(f"| {f['family']} | {f['model']} | {f['fitted_runs']} of {f['runs']} | "
                     f"{plus_minus(f['qstar'], f['qstar_err'])}{note} | {pub_q} | "
                     f"{plus_minus(f['velocity'] / 1e3, f['velocity_err'] / 1e3)} | {pub_v} | "
                     f"{plus_minus(f['slope'], f['slope_err'])} | {pub_s} |")
    scatter = [f"family {f['family']} {f['model']} {f['replicate_std']:.2g}" for f in report["qstar"]
               if math.isfinite(f.get("replicate_std", float("nan")))]
    if scatter:
        lines += ["", "Standard deviation of M_lr/M_T between the seeds of a run, pooled over the family's speeds: "
                  + "; ".join(scatter) + ". Every seed is a run of the fit, so this scatter is in the bootstrap "
                  "errors above."]
    if report["collision_models"]:
        lines += ["", "## Case 8: collision model against perfect merging", "",
                  "| case | model | M_lr/M_T | with merge | change |", "|---|---|---|---|---|"]
        for m in report["collision_models"]:
            lines.append(f"| {m['case']} | {m['model']} | {_g(m['M_lr_over_M_T'])} | {_g(m['merge_M_lr_over_M_T'])} | "
                         f"{_g(m['change_from_merge'], 2)} |")
    p = report["handoff_plateau"]
    if p is not None:
        lines += ["", "## Case 8c: hand-off time", "", "| hand-off (s) | M_lr/M_T |", "|---|---|"]
        lines += [f"| {t:g} | {_g(m)} |" for t, m in zip(p["times"], p["M_lr_over_M_T"])]
        lines += ["", f"Late slope (hand-offs at t >= {p['late_from']:.3g} s): {_g(p['late_slope_per_s'])} "
                      f"+- {_g(p['late_slope_err_per_s'], 2)} per s. Over {p['published_window_s'][0]:g}-"
                      f"{p['published_window_s'][1]:g} s (where the published M_lr/M_T levels off): mean "
                      f"{_g(p['window_mean'])}, range {_g(p['window_range'], 2)}, least-squares slope "
                      f"{_g(p['window_slope_per_s'], 2)} per s."
                      + (f" Failed hand-offs: {p['failed']}." if p["failed"] else "")]
    c = report["cost"]
    lines += ["", "## Cost", "",
              f"{c['wall_seconds']:.1f} s of wall time on {c['cores_used']} of {c['machine_cores']} cores "
              f"({c['backend']} backend, {c['workers']} parallel runs x {c['threads_per_run']} thread(s)); "
              f"the stages the runs ran themselves took {c['run_wall_seconds_total']:.1f} s in all."]
    return lines


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        options = options_from_args(args)
        report = run_validation(options)
    except UsageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (SweepError, ConfigError) as exc:
        for message in exc.messages:
            print(message, file=sys.stderr)
        return 2
    print("\n".join(format_report(report)))
    print(f"\nwrote {options['out'] / 'validation.json'} and {options['out'] / 'validation.md'}")
    failed = [r for r in report["runs"] if r["status"] != "complete"]
    scan_failed = report["handoff_plateau"] is not None and report["handoff_plateau"]["failed"]
    return 1 if failed or scan_failed else 0


if __name__ == "__main__":
    sys.exit(main())
