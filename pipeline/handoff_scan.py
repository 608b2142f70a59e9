"""Hand-off scan: one hydro run, handed off at several times, each reaccumulated and analysed.

As in the reference study, the largest remnant should level off once the hand-off is
late enough (after ~4 target sound-crossing times); the least-squares slope of M_lr/M_T
against hand-off time over those late times, and its scatter, measure the method's
error.  The scan is a sweep over ``handoff.time`` with the hydro stage run once to the
latest time (snapshots at every scan time) and shared by all points.
"""

from __future__ import annotations

import concurrent.futures as cf
import logging
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy import stats

from impactpipe import storage

from . import derived
from .config import load_config
from .sweep import load_sweep, run_sweep

log = logging.getLogger(__name__)

SCAN_FILE = "handoff_scan.yaml"
TABLE_FILE = "handoff_scan.csv"
FIGURE_FILE = "handoff_scan.png"
#: Hand-offs at or after this many target sound-crossing times enter the slope.
LATE_CROSSING_TIMES = 4.0


def handoff_scan(config_path: str | Path, times: list[float], out_dir: str | Path,
                 executor: cf.Executor | None = None, show_progress: bool = True,
                 execution: dict[str, Any] | None = None) -> dict[str, Any]:
    """Run the scan; returns {"times", "mlr_over_mt", "n_lr", "slope", "slope_err", "late_from"}.

    Writes ``handoff_scan.csv`` and ``handoff_scan.png`` into ``out_dir`` (SI units).
    """
    config_path = Path(config_path).resolve()
    times = sorted(float(t) for t in times)
    if not times or times[0] <= 0:
        raise ValueError(f"--times: give hand-off times > 0 s (got {times})")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    spec = {
        "name": f"{load_config(config_path).name}-handoff-scan",
        "base": str(config_path),
        "output": str(out),
        "overrides": {"hydro.end_time": times[-1], "hydro.output_times": times},
        "axes": {"handoff.time": times},
        "execution": execution or {},
    }
    storage.write_text_atomic(out / SCAN_FILE, yaml.safe_dump(spec, sort_keys=False))
    sweep = load_sweep(out / SCAN_FILE)
    result = run_sweep(sweep, executor=executor, show_progress=show_progress)
    rows = []
    for point in result["points"].values():
        summary = point.get("summary", {})
        rows.append((point["params"]["handoff.time"], summary.get("M_lr_over_M_T", np.nan),
                     summary.get("N_lr", np.nan), point["status"]))
    rows.sort()
    t = np.array([r[0] for r in rows])
    mlr = np.array([r[1] for r in rows], dtype=float)
    n_lr = np.array([r[2] for r in rows], dtype=float)
    crossing = derived.derive(sweep.config_for({}))["sound_crossing_time"]
    late_from = LATE_CROSSING_TIMES * crossing
    late = (t >= late_from) & np.isfinite(mlr)
    slope = slope_err = float("nan")
    if late.sum() >= 3:
        fit = stats.linregress(t[late], mlr[late])
        slope, slope_err = float(fit.slope), float(fit.stderr)
    elif late.sum() == 2:
        slope = float((mlr[late][1] - mlr[late][0]) / (t[late][1] - t[late][0]))
    lines = ["# hand-off scan of " + str(config_path),
             "# " + slope_text(slope, slope_err, int(late.sum()), late_from),
             "handoff_time_s,M_lr_over_M_T,N_lr,late,status"]
    lines += [f"{ti:.6g},{mi:.6g},{ni:.0f},{int(li)},{r[3]}" for ti, mi, ni, li, r in zip(t, mlr, n_lr, late, rows)]
    storage.write_text_atomic(out / TABLE_FILE, "\n".join(lines) + "\n")
    _figure(out / FIGURE_FILE, t, mlr, late, late_from, slope)
    return {"times": t, "mlr_over_mt": mlr, "n_lr": n_lr, "slope": slope, "slope_err": slope_err,
            "late_from": late_from, "n_late": int(late.sum()), "points": result["points"]}


def slope_text(slope: float, slope_err: float, n_late: int, late_from: float) -> str:
    """One line on the late-time slope of M_lr/M_T: the value, or why there is none."""
    where = f"over hand-offs at t >= {late_from:.4g} s ({LATE_CROSSING_TIMES:g} crossing times)"
    if n_late < 2:
        return (f"no slope of M_lr/M_T {where}: {n_late} hand-off time(s) there, at least 2 needed "
                "(scan later times)")
    if n_late == 2:
        return f"slope of M_lr/M_T {where}: {slope:.4g} per s (two hand-offs: no error bar)"
    return f"slope of M_lr/M_T {where}: {slope:.4g} +- {slope_err:.2g} per s"


def _figure(path: Path, t, mlr, late, late_from: float, slope: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 4.2), constrained_layout=True)
    ax.plot(t, mlr, "o-", label="runs")
    ax.axvline(late_from, color="grey", ls=":", label=f"{LATE_CROSSING_TIMES:g} crossing times")
    if np.isfinite(slope) and late.sum() >= 2:
        tl = t[late]
        ax.plot(tl, np.mean(mlr[late]) + slope * (tl - np.mean(tl)), "k--", label=f"late slope {slope:.3g} /s")
    ax.set_xlabel("hand-off time (s)")
    ax.set_ylabel("M_lr / M_T")
    ax.legend()
    with storage.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=150, format="png")
    plt.close(fig)
