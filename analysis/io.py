"""analysis.h5: the analysis results with units on every dataset.

Layout: nested groups of datasets.  :func:`write_analysis` takes a nested mapping
whose leaves are ``(value, units)`` or ``(value, units, description)`` tuples
(the ``as_datasets()`` methods of the result objects return such mappings), so a
dataset cannot be written without units.  Root attributes carry provenance
(:func:`impactpipe.storage.provenance`) and any other string metadata.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from impactpipe.storage import atomic_path, write_dataset, write_provenance


@dataclass
class AnalysisData:
    """Contents of an analysis.h5 file.

    Attributes:
        data: nested dict of numpy arrays (0-d arrays for scalars), by group.
        units: "group/name" -> units string for every dataset.
        attrs: root attributes (provenance).
    """

    data: dict[str, Any]
    units: dict[str, str]
    attrs: dict[str, Any]

    def __getitem__(self, key: str) -> Any:
        """The dataset or group at a "/"-separated path, e.g. ``"remnants/mass"``."""
        node: Any = self.data
        for part in key.strip("/").split("/"):
            node = node[part]
        return node


def _write_group(group: h5py.Group, content: Mapping[str, Any], prefix: str) -> None:
    for name, value in content.items():
        if isinstance(value, Mapping):
            _write_group(group.create_group(name), value, f"{prefix}{name}/")
        elif isinstance(value, tuple) and len(value) in (2, 3) and isinstance(value[1], str):
            write_dataset(group, name, value[0], value[1], value[2] if len(value) == 3 else None)
        else:
            raise TypeError(f"{prefix}{name}: leaves must be (value, units) or (value, units, description) tuples")


def write_analysis(path: str | os.PathLike, content: Mapping[str, Any],
                   attrs: Mapping[str, str] | None = None) -> Path:
    """Write ``content`` to the HDF5 file ``path`` atomically.

    Args:
        path: output file (analysis.h5).
        content: nested mapping group name -> mapping, dataset name ->
            (value, units[, description]); units use yt-style strings ("kg", "m/s",
            "J/kg", "Pa", "dimensionless").
        attrs: root attributes, e.g. ``impactpipe.storage.provenance(...)``.
    """
    with atomic_path(path) as tmp:
        with h5py.File(tmp, "w") as fh:
            _write_group(fh, content, "")
            if attrs:
                write_provenance(fh, attrs)
    return Path(path)


def _read_group(group: h5py.Group, prefix: str, units: dict[str, str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, item in group.items():
        if isinstance(item, h5py.Group):
            out[name] = _read_group(item, f"{prefix}{name}/", units)
        else:
            value = item[()]
            out[name] = value.decode() if isinstance(value, bytes) else np.asarray(value)
            units[f"{prefix}{name}"] = str(item.attrs["units"])
    return out


def read_analysis(path: str | os.PathLike) -> AnalysisData:
    """Read an analysis.h5 file written by :func:`write_analysis`.

    Example, on the quickstart's run directory (:func:`impactpipe.pipeline.run`)::

        >>> from impactpipe.analysis import read_analysis
        >>> analysis = read_analysis("runs/quickstart/analysis.h5")
        >>> analysis.units["energies/Q"]
        'J/kg'
        >>> round(float(analysis["energies/Q"]), 2)
        31.25
    """
    units: dict[str, str] = {}
    with h5py.File(path, "r") as fh:
        data = _read_group(fh, "", units)
        attrs = {key: fh.attrs[key] for key in fh.attrs}
    return AnalysisData(data=data, units=units, attrs=attrs)
