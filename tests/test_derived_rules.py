"""Each automatic choice is derived with its rule, shown by validate, and skipped physics costs
nothing (issue 11, "model only what a scene requires")."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from impactpipe.hydro.output.io import read_snapshot
from impactpipe.pipeline.adapters.hydro import build_simulation
from impactpipe.pipeline import derived, run
from impactpipe.pipeline.cli import main
from impactpipe.pipeline.config import load_config, parse_config

CONFIGS = Path(__file__).parent.parent / "configs"
QUICKSTART = CONFIGS / "quickstart.yaml"
CASE_9A = CONFIGS / "reference" / "case9a.yaml"  # hydro strength preset
CASE_8C = CONFIGS / "reference" / "case8c.yaml"  # GEO weak
SOD = (Path(__file__).parent / "configs" / "sod.yaml").read_text()


def test_geometry_follows_the_impact_angle():
    head_on = derived.derive(load_config(QUICKSTART))
    assert head_on["geometry"] == "2d-cylindrical" and "90" in head_on["geometry_rule"]
    oblique = derived.derive(load_config(QUICKSTART, overrides={"scene.impact.angle": 45.0}))
    assert oblique["geometry"] == "3d"
    assert oblique["domain"]["half_domain"] and oblique["domain"]["symmetry"]


def test_hand_off_time_is_four_sound_crossing_times():
    values = derived.derive(load_config(QUICKSTART))
    assert values["end_time"] == pytest.approx(4.0 * values["sound_crossing_time"], rel=1e-12)
    assert "4 target sound-crossing times" in values["end_time_rule"]
    fixed = derived.derive(load_config(QUICKSTART, overrides={"hydro.end_time": 2.5}))
    assert fixed["end_time"] == 2.5 and fixed["end_time_rule"] == "set in the config"


def test_hydro_preset_runs_no_strength_kernel():
    """Case 9a's 'hydro' GEO preset has zero yield strength: strength is off and the simulation
    carries no stress state; case 8c's 'weak' preset turns it on."""
    hydro = load_config(CASE_9A, overrides={"hydro.cells_per_projectile_radius": 1})
    values = derived.derive(hydro)
    assert all(not choice["enabled"] for choice in values["strength"].values())
    assert "no strength kernel" in values["strength"]["basalt"]["rule"]
    sim = build_simulation(hydro, values)
    assert sim.strength is None and sim.state.arhoq.shape[1] == 0
    weak = load_config(CASE_8C, overrides={"hydro.cells_per_projectile_radius": 1})
    weak_values = derived.derive(weak)
    assert weak_values["strength"]["basalt"]["enabled"]
    assert build_simulation(weak, weak_values).strength is not None


def test_self_gravity_rule_is_stated_with_its_numbers():
    values = derived.derive(load_config(QUICKSTART))
    assert values["self_gravity"] is False
    rule = values["self_gravity_rule"]
    assert "Pa" in rule and "m/s" in rule, rule


def test_a_porous_target_with_self_gravity_starts_unstrained_in_equilibrium_and_says_so():
    """configs/large_body/porous.yaml with self_gravity auto: on, the rule compares the central
    pressure with the porous target's bulk tensile strength Y_T / alpha0, the initial state names
    the porous choice, and the setup builds it (no refusal): distension alpha0 in the target and
    the lithostatic pressure at its centre."""
    config = load_config(CONFIGS / "large_body" / "porous.yaml",
                         overrides={"hydro.self_gravity": "auto", "hydro.cells_per_projectile_radius": 1})
    values = derived.derive(config)
    assert values["self_gravity"] is True
    assert "auto: on" in values["self_gravity_rule"] and "Y_T / alpha0" in values["self_gravity_rule"]
    assert "distension alpha0 = 1.5" in values["initial_state"] and "unstrained" in values["initial_state"]
    sim = build_simulation(config, values)
    snap = sim.snapshot()
    target = snap.volume_fraction[:, 0] > 0.0
    assert np.abs(snap.extra["distension"][target] / 1.5 - 1.0).max() < 1.0e-15
    central = derived.central_pressure(values["target_reference_density"], config.scene.target.radius)
    # the target's own cells (the few it shares with the projectile at the contact point are
    # heated by the bodies' merged kinetic energy, HydroState.set_material)
    alone = target & (snap.volume_fraction[:, 1] == 0.0)
    assert 0.9 * central < snap.pressure[alone].max() < central


def test_tracers_only_where_the_analysis_needs_them():
    impact = load_config(QUICKSTART)
    on, why = derived.derive(impact)["tracers"], derived.derive(impact)["tracers_rule"]
    assert on and "auto" in why
    tube = parse_config(SOD)
    values = derived.derive(tube)
    assert values["tracers"] is False and "off" in values["tracers_rule"]
    assert build_simulation(tube, values).tracers is None
    off = load_config(QUICKSTART, overrides={"hydro.tracers.enabled": False})
    assert derived.derive(off)["tracers"] is False


def test_validate_prints_every_choice_and_its_rule():
    result = CliRunner().invoke(main, ["validate", str(QUICKSTART)])
    assert result.exit_code == 0, result.output
    for key in ("geometry", "end_time", "self_gravity", "tracers", "strength", "margin"):
        assert key in result.output, key


def test_an_under_resolved_projectile_is_warned_about_before_any_work(tmp_path):
    """1 cell per projectile radius (2 across) warns before any work (validate, run), naming the key and the
    value; the quickstart's 4 cells and scenes without a projectile do not."""
    coarse = tmp_path / "coarse.yaml"
    coarse.write_text(QUICKSTART.read_text().replace("cells_per_projectile_radius: 4", "cells_per_projectile_radius: 1"))
    result = CliRunner().invoke(main, ["validate", str(coarse)])
    assert result.exit_code == 0, result.output
    assert ("warning: hydro.cells_per_projectile_radius: 1 (2 cells across the projectile) is under-resolved"
            in result.output)
    assert derived.resolution_warnings(load_config(QUICKSTART)) == []
    assert derived.resolution_warnings(parse_config(SOD)) == []


def test_per_level_time_stepping_on_an_impact_is_warned_about(tmp_path):
    """A strengthless impact, with or without tracers, validates with ``per_level`` and gets a warning
    naming the key and the docs (with self-gravity it is refused); the global step and a per_level Sod
    do not."""
    impact = Path(__file__).parent / "configs" / "mpi" / "impact_uniform.yaml"
    per_level = tmp_path / "per_level.yaml"
    per_level.write_text(impact.read_text().replace("max_levels: 1", "max_levels: 2\n  time_stepping: per_level"))
    result = CliRunner().invoke(main, ["validate", str(per_level)])
    assert result.exit_code == 0, result.output
    assert "warning: hydro.time_stepping: per_level on an impact is not yet sound at every resolution" in result.output
    with_tracers = tmp_path / "per_level_tracers.yaml"
    with_tracers.write_text(per_level.read_text().replace("tracers: {enabled: false}", "tracers: {enabled: true}"))
    result = CliRunner().invoke(main, ["validate", str(with_tracers)])
    assert result.exit_code == 0 and "does not support" not in result.output, result.output
    gravity = tmp_path / "per_level_gravity.yaml"
    gravity.write_text(with_tracers.read_text().replace("max_levels: 2", "max_levels: 2\n  self_gravity: true"))
    result = CliRunner().invoke(main, ["validate", str(gravity)])
    assert result.exit_code != 0 and "per_level does not support self-gravity" in result.output, result.output
    assert derived.time_stepping_warnings(load_config(impact)) == []
    sod = load_config(Path(__file__).parent / "configs" / "sod.yaml", overrides={"hydro.time_stepping": "per_level"})
    assert derived.time_stepping_warnings(sod) == []


def test_a_verification_scene_refines_adaptively_through_the_pipeline(tmp_path):
    """Sod (1d-planar, 128 finest cells) with ``hydro.max_levels: 2``: validate states the adaptive
    mesh, the hydro stage runs on it (finest cells 1/128 m, root cells twice that, both levels at
    the start and the end, the mass and energy budget closed) and auto keeps a verification scene
    on one level."""
    auto = derived.derive(parse_config(SOD))
    assert auto["levels"] == 1 and auto["levels_rule"].startswith("auto: one level")
    path = tmp_path / "sod.yaml"
    path.write_text(SOD.replace("cells: 64", "cells: 128") + "hydro:\n  max_levels: 2\n")
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 0 and "adaptive, 2 levels" in result.output, result.output
    summary = run(load_config(path), tmp_path / "run", show_progress=False)
    assert list(summary["stages"]) == ["hydro"]
    budget = summary["hydro_budget"]
    assert abs(budget["mass_error"]) < 1e-13 and abs(budget["energy_error"]) < 1e-13
    first, last = (read_snapshot(tmp_path / "run" / "hydro.h5", index) for index in (0, -1))
    for snap in (first, last):
        cell_width = (snap.block_hi[:, 0] - snap.block_lo[:, 0]) / 8
        assert np.allclose(cell_width, np.where(snap.block_level == 1, 1 / 128, 2 / 128), rtol=1e-14, atol=0.0)
        assert set(np.unique(snap.block_level)) == {0, 1}
