"""``impactpipe fragments RUN_DIR``: the intact fragments of a run's target in a hydro snapshot.

Reads a snapshot of ``hydro.h5`` (the last, or the one nearest ``time``;
:func:`impactpipe.hydro.output.lookup.find_snapshot`), joins a 3d
half-domain snapshot with its mirror image across y = 0
(:func:`impactpipe.handoff.mirror.mirror_across_y0`, so that a fragment cut by the symmetry
plane counts once, whole), flattens its leaf cells and finds the fragments
(:func:`impactpipe.analysis.fragments.find_fragments`).  The body is the material (or
materials) named, by default the target's; its mass M_T, the reference of every mass
fraction, is the mass of those materials in the first snapshot.  The fragments are written
to ``fragments.h5`` (units, provenance) and their cumulative mass distribution and speeds to
``plots/fragments.png``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from impactpipe import storage
from impactpipe.analysis.fragments import Fragments, find_fragments, intact_cells
from impactpipe.analysis.io import write_analysis
from impactpipe.handoff.mirror import mirror_across_y0
from impactpipe.hydro.output.lookup import find_snapshot
from impactpipe.hydro.output.snapshot import Snapshot

FRAGMENTS_FILE = "fragments.h5"


def body_cells(snapshot: Snapshot, materials: list[int]) -> dict[str, np.ndarray]:
    """The leaf cells of ``snapshot`` as flat arrays: ``center``, ``width`` (N, 3) (m),
    ``mass`` (N,) of the ``materials`` (kg), ``velocity`` (N, 3) (m/s), ``fill`` (N,) their
    volume fraction (-) and ``damage`` (N,) (-; the snapshot's mass-weighted damage)."""
    if "damage" not in snapshot.extra:
        raise ValueError("the snapshot has no damage field: fragments need a run with material strength")
    nb = snapshot.block_lo.shape[0]
    ncell = int(np.prod(snapshot.cells_per_block))
    center = snapshot.block_cell_centers().transpose(0, 2, 3, 4, 1).reshape(nb * ncell, 3)
    width = np.repeat(snapshot.cell_size, ncell, axis=0)
    volume = snapshot.block_cell_volumes().reshape(-1)
    partial = snapshot.partial_density[:, materials].sum(axis=1).reshape(-1)
    return {
        "center": center,
        "width": width,
        "mass": partial * volume,
        "velocity": snapshot.velocity.transpose(0, 2, 3, 4, 1).reshape(nb * ncell, 3),
        "fill": snapshot.volume_fraction[:, materials].sum(axis=1).reshape(-1),
        "damage": snapshot.extra["damage"].reshape(-1),
    }


def body_mass(snapshot: Snapshot, materials: list[int]) -> float:
    """Mass (kg) of the ``materials`` on the mesh of ``snapshot``."""
    volume = snapshot.block_cell_volumes()
    return float((snapshot.partial_density[:, materials].sum(axis=1) * volume).sum())


def snapshot_fragments(snapshot: Snapshot, materials: list[int], half_domain: bool, min_fill: float,
                       max_damage: float) -> Fragments:
    """The fragments of the ``materials`` in ``snapshot`` (mirrored first when ``half_domain``)."""
    whole = mirror_across_y0(snapshot)[0] if half_domain else snapshot
    cells = body_cells(whole, materials)
    intact = intact_cells(cells["fill"], cells["damage"], min_fill, max_damage)
    return find_fragments(cells["center"], cells["width"], cells["mass"], cells["velocity"], intact, whole.ndim)


def intact_fragment_labels(snapshot: Snapshot, min_fill: float, max_damage: float) -> np.ndarray:
    """(NB, nx, ny, nz) the fragment of each cell of a whole (mirrored) ``snapshot``, for the
    hand-off's ``handoff.intact_fragments``: the fragments of all materials larger than one
    block (fewer cells are already a block's sphere or part of one), numbered 0, 1, ... largest
    first, -1 elsewhere."""
    cells = body_cells(snapshot, list(range(len(snapshot.material_names))))
    intact = intact_cells(cells["fill"], cells["damage"], min_fill, max_damage)
    fragments = find_fragments(cells["center"], cells["width"], cells["mass"], cells["velocity"], intact,
                               snapshot.ndim)
    large = fragments.cells > int(np.prod(snapshot.cells_per_block))
    renumber = np.append(np.where(large, np.cumsum(large) - 1, -1), -1)
    return renumber[fragments.label].reshape(snapshot.pressure.shape)


def run_fragments(run_dir: Path, material_names: list[str], half_domain: bool, at_time: float | None,
                  min_fill: float, max_damage: float, resolved_config: str) -> tuple[Fragments, float, Snapshot]:
    """Find the fragments of ``run_dir``'s hydro snapshot and write ``fragments.h5``.

    Returns (fragments, M_T (kg), the snapshot used).  Raises ValueError for a material the
    run does not have or a snapshot without damage.
    """
    started = storage.utc_now()
    t0 = time.perf_counter()
    first, _ = find_snapshot(run_dir, index=0)
    unknown = [name for name in material_names if name not in first.material_names]
    if unknown:
        raise ValueError(f"material {', '.join(unknown)} not in the run (materials: {', '.join(first.material_names)})")
    materials = [first.material_names.index(name) for name in material_names]
    snapshot, _ = find_snapshot(run_dir, time=at_time)
    target_mass = body_mass(first, materials) * (2.0 if half_domain else 1.0)
    fragments = snapshot_fragments(snapshot, materials, half_domain, min_fill, max_damage)
    content = {"fragments": fragments.as_datasets(target_mass),
               "criteria": {"min_fill": (min_fill, "dimensionless", "least volume fraction of the body in a cell"),
                            "max_damage": (max_damage, "dimensionless", "cells at or above this damage are broken"),
                            "time": (snapshot.time, "s", "snapshot time")}}
    attrs = storage.provenance(resolved_config, started, time.perf_counter() - t0)
    attrs["materials"] = ",".join(material_names)
    write_analysis(run_dir / FRAGMENTS_FILE, content, attrs)
    return fragments, target_mass, snapshot
