"""The messages between ranks: strips before a ghost fill or a tracer sample, owned blocks
before an output, tracer rows after a tracer sample.

All fields are float64 arrays (NB, C, NX, NY, NZ), C-contiguous, so a block's values are one
contiguous run and a strip is a fixed set of flat indices (:class:`~.decomposition.Strips`).
Each exchange adds what it moved and how long it took to a :class:`Traffic` (a few integer
additions and two clock reads per ghost fill, nothing per cell).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
from numba import njit

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
#: Message tag of the strips along every axis before a derived field's ghost fills along every
#: axis (the stress step's work arrays), one message per peer.
FIELD_TAG = 600


@dataclass
class Traffic:
    """What one rank exchanged with the others since the last :meth:`reset` (cumulative).

    ``bytes_sent`` / ``bytes_received`` (B) and ``messages_sent`` / ``messages_received``:
    the strips of the ghost fills (:func:`exchange_strips`); ``exchanges``: the ghost fills
    (one exchange each, without messages where no other rank owns a neighbour);
    ``exchange_seconds`` (s): wall time inside them (packing, waiting and unpacking);
    ``wait_seconds`` (s): the part spent in ``Waitall``, waiting for the
    peers' strips (their transfer, and the peers' lateness in reaching the fill);
    ``allreduces`` and ``allreduce_seconds`` (s): the reductions of the time step and the
    failure checks; ``gathers`` and ``gather_seconds`` (s): the sharing of every block before
    an output (:func:`share_owned_blocks`).
    """

    bytes_sent: int = 0
    bytes_received: int = 0
    messages_sent: int = 0
    messages_received: int = 0
    exchanges: int = 0
    exchange_seconds: float = 0.0
    wait_seconds: float = 0.0
    allreduces: int = 0
    allreduce_seconds: float = 0.0
    gathers: int = 0
    gather_seconds: float = 0.0

    def reset(self) -> None:
        """Every counter back to zero."""
        for name, value in asdict(Traffic()).items():
            setattr(self, name, value)

    def as_dict(self) -> dict:
        """The counters by name."""
        return asdict(self)


def exchange_strips(comm, routes: list[Route], fields: tuple[np.ndarray, ...], tag: int, traffic: Traffic,
                    runs: tuple[slice, ...] = (slice(None),)) -> None:
    """Send this rank's strips and receive its peers' into the components of ``fields`` that the
    ``runs`` (slices of the component axis) select, one message per peer (every field's runs
    packed one after another into one float64 buffer, message tag ``tag``), non-blocking both
    ways, then unpack; the bytes, messages and seconds go to ``traffic``.  The buffers are kept
    on the routes' strips and reused (:meth:`Strips.buffer`); packing and unpacking are numba
    loops over the strips' flat indices."""
    finish_strips(post_strips(comm, routes, fields, tag, traffic, runs))


@dataclass
class PendingStrips:
    """An exchange of :func:`post_strips` whose messages may still be in flight."""

    requests: list
    received: list
    fields: tuple
    runs: tuple
    traffic: Traffic
    sent_bytes: int


def post_strips(comm, routes: list[Route], fields: tuple[np.ndarray, ...], tag: int, traffic: Traffic,
                runs: tuple[slice, ...] = (slice(None),)) -> PendingStrips:
    """The first half of :func:`exchange_strips`: post the receives, pack and post the sends,
    and return without waiting, so that work which needs none of the peers' strips can run
    while they travel; :func:`finish_strips` waits and unpacks.  The sent strips are packed
    here, from the fields as they are now."""
    started = time.perf_counter()
    requests, received, sent_bytes = [], [], 0
    for route in routes:
        buffer = route.receive.buffer(fields, runs)
        requests.append(comm.Irecv(buffer, source=route.peer, tag=tag))
        received.append((buffer, route.receive))
    flats = [_flat(field) for field in fields]
    for route in routes:
        buffer = route.send.buffer(fields, runs)
        start = 0
        for flat, field in zip(flats, fields):
            start = pack_values(flat, route.send.indices(field, runs), buffer, start)
        requests.append(comm.Isend(buffer, dest=route.peer, tag=tag))
        sent_bytes += buffer.nbytes
    traffic.messages_sent += len(routes)
    traffic.exchange_seconds += time.perf_counter() - started
    return PendingStrips(requests, received, fields, runs, traffic, sent_bytes)


def finish_strips(pending: PendingStrips) -> None:
    """Wait for the messages of :func:`post_strips` and unpack the received strips."""
    from mpi4py import MPI

    traffic = pending.traffic
    waiting = time.perf_counter()
    MPI.Request.Waitall(pending.requests)
    traffic.wait_seconds += time.perf_counter() - waiting
    flats = [_flat(field) for field in pending.fields]
    for buffer, strips in pending.received:
        start = 0
        for flat, field in zip(flats, pending.fields):
            start = unpack_values(buffer, start, strips.indices(field, pending.runs), flat)
    traffic.bytes_sent += pending.sent_bytes
    traffic.bytes_received += sum(buffer.nbytes for buffer, _ in pending.received)
    traffic.messages_received += len(pending.received)
    traffic.exchanges += 1
    traffic.exchange_seconds += time.perf_counter() - waiting


@njit(cache=True)
def pack_values(flat, indices, buffer, start):
    """buffer[start + i] = flat[indices[i]]; returns the next free position of ``buffer``."""
    for i in range(indices.size):
        buffer[start + i] = flat[indices[i]]
    return start + indices.size


@njit(cache=True)
def unpack_values(buffer, start, indices, flat):
    """flat[indices[i]] = buffer[start + i]; returns the position after the values read."""
    for i in range(indices.size):
        flat[indices[i]] = buffer[start + i]
    return start + indices.size


def share_owned_blocks(comm, arrays: list[np.ndarray], cuts: np.ndarray, traffic: Traffic) -> None:
    """Every rank receives every rank's owned blocks (rows ``cuts[r] .. cuts[r + 1] - 1`` of
    each array, in place): one Allgatherv per array, counted in ``traffic`` as one gather."""
    from mpi4py import MPI
    from mpi4py.util.dtlib import from_numpy_dtype

    started = time.perf_counter()
    for array in arrays:
        flat = _flat(array)
        row = int(np.prod(array.shape[1:], dtype=np.int64))
        counts = (np.diff(cuts) * row).tolist()
        displacements = (cuts[:-1] * row).tolist()
        comm.Allgatherv(MPI.IN_PLACE, [flat, (counts, displacements), from_numpy_dtype(array.dtype)])
    traffic.gathers += 1
    traffic.gather_seconds += time.perf_counter() - started


def gather_owned_blocks(comm, arrays: list[np.ndarray], cuts: np.ndarray, traffic: Traffic) -> None:
    """Rank 0 receives every rank's owned blocks (rows ``cuts[r] .. cuts[r + 1] - 1`` of each
    array, in place; the other ranks' arrays are unchanged): one Gatherv per array, counted in
    ``traffic`` as one gather."""
    from mpi4py import MPI
    from mpi4py.util.dtlib import from_numpy_dtype

    started = time.perf_counter()
    lo, hi = int(cuts[comm.rank]), int(cuts[comm.rank + 1])
    for array in arrays:
        flat = _flat(array)
        row = int(np.prod(array.shape[1:], dtype=np.int64))
        kind = from_numpy_dtype(array.dtype)
        if comm.rank == 0:
            counts = (np.diff(cuts) * row).tolist()
            displacements = (cuts[:-1] * row).tolist()
            comm.Gatherv(MPI.IN_PLACE, [flat, (counts, displacements), kind], root=0)
        else:
            comm.Gatherv([flat[lo * row:hi * row], kind], None, root=0)
    traffic.gathers += 1
    traffic.gather_seconds += time.perf_counter() - started


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
