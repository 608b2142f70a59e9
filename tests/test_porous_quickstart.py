"""configs/porous_quickstart.yaml (the quickstart impact into a porous basalt target, alpha0 = 1.5)
and configs/porous_strength_quickstart.yaml (the same with GEO weak strength and chi = 0.5 on the
porous target) through all four stages: budgets closed, the target compacted where the
projectile hit it and nowhere beyond alpha0, the hand-off's density floor taken from the porous
bulk density, and with strength a deviatoric stress in the target."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from impactpipe.pipeline.cli import main

CONFIGS = Path(__file__).parent.parent / "configs"
CONFIG = CONFIGS / "porous_quickstart.yaml"


def run_config(tmp_path_factory, config: Path) -> Path:
    """The run directory of ``impactpipe run config``."""
    out = tmp_path_factory.mktemp(config.stem)
    result = CliRunner().invoke(main, ["run", str(config), "--out", str(out), "-q"])
    assert result.exit_code == 0, result.output
    return out


@pytest.fixture(scope="module")
def porous_run(tmp_path_factory):
    return run_config(tmp_path_factory, CONFIG)


@pytest.fixture(scope="module")
def porous_strength_run(tmp_path_factory):
    return run_config(tmp_path_factory, CONFIGS / "porous_strength_quickstart.yaml")


@pytest.mark.parametrize("run", ["porous_run", "porous_strength_run"])
def test_every_stage_runs_and_the_budgets_close(run, request):
    summary = json.loads((request.getfixturevalue(run) / "summary.json").read_text())
    assert set(summary["stages"]) == {"hydro", "handoff", "nbody", "analysis"}
    hydro, handoff, nbody = summary["hydro_budget"], summary["handoff_budget"], summary["nbody_budget"]
    assert abs(hydro["mass_error"]) < 1e-12
    assert abs(hydro["mass_unaccounted"]) < 1e-12 and abs(hydro["energy_unaccounted"]) < 1e-12
    assert handoff["particle_mass"] + handoff["dropped_mass"] == pytest.approx(handoff["mesh_mass"], rel=1e-12)
    assert abs(nbody["mass_error"]) < 1e-12
    # the hand-off's floor is 0.75 of the porous target's bulk density 2700 / 1.5
    assert handoff["density_floor"] == pytest.approx(0.75 * 2700.0 / 1.5)


def test_target_compacted_under_the_impact_only(porous_run):
    with h5py.File(porous_run / "hydro.h5", "r") as fh:
        last = sorted(fh["snapshots"])[-1]
        snap = fh["snapshots"][last]
        distension = snap["extra/distension"][()]
        arho = snap["partial_density"][()]
    target = arho[:, 0] > 0.0
    values = distension[target]
    assert values.min() >= 1.0 and values.max() <= 1.5 * (1 + 1e-12)
    compacted = values < 1.5 * (1 - 1e-6)
    # the shock of a 250 m/s impact crushes part of the target, not all of it
    assert 0.0 < compacted.mean() < 1.0


def test_validate_prints_the_porosity_choice_and_why():
    from impactpipe.pipeline.config import load_config
    from impactpipe.pipeline.derived import derive

    porous = derive(load_config(CONFIG))
    assert porous["porosity"] is True
    assert porous["porosity_rule"].startswith("on: porous_basalt alpha0 = 1.5 > 1")
    assert porous["target_reference_density"] == pytest.approx(2700.0 / 1.5)
    solid = derive(load_config(CONFIG.parent / "quickstart.yaml"))
    assert solid["porosity"] is False and solid["porosity_rule"].startswith("off:")
    assert solid["target_reference_density"] == pytest.approx(2700.0)
    result = CliRunner().invoke(main, ["validate", str(CONFIG)])
    assert result.exit_code == 0 and "porosity_rule: 'on: porous_basalt alpha0 = 1.5" in result.output


def test_handoff_spheres_carry_the_distension_of_their_material(porous_run):
    """Each sphere's distension is its block's mass-weighted one, 1 + E / m with E = sum_c m_por,c (d_c - 1)
    (handoff/moments.py): between 1 and alpha0, exactly 1 for spheres of projectile (solid) material alone,
    and sum_p m_p (alpha_p - 1) is the snapshot's E up to what the mass floor dropped (at most
    (alpha0 - 1) of the dropped mass)."""
    from impactpipe.handoff import read_particles
    from impactpipe.handoff.store import read_budget
    from impactpipe.hydro.output.io import read_snapshot

    particles = read_particles(porous_run / "handoff.h5")
    budget = read_budget(porous_run / "handoff.h5")
    alpha = particles.distension
    assert np.isfinite(alpha).all() and alpha.min() >= 1.0 and alpha.max() <= 1.5 * (1 + 1e-12)
    solid = particles.projectile_fraction == 1.0
    assert solid.any() and (alpha[solid] == 1.0).all()
    assert (alpha[particles.projectile_fraction == 0.0] > 1.0).any()
    with h5py.File(porous_run / "handoff.h5", "r") as fh:
        handoff_time = float(fh.attrs["handoff_time"])
    with h5py.File(porous_run / "hydro.h5", "r") as fh:
        times = [float(fh["snapshots"][name].attrs["time"]) for name in sorted(fh["snapshots"])]
    snap = read_snapshot(porous_run / "hydro.h5", index=times.index(handoff_time))
    volume = snap.block_cell_volumes()
    porous_mass = snap.partial_density[:, 0] * volume
    excess = float(np.where(porous_mass > 0.0, porous_mass * (snap.extra["distension"] - 1.0), 0.0).sum())
    carried = float((particles.mass * (alpha - 1.0)).sum())
    assert abs(carried - excess) <= 0.5 * budget.dropped_mass + 1e-9 * excess


def test_the_porous_target_with_strength_compacts_and_carries_stress(porous_strength_run):
    with h5py.File(porous_strength_run / "hydro.h5", "r") as fh:
        snap = fh["snapshots"][sorted(fh["snapshots"])[-1]]
        distension = snap["extra/distension"][()]
        von_mises = snap["extra/von_mises_stress"][()]
        arho = snap["partial_density"][()]
    target = arho[:, 0] > 0.0
    values = distension[target]
    assert values.min() >= 1.0 and values.max() <= 1.5 * (1 + 1e-12)
    compacted = values < 1.5 * (1 - 1e-3)
    assert 0.0 < compacted.mean() < 1.0
    assert von_mises[target].max() > 0.0
