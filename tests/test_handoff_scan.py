"""Hand-off scan on a tiny real impact: one hydro run, one hand-off per time."""

import concurrent.futures as cf
import json
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from impactpipe.pipeline.cli import main
from impactpipe.pipeline.handoff_scan import handoff_scan, slope_text

HERE = Path(__file__).parent


def tiny_config(tmp_path):
    path = tmp_path / "tiny.yaml"
    path.write_text((HERE.parent / "configs" / "quickstart.yaml").read_text()
                    .replace("cells_per_projectile_radius: 4", "cells_per_projectile_radius: 2"))
    return path


def test_scan_runs_hydro_once_and_hands_off_at_each_time(tmp_path):
    times = [0.4, 0.8, 1.2]
    with cf.ThreadPoolExecutor(1) as pool:
        result = handoff_scan(tiny_config(tmp_path), times, tmp_path / "scan", executor=pool, show_progress=False)
    assert list(result["times"]) == times
    points = list(result["points"].values())
    records = [json.loads(Path(p["run_dir"], "stages.json").read_text()) for p in points]
    own_hydro = [r for r in records if "reused_from" not in r["hydro"]]
    assert len(own_hydro) == 1, "the hydro stage runs once for the whole scan"
    handoff_times = sorted(json.loads(Path(p["run_dir"], "summary.json").read_text())["handoff_time"] for p in points)
    assert np.allclose(handoff_times, times)
    gamma = 0.1 ** 3  # m_p / M_T: the largest remnant may hold the projectile too
    assert np.all((result["mlr_over_mt"] > 0) & (result["mlr_over_mt"] <= (1 + gamma) * (1 + 1e-3)))
    table = (tmp_path / "scan" / "handoff_scan.csv").read_text().splitlines()
    assert len([l for l in table if not l.startswith("#")]) == 4
    # the tiny target's 4 crossing times come after the last scan time: no late hand-offs, no slope
    assert result["late_from"] > max(times) and result["n_late"] == 0
    assert np.isnan(result["slope"]) and any(l.startswith("# no slope of M_lr/M_T") for l in table)
    assert (tmp_path / "scan" / "handoff_scan.png").stat().st_size > 0


def test_handoff_time_without_snapshot_is_rejected(tmp_path):
    config = tiny_config(tmp_path)
    config.write_text(config.read_text().replace("handoff: {", "handoff: {time: 0.5, "))
    result = CliRunner().invoke(main, ["validate", str(config)])
    assert result.exit_code == 2 and "handoff.time: 0.5 s has no hydro snapshot" in result.output


def test_handoff_time_on_a_default_snapshot_is_accepted(tmp_path):
    """Without output times the hydro stage writes 10 evenly spaced snapshots: each is a valid
    hand-off time, so a finished run serves a hand-off-time ladder without rerunning its hydro."""
    config = tiny_config(tmp_path)
    config.write_text(config.read_text().replace("handoff: {", "handoff: {time: 0.6, ")
                      .replace("hydro:\n", "hydro:\n  end_time: 1.0\n"))
    result = CliRunner().invoke(main, ["validate", str(config)])
    assert result.exit_code == 0, result.output
    config.write_text(config.read_text().replace("time: 0.6,", "time: 0.65,"))
    result = CliRunner().invoke(main, ["validate", str(config)])
    assert result.exit_code == 2 and "handoff.time: 0.65 s has no hydro snapshot; the snapshots are at 0, 0.1," \
        in result.output


def test_slope_text_says_why_there_is_no_slope():
    none = slope_text(float("nan"), float("nan"), 1, 12.7)
    assert none.startswith("no slope of M_lr/M_T over hand-offs at t >= 12.7 s")
    assert "two hand-offs: no error bar" in slope_text(-0.01, float("nan"), 2, 12.7)
    assert slope_text(-0.01, 0.004, 3, 12.7).endswith("-0.01 +- 0.004 per s")
