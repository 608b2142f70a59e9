"""Eulerian multi-material shock physics on a block mesh (the hydro stage's library).

Public API: :class:`Simulation`, :class:`HydroFailure`, :class:`BlockMesh`,
:class:`HydroState`, the problem registry :data:`PROBLEMS`, snapshot I/O
(:func:`read_snapshot`, :func:`write_snapshot`, :func:`append_snapshot`) and the data
contract :class:`Snapshot`.
"""

from impactpipe.hydro.io import append_snapshot, read_snapshot, write_snapshot
from impactpipe.hydro.mesh import BlockMesh
from impactpipe.hydro.problems import PROBLEMS
from impactpipe.hydro.snapshot import Snapshot, TracerSet
from impactpipe.hydro.solver import HydroFailure, Simulation
from impactpipe.hydro.state import HydroState

__all__ = [
    "PROBLEMS", "BlockMesh", "HydroFailure", "HydroState", "Simulation", "Snapshot", "TracerSet",
    "append_snapshot", "read_snapshot", "write_snapshot",
]
