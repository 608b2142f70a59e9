"""The README's main command: the quickstart impact through all four stages, budgets closed."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from impactpipe.handoff import read_particles
from impactpipe.pipeline.cli import main

QUICKSTART = Path(__file__).parent.parent / "configs" / "quickstart.yaml"
STAGE_FILES = ("hydro.h5", "handoff.h5", "nbody.h5", "analysis.h5")


@pytest.fixture(scope="module")
def quickstart(tmp_path_factory):
    out = tmp_path_factory.mktemp("quickstart")
    result = CliRunner().invoke(main, ["run", str(QUICKSTART), "--out", str(out), "-q"])
    assert result.exit_code == 0, result.output
    return out, result.output


def test_all_stages_write_their_files(quickstart):
    out, output = quickstart
    for name in STAGE_FILES + ("summary.json", "config.resolved.yaml", "nbody.bin"):
        assert (out / name).is_file(), name
    assert (out / "plots" / "handoff_velocity.png").stat().st_size > 0
    assert f"outputs in {out}" in output


def test_summary_holds_the_published_quantities(quickstart):
    out, _ = quickstart
    summary = json.loads((out / "summary.json").read_text())
    for key in ("Q", "Q_R", "gamma", "M_lr_over_M_T", "M_slr_over_M_T", "N_init", "N_lr", "handoff_time",
                "hydro_budget", "handoff_budget", "nbody_budget", "versions", "target_kinetic_energy"):
        assert key in summary, key
    assert 0.0 < summary["target_kinetic_energy"] < summary["handoff_budget"]["mesh_kinetic_energy"]
    assert set(summary["stages"]) == {"hydro", "handoff", "nbody", "analysis"}
    assert all(s["wall_seconds"] > 0 for s in summary["stages"].values())
    assert summary["Q"] == pytest.approx(0.5 * 0.1 ** 3 * 250.0 ** 2)
    assert 0.0 < summary["M_lr_over_M_T"] <= (1.0 + summary["gamma"]) * (1 + 1e-3)
    assert 0 < summary["N_lr"] <= summary["N_init"]


def test_mass_budget_closes_through_every_stage(quickstart):
    out, _ = quickstart
    summary = json.loads((out / "summary.json").read_text())
    hydro, handoff, nbody = summary["hydro_budget"], summary["handoff_budget"], summary["nbody_budget"]
    assert abs(hydro["mass_error"]) < 1e-12
    assert abs(hydro["mass_unaccounted"]) < 1e-12 and abs(hydro["energy_unaccounted"]) < 1e-12
    mesh_end = hydro["mass_on_mesh"]
    assert handoff["mesh_mass"] == pytest.approx(mesh_end, rel=1e-12)
    assert handoff["particle_mass"] + handoff["dropped_mass"] == pytest.approx(handoff["mesh_mass"], rel=1e-12)
    assert nbody["mass_initial"] == pytest.approx(handoff["particle_mass"], rel=1e-12)
    assert abs(nbody["mass_error"]) < 1e-12


def test_handoff_at_a_coarser_particle_resolution_reuses_the_hydro_run(quickstart, tmp_path):
    """handoff.particle_resolution 2 (half the mesh's 4 cells per R_P): the same hydro run hands
    off from blocks twice as wide, with fewer, larger particles and the same mass and momentum."""
    out, _ = quickstart
    for name in ("hydro.h5", "config.resolved.yaml"):
        (tmp_path / name).write_bytes((out / name).read_bytes())
    records = json.loads((out / "stages.json").read_text())
    (tmp_path / "stages.json").write_text(json.dumps({"hydro": records["hydro"]}))
    config = tmp_path / "coarse.yaml"
    config.write_text(QUICKSTART.read_text().replace("seed: 1}", "seed: 1, particle_resolution: 2}"))
    result = CliRunner().invoke(main, ["run", str(config), "--out", str(tmp_path), "--stage", "handoff", "-q"])
    assert result.exit_code == 0, result.output
    assert "reused_from" not in json.loads((tmp_path / "stages.json").read_text())["hydro"]
    fine = json.loads((out / "summary.json").read_text())
    coarse = json.loads((tmp_path / "summary.json").read_text())
    assert coarse["stages"].keys() == {"handoff"}, "the hydro stage is not rerun"
    budget, fine_budget = coarse["handoff_budget"], fine["handoff_budget"]
    assert budget["block_edge"] == pytest.approx(4 * 100.0 / 2)
    assert budget["sphere_blocks"] < budget["n_blocks"] == fine_budget["n_blocks"]
    assert coarse["N_init"] < fine["N_init"]
    assert budget["mesh_mass"] == pytest.approx(fine_budget["mesh_mass"], rel=1e-13)  # summed in another order
    assert abs(budget["mass_residual"]) <= 1e-12 * budget["mesh_mass"]
    assert budget["unresolved_kinetic_energy"] > fine_budget["unresolved_kinetic_energy"]
    particles = read_particles(tmp_path / "handoff.h5")
    assert particles.radius.max() == pytest.approx(0.5 * 4 * 100.0 / 2)


def test_particle_resolution_that_is_no_block_level_is_refused(tmp_path):
    config = tmp_path / "bad.yaml"
    config.write_text(QUICKSTART.read_text().replace("seed: 1}", "seed: 1, particle_resolution: 3}"))
    result = CliRunner().invoke(main, ["run", str(config), "--out", str(tmp_path / "run")])
    assert result.exit_code == 2
    assert "handoff.particle_resolution: 3 is not the resolution of a block level" in result.output
    assert "use one of 4, 2, 1, 0.5" in result.output
    assert not (tmp_path / "run").exists()
    column = tmp_path / "column.yaml"
    column.write_text((QUICKSTART.parent / "column_collapse.yaml").read_text() + "handoff: {particle_resolution: 2}\n")
    result = CliRunner().invoke(main, ["validate", str(column)])
    assert result.exit_code == 2 and "handoff.particle_resolution: 2 applies to impact scenes only" in result.output


def test_particles_carry_the_projectile_fraction(quickstart):
    """The projectile's mass in the particles (sum m_i f_i) is the projectile's mass on the mesh."""
    out, _ = quickstart
    particles = read_particles(out / "handoff.h5")
    assert np.isfinite(particles.projectile_fraction).all()
    with h5py.File(out / "hydro.h5", "r") as f:
        projectile_mass = float(f["budget"].attrs["mass_initial"]) * 0.1 ** 3 / (1 + 0.1 ** 3)
    assert (particles.mass * particles.projectile_fraction).sum() == pytest.approx(projectile_mass, rel=0.05)


def test_outputs_carry_units_and_provenance(quickstart):
    out, _ = quickstart
    for name in STAGE_FILES:
        with h5py.File(out / name, "r") as f:
            for key in ("resolved_config", "versions", "git_commit", "host", "start_time", "end_time"):
                assert key in f.attrs, (name, key)
            missing = []
            f.visititems(lambda path, obj: missing.append(path)
                         if isinstance(obj, h5py.Dataset) and "units" not in obj.attrs else None)
            assert not missing, (name, missing[:5])


def test_rerun_skips_every_finished_stage(quickstart):
    out, _ = quickstart
    before = json.loads((out / "stages.json").read_text())
    result = CliRunner().invoke(main, ["run", str(QUICKSTART), "--out", str(out), "-q"])
    assert result.exit_code == 0, result.output
    assert json.loads((out / "stages.json").read_text()) == before


def test_plot_field_slice_and_tracer_ray(quickstart):
    out, _ = quickstart
    result = CliRunner().invoke(main, ["plot", str(out), "--field", "pressure", "--time", "0.5"])
    assert result.exit_code == 0, result.output
    png = Path(result.output.split("wrote ")[1].split(" (")[0])
    assert png.stat().st_size > 10_000
    result = CliRunner().invoke(main, ["plot", str(out), "--tracers"])
    assert result.exit_code == 0, result.output
    slope = float(result.output.split("r^")[1])
    assert -4.0 < slope < -0.5, "peak pressure must fall with distance from the impact point"
    result = CliRunner().invoke(main, ["plot", str(out), "--field", "pressur"])
    assert result.exit_code == 2 and "unknown field" in result.output


def test_the_nbody_stage_logs_a_handful_of_lines(quickstart):
    """Per-output diagnostics go to DEBUG; the progress reporter and the stage's summary lines
    are what run.log gets at INFO."""
    out, _ = quickstart
    lines = [line for line in (out / "run.log").read_text().splitlines() if "impactpipe.nbody" in line
             or "adapters.nbody" in line]
    assert 1 <= len(lines) <= 8, lines
