"""The storage primitives of outputs that several MPI ranks write together
(:func:`impactpipe.storage.store_array`, :func:`impactpipe.storage.atomic_path_together`), on their
single-process side: the collective side runs where h5py has parallel HDF5
(tests/test_parallel_hdf5.py)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from impactpipe.storage import COMPRESS_MIN_BYTES, TEMP_PREFIX, atomic_path_together, store_array, written_together


class _Rank:
    """The part of an mpi4py communicator that atomic_path_together uses: rank 0 broadcasts
    ``value``; another rank receives what rank 0 sent (``sent``)."""

    def __init__(self, rank: int, sent: str | None = None):
        self.rank = rank
        self.sent = sent
        self.broadcast = []

    def bcast(self, value, root=0):
        assert root == 0
        if self.rank == 0:
            self.broadcast.append(value)
            return value
        return self.sent


def test_in_a_file_of_one_process_store_array_writes_every_row_and_compresses_large_arrays(tmp_path):
    large = np.arange(COMPRESS_MIN_BYTES // 8 + 8, dtype=np.float64).reshape(-1, 8)
    with h5py.File(tmp_path / "one.h5", "w") as fh:
        assert not written_together(fh)
        store_array(fh, "large", large, rows=slice(0, 1))
        store_array(fh, "small", large[:2], rows=slice(1, 2))
        store_array(fh, "scalar", np.float64(2.5))
    with h5py.File(tmp_path / "one.h5", "r") as fh:
        assert np.array_equal(fh["large"][()], large) and fh["large"].compression == "gzip"
        assert np.array_equal(fh["small"][()], large[:2]) and fh["small"].compression is None
        assert fh["scalar"][()] == 2.5


def test_rank_0_renames_the_file_written_together_and_the_others_only_learn_its_name(tmp_path):
    target = tmp_path / "checkpoint.h5"
    root = _Rank(0)
    with atomic_path_together(target, root) as tmp:
        assert tmp.name.startswith(TEMP_PREFIX) and not target.exists()
        tmp.write_bytes(b"state")
    assert root.broadcast == [str(tmp)]
    assert target.read_bytes() == b"state" and not tmp.exists()

    other = _Rank(1, sent=str(tmp_path / "sent-by-rank-0"))
    with atomic_path_together(target, other) as name:
        assert str(name) == other.sent
    assert target.read_bytes() == b"state"  # only rank 0 renames


def test_a_failed_write_together_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "checkpoint.h5"
    target.write_bytes(b"last good")
    with pytest.raises(RuntimeError):
        with atomic_path_together(target, _Rank(0)) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("a rank failed")
    assert target.read_bytes() == b"last good"
    assert [p.name for p in tmp_path.iterdir()] == ["checkpoint.h5"]
