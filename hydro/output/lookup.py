"""Find one snapshot of a run: by run directory or ``hydro.h5`` path, and by time or index."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from impactpipe.hydro.output.io import SNAPSHOT_GROUP, read_snapshot
from impactpipe.hydro.output.snapshot import Snapshot

HYDRO_FILE = "hydro.h5"


def hydro_file(path_or_run_dir: str | Path) -> Path:
    """The ``hydro.h5`` of a run directory, or the given file itself; FileNotFoundError if absent."""
    path = Path(path_or_run_dir)
    if path.is_dir():
        path = path / HYDRO_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file (has the hydro stage run?)")
    return path


def snapshot_times(path: str | Path) -> np.ndarray:
    """(K,) times (s) of the snapshots in a ``hydro.h5`` file, in index order."""
    with h5py.File(path, "r") as fh:
        if SNAPSHOT_GROUP not in fh:
            return np.zeros(0)
        group = fh[SNAPSHOT_GROUP]
        return np.array([group[name].attrs["time"] for name in sorted(group)], dtype=float)


def find_snapshot(path_or_run_dir: str | Path, time: float | None = None,
                  index: int | None = None) -> tuple[Snapshot, int]:
    """(snapshot, its index) from a run directory or ``hydro.h5`` file.

    ``time`` (s) picks the snapshot nearest to it, ``index`` picks by position (negative
    counts from the last); with neither, the last snapshot.  Giving both is a ValueError.
    """
    if time is not None and index is not None:
        raise ValueError("give a snapshot time or an index, not both")
    path = hydro_file(path_or_run_dir)
    times = snapshot_times(path)
    if times.size == 0:
        raise KeyError(f"{path}: no snapshots")
    if time is not None:
        index = int(np.argmin(np.abs(times - time)))
    elif index is None:
        index = times.size - 1
    elif not -times.size <= index < times.size:
        raise IndexError(f"{path}: snapshot index {index} out of range ({times.size} snapshots)")
    index %= times.size
    return read_snapshot(path, index), index
