"""The memory a rank holds: its own blocks and the cells its exchanges write.

The per-block arrays of a run shared between ranks keep the whole mesh's shape and block
numbering on every rank (every kernel and every exchange plan indexes them by block number),
but a rank writes only the rows of the blocks it owns (``cuts[rank] .. cuts[rank + 1] - 1``,
ghosts included) and, through its exchanges, the cells of other ranks' blocks that its ghost
fills and its tracers read (the halo, :mod:`.decomposition`: interior strips and, on an
adaptive mesh, the fine cells of a restriction and the coarse cells, ghosts included, of a
prolongation).  In an anonymous
private mapping (Linux, macOS) a page is committed when it is first written, and a page only
read maps the system's shared zero page; so an array whose other rows are never written holds
about the rank's own rows and its halo in memory, whatever its shape.

The ranks of a run build it together, each its own blocks
(:func:`~.distributed.shared_simulation`, which places them with :func:`placed_rows`), or
rank 0 alone builds it (a script's run, :func:`~.distributed.distribute_from_root`) and sends
the other ranks the outline of its Simulation (:func:`outline`: everything but the per-block arrays of cells, which travel as
their shapes only), from which each rank builds its own Simulation with arrays of zeros that
hold no memory yet (:func:`from_outline`).  :func:`receive_owned_blocks` then gives each rank,
in such arrays, the rows of its own blocks of rank 0's state and of the strength model's
per-block work arrays (one Scatterv each, :func:`~.exchange.scatter_owned_blocks`) and the halo
cells from their owners (one exchange of strips); whatever whole arrays a rank held are
dropped.  Nothing but those rows and cells is written afterwards on that rank; on an adaptive
mesh each regrid builds a rank's new blocks in new such arrays from the old blocks their owners
send it (:meth:`~.distributed.BlockRanges.regrid`).  A run resumed from a checkpoint on
several ranks is not built on rank 0 at all: each rank reads its own rows from the file
(:func:`read_owned_rows`, :meth:`~impactpipe.hydro.solver.Simulation.from_checkpoint`) and
receives its halo (:func:`receive_halos`).  tests/test_owned_memory.py checks that no
other page is written, on a uniform mesh and across an adaptive mesh's regrids, for a run
built or resumed by the ranks together too, and that no rank holds the whole state but rank 0
where it builds or reads the run alone.
"""

from __future__ import annotations

import io
import mmap
import pickle

import numpy as np

from impactpipe.hydro.mesh.state import FIELDS

from .decomposition import Route
from .exchange import SETUP_TAG, StripExchange, Traffic, scatter_owned_blocks


#: The transparent huge page (B) of x86-64 and of arm64 with 4 KiB pages.
HUGE_PAGE = 2 ** 21


def lazy_zeros(shape: tuple[int, ...], dtype=np.float64, dense_rows: tuple[int, int] | None = None) -> np.ndarray:
    """An array of zeros in an anonymous private mapping of its own, whose 4 KiB pages are
    committed when first written; ``np.zeros`` where the platform has no such mapping or the
    array is empty.  Not ``np.zeros``: its ``calloc`` may hand out (and clear) reused heap
    memory, and numpy asks for transparent huge pages on large arrays, where writing one strip
    would commit the 2 MiB around it.  This mapping asks the kernel for none
    (``MADV_NOHUGEPAGE``, where the kernel has the advice; also where huge pages are on for
    every mapping), except over the whole huge pages within rows ``dense_rows[0] ..
    dense_rows[1] - 1`` of the first axis, when given: rows that are written whole, where huge
    pages save the sweeps translation misses (``MADV_HUGEPAGE``)."""
    nbytes = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
    if nbytes == 0 or not hasattr(mmap, "MAP_PRIVATE"):
        return np.zeros(shape, dtype)
    pages = mmap.mmap(-1, nbytes, flags=mmap.MAP_PRIVATE)
    if hasattr(mmap, "MADV_NOHUGEPAGE"):
        pages.madvise(mmap.MADV_NOHUGEPAGE)
        if dense_rows is not None:
            row = nbytes // shape[0]
            start = -(-dense_rows[0] * row // HUGE_PAGE) * HUGE_PAGE
            stop = dense_rows[1] * row // HUGE_PAGE * HUGE_PAGE
            if stop > start:
                pages.madvise(mmap.MADV_HUGEPAGE, start, stop - start)
    return np.frombuffer(pages, dtype=dtype).reshape(shape)


def shared_arrays(sim) -> list[np.ndarray]:
    """The per-block arrays of cells (each (NB, C, ...), float64) that the ranks of ``sim`` share
    out from rank 0: the state and the strength model's work arrays and face stresses."""
    arrays = list(sim.state.arrays().values())
    strength = sim.strength
    if strength is not None:
        arrays.append(strength.work)
        if strength.face is not None:
            arrays.append(strength.face)
    return arrays


def cell_arrays(sim) -> list[np.ndarray]:
    """Every per-block array of cells of ``sim``: :func:`shared_arrays`, the last-good copy
    of the state (which each rank takes from its own blocks) and, on an adaptive mesh, the
    coarse/fine face fluxes of the sweeps and of the stress step (zeros until a step writes
    its own blocks' rows).  The self-gravity potential is allocated at the first step, in the
    partition's own arrays."""
    arrays = shared_arrays(sim) + list(sim._good.values())
    if sim.mesh.adaptive:
        arrays.append(sim._face_flux)
        if sim.strength is not None:
            arrays.append(sim.strength.face_flux)
    return arrays


class _OutlinePickler(pickle.Pickler):
    """Pickles an object with the arrays of ``cells`` as their shape and dtype only."""

    def __init__(self, file, cells: list[np.ndarray]):
        super().__init__(file, protocol=pickle.HIGHEST_PROTOCOL)
        self._cells = {id(array) for array in cells}

    def persistent_id(self, obj):
        if isinstance(obj, np.ndarray) and id(obj) in self._cells:
            return id(obj), obj.shape, obj.dtype.str
        return None


class _OutlineUnpickler(pickle.Unpickler):
    """Unpickles what :class:`_OutlinePickler` wrote, each array of cells a :func:`lazy_zeros`
    (one per array pickled, however often it was referred to)."""

    def __init__(self, file):
        super().__init__(file)
        self._arrays: dict[int, np.ndarray] = {}

    def persistent_load(self, pid):
        key, shape, dtype = pid
        if key not in self._arrays:
            self._arrays[key] = lazy_zeros(shape, np.dtype(dtype))
        return self._arrays[key]


def outline(sim) -> bytes:
    """``sim`` pickled without the values of its arrays of cells (:func:`cell_arrays`): the
    mesh, the materials, the counters, the tracers and the clock, about the size of the mesh's
    per-block tables, not of its cells."""
    out = io.BytesIO()
    _OutlinePickler(out, cell_arrays(sim)).dump(sim)
    return out.getvalue()


def from_outline(data: bytes):
    """The Simulation of an :func:`outline`, its arrays of cells zeros in :func:`lazy_zeros` (no
    memory committed until written)."""
    return _OutlineUnpickler(io.BytesIO(data)).load()


def owned_rows(array: np.ndarray, partition) -> np.ndarray:
    """A :func:`lazy_zeros` array of the shape of the per-block ``array`` (NB, ...) holding rank 0's
    rows of this rank's blocks (``partition``: a :class:`~.distributed.BlockRanges`; huge pages
    within those rows), received in one Scatterv; the other rows are zero and their pages
    uncommitted.  Only rank 0 reads ``array``'s values."""
    kept = lazy_zeros(array.shape, array.dtype, (partition.lo, partition.hi))
    scatter_owned_blocks(partition.comm, array if partition.is_root else None, kept, partition.cuts)
    return kept


def receive_halo(arrays: list[np.ndarray], partition, routes: list[Route]) -> None:
    """Receive the cells of ``routes`` (by peer) of every component of ``arrays`` (NB, C, NX, NY,
    NZ) from the ranks that own them, who send them from their own rows (one exchange of
    strips, its persistent requests freed at the end)."""
    fields = tuple(array for array in arrays if array.size)
    if fields:
        StripExchange(partition.comm, routes, SETUP_TAG).exchange(fields, Traffic())


def receive_owned_blocks(sim, partition) -> None:
    """Replace the per-block arrays of ``sim`` (a Simulation just given its
    ``partition``, a :class:`~.distributed.BlockRanges`) that this rank writes only for its own
    blocks by :func:`owned_rows` of rank 0's: the state and the strength model's work arrays,
    then :func:`receive_halos`, and the face stresses (own rows only: each block updates and
    reads its own faces, :mod:`impactpipe.hydro.strength.face_shear`)."""
    state = sim.state
    for name in FIELDS:  # one array at a time, each whole one dropped before the next is received
        setattr(state, name, owned_rows(getattr(state, name), partition))
    strength = sim.strength
    if strength is not None:
        strength.work = owned_rows(strength.work, partition)
        if strength.face is not None:
            strength.face = owned_rows(strength.face, partition)
    receive_halos(sim, partition)


def receive_halos(sim, partition) -> None:
    """Receive from their owners the halo cells of ``sim``'s state (the ghost fills' strips and
    the tracers' neighbourhood: :attr:`~.distributed.BlockRanges.field_routes`,
    :attr:`~.distributed.BlockRanges.neighbourhood`) and of the strength model's work arrays
    (the strips), every rank holding its own blocks' rows (collective)."""
    fields = list(sim.state.arrays().values())
    receive_halo(fields, partition, partition.field_routes)
    receive_halo(fields, partition, partition.neighbourhood)
    if sim.strength is not None:
        receive_halo([sim.strength.work], partition, partition.field_routes)


def placed_rows(rows: np.ndarray, partition) -> np.ndarray:
    """A :func:`lazy_zeros` array (NB, ...) holding ``rows`` (this rank's blocks', (B, ...)) at
    their place in the mesh (``partition``: a :class:`~.distributed.BlockRanges`; huge pages
    within them), the other rows zero and uncommitted."""
    placed = lazy_zeros((partition.nblocks,) + rows.shape[1:], rows.dtype, (partition.lo, partition.hi))
    placed[partition.blocks] = rows
    return placed


def read_owned_rows(dataset, partition) -> np.ndarray:
    """The per-block array of the HDF5 ``dataset`` (NB, ...): whole without a ``partition``; with
    one (a :class:`~.distributed.BlockRanges`), a :func:`lazy_zeros` array of its shape holding
    only this rank's rows, read from the file (huge pages within them), the others zero and
    uncommitted."""
    if partition is None:
        return dataset[()]
    kept = lazy_zeros(dataset.shape, dataset.dtype, (partition.lo, partition.hi))
    rows = np.s_[partition.lo : partition.hi]
    if kept.size:
        dataset.read_direct(kept, rows, rows)
    return kept
