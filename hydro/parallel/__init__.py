"""One hydro run across several MPI ranks (mpi4py): the block mesh cut into owned block ranges.

Every rank holds the whole mesh and state (replicated arrays) and advances only the contiguous
range of the mesh's Morton-ordered blocks it owns, cut by measured block costs
(:mod:`.decomposition`).  Before each ghost fill the ranks exchange the cells that the ghosts
of their blocks read from other ranks' blocks: same-level strips and, on an adaptive mesh, the
sources of restriction and prolongation and the face fluxes before a reflux (:mod:`.exchange`).
The time step and the failure checks are reductions; a snapshot gathers each rank's own
blocks' fields on rank 0, and a checkpoint or a regrid gives every rank every block
(:mod:`.distributed`).  Strength, external gravity and tracers follow the same ownership (each
tracer sample is taken by the owner of the block holding the point, then gathered on every
rank).  The answer is the serial run's bit for bit.  mpi4py is imported only by the code that
talks to other ranks, so without it everything runs as a single process.
"""
