"""Stamps that let a step's ghost fill skip the transported scalars a slab already holds.

A block's transported scalars (``arhoq``: stress, plastic strain, damage, a Grady-Kipp
material's flaws) change only where the sweeps move mass that carries them, or where the
stress update writes them.  Inside a body at rest nothing changes them, but a step's ghost
fill (:func:`impactpipe.hydro.mesh.boundary.fill_state_ghost_slabs`) copies every scalar column
of every slab again along each axis: with fracture, 8 flaw columns per material that are not
zero wherever the material is, so the record of the blocks whose scalars are +0.0
(:func:`impactpipe.hydro.mesh.last_good.scalar_clear_blocks`) skips none of them.

The stamps say when a copy would write what the slab holds already:

- ``block[b]`` (int64): raised by every kernel that may have changed block b's interior
  scalars: a sweep where a plain pencil moved scalars or the general update changed the bits
  of one (:func:`impactpipe.hydro.scheme.directional.sweep`), the stress update of a block it
  did not pass over (:func:`impactpipe.hydro.strength.update.update_stress`);
- ``ghost[b, axis, side]`` (int64): the source block's ``block`` stamp when the fill last copied
  the scalars of block b's slab on ``side`` of ``axis`` (the neighbour's, or block b's own at a
  domain face), or -1: unknown.

A slab whose ``ghost`` stamp equals its source's ``block`` stamp holds the scalars the copy would
write, bit for bit: the source has not changed since they were copied, and nothing but the
ghost fills writes a ghost cell of the scalars.  The step keeps stamps only where it keeps the
block record (a uniform mesh in one process) and no kernel outside those two changes the
scalars between steps (no tensile limit at the end of the step, void settling or compaction:
:meth:`impactpipe.hydro.solver.Simulation.step`).  Whatever else changes the state (a restore
of the last-good copy, a change from outside announced by
:meth:`~impactpipe.hydro.solver.Simulation.state_changed`, a new mesh) makes every ghost stamp
unknown (:meth:`ScalarStamps.forget`).
"""

from __future__ import annotations

import numpy as np

#: ``(block, ghost)`` of a fill or kernel without stamps: every slab's scalars are copied.
NO_STAMPS = (np.zeros(0, dtype=np.int64), np.zeros((0, 3, 2), dtype=np.int64))


class ScalarStamps:
    """The ``block`` (NB,) and ``ghost`` (NB, 3, 2) stamps of a mesh of ``nblocks`` blocks
    (module docstring); every ghost stamp starts unknown."""

    def __init__(self, nblocks: int):
        self.block = np.zeros(nblocks, dtype=np.int64)
        self.ghost = np.full((nblocks, 3, 2), -1, dtype=np.int64)

    def forget(self) -> None:
        """Make every ghost stamp unknown: the next fill copies every slab's scalars."""
        self.ghost.fill(-1)
