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
                "hydro_budget", "handoff_budget", "nbody_budget", "versions"):
        assert key in summary, key
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
    mesh_end = hydro["mass_on_mesh"]
    assert handoff["mesh_mass"] == pytest.approx(mesh_end, rel=1e-12)
    assert handoff["particle_mass"] + handoff["dropped_mass"] == pytest.approx(handoff["mesh_mass"], rel=1e-12)
    assert nbody["mass_initial"] == pytest.approx(handoff["particle_mass"], rel=1e-12)
    assert abs(nbody["mass_error"]) < 1e-12


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
