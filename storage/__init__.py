"""File primitives every impactpipe package writes with: atomic writes, HDF5 datasets with units,
provenance records and compression.

This is the bottom layer of the package: it imports nothing else of impactpipe, so the stage
libraries (hydro, handoff, nbody, analysis) and the orchestrator (pipeline) all build on it.

Every file the pipeline writes goes through :func:`atomic_path`: the content is written
to a temporary file in the same directory and renamed over the target only when the
writer finished without an exception, so an interrupted writer never leaves a file that
looks complete.  Every HDF5 file carries :func:`provenance` as attributes of its root.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import json
import os
import platform
import subprocess
import tempfile
from collections.abc import Iterator, Mapping
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

TEMP_PREFIX = ".tmp-"


def _process_umask() -> int:
    """The process umask (read by setting and restoring it, at import, before any threads)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: Permission bits a new output file gets: what ``open(path, "w")`` would give it.
FILE_MODE = 0o666 & ~_process_umask()
DEPENDENCIES = ("numpy", "numba", "rebound", "h5py", "scipy", "click", "pyyaml", "pydantic", "tqdm")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    On an exception (including KeyboardInterrupt) the temporary file is removed and
    ``path`` is left as it was.  The rename is atomic on POSIX file systems.  The file gets
    the permissions of the file it replaces, or those of a new file under the process umask
    (the temporary file starts private, mode 0600).
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=TEMP_PREFIX + target.name + ".", dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        mode = target.stat().st_mode & 0o777 if target.exists() else FILE_MODE
        os.chmod(tmp, mode)
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def atomic_path_together(path: str | os.PathLike, comm: Any) -> Iterator[Path]:
    """:func:`atomic_path` for the processes of an MPI communicator ``comm`` (mpi4py) that write
    one file together (:func:`written_together`): rank 0 makes the temporary path and gives it to
    the others, and renames it onto ``path`` as it leaves the block.  Every process must close
    the file inside the block: closing a file of h5py's ``mpio`` driver is collective, so when
    rank 0 has closed it every process has finished writing."""
    if comm.rank == 0:
        with atomic_path(path) as tmp:
            comm.bcast(str(tmp), root=0)
            yield tmp
    else:
        yield Path(comm.bcast(None, root=0))


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_json_atomic(path: str | os.PathLike, data: Mapping[str, Any]) -> None:
    """Write ``data`` as indented JSON to ``path`` atomically (numpy scalars converted)."""
    write_text_atomic(path, json.dumps(data, indent=2, sort_keys=False, default=_json_default) + "\n")


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def package_versions() -> dict[str, str]:
    """Versions of impactpipe, Python and the runtime dependencies."""
    versions = {"impactpipe": _version("impactpipe"), "python": platform.python_version()}
    for name in DEPENDENCIES:
        versions[name] = _version(name)
    return versions


def _version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "not installed"


def git_commit() -> str | None:
    """The git commit of the impactpipe source tree, with ``-dirty`` if modified; None if unknown."""
    source = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(
            ["git", "-C", str(source), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5
        )
        if commit.returncode != 0:
            return None
        dirty = subprocess.run(
            ["git", "-C", str(source), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, timeout=5,
        )
        return commit.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None


#: The commit of the source this process imported (read once, at import): a long-lived process
#: (a sweep's worker) keeps running the code it imported even if the tree changes later, so
#: provenance must not read the commit again when it writes an output.
SOURCE_COMMIT = git_commit()


def utc_now() -> str:
    """Current UTC time as an ISO-8601 string."""
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def provenance(resolved_config_yaml: str, started: str, wall_seconds: float) -> dict[str, str]:
    """Provenance attributes for an output file: config, versions, commit, host and times."""
    return {
        "resolved_config": resolved_config_yaml,
        "versions": json.dumps(package_versions()),
        "git_commit": SOURCE_COMMIT or "unknown",
        "host": platform.node(),
        "start_time": started,
        "end_time": utc_now(),
        "wall_seconds": f"{wall_seconds:.3f}",
    }


def write_provenance(h5obj: Any, attrs: Mapping[str, str]) -> None:
    """Store provenance attributes on an h5py File or Group."""
    for key, value in attrs.items():
        h5obj.attrs[key] = value


#: Arrays of at least this many bytes are stored compressed (:func:`compression`).
COMPRESS_MIN_BYTES = 1 << 16


def compression(data: np.ndarray) -> dict[str, Any]:
    """h5py dataset options for ``data``: deflate (gzip level 1, a filter every HDF5 reader has)
    after the byte shuffle, for arrays of at least COMPRESS_MIN_BYTES; none for small ones.
    Lossless; hydro snapshots shrink about 3x and checkpoints about 4x for a few tenths of a
    second per write (docs/architecture.md, "Conventions")."""
    if data.ndim == 0 or data.nbytes < COMPRESS_MIN_BYTES:
        return {}
    return {"compression": "gzip", "compression_opts": 1, "shuffle": True}


def written_together(group: Any) -> bool:
    """Whether the file of the h5py ``group`` is written by several MPI processes together
    (opened with h5py's ``mpio`` driver, parallel HDF5)."""
    return group.file.driver == "mpio"


def store_array(group: Any, name: str, data: Any, rows: slice | None = None) -> Any:
    """Create dataset ``name`` in an h5py group holding ``data``, compressed when large
    (:func:`compression`); returns the dataset.

    In a file that several MPI processes write together (:func:`written_together`) every
    process calls this with an array of the same shape and dtype, and it writes, in one
    collective write, the rows ``rows`` (a slice of the first axis: the blocks this process
    owns) of ``data``, or, where ``rows`` is None, all of ``data``, which every process then
    holds the same.  In any other file ``rows`` is ignored and the whole array is written.
    """
    array = np.asarray(data)
    if not written_together(group):
        return group.create_dataset(name, data=array, **compression(array))
    dset = group.create_dataset(name, shape=array.shape, dtype=array.dtype, **compression(array))
    part = () if array.ndim == 0 else slice(None) if rows is None else rows
    with dset.collective:
        dset[part] = array[part]
    return dset


def write_dataset(group: Any, name: str, data: Any, units: str, description: str | None = None,
                  rows: slice | None = None) -> Any:
    """Create dataset ``name`` in an h5py group with a ``units`` attribute (and a description);
    large arrays are compressed (:func:`compression`); ``rows``: see :func:`store_array`.

    ``units`` uses yt-style strings: "m", "kg", "s", "m/s", "kg/m**3", "Pa", "J/kg", "K",
    "dimensionless".
    """
    dset = store_array(group, name, data, rows)
    dset.attrs["units"] = units
    if description:
        dset.attrs["description"] = description
    return dset
