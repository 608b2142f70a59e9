"""Eulerian multi-material shock physics on a block mesh (the hydro stage's library).

Public API: :class:`Simulation`, :class:`HydroFailure`, :class:`BlockMesh`,
:class:`HydroState`, the problem registry :data:`PROBLEMS`, snapshot I/O
(:func:`read_snapshot`, :func:`write_snapshot`, :func:`append_snapshot`), Lagrangian
tracers (:class:`Tracers`, tracer I/O :func:`write_tracers`, :func:`read_tracers`,
:func:`read_tracer_history`) and the data contracts :class:`Snapshot` and :class:`TracerSet`.

Rooms, one job each: ``solver`` (the :class:`Simulation` driver: step, CFL, regrid,
checkpoints), ``scheme/`` (the directional sweep kernels, reconstruction, the HLLC face
solver, the time step), ``mesh/`` (blocks, the conserved state, ghost layers), ``amr/``
(refinement criteria, regrid, transfers between levels), ``eos/``, ``strength/``,
``gravity``, ``tracers/`` (placement, block lookup, sampling, motion), ``parallel/`` (one run's
blocks shared between MPI ranks), ``output/``
(snapshot files and the snapshot contract, VTKHDF export, figures, yt), ``budget`` (the
conservation budget), ``problems/`` (each scene with its parameters) and ``exact/`` (exact
solutions of the verification problems).
"""

from impactpipe.hydro.output.io import (
    append_snapshot,
    read_snapshot,
    read_tracer_history,
    read_tracers,
    write_snapshot,
    write_tracers,
)
from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.problems import PROBLEMS
from impactpipe.hydro.output.snapshot import Snapshot, TracerSet
from impactpipe.hydro.solver import HydroFailure, Simulation
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.tracers.motion import Tracers

__all__ = [
    "PROBLEMS", "BlockMesh", "HydroFailure", "HydroState", "Simulation", "Snapshot", "TracerSet", "Tracers",
    "append_snapshot", "read_snapshot", "read_tracer_history", "read_tracers", "write_snapshot", "write_tracers",
]
