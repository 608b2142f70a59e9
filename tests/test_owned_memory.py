"""On several MPI ranks a rank writes only its own blocks and the cells its exchanges receive
(:mod:`impactpipe.hydro.parallel.owned_memory`): after steps, a snapshot and a checkpoint of the
r-z impact with strength and tracers on 3 ranks, on a uniform mesh and on an adaptive one
across regrids that refine and coarsen, no rank has written a page
of the state, of the strength model's work arrays or of the last-good copy outside those
(``/proc/self/pagemap``: present and exclusively mapped; a page only read maps the shared zero
page), and every other value is still +0.0 (the wall sign flips of the work ghosts that wrote
other ranks' blocks, -0.0 after one flip and +0.0 after two, fail the page check); the same
holds when the ranks build the run together or resume it from a checkpoint, each its own
blocks.  Nor does a rank ever hold the whole state while the run starts, but rank 0 where it
builds the run or reads the checkpoint alone
(:func:`~impactpipe.hydro.parallel.distributed.distribute_from_root`): the others' peak
resident memory grows by about their share of it (``/proc/self/status``), and every rank's
when the ranks build or read the run together.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from impactpipe.hydro.parallel.owned_memory import lazy_zeros

_spec = importlib.util.spec_from_file_location(
    "mpi_start_memory", Path(__file__).resolve().parent.parent / "benchmarks" / "mpi_start_memory.py")
mpi_start_memory = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(mpi_start_memory)

pytest.importorskip("mpi4py")

from impactpipe.pipeline import ranks  # noqa: E402

CONFIG = Path(__file__).resolve().parent / "configs" / "mpi" / "impact_strength.yaml"
ADAPTIVE_CONFIG = CONFIG.parent / "impact_adaptive.yaml"
ENV = {**os.environ, "NUMBA_NUM_THREADS": "1"}

#: Argument 1: the config, which rank 0 alone builds (with argument 4 "together", the ranks
#: build it together, each its own blocks); argument 3: the steps on the ranks (on an
#: adaptive mesh at least that many, then on until a regrid has refined blocks and one has
#: coarsened blocks since the sharing began), then a snapshot and a checkpoint (with argument 4
#: "resume", the run is then resumed from the checkpoint on the ranks, each reading its own
#: blocks, and takes two more steps and a snapshot: what follows counts that run); writes, per
#: rank, to OUT.rankR.json (argument 2): the blocks refined and coarsened meanwhile and, for
#: each array, the values outside the rank's own rows and its halo (the cells of its ghost
#: fills' strips, of the coarse/fine plans' exchanges on an adaptive mesh and, for the state,
#: the other ranks' coarse ghosts that the rank restricts itself and the tracers'
#: neighbourhood) that are not +0.0 (bit patterns), the halo's values that
#: are not (what the exchanges wrote), and the pages written that hold none of the own rows'
#: and halo's values.
UNWRITTEN = """
import json, mmap, sys
from types import SimpleNamespace
import numpy as np
from impactpipe.hydro.parallel.decomposition import Strips
from impactpipe.hydro.parallel.distributed import distribute_from_root
from impactpipe.pipeline import derived, load_config, ranks
from impactpipe.pipeline.adapters.hydro import add_tracers, build_simulation
comm = ranks.join_world()
config = load_config(sys.argv[1])
values = derived.derive(config)
if sys.argv[4:] == ["together"]:
    sim = build_simulation(config, values, comm)
    add_tracers(sim, config, float(values["end_time"]))
else:
    sim = None
    if comm.rank == 0:
        sim = build_simulation(config, values)
        add_tracers(sim, config, float(values["end_time"]))
    sim = distribute_from_root(sim, comm)
refined, coarsened = sim.blocks_refined, sim.blocks_coarsened
for step in range(60):
    if step >= int(sys.argv[3]) and (not sim.mesh.adaptive or (sim.blocks_refined > refined
                                                              and sim.blocks_coarsened > coarsened)):
        break
    sim.step()
sim.snapshot()
sim.save_checkpoint(sys.argv[2] + ".checkpoint.h5")
if sys.argv[4:] == ["resume"]:
    from impactpipe.hydro.solver import Simulation
    sim = Simulation.from_checkpoint(sys.argv[2] + ".checkpoint.h5", comm)
    for _ in range(2):
        sim.step()
    sim.snapshot()
part = sim.partition
strips = [route for routes in part.routes for route in routes]
restricted = []
if sim.mesh.adaptive:
    padded = sim.mesh.padded_shape
    for axis in range(sim.mesh.ndim):
        plans = part.plans(sim.mesh, axis)
        strips += plans["level_strips"].routes
        # the other ranks' coarse ghosts that this rank restricts itself for its prolongation
        rows = plans["restrict_borrowed"]
        cells = (rows[:, 1] * padded[1] + rows[:, 2]) * padded[2] + rows[:, 3]
        restricted.append(SimpleNamespace(receive=Strips(rows[:, 0], cells)))
arrays = {**sim.state.arrays(), "work": sim.strength.work}
halos = {name: strips + restricted + part.neighbourhood for name in sim.state.arrays()}
halos["work"] = strips
def stray_pages(array, kept):
    # pages of ``array`` that this process wrote (present and exclusively mapped, /proc/self/pagemap:
    # a page only read maps the shared zero page) and that hold none of the values where ``kept`` (flat) is True
    pages = -(-array.nbytes // mmap.PAGESIZE)
    with open("/proc/self/pagemap", "rb") as pagemap:
        pagemap.seek(array.ctypes.data // mmap.PAGESIZE * 8)
        entries = np.frombuffer(pagemap.read(8 * pages), dtype=np.uint64)
    written = ((entries >> np.uint64(63)) & (entries >> np.uint64(56)) & np.uint64(1)).astype(bool)
    allowed = np.zeros(pages, dtype=bool)
    allowed[np.flatnonzero(kept) * array.itemsize // mmap.PAGESIZE] = True
    return int(np.count_nonzero(written & ~allowed))
out = {"tracers": len(sim.tracers), "lo": part.lo, "hi": part.hi, "nblocks": sim.mesh.nblocks,
       "refined": sim.blocks_refined - refined, "coarsened": sim.blocks_coarsened - coarsened}
for name, array in arrays.items():
    halo = np.zeros(array.size, dtype=bool)
    for route in halos[name]:
        halo[route.receive.indices(array)] = True
    own = np.zeros(array.shape, dtype=bool)
    own[part.lo:part.hi] = True
    bits = array.view(np.int64).reshape(-1)
    outside = ~(own.reshape(-1) | halo)
    out[name] = {"outside": int(np.count_nonzero(bits[outside])),
                 "halo": int(np.count_nonzero(bits[halo & ~own.reshape(-1)])),
                 "stray_pages": stray_pages(array, ~outside)}
for name, good in sim._good.items():
    own = np.zeros(good.shape, dtype=bool)
    own[part.lo:part.hi] = True
    out["good_" + name] = {"outside": int(np.count_nonzero(good.view(np.int64)[~own])),
                           "stray_pages": stray_pages(good, own.reshape(-1))}
with open(f"{sys.argv[2]}.rank{comm.rank}.json", "w") as fh:
    fh.write(json.dumps(out))
"""

def test_lazy_zeros_commits_a_page_only_when_written():
    array = lazy_zeros((4, 3, 1024))
    assert array.dtype == np.float64 and array.flags.c_contiguous and array.flags.writeable
    assert not array.any()
    array[2, 1, 7] = 1.5
    assert array.sum() == 1.5
    assert lazy_zeros((0, 3)).shape == (0, 3)


def unwritten(path: Path, steps: int, out: Path, *resume: str) -> list[dict]:
    """What :data:`UNWRITTEN` counts on each of 3 ranks for the config at ``path`` (``resume``:
    "resume", or nothing)."""
    result = subprocess.run([ranks.mpiexec_path(), "-n", "3", sys.executable, "-c", UNWRITTEN, str(path), str(out),
                             str(steps), *resume], env=ENV, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    return [json.loads(Path(f"{out}.rank{rank}.json").read_text()) for rank in range(3)]


def assert_own_blocks_and_halo_only(per_rank: list[dict]) -> None:
    """No rank wrote a value or a page of the state, the work arrays or the last-good copy
    outside its own blocks and halo (``per_rank``: what :func:`unwritten` counted), and its
    exchanges wrote some of its halo."""
    for rank, counted in enumerate(per_rank):
        assert counted["tracers"] > 0
        assert counted["hi"] - counted["lo"] < counted["nblocks"]
        for name in ("alpha", "arho", "arhoe", "momentum", "energy", "arhoq", "work"):
            assert counted[name] == {**counted[name], "outside": 0, "stray_pages": 0}, (rank, name)
        for name in ("alpha", "arho", "arhoe", "momentum", "energy", "arhoq"):
            assert counted["good_" + name] == {"outside": 0, "stray_pages": 0}, (rank, name)
        assert counted["arho"]["halo"] > 0 and counted["work"]["halo"] > 0, rank


def test_a_rank_writes_only_its_own_blocks_and_the_cells_its_exchanges_receive(tmp_path):
    config = yaml.safe_load(CONFIG.read_text())
    config["hydro"]["tracers"] = {"enabled": True, "count": 60, "history_interval": 0.01}
    path = tmp_path / "impact_strength_tracers.yaml"
    path.write_text(yaml.safe_dump(config))
    assert_own_blocks_and_halo_only(unwritten(path, 4, tmp_path / "unwritten"))


def test_on_an_adaptive_mesh_a_rank_writes_only_its_own_blocks_and_halo_across_regrids(tmp_path):
    """The adaptive impact (strength, Grady-Kipp fracture, self-gravity, tracers; a regrid every
    2 steps), shared out by rank 0: each regrid builds a rank's new blocks from the old ones
    its owners send it, so no rank ever holds the whole state
    (:meth:`~impactpipe.hydro.parallel.distributed.BlockRanges.regrid`)."""
    counted = unwritten(ADAPTIVE_CONFIG, 3, tmp_path / "unwritten")
    assert counted[0]["refined"] > 0 and counted[0]["coarsened"] > 0, counted[0]
    assert_own_blocks_and_halo_only(counted)


@pytest.mark.parametrize("config_path", [CONFIG, ADAPTIVE_CONFIG], ids=["uniform", "adaptive"])
@pytest.mark.parametrize("start", ["together", "resume"])
def test_a_run_built_or_resumed_by_the_ranks_together_writes_only_each_ranks_own_blocks_and_halo(
        config_path, start, tmp_path):
    """:func:`~impactpipe.hydro.parallel.distributed.shared_simulation` (the ranks build the run,
    each its own blocks: the adaptive scene draws Grady-Kipp flaws over them) and
    :meth:`~impactpipe.hydro.solver.Simulation.from_checkpoint` on the ranks: rank 0 included, no
    rank sets or reads the whole state or writes outside its blocks and halo."""
    config = yaml.safe_load(config_path.read_text())
    config["hydro"]["tracers"] = {"enabled": True, "count": 60, "history_interval": 0.01}
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(config))
    assert_own_blocks_and_halo_only(unwritten(path, 3, tmp_path / "unwritten", start))


def test_no_rank_but_0_holds_the_whole_state_and_rank_0_only_when_it_builds_or_reads_the_run_alone(tmp_path):
    """The four starts of benchmarks/mpi_start_memory.py on 3 ranks (the r-z impact with strength at
    24 cells per projectile radius, a state of about 55 MB)."""
    counted = mpi_start_memory.start_peaks(tmp_path, 24, 3)
    whole = counted[0]["whole"]
    assert whole > 50e6  # the state stands well above the other memory the starts move
    alone = [counted[0]["rank_0_builds"], counted[0]["rank_0_reads"]]
    assert min(alone) > whole, counted  # rank 0 built or read the whole run
    # A rank that built, read or received the whole state would grow as much as rank 0 alone; a
    # rank holds its own blocks (28 % to 41 % of them here), their last-good copy and work arrays,
    # and the pages of its halo
    for start in ("rank_0_builds", "rank_0_reads"):
        assert max(c[start] for c in counted[1:]) < 0.75 * min(alone), (start, counted)
    for start in ("built_together", "read_together"):
        assert max(c[start] for c in counted) < 0.75 * min(alone), (start, counted)
