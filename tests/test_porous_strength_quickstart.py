"""configs/porous_strength_quickstart.yaml (the porous quickstart with GEO weak strength and chi = 0.5 on
the porous target) through all four stages: budgets closed, the target compacted where the projectile hit
it and nowhere beyond alpha0, its strength at work (yield returns, a deviatoric stress in the target)."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from impactpipe.pipeline.cli import main

CONFIG = Path(__file__).parent.parent / "configs" / "porous_strength_quickstart.yaml"


@pytest.fixture(scope="module")
def porous_strength_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("porous_strength_quickstart")
    result = CliRunner().invoke(main, ["run", str(CONFIG), "--out", str(out), "-q"])
    assert result.exit_code == 0, result.output
    return out


def test_every_stage_runs_and_the_budgets_close(porous_strength_run):
    summary = json.loads((porous_strength_run / "summary.json").read_text())
    assert set(summary["stages"]) == {"hydro", "handoff", "nbody", "analysis"}
    hydro, handoff, nbody = summary["hydro_budget"], summary["handoff_budget"], summary["nbody_budget"]
    assert abs(hydro["mass_error"]) < 1e-12
    assert abs(hydro["mass_unaccounted"]) < 1e-12 and abs(hydro["energy_unaccounted"]) < 1e-12
    assert handoff["particle_mass"] + handoff["dropped_mass"] == pytest.approx(handoff["mesh_mass"], rel=1e-12)
    assert abs(nbody["mass_error"]) < 1e-12
    assert handoff["density_floor"] == pytest.approx(0.75 * 2700.0 / 1.5)


def test_the_porous_target_compacts_and_carries_stress(porous_strength_run):
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
