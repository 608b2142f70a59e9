"""Eulerian multi-material shock physics on a block mesh (the hydro stage's library).

Public API: :class:`Simulation`, :class:`HydroFailure`, :class:`BlockMesh`,
:class:`HydroState`, the problem registry :data:`PROBLEMS`, snapshot I/O
(:func:`read_snapshot`, :func:`write_snapshot`, :func:`append_snapshot`), Lagrangian
tracers (:class:`Tracers`, tracer I/O :func:`write_tracers`, :func:`read_tracers`,
:func:`read_tracer_history`) and the data contracts :class:`Snapshot` and :class:`TracerSet`.
"""

from impactpipe.hydro.io import (
    append_snapshot,
    read_snapshot,
    read_tracer_history,
    read_tracers,
    write_snapshot,
    write_tracers,
)
from impactpipe.hydro.mesh import BlockMesh
from impactpipe.hydro.problems import PROBLEMS
from impactpipe.hydro.snapshot import Snapshot, TracerSet
from impactpipe.hydro.solver import HydroFailure, Simulation
from impactpipe.hydro.state import HydroState
from impactpipe.hydro.tracers import Tracers

__all__ = [
    "PROBLEMS", "BlockMesh", "HydroFailure", "HydroState", "Simulation", "Snapshot", "TracerSet", "Tracers",
    "append_snapshot", "read_snapshot", "read_tracer_history", "read_tracers", "write_snapshot", "write_tracers",
]
