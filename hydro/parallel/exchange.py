"""The messages between ranks: strips before a ghost fill or a tracer sample, owned blocks
before an output, tracer rows after a tracer sample.

All fields are float64 arrays (NB, C, NX, NY, NZ), C-contiguous, so a block's values are one
contiguous run and a strip is a fixed set of flat indices (:class:`~.decomposition.Strips`).
"""

from __future__ import annotations

import numpy as np

from .decomposition import Route

#: Message tag of the strips before a ghost fill along axis d: STRIP_TAG + d.
STRIP_TAG = 100
#: Message tag of the cells around the blocks before the tracers sample the state.
NEIGHBOURHOOD_TAG = 200
#: Message tags before the restriction and the prolongation of coarse/fine ghosts along axis
#: d (+ d), and of the face fluxes before a reflux along axis d (+ d).
RESTRICT_TAG = 300
PROLONG_TAG = 400
FLUX_TAG = 500


def exchange_strips(comm, routes: list[Route], fields: tuple[np.ndarray, ...], tag: int,
                    components: slice = slice(None)) -> None:
    """Send this rank's strips and receive its peers' into the ``components`` of ``fields``, one
    message per peer (every field packed into one float64 buffer, message tag ``tag``),
    non-blocking both ways, then unpack."""
    from mpi4py import MPI

    flats = [_flat(field) for field in fields]
    requests, received, sent = [], [], []
    for route in routes:
        buffer = np.empty(sum(route.receive.values(field, components) for field in fields))
        requests.append(comm.Irecv(buffer, source=route.peer, tag=tag))
        received.append((buffer, route.receive))
    for route in routes:
        buffer = np.concatenate([flat[route.send.indices(field, components)] for flat, field in zip(flats, fields)])
        requests.append(comm.Isend(buffer, dest=route.peer, tag=tag))
        sent.append(buffer)
    MPI.Request.Waitall(requests)
    for buffer, strips in received:
        start = 0
        for flat, field in zip(flats, fields):
            size = strips.values(field, components)
            flat[strips.indices(field, components)] = buffer[start:start + size]
            start += size


def share_owned_blocks(comm, arrays: list[np.ndarray], cuts: np.ndarray) -> None:
    """Every rank receives every rank's owned blocks (rows ``cuts[r] .. cuts[r + 1] - 1`` of
    each array, in place): one Allgatherv per array."""
    from mpi4py import MPI
    from mpi4py.util.dtlib import from_numpy_dtype

    for array in arrays:
        flat = _flat(array)
        row = int(np.prod(array.shape[1:], dtype=np.int64))
        counts = (np.diff(cuts) * row).tolist()
        displacements = (cuts[:-1] * row).tolist()
        comm.Allgatherv(MPI.IN_PLACE, [flat, (counts, displacements), from_numpy_dtype(array.dtype)])


def gather_rows(comm, owner: np.ndarray, arrays: list[np.ndarray]) -> None:
    """Row t of every float64 array in ``arrays`` (each (N, ...), C-contiguous) from rank
    ``owner[t]`` on every rank, in place; rows with ``owner`` -1 stay as they are.  One
    Allgatherv of each rank's rows side by side, by rank, then by row (the values are copied,
    NaN and -0.0 included)."""
    from mpi4py import MPI

    n = len(owner)
    rows = [_flat(array).reshape(n, -1) for array in arrays]
    width = sum(row.shape[1] for row in rows)
    sent = np.concatenate([row[owner == comm.rank] for row in rows], axis=1)
    counts = np.bincount(owner[owner >= 0], minlength=comm.size) * width
    order = np.argsort(owner, kind="stable")[n - int(counts.sum()) // width:]
    received = np.empty((len(order), width))
    displacements = np.concatenate([[0], np.cumsum(counts)[:-1]])
    comm.Allgatherv([sent, MPI.DOUBLE], [received, (counts.tolist(), displacements.tolist()), MPI.DOUBLE])
    start = 0
    for row in rows:
        row[order] = received[:, start:start + row.shape[1]]
        start += row.shape[1]


def broadcast_arrays(comm, arrays: list[np.ndarray]) -> None:
    """Rank 0's values of ``arrays`` on every rank (in place)."""
    for array in arrays:
        comm.Bcast(_flat(array), root=0)


def _flat(array: np.ndarray) -> np.ndarray:
    """A flat view (no copy) of a C-contiguous array."""
    if not array.flags.c_contiguous:
        raise ValueError("the arrays exchanged between ranks must be C-contiguous")
    return array.reshape(-1)
