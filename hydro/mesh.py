"""Block-structured mesh: the domain tiled with equal blocks of cells, with ghost layers.

One refinement level for now.  Every block carries its own lower corner, cell size and
level (``block_lo``, ``block_dx``, ``block_level``) and the mesh keeps a neighbour table
``neighbor[NB, 3, 2]`` (axis, side: 0 = low, 1 = high): a value >= 0 is the index of the
adjacent block (periodic wrap included), a negative value is a domain boundary code
(:data:`OUTFLOW`, :data:`REFLECTING`).  Ghost filling (:mod:`impactpipe.hydro.boundary`) is
driven by that table only, so a later AMR level can add coarse/fine neighbour entries
without touching the sweeps.

Field arrays have shape ``(NB, C, NX, NY, NZ)`` with ``NX = nx + 2 g`` on used axes and
``1`` (no ghosts) on unused ones; ``g = GHOST = 2`` serves the second-order stencil.

Geometries (:data:`impactpipe.hydro.snapshot.GEOMETRIES`): 1d-planar (unit cross-section,
1 m^2), 2d-planar (unit depth, 1 m), 2d-cylindrical (axes r, z; cells are full annuli of
volume pi (r_hi^2 - r_lo^2) dz) and 3d.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from impactpipe.hydro.snapshot import GEOMETRIES, GEOMETRY_DIMENSIONS

GHOST = 2
OUTFLOW = -1
REFLECTING = -2
BOUNDARY_KINDS = ("outflow", "reflecting", "periodic")
DEFAULT_BLOCK_CELLS = {1: 8, 2: 16, 3: 8}

GEOMETRY_CODES = {"1d-planar": 0, "2d-planar": 1, "2d-cylindrical": 2, "3d": 3}
CYLINDRICAL = 2


@dataclass
class BlockMesh:
    """A uniform single-level block mesh.

    Attributes:
        geometry: one of the snapshot geometries.
        domain_lo, domain_hi: (3,) domain corners (m); unused axes 0.
        blocks_per_axis: (3,) number of blocks along each axis (1 on unused axes).
        block_cells: cells per block along each used axis.
        boundaries: ((low, high), ...) boundary kind per used axis, from :data:`BOUNDARY_KINDS`.
        block_lo: (NB, 3) lower corner of each block (m).
        block_dx: (NB, 3) cell size of each block (m); 0 on unused axes.
        block_level: (NB,) refinement level (all 0 here).
        block_id: (NB,) stable block ids.
        neighbor: (NB, 3, 2) neighbour block index or boundary code.
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

    @classmethod
    def uniform(
        cls,
        geometry: str,
        domain_lo,
        domain_hi,
        cells,
        boundaries,
        block_cells: int | None = None,
    ) -> "BlockMesh":
        """Tile the box ``[domain_lo, domain_hi]`` with ``cells`` cells per used axis.

        ``cells`` (one int per used axis) must be a multiple of ``block_cells`` along each
        axis.  ``boundaries`` gives a (low, high) pair of kinds per used axis; periodic must
        be set on both sides.  In 2d-cylindrical the low r boundary is the symmetry axis and
        must be "reflecting" with ``domain_lo[0] == 0``.
        """
        if geometry not in GEOMETRIES:
            raise ValueError(f"unknown geometry {geometry!r}; choose one of {GEOMETRIES}")
        ndim = GEOMETRY_DIMENSIONS[geometry]
        block_cells = int(block_cells or DEFAULT_BLOCK_CELLS[ndim])
        cells = list(np.atleast_1d(cells).astype(int))
        if len(cells) != ndim or len(boundaries) != ndim:
            raise ValueError(f"{geometry} needs {ndim} entries in cells and boundaries")
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

        nb = int(np.prod(nblk))
        idx = np.arange(nb)
        ib = np.stack([idx % nblk[0], (idx // nblk[0]) % nblk[1], idx // (nblk[0] * nblk[1])], axis=1)
        dx = np.zeros(3)
        dx[:ndim] = (hi[:ndim] - lo[:ndim]) / np.asarray(cells, dtype=float)
        block_lo = lo[None, :] + ib * (dx * block_cells)[None, :]
        block_lo[:, ndim:] = 0.0
        neighbor = np.zeros((nb, 3, 2), dtype=np.int64)
        codes = {"outflow": OUTFLOW, "reflecting": REFLECTING}
        for d in range(3):
            for side, step in ((0, -1), (1, 1)):
                if d >= ndim:
                    neighbor[:, d, side] = REFLECTING
                    continue
                j = ib.copy()
                j[:, d] += step
                inside = (j[:, d] >= 0) & (j[:, d] < nblk[d])
                kind = boundaries[d][side]
                if kind == "periodic":
                    j[:, d] %= nblk[d]
                    inside[:] = True
                flat = j[:, 0] + nblk[0] * (j[:, 1] + nblk[1] * j[:, 2])
                neighbor[:, d, side] = np.where(inside, flat, codes.get(kind, OUTFLOW))
        return cls(
            geometry=geometry,
            domain_lo=lo,
            domain_hi=hi,
            blocks_per_axis=nblk,
            block_cells=block_cells,
            boundaries=tuple(tuple(b) for b in boundaries),
            block_lo=block_lo,
            block_dx=np.repeat(dx[None, :], nb, axis=0),
            block_level=np.zeros(nb, dtype=np.int64),
            block_id=idx.astype(np.int64),
            neighbor=neighbor,
        )

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

    def cell_volumes(self) -> np.ndarray:
        """(NB, nx, ny, nz) physical interior cell volumes (m^3), see the module docstring."""
        n = self.interior_shape
        vol = np.ones((self.nblocks,) + n)
        for d in range(self.ndim):
            edges = self.block_lo[:, d, None] + np.arange(n[d] + 1)[None, :] * self.block_dx[:, d, None]
            if self.geometry == "2d-cylindrical" and d == 0:
                width = np.pi * (edges[:, 1:] ** 2 - edges[:, :-1] ** 2)
            else:
                width = edges[:, 1:] - edges[:, :-1]
            shape = [self.nblocks, 1, 1, 1]
            shape[d + 1] = n[d]
            vol = vol * width.reshape(shape)
        return vol

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
        }

    @classmethod
    def from_arrays(cls, data: dict) -> "BlockMesh":
        """Inverse of :meth:`to_arrays`."""
        bnd = tuple(tuple(s.decode() if isinstance(s, bytes) else str(s) for s in row) for row in data["boundaries"])
        geometry = data["geometry"]
        return cls(
            geometry=geometry.decode() if isinstance(geometry, bytes) else str(geometry),
            domain_lo=np.asarray(data["domain_lo"], dtype=float),
            domain_hi=np.asarray(data["domain_hi"], dtype=float),
            blocks_per_axis=np.asarray(data["blocks_per_axis"], dtype=np.int64),
            block_cells=int(data["block_cells"]),
            boundaries=bnd,
            block_lo=np.asarray(data["block_lo"], dtype=float),
            block_dx=np.asarray(data["block_dx"], dtype=float),
            block_level=np.asarray(data["block_level"], dtype=np.int64),
            block_id=np.asarray(data["block_id"], dtype=np.int64),
            neighbor=np.asarray(data["neighbor"], dtype=np.int64),
        )
