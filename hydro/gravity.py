"""Uniform external gravity as an operator-split momentum and energy source.

After the sweeps, in two half steps around the stress update (half the impulse before it
and half after it, :meth:`impactpipe.hydro.solver.Simulation._momentum_sources`), every
interior cell with mass gets, over each part dt,

    (rho u)_new = (rho u)_old + rho g dt
    E_new       = E_old + g . ((rho u)_old + (rho u)_new) / 2 dt
                = E_old + g . (rho u)_old dt + rho |g|^2 dt^2 / 2

with rho = sum_k alpha_k rho_k (kg/m^3), g the constant acceleration (m/s^2) and E the
total energy density (J/m^3).  This is the exact solution of the split equations
d(rho u)/dt = rho g, dE/dt = g . (rho u) over the step (the momentum is linear in t), so
E - |rho u|^2 / (2 rho), the internal energy, is unchanged: gravity does work on the bulk
motion only.  Mass, volume fractions and per-material energies are untouched.

The work gravity does on the mesh, sum over cells of (E_new - E_old) V (J, V the physical
cell volume: annuli in 2d-cylindrical), is accumulated in :attr:`ExternalGravity.work`;
it closes the energy budget of a run with gravity (mesh + left - initial = work + floors).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numba import njit, prange

from impactpipe.hydro.gravity_kick import cell_volume, gravity_kick
from impactpipe.hydro.mesh.blocks import GHOST, BlockMesh
from impactpipe.hydro.mesh.state import HydroState


@njit(cache=True, parallel=True)
def apply_gravity(dt, gx, gy, gz, geometry, ndim, arho, momentum, energy, block_lo, block_dx, block_work):
    """Add the gravity impulse and its work over ``dt`` (s) to every interior cell; see the module docstring.

    ``(gx, gy, gz)`` is g in mesh components (m/s^2; in 2d-cylindrical (g_r, g_z, 0) with
    g_r = 0).  ``block_work[b]`` receives the work done in block b during this step (J).
    """
    nb, nmat, nx, ny, nz = arho.shape
    lo_x = GHOST if nx > 1 else 0
    lo_y = GHOST if ny > 1 else 0
    lo_z = GHOST if nz > 1 else 0
    for b in prange(nb):
        dx0 = block_dx[b, 0]
        dx1 = block_dx[b, 1] if ndim > 1 else 1.0
        dx2 = block_dx[b, 2] if ndim > 2 else 1.0
        work = 0.0
        for ix in range(lo_x, nx - lo_x):
            vol = cell_volume(geometry, block_lo[b, 0] + (ix - lo_x) * dx0, dx0, dx1, dx2)
            for iy in range(lo_y, ny - lo_y):
                for iz in range(lo_z, nz - lo_z):
                    rho = 0.0
                    for k in range(nmat):
                        rho += arho[b, k, ix, iy, iz]
                    if rho <= 0.0:
                        continue
                    work += gravity_kick(dt, gx, gy, gz, rho, momentum, energy, b, ix, iy, iz) * vol
        block_work[b] = work


class ExternalGravity:
    """A uniform gravitational acceleration acting on every cell of a :class:`BlockMesh`.

    Args:
        acceleration: g as a (3,) vector in mesh components (m/s^2): (g_x, g_y, g_z) in
            planar geometries and 3d, (g_r, g_z, 0) in 2d-cylindrical, where only g_z may be
            non-zero (a uniform radial field is not axisymmetric).  Components along unused
            axes must be 0.
        mesh: the mesh the state lives on (geometry and dimension).

    Attributes:
        acceleration: the (3,) vector (m/s^2).
        work: work gravity has done on the mesh since the start (J).
    """

    def __init__(self, acceleration: Iterable[float], mesh: BlockMesh):
        g = np.asarray(acceleration, dtype=float)
        if g.shape != (3,) or not np.isfinite(g).all():
            raise ValueError(f"gravity must be a finite (3,) vector in m/s^2 (got {acceleration!r})")
        if mesh.geometry == "2d-cylindrical" and g[0] != 0.0:
            raise ValueError(f"gravity in 2d-cylindrical acts along z only: g_r must be 0 (got {g[0]:g} m/s^2)")
        if (g[mesh.ndim:] != 0.0).any():
            raise ValueError(f"gravity has components along axes a {mesh.geometry} mesh does not use: {g.tolist()}")
        self.acceleration = g
        self.geometry_code = mesh.geometry_code
        self.ndim = mesh.ndim
        self.work = 0.0
        self._block_work = np.zeros(mesh.nblocks)

    def spec(self) -> dict:
        """What rebuilds this object (:func:`gravity_from_spec`)."""
        return {"kind": "uniform", "acceleration": self.acceleration.tolist(), "work": self.work}

    def prepare(self, state: HydroState, mesh: BlockMesh, partition=None) -> None:
        """Nothing to compute before a step's kicks: the field is uniform."""

    def advance(self, state: HydroState, dt: float, block_lo: np.ndarray, block_dx: np.ndarray,
                partition=None) -> None:
        """Apply the gravity impulse and work of one step of ``dt`` (s) to the interior cells of
        the blocks this process advances (``partition``, :mod:`impactpipe.hydro.parallel`; every
        block without one).  The work is summed over every block in block order, the blocks of
        other processes received first (``partition.share_rows``), so it is the same on any
        number of processes."""
        nb = state.arho.shape[0]
        if self._block_work.shape[0] != nb:
            self._block_work = np.zeros(nb)
        own = slice(None) if partition is None else partition.blocks
        g = self.acceleration
        apply_gravity(dt, g[0], g[1], g[2], self.geometry_code, self.ndim, state.arho[own], state.momentum[own],
                      state.energy[own], block_lo[own], block_dx[own], self._block_work[own])
        if partition is not None:
            partition.share_rows(self._block_work)
        self.work += float(self._block_work.sum())


def gravity_from_spec(spec: dict, mesh: BlockMesh):
    """The gravity object a ``spec()`` dict describes (checkpoints), its work restored: uniform
    (:class:`ExternalGravity`) or the bodies' own (:class:`impactpipe.hydro.self_gravity.SelfGravity`)."""
    if spec["kind"] == "uniform":
        gravity = ExternalGravity(spec["acceleration"], mesh)
    elif spec["kind"] == "self":
        from impactpipe.hydro.self_gravity import SelfGravity

        gravity = SelfGravity(mesh, order=spec["order"], mirror_y=spec["mirror_y"])
    else:
        raise ValueError(f"unknown gravity kind {spec['kind']!r} (uniform, self)")
    gravity.work = float(spec["work"])
    return gravity
