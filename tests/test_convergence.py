"""Convergence ladders: Richardson extrapolation, argument checks, and ladders run through the sweep
machinery with instant stand-in stages whose answer converges as a known power of the cell size."""

import collections
import concurrent.futures as cf
import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from sweep_stand_ins import _finish

from impactpipe.pipeline import stages
from impactpipe.pipeline.cli import main
from impactpipe.pipeline.config import load_config, load_yaml
from impactpipe.pipeline.derived import derive
from impactpipe.analysis.richardson import richardson
from impactpipe.pipeline.convergence import (LadderError, cheapest_within, parse_vary,
                                             richardson_uncertainty, run_ladders)

HERE = Path(__file__).parent
QUICKSTART = HERE.parent / "configs" / "quickstart.yaml"

#: Stand-in answer: M_lr/M_T = CONVERGED + AMPLITUDE h^ORDER with h = 1 / cells_per_projectile_radius,
#: plus NBODY_SLOPE (1/n - 1/100) with n = nbody.steps_per_dynamical_time (0 at its default 100),
#: plus HANDOFF_SLOPE (t - 1 s) with t = handoff.time when one is set,
#: plus SEED_SLOPE x (0, -1, +1) at handoff.seed 1, 2, 3 (0 at the default seed; mean 0 over seeds 1-3),
#: plus PARTICLE_SLOPE / n_p with n_p = handoff.particle_resolution when one is set.
CONVERGED, AMPLITUDE, ORDER = 0.7, 0.3, 2.0
NBODY_SLOPE = 2.0
HANDOFF_SLOPE = 0.05
SEED_SLOPE = 0.01
PARTICLE_SLOPE = 0.04


def hydro(ctx):
    cells = ctx.config.hydro.cells_per_projectile_radius
    _finish(ctx, "hydro")
    return {"stage": {"steps": int(100 * cells), "cell_updates": int(1000 * cells ** 3)}}


def handoff(ctx):
    _finish(ctx, "handoff")
    return {}


def nbody(ctx):
    _finish(ctx, "nbody")
    steps = int(ctx.config.nbody.steps_per_dynamical_time / 2)
    return {"stage": {"steps": steps, "particle_steps": int(100 * steps / ctx.config.nbody.opening_angle)}}


def analysis(ctx):
    h = 1.0 / ctx.config.hydro.cells_per_projectile_radius
    h_nbody = 1.0 / ctx.config.nbody.steps_per_dynamical_time
    t = ctx.config.handoff.time
    n_p = ctx.config.handoff.particle_resolution
    _finish(ctx, "analysis")
    return {"M_lr_over_M_T": CONVERGED + AMPLITUDE * h ** ORDER + NBODY_SLOPE * (h_nbody - 0.01)
            + (HANDOFF_SLOPE * (t - 1.0) if t is not None else 0.0) + SEED_SLOPE * {1: 0.0, 2: -1.0, 3: 1.0}[ctx.config.handoff.seed]
            + (PARTICLE_SLOPE / n_p if n_p is not None else 0.0), "N_lr": 100, "Q": 500.0}


STAGES = {s: f"test_convergence:{s}" for s in ("hydro", "handoff", "nbody", "analysis")}


def calls(out):
    log = out / "runs" / "calls.log"
    lines = log.read_text().split("\n") if log.is_file() else []
    return collections.Counter(tuple(line.split()) for line in lines if line)


# --------------------------------------------------------------------------- Richardson


def test_richardson_recovers_order_and_limit_for_constant_and_varying_ratios():
    for cells in ([5, 10, 20, 40], [4, 6, 10], [3, 4, 7, 12]):
        h = 1.0 / np.array(cells, dtype=float)
        f = CONVERGED + AMPLITUDE * h ** ORDER
        ext = richardson(h, f)
        assert ext.ok, ext.status
        assert ext.order == pytest.approx(ORDER, rel=1e-8)
        assert ext.value == pytest.approx(CONVERGED, abs=1e-12)
        assert np.allclose(ext.errors, AMPLITUDE * h ** ORDER)


def test_richardson_uses_the_three_finest_rungs_in_any_order():
    h = np.array([0.1, 0.4, 0.05, 0.2, 0.8])
    f = 1.0 - 2.0 * h ** 1.5
    f[4] = 7.0  # the coarsest rung is off the power law; it must not enter the estimate
    ext = richardson(h, f)
    assert ext.order == pytest.approx(1.5, rel=1e-8) and ext.value == pytest.approx(1.0, abs=1e-12)


def test_richardson_refuses_to_invent_a_number():
    h = np.array([0.05, 0.1, 0.2])
    assert "needs 3" in richardson(h[:2], np.array([0.5, 0.6])).status
    assert "needs 3" in richardson(h, np.array([0.5, np.nan, 0.7])).status
    assert richardson(h, np.array([0.5, 0.6, 0.55])).status.startswith("non-monotone")
    assert richardson(h, np.array([0.5, 0.6, 0.65])).status.startswith("not converging")
    assert "agree exactly" in richardson(h, np.array([0.5, 0.5, 0.5])).status
    # changes of 0.067 and then 0.069 per halving (case 8c's ladder averaged over hand-offs): order 0.04,
    # whose extrapolation would lie 25 changes beyond the finest rung
    slow = richardson(h, np.array([0.719, 0.786, 0.855]))
    assert slow.status == "observed order 0.042 below 0.5: not in the asymptotic range" and np.isnan(slow.value)
    for status in ("non-monotone", "not converging"):
        ext = richardson(h, np.array([0.5, 0.6, 0.55 if status == "non-monotone" else 0.65]))
        assert not ext.ok and np.isnan(ext.value) and np.all(np.isnan(ext.errors))


def test_cheapest_within_needs_every_finer_rung_inside_the_band():
    h = np.array([0.5, 0.25, 0.125, 0.0625])
    f = np.array([0.80, 0.69, 0.74, 0.71])
    assert cheapest_within(h, f, 0.72, 0.05) == 1
    assert cheapest_within(h, f, 0.72, 0.015) == 3
    assert cheapest_within(h, f, 0.60, 0.05) is None
    assert cheapest_within(h, f, float("nan"), 0.05) is None


def test_richardson_uncertainty_carries_the_seed_scatter_into_the_limit_and_the_tolerance_test():
    """f = 0.5 + 0.4 h at h = 1/20, 1/40, 1/80 (first order): exact means give f* = 0.5 and a
    next refinement at 0.5 + 0.4 / 160; resampling within the standard errors brackets 0.5
    with a 68 % range that grows with the errors, and the share of draws in which a rung lies
    within the tolerance of f* falls for rungs farther than the tolerance."""
    h = np.array([1 / 20, 1 / 40, 1 / 80])
    f = 0.5 + 0.4 * h
    tight = richardson_uncertainty(h, f, np.full(3, 1e-4), tolerance=0.015)
    assert tight.refused == 0.0 and tight.low < 0.5 < tight.high and tight.high - tight.low < 0.002
    assert tight.next_value == pytest.approx(0.5 + 0.4 / 160, abs=1e-12)
    # 20 cells lies 0.02 from f*, 40 cells 0.01, 80 cells 0.005, the next refinement 0.0025
    assert tight.within[0] < 0.01 and tight.within[1] > 0.99 and tight.within[2] > 0.99 and tight.next_within > 0.99
    loose = richardson_uncertainty(h, f, np.full(3, 3e-3), tolerance=0.011)
    assert loose.high - loose.low > 5 * (tight.high - tight.low) and loose.refused > tight.refused
    assert loose.low < 0.5 < loose.high
    assert 0.05 < loose.within[1] < 0.95, "40 cells is 0.01 from f*: the scatter makes it uncertain"
    again = richardson_uncertainty(h, f, np.full(3, 3e-3), tolerance=0.011)
    assert (again.low, again.high) == (loose.low, loose.high), "deterministic for a given seed"
    assert richardson_uncertainty(h, f, np.array([1e-3, np.nan, 1e-3]), tolerance=0.05) is None


def test_parse_vary_errors_name_the_argument():
    assert parse_vary(["hydro.max_levels=1,auto", "nbody.opening_angle=0.25,0.5"]) == {
        "hydro.max_levels": [1, "auto"], "nbody.opening_angle": [0.25, 0.5]}
    with pytest.raises(LadderError) as info:
        parse_vary(["hydro.cfl", "nbody.opening_angle=0.5", "a=1,2", "a=3,4", "b=1,1"])
    text = str(info.value)
    assert "expected KEY=V1,V2,... (got 'hydro.cfl')" in text
    assert "nbody.opening_angle: a ladder needs at least two distinct values" in text
    assert "--vary a: given twice" in text and "--vary b: a ladder needs" in text


def test_cli_rejects_bad_ladders_before_any_work(tmp_path):
    out = tmp_path / "ladder"
    runner = CliRunner()
    result = runner.invoke(main, ["convergence", str(QUICKSTART), "--out", str(out),
                                  "--vary", "hydro.cells_per_projectile_radiu=2,4,8"])
    assert result.exit_code == 2
    assert "--vary hydro.cells_per_projectile_radiu: not a config key" in result.output
    result = runner.invoke(main, ["convergence", str(QUICKSTART), "--out", str(out),
                                  "--vary", "hydro.cells_per_projectile_radius=2,-4,8"])
    assert result.exit_code == 2 and "values must be numbers > 0 (got [2, -4, 8])" in result.output
    result = runner.invoke(main, ["convergence", str(QUICKSTART), "--out", str(out),
                                  "--vary", "hydro.max_levels=1,0"])
    assert result.exit_code == 2
    assert "--vary hydro.max_levels=0: " in result.output and "integer >= 1 (got 0)" in result.output
    result = runner.invoke(main, ["convergence", str(QUICKSTART), "--out", str(out),
                                  "--vary", "hydro.cfl=0.2,0.4", "--depths", "1,x"])
    assert result.exit_code == 2 and "--depths: expected comma-separated numbers (got '1,x')" in result.output
    result = runner.invoke(main, ["convergence", str(QUICKSTART), "--out", str(out),
                                  "--vary", "hydro.block_cells=6,8"])
    assert result.exit_code == 2
    assert re.search(r"--vary hydro\.block_cells=6: \S*quickstart\.yaml:\d+: hydro\.block_cells: 6 cells per block",
                     result.output), "a rung's capability error is located like any config error"
    assert "block_cells=8" not in result.output
    assert not out.exists(), "nothing may be written for bad arguments"


# --------------------------------------------------------------------------- ladders on stand-ins


def test_ladders_through_the_sweep_machinery(tmp_path):
    out = tmp_path / "ladder"
    cells = [2.0, 4.0, 8.0, 16.0]
    angles = [0.25, 0.5, 1.0]  # the base config's 0.5 at its 4 cells is also a rung of the cells ladder
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_ladders(QUICKSTART, {"hydro.cells_per_projectile_radius": cells, "nbody.opening_angle": angles},
                             out, executor=pool, stage_functions=STAGES, show_progress=False)
    done = calls(out)
    runs = {run for run, _ in done}
    assert len(runs) == len(cells) + len(angles) - 1, "the rung common to both ladders runs once"
    assert sum(n for (_, stage), n in done.items() if stage == "hydro") == len(cells), \
        "the opening-angle ladder shares the hydro run of its cell size"
    assert set(done.values()) == {1}
    ext = result["richardson"]["hydro.cells_per_projectile_radius"]["M_lr_over_M_T"]
    assert ext.ok and ext.order == pytest.approx(ORDER, rel=1e-6) and ext.value == pytest.approx(CONVERGED, abs=1e-9)
    # 0.3 h^2 <= 0.05 from 4 cells per projectile radius on: the cheapest rung is 4
    rungs = [r for r in result["rungs"] if r.ladder == "hydro.cells_per_projectile_radius"]
    assert rungs[result["cheapest"]["hydro.cells_per_projectile_radius"]].value == 4.0
    angle = result["richardson"]["nbody.opening_angle"]["M_lr_over_M_T"]
    assert "agree exactly" in angle.status
    with open(out / "convergence.csv") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    by_cells = {float(r["value"]): r for r in rows if r["ladder"] == "hydro.cells_per_projectile_radius"}
    assert [float(r["value"]) for r in rows if r["ladder"] == "hydro.cells_per_projectile_radius"] == cells[::-1], \
        "rows of a ladder with a step size run from the finest rung"
    for c in cells:
        row = by_cells[c]
        assert float(row["cell_updates"]) == 1000 * c ** 3 and float(row["hydro_steps"]) == 100 * c
        assert float(row["M_lr_over_M_T_error_estimate"]) == pytest.approx(AMPLITUDE / c ** 2, rel=1e-5)
        assert row["peak_pressure_at_1Rp"] == "", "stand-in hydro files carry no tracers"
    assert float(by_cells[4.0]["M_lr_over_M_T_change_from_previous"]) == pytest.approx(
        AMPLITUDE / 16 - AMPLITUDE / 64, rel=1e-5)
    by_angle = {float(r["value"]): r for r in rows if r["ladder"] == "nbody.opening_angle"}
    assert float(by_angle[0.25]["particle_steps"]) == 20000
    assert by_angle[0.25]["hydro_from"] or by_angle[1.0]["hydro_from"], "shared hydro runs are named"
    table = (out / "convergence.csv").read_text()
    assert "cheapest rung within +-0.05 of the extrapolated M_lr/M_T 0.7: hydro.cells_per_projectile_radius = 4.0" \
        in table
    # the angle rungs agree exactly: no extrapolation, so the cheapest rung is measured against the finest one
    assert "nbody.opening_angle: no extrapolation (the three finest rungs agree exactly" in table
    assert "cheapest rung within +-0.05 of the finest rung's M_lr/M_T" in table
    summary = json.loads((out / "convergence.json").read_text())
    assert summary["cheapest_within_tolerance"] == {"hydro.cells_per_projectile_radius": 4.0,
                                                    "nbody.opening_angle": 1.0}
    assert summary["cheapest_measured_against"]["hydro.cells_per_projectile_radius"]["basis"] == "extrapolated"
    assert summary["cheapest_measured_against"]["nbody.opening_angle"]["basis"] == "finest rung"
    for name in ("convergence_cells_per_projectile_radius.png", "convergence_opening_angle.png"):
        assert (out / name).stat().st_size > 0
    assert (out / "points.json").is_file() and (out / "results.csv").is_file()
    with cf.ThreadPoolExecutor(2) as pool:
        run_ladders(QUICKSTART, {"hydro.cells_per_projectile_radius": cells, "nbody.opening_angle": angles},
                    out, executor=pool, stage_functions=STAGES, show_progress=False)
    assert calls(out) == done, "rerunning a finished ladder does no work"


def test_nbody_time_step_ladders(tmp_path):
    out = tmp_path / "ladder"
    steps = [50, 100, 200, 400]
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_ladders(QUICKSTART, {"nbody.steps_per_dynamical_time": steps}, out, executor=pool,
                             stage_functions=STAGES, show_progress=False)
    done = calls(out)
    assert sum(n for (_, stage), n in done.items() if stage == "hydro") == 1, "an N-body key shares the hydro run"
    assert sum(n for (_, stage), n in done.items() if stage == "nbody") == len(steps)
    rungs = result["rungs"]
    assert [r.step for r in rungs] == [1.0 / n for n in steps], "step size h = 1 / steps_per_dynamical_time"
    assert [r.costs["nbody_steps"] for r in rungs] == [n / 2 for n in steps]
    ext = result["richardson"]["nbody.steps_per_dynamical_time"]["M_lr_over_M_T"]
    h_cells = 1.0 / config_value(QUICKSTART, "hydro", "cells_per_projectile_radius")
    assert ext.ok and ext.order == pytest.approx(1.0, rel=1e-6)
    assert ext.value == pytest.approx(CONVERGED + AMPLITUDE * h_cells ** ORDER - 0.01 * NBODY_SLOPE, abs=1e-9)
    # the collision term of the rule is a ladder key too; its bound (0, 1] is checked before any work
    runner = CliRunner()
    result = runner.invoke(main, ["convergence", str(QUICKSTART), "--out", str(tmp_path / "bad"),
                                  "--vary", "nbody.collision_step_fraction=0.5,2"])
    assert result.exit_code == 2
    assert result.output.startswith("--vary nbody.collision_step_fraction=2: ")
    assert "nbody.collision_step_fraction: must be <= 1 (got 2)" in result.output
    assert not (tmp_path / "bad").exists()


def config_value(path, section, key):
    return load_yaml(Path(path).read_text())[section][key]


def test_handoff_time_ladder_shares_one_hydro_run_to_the_latest_time(tmp_path):
    out = tmp_path / "ladder"
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_ladders(QUICKSTART, {"handoff.time": [0.4, 0.8, 1.2]}, out, executor=pool,
                             stage_functions=STAGES, show_progress=False)
    done = calls(out)
    assert sum(n for (_, stage), n in done.items() if stage == "hydro") == 1
    assert sum(n for (_, stage), n in done.items() if stage == "nbody") == 3
    ext = result["richardson"]["handoff.time"]["M_lr_over_M_T"]
    assert not ext.ok and "no step size" in ext.status


def test_ladder_averaged_over_handoff_times(tmp_path):
    """--handoff-times: each rung hands off at every time from one hydro run; its answer is the mean
    over them (the hand-off term of the stand-in, HANDOFF_SLOPE (t - 1 s), averages to zero)."""
    out = tmp_path / "ladder"
    cells, times = [2.0, 4.0, 8.0], [0.8, 1.0, 1.2]
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_ladders(QUICKSTART, {"hydro.cells_per_projectile_radius": cells}, out, executor=pool,
                             stage_functions=STAGES, show_progress=False, handoff_times=times)
    done = calls(out)
    assert sum(n for (_, stage), n in done.items() if stage == "hydro") == len(cells), "one hydro run per rung"
    assert sum(n for (_, stage), n in done.items() if stage == "nbody") == len(cells) * len(times)
    for rung in result["rungs"]:
        h = 1.0 / rung.value
        assert rung.samples == pytest.approx([CONVERGED + AMPLITUDE * h ** ORDER + HANDOFF_SLOPE * (t - 1.0)
                                              for t in times], abs=1e-12)
        assert rung.answers["M_lr_over_M_T"] == pytest.approx(CONVERGED + AMPLITUDE * h ** ORDER, abs=1e-12)
        assert rung.spread == pytest.approx(HANDOFF_SLOPE * 0.4, abs=1e-12)
        assert rung.costs["cell_updates"] == 1000 * rung.value ** 3, "the shared hydro run is counted once"
        assert rung.costs["nbody_steps"] == len(times) * 50, "the N-body runs add up"
    ext = result["richardson"]["hydro.cells_per_projectile_radius"]["M_lr_over_M_T"]
    assert ext.ok and ext.value == pytest.approx(CONVERGED, abs=1e-9)
    with open(out / "convergence.csv") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    assert {r["handoffs"] for r in rows} == {"3"} and {float(r["M_lr_over_M_T_spread"]) for r in rows} == {0.02}
    assert json.loads((out / "convergence.json").read_text())["handoff_times"] == times
    runner = CliRunner()
    bad = runner.invoke(main, ["convergence", str(QUICKSTART), "--out", str(tmp_path / "bad"),
                               "--vary", "handoff.time=0.5,1.0", "--handoff-times", "1,2"])
    assert bad.exit_code == 2 and "--handoff-times: not with a handoff.time ladder" in bad.output
    bad = runner.invoke(main, ["convergence", str(QUICKSTART), "--out", str(tmp_path / "bad"),
                               "--vary", "hydro.cfl=0.2,0.4", "--handoff-times", "1,x"])
    assert bad.exit_code == 2 and "--handoff-times: expected comma-separated numbers (got '1,x')" in bad.output
    bad = runner.invoke(main, ["convergence", str(QUICKSTART), "--out", str(tmp_path / "bad"),
                               "--vary", "hydro.end_time=1.5,2.0", "--handoff-times", "1,1.2"])
    assert bad.exit_code == 2 and "--handoff-times: not with a hydro.end_time ladder" in bad.output
    assert not (tmp_path / "bad").exists()


def test_cli_hands_off_over_the_config_window_by_default(tmp_path, monkeypatch):
    """A config's handoff.window is the ladder's hand-off times unless --handoff-times or
    --single-handoff says otherwise, or a ladder sets the hand-off times itself; a bad window is
    refused with its line before any work; the window leaves every stage hash as it is."""
    from impactpipe.pipeline import convergence

    def spy(config_path, ladders, out, **kwargs):
        raise LadderError([f"spy: times={kwargs['handoff_times']}"])

    monkeypatch.setattr(convergence, "run_ladders", spy)
    text = QUICKSTART.read_text().replace("seed: 1}", "seed: 1, window: [0.8, 1.2, 1.6]}")
    config = tmp_path / "window.yaml"
    config.write_text(text)
    runner = CliRunner()

    def times_used(*args):
        result = runner.invoke(main, ["convergence", str(config), "--out", str(tmp_path / "out"), *args])
        assert result.exit_code == 2
        return result.output.strip().splitlines()[-1]

    assert times_used("--vary", "hydro.cfl=0.2,0.4") == "spy: times=[0.8, 1.2, 1.6]"
    assert times_used("--vary", "hydro.cfl=0.2,0.4", "--single-handoff") == "spy: times=None"
    assert times_used("--vary", "hydro.cfl=0.2,0.4", "--handoff-times", "1,2") == "spy: times=[1.0, 2.0]"
    assert times_used("--vary", "handoff.time=0.5,1.0") == "spy: times=None"
    assert times_used("--vary", "hydro.end_time=1.5,2.0") == "spy: times=None"
    assert times_used("--vary", "hydro.cfl=0.2,0.4", "--single-handoff", "--handoff-times", "1,2") == \
        "--single-handoff: not with --handoff-times"
    assert stages.stage_hashes(load_config(config)) == stages.stage_hashes(load_config(QUICKSTART))
    for window in ("[1.2, 0.8]", "[1.0]", "[0.0, 1.0]"):
        config.write_text(QUICKSTART.read_text().replace("seed: 1}", f"seed: 1, window: {window}}}"))
        result = runner.invoke(main, ["convergence", str(config), "--out", str(tmp_path / "out"),
                                      "--vary", "hydro.cfl=0.2,0.4"])
        assert result.exit_code == 2
        assert "window.yaml:19: handoff.window: must be two or more increasing times > 0 s" in result.output
    assert not (tmp_path / "out").exists()


def test_ladders_averaged_over_seeds_and_a_particle_resolution_ladder(tmp_path):
    """--seeds 3: each rung hands off with seeds 1-3 from one hydro run; its answer is their mean
    (the stand-in's seed term averages to zero) with the standard error of that mean.  A
    handoff.particle_resolution ladder shares one hydro run and extrapolates in 1 / value."""
    out = tmp_path / "ladder"
    cells, particles = [2.0, 4.0, 8.0], [1.0, 2.0, 4.0]
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_ladders(QUICKSTART, {"hydro.cells_per_projectile_radius": cells,
                                          "handoff.particle_resolution": particles}, out, executor=pool,
                             stage_functions=STAGES, show_progress=False, seeds=3)
    done = calls(out)
    # the particle ladder runs at the base config's 4 cells, which the resolution ladder has too
    assert sum(n for (_, stage), n in done.items() if stage == "hydro") == len(cells)
    assert sum(n for (_, stage), n in done.items() if stage == "nbody") == (len(cells) + len(particles)) * 3
    for rung in (r for r in result["rungs"] if r.ladder == "hydro.cells_per_projectile_radius"):
        mean = CONVERGED + AMPLITUDE * rung.value ** -ORDER
        assert rung.samples == pytest.approx([mean, mean - SEED_SLOPE, mean + SEED_SLOPE], abs=1e-12)
        assert rung.answers["M_lr_over_M_T"] == pytest.approx(mean, abs=1e-12)
        assert rung.sem == pytest.approx(SEED_SLOPE / np.sqrt(3.0), rel=1e-9)
    ext = result["richardson"]["handoff.particle_resolution"]["M_lr_over_M_T"]
    assert ext.ok and ext.order == pytest.approx(1.0, abs=1e-9)
    assert ext.value == pytest.approx(CONVERGED + AMPLITUDE * 4.0 ** -ORDER, abs=1e-9)
    with open(out / "convergence.csv") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    assert {r["handoffs"] for r in rows} == {"3"}
    assert [float(r["M_lr_over_M_T_sem"]) for r in rows] == pytest.approx([SEED_SLOPE / np.sqrt(3.0)] * len(rows),
                                                                         rel=1e-5)
    saved = json.loads((out / "convergence.json").read_text())
    assert saved["ladders"]["handoff.particle_resolution"] == particles
    spread = saved["richardson_uncertainty"]["handoff.particle_resolution"]
    assert spread["f_star_16"] < ext.value < spread["f_star_84"]
    assert set(spread["within_tolerance"]) == {"1.0", "2.0", "4.0"}
    bad = CliRunner().invoke(main, ["convergence", str(QUICKSTART), "--out", str(tmp_path / "bad"),
                                    "--vary", "handoff.seed=1,2", "--seeds", "3"])
    assert bad.exit_code == 2 and "--seeds: not with a handoff.seed ladder" in bad.output
    bad = CliRunner().invoke(main, ["convergence", str(QUICKSTART), "--out", str(tmp_path / "bad"),
                                    "--vary", "handoff.particle_resolution=3,4"])
    assert bad.exit_code == 2 and "handoff.particle_resolution: 3 is not the resolution of a block level" in bad.output
    assert not (tmp_path / "bad").exists()


def test_ladder_adopts_the_hydro_run_of_a_finished_run(tmp_path):
    """--reuse-hydro: rungs with the donor's hydro settings adopt its hydro run (no hydro stage
    runs); rungs with other hydro settings run their own; an unfinished donor is refused."""
    donor = tmp_path / "donor" / "run"
    stages.run(load_config(QUICKSTART), donor, show_progress=False, stage_functions=STAGES)
    out = tmp_path / "ladder"
    with cf.ThreadPoolExecutor(2) as pool:
        result = run_ladders(QUICKSTART, {"nbody.opening_angle": [0.25, 0.5, 1.0], "hydro.cfl": [0.2, 0.4]}, out,
                             executor=pool, stage_functions=STAGES, show_progress=False, reuse_runs=[donor])
    done = calls(out)
    hydro_runs = {run for (run, stage) in done if stage == "hydro"}
    assert hydro_runs == {r.name for r in result["rungs"] if r.ladder == "hydro.cfl" and r.value == 0.2}, \
        "only the rung whose hydro settings differ from the donor's runs a hydro stage"
    assert sum(n for (_, stage), n in done.items() if stage == "nbody") == 3, \
        "the base rung (common to both ladders) is the donor's config and adopts all its stages"
    adopted = [r for r in result["rungs"] if r.hydro_from == "run"]
    assert len(adopted) == 4 and all(r.status == "complete" for r in result["rungs"])
    (tmp_path / "empty").mkdir()
    bad = CliRunner().invoke(main, ["convergence", str(QUICKSTART), "--out", str(tmp_path / "bad"),
                                    "--vary", "hydro.cfl=0.2,0.4", "--reuse-hydro", str(tmp_path / "empty")])
    assert bad.exit_code == 2 and "no finished hydro stage there" in bad.output
    # a donor whose hydro settings no rung shares would silently run every hydro stage: refused
    bad = CliRunner().invoke(main, ["convergence", str(QUICKSTART), "--out", str(tmp_path / "bad"),
                                    "--vary", "hydro.cfl=0.1,0.2", "--reuse-hydro", str(donor)])
    assert bad.exit_code == 2 and "its hydro settings match no rung's" in bad.output
    assert not (tmp_path / "bad").exists()


def test_handoff_time_ladder_on_the_default_snapshots_adopts_a_finished_hydro_run(tmp_path):
    """Hand-off times that are snapshots the config writes anyway (10 evenly spaced by default)
    need no hydro settings of their own: a finished run of the config serves the ladder, and
    --handoff-times on those snapshots does too; a time off the snapshots gets its own hydro run."""
    donor = tmp_path / "donor" / "run"
    stages.run(load_config(QUICKSTART), donor, show_progress=False, stage_functions=STAGES)
    end = derive(load_config(QUICKSTART))["end_time"]
    times = [0.6 * end, 0.8 * end, end]
    out = tmp_path / "ladder"
    with cf.ThreadPoolExecutor(2) as pool:
        run_ladders(QUICKSTART, {"handoff.time": times}, out, executor=pool, stage_functions=STAGES,
                    show_progress=False, reuse_runs=[donor])
        run_ladders(QUICKSTART, {"hydro.cfl": [0.4]}, tmp_path / "averaged", executor=pool, stage_functions=STAGES,
                    show_progress=False, reuse_runs=[donor], handoff_times=times[:2])
    assert not any(stage == "hydro" for (_, stage) in calls(out) | calls(tmp_path / "averaged"))
    assert sum(n for (_, stage), n in calls(out).items() if stage == "handoff") == 3
    bad = CliRunner().invoke(main, ["convergence", str(QUICKSTART), "--out", str(tmp_path / "bad"),
                                    "--vary", f"handoff.time={0.55 * end},{end}", "--reuse-hydro", str(donor)])
    assert bad.exit_code == 2 and "its hydro settings match no rung's" in bad.output


@pytest.mark.validation
def test_quickstart_resolution_ladder_real_stages(tmp_path):
    """Three resolutions of the quickstart with the real stages: costs grow with resolution and the
    peak pressures at fixed depths are measured (about 2 minutes on 2 cores)."""
    result = CliRunner().invoke(main, ["convergence", str(QUICKSTART), "--out", str(tmp_path / "ladder"), "-q",
                                       "--workers", "1", "--vary", "hydro.cells_per_projectile_radius=1,2,4"])
    assert result.exit_code == 0, result.output
    with open(tmp_path / "ladder" / "convergence.csv") as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    cost = [float(r["cell_updates"]) for r in rows]
    assert cost == sorted(cost, reverse=True) and cost[-1] > 0
    for row in rows:
        assert 0 < float(row["M_lr_over_M_T"]) <= 1.01
        assert float(row["peak_pressure_at_1Rp"]) > float(row["peak_pressure_at_4Rp"]) > 0
        summary = json.loads((tmp_path / "ladder" / "runs" / row["run"] / "summary.json").read_text())
        budget = summary["nbody_budget"]
        mass = summary["handoff_budget"]["particle_mass"]
        assert float(row["unbound_at_handoff"]) == pytest.approx(budget["initial_unbound_mass"] / mass, rel=1e-5)
        assert float(row["near_escape_at_handoff"]) == pytest.approx(budget["initial_near_escape_mass"] / mass,
                                                                     rel=1e-5)
        assert 0.0 <= float(row["near_escape_at_handoff"]) <= 1.0 - float(row["unbound_at_handoff"])
    assert "Richardson M_lr_over_M_T" in result.output


def _compile_after_a_parallel_region(_):
    """In a pool worker: set the thread count as run_point does (this starts numba's threads), run a
    parallel kernel, then compile a new function (which re-reads numba's config)."""
    import numba
    from numba import njit, prange

    numba.set_num_threads(1)

    @njit(parallel=True)
    def total(a):
        s = 0.0
        for i in prange(a.size):
            s += a[i]
        return s

    total(np.ones(8))

    @njit
    def plus_one(x):
        return x + 1

    return plus_one(1), numba.config.NUMBA_NUM_THREADS


def test_pool_workers_take_their_thread_count_before_numba_starts_threads():
    """Ladder rungs run in spawned pool workers; a worker imports numba while unpickling its initializer,
    so the thread count must be re-read there, or the first compile after a parallel region raises
    "Cannot set NUMBA_NUM_THREADS to a different value" (seen with a cold numba cache)."""
    from impactpipe.pipeline.sweep import Execution, make_executor

    pool, close = make_executor(Execution(backend="local", workers=1, threads_per_run=1))
    try:
        assert pool.submit(_compile_after_a_parallel_region, None).result(timeout=300) == (2, 1)
    finally:
        close()
