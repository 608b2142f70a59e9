"""Self-gravity of the mass on the mesh: a multipole expansion about the centre of mass.

The potential of the cells' masses m' at x' (kg, m), Phi(x) = -G sum m' / |x - x'| (J/kg),
is expanded in spherical harmonics about the centre of mass X of the mesh (Laplace's
expansion with the addition theorem; (r, theta, phi) spherical coordinates of x - X about
the z axis, r_< and r_> the smaller and larger of r and r'):

    1 / |x - x'| = sum_l r_<^l / r_>^(l+1) sum_{m=0..l} w_lm P_l^m(cos theta) P_l^m(cos theta') cos m (phi - phi'),
    w_lm = (2 - delta_m0) (l - m)! / (l + m)!,

so that, truncated at order L,

    Phi(x) = -G sum_{l<=L, m<=l} w_lm P_l^m(cos theta) [ r^-(l+1) (I^c_lm(r) cos m phi + I^s_lm(r) sin m phi)
                                                      + r^l      (O^c_lm(r) cos m phi + O^s_lm(r) sin m phi) ]

with the inner moments I^c_lm(r) = sum_{r' < r} m' r'^l P_l^m(cos theta') cos m phi' (I^s: sin)
and the outer moments O_lm(r) = sum_{r' > r} m' r'^-(l+1) P_l^m(...) (...).  The expansion is
exact for any mass distribution as L grows, and at every L for a spherically symmetric one
(only l = 0 is non-zero); the interior/exterior split in r makes it converge inside the body
as well as outside it.  In 2d-cylindrical a cell is a ring about the z axis: only the m = 0
terms survive the average over phi', so the ring's potential is expanded exactly with them.

Shells: the moments are accumulated in spherical shells of width Delta = half the finest
cell edge; a field point in shell j, at the fraction f of its width, takes the shells below
it plus f of its own for the inner moments and the shells above it plus (1 - f) of its own
for the outer ones.  Radii below Delta count as Delta (the potential is softened within half
a cell of the centre, where every l >= 1 term would otherwise diverge for a source or field
point there).

The moments are summed exactly: every cell's contribution is rounded to an integer number
of quanta (2^-36 of the largest contribution any cell of the mesh can make to that shell
and l, a relative error below 1e-10), so the sums do not depend on the order of the cells
and the potential is the same bit for bit on any number of threads or MPI ranks.

A 3d half domain (y >= 0, reflecting at y = 0; ``mirror_y``) stands for the whole body: the
mirror half adds the same cos moments and cancels the sin ones, and the centre of mass lies
at y = 0.

Acceleration g = -grad Phi (m/s^2) by central differences of Phi at the neighbouring cell
centres (Phi evaluated there from the expansion; O(dx^2)), applied as the momentum and
energy sources of :mod:`impactpipe.hydro.gravity`:

    (rho u)_new = (rho u)_old + rho g dt,   E_new = E_old + g . (rho u)_old dt + rho |g|^2 dt^2 / 2.

:attr:`SelfGravity.work` sums the energy it adds (J); :attr:`SelfGravity.potential_energy`
is W = (1/2) sum m Phi(x) (J) of the current mass, so that E_mesh + W is the conserved total
up to the splitting error (measured in tests/test_self_gravity.py and docs/hydro.md).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange
from scipy.constants import G

from impactpipe.hydro.gravity_kick import cell_volume, gravity_kick
from impactpipe.hydro.mesh.blocks import CYLINDRICAL, BlockMesh, ghost_widths
from impactpipe.hydro.mesh.state import HydroState

#: Default expansion order L.
DEFAULT_ORDER = 4
#: A cell's contribution is rounded to this fraction of the largest contribution possible in its shell.
QUANTUM = 2.0 ** -36


def harmonic_count(order: int, axisymmetric: bool) -> int:
    """Number of moment slots: L + 1 (m = 0 only) or (L + 1)^2 (cos and sin for m > 0)."""
    return order + 1 if axisymmetric else (order + 1) ** 2


@njit(cache=True, inline="always")
def _slot(l, m, cosine, axisymmetric):
    """Moment slot of (l, m, cos or sin): l (m = 0 only) or l^2 + 2m - (1 if cos else 0), m = 0 at l^2."""
    if axisymmetric:
        return l
    if m == 0:
        return l * l
    return l * l + 2 * m - (1 if cosine else 0)


@njit(cache=True)
def _harmonics(mu, cos_phi, sin_phi, order, axisymmetric, out):
    """Real harmonics P_l^m(mu) cos m phi and P_l^m(mu) sin m phi into ``out`` by slot
    (associated Legendre recursion without the Condon-Shortley phase, which cancels in the products)."""
    s = math.sqrt(max(1.0 - mu * mu, 0.0))
    pmm = 1.0
    cm, sm = 1.0, 0.0
    mmax = 0 if axisymmetric else order
    for m in range(mmax + 1):
        if m > 0:
            pmm *= (2 * m - 1) * s
            cm, sm = cm * cos_phi - sm * sin_phi, sm * cos_phi + cm * sin_phi
        p_prev = 0.0
        p = pmm
        for l in range(m, order + 1):
            if l == m + 1:
                p_prev, p = p, mu * (2 * m + 1) * pmm
            elif l > m + 1:
                p_prev, p = p, ((2 * l - 1) * mu * p - (l + m - 1) * p_prev) / (l - m)
            out[_slot(l, m, True, axisymmetric)] = p * cm
            if m > 0:
                out[_slot(l, m, False, axisymmetric)] = p * sm


def harmonic_weights(order: int, axisymmetric: bool) -> np.ndarray:
    """w_lm = (2 - delta_m0) (l - m)! / (l + m)! by slot (for both the cos and the sin slot)."""
    w = np.zeros(harmonic_count(order, axisymmetric))
    for l in range(order + 1):
        for m in [0] if axisymmetric else range(l + 1):
            value = (1.0 if m == 0 else 2.0) * math.factorial(l - m) / math.factorial(l + m)
            w[_slot(l, m, True, axisymmetric)] = value
            if m > 0:
                w[_slot(l, m, False, axisymmetric)] = value
    return w


def harmonic_bounds(order: int) -> np.ndarray:
    """(L + 1,) an upper bound of |P_l^m(mu)| over mu in [-1, 1] and m <= l, per l."""
    mu = np.linspace(-1.0, 1.0, 2001)
    out = np.zeros((order + 1) ** 2)
    bound = np.zeros(order + 1)
    for x in mu:
        _harmonics(x, 1.0, 0.0, order, False, out)
        for l in range(order + 1):
            bound[l] = max(bound[l], np.abs(out[l * l:(l + 1) ** 2]).max())
    return 1.01 * bound + 1e-300


@njit(cache=True, inline="always")
def _cell_mass(arho, geometry, ndim, block_lo, block_dx, b, ix, iy, iz, gx, gy, gz):
    """(mass (kg), centre x, y, z (m)) of interior cell (ix, iy, iz) of block b (padded indices,
    ``gx, gy, gz`` the ghost widths): sum_k alpha_k rho_k times the cell volume (annulus in r-z)."""
    dx0 = block_dx[b, 0]
    dx1 = block_dx[b, 1] if ndim > 1 else 1.0
    dx2 = block_dx[b, 2] if ndim > 2 else 1.0
    r_lo = block_lo[b, 0] + (ix - gx) * dx0
    rho = 0.0
    for k in range(arho.shape[1]):
        rho += arho[b, k, ix, iy, iz]
    return (rho * cell_volume(geometry, r_lo, dx0, dx1, dx2), r_lo + 0.5 * dx0,
            block_lo[b, 1] + (iy - gy + 0.5) * dx1, block_lo[b, 2] + (iz - gz + 0.5) * dx2)


@njit(cache=True, parallel=True)
def block_mass_moments(arho, block_lo, block_dx, geometry, ndim, out):
    """Per block: mass (kg), mass x position (3 components, kg m) and the largest cell mass
    (kg) into ``out[NB, 5]`` (each block's cells summed in order)."""
    nb, nmat, nx, ny, nz = arho.shape
    gx, gy, gz = ghost_widths(nx, ny, nz)
    for b in prange(nb):
        mass = 0.0
        mx = 0.0
        my = 0.0
        mz = 0.0
        largest = 0.0
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    m, x, y, z = _cell_mass(arho, geometry, ndim, block_lo, block_dx, b, ix, iy, iz, gx, gy, gz)
                    mass += m
                    largest = max(largest, m)
                    if geometry == CYLINDRICAL:
                        my += m * y  # z of the ring, the only component of its centre of mass
                    else:
                        mx += m * x
                        my += m * y
                        mz += m * z
        out[b, 0] = mass
        out[b, 1] = mx
        out[b, 2] = my
        out[b, 3] = mz
        out[b, 4] = largest


@njit(cache=True, inline="always")
def _spherical(geometry, x, y, z, center):
    """(r, cos theta, cos phi, sin phi) of a point about ``center`` (axis z; in 2d-cylindrical
    the point is (r_cyl, z) and the axis the cylinder's)."""
    if geometry == CYLINDRICAL:
        dz = y - center[1]
        r = math.sqrt(x * x + dz * dz)
        return r, (dz / r if r > 0.0 else 1.0), 1.0, 0.0
    dx = x - center[0]
    dy = y - center[1]
    dz = z - center[2]
    rho2 = dx * dx + dy * dy
    r = math.sqrt(rho2 + dz * dz)
    rho = math.sqrt(rho2)
    if rho > 0.0:
        return r, (dz / r), dx / rho, dy / rho
    return r, (1.0 if dz >= 0.0 else -1.0), 1.0, 0.0


@njit(cache=True, parallel=True)
def shell_moments(arho, block_lo, block_dx, geometry, ndim, center, shell, order, quantum_in, quantum_out,
                  lo, hi, work, inner, outer):
    """Integer inner and outer moments per shell of the cells of blocks ``lo .. hi - 1`` into
    ``inner``, ``outer`` (int64[threads, shells, slots], added to; module docstring).

    ``quantum_in``, ``quantum_out`` [shells, L + 1]: the quantum of each shell and l;
    ``work`` [threads, slots] per-thread harmonic scratch.
    """
    nb, nmat, nx, ny, nz = arho.shape
    gx, gy, gz = ghost_widths(nx, ny, nz)
    nshell = inner.shape[1]
    axisymmetric = geometry == CYLINDRICAL
    for b in prange(lo, hi):
        t = numba.get_thread_id()
        harm = work[t]
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    m, x, y, z = _cell_mass(arho, geometry, ndim, block_lo, block_dx, b, ix, iy, iz, gx, gy, gz)
                    if m <= 0.0:
                        continue
                    r, mu, cp, sp = _spherical(geometry, x, y, z, center)
                    j = min(int(r / shell), nshell - 1)
                    reff = max(r, shell)
                    _harmonics(mu, cp, sp, order, axisymmetric, harm)
                    up = m  # m r'^l
                    down = m / reff  # m r'^-(l+1), softened
                    for l in range(order + 1):
                        first = l if axisymmetric else l * l
                        last = l + 1 if axisymmetric else (l + 1) * (l + 1)
                        for s in range(first, last):
                            inner[t, j, s] += np.int64(round(up * harm[s] / quantum_in[j, l]))
                            outer[t, j, s] += np.int64(round(down * harm[s] / quantum_out[j, l]))
                        up *= r
                        down /= reff


@njit(cache=True)
def _potential(geometry, x, y, z, center, shell, order, weights, cin, cout, own_in, own_out, harm):
    """Phi (J/kg, without the factor -G) at (x, y, z) from the cumulative shell moments."""
    axisymmetric = geometry == CYLINDRICAL
    nshell = cin.shape[0]
    r, mu, cp, sp = _spherical(geometry, x, y, z, center)
    j = min(int(r / shell), nshell - 1)
    f = min(r / shell - j, 1.0)
    reff = max(r, shell)
    _harmonics(mu, cp, sp, order, axisymmetric, harm)
    total = 0.0
    up = 1.0  # r^l
    down = 1.0 / reff  # r^-(l+1), softened
    for l in range(order + 1):
        first = l if axisymmetric else l * l
        last = l + 1 if axisymmetric else (l + 1) * (l + 1)
        for s in range(first, last):
            inner = cin[j, s] + f * own_in[j, s]
            outer = cout[j, s] + (1.0 - f) * own_out[j, s]
            total += weights[s] * harm[s] * (down * inner + up * outer)
        up *= r
        down /= reff
    return total


@njit(cache=True, parallel=True)
def potential_field(geometry, ndim, block_lo, block_dx, block_mass, center, shell, order, weights, cin, cout, own_in,
                    own_out, lo, hi, work, phi):
    """Phi (J/kg) at the centres of the interior cells and one ghost layer of the blocks
    ``lo .. hi - 1`` that hold mass (``block_mass[b]`` > 0, kg) into ``phi[NB, NX, NY, NZ]``
    (padded indices); the kicks use it only where there is mass."""
    nb, nx, ny, nz = phi.shape
    gx, gy, gz = ghost_widths(nx, ny, nz)
    ex, ey, ez = min(gx, 1), min(gy, 1), min(gz, 1)
    for b in prange(lo, hi):
        if block_mass[b] <= 0.0:
            continue
        harm = work[numba.get_thread_id()]
        dx0 = block_dx[b, 0]
        dx1 = block_dx[b, 1] if ndim > 1 else 1.0
        dx2 = block_dx[b, 2] if ndim > 2 else 1.0
        for ix in range(gx - ex, nx - gx + ex):
            x = block_lo[b, 0] + (ix - gx + 0.5) * dx0
            for iy in range(gy - ey, ny - gy + ey):
                y = block_lo[b, 1] + (iy - gy + 0.5) * dx1
                for iz in range(gz - ez, nz - gz + ez):
                    z = block_lo[b, 2] + (iz - gz + 0.5) * dx2
                    phi[b, ix, iy, iz] = -G * _potential(geometry, abs(x) if geometry == CYLINDRICAL else x, y, z,
                                                         center, shell, order, weights, cin, cout, own_in, own_out,
                                                         harm)


@njit(cache=True, parallel=True)
def apply_self_gravity(dt, geometry, ndim, phi, arho, momentum, energy, block_lo, block_dx, lo, hi, block_work,
                       block_potential):
    """Kick every interior cell of blocks ``lo .. hi - 1`` by g = -grad Phi over ``dt`` (s)
    (module docstring); per block the work done (J) into ``block_work`` and
    (1/2) sum m Phi (J) into ``block_potential``."""
    nb, nmat, nx, ny, nz = arho.shape
    gx, gy, gz = ghost_widths(nx, ny, nz)
    for b in prange(lo, hi):
        dx0 = block_dx[b, 0]
        dx1 = block_dx[b, 1] if ndim > 1 else 1.0
        dx2 = block_dx[b, 2] if ndim > 2 else 1.0
        work = 0.0
        pot = 0.0
        for ix in range(gx, nx - gx):
            r_lo = block_lo[b, 0] + (ix - gx) * dx0
            vol = cell_volume(geometry, r_lo, dx0, dx1, dx2)
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    rho = 0.0
                    for k in range(nmat):
                        rho += arho[b, k, ix, iy, iz]
                    if rho <= 0.0:
                        continue
                    g0 = -(phi[b, ix + 1, iy, iz] - phi[b, ix - 1, iy, iz]) / (2.0 * dx0)
                    g1 = -(phi[b, ix, iy + 1, iz] - phi[b, ix, iy - 1, iz]) / (2.0 * dx1) if ndim > 1 else 0.0
                    g2 = -(phi[b, ix, iy, iz + 1] - phi[b, ix, iy, iz - 1]) / (2.0 * dx2) if ndim > 2 else 0.0
                    work += gravity_kick(dt, g0, g1, g2, rho, momentum, energy, b, ix, iy, iz) * vol
                    pot += 0.5 * rho * vol * phi[b, ix, iy, iz]
        block_work[b] = work
        block_potential[b] = pot


class SelfGravity:
    """The self-gravity of the mass on a :class:`BlockMesh` (module docstring).

    Args:
        mesh: the mesh (3d or 2d-cylindrical).
        order: expansion order L (>= 0; 0 is the monopole, exact for spherical symmetry).
        mirror_y: the mesh is the y >= 0 half of a body symmetric about y = 0 (3d only).

    Attributes:
        work: energy the gravity has added to the mesh since the start (J).
        potential_energy: W = (1/2) sum m Phi of the mass at the last step (J).
        center: (3,) the expansion centre, the centre of mass (m; (0, z, 0) in 2d-cylindrical).
    """

    def __init__(self, mesh: BlockMesh, order: int = DEFAULT_ORDER, mirror_y: bool = False):
        if mesh.geometry not in ("3d", "2d-cylindrical"):
            raise ValueError(f"self-gravity needs a 3d or 2d-cylindrical mesh (got {mesh.geometry})")
        if mirror_y and mesh.geometry != "3d":
            raise ValueError("self-gravity: mirror_y applies to a 3d half domain only")
        if not 0 <= int(order) <= 16:
            raise ValueError(f"self-gravity order must lie in 0 .. 16 (got {order})")
        self.order = int(order)
        self.mirror_y = bool(mirror_y)
        self.geometry_code = mesh.geometry_code
        self.ndim = mesh.ndim
        self.axisymmetric = mesh.geometry == "2d-cylindrical"
        self.work = 0.0
        self.potential_energy = 0.0
        self.center = np.zeros(3)
        nh = harmonic_count(self.order, self.axisymmetric)
        self._weights = harmonic_weights(self.order, self.axisymmetric)
        self._bounds = harmonic_bounds(self.order)
        self._slot_l = np.array([l for l in range(self.order + 1)
                                 for _ in range(1 if self.axisymmetric else 2 * l + 1)])
        self._cos = np.array([True] if self.axisymmetric else
                             [s == l * l or (s - l * l) % 2 == 1 for l in range(self.order + 1)
                              for s in range(l * l, (l + 1) ** 2)])
        threads = numba.config.NUMBA_NUM_THREADS
        self._harm = np.zeros((threads, nh))
        self._phi = np.zeros(0)
        #: (first, one past the last) block whose rows of ``_phi`` this process writes.
        self._phi_rows = (0, 0)
        #: Per-thread integer inner and outer shell moments, kept between steps.
        self._moments = np.zeros((2, 0, 0, 0), dtype=np.int64)
        self._rows = np.zeros((0, 5))
        self._block_work = np.zeros(0)
        self._block_potential = np.zeros(0)

    def spec(self) -> dict:
        """What rebuilds this object (:func:`impactpipe.hydro.gravity.gravity_from_spec`)."""
        return {"kind": "self", "order": self.order, "mirror_y": self.mirror_y, "work": self.work}

    def _allocate(self, mesh: BlockMesh, partition=None) -> None:
        """New per-block arrays when the mesh's blocks or the range of them this process advances
        changed (a regrid): the potential in the partition's zeros (every prepare sets the rows
        of that range, and no other row is read), the per-block rows in numpy's."""
        nb = mesh.nblocks
        rows = (0, nb) if partition is None else tuple(partition.blocks.indices(nb)[:2])
        if self._phi.shape != (nb,) + mesh.padded_shape or self._phi_rows != rows:
            zeros = np.zeros if partition is None else partition.zeros
            self._phi = zeros((nb,) + mesh.padded_shape)
            self._phi_rows = rows
            self._rows = np.zeros((nb, 5))
            self._block_work = np.zeros(nb)
            self._block_potential = np.zeros(nb)

    def prepare(self, state: HydroState, mesh: BlockMesh, partition=None) -> None:
        """The potential of the current mass at the cells of the blocks this process advances
        (and one layer around them): centre of mass, exact shell moments, Phi."""
        self._allocate(mesh, partition)
        nb = mesh.nblocks
        own = slice(0, nb) if partition is None else partition.blocks
        lo, hi, _ = own.indices(nb)
        rows = self._rows
        block_mass_moments(state.arho[own], mesh.block_lo[own], mesh.block_dx[own], self.geometry_code, self.ndim,
                           rows[own])
        if partition is not None:
            partition.share_rows(rows)
        mass = float(rows[:, 0].sum())
        largest = float(rows[:, 4].max(initial=0.0))
        self._phi[own] = 0.0
        if mass <= 0.0:
            return
        if self.axisymmetric:
            self.center = np.array([0.0, rows[:, 2].sum() / mass, 0.0])
        else:
            self.center = rows[:, 1:4].sum(axis=0) / mass
            if self.mirror_y:
                self.center[1] = 0.0
        shell = 0.5 * float(mesh.block_dx[:, :self.ndim].min())
        corners = np.stack([mesh.block_lo.min(axis=0), mesh.block_hi.max(axis=0)])
        extent = np.abs(corners - self.center).max(axis=0)[:self.ndim]
        if self.axisymmetric:
            extent[0] = np.abs(corners[:, 0]).max()
        nshell = int(np.linalg.norm(extent) / shell) + 2
        radii = np.arange(nshell + 1) * shell
        powers = np.arange(self.order + 1)
        quantum_in = largest * self._bounds * QUANTUM * radii[1:, None] ** powers
        quantum_out = largest * self._bounds * QUANTUM * np.maximum(radii[:-1], shell)[:, None] ** -(powers + 1.0)
        shape = self._harm.shape[:1] + (nshell,) + self._harm.shape[1:]
        if self._moments.shape[1:] != shape:
            self._moments = np.zeros((2,) + shape, dtype=np.int64)
        self._moments[:] = 0
        shell_moments(state.arho, mesh.block_lo, mesh.block_dx, self.geometry_code, self.ndim, self.center, shell,
                      self.order, quantum_in, quantum_out, lo, hi, self._harm, self._moments[0], self._moments[1])
        inner = self._moments[0].sum(axis=0)
        outer = self._moments[1].sum(axis=0)
        if partition is not None:
            partition.sum_integers(inner)
            partition.sum_integers(outer)
        own_in = inner * quantum_in[:, self._slot_l]
        own_out = outer * quantum_out[:, self._slot_l]
        if self.mirror_y:
            mirror = np.where(self._cos, 2.0, 0.0)
            own_in *= mirror
            own_out *= mirror
        cin = np.cumsum(own_in, axis=0) - own_in
        cout = np.cumsum(own_out[::-1], axis=0)[::-1] - own_out
        potential_field(self.geometry_code, self.ndim, mesh.block_lo, mesh.block_dx, np.ascontiguousarray(rows[:, 0]),
                        self.center, shell, self.order, self._weights, cin, cout, own_in, own_out, lo, hi, self._harm,
                        self._phi)

    def potential(self, mesh: BlockMesh) -> np.ndarray:
        """Phi (J/kg) at the interior cells of the blocks this process advanced at the last
        :meth:`prepare` (block-shaped, interior cells only)."""
        return mesh.interior(self._phi[:, None])[:, 0]

    def advance(self, state: HydroState, dt: float, block_lo: np.ndarray, block_dx: np.ndarray,
                partition=None) -> None:
        """Kick the interior cells of this process's blocks by g = -grad Phi over ``dt`` (s)
        with the potential of the last :meth:`prepare`; the work (J) and W (J) are summed over
        every block in block order (other processes' rows received first)."""
        nb = state.arho.shape[0]
        own = slice(0, nb) if partition is None else partition.blocks
        lo, hi, _ = own.indices(nb)
        apply_self_gravity(dt, self.geometry_code, self.ndim, self._phi, state.arho, state.momentum, state.energy,
                           block_lo, block_dx, lo, hi, self._block_work, self._block_potential)
        if partition is not None:
            partition.share_rows(self._block_work)
            partition.share_rows(self._block_potential)
        self.work += float(self._block_work.sum())
        self.potential_energy = float(self._block_potential.sum())
