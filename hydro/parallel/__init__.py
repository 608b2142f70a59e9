"""One hydro run across several MPI ranks (mpi4py): the block mesh cut into owned block ranges.

Every rank holds the whole mesh and state (replicated arrays) and advances only the contiguous
block range it owns (:mod:`.decomposition`); before each ghost fill the ranks exchange the
interior strips that their neighbours' ghosts copy (:mod:`.exchange`); the time step is one
reduction, and before any output every rank receives every block (:mod:`.distributed`).
Every rank holds every tracer; each tracer sample is taken by the owner of the block holding
the point, after an exchange of the cells within one cell of each rank's blocks, and then
gathered on every rank.  The answer is the serial run's bit for bit.  mpi4py is imported only
by the code that talks to other ranks, so without it everything runs as a single process.
"""
