"""Which blocks the last-good copy of a step must copy (:meth:`impactpipe.hydro.solver.Simulation._save_good`).

The last-good copy holds the interior cells of the six conserved fields
(:mod:`impactpipe.hydro.mesh.state`) as they were at the start of the step, for
:meth:`~impactpipe.hydro.solver.Simulation.restore_last_good`.  A void block whose copy is
void already need not be copied again: one whose alpha_k, alpha_k rho_k, alpha_k rho_k e_k,
momentum and total energy are +0.0 in every interior cell now and were at the copy.  Its
transported scalars ``arhoq`` are 0 as well, then and now: a cell without mass holds none,
since every kernel that removes a material's last mass zeroes its scalars with it (the
invariant the sweeps' empty-pencil test rests on,
:func:`impactpipe.hydro.scheme.plain_pencils.plain_material`).  :func:`void_blocks` tests
the blocks on int64 views of the float64 fields, so +0.0 is tested by its bits (a -0.0 is not
void); the void half of an impact's blocks then costs a read of its 3 M + 4 columns instead
of a copy of all 3 M + 4 + M NQ.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

#: Codes of the per-block record a step keeps on a uniform mesh in one process
#: (:meth:`impactpipe.hydro.solver.Simulation.step`): a block's transported scalars are +0.0
#: (:func:`scalar_clear_blocks`) ...
RECORD_CLEAR = 1
#: ... or the block is void (:func:`void_blocks`; its scalars are then +0.0 too), every conserved
#: field +0.0 in every cell, ghosts included, at the start of the step and, along the later axes,
#: its interior unchanged by the sweeps before (:func:`impactpipe.hydro.scheme.directional.sweep`).
RECORD_VOID = 2
#: ``known`` of :func:`void_blocks` and :func:`scalar_clear_blocks` without a record: every block is looked at.
NONE_KNOWN = np.zeros(0, dtype=np.uint8)


@njit(cache=True, parallel=True)
def void_blocks(alpha, arho, arhoe, mom, energy, lo, hi, void, known):
    """``void[b]`` = 1 where block b of ``lo .. hi - 1`` is void (module docstring), else 0.

    The fields are int64 views of the padded float64 fields ``(NB, C, NX, NY, NZ)``.  A block
    counts as void when its ghosts are +0.0 as well: a void block next to material (whose
    ghosts hold it) is copied although it need not be, and the test reads each block's
    fields as one contiguous run, several times faster than picking out the interior rows.
    The partial densities are read first: a block holding material stops there.

    ``known`` (uint8, (NB,), or empty): the blocks known to be void without a look, where the
    last step's sweeps found every pencil empty (RECORD_VOID after its last sweep: interior and
    ghost slabs +0.0) and nothing wrote to them since
    (:meth:`impactpipe.hydro.solver.Simulation.step`).  Such a block is void but for the corner
    cells of its padding, which no kernel reads or writes.
    """
    knows = known.shape[0] > 0
    for b in prange(lo, hi):
        if knows and known[b] != 0:
            void[b] = 1
            continue
        empty = (_zero_run(arho[b]) and _zero_run(alpha[b]) and _zero_run(arhoe[b]) and _zero_run(energy[b])
                 and _zero_run(mom[b]))
        void[b] = 1 if empty else 0


@njit(cache=True, parallel=True)
def scalar_clear_blocks(arhoq, void, lo, hi, clear, hint, known):
    """``clear[b]`` = 1 where the transported scalars of block b of ``lo .. hi - 1`` are +0.0 in
    its interior and in the ghost layers a step's ghost fill writes of them
    (:func:`impactpipe.hydro.scheme.pencil_layout.transport_ghost_layers`), else 0; ``arhoq`` an
    int64 view of the padded scalars ``(NB, M NQ, NX, NY, NZ)``, ``void`` from :func:`void_blocks`.

    A void block is clear: its interior cells hold no mass, so no scalars, and each ghost layer
    of its scalars was written with that of its partial densities, from a cell that held no
    mass either.  Another block is clear when every scalar of it, ghosts included, is +0.0
    (its bits: a -0.0 is not), tested like :func:`void_blocks` (a layer that no fill writes
    counts too, so a block whose unread layer keeps an old value is not clear, which costs
    only the skips).  Right after an impact's contact most of the target is clear; the ghost
    fills, the sweeps and the last-good copy then need not move its scalars
    (:meth:`impactpipe.hydro.solver.Simulation.step`).

    ``hint[b]`` (int64, (NB,)): a column of block b that held a value other than +0.0 at the last
    call that found one, or -1.  That column is tested first, alone: where it still holds one
    the block is not clear without a look at its other columns.  A material's flaws (Grady-Kipp)
    or distension (porosity) are not zero wherever it is, and a block holding it is never clear:
    one column of it is read instead of all.  The record is the same whatever the hints.

    ``known`` (uint8, (NB,), or empty): the blocks known to be clear without a look, where the
    last step's sweeps left the block clear (its record after the last sweep not 0) and the
    stress update passed over it (its scalar stamp unchanged,
    :meth:`impactpipe.hydro.solver.Simulation.step`): every scalar of it, ghosts included, is
    still the +0.0 the step began with.
    """
    knows = known.shape[0] > 0
    for b in prange(lo, hi):
        if void[b] != 0 or (knows and known[b] != 0):
            clear[b] = 1
            continue
        h = hint[b]
        if h >= 0 and not _zero_run(arhoq[b, h]):
            clear[b] = 0
            continue
        if _zero_run(arhoq[b]):
            clear[b] = 1
            continue
        clear[b] = 0
        for c in range(arhoq.shape[1]):
            if not _zero_run(arhoq[b, c]):
                hint[b] = c
                break


@njit(cache=True, inline="always")
def _zero_run(field):
    """Whether every element of ``field`` (an int64 view of floats, C-contiguous: one block's
    scalars or one column of them, ghosts included) is +0.0: the bits of the whole run or-ed
    together, then tested (a loop that LLVM vectorizes; one that tests as it goes is not, and
    took several times as long)."""
    run = field.reshape(field.size)
    bits = 0
    for i in range(run.size):
        bits |= run[i]
    return bits == 0


def block_runs(copy: np.ndarray) -> list[tuple[int, int]]:
    """The runs ``(start, stop)`` of consecutive blocks where ``copy`` (bool, (NB,)) holds."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], copy.view(np.int8), [0]))))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist()))
