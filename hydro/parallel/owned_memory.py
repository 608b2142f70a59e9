"""The memory a rank holds on a uniform mesh: its own blocks and the cells its exchanges write.

The per-block arrays of a run shared between ranks keep the whole mesh's shape and block
numbering on every rank (every kernel and every exchange plan indexes them by block number),
but a rank writes only the rows of the blocks it owns (``cuts[rank] .. cuts[rank + 1] - 1``,
ghosts included) and, through its exchanges, the interior strips of other ranks' blocks that
its ghost fills and its tracers read (the halo, :mod:`.decomposition`).  In an anonymous
private mapping (Linux, macOS) a page is committed when it is first written, and a page only
read maps the system's shared zero page; so an array whose other rows are never written holds
about the rank's own rows and its halo in memory, whatever its shape.

:func:`keep_owned_blocks` moves a distributed Simulation's state, and the strength model's
per-block work arrays, into such arrays (:func:`owned_copy`): the rows of the rank's own
blocks and the halo cells are copied from the arrays every rank built (and rank 0's values
broadcast into), and the old arrays are dropped.  Nothing but those rows and cells is written
afterwards on that rank (tests/test_owned_memory.py checks that no other page is written).
"""

from __future__ import annotations

import mmap

import numpy as np

from impactpipe.hydro.mesh.state import FIELDS

from .decomposition import Route


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


def owned_copy(array: np.ndarray, lo: int, hi: int, routes: list[Route]) -> np.ndarray:
    """A copy of the per-block ``array`` (NB, C, NX, NY, NZ) in :func:`lazy_zeros` (huge pages
    within rows ``lo .. hi - 1``) holding only those rows (ghosts included) and the cells the
    ``routes`` receive (every component); the other rows and cells are zero and their pages
    uncommitted."""
    kept = lazy_zeros(array.shape, array.dtype, (lo, hi))
    kept[lo:hi] = array[lo:hi]
    if routes and array.shape[1]:
        source, target = array.reshape(-1), kept.reshape(-1)
        for route in routes:
            index = route.receive.indices(array)
            target[index] = source[index]
    return kept


def keep_owned_blocks(sim, partition) -> None:
    """Replace the per-block arrays of ``sim`` (a Simulation on a uniform mesh just given its
    ``partition``, a :class:`~.distributed.BlockRanges`) that this rank writes only for its own
    blocks by :func:`owned_copy`: the state, kept with the cells of the ghost fills' strips and
    of the tracers' neighbourhood (:attr:`~.distributed.BlockRanges.routes`,
    :attr:`~.distributed.BlockRanges.neighbourhood`), and the strength model's work arrays
    (with the strips) and face stresses (own rows only: each block updates and reads its own
    faces, :mod:`impactpipe.hydro.strength.face_shear`)."""
    lo, hi = partition.lo, partition.hi
    strips = [route for routes in partition.routes for route in routes]
    for name in FIELDS:  # one array at a time, each whole one dropped before the next is copied
        setattr(sim.state, name, owned_copy(getattr(sim.state, name), lo, hi, strips + partition.neighbourhood))
    strength = sim.strength
    if strength is not None:
        strength.work = owned_copy(strength.work, lo, hi, strips)
        if strength.face is not None:
            strength.face = owned_copy(strength.face, lo, hi, [])
