"""The hydro stage shared between 2, 3 and 4 MPI ranks (oversubscribed) gives the single-process
answer bit for bit, on uniform and adaptive meshes, in r-z and in 3d, with and without
strength and tracers, with external gravity (the column collapse), with a porous target with
strength and self-gravity, and a Sedov blast whose ranks refine its initial mesh together:
every dataset of hydro.h5 (the snapshots, the tracers and their history),
the hydro budget, the stage's counters and the summary's tracer counts; tracers handed to
another rank with their material keep their records; a run checkpointed on 2 ranks resumes on 3 or on
one; what this version does not share is a clear error (docs/runs.md, "Several MPI ranks").

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
          "impact-strength": CONFIGS / "impact_strength.yaml", "impact_tracers": CONFIGS / "impact_tracers.yaml",
          "impact_adaptive": CONFIGS / "impact_adaptive.yaml", "impact_3d": CONFIGS / "impact_3d.yaml",
          "impact_3d_uniform": CONFIGS / "impact_3d_uniform.yaml",
          "column_collapse": CONFIGS / "column_collapse.yaml", "sedov_adaptive": CONFIGS / "sedov_adaptive.yaml",
          "advection_adaptive": CONFIGS / "advection_adaptive.yaml"}
#: One numba thread per rank: the ranks already oversubscribe the test machine's cores.
ENV = {**os.environ, "NUMBA_NUM_THREADS": "1"}
#: Seconds a run may take: the first one in a fresh environment compiles every kernel it calls
#: (271 s of the module fixture on an idle 2-core machine), so 300 s left no margin under load.
SUBPROCESS_TIMEOUT_S = 900
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

#: The advection scene through the Python API (argument 1: its config) with 120 tracers on a
#: lattice over the periodic box, shared between the ranks when run under mpiexec.
ADVECTION_WITH_TRACERS = """
import json, sys
import numpy as np
from impactpipe.hydro.parallel.distributed import collect, distribute
from impactpipe.hydro.solver import HydroFailure
from impactpipe.hydro.tracers.motion import TRACER_UNITS, Tracers
from impactpipe.pipeline import derived, load_config, ranks
from impactpipe.pipeline.adapters.hydro import build_simulation
config = load_config(sys.argv[1])
sim = build_simulation(config, derived.derive(config))
lo, hi = sim.mesh.domain_lo, sim.mesh.domain_hi
x, y = np.meshgrid(lo[0] + (hi[0] - lo[0]) * (np.arange(40) + 0.3) / 40,
                   lo[1] + (hi[1] - lo[1]) * (np.arange(3) + 0.5) / 3, indexing="ij")
sim.tracers = Tracers(np.column_stack([x.ravel(), y.ravel()]), np.zeros(x.size, dtype=int), history_interval=0.02)
comm = ranks.join_world()
if comm is not None:
    distribute(sim, comm)
"""

#: Three steps of the advection scene with tracers, then a NaN in one cell's energy: the next
#: sweep fails (from the failing block's owner on several ranks); the last good state is
#: restored and checkpointed (argument 2).  Writes the failure as each rank raised it to
#: CHECKPOINT.rankR.json.
FAIL_IN_A_SWEEP = ADVECTION_WITH_TRACERS + """
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

#: 24 steps of the advection scene with tracers (the wave moves 4 cells, one block, so many
#: tracers move into another rank's blocks), then the tracers' records and history to the
#: file of argument 2 (.npz), with how many tracers the ranks handed to another rank and how
#: many a rank held, after a step, outside its own blocks.
TRACERS_ACROSS_RANKS = ADVECTION_WITH_TRACERS + """
held_elsewhere = 0
for _ in range(24):
    sim.step()
    owner = np.empty(len(sim.tracers), dtype=np.int64)
    sim.partition.block_owners(sim.tracers.owning_block, owner)
    held_elsewhere += int(np.count_nonzero((owner != sim.partition.rank) & ~sim.tracers.exited))
handed_over = sim.partition.traffic.items_handed_over
if comm is not None:
    handed_over, held_elsewhere = comm.allreduce(handed_over), comm.allreduce(held_elsewhere)
    collect(sim)
if comm is None or comm.rank == 0:
    times, positions = sim.tracers.history
    np.savez(sys.argv[2], handed_over=handed_over, held_elsewhere=held_elsewhere, history_time=times,
             history_position=positions, **{name: getattr(sim.tracers, name) for name in TRACER_UNITS})
"""


#: Two steps of a 16 x 8 cell box of one ideal gas in 4 x 2 blocks of 4^2 (outflow faces), the
#: traffic counters reset after the first; writes each rank's counters and the bytes its routes
#: imply per step to OUT.rankR.json.
COUNT_TRAFFIC = """
import json, sys
import numpy as np
from mpi4py import MPI
from impactpipe.hydro import BlockMesh, HydroState, Simulation
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.parallel.distributed import distribute
gas = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}
mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [2.0, 1.0], [16, 8], [("outflow", "outflow")] * 2, 4)
state = HydroState.empty(mesh, 1)
state.set_material(mesh, 1.0, 0, pack_eos([gas]), 1.0, np.zeros(3), pressure=1.0)
sim = Simulation(mesh, ["gas"], [gas], state)
comm = MPI.COMM_WORLD
distribute(sim, comm)
sim.step()
sim.partition.traffic.reset()
sim.step()
fields = sim.state.arrays().values()
implied = sum(8 * route.send.values(field) for routes in sim.partition.routes for route in routes for field in fields)
with open(f"{sys.argv[1]}.rank{comm.rank}.json", "w") as out:
    out.write(json.dumps({"traffic": sim.partition.traffic.as_dict(), "routes_bytes": implied}))
"""


#: ``impactpipe run ... --ranks 2`` whose ranks run the command line with rank 1 killed
#: (SIGKILL, as the kernel's out-of-memory killer or a lost node would) at the start of its 8th
#: step; the remaining arguments are the command line's.
KILL_RANK_ONE = """
import sys
from impactpipe.pipeline import cli, ranks
HOOK = '''
import os, signal, sys
from impactpipe.hydro.solver import Simulation
from impactpipe.pipeline.cli import main
step = Simulation.step
def dying_step(self, *args, **kwargs):
    if self.partition.rank == 1 and self.step_count == 7:
        os.kill(os.getpid(), signal.SIGKILL)
    return step(self, *args, **kwargs)
Simulation.step = dying_step
sys.argv = ["impactpipe", *sys.argv[1:]]
main()
'''
ranks.launch_command = lambda n, arguments: [ranks.mpiexec_path(), "-n", str(n), sys.executable, "-c", HOOK,
                                             *arguments]
sys.argv = ["impactpipe", *sys.argv[1:]]
cli.main()
"""


#: The column collapse of tests/test_column_collapse.py whose mesh grows along x (scene.room 0.01,
#: 8 cells per height, to 3 tau), shared between the ranks when run under mpiexec; writes the
#: state's interior cells, the counters and the clock to the file of argument 1 (.npz).
GROWING_COLUMN = """
import sys
import numpy as np
sys.path.insert(0, sys.argv[2])
from test_column_collapse import HEIGHT, TAU, granular
from impactpipe.hydro.parallel.distributed import collect, distribute
from impactpipe.hydro.problems import column_collapse
from impactpipe.pipeline import ranks
sim = column_collapse.setup({"material": "sand", "height": HEIGHT, "width": HEIGHT, "cells_per_height": 8,
                             "room": 0.01}, {"sand": granular(cohesion=0.0)}, block_cells=4, cfl=0.4)
comm = ranks.join_world()
if comm is not None:
    distribute(sim, comm)
sim.run(3.0 * TAU)
if comm is not None:
    collect(sim)
if comm is None or comm.rank == 0:
    np.savez(sys.argv[1], growths=sim.growths, clock=np.array([sim.time, sim.step_count]), boundary=sim.boundary,
             floors=sim.floors, amounts=sim.amounts, block_lo=sim.mesh.block_lo,
             **{name: sim.mesh.interior(array) for name, array in sim.state.arrays().items()})
"""


def impactpipe_run(config: Path, out: Path, *options: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "impactpipe.pipeline.cli", "run", str(config), "--out", str(out),
                           "--stage", "hydro", "-q", *options], env=ENV, capture_output=True, text=True, timeout=SUBPROCESS_TIMEOUT_S)


def run_serial_and_shared(script: str, nranks: int, serial_out: Path, shared_out: Path) -> None:
    """``script`` on the advection scene as one process (writing ``serial_out``) and on ``nranks``
    ranks (``shared_out``); both must exit 0."""
    serial = subprocess.run([sys.executable, "-c", script, str(SCENES["advection"]), str(serial_out)],
                            env=ENV, capture_output=True, text=True, timeout=SUBPROCESS_TIMEOUT_S)
    shared = subprocess.run([ranks.mpiexec_path(), "-n", str(nranks), sys.executable, "-c", script,
                             str(SCENES["advection"]), str(shared_out)], env=ENV, capture_output=True, text=True,
                            timeout=SUBPROCESS_TIMEOUT_S)
    assert serial.returncode == 0 and shared.returncode == 0, serial.stderr + shared.stderr


def hydro_answer(run_dir: Path) -> dict:
    """Every dataset of hydro.h5, its budget and counters, and the summary's hydro_budget."""
    out: dict = {}
    with h5py.File(run_dir / "hydro.h5", "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
        out.update({f"budget/{k}": v for k, v in f["budget"].attrs.items()})
        out.update({k: f.attrs[k] for k in ("cell_updates", "steps", "floor_counts")})
    summary = json.loads((run_dir / "summary.json").read_text())
    out["summary/hydro_budget"] = json.dumps(summary["hydro_budget"])
    out["summary/tracers"] = json.dumps(summary["tracers"])
    return out


def assert_same_answer(run_dir: Path, reference: Path) -> None:
    """Every value bit for bit (NaN records included)."""
    got, want = hydro_answer(run_dir), hydro_answer(reference)
    assert sorted(got) == sorted(want)
    for key, value in want.items():
        got_value, value = np.asarray(got[key]), np.asarray(value)
        assert (got_value.dtype, got_value.shape) == (value.dtype, value.shape), key
        assert got_value.tobytes() == value.tobytes(), key


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


def test_the_tracer_scene_samples_tracers_and_records_their_peaks(serial):
    """The tracers that the shared runs must reproduce moved, recorded peaks and a history."""
    answer = hydro_answer(serial["impact_tracers"])
    assert answer["tracers/position"].shape == (len(answer["tracers/id"]), 3)
    assert not np.array_equal(answer["tracers/position"], answer["tracers/initial_position"])
    assert np.isfinite(answer["tracers/peak_pressure"]).all()
    assert len(answer["tracers/history_time"]) >= 5


def test_the_face_shear_stress_on_three_ranks_gives_the_single_process_answer_bit_for_bit(tmp_path):
    """The column collapse with the face shear stress instead of the hourglass viscosity: each block
    computes the face stresses of its own faces from its work arrays' ghosts, which travel between
    ranks, so three ranks give the single-process answer bit for bit."""
    config = yaml.safe_load(SCENES["column_collapse"].read_text())
    config["scene"].update(hourglass=0, face_shear=True)
    path = tmp_path / "face_shear.yaml"
    path.write_text(yaml.safe_dump(config))
    result = impactpipe_run(path, tmp_path / "serial")
    assert result.returncode == 0, result.stderr
    result = impactpipe_run(path, tmp_path / "shared", "--ranks", "3")
    assert result.returncode == 0, result.stderr
    assert_same_answer(tmp_path / "shared", tmp_path / "serial")


def test_a_porous_run_with_strength_on_two_ranks_gives_the_single_process_answer_bit_for_bit(tmp_path):
    """A porous target with strength, chi and self-gravity (the distension transported, compacted and exchanged
    with the strength scalars between ranks; the lithostatic start and the potential's moments summed over the
    ranks): the hydro stage on two ranks gives the single-process answer bit for bit."""
    config = CONFIGS / "impact_porous.yaml"
    result = impactpipe_run(config, tmp_path / "serial")
    assert result.returncode == 0, result.stderr
    result = impactpipe_run(config, tmp_path / "shared", "--ranks", "2")
    assert result.returncode == 0, result.stderr
    assert_same_answer(tmp_path / "shared", tmp_path / "serial")
    with h5py.File(tmp_path / "serial" / "hydro.h5", "r") as fh:
        snap = fh["snapshots"][sorted(fh["snapshots"])[-1]]
        distension = snap["extra/distension"][()][snap["partial_density"][()][:, 0] > 0.0]
    assert distension.min() < 1.5 * (1 - 1e-3)   # the impact has compacted part of the target


@pytest.mark.parametrize("nranks", [2, 3])
def test_tracers_handed_between_ranks_with_their_material_keep_the_single_process_records(nranks, tmp_path):
    run_serial_and_shared(TRACERS_ACROSS_RANKS, nranks, tmp_path / "serial.npz", tmp_path / "shared.npz")
    want, got = np.load(tmp_path / "serial.npz"), np.load(tmp_path / "shared.npz")
    assert got["handed_over"] > 10
    assert got["held_elsewhere"] == want["handed_over"] == 0
    assert len(want["history_time"]) >= 3
    for name in want.files:
        if name not in ("handed_over", "held_elsewhere"):
            assert (got[name].dtype, got[name].shape) == (want[name].dtype, want[name].shape), name
            assert got[name].tobytes() == want[name].tobytes(), name


@pytest.mark.parametrize(("scene", "resume_ranks"), [("advection", 3), ("impact_tracers", 1), ("impact_adaptive", 3)])
def test_a_run_checkpointed_on_two_ranks_resumes_on_another_number_to_the_same_answer(scene, resume_ranks, serial,
                                                                                       tmp_path):
    command = [ranks.mpiexec_path(), "-n", "2", sys.executable, "-c", STOP_AFTER_FOUR_STEPS, "run",
               str(SCENES[scene]), "--out", str(tmp_path), "--stage", "hydro", "-q"]
    stopped = subprocess.run(command, env=ENV, capture_output=True, text=True, timeout=SUBPROCESS_TIMEOUT_S)
    assert stopped.returncode == 130, stopped.stderr
    with h5py.File(tmp_path / "hydro.checkpoint.h5", "r") as f:
        assert f.attrs["step_count"] == 4
    resumed = impactpipe_run(SCENES[scene], tmp_path, "--ranks", str(resume_ranks))
    assert resumed.returncode == 0, resumed.stderr
    assert "resuming from checkpoint at" in (tmp_path / "run.log").read_text()
    assert_same_answer(tmp_path, serial[scene])


@pytest.mark.parametrize("nranks", [2, 3])
def test_a_sweep_failure_stops_every_rank_with_the_single_process_failure_and_checkpoint(nranks, tmp_path):
    """The failure, and the last good state and tracers that every rank restores."""
    run_serial_and_shared(FAIL_IN_A_SWEEP, nranks, tmp_path / "serial.h5", tmp_path / "shared.h5")
    failure = (tmp_path / "serial.h5.rank0.json").read_text()
    assert "NaN in the updated state" in failure
    for rank in range(nranks):
        assert (tmp_path / f"shared.h5.rank{rank}.json").read_text() == failure
    with h5py.File(tmp_path / "serial.h5", "r") as want, h5py.File(tmp_path / "shared.h5", "r") as got:
        assert want.attrs["step_count"] == got.attrs["step_count"] == 3
        for name in want["state"]:
            assert np.array_equal(got["state"][name][()], want["state"][name][()], equal_nan=True), name
        for name in want["tracers"]:
            assert got["tracers"][name][()].tobytes() == want["tracers"][name][()].tobytes(), name


def test_the_traffic_counters_count_the_bytes_and_messages_of_one_step(tmp_path):
    """On 4 x 2 blocks in Morton order each rank owns a square of 2 x 2 blocks: one message per
    step (the fill along x), carrying the GHOST = 2 columns of 4 cells next to each of its 2
    blocks' shared faces, 7 float64 fields (alpha, arho, arhoe, momentum x 3, energy):
    2 x 2 x 4 x 7 x 8 = 896 B (a row of 4 blocks each, as the x-fastest order cut it, shares 4
    faces: twice that); three allreduces (the time step and the failure check of each sweep)."""
    result = subprocess.run([ranks.mpiexec_path(), "-n", "2", sys.executable, "-c", COUNT_TRAFFIC,
                             str(tmp_path / "traffic")], env=ENV, capture_output=True, text=True, timeout=SUBPROCESS_TIMEOUT_S)
    assert result.returncode == 0, result.stderr
    for rank in range(2):
        counted = json.loads((tmp_path / f"traffic.rank{rank}.json").read_text())
        traffic = counted["traffic"]
        assert traffic["bytes_sent"] == traffic["bytes_received"] == counted["routes_bytes"] == 2 * 2 * 4 * 7 * 8
        assert traffic["messages_sent"] == traffic["messages_received"] == 1
        assert traffic["exchanges"] == 2
        assert traffic["allreduces"] == 3
        assert traffic["gathers"] == 0
        assert 0.0 <= traffic["wait_seconds"] <= traffic["exchange_seconds"]


def test_a_killed_rank_stops_every_rank_with_a_clear_message_and_the_same_command_resumes(serial, tmp_path):
    """Checkpoints every step; rank 1 dies (SIGKILL) in the 8th: mpiexec ends rank 0, the
    launcher names what happened, a whole checkpoint of step 6 or 7 is left (rank 0 may be
    ended while it writes the step-7 file, which the atomic write then discards), and the same
    command resumes it to the single-process answer."""
    config = yaml.safe_load(SCENES["impact_adaptive"].read_text())
    config["hydro"]["checkpoint_wall_seconds"] = 1e-9
    path = tmp_path / "every_step.yaml"
    path.write_text(yaml.safe_dump(config))
    run_dir = tmp_path / "run"
    killed = subprocess.run([sys.executable, "-c", KILL_RANK_ONE, "run", str(path), "--out", str(run_dir),
                             "--stage", "hydro", "-q", "--ranks", "2"], env=ENV, capture_output=True, text=True,
                            timeout=SUBPROCESS_TIMEOUT_S)
    assert killed.returncode not in ranks.PIPELINE_STATUSES
    assert "an MPI rank ended abnormally" in killed.stderr and "run the same command again" in killed.stderr
    with h5py.File(run_dir / "hydro.checkpoint.h5", "r") as f:
        assert f.attrs["step_count"] in (6, 7)
    resumed = impactpipe_run(path, run_dir, "--ranks", "2")
    assert resumed.returncode == 0, resumed.stderr
    assert "resuming from checkpoint at" in (run_dir / "run.log").read_text()
    assert_same_answer(run_dir, serial["impact_adaptive"])


@pytest.mark.parametrize("nranks", [2, 3])
def test_a_column_collapse_whose_mesh_grows_on_several_ranks_gives_the_single_process_answer(nranks, tmp_path):
    """The mesh's growth along x (a regrid onto a longer root grid) on several ranks: the state's
    interior cells, the counters and the clock of the single process bit for bit."""
    here = str(Path(__file__).resolve().parent)
    serial = subprocess.run([sys.executable, "-c", GROWING_COLUMN, str(tmp_path / "serial.npz"), here], env=ENV,
                            capture_output=True, text=True, timeout=SUBPROCESS_TIMEOUT_S)
    shared = subprocess.run([ranks.mpiexec_path(), "-n", str(nranks), sys.executable, "-c", GROWING_COLUMN,
                             str(tmp_path / "shared.npz"), here], env=ENV, capture_output=True, text=True,
                            timeout=SUBPROCESS_TIMEOUT_S)
    assert serial.returncode == 0 and shared.returncode == 0, serial.stderr + shared.stderr
    want, got = np.load(tmp_path / "serial.npz"), np.load(tmp_path / "shared.npz")
    assert want["growths"] >= 1
    for name in want.files:
        assert (got[name].dtype, got[name].shape) == (want[name].dtype, want[name].shape), name
        assert got[name].tobytes() == want[name].tobytes(), name


def test_more_ranks_than_blocks_is_a_clear_error(tmp_path):
    config = yaml.safe_load(SCENES["advection"].read_text())
    config["scene"]["cells"] = 8  # two blocks of 4 cells
    path = tmp_path / "two_blocks.yaml"
    path.write_text(yaml.safe_dump(config))
    result = impactpipe_run(path, tmp_path / "run", "--ranks", "3")
    assert result.returncode == 2
    assert "more ranks (3) than blocks (2)" in result.stderr
    assert not (tmp_path / "run").exists()  # refused before anything was written
    direct = subprocess.run([ranks.mpiexec_path(), "-n", "3", sys.executable, "-m", "impactpipe.pipeline.cli", "run",
                             str(path), "--out", str(tmp_path / "direct"), "-q"], env=ENV, capture_output=True,
                            text=True, timeout=SUBPROCESS_TIMEOUT_S)
    assert direct.returncode == 2, direct.stderr
    assert "more ranks (3) than blocks (2)" in direct.stderr
    assert not (tmp_path / "direct").exists()


def test_ranks_without_mpi4py_name_the_extra_to_install(monkeypatch, tmp_path):
    from click.testing import CliRunner

    monkeypatch.setattr(ranks, "mpi_installed", lambda: False)
    result = CliRunner().invoke(cli.main, ["run", str(SCENES["advection"]), "--out", str(tmp_path), "--ranks", "2"])
    assert result.exit_code == 2
    assert 'pip install "impactpipe[mpi]"' in result.output
