"""Block-structured mesh: the domain tiled with leaf blocks of a quadtree / octree, with ghost layers.

Every block has the same number of cells, ``block_cells`` per used axis.  The root level 0
tiles the domain with ``blocks_per_axis`` blocks; refining a block splits it in two along
each used axis (2^ndim children at level L + 1, cell size halved), so a block at level L
with integer index ``block_index`` = (i, j, k) covers

    [domain_lo + (i, j, k) W_L, domain_lo + (i + 1, j + 1, k + 1) W_L],   W_L = block_cells dx_0 / 2^L

(dx_0 the root cell size).  Only leaf blocks are stored, in Morton (Z-order) order of their
lower corners (:func:`morton_keys`): the blocks of a contiguous range of the order form a
compact region, which is what one MPI rank owns (:mod:`impactpipe.hydro.parallel`).  Neighbouring leaves differ by at
most one level across faces, edges and corners (2:1 balance, kept by
:mod:`impactpipe.hydro.amr.regrid`).

The neighbour table ``neighbor[NB, 3, 2]`` (axis, side: 0 = low, 1 = high) holds, for a
face inside the domain, the index of a leaf across it (periodic wrap included): the block
of the same level, the coarser block (``neighbor_level`` = -1) or one of the 2^(ndim-1)
finer blocks (``neighbor_level`` = +1); for a domain face a negative boundary code
(:data:`OUTFLOW`, :data:`REFLECTING`).  Same-level faces and domain faces are filled by
:func:`impactpipe.hydro.mesh.boundary.fill_ghosts`, coarse/fine faces by restriction and
prolongation (:mod:`impactpipe.hydro.amr.transfer`).

Field arrays have shape ``(NB, C, NX, NY, NZ)`` with ``NX = nx + 2 g`` on used axes and
``1`` (no ghosts) on unused ones; ``g = GHOST = 2`` serves the second-order stencil.

Geometries (:data:`impactpipe.hydro.output.snapshot.GEOMETRIES`): 1d-planar (unit cross-section,
1 m^2), 2d-planar (unit depth, 1 m), 2d-cylindrical (axes r, z; cells are full annuli of
volume pi (r_hi^2 - r_lo^2) dz) and 3d.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

from impactpipe.hydro.output.snapshot import GEOMETRIES, GEOMETRY_DIMENSIONS

GHOST = 2


@njit(cache=True, inline="always")
def ghost_widths(nx, ny, nz):
    """Ghost layers (gx, gy, gz) on each side of a block padded to (nx, ny, nz) cells: GHOST along
    an axis the mesh has, 0 along one it lacks (padded to a single cell)."""
    return (GHOST if nx > 1 else 0, GHOST if ny > 1 else 0, GHOST if nz > 1 else 0)
OUTFLOW = -1
REFLECTING = -2
BOUNDARY_KINDS = ("outflow", "reflecting", "periodic")
#: Cells per block edge of an adaptive mesh, and of a uniform one whose cells no larger edge divides.
DEFAULT_BLOCK_CELLS = {1: 8, 2: 16, 3: 8}
#: Block edges a uniform mesh may take by default, largest first (:func:`uniform_block_cells`).
UNIFORM_BLOCK_CELLS = {1: (8,), 2: (64, 32, 16), 3: (16, 8)}
#: Fewest blocks a uniform mesh's default edge leaves, so that threads have blocks to share.
MIN_UNIFORM_BLOCKS = 64

GEOMETRY_CODES = {"1d-planar": 0, "2d-planar": 1, "2d-cylindrical": 2, "3d": 3}
CYLINDRICAL = 2
#: Bits per axis of a block key (:func:`block_keys`): up to 2^18 blocks along an axis at any level.
KEY_BITS = 18


def uniform_block_cells(ndim: int, cells) -> int:
    """Default cells per block edge of a uniform mesh with ``cells`` cells per used axis.

    The largest edge of :data:`UNIFORM_BLOCK_CELLS` that divides every axis and still leaves
    :data:`MIN_UNIFORM_BLOCKS` blocks, else :data:`DEFAULT_BLOCK_CELLS`.  Larger blocks carry
    fewer ghost cells per interior cell ((n + 4)^d / n^d: 1.56 for 16^2, 1.27 for 32^2,
    1.13 for 64^2) and split each sweep into fewer pencils, so a step costs less per cell
    (docs/performance.md).  The rule depends on the mesh alone, never on the thread count,
    so a run's blocks, and its answer, are the same on every machine.  Adaptive meshes and
    impacts keep :data:`DEFAULT_BLOCK_CELLS`: there the block edge is the refinement's
    granularity and the hand-off's particle size.
    """
    cells = [int(c) for c in np.atleast_1d(cells)]
    for edge in UNIFORM_BLOCK_CELLS[ndim]:
        if all(c % edge == 0 for c in cells) and int(np.prod([c // edge for c in cells])) >= MIN_UNIFORM_BLOCKS:
            return edge
    return DEFAULT_BLOCK_CELLS[ndim]


def block_keys(level, index) -> np.ndarray:
    """Integer keys of blocks (level (N,), index (N, 3)) for sorted lookup; unique per block."""
    level = np.asarray(level, dtype=np.int64)
    index = np.asarray(index, dtype=np.int64)
    return ((level << KEY_BITS | index[:, 2]) << KEY_BITS | index[:, 1]) << KEY_BITS | index[:, 0]


def morton_keys(level, index, max_level: int) -> np.ndarray:
    """Keys that order blocks (level (N,), index (N, 3)) along a Morton (Z-order) curve: the bits
    of their lower corners on the level-``max_level`` block grid, c_d = index_d 2^(max_level -
    level), interleaved (x lowest).  Leaves never share a lower corner, so the keys of a mesh's
    leaves are unique; a parent's key is its first child's, so refining or coarsening keeps
    the blocks of a region together in the order."""
    level = np.asarray(level, dtype=np.int64)
    corner = np.asarray(index, dtype=np.int64) << (int(max_level) - level)[:, None]
    keys = np.zeros(len(level), dtype=np.int64)
    for bit in range(KEY_BITS):
        for d in range(3):
            keys |= ((corner[:, d] >> bit) & 1) << (3 * bit + d)
    return keys


@dataclass
class BlockMesh:
    """The leaf blocks of a block-structured (optionally adaptive) mesh.

    Attributes:
        geometry: one of the snapshot geometries.
        domain_lo, domain_hi: (3,) domain corners (m); unused axes 0.
        blocks_per_axis: (3,) number of root (level 0) blocks along each axis (1 on unused axes).
        block_cells: cells per block along each used axis.
        boundaries: ((low, high), ...) boundary kind per used axis, from :data:`BOUNDARY_KINDS`.
        block_lo: (NB, 3) lower corner of each block (m).
        block_dx: (NB, 3) cell size of each block (m); 0 on unused axes.
        block_level: (NB,) refinement level, 0 = root.
        block_id: (NB,) block ids, unique within the mesh (:func:`block_keys`).
        neighbor: (NB, 3, 2) neighbour block index or boundary code.
        block_index: (NB, 3) integer position of each block on the block grid of its level.
        neighbor_level: (NB, 3, 2) level of the neighbour minus the block's own (-1, 0, +1; 0 at
            domain faces).
        max_level: the finest level refinement may reach (0: a uniform mesh).
    """

    geometry: str
    domain_lo: np.ndarray
    domain_hi: np.ndarray
    blocks_per_axis: np.ndarray
    block_cells: int
    boundaries: tuple
    block_lo: np.ndarray
    block_dx: np.ndarray
    block_level: np.ndarray
    block_id: np.ndarray
    neighbor: np.ndarray
    block_index: np.ndarray
    neighbor_level: np.ndarray
    max_level: int = 0
    #: Derived data cached per mesh (ghost-exchange and reflux plans), never saved.
    cache: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def uniform(
        cls,
        geometry: str,
        domain_lo,
        domain_hi,
        cells,
        boundaries,
        block_cells: int | None = None,
        max_level: int = 0,
    ) -> "BlockMesh":
        """Tile the box ``[domain_lo, domain_hi]`` with ``cells`` cells per used axis (all at level 0).

        ``cells`` (one int per used axis) must be a multiple of ``block_cells`` along each
        axis; without ``block_cells`` a uniform mesh (``max_level`` 0) takes
        :func:`uniform_block_cells`, an adaptive one :data:`DEFAULT_BLOCK_CELLS`.
        ``boundaries`` gives a (low, high) pair of kinds per used axis; periodic must be set
        on both sides.  In 2d-cylindrical the low r boundary is the symmetry axis and
        must be "reflecting" with ``domain_lo[0] == 0``.  ``max_level`` is the finest level
        adaptive refinement may later reach (cell size dx / 2^max_level).
        """
        if geometry not in GEOMETRIES:
            raise ValueError(f"unknown geometry {geometry!r}; choose one of {GEOMETRIES}")
        ndim = GEOMETRY_DIMENSIONS[geometry]
        cells = list(np.atleast_1d(cells).astype(int))
        if not block_cells:
            block_cells = DEFAULT_BLOCK_CELLS[ndim] if max_level else uniform_block_cells(ndim, cells)
        block_cells = int(block_cells)
        if len(cells) != ndim or len(boundaries) != ndim:
            raise ValueError(f"{geometry} needs {ndim} entries in cells and boundaries")
        if not 0 <= int(max_level) < 2 ** KEY_BITS:
            raise ValueError(f"max_level must be >= 0, got {max_level}")
        lo = np.zeros(3)
        hi = np.zeros(3)
        lo[:ndim] = np.asarray(domain_lo, dtype=float)[:ndim]
        hi[:ndim] = np.asarray(domain_hi, dtype=float)[:ndim]
        nblk = np.ones(3, dtype=np.int64)
        for d in range(ndim):
            if cells[d] % block_cells:
                raise ValueError(f"cells[{d}] = {cells[d]} is not a multiple of block_cells = {block_cells}")
            if not hi[d] > lo[d]:
                raise ValueError(f"empty domain along axis {d}")
            nblk[d] = cells[d] // block_cells
            low, high = boundaries[d]
            for kind in (low, high):
                if kind not in BOUNDARY_KINDS:
                    raise ValueError(f"unknown boundary {kind!r}; choose one of {BOUNDARY_KINDS}")
            if (low == "periodic") != (high == "periodic"):
                raise ValueError(f"axis {d}: periodic must be set on both sides")
        if geometry == "2d-cylindrical" and (lo[0] != 0.0 or boundaries[0][0] != "reflecting"):
            raise ValueError("2d-cylindrical needs r_lo = 0 with a reflecting axis boundary")
        if (nblk << int(max_level)).max() >= 2 ** KEY_BITS:
            raise ValueError(f"{nblk[:ndim].tolist()} root blocks refined {max_level} times exceed "
                             f"2^{KEY_BITS} blocks along an axis")
        nb = int(np.prod(nblk))
        idx = np.arange(nb)
        index = np.stack([idx % nblk[0], (idx // nblk[0]) % nblk[1], idx // (nblk[0] * nblk[1])], axis=1)
        index = index[np.argsort(morton_keys(np.zeros(nb, dtype=np.int64), index, 0), kind="stable")]
        return cls.from_leaves(geometry, lo, hi, nblk, block_cells, tuple(tuple(b) for b in boundaries),
                               np.zeros(nb, dtype=np.int64), index, int(max_level))

    @classmethod
    def from_leaves(cls, geometry: str, domain_lo, domain_hi, blocks_per_axis, block_cells: int, boundaries,
                    level, index, max_level: int) -> "BlockMesh":
        """The mesh of the leaf blocks (``level`` (NB,), ``index`` (NB, 3)) over a root grid.

        Geometry, cell sizes and the neighbour tables follow from the root grid; the leaves
        must tile the domain and be 2:1 balanced across faces (a ValueError names the first
        block whose face has no leaf across it).
        """
        ndim = GEOMETRY_DIMENSIONS[geometry]
        level = np.asarray(level, dtype=np.int64)
        index = np.asarray(index, dtype=np.int64)
        lo = np.asarray(domain_lo, dtype=float)
        hi = np.asarray(domain_hi, dtype=float)
        nblk = np.asarray(blocks_per_axis, dtype=np.int64)
        used = np.arange(3) < ndim
        root_dx = np.where(used, (hi - lo) / (nblk * block_cells), 0.0)
        block_dx = root_dx[None, :] / (2.0 ** level)[:, None]
        block_lo = np.where(used, lo[None, :] + index * block_cells * block_dx, 0.0)
        mesh = cls(geometry=geometry, domain_lo=lo, domain_hi=hi, blocks_per_axis=nblk, block_cells=int(block_cells),
                   boundaries=tuple(tuple(b) for b in boundaries), block_lo=block_lo, block_dx=block_dx,
                   block_level=level, block_id=block_keys(level, index), neighbor=np.zeros((len(level), 3, 2), np.int64),
                   block_index=index, neighbor_level=np.zeros((len(level), 3, 2), np.int64),
                   max_level=int(max_level))
        mesh._link_neighbors()
        return mesh

    def blocks_at_level(self, level) -> np.ndarray:
        """(N, 3) number of blocks along each axis that tile the domain at ``level`` (N,)."""
        level = np.asarray(level, dtype=np.int64)
        grow = np.where(np.arange(3) < self.ndim, 1, 0)
        return self.blocks_per_axis[None, :] << (np.atleast_1d(level)[:, None] * grow[None, :])

    def lookup(self, level, index) -> np.ndarray:
        """Indices of the leaf blocks at ``level`` (N,) and ``index`` (N, 3); -1 where none is a leaf."""
        if "sorted_keys" not in self.cache:
            order = np.argsort(self.block_id, kind="stable")
            self.cache["sorted_keys"] = (self.block_id[order], order)
        keys, order = self.cache["sorted_keys"]
        level = np.asarray(level, dtype=np.int64)
        index = np.asarray(index, dtype=np.int64)
        out = np.full(len(level), -1, dtype=np.int64)
        valid = (level >= 0) & (index >= 0).all(axis=1)
        if not valid.any() or keys.size == 0:
            return out
        want = block_keys(level[valid], index[valid])
        pos = np.minimum(np.searchsorted(keys, want), keys.size - 1)
        out[valid] = np.where(keys[pos] == want, order[pos], -1)
        return out

    def _link_neighbors(self) -> None:
        """Fill ``neighbor`` and ``neighbor_level`` from the leaf positions (see the module docstring)."""
        codes = {"outflow": OUTFLOW, "reflecting": REFLECTING}
        level = self.block_level
        extent = self.blocks_at_level(level)
        for d in range(3):
            for side, step in ((0, -1), (1, 1)):
                if d >= self.ndim:
                    self.neighbor[:, d, side] = REFLECTING
                    self.neighbor_level[:, d, side] = 0
                    continue
                probe = self.block_index.copy()
                probe[:, d] += step
                kind = self.boundaries[d][side]
                if kind == "periodic":
                    probe[:, d] %= extent[:, d]
                inside = (probe[:, d] >= 0) & (probe[:, d] < extent[:, d])
                same = self.lookup(np.where(inside, level, -1), probe)
                coarse = self.lookup(np.where(inside & (same < 0), level - 1, -1), probe >> 1)
                child = 2 * probe
                if side == 0:
                    child[:, d] += 1
                fine = self.lookup(np.where(inside & (same < 0) & (coarse < 0), level + 1, -1), child)
                nbr = np.where(same >= 0, same, np.where(coarse >= 0, coarse, fine))
                missing = inside & (nbr < 0)
                if missing.any():
                    b = int(np.argmax(missing))
                    raise ValueError(f"block {b} (level {level[b]}, index {self.block_index[b].tolist()}): no leaf "
                                     f"across its {'low' if side == 0 else 'high'} face along axis {d}; the leaves "
                                     f"do not tile the domain 2:1 balanced")
                self.neighbor[:, d, side] = np.where(inside, nbr, codes.get(kind, OUTFLOW))
                self.neighbor_level[:, d, side] = np.where(inside & (same < 0), np.where(coarse >= 0, -1, 1), 0)

    @property
    def adaptive(self) -> bool:
        """True when the mesh may hold more than one level."""
        return self.max_level > 0

    @property
    def root_cell_size(self) -> np.ndarray:
        """(3,) cell size of level 0 (m); 0 on unused axes."""
        used = np.arange(3) < self.ndim
        return np.where(used, (self.domain_hi - self.domain_lo) / (self.blocks_per_axis * self.block_cells), 0.0)

    @property
    def ndim(self) -> int:
        """Number of used axes."""
        return GEOMETRY_DIMENSIONS[self.geometry]

    @property
    def geometry_code(self) -> int:
        """Integer code of the geometry passed to the kernels (:data:`GEOMETRY_CODES`)."""
        return GEOMETRY_CODES[self.geometry]

    @property
    def nblocks(self) -> int:
        """Number of blocks NB."""
        return int(self.block_lo.shape[0])

    @property
    def interior_shape(self) -> tuple[int, int, int]:
        """Interior cells per block (nx, ny, nz), 1 on unused axes."""
        return tuple(self.block_cells if d < self.ndim else 1 for d in range(3))

    @property
    def padded_shape(self) -> tuple[int, int, int]:
        """Cells per block including ghosts (NX, NY, NZ)."""
        return tuple(self.block_cells + 2 * GHOST if d < self.ndim else 1 for d in range(3))

    @property
    def ghost(self) -> np.ndarray:
        """(3,) ghost width per axis (GHOST on used axes, 0 otherwise)."""
        return np.array([GHOST if d < self.ndim else 0 for d in range(3)], dtype=np.int64)

    @property
    def ncells(self) -> int:
        """Number of interior cells of the whole mesh."""
        return self.nblocks * int(np.prod(self.interior_shape))

    @property
    def block_hi(self) -> np.ndarray:
        """(NB, 3) upper corner of each block (m)."""
        return self.block_lo + self.block_dx * np.asarray(self.interior_shape)[None, :] * (
            np.arange(3) < self.ndim
        )

    def interior(self, arr: np.ndarray) -> np.ndarray:
        """View of the interior cells of a field array ``(NB, ..., NX, NY, NZ)``."""
        g = self.ghost
        n = self.interior_shape
        return arr[..., g[0] : g[0] + n[0], g[1] : g[1] + n[1], g[2] : g[2] + n[2]]

    def cell_centers(self) -> np.ndarray:
        """(NB, 3, nx, ny, nz) interior cell centres (m); 0 on unused axes."""
        n = self.interior_shape
        out = np.zeros((self.nblocks, 3) + n)
        for d in range(self.ndim):
            c = self.block_lo[:, d, None] + (np.arange(n[d]) + 0.5)[None, :] * self.block_dx[:, d, None]
            shape = [self.nblocks, 1, 1, 1]
            shape[d + 1] = n[d]
            out[:, d] = c.reshape(shape)
        return out

    def cell_volumes(self, blocks: slice = slice(None)) -> np.ndarray:
        """(B, nx, ny, nz) physical interior cell volumes (m^3) of the B blocks ``blocks`` (every
        block by default), see the module docstring."""
        n = self.interior_shape
        lo, dx = self.block_lo[blocks], self.block_dx[blocks]
        vol = np.ones((len(lo),) + n)
        for d in range(self.ndim):
            edges = lo[:, d, None] + np.arange(n[d] + 1)[None, :] * dx[:, d, None]
            if self.geometry == "2d-cylindrical" and d == 0:
                width = np.pi * (edges[:, 1:] ** 2 - edges[:, :-1] ** 2)
            else:
                width = edges[:, 1:] - edges[:, :-1]
            shape = [len(lo), 1, 1, 1]
            shape[d + 1] = n[d]
            vol = vol * width.reshape(shape)
        return vol

    def some_blocks(self, blocks: slice | np.ndarray) -> "BlockMesh":
        """The blocks ``blocks`` (a slice or block indices) of this mesh as a mesh of their own, in
        their order here, for work that reads only each
        block's geometry (cell centres and volumes, an initial state set on them): its
        ``neighbor`` table still numbers the blocks of this mesh."""
        return replace(self, block_lo=self.block_lo[blocks], block_dx=self.block_dx[blocks],
                                   block_level=self.block_level[blocks], block_id=self.block_id[blocks],
                                   neighbor=self.neighbor[blocks], block_index=self.block_index[blocks],
                                   neighbor_level=self.neighbor_level[blocks], cache={})

    def min_cell_size(self) -> float:
        """Smallest cell edge over used axes (m)."""
        return float(self.block_dx[:, : self.ndim].min())

    def to_arrays(self) -> dict:
        """The mesh as plain arrays and scalars (for checkpoints)."""
        return {
            "geometry": self.geometry,
            "domain_lo": self.domain_lo,
            "domain_hi": self.domain_hi,
            "blocks_per_axis": self.blocks_per_axis,
            "block_cells": self.block_cells,
            "boundaries": np.array(self.boundaries, dtype="S16"),
            "block_lo": self.block_lo,
            "block_dx": self.block_dx,
            "block_level": self.block_level,
            "block_id": self.block_id,
            "neighbor": self.neighbor,
            "block_index": self.block_index,
            "neighbor_level": self.neighbor_level,
            "max_level": self.max_level,
        }

    @classmethod
    def from_arrays(cls, data: dict) -> "BlockMesh":
        """Inverse of :meth:`to_arrays` (a single-level mesh saved without ``block_index`` is rebuilt from its corners)."""
        bnd = tuple(tuple(s.decode() if isinstance(s, bytes) else str(s) for s in row) for row in data["boundaries"])
        geometry = data["geometry"]
        geometry = geometry.decode() if isinstance(geometry, bytes) else str(geometry)
        lo = np.asarray(data["domain_lo"], dtype=float)
        hi = np.asarray(data["domain_hi"], dtype=float)
        nblk = np.asarray(data["blocks_per_axis"], dtype=np.int64)
        level = np.asarray(data["block_level"], dtype=np.int64)
        if "block_index" in data:
            index = np.asarray(data["block_index"], dtype=np.int64)
        else:
            width = np.where(nblk > 0, (hi - lo) / nblk, 1.0)
            index = np.rint((np.asarray(data["block_lo"], dtype=float) - lo) / np.where(width > 0, width, 1.0))
            index = np.where(np.arange(3) < GEOMETRY_DIMENSIONS[geometry], index, 0).astype(np.int64)
        return cls.from_leaves(geometry, lo, hi, nblk, int(data["block_cells"]), bnd, level, index,
                               int(data.get("max_level", 0)))
