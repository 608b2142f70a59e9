"""The hydro stage shared between 2, 3 and 4 MPI ranks (oversubscribed) gives the single-process
answer bit for bit: every dataset of hydro.h5 (the snapshots), the hydro budget and the stage's
counters; a run checkpointed on 2 ranks resumes on 3; what this version does not share is a
clear error (docs/runs.md, "Several MPI ranks").

The runs go through the command line (``impactpipe run --ranks N``, which launches ``mpiexec``),
each a few steps on a mesh of a few blocks per rank.  The scenes place their snapshots
between steps, so the exchange of strips between ranks (not only the sharing of every block
before an output) carries the answer.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

pytest.importorskip("mpi4py")

from impactpipe.pipeline import cli, ranks  # noqa: E402

CONFIGS = Path(__file__).resolve().parent / "configs" / "mpi"
SCENES = {"advection": CONFIGS / "advection_2d.yaml", "impact": CONFIGS / "impact_uniform.yaml",
          "impact-strength": CONFIGS / "impact_strength.yaml"}
#: One numba thread per rank: the ranks already oversubscribe the test machine's cores.
ENV = {**os.environ, "NUMBA_NUM_THREADS": "1"}
#: Stops rank 0's hydro stage at the end of its 4th step, as a first SIGINT would (the run
#: writes its checkpoint and exits 130); the remaining arguments are the command line's.
STOP_AFTER_FOUR_STEPS = """
import sys
from impactpipe.pipeline import stages
from impactpipe.pipeline.cli import main
calls = [0]
def stop_requested(self):
    calls[0] += 1
    return "SIGINT" if calls[0] >= 4 else None
stages.StageContext.stop_requested = stop_requested
sys.argv = ["impactpipe", *sys.argv[1:]]
main()
"""

#: Three steps of the advection scene through the Python API, then a NaN in one cell's energy:
#: the next sweep fails (from the failing block's owner on several ranks); the last good state
#: is restored and checkpointed.  Writes the failure as each rank raised it to CHECKPOINT.rankR.json.
FAIL_IN_A_SWEEP = """
import json, sys
import numpy as np
from impactpipe.hydro.parallel.distributed import distribute
from impactpipe.hydro.solver import HydroFailure
from impactpipe.pipeline import derived, load_config, ranks
from impactpipe.pipeline.adapters.hydro import build_simulation
config = load_config(sys.argv[1])
sim = build_simulation(config, derived.derive(config))
comm = ranks.join_world()
if comm is not None:
    distribute(sim, comm)
for _ in range(3):
    sim.step()
sim.state.energy[6, 0, 3, 3, 0] = np.nan
try:
    sim.step()
except HydroFailure as exc:
    sim.restore_last_good()
    sim.save_checkpoint(sys.argv[2])
    rank = 0 if comm is None else comm.rank
    with open(f"{sys.argv[2]}.rank{rank}.json", "w") as out:
        out.write(json.dumps([str(exc), exc.block, exc.cell, exc.state]))
"""


def impactpipe_run(config: Path, out: Path, *options: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "impactpipe.pipeline.cli", "run", str(config), "--out", str(out),
                           "--stage", "hydro", "-q", *options], env=ENV, capture_output=True, text=True, timeout=300)


def hydro_answer(run_dir: Path) -> dict:
    """Every dataset of hydro.h5, its budget and counters, and the summary's hydro_budget."""
    out: dict = {}
    with h5py.File(run_dir / "hydro.h5", "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
        out.update({f"budget/{k}": v for k, v in f["budget"].attrs.items()})
        out.update({k: f.attrs[k] for k in ("cell_updates", "steps", "floor_counts")})
    out["summary/hydro_budget"] = json.dumps(json.loads((run_dir / "summary.json").read_text())["hydro_budget"])
    return out


def assert_same_answer(run_dir: Path, reference: Path) -> None:
    got, want = hydro_answer(run_dir), hydro_answer(reference)
    assert sorted(got) == sorted(want)
    for key, value in want.items():
        assert np.array_equal(np.asarray(got[key]), np.asarray(value)), key


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The single-process runs of the scenes: the answers every shared run must give."""
    out = {}
    for name, config in SCENES.items():
        out[name] = tmp_path_factory.mktemp(f"serial-{name}")
        result = impactpipe_run(config, out[name])
        assert result.returncode == 0, result.stderr
    return out


@pytest.mark.parametrize("nranks", [2, 3, 4])
@pytest.mark.parametrize("scene", sorted(SCENES))
def test_a_run_on_several_ranks_gives_the_single_process_answer_bit_for_bit(scene, nranks, serial, tmp_path):
    result = impactpipe_run(SCENES[scene], tmp_path, "--ranks", str(nranks))
    assert result.returncode == 0, result.stderr
    assert_same_answer(tmp_path, serial[scene])


def test_a_run_checkpointed_on_two_ranks_resumes_on_three_to_the_same_answer(serial, tmp_path):
    command = [ranks.mpiexec_path(), "-n", "2", sys.executable, "-c", STOP_AFTER_FOUR_STEPS, "run",
               str(SCENES["advection"]), "--out", str(tmp_path), "--stage", "hydro", "-q"]
    stopped = subprocess.run(command, env=ENV, capture_output=True, text=True, timeout=300)
    assert stopped.returncode == 130, stopped.stderr
    with h5py.File(tmp_path / "hydro.checkpoint.h5", "r") as f:
        assert f.attrs["step_count"] == 4
    resumed = impactpipe_run(SCENES["advection"], tmp_path, "--ranks", "3")
    assert resumed.returncode == 0, resumed.stderr
    assert "resuming from checkpoint at" in (tmp_path / "run.log").read_text()
    assert_same_answer(tmp_path, serial["advection"])


@pytest.mark.parametrize("nranks", [2, 3])
def test_a_sweep_failure_stops_every_rank_with_the_single_process_failure_and_checkpoint(nranks, tmp_path):
    serial = subprocess.run([sys.executable, "-c", FAIL_IN_A_SWEEP, str(SCENES["advection"]),
                             str(tmp_path / "serial.h5")], env=ENV, capture_output=True, text=True, timeout=300)
    shared = subprocess.run([ranks.mpiexec_path(), "-n", str(nranks), sys.executable, "-c", FAIL_IN_A_SWEEP,
                             str(SCENES["advection"]), str(tmp_path / "shared.h5")],
                            env=ENV, capture_output=True, text=True, timeout=300)
    assert serial.returncode == 0 and shared.returncode == 0, serial.stderr + shared.stderr
    failure = (tmp_path / "serial.h5.rank0.json").read_text()
    assert "NaN in the updated state" in failure
    for rank in range(nranks):
        assert (tmp_path / f"shared.h5.rank{rank}.json").read_text() == failure
    with h5py.File(tmp_path / "serial.h5", "r") as want, h5py.File(tmp_path / "shared.h5", "r") as got:
        assert want.attrs["step_count"] == got.attrs["step_count"] == 3
        for name in want["state"]:
            assert np.array_equal(got["state"][name][()], want["state"][name][()], equal_nan=True), name


def test_more_ranks_than_blocks_is_a_clear_error(tmp_path):
    config = yaml.safe_load(SCENES["advection"].read_text())
    config["scene"]["cells"] = 8  # two blocks of 4 cells
    path = tmp_path / "two_blocks.yaml"
    path.write_text(yaml.safe_dump(config))
    result = impactpipe_run(path, tmp_path / "run", "--ranks", "3")
    assert result.returncode == 2
    assert "more ranks (3) than blocks (2)" in result.stderr


def test_an_adaptive_mesh_and_tracers_are_refused_before_mpiexec_starts(tmp_path):
    config = yaml.safe_load(SCENES["impact"].read_text())
    config["hydro"].update(max_levels=2, tracers={"enabled": True})
    path = tmp_path / "unshared.yaml"
    path.write_text(yaml.safe_dump(config))
    result = impactpipe_run(path, tmp_path / "run", "--ranks", "2")
    assert result.returncode == 2
    for what in ("hydro.max_levels = 2", "hydro.tracers.enabled"):
        assert what in result.stderr
    assert not (tmp_path / "run").exists()


def test_external_gravity_is_refused_before_mpiexec_starts(tmp_path):
    """The column collapse's gravity named before anything is written."""
    config = Path(__file__).resolve().parents[1] / "configs" / "column_collapse.yaml"
    result = impactpipe_run(config, tmp_path / "run", "--ranks", "2")
    assert result.returncode == 2
    assert "external gravity (scene.gravity of the column_collapse problem)" in result.stderr
    assert not (tmp_path / "run").exists()


def test_ranks_without_mpi4py_name_the_extra_to_install(monkeypatch, tmp_path):
    from click.testing import CliRunner

    monkeypatch.setattr(ranks, "mpi_installed", lambda: False)
    result = CliRunner().invoke(cli.main, ["run", str(SCENES["advection"]), "--out", str(tmp_path), "--ranks", "2"])
    assert result.exit_code == 2
    assert 'pip install "impactpipe[mpi]"' in result.output
