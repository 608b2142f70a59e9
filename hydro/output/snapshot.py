"""Hydro snapshots and tracer sets: the data the hydro stage hands to the rest of the pipeline.

A :class:`Snapshot` holds the leaf blocks of the mesh at one time, interior cells only
(no ghost layers), as block-shaped arrays with a leading block index.  Axes:

- 1d-planar: x; 2d-planar: (x, y); 2d-cylindrical: (r, z) with the symmetry axis at r = 0;
  3d: (x, y, z).  Unused axes have one cell and zero extent in ``block_lo``/``block_hi``.
- Vectors (velocity, positions) always have 3 components; the unused ones are zero.
  In 2d-cylindrical the components are (v_r, v_z, 0).

Cell volumes are physical volumes (m^3): 2d-cylindrical cells are full annuli,
pi (r_hi^2 - r_lo^2) dz; 2d-planar cells have unit depth (1 m) and 1d-planar cells unit
cross-section (1 m^2).  All quantities are SI.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

GEOMETRIES = ("1d-planar", "2d-planar", "2d-cylindrical", "3d")
GEOMETRY_DIMENSIONS = {"1d-planar": 1, "2d-planar": 2, "2d-cylindrical": 2, "3d": 3}


@dataclass
class Snapshot:
    """Leaf blocks of the mesh at one time.

    Attributes (NB blocks, M materials, (nx, ny, nz) cells per block):
        time: simulated time (s).
        geometry: one of :data:`GEOMETRIES`.
        material_names: names of the M materials (void is not a material; its volume
            fraction is 1 - sum of the material volume fractions).
        block_lo, block_hi: (NB, 3) lower and upper corners of each block (m).
        block_level: (NB,) refinement level (0 = coarsest).
        block_id: (NB,) stable integer id of each block.
        partial_density: (NB, M, nx, ny, nz) material mass per cell volume, alpha_k rho_k (kg/m^3).
        volume_fraction: (NB, M, nx, ny, nz) alpha_k (dimensionless).
        velocity: (NB, 3, nx, ny, nz) cell velocity (m/s).
        specific_internal_energy: (NB, nx, ny, nz) mass-weighted mean over materials (J/kg).
        pressure: (NB, nx, ny, nz) volume-fraction-weighted mean pressure (Pa).
        temperature: (NB, nx, ny, nz) mass-weighted mean temperature (K).
        sound_speed: (NB, nx, ny, nz) cell sound speed used for the time step (m/s).
        extra: optional further block-shaped fields (strength, damage...) by name.
    """

    time: float
    geometry: str
    material_names: list[str]
    block_lo: np.ndarray
    block_hi: np.ndarray
    block_level: np.ndarray
    block_id: np.ndarray
    partial_density: np.ndarray
    volume_fraction: np.ndarray
    velocity: np.ndarray
    specific_internal_energy: np.ndarray
    pressure: np.ndarray
    temperature: np.ndarray
    sound_speed: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def ndim(self) -> int:
        """Number of spatial dimensions of the geometry."""
        return GEOMETRY_DIMENSIONS[self.geometry]

    @property
    def cells_per_block(self) -> tuple[int, int, int]:
        """Cells per block along each of the three axes (1 for unused axes)."""
        return tuple(int(n) for n in self.partial_density.shape[2:])

    @property
    def cell_size(self) -> np.ndarray:
        """(NB, 3) cell edge lengths per block (m); unused axes give 0."""
        return (self.block_hi - self.block_lo) / np.asarray(self.cells_per_block, dtype=float)

    def cell_edges(self, axis: int) -> np.ndarray:
        """(NB, n_axis + 1) cell face coordinates along ``axis`` for every block (m)."""
        n = self.cells_per_block[axis]
        frac = np.linspace(0.0, 1.0, n + 1)
        lo = self.block_lo[:, axis : axis + 1]
        hi = self.block_hi[:, axis : axis + 1]
        return lo + (hi - lo) * frac[None, :]

    def block_cell_centers(self) -> np.ndarray:
        """(NB, 3, nx, ny, nz) cell-centre coordinates (m)."""
        nb = self.block_lo.shape[0]
        shape = self.cells_per_block
        out = np.zeros((nb, 3) + shape)
        for axis in range(3):
            edges = self.cell_edges(axis)
            mid = 0.5 * (edges[:, 1:] + edges[:, :-1])
            bshape = [nb, 1, 1, 1]
            bshape[axis + 1] = shape[axis]
            out[:, axis] = mid.reshape(bshape)
        return out

    def block_cell_volumes(self) -> np.ndarray:
        """(NB, nx, ny, nz) physical cell volumes (m^3), see the module docstring."""
        nb = self.block_lo.shape[0]
        shape = self.cells_per_block
        vol = np.ones((nb,) + shape)
        for axis in range(3):
            edges = self.cell_edges(axis)
            if self.geometry == "2d-cylindrical" and axis == 0:
                width = np.pi * (edges[:, 1:] ** 2 - edges[:, :-1] ** 2)
            elif axis < self.ndim:
                width = edges[:, 1:] - edges[:, :-1]
            else:
                continue
            bshape = [nb, 1, 1, 1]
            bshape[axis + 1] = shape[axis]
            vol = vol * width.reshape(bshape)
        return vol

    @property
    def density(self) -> np.ndarray:
        """(NB, nx, ny, nz) cell density, sum of the partial densities (kg/m^3)."""
        return self.partial_density.sum(axis=1)

    def block_masses(self) -> np.ndarray:
        """(NB, M) mass of each material in each block (kg)."""
        return (self.partial_density * self.block_cell_volumes()[:, None]).sum(axis=(2, 3, 4))

    # Flattened leaf-cell views (N = NB * nx * ny * nz cells), for analysis and plotting.

    @property
    def centers(self) -> np.ndarray:
        """(N, ndim) cell centres of all leaf cells (m)."""
        c = self.block_cell_centers()[:, : self.ndim]
        return np.moveaxis(c, 1, -1).reshape(-1, self.ndim)

    @property
    def volumes(self) -> np.ndarray:
        """(N,) physical cell volumes (m^3)."""
        return self.block_cell_volumes().reshape(-1)

    @property
    def fields(self) -> dict[str, np.ndarray]:
        """Flattened cell fields: density, pressure, velocity (N, ndim), specific_internal_energy,
        temperature, sound_speed, volume_fraction (N, M), partial_density (N, M)."""
        m = len(self.material_names)
        out = {
            "density": self.density.reshape(-1),
            "pressure": self.pressure.reshape(-1),
            "velocity": np.moveaxis(self.velocity[:, : self.ndim], 1, -1).reshape(-1, self.ndim),
            "specific_internal_energy": self.specific_internal_energy.reshape(-1),
            "temperature": self.temperature.reshape(-1),
            "sound_speed": self.sound_speed.reshape(-1),
            "volume_fraction": np.moveaxis(self.volume_fraction, 1, -1).reshape(-1, m),
            "partial_density": np.moveaxis(self.partial_density, 1, -1).reshape(-1, m),
        }
        for name, arr in self.extra.items():
            out[name] = arr.reshape(-1) if arr.ndim == 4 else np.moveaxis(arr, 1, -1).reshape(-1, arr.shape[1])
        return out

    @property
    def blocks(self) -> list[dict]:
        """The block list: one dict per leaf block with id, level, lo and hi (m)."""
        return [
            {"id": int(i), "level": int(lv), "lo": lo.copy(), "hi": hi.copy()}
            for i, lv, lo, hi in zip(self.block_id, self.block_level, self.block_lo, self.block_hi)
        ]


@dataclass
class TracerSet:
    """Massless Lagrangian tracers and what they recorded (N tracers, SI units).

    Positions use the mesh coordinates of the geometry ((r, z, 0) in 2d-cylindrical).

    Attributes:
        id: (N,) int64 tracer ids.
        material: (N,) int index into the snapshot's material_names.
        initial_position: (N, 3) position at t = 0 (m).
        position: (N, 3) current position (m).
        velocity: (N, 3) current velocity (m/s).
        peak_pressure: (N,) highest pressure met (Pa).
        peak_pressure_time: (N,) time of the peak pressure (s).
        peak_temperature: (N,) highest temperature met (K).
        exited: (N,) bool, True once the tracer left the mesh.
        exit_time: (N,) time it left the mesh (s), NaN if it did not.
    """

    id: np.ndarray
    material: np.ndarray
    initial_position: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    peak_pressure: np.ndarray
    peak_pressure_time: np.ndarray
    peak_temperature: np.ndarray
    exited: np.ndarray
    exit_time: np.ndarray

    def __len__(self) -> int:
        return int(self.id.shape[0])
