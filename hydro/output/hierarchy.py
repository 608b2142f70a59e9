"""Cell fields of a snapshot, its block grid, and its nested block hierarchy for AMR viewers.

A :class:`~impactpipe.hydro.output.snapshot.Snapshot` stores only the leaf blocks of the block
quadtree / octree (docs/hydro.md, "Mesh and data layout"): where a block is refined, its
parent is not stored, so the coarse levels do not cover the domain.  Viewers of nested
AMR data (``yt.load_amr_grids``) expect every level-L block to lie inside a level-(L-1)
block, so :func:`complete_hierarchy` rebuilds every ancestor of the leaves.  An ancestor
cell is the conservative average of the 2^ndim cells it covers:

- per-volume fields (densities, volume fractions, pressure, sound speed, stresses)
  by volume, f_parent = sum(V f) / sum(V), so the parent holds the children's mass;
- per-mass fields (velocity, specific internal energy, temperature, plastic strain,
  damage) by mass, f_parent = sum(m f) / sum(m) with m = rho V, so the parent holds the
  children's momentum and internal energy (by volume where the children hold no mass).

V are the physical cell volumes of the geometry (annuli in 2d-cylindrical).  Every cell of
an ancestor is covered by finer cells, so a viewer that masks covered cells shows each
leaf cell once.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from impactpipe.hydro.output.io import EXTRA_UNITS
from impactpipe.hydro.output.snapshot import Snapshot

#: Names of the three velocity components (snapshot order) per geometry.
VELOCITY_COMPONENTS = {
    "1d-planar": ("x", "y", "z"),
    "2d-planar": ("x", "y", "z"),
    "2d-cylindrical": ("r", "z", "theta"),
    "3d": ("x", "y", "z"),
}

#: Extra snapshot fields averaged by mass (the others are averaged by volume).
MASS_AVERAGED_EXTRAS = ("plastic_strain", "damage")


@dataclass(frozen=True)
class CellField:
    """One scalar cell field of a snapshot, with its units and how parents average it.

    Attributes:
        name: field name (snake case; per-material fields end with the material's name).
        units: unit string ("kg/m**3", "Pa", "m/s", "J/kg", "K", "dimensionless").
        values: (NB, nx, ny, nz) values on the blocks they belong to.
        average: "volume" or "mass", the weight of a parent cell's average.
        description: what the field is.
    """

    name: str
    units: str
    values: np.ndarray
    average: str
    description: str


def material_field_names(material_names: list[str]) -> list[str]:
    """Field-name suffixes of the materials: lower case, runs of other characters replaced
    by ``_`` ("basalt (projectile)" -> "basalt_projectile"), made unique with ``_<index>``."""
    out = []
    for index, name in enumerate(material_names):
        suffix = re.sub(r"[^0-9a-z]+", "_", name.lower()).strip("_") or f"material_{index}"
        out.append(f"{suffix}_{index}" if suffix in out else suffix)
    return out


def cell_fields(snapshot: Snapshot) -> list[CellField]:
    """The snapshot's cell fields as scalars, in SI units.

    density, partial_density_<material>, volume_fraction_<material>, velocity_<component>
    (x, y, z; r, z, theta in 2d-cylindrical), pressure, specific_internal_energy,
    temperature, sound_speed, then the snapshot's extra fields (multi-component extras as
    <name>_<index>; units from :data:`impactpipe.hydro.output.io.EXTRA_UNITS`, "dimensionless"
    for a field not listed there, whose units the snapshot does not give).
    """
    fields = [CellField("density", "kg/m**3", snapshot.density, "volume", "mixture density sum_k alpha_k rho_k")]
    for k, suffix in enumerate(material_field_names(snapshot.material_names)):
        name = snapshot.material_names[k]
        fields.append(CellField(f"partial_density_{suffix}", "kg/m**3", snapshot.partial_density[:, k], "volume",
                                f"alpha_k rho_k of {name}"))
        fields.append(CellField(f"volume_fraction_{suffix}", "dimensionless", snapshot.volume_fraction[:, k],
                                "volume", f"volume fraction alpha_k of {name}"))
    for c, component in enumerate(VELOCITY_COMPONENTS[snapshot.geometry]):
        fields.append(CellField(f"velocity_{component}", "m/s", snapshot.velocity[:, c], "mass",
                                f"{component} component of the cell velocity"))
    fields += [
        CellField("pressure", "Pa", snapshot.pressure, "volume", "volume-fraction-weighted mean pressure"),
        CellField("specific_internal_energy", "J/kg", snapshot.specific_internal_energy, "mass",
                  "mass-weighted mean specific internal energy"),
        CellField("temperature", "K", snapshot.temperature, "mass", "mass-weighted mean temperature"),
        CellField("sound_speed", "m/s", snapshot.sound_speed, "volume", "cell signal speed of the time step"),
    ]
    for name, values in snapshot.extra.items():
        units, description = EXTRA_UNITS.get(name, ("dimensionless", f"{name} (units not given by the snapshot)"))
        average = "mass" if name in MASS_AVERAGED_EXTRAS else "volume"
        if values.ndim == 4:
            fields.append(CellField(name, units, values, average, description))
        else:
            fields += [CellField(f"{name}_{c}", units, values[:, c], average, f"{description}, component {c}")
                       for c in range(values.shape[1])]
    return fields


@dataclass
class BlockHierarchy:
    """The leaf blocks of a snapshot and all their ancestors (NG blocks, sorted by level).

    Attributes:
        geometry: the snapshot's geometry.
        cells_per_block: (nx, ny, nz), 1 on unused axes.
        domain_lo, domain_hi: (3,) corners of the domain (m; 0 on unused axes).
        root_blocks: (3,) number of level-0 blocks along each axis (1 on unused axes).
        level: (NG,) refinement level of each block.
        index: (NG, 3) integer position of each block on the block grid of its level.
        lo, hi: (NG, 3) corners of each block (m; 0 on unused axes).
        is_leaf: (NG,) True for the snapshot's blocks, False for rebuilt ancestors.
        leaf_index: (NG,) index of the block in the snapshot, -1 for ancestors.
        fields: :func:`cell_fields` of the snapshot extended to all NG blocks.
    """

    geometry: str
    cells_per_block: tuple[int, int, int]
    domain_lo: np.ndarray
    domain_hi: np.ndarray
    root_blocks: np.ndarray
    level: np.ndarray
    index: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    is_leaf: np.ndarray
    leaf_index: np.ndarray
    fields: list[CellField]


@dataclass
class BlockGrid:
    """Where the leaf blocks of a snapshot sit on the block grids of their levels.

    Attributes:
        domain_lo, domain_hi: (3,) corners of the domain (m; 0 on unused axes).
        root_block_size: (3,) edge lengths of a level-0 block (m; 1 on unused axes).
        root_blocks: (3,) number of level-0 blocks along each axis (1 on unused axes).
        index: (NB, 3) integer position of each leaf on the block grid of its level
            (0 on unused axes): block b covers domain_lo + [index, index + 1] W_0 / 2^level.
    """

    domain_lo: np.ndarray
    domain_hi: np.ndarray
    root_block_size: np.ndarray
    root_blocks: np.ndarray
    index: np.ndarray


def block_grid(snapshot: Snapshot) -> BlockGrid:
    """The :class:`BlockGrid` of ``snapshot``'s leaves; ValueError when a block is off the grid
    (its size not W_0 / 2^level or its corner not on a multiple of it)."""
    used = np.arange(3) < snapshot.ndim
    level = np.asarray(snapshot.block_level, dtype=np.int64)
    domain_lo = np.where(used, snapshot.block_lo.min(axis=0), 0.0)
    domain_hi = np.where(used, snapshot.block_hi.max(axis=0), 0.0)
    root_size = (snapshot.block_hi - snapshot.block_lo) * (2.0 ** level)[:, None]
    root_size = np.where(used, root_size[np.argmax(level)], 1.0)
    root_blocks = np.where(used, np.rint((domain_hi - domain_lo) / root_size), 1).astype(np.int64)
    sizes = root_size[None, :] / (2.0 ** level)[:, None]
    index = np.where(used, np.rint((snapshot.block_lo - domain_lo) / sizes), 0).astype(np.int64)
    tolerance = 1e-9 * sizes
    if (np.abs(np.where(used, domain_lo + index * sizes - snapshot.block_lo, 0.0)) > tolerance).any() or (
            np.abs(np.where(used, snapshot.block_hi - snapshot.block_lo - sizes, 0.0)) > tolerance).any():
        raise ValueError("the snapshot's blocks are not on one block grid (block sizes must be W_0 / 2^level)")
    return BlockGrid(domain_lo, domain_hi, root_size, root_blocks, index)


def complete_hierarchy(snapshot: Snapshot) -> BlockHierarchy:
    """The leaves of ``snapshot`` and every ancestor block, parents averaged conservatively.

    Raises ValueError when the blocks are not the leaves of one quadtree / octree over a
    box (a refined block missing a child, overlapping blocks, blocks off the block grid)
    or when a multi-level snapshot has an odd number of cells per block.
    """
    shape = snapshot.cells_per_block
    used = np.arange(3) < snapshot.ndim
    level = np.asarray(snapshot.block_level, dtype=np.int64)
    grid = block_grid(snapshot)
    domain_lo, domain_hi, root_size, index = grid.domain_lo, grid.domain_hi, grid.root_block_size, grid.index
    if level.max() > 0 and any(n % 2 for n, u in zip(shape, used) if u):
        raise ValueError(f"a multi-level snapshot needs an even number of cells per block, got {shape}")

    fields = cell_fields(snapshot)
    volume = snapshot.block_cell_volumes()
    blocks = {(int(lv), *map(int, ix)): b for b, (lv, ix) in enumerate(zip(level, index))}
    if len(blocks) != len(level):
        raise ValueError("the snapshot holds two blocks at the same place and level")
    # per refined block: volume, mass, sum(w f) for each field (w = V, plus m for per-mass fields)
    sums = {key: _leaf_sums(fields, volume, snapshot.density, b) for key, b in blocks.items() if key[0] > 0}
    for lv in range(int(level.max()), 0, -1):
        parents: dict[tuple, list[tuple]] = {}
        for key in [key for key in sums if key[0] == lv]:
            parent = (lv - 1, *(i // 2 if u else 0 for i, u in zip(key[1:], used)))
            parents.setdefault(parent, []).append(key)
        for parent, kids in parents.items():
            if parent in blocks:
                raise ValueError(f"block {parent} is a leaf and has children {kids}")
            if len(kids) != 2 ** snapshot.ndim:
                raise ValueError(f"block {parent} has {len(kids)} of its {2 ** snapshot.ndim} children")
            sums[parent] = _restrict(sums, parent, kids, used, shape)

    keys = sorted(set(blocks) | set(sums), key=lambda k: (k[0], k[3], k[2], k[1]))
    g_level = np.array([k[0] for k in keys], dtype=np.int64)
    g_index = np.array([k[1:] for k in keys], dtype=np.int64)
    g_size = root_size[None, :] / (2.0 ** g_level)[:, None]
    g_lo = np.where(used, domain_lo + g_index * g_size, 0.0)
    g_hi = np.where(used, g_lo + g_size, 0.0)
    leaf_index = np.array([blocks.get(k, -1) for k in keys], dtype=np.int64)
    out_fields = []
    for f, field in enumerate(fields):
        values = np.empty((len(keys),) + shape)
        for g, key in enumerate(keys):
            values[g] = field.values[leaf_index[g]] if leaf_index[g] >= 0 else _average(sums[key], f, field.average)
        out_fields.append(CellField(field.name, field.units, values, field.average, field.description))
    return BlockHierarchy(snapshot.geometry, shape, domain_lo, domain_hi, grid.root_blocks, g_level, g_index,
                          g_lo, g_hi, leaf_index >= 0, leaf_index, out_fields)


def _leaf_sums(fields: list[CellField], volume: np.ndarray, density: np.ndarray, b: int) -> dict:
    """Volume, mass and the weighted field sums of leaf block ``b``."""
    v = volume[b]
    m = density[b] * v
    return {
        "volume": v,
        "mass": m,
        "by_volume": [v * field.values[b] for field in fields],
        "by_mass": [m * field.values[b] if field.average == "mass" else None for field in fields],
    }


def _coarsen(values: np.ndarray, used: np.ndarray) -> np.ndarray:
    """Sum ``values`` over 2 x 2 (x 2) cell groups along the used axes."""
    shape = []
    for n, u in zip(values.shape, used):
        shape += [n // 2, 2] if u else [n, 1]
    return values.reshape(shape).sum(axis=(1, 3, 5))


def _restrict(sums: dict, parent: tuple, kids: list[tuple], used: np.ndarray, shape: tuple) -> dict:
    """The sums of ``parent`` from those of its children (each child fills one half per used axis)."""
    half = tuple(n // 2 if u else n for n, u in zip(shape, used))

    def gather(get) -> np.ndarray:
        out = np.zeros(shape)
        for kid in kids:
            start = [(i - 2 * p) * h if u else 0 for i, p, h, u in zip(kid[1:], parent[1:], half, used)]
            out[tuple(slice(s, s + h) for s, h in zip(start, half))] = _coarsen(get(sums[kid]), used)
        return out

    first = sums[kids[0]]
    return {
        "volume": gather(lambda s: s["volume"]),
        "mass": gather(lambda s: s["mass"]),
        "by_volume": [gather(lambda s, f=f: s["by_volume"][f]) for f in range(len(first["by_volume"]))],
        "by_mass": [None if w is None else gather(lambda s, f=f: s["by_mass"][f])
                    for f, w in enumerate(first["by_mass"])],
    }


def _average(block_sums: dict, f: int, average: str) -> np.ndarray:
    """Field ``f`` of an ancestor: sum(w f) / sum(w), by volume where the cell holds no mass."""
    by_volume = block_sums["by_volume"][f] / block_sums["volume"]
    if average == "volume":
        return by_volume
    mass = block_sums["mass"]
    return np.where(mass > 0.0, block_sums["by_mass"][f] / np.where(mass > 0.0, mass, 1.0), by_volume)
