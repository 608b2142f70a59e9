"""Snapshot I/O: ``hydro.h5`` holds snapshots under ``/snapshots/<index:04d>``.

Each snapshot group carries the attributes ``time`` (s), ``geometry`` and
``material_names`` (JSON list) and one dataset per :class:`~impactpipe.hydro.output.snapshot.Snapshot`
array, each with a ``units`` attribute (:func:`impactpipe.storage.write_dataset`).
Extra fields go to ``extra/<name>`` with the units and description of
:data:`EXTRA_UNITS` (the material-strength fields and the distension), or ``units = "unspecified"`` for any other.

Tracers go to the group ``/tracers``: one dataset per
:class:`~impactpipe.hydro.output.snapshot.TracerSet` field and, when written from a
:class:`~impactpipe.hydro.tracers.motion.Tracers` with a history, ``history_time`` (K,) and
``history_position`` (K, N, 3), all with ``units`` attributes.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from impactpipe.hydro.output.snapshot import Snapshot, TracerSet
from impactpipe.hydro.tracers.motion import HISTORY_UNITS, TRACER_UNITS, Tracers
from impactpipe.storage import write_dataset

SNAPSHOT_GROUP = "snapshots"
TRACER_GROUP = "tracers"

#: Extra snapshot fields written when material strength is on (hydro/strength/model.py).
EXTRA_UNITS = {
    **{f"deviatoric_stress_{c}": ("Pa", f"mixture deviatoric stress sum_k alpha_k S_k,{c} (2d-cylindrical: "
                                        "xx = rr, yy = zz, zz = theta-theta, xy = rz)")
       for c in ("xx", "yy", "zz", "xy", "xz", "yz")},
    "von_mises_stress": ("Pa", "von Mises equivalent stress sqrt(3/2 S:S) of the mixture deviatoric stress"),
    "plastic_strain": ("dimensionless", "mass-weighted equivalent plastic strain of the materials with strength"),
    "damage": ("dimensionless", "mass-weighted damage D (0 intact, 1 failed) of the materials with strength"),
    "distension": ("dimensionless", "mass-weighted distension rho_solid / rho of the porous materials (0: none)"),
}

#: Snapshot array fields with their units and descriptions.
FIELD_UNITS = {
    "block_lo": ("m", "lower corner of each block"),
    "block_hi": ("m", "upper corner of each block"),
    "block_level": ("dimensionless", "refinement level of each block"),
    "block_id": ("dimensionless", "stable block id"),
    "partial_density": ("kg/m**3", "alpha_k rho_k per material"),
    "volume_fraction": ("dimensionless", "alpha_k per material"),
    "velocity": ("m/s", "cell velocity, 3 components"),
    "specific_internal_energy": ("J/kg", "mass-weighted mean over materials"),
    "pressure": ("Pa", "volume-fraction-weighted mean pressure"),
    "temperature": ("K", "mass-weighted mean temperature"),
    "sound_speed": ("m/s", "cell signal speed used for the time step"),
}


def snapshot_name(index: int) -> str:
    """Group path of snapshot ``index``."""
    return f"{SNAPSHOT_GROUP}/{index:04d}"


def write_snapshot(group: h5py.Group, snapshot: Snapshot, rows: slice | None = None) -> None:
    """Write ``snapshot`` into an (empty) h5py group.  In a file that several MPI processes write
    together (:func:`impactpipe.storage.written_together`) each writes the block rows ``rows``
    of every array (its own blocks; :func:`impactpipe.storage.store_array`)."""
    group.attrs["time"] = float(snapshot.time)
    group.attrs["geometry"] = snapshot.geometry
    group.attrs["material_names"] = json.dumps(list(snapshot.material_names))
    for name, (units, description) in FIELD_UNITS.items():
        write_dataset(group, name, getattr(snapshot, name), units, description, rows)
    if snapshot.extra:
        extra = group.create_group("extra")
        for name, arr in snapshot.extra.items():
            units, description = EXTRA_UNITS.get(name, ("unspecified", ""))
            write_dataset(extra, name, arr, units, description, rows)


def append_snapshot(h5file: h5py.File, snapshot: Snapshot, rows: slice | None = None) -> int:
    """Write ``snapshot`` as the next ``/snapshots/<index>`` of an open file; returns the index
    (``rows``: see :func:`write_snapshot`)."""
    root = h5file.require_group(SNAPSHOT_GROUP)
    index = len(root)
    write_snapshot(h5file.create_group(snapshot_name(index)), snapshot, rows)
    return index


def snapshot_count(path: str | Path) -> int:
    """Number of snapshots in ``path``."""
    with h5py.File(path, "r") as fh:
        return len(fh[SNAPSHOT_GROUP]) if SNAPSHOT_GROUP in fh else 0


def read_snapshot(path: str | Path, index: int = -1) -> Snapshot:
    """Read snapshot ``index`` (negative counts from the last) from a ``hydro.h5`` file.

    Example, on the quickstart's run directory (:func:`impactpipe.pipeline.run`)::

        >>> from impactpipe.hydro import read_snapshot
        >>> snapshot = read_snapshot("runs/quickstart/hydro.h5", index=-1)
        >>> snapshot.geometry, snapshot.material_names
        ('2d-cylindrical', ['basalt', 'basalt (projectile)'])
        >>> bool(snapshot.time > 0.0)
        True
    """
    with h5py.File(path, "r") as fh:
        if SNAPSHOT_GROUP not in fh or len(fh[SNAPSHOT_GROUP]) == 0:
            raise KeyError(f"{path}: no snapshots")
        names = sorted(fh[SNAPSHOT_GROUP].keys())
        try:
            grp = fh[SNAPSHOT_GROUP][names[index]]
        except IndexError:
            raise IndexError(f"{path}: snapshot index {index} out of range ({len(names)} snapshots)") from None
        fields = {name: np.asarray(grp[name][()]) for name in FIELD_UNITS}
        extra = {name: np.asarray(ds[()]) for name, ds in grp["extra"].items()} if "extra" in grp else {}
        geometry = grp.attrs["geometry"]
        return Snapshot(
            time=float(grp.attrs["time"]),
            geometry=geometry.decode() if isinstance(geometry, bytes) else str(geometry),
            material_names=json.loads(grp.attrs["material_names"]),
            extra=extra,
            **fields,
        )


def write_tracers(h5file: h5py.File, tracers: Tracers | TracerSet) -> None:
    """Write tracer records into ``/tracers`` of an open file, replacing a previous ``/tracers``.

    ``tracers`` is a :class:`~impactpipe.hydro.tracers.motion.Tracers` (its trajectory history is
    written too) or a :class:`~impactpipe.hydro.output.snapshot.TracerSet`.
    """
    history = None
    if isinstance(tracers, Tracers):
        history = tracers.history
        tracers = tracers.to_tracer_set()
    if TRACER_GROUP in h5file:
        del h5file[TRACER_GROUP]
    group = h5file.create_group(TRACER_GROUP)
    for name, (units, description) in TRACER_UNITS.items():
        write_dataset(group, name, getattr(tracers, name), units, description)
    if history is not None:
        for name, values in zip(HISTORY_UNITS, history):
            write_dataset(group, name, values, *HISTORY_UNITS[name])


def read_tracers(path: str | Path) -> TracerSet | None:
    """The :class:`~impactpipe.hydro.output.snapshot.TracerSet` in ``/tracers`` of ``path``, or None without one."""
    with h5py.File(path, "r") as fh:
        if TRACER_GROUP not in fh:
            return None
        group = fh[TRACER_GROUP]
        fields = {name: np.asarray(group[name][()]) for name in TRACER_UNITS}
    fields["exited"] = fields["exited"].astype(np.bool_)
    return TracerSet(**fields)


def read_tracer_history(path: str | Path) -> tuple[np.ndarray, np.ndarray] | None:
    """(times (K,) s, positions (K, N, 3) m) of the tracer trajectories in ``path``, or None without."""
    with h5py.File(path, "r") as fh:
        if TRACER_GROUP not in fh or "history_time" not in fh[TRACER_GROUP]:
            return None
        group = fh[TRACER_GROUP]
        return np.asarray(group["history_time"][()]), np.asarray(group["history_position"][()])
