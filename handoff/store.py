"""handoff.h5: the particle table and the hand-off budget on disk.

Layout (every dataset carries a ``units`` attribute):

    /            attributes: the caller's ``attrs`` (provenance)
    /particles/  one dataset per ParticleSet field, units from PARTICLE_UNITS
    /budget/     one dataset per HandoffBudget number, units from BUDGET_UNITS;
                 attributes ``geometry`` and ``mirrored_y0``; fields that are None are not written
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import fields
from typing import Any

import h5py
import numpy as np

from impactpipe.handoff.budget import BUDGET_UNITS, HandoffBudget
from impactpipe.handoff.particles import PARTICLE_UNITS, ParticleSet
from impactpipe.storage import atomic_path, write_dataset, write_provenance

#: HandoffBudget fields stored as attributes of /budget rather than datasets.
_ATTRIBUTES = ("geometry", "mirrored_y0")


def write_particles(path: str | os.PathLike, particles: ParticleSet, budget: HandoffBudget,
                    attrs: Mapping[str, Any]) -> None:
    """Write the particles and the budget to ``path`` atomically (see the module docstring)."""
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as h5:
            write_provenance(h5, attrs)
            group = h5.create_group("particles")
            for f in fields(ParticleSet):
                write_dataset(group, f.name, getattr(particles, f.name), PARTICLE_UNITS[f.name])
            group = h5.create_group("budget")
            group.attrs["geometry"] = budget.geometry
            group.attrs["mirrored_y0"] = budget.mirrored_y0
            for f in fields(HandoffBudget):
                value = getattr(budget, f.name)
                if f.name not in _ATTRIBUTES and value is not None:
                    write_dataset(group, f.name, value, BUDGET_UNITS[f.name])


#: ParticleSet fields that hand-off files written before them lack, with the value they read as
#: there: the distension, unknown (NaN).
LATER_FIELDS = {"distension": np.nan}


def read_particles(path: str | os.PathLike) -> ParticleSet:
    """The ParticleSet stored in a handoff.h5 file (units checked against PARTICLE_UNITS).

    Example, on the quickstart's run directory (:func:`impactpipe.pipeline.run`)::

        >>> from impactpipe.handoff import read_particles
        >>> particles = read_particles("runs/quickstart/handoff.h5")
        >>> particles.position.shape[1], bool((particles.mass > 0).all())
        (3, True)
    """
    with h5py.File(path, "r") as h5:
        group = h5["particles"]
        values = {f.name: _read(group, f.name, PARTICLE_UNITS[f.name]) for f in fields(ParticleSet)
                  if f.name not in LATER_FIELDS or f.name in group}
        for name in set(LATER_FIELDS) - set(values):
            values[name] = np.full(group["mass"].shape, LATER_FIELDS[name])
        return ParticleSet(**values)


def read_budget(path: str | os.PathLike) -> HandoffBudget:
    """The HandoffBudget stored in a handoff.h5 file (units checked against BUDGET_UNITS)."""
    values: dict[str, Any] = {}
    with h5py.File(path, "r") as h5:
        group = h5["budget"]
        values["geometry"] = str(group.attrs["geometry"])
        values["mirrored_y0"] = bool(group.attrs.get("mirrored_y0", False))
        for f in fields(HandoffBudget):
            if f.name in _ATTRIBUTES:
                continue
            if f.name not in group:
                values[f.name] = None
                continue
            value = _read(group, f.name, BUDGET_UNITS[f.name])
            if np.ndim(value) > 0:
                values[f.name] = value
            elif np.issubdtype(np.asarray(value).dtype, np.integer):
                values[f.name] = int(value)
            else:
                values[f.name] = float(value)
    return HandoffBudget(**values)


def _read(group: h5py.Group, name: str, units: str) -> np.ndarray:
    """Dataset ``name`` of ``group`` as an array, after checking its ``units`` attribute."""
    dset = group[name]
    found = dset.attrs.get("units")
    if found != units:
        raise ValueError(f"{dset.name}: units {found!r}, expected {units!r}")
    return dset[()]
