"""Open hydro snapshots in yt (``pip install "impactpipe[viz]"``).

    import yt
    from impactpipe.hydro.output.yt_loader import load

    ds = load("runs/quickstart", time=1.0)   # the nearest snapshot; or index=-1, or a hydro.h5 path
    ds.all_data().quantities.total_quantity(("gas", "mass"))   # kg
    yt.SlicePlot(ds, "theta", ("gas", "pressure"), origin="native").save()   # the r-z plane

How: ``yt.load_amr_grids`` with one yt grid per mesh block.  A snapshot holds only the
leaf blocks of the block quadtree / octree, and yt's grid hierarchy needs every level-L
grid nested in a level-(L-1) grid, so the ancestors of the leaves are rebuilt by
:func:`impactpipe.hydro.output.hierarchy.complete_hierarchy` (conservative averages of their
children: by volume for per-volume fields, by mass for per-mass fields).  yt masks every
cell covered by a finer grid, so selections, totals, slices and projections see the leaf
cells only, each once; the ancestors' averages appear only in data yt builds at a coarser
level (``ds.covering_grid(level=0, ...)``), where they keep mass, momentum and internal
energy.  (``yt.load_octree`` would take the leaves directly but, as its documentation
says, fluid fields may not work with it.)

Geometry and units: code units are SI (code_length = m, code_mass = kg, code_time = s,
``unit_system="mks"``) and ``ds.current_time`` is the snapshot time.  1d-planar, 2d-planar
and 3d load as "cartesian" (a 2d-planar run has its 1 m depth as the z extent, a 1d run
1 m in y and z, so yt's cell volumes are the snapshot's); 2d-cylindrical loads as
"cylindrical" with yt's axis order (r, z, theta), dimensions [nr, nz, 1] and theta over
[0, 2 pi], so yt's cell volumes are the full annuli pi (r+^2 - r-^2) dz.

Fields (:func:`impactpipe.hydro.output.hierarchy.cell_fields`), each as ``("stream", name)``
and ``("gas", name)``: density, pressure (kg/m**3, Pa), velocity_x/_y/_z (velocity_r/_z/
_theta in r-z; m/s), specific_internal_energy (J/kg, also ``("gas",
"specific_thermal_energy")``), temperature (K), sound_speed (m/s; the EOS's, replacing
yt's ideal-gas ``("gas", "sound_speed")``), partial_density_<material> (kg/m**3),
volume_fraction_<material> (dimensionless) and the snapshot's extra fields (stresses in
Pa, plastic_strain, damage).  <material> is the material name in lower case with other
characters as ``_`` ("basalt (projectile)" -> "basalt_projectile"); the list is in
``ds.parameters["material_fields"]`` beside ``ds.parameters["material_names"]``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from impactpipe.hydro.output.hierarchy import complete_hierarchy, material_field_names
from impactpipe.hydro.output.snapshot import Snapshot
from impactpipe.hydro.output.lookup import find_snapshot

try:
    import yt
except ImportError as exc:  # yt is an optional dependency
    raise ImportError('impactpipe.hydro.output.yt_loader needs yt: pip install "impactpipe[viz]"') from exc

#: yt's name for a geometry, and the extent (lo, hi) yt gets on the unused axes.
YT_GEOMETRY = {
    "1d-planar": ("cartesian", ((0.0, 1.0), (0.0, 1.0))),
    "2d-planar": ("cartesian", ((0.0, 1.0),)),
    "2d-cylindrical": ("cylindrical", ((0.0, 2.0 * np.pi),)),
    "3d": ("cartesian", ()),
}

#: ``("gas", alias)`` fields that stand for one of the snapshot's fields.
GAS_ALIASES = {"specific_thermal_energy": "specific_internal_energy"}


def load(path_or_run_dir: str | Path, time: float | None = None, index: int | None = None):
    """A yt dataset of one snapshot of a run directory or ``hydro.h5`` file.

    ``time`` (s) picks the snapshot nearest to it, ``index`` picks by position (negative
    counts from the last); with neither, the last snapshot (see the module docstring).
    """
    snapshot, found = find_snapshot(path_or_run_dir, time=time, index=index)
    return to_yt(snapshot, dataset_name=f"{path_or_run_dir}:snapshot{found:04d}")


def to_yt(snapshot: Snapshot, dataset_name: str = "impactpipe snapshot"):
    """A yt dataset of ``snapshot`` (geometry, units and fields in the module docstring)."""
    hierarchy = complete_hierarchy(snapshot)
    geometry, unused_extent = YT_GEOMETRY[snapshot.geometry]
    ndim = snapshot.ndim
    lo = np.concatenate([hierarchy.domain_lo[:ndim], [e[0] for e in unused_extent]])
    hi = np.concatenate([hierarchy.domain_hi[:ndim], [e[1] for e in unused_extent]])
    grids = []
    for g in range(len(hierarchy.level)):
        grid = {
            "left_edge": np.concatenate([hierarchy.lo[g, :ndim], lo[ndim:]]),
            "right_edge": np.concatenate([hierarchy.hi[g, :ndim], hi[ndim:]]),
            "level": int(hierarchy.level[g]),
            "dimensions": np.array(hierarchy.cells_per_block),
        }
        for field in hierarchy.fields:
            grid[field.name] = (field.values[g], field.units)
        grids.append(grid)
    ds = yt.load_amr_grids(
        grids,
        hierarchy.root_blocks * np.array(hierarchy.cells_per_block),
        bbox=np.stack([lo, hi], axis=1),
        sim_time=float(snapshot.time),
        length_unit="m",
        mass_unit="kg",
        time_unit="s",
        velocity_unit="m/s",
        unit_system="mks",
        geometry=geometry,
        refine_by=np.where(np.arange(3) < ndim, 2, 1),
        periodicity=(False, False, geometry == "cylindrical"),
        parameters={
            "geometry": snapshot.geometry,
            "material_names": list(snapshot.material_names),
            "material_fields": material_field_names(snapshot.material_names),
        },
        dataset_name=dataset_name,
    )
    for field in hierarchy.fields:
        _add_gas_field(ds, field.name, field.name, field.units)
    for alias, name in GAS_ALIASES.items():
        _add_gas_field(ds, alias, name, next(f.units for f in hierarchy.fields if f.name == name))
    return ds


def _add_gas_field(ds, name: str, source: str, units: str) -> None:
    """Define ``("gas", name)`` as the stream field ``source``, replacing any field of yt's own."""

    def copy(field, data):
        return data["stream", source]

    ds.add_field(("gas", name), function=copy, units=units, sampling_type="cell", force_override=True)
