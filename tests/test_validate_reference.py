"""benchmarks/validate_reference.py: argument checks, the report on instant stand-in stages whose
M_lr/M_T(Q) law has a known Q*_D, and (validation) the quick mode with the real stages."""

import collections
import concurrent.futures as cf
import importlib.util
import json
import math
import shutil
from pathlib import Path

import pytest

import sweep_stand_ins

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("validate_reference", ROOT / "benchmarks" / "validate_reference.py")
vr = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(vr)

SIZE_RATIO = 830.0 / 1.0e4


def stage_calls(out):
    counts = collections.Counter()
    for log in out.glob("case*/runs/calls.log"):
        counts.update(line.split()[1] for line in log.read_text().splitlines() if line)
    return counts


def test_report_on_stand_ins_recovers_the_synthetic_qstar(tmp_path):
    out = tmp_path / "v"
    options = vr.options_from_args(vr.parse_args(["--out", str(out), "--handoff-times", "none", "--quick",
                                                       "--models", "merge,conditional_merge,bounce"]))
    assert options["cells"] == vr.QUICK_CELLS
    with cf.ThreadPoolExecutor(2) as pool:
        report = vr.run_validation(options, executor=pool, stage_functions=sweep_stand_ins.STAGES)
    runs = report["runs"]
    assert len(runs) == 3 * 3 + 2 and all(r["status"] == "complete" for r in runs)
    calls = stage_calls(out)
    assert calls["hydro"] == 5, "one hydro run per impact speed, shared by the collision models"
    assert calls["nbody"] == 11
    by = {(r["case"], r["model"]): r for r in runs}
    q = 0.5 * SIZE_RATIO ** 3 * 1900.0 ** 2
    assert by["8c", "merge"]["M_lr_over_M_T"] == pytest.approx(1 - 0.5 * q / sweep_stand_ins.QSTAR)
    assert by["8c", "merge"]["difference"] == pytest.approx(by["8c", "merge"]["M_lr_over_M_T"] - 0.76)
    assert by["9b", "merge"]["published_M_lr_over_M_T"] == 0.81
    fits = {(f["family"], f["model"]): f for f in report["qstar"]}
    assert set(fits) == {("8", "merge"), ("8", "conditional_merge"), ("8", "bounce"), ("9", "merge")}
    for fit in fits.values():
        assert fit["qstar"] == pytest.approx(sweep_stand_ins.QSTAR, rel=1e-9)
        assert fit["velocity"] == pytest.approx(math.sqrt(2 * sweep_stand_ins.QSTAR / SIZE_RATIO ** 3), rel=1e-9)
        assert fit["slope"] == pytest.approx(-0.5, rel=1e-9)
    assert fits["8", "merge"]["fitted_runs"] == 2, "8a (M_lr/M_T = 0 in the stand-in law) is left out of the fit"
    assert {(m["case"], m["model"]) for m in report["collision_models"]} == {
        (c, m) for c in ("8a", "8b", "8c") for m in ("conditional_merge", "bounce")}
    assert all(m["change_from_merge"] == 0.0 for m in report["collision_models"])
    assert report["handoff_plateau"] is None
    assert report["cost"]["cores_used"] == report["cost"]["workers"] * report["cost"]["threads_per_run"]
    points = json.loads((out / "case8" / "points.json").read_text())
    bounce = next(p for p in points.values() if p["params"]["nbody.collision_model"] == "bounce")
    config = Path(bounce["run_dir"], "config.resolved.yaml").read_text()
    assert "min_dynamical_times: 10.0" in config and "cells_per_projectile_radius: 4.0" in config
    text = (out / "validation.md").read_text()
    assert "| 8c | 1900 | merge | 0.712 | 0.76 |" in text
    assert json.loads((out / "validation.json").read_text())["settings"]["quick"] is True


def test_case_8_runs_perfect_merging_only_unless_asked():
    assert vr.options_from_args(vr.parse_args([]))["models"] == ["merge"]
    assert vr.options_from_args(vr.parse_args(["--models", "bounce"]))["models"] == ["merge", "bounce"]


def test_bad_arguments_name_the_option_and_the_allowed_values(tmp_path, capsys):
    out = tmp_path / "v"
    assert vr.main(["--cases", "8a,8d", "--out", str(out)]) == 2
    assert "--cases: unknown case(s) 8d (allowed: 8a, 8b, 8c, 9a, 9b)" in capsys.readouterr().err
    assert vr.main(["--models", "merge,stick", "--out", str(out)]) == 2
    assert "--models: unknown model(s) stick (allowed: merge, conditional_merge, bounce)" in capsys.readouterr().err
    assert vr.main(["--handoff-times", "4,x", "--out", str(out)]) == 2
    assert "--handoff-times: expected comma-separated seconds or 'none' (got '4,x')" in capsys.readouterr().err
    assert vr.main(["--cells-per-projectile-radius", "0", "--out", str(out)]) == 2
    assert "--cells-per-projectile-radius: must be > 0 (got 0)" in capsys.readouterr().err
    assert not out.exists()


def test_a_family_whose_cases_differ_in_more_than_speed_is_refused(tmp_path, monkeypatch):
    configs = tmp_path / "reference"
    shutil.copytree(vr.REFERENCE_DIR, configs)
    path = configs / "case8b.yaml"
    path.write_text(path.read_text().replace("end_time: 12.0", "end_time: 10.0"))
    monkeypatch.setattr(vr, "REFERENCE_DIR", configs)
    options = vr.options_from_args(vr.parse_args(["--cases", "8a,8b", "--out", str(tmp_path / "v")]))
    with pytest.raises(vr.UsageError, match="case8b.yaml differs from case8a.yaml in more than the impact speed"):
        vr.family_sweeps(options)


@pytest.mark.validation
def test_quick_mode_with_the_real_stages(tmp_path):
    """The smoke mode end to end: every case, all three collision models, the 8c hand-off scan."""
    out = tmp_path / "v"
    status = vr.main(["--quick", "--cells-per-projectile-radius", "4", "--handoff-times", "6,10,12,15",
                      "--models", "merge,conditional_merge,bounce", "--out", str(out), "--workers", "2"])
    assert status == 0
    report = json.loads((out / "validation.json").read_text())
    assert len(report["runs"]) == 11 and all(r["status"] == "complete" for r in report["runs"])
    assert all(0.0 <= r["M_lr_over_M_T"] <= 1.01 for r in report["runs"])
    assert report["handoff_plateau"]["times"] == [6.0, 10.0, 12.0, 15.0]
    assert all(math.isfinite(m) for m in report["handoff_plateau"]["M_lr_over_M_T"])


def test_seeds_average_each_case_and_enter_the_fit(tmp_path):
    """--seeds 5: one hydro run per speed, five hand-offs each; the tables give mean +- standard
    deviation (the stand-in's seed offsets cancel in the mean) and the fit reports their scatter."""
    out = tmp_path / "v"
    options = vr.options_from_args(vr.parse_args(["--out", str(out), "--handoff-times", "none", "--quick",
                                                   "--cases", "8a,8b,8c", "--seeds", "5"]))
    with cf.ThreadPoolExecutor(2) as pool:
        report = vr.run_validation(options, executor=pool, stage_functions=sweep_stand_ins.NOISY_STAGES)
    assert len(report["runs"]) == 15
    calls = stage_calls(out)
    assert calls["hydro"] == 3 and calls["handoff"] == 15
    by = {r["case"]: r for r in report["cases"]}
    q = 0.5 * SIZE_RATIO ** 3 * 1900.0 ** 2
    std = sweep_stand_ins.REPLICATE_NOISE * math.sqrt(2.5)
    assert by["8c"]["M_lr_over_M_T"] == pytest.approx(1 - 0.5 * q / sweep_stand_ins.QSTAR, abs=1e-12)
    assert by["8c"]["M_lr_over_M_T_std"] == pytest.approx(std, rel=1e-9)
    assert (by["8c"]["seeds"], by["8c"]["complete"]) == (5, 5)
    (fit,) = report["qstar"]
    assert fit["replicate_std"] == pytest.approx(std, rel=1e-9)
    assert math.isfinite(fit["qstar_err"]) and fit["qstar_err"] > 0.0
    assert abs(fit["qstar"] - sweep_stand_ins.QSTAR) < 2.0 * fit["qstar_err"]
    text = (out / "validation.md").read_text()
    assert f"| 8c | 1900 | merge | {by['8c']['M_lr_over_M_T']:.3g} +- {std:.2g} (n 5) | 0.76 |" in text
    assert "between the seeds of a run" in text
    assert vr.main(["--seeds", "0", "--out", str(tmp_path / "bad")]) == 2
