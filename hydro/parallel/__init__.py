"""One hydro run across several MPI ranks (mpi4py): the block mesh cut into owned block ranges.

Every rank holds the whole mesh and indexes the state by the whole mesh's block numbers, and
advances only the contiguous range of the mesh's Morton-ordered blocks it owns, cut by measured
block costs (:mod:`.decomposition`).  A rank's state arrays commit memory only for its own
blocks and the cells its exchanges write (:mod:`.owned_memory`), on an adaptive mesh through
its regrids too: each rank flags its own blocks, every rank plans the same new mesh, and each
builds its new blocks from the old ones their owners send it.  Before each ghost fill the
ranks exchange the cells that the ghosts of their blocks read from other ranks' blocks:
same-level strips and, on an adaptive mesh, the sources of restriction and prolongation and
the face fluxes before a reflux (:mod:`.exchange`).  The time step and the failure checks are
reductions; a snapshot and a checkpoint are written by every rank together, each its own
blocks' rows, where h5py has parallel HDF5, and else gather each rank's own blocks on rank 0,
as the end of the sharing does (:mod:`.distributed`).  Strength, external gravity and tracers
follow the same ownership (each tracer sample is taken by the owner of the block holding the
point, then gathered on every rank).  The answer is the serial run's bit for bit.  mpi4py is
imported only by the code that talks to other ranks, so without it everything runs as a
single process.
"""
