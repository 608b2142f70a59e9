"""The messages between ranks: strips before a ghost fill or a tracer sample, owned blocks
before an output and from rank 0 at the start, tracers handed to the rank whose blocks hold
them and gathered for an output.

All fields are float64 arrays (NB, C, NX, NY, NZ), C-contiguous, so a block's values are one
contiguous run and a strip is a fixed set of flat indices (:class:`~.decomposition.Strips`).
The strips of one call site (:class:`StripExchange`) are planned once per partition: their
flat indices, buffers and persistent requests (:class:`StripPlan`).
Each exchange adds what it moved and how long it took to a :class:`Traffic` (a few integer
additions and two clock reads per ghost fill, nothing per cell).
"""

from __future__ import annotations

import operator
import time
import weakref
from dataclasses import asdict, dataclass

import numpy as np
from numba import njit

from .decomposition import Route, Strips, run_bounds

#: Message tag of the strips before a ghost fill along axis d: STRIP_TAG + d (on an adaptive
#: mesh with the cells that the restriction and the prolongation of coarse/fine ghosts read).
STRIP_TAG = 100
#: Message tag of the cells around the blocks before the tracers sample the state.
NEIGHBOURHOOD_TAG = 200
#: Message tag of the face fluxes before a reflux along axis d: FLUX_TAG + d.
FLUX_TAG = 500
#: Message tag of the strips along every axis before a derived field's ghost fills along every
#: axis (the stress step's work arrays), one message per peer.
FIELD_TAG = 600
#: Message tag of the halo cells a rank receives from their owners when the run is shared
#: (:func:`~.owned_memory.receive_owned_blocks`).
SETUP_TAG = 700
#: The tag of the values carried from rank to rank in block order
#: (:meth:`~.distributed.BlockRanges.carry_through`).
CARRY_TAG = 800
#: The tag of the tracers handed to the rank whose blocks they moved into (:func:`hand_over_rows`).
HANDOVER_TAG = 900


@dataclass
class Traffic:
    """What one rank exchanged with the others since the last :meth:`reset` (cumulative).

    ``bytes_sent`` / ``bytes_received`` (B) and ``messages_sent`` / ``messages_received``:
    the strips of the ghost fills (:class:`StripExchange`); ``exchanges``: the ghost fills
    (one exchange each, without messages where no other rank owns a neighbour);
    ``exchange_seconds`` (s): wall time inside them (packing, waiting and unpacking);
    ``wait_seconds`` (s): the part spent in ``Waitall``, waiting for the
    peers' strips (their transfer, and the peers' lateness in reaching the fill);
    ``allreduces`` and ``allreduce_seconds`` (s): the reductions of the time step and the
    failure checks; ``gathers`` and ``gather_seconds`` (s): the sharing of every block before
    an output (:func:`share_owned_blocks`) and, on an adaptive mesh, the regrid's move of the
    old blocks to the owners of the new blocks made from them (:func:`move_rows`, one each);
    ``handovers``, ``items_handed_over`` and ``handover_seconds`` (s): the hand-overs of
    tracers to the ranks whose blocks they moved into (:func:`hand_over_rows`, one each, the
    tracers this rank sent).
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
    handovers: int = 0
    items_handed_over: int = 0
    handover_seconds: float = 0.0

    def reset(self) -> None:
        """Every counter back to zero."""
        for name, value in asdict(Traffic()).items():
            setattr(self, name, value)

    def as_dict(self) -> dict:
        """The counters by name."""
        return asdict(self)


class StripExchange:
    """The strips of one list of routes (one peer each) under one message tag: for each set of
    field shapes and runs of components, a :class:`StripPlan` built on first use and kept, so
    that an exchange before a ghost fill does no per-call planning (one plan per call site:
    the state's fill along an axis, the stress step's fills of the work arrays, ...).

    :meth:`post` starts the receives, packs every strip of every field for every peer in one
    numba call and starts the sends; :func:`finish_strips` waits and unpacks in one call.  The
    messages are the same as one ``Irecv``/``Isend`` per peer of every field's strips packed
    one after another (tag ``tag``), sent through persistent requests
    (``Recv_init``/``Send_init``) on fixed buffers, freed with the plan
    (:func:`free_requests`).  A plan's buffers and requests serve one exchange at a time: each
    :meth:`post` is finished before the same plan posts again."""

    def __init__(self, comm, routes: list[Route], tag: int):
        self.comm = comm
        self.routes = routes
        self.tag = tag
        self._plans: dict = {}
        #: The plans bound to the arrays of recent calls, one per runs of components
        #: (:meth:`bound`).
        self._bindings: list[Binding] = []

    def plan(self, fields: tuple[np.ndarray, ...], runs: tuple[slice, ...] = (slice(None),)) -> "StripPlan":
        """The plan of the components of ``fields`` that the ``runs`` (slices of the component
        axis) select, built once per set of field shapes and runs."""
        key = (tuple(f.shape for f in fields), run_bounds(runs, fields[0].shape[1]))
        plan = self._plans.get(key)
        if plan is None:
            plan = self._plans[key] = StripPlan.build(self.comm, self.routes, fields, runs, self.tag)
        return plan

    def bound(self, fields: tuple[np.ndarray, ...], runs: tuple[slice, ...]) -> "Binding":
        """The plan of ``fields`` and ``runs`` with the fields' flat views: those of an earlier
        call with the same runs while the same arrays come back (every step until a regrid
        replaces them), so that a call builds no key and no view; otherwise bound anew, in
        place of the earlier call's binding with these runs."""
        for binding in self._bindings:
            if binding.runs == runs and len(binding.fields) == len(fields) and all(
                    map(operator.is_, binding.fields, fields)):
                return binding
        binding = Binding(tuple(fields), runs, tuple(_flat(field) for field in fields), self.plan(fields, runs))
        self._bindings = [kept for kept in self._bindings if kept.runs != runs] + [binding]
        return binding

    def post(self, fields: tuple[np.ndarray, ...], traffic: Traffic,
             runs: tuple[slice, ...] = (slice(None),)) -> "PendingStrips":
        """Start this rank's receives, pack its strips of the components of ``fields`` that the
        ``runs`` select and start its sends, then return without waiting, so that work which
        needs none of the peers' strips can run while they travel; :func:`finish_strips` waits
        and unpacks.  The sent strips are packed here, from the fields as they are now."""
        started = time.perf_counter()
        binding = self.bound(fields, runs)
        binding.plan.start(binding.flats)
        traffic.messages_sent += binding.plan.messages
        traffic.exchange_seconds += time.perf_counter() - started
        return PendingStrips(binding.plan, binding.flats, traffic)

    def exchange(self, fields: tuple[np.ndarray, ...], traffic: Traffic,
                 runs: tuple[slice, ...] = (slice(None),)) -> None:
        """Send this rank's strips and receive its peers' into the components of ``fields`` that
        the ``runs`` select (:meth:`post`, then :func:`finish_strips`); the bytes, messages and
        seconds go to ``traffic``."""
        finish_strips(self.post(fields, traffic, runs))


@dataclass
class Binding:
    """A :class:`StripPlan` bound to the arrays of a call: the ``fields``, the ``runs`` of
    components and the fields' flat views (no copies)."""

    fields: tuple
    runs: tuple
    flats: tuple
    plan: StripPlan


@dataclass
class StripPlan:
    """One exchange of strips, fixed for a set of routes, field shapes, runs of components and
    tag: every message's values lie in one send and one receive buffer (float64), peer after
    peer (each peer's message a slice of the buffer), each message field after field, each
    field's values as :meth:`~.decomposition.Strips.indices` orders them.  Value ``i`` of the
    send buffer is ``flats[send_field[s]][send_index[i]]`` for ``i`` in the segment ``s``
    (``send_starts[s] .. send_starts[s + 1] - 1``, one per peer and field); likewise the
    receive buffer into the fields."""

    send_buffer: np.ndarray
    receive_buffer: np.ndarray
    send_index: np.ndarray
    send_starts: np.ndarray
    send_field: np.ndarray
    receive_index: np.ndarray
    receive_starts: np.ndarray
    receive_field: np.ndarray
    #: Persistent requests: the receives (one per peer), the sends, and both (the receives first).
    receives: list
    sends: list
    requests: list
    messages: int
    sent_bytes: int
    received_bytes: int

    @classmethod
    def build(cls, comm, routes: list[Route], fields: tuple[np.ndarray, ...], runs: tuple[slice, ...],
              tag: int) -> "StripPlan":
        """The plan of ``routes`` for the components of ``fields`` that the ``runs`` select."""
        send = _segments([route.send for route in routes], fields, runs)
        receive = _segments([route.receive for route in routes], fields, runs)
        send_buffer, receive_buffer = np.empty(send[0].size), np.empty(receive[0].size)
        receives = [comm.Recv_init(receive_buffer[lo:hi], source=route.peer, tag=tag)
                    for route, lo, hi in zip(routes, receive[3][:-1], receive[3][1:])]
        sends = [comm.Send_init(send_buffer[lo:hi], dest=route.peer, tag=tag)
                 for route, lo, hi in zip(routes, send[3][:-1], send[3][1:])]
        plan = cls(send_buffer, receive_buffer, *send[:3], *receive[:3], receives, sends, receives + sends,
                   len(routes), send_buffer.nbytes, receive_buffer.nbytes)
        weakref.finalize(plan, free_requests, plan.requests)
        return plan

    def start(self, flats: tuple[np.ndarray, ...]) -> None:
        """Start the receives, pack the strips of the flat fields ``flats`` and start the sends."""
        if not self.messages:
            return
        from mpi4py import MPI

        MPI.Prequest.Startall(self.receives)
        pack_strips(flats, self.send_field, self.send_starts, self.send_index, self.send_buffer)
        MPI.Prequest.Startall(self.sends)


def free_requests(requests: list) -> None:
    """Free the persistent ``requests`` of a plan when it is dropped (a regrid's new partition
    replaced it) or at exit, before MPI is finalized."""
    for request in requests:
        request.Free()


def _segments(strips: list[Strips], fields: tuple[np.ndarray, ...], runs: tuple[slice, ...]
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(flat indices, segment starts, field of each segment, message offsets) of the values of
    the ``strips`` (one per message) of every field of ``fields``, message after message, field
    after field (int64 arrays; the offsets are positions in the buffer, one more than the
    messages)."""
    indices, field_of, sizes, offsets = [], [], [], [0]
    for part in strips:
        for number, values in enumerate(fields):
            indices.append(part.indices(values, runs))
            field_of.append(number)
            sizes.append(indices[-1].size)
        offsets.append(offsets[-1] + sum(sizes[len(sizes) - len(fields):]))
    index = np.concatenate(indices) if indices else np.zeros(0, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(sizes, dtype=np.int64)]).astype(np.int64)
    return (np.ascontiguousarray(index, dtype=np.int64), starts, np.array(field_of, dtype=np.int64),
            np.array(offsets, dtype=np.int64))


@dataclass
class PendingStrips:
    """An exchange of :meth:`StripExchange.post` whose messages may still be in flight."""

    plan: StripPlan
    flats: tuple
    traffic: Traffic


def finish_strips(pending: PendingStrips) -> None:
    """Wait for the messages of :meth:`StripExchange.post` and unpack the received strips (every
    peer's, every field's, in one numba call)."""
    from mpi4py import MPI

    plan, traffic = pending.plan, pending.traffic
    waiting = time.perf_counter()
    if plan.messages:
        MPI.Request.Waitall(plan.requests)
    traffic.wait_seconds += time.perf_counter() - waiting
    if plan.messages:
        unpack_strips(plan.receive_buffer, plan.receive_field, plan.receive_starts, plan.receive_index, pending.flats)
    traffic.bytes_sent += plan.sent_bytes
    traffic.bytes_received += plan.received_bytes
    traffic.messages_received += plan.messages
    traffic.exchanges += 1
    traffic.exchange_seconds += time.perf_counter() - waiting


@njit(cache=True)
def pack_strips(flats, field_of, starts, indices, buffer):
    """buffer[i] = flats[field_of[s]][indices[i]] for i in starts[s] .. starts[s + 1] - 1, for
    every segment s (a tuple of flat float64 fields, int64 segment fields, starts and indices)."""
    for s in range(field_of.size):
        flat = flats[field_of[s]]
        for i in range(starts[s], starts[s + 1]):
            buffer[i] = flat[indices[i]]


@njit(cache=True)
def unpack_strips(buffer, field_of, starts, indices, flats):
    """flats[field_of[s]][indices[i]] = buffer[i] for i in starts[s] .. starts[s + 1] - 1, for
    every segment s."""
    for s in range(field_of.size):
        flat = flats[field_of[s]]
        for i in range(starts[s], starts[s + 1]):
            flat[indices[i]] = buffer[i]


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


def scatter_owned_blocks(comm, source: np.ndarray | None, target: np.ndarray, cuts: np.ndarray) -> None:
    """Each rank receives the rows ``cuts[rank] .. cuts[rank + 1] - 1`` of rank 0's ``source``
    into the same rows of ``target`` (both (NB, ...), C-contiguous, of one shape and dtype;
    ``source`` is read on rank 0 only): one Scatterv."""
    from mpi4py import MPI
    from mpi4py.util.dtlib import from_numpy_dtype

    row = int(np.prod(target.shape[1:], dtype=np.int64))
    lo, hi = int(cuts[comm.rank]), int(cuts[comm.rank + 1])
    kind = from_numpy_dtype(target.dtype)
    received = [_flat(target)[lo * row:hi * row], kind]
    if comm.rank == 0:
        counts = (np.diff(cuts) * row).tolist()
        displacements = (cuts[:-1] * row).tolist()
        comm.Scatterv([_flat(source), (counts, displacements), kind], received, root=0)
    else:
        comm.Scatterv(None, received, root=0)


def _row_bytes(arrays: list[np.ndarray]) -> np.ndarray:
    """The rows of ``arrays`` (each (N, ...), of any dtype) side by side as bytes, (N, W) uint8."""
    n = len(arrays[0])
    return np.concatenate([np.ascontiguousarray(array).reshape(n, int(np.prod(array.shape[1:], dtype=np.int64)))
                           .view(np.uint8) for array in arrays], axis=1)


def _rows_from_bytes(rows: np.ndarray, like: list[np.ndarray]) -> list[np.ndarray]:
    """Arrays shaped and typed as ``like`` (rows beyond the first axis) from the bytes of :func:`_row_bytes`."""
    out, start = [], 0
    for array in like:
        width = int(np.prod(array.shape[1:], dtype=np.int64)) * array.itemsize
        part = np.ascontiguousarray(rows[:, start:start + width])
        out.append(part.view(array.dtype).reshape((len(rows),) + array.shape[1:]))
        start += width
    return out


def hand_over_rows(comm, destination: np.ndarray, arrays: list[np.ndarray]) -> list[np.ndarray] | None:
    """Rows of per-item arrays (tracers) to other ranks: row t of each of ``arrays`` (each
    (N, ...), any dtype, the same N) goes to rank ``destination[t]``.  Returns the arrays of
    the rows this rank holds afterwards: those it kept, in their order, then those it
    received, by sending rank and in that rank's order (the bytes copied, NaN and -0.0
    included); None where it neither sends nor receives a row (it keeps ``arrays``).  One
    Alltoall of the counts, then one message (tag :data:`HANDOVER_TAG`) to each rank it sends
    rows to and from each it receives rows from, the rows as bytes."""
    from mpi4py import MPI

    leaving = destination != comm.rank
    send_counts = np.bincount(destination[leaving], minlength=comm.size).astype(np.int64)
    receive_counts = np.empty(comm.size, dtype=np.int64)
    comm.Alltoall(send_counts, receive_counts)
    if not leaving.any() and not receive_counts.any():
        return None
    order = np.flatnonzero(leaving)[np.argsort(destination[leaving], kind="stable")]
    outgoing = _row_bytes([array[order] for array in arrays])
    width = outgoing.shape[1]
    incoming = np.empty((int(receive_counts.sum()), width), dtype=np.uint8)
    requests = []
    for peer, start, count in zip(range(comm.size), _starts(receive_counts), receive_counts):
        if count:
            requests.append(comm.Irecv([incoming[start:start + count], MPI.BYTE], source=peer, tag=HANDOVER_TAG))
    for peer, start, count in zip(range(comm.size), _starts(send_counts), send_counts):
        if count:
            requests.append(comm.Isend([outgoing[start:start + count], MPI.BYTE], dest=peer, tag=HANDOVER_TAG))
    MPI.Request.Waitall(requests)
    return [np.concatenate([array[~leaving], received])
            for array, received in zip(arrays, _rows_from_bytes(incoming, arrays))]


def gather_item_rows(comm, arrays: list[np.ndarray], everywhere: bool) -> list[np.ndarray] | None:
    """Every rank's rows of per-item arrays (tracers; each (N_rank, ...), any dtype) side by
    side, by rank: on rank 0 (one Gatherv of the rows as bytes), or on every rank with
    ``everywhere`` (one Allgatherv); None on the other ranks."""
    from mpi4py import MPI

    rows = _row_bytes(arrays)
    width = rows.shape[1]
    counts = np.array(comm.allgather(len(rows)), dtype=np.int64) * width
    received = (np.empty((int(counts.sum()) // max(width, 1), width), dtype=np.uint8)
                if everywhere or comm.rank == 0 else None)
    spec = [received, (counts.tolist(), _starts(counts)), MPI.BYTE]
    if everywhere:
        comm.Allgatherv([rows, MPI.BYTE], spec)
    else:
        comm.Gatherv([rows, MPI.BYTE], spec if comm.rank == 0 else None, root=0)
    return None if received is None else _rows_from_bytes(received, arrays)


def move_rows(comm, arrays: list[np.ndarray], sent: list[np.ndarray], received: list[np.ndarray]) -> None:
    """Rows of per-block arrays between ranks, in place: for each of ``arrays`` (each (NB, ...),
    C-contiguous, of the same NB on every rank) the rows ``sent[r]`` (int64 block numbers) go
    to rank r and the rows ``received[r]`` come from rank r into the same rows here (rank r
    sends them in that order).  One Alltoallv per array, through a buffer of the rows sent and
    one of the rows received."""
    from mpi4py.util.dtlib import from_numpy_dtype

    send_rows, receive_rows = np.concatenate(sent), np.concatenate(received)
    send_counts = np.array([len(rows) for rows in sent], dtype=np.int64)
    receive_counts = np.array([len(rows) for rows in received], dtype=np.int64)
    for array in arrays:
        row = int(np.prod(array.shape[1:], dtype=np.int64))
        if row == 0:
            continue
        kind = from_numpy_dtype(array.dtype)
        outgoing = np.ascontiguousarray(array[send_rows])
        incoming = np.empty((len(receive_rows),) + array.shape[1:], dtype=array.dtype)
        comm.Alltoallv([outgoing, (send_counts * row).tolist(), _starts(send_counts * row), kind],
                       [incoming, (receive_counts * row).tolist(), _starts(receive_counts * row), kind])
        array[receive_rows] = incoming


def _starts(counts: np.ndarray) -> list[int]:
    """The displacements of consecutive segments of ``counts`` elements."""
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64).tolist()


def broadcast_arrays(comm, arrays: list[np.ndarray]) -> None:
    """Rank 0's values of ``arrays`` on every rank (in place)."""
    for array in arrays:
        comm.Bcast(_flat(array), root=0)


def _flat(array: np.ndarray) -> np.ndarray:
    """A flat view (no copy) of a C-contiguous array."""
    if not array.flags.c_contiguous:
        raise ValueError("the arrays exchanged between ranks must be C-contiguous")
    return array.reshape(-1)
