"""Snapshots and checkpoints written by every MPI rank together, each its own blocks' rows, into one
file (parallel HDF5, h5py's mpio driver; :func:`impactpipe.hydro.parallel.distributed.parallel_hdf5`).

Runs only where h5py was built with parallel HDF5 (the wheels of the package index are not; see
docs/runs.md, "Several MPI ranks", for an environment that is).  There every test of
tests/test_mpi_hydro.py runs the ranks on this path, since it is the default, and checks the
single-process answer bit for bit; here: the files written together are the files rank 0
writes after gathering every block, and rank 0's memory for a snapshot and a checkpoint is
about its own share of the state, where gathering made it hold the whole.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import h5py
import numpy as np
import pytest

pytest.importorskip("mpi4py")
if not h5py.get_config().mpi:
    pytest.skip("h5py is built without parallel HDF5", allow_module_level=True)

_spec = importlib.util.spec_from_file_location(
    "output_memory", Path(__file__).resolve().parent.parent / "benchmarks" / "output_memory.py")
output_memory = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(output_memory)


def datasets(path: Path) -> dict:
    """Every dataset (values, dtype, shape, compression) and attribute of an HDF5 file, by name."""
    found: dict = {}

    def visit(name, obj):
        found.update({f"{name}@{key}": np.asarray(value).tobytes() for key, value in obj.attrs.items()})
        if isinstance(obj, h5py.Dataset):
            found[name] = (obj[()].tobytes(), obj.dtype.str, obj.shape, obj.compression)

    with h5py.File(path, "r") as fh:
        found.update({f"@{key}": np.asarray(value).tobytes() for key, value in fh.attrs.items()})
        fh.visititems(visit)
    return found


def test_outputs_written_together_are_the_gathered_outputs_and_rank_0_holds_its_share(tmp_path):
    """The r-z impact with strength and tracers on 3 ranks (benchmarks/output_memory.py), a
    state of about 55 MB that stands well above the other memory an output moves."""
    config = output_memory.scene(tmp_path, 24)
    gathered = output_memory.write_outputs(config, tmp_path / "gathered", together=False)
    together = output_memory.write_outputs(config, tmp_path / "together", together=True)
    for suffix in (".work.h5", ".checkpoint.h5"):
        assert datasets(Path(f"{tmp_path / 'together'}{suffix}")) == datasets(Path(f"{tmp_path / 'gathered'}{suffix}"))
    whole = gathered[0]["whole"]
    assert whole > 40e6, whole
    # Gathering, rank 0 receives every block for the snapshot's fields and again for the checkpoint.
    assert gathered[0]["grown"] > 0.9 * whole, gathered
    # Together, each rank holds its own blocks' snapshot fields and HDF5's buffers of the chunks it
    # writes: its share of the state (31 to 41 % here) and about a tenth of the whole more.
    for rank in range(3):
        assert together[rank]["grown"] < together[rank]["own"] + 0.25 * whole, (rank, together)
    assert together[0]["grown"] < 0.5 * gathered[0]["grown"], (together, gathered)
