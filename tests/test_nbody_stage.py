"""The N-body stage in the pipeline on synthetic hand-offs: cost counters in summary.json, the
time-step keys (stage hash, restart of the checkpointed run), and hand-offs that leave no remnant
(every particle escapes, a single particle, no particle) carried through the analysis stage."""

from dataclasses import fields

import h5py
import numpy as np
from scipy.constants import G
import pytest
from test_nbody import cold_cloud, drop_sidecar_meta, sphere_radius

from impactpipe.handoff.particles import PARTICLE_UNITS, ParticleSet
from impactpipe.nbody import read_result
from impactpipe.pipeline import derived, stages
from impactpipe.pipeline.config import parse_config
from impactpipe.pipeline.convergence import costs_of
from impactpipe.storage import atomic_path, write_dataset

CONFIG = """
name: nbody-stage
scene:
  problem: impact
  target: {material: basalt, radius: 1.0e3}
  projectile: {material: basalt, radius: 1.0e2}
  impact: {velocity: 1.0e3}
materials:
  basalt: {eos: {model: tillotson, preset: basalt}}
nbody:
  collision_model: merge
  stop: {min_dynamical_times: 2}
analysis: {plots: false}
"""

#: The particle set the stand-in hand-off stage writes (set by each test).
HANDOFF: dict[str, ParticleSet] = {}
STAND_INS = {"hydro": "test_nbody_stage:hydro", "handoff": "test_nbody_stage:handoff"}


def hydro(ctx):
    with atomic_path(ctx.path("hydro")) as tmp:
        tmp.write_text("hydro stand-in")
    return {}


def handoff(ctx):
    """handoff.h5 with the particle table only (all the N-body and analysis stages read of it)."""
    with atomic_path(ctx.path("handoff")) as tmp:
        with h5py.File(tmp, "w") as h5:
            group = h5.create_group("particles")
            for f in fields(ParticleSet):
                write_dataset(group, f.name, getattr(HANDOFF["particles"], f.name), PARTICLE_UNITS[f.name])
    return {}


def config(**overrides):
    return parse_config(CONFIG, source="nbody-stage.yaml", overrides=overrides)


def run(tmp_path, particles, **overrides):
    HANDOFF["particles"] = particles
    return stages.run(config(**overrides), tmp_path, show_progress=False, stage_functions=STAND_INS)


def test_counters_reach_the_summary_and_time_step_keys_rerun_the_stage(tmp_path):
    summary = run(tmp_path, cold_cloud(40, seed=4))
    nbody = summary["stages"]["nbody"]
    result = read_result(tmp_path / "nbody.h5")
    assert summary["nbody_status"] == "equilibrium" and result.merge_time.size > 0
    assert (nbody["steps"], nbody["particle_steps"]) == (result.steps, result.particle_steps)
    assert len(result) * result.steps < result.particle_steps < 40 * result.steps
    costs = costs_of(stages.read_summary(tmp_path))  # what `impactpipe convergence` reads
    assert (costs["nbody_steps"], costs["particle_steps"]) == (result.steps, result.particle_steps)
    # each time-step key changes the N-body hash (and the analysis hash after it), nothing upstream
    base = stages.stage_hashes(config())
    for key, value in (("nbody.steps_per_dynamical_time", 200.0), ("nbody.collision_step_fraction", 0.25)):
        changed = stages.stage_hashes(config(**{key: value}))
        assert [changed[s] == base[s] for s in stages.STAGES] == [True, True, False, False], key
    # a cap alone resumes the finished checkpoint (no stepping); one written before the particle-step
    # counter existed leaves that count out of the summary, which the convergence table shows blank
    sidecar = tmp_path / "nbody.bin.state.npz"
    drop_sidecar_meta(sidecar, "particle_steps")
    summary = run(tmp_path, cold_cloud(40, seed=4), **{"nbody.stop.max_wall_seconds": 1000.0})
    assert summary["stages"]["nbody"]["steps"] == result.steps and "particle_steps" not in summary["stages"]["nbody"]
    assert np.isnan(costs_of(summary)["particle_steps"])
    # here the orbit term t_dyn / n sets the step: twice the steps per t_dyn, about twice the steps;
    # the checkpoint of the first run (other parameters) is replaced, not resumed
    summary = run(tmp_path, cold_cloud(40, seed=4), **{"nbody.steps_per_dynamical_time": 200.0})
    rerun = read_result(tmp_path / "nbody.h5")
    assert summary["stages"]["nbody"]["steps"] == rerun.steps
    assert rerun.time_step == pytest.approx(result.time_step / 2, rel=1e-12)
    assert 1.6 * result.steps < rerun.steps < 2.4 * result.steps


def _receding_pair():
    m = np.array([1e9, 1e9])
    r = sphere_radius(m)
    return ParticleSet.from_bodies(m, r, [[-3 * r[0], 0.0, 0.0], [3 * r[0], 0.0, 0.0]],
                                   [[-30.0, 0.0, 0.0], [30.0, 0.0, 0.0]])


@pytest.mark.parametrize("case", ["all_escape", "single", "empty"])
def test_handoffs_without_a_remnant_run_through_the_analysis(tmp_path, case):
    particles = {
        "all_escape": _receding_pair(),
        "single": ParticleSet.from_bodies([1e12], sphere_radius([1e12]), [[0.0, 0.0, 0.0]], [[1.0, 0.0, 0.0]]),
        "empty": ParticleSet.from_bodies(np.zeros(0), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))),
    }[case]
    summary = run(tmp_path, particles)
    budget = summary["nbody_budget"]
    assert (tmp_path / "analysis.h5").is_file()
    assert budget["mass_final"] + budget["mass_escaped"] == budget["mass_initial"] == particles.mass.sum()
    if case == "single":
        m_t = derived.derive(config())["target_mass"]
        assert summary["nbody_status"] == "equilibrium"
        assert summary["M_lr_over_M_T"] == pytest.approx(1e12 / m_t, rel=1e-12) and summary["N_lr"] == 1
        return
    assert summary["nbody_status"] == "no_particles_left"
    assert summary["M_lr_over_M_T"] == 0.0 and summary["M_slr_over_M_T"] == 0.0
    assert summary["N_lr"] == 0 and "largest_remnant" not in summary
    assert summary["stages"]["nbody"]["particles_final"] == 0
    assert summary["stages"]["nbody"]["particles_escaped"] == len(particles)


def test_box_factor_decides_whether_a_bound_satellite_is_removed_as_left_box(tmp_path, caplog):
    """A satellite launched radially at 0.9 of its escape speed from 5 central radii rises to 5.3
    times that distance: nbody.box_factor 1.2 removes it as left_box (reported and warned
    about), 20 keeps it bound."""
    m = np.array([1e12, 1e10])
    r = sphere_radius(m)
    d = 5.0 * r[0]
    v = 0.9 * np.sqrt(2.0 * G * m[0] / d)
    particles = ParticleSet.from_bodies(m, r, [[0.0, 0.0, 0.0], [d, 0.0, 0.0]], [[0.0, 0.0, 0.0], [v, 0.0, 0.0]])
    small = run(tmp_path / "small", particles, **{"nbody.box_factor": 1.2})
    assert small["nbody_budget"]["mass_left_box"] == pytest.approx(m[1], rel=1e-12)
    assert small["nbody_budget"]["mass_escaped"] == pytest.approx(m[1], rel=1e-12)
    assert small["nbody_budget"]["mass_lost"] == 0.0
    assert "raise nbody.box_factor" in caplog.text
    large = run(tmp_path / "large", particles, **{"nbody.box_factor": 20.0})
    assert large["nbody_budget"]["mass_left_box"] == 0.0 and large["nbody_budget"]["mass_escaped"] == 0.0
    assert stages.stage_hashes(config(**{"nbody.box_factor": 20.0}))["handoff"] == stages.stage_hashes(config())["handoff"]


def test_nbody_time_cap_is_the_smaller_of_the_two_caps_and_validate_shows_it():
    config = parse_config(CONFIG, source="n.yaml")
    values = derived.derive(config)
    t_dyn = values["nbody_dynamical_time"]
    assert t_dyn == pytest.approx(1.0 / np.sqrt(G * values["target_reference_density"]), rel=1e-3)
    assert values["nbody_time_cap"] == pytest.approx(2000.0 * t_dyn, rel=1e-12)
    assert "max_dynamical_times" in values["nbody_time_cap_rule"]
    capped = derived.derive(parse_config(CONFIG, source="n.yaml", overrides={"nbody.stop.max_time": 100.0}))
    assert capped["nbody_time_cap"] == 100.0 and "max_time" in capped["nbody_time_cap_rule"]
    short = derived.derive(parse_config(CONFIG, source="n.yaml",
                                        overrides={"nbody.stop.max_dynamical_times": 10.0}))
    assert short["nbody_time_cap"] == pytest.approx(10.0 * t_dyn, rel=1e-12)
