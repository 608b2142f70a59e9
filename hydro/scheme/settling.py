"""Void under a load settles out at the end of each step (``Simulation.void_settling``; 2d-planar, one level).

A cell that holds some void and some material at no tension is at zero pressure: the volume
closure relaxes the material of a cell with void to p = 0 (docs/hydro.md, "Volume closure"),
and the sweeps close the void only at the rate their face velocities carry material into it,
which for a stiff material under a load of Delta p is of the order of Delta p / (rho c), a
fraction of a metre per second.  A cohesionless granular material there holds no strength.
At a free surface (void above the material) that is right; inside a granular flow (void that
the flow's shear or stretching put under material resting on it) it is not: grains do not
stay dilated under a load, the material above falls into the gap within sqrt(2 h / g) (h the
gap, at most a cell), and in the granular column collapse the flow rode on floor cells held
open at zero pressure, with a floor friction that fell with the cell size and a run-out that
grew with resolution (docs/validation.md, "Granular column collapse").

:func:`settle_void` closes such void at the end of each step, after the sweeps and the tensile
limit: in every column of cells along the gravity axis, from the floor up, a cell that holds
material (fill phi_r = sum_k alpha_k >= PHI_VOID) and void (phi_r < 1 - FULL_GAP) takes the volume

    v = min(1 - phi_r, phi_d)

from the lowest cell above it that still holds material (the donor, fill phi_d; the cells
between are donors emptied before it), the share q = v / phi_d of each of the donor's amounts
(alpha_k, alpha_k rho_k, alpha_k rho_k e_k, the transported scalars, momentum, total energy):
mass, momentum and total energy are conserved, the column is compacted downwards in one pass,
and the void ends in the topmost cell of each contiguous stack of material (its free surface).
Material above a cell that held none (phi < PHI_VOID) is left alone: it rests on nothing.  The
merged cell's velocity is the momentum-weighted mean; the kinetic energy that merging the two
velocities removes, and the potential energy m g h the moved mass m (kg/m^3) loses in falling
through the gap h = (d - r - phi_r) dx (d, r the donor's and the receiver's rows), go into the
receiver's internal energy (each material by its mass share), and the latter is added to the
work of gravity (``block_work``), so the energy budget stays closed.  Each transfer counts in
``counts[b]`` of the receiver's block.  The void is closed whatever the step, so the result
does not depend on the time step; impact scenes do not use it.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from impactpipe.hydro.mesh.blocks import GHOST
from impactpipe.hydro.scheme.timestep import PHI_VOID

#: A cell whose fill is within this of 1 counts as full: no void to settle out.
FULL_GAP = 1.0e-9


@njit(cache=True, inline="always")
def _fill(alpha, b, ix, iy, iz):
    """Material volume fraction sum_k alpha_k of a cell (-)."""
    f = 0.0
    for k in range(alpha.shape[1]):
        f += alpha[b, k, ix, iy, iz]
    return f


@njit(cache=True)
def _transfer(alpha, arho, arhoe, arhoq, momentum, energy, rb, ri, db, di, ix, iz, q, drop):
    """Move the share ``q`` (0 < q <= 1) of the amounts of donor cell (db, ix, di, iz) into the
    receiver (rb, ix, ri, iz) (module docstring); ``drop`` is g times the fall height (J/kg).
    Returns the potential energy released per unit volume (J/m^3)."""
    nmat = alpha.shape[1]
    keep = 1.0 - q
    m_r = 0.0
    m_d = 0.0
    for k in range(nmat):
        m_r += arho[rb, k, ix, ri, iz]
        m_d += q * arho[db, k, ix, di, iz]
    lost = 0.0
    for c in range(3):
        pr = momentum[rb, c, ix, ri, iz]
        pd = q * momentum[db, c, ix, di, iz]
        lost += (0.5 * pr * pr / m_r if m_r > 0.0 else 0.0) + 0.5 * pd * pd / m_d
        lost -= 0.5 * (pr + pd) * (pr + pd) / (m_r + m_d)
        momentum[rb, c, ix, ri, iz] = pr + pd
        momentum[db, c, ix, di, iz] *= keep
    released = m_d * drop
    heat = max(lost, 0.0) + released
    m_new = m_r + m_d
    energy[rb, 0, ix, ri, iz] += q * energy[db, 0, ix, di, iz] + released
    energy[db, 0, ix, di, iz] *= keep
    for k in range(nmat):
        share = (arho[rb, k, ix, ri, iz] + q * arho[db, k, ix, di, iz]) / m_new
        alpha[rb, k, ix, ri, iz] += q * alpha[db, k, ix, di, iz]
        arho[rb, k, ix, ri, iz] += q * arho[db, k, ix, di, iz]
        arhoe[rb, k, ix, ri, iz] += q * arhoe[db, k, ix, di, iz] + share * heat
        alpha[db, k, ix, di, iz] *= keep
        arho[db, k, ix, di, iz] *= keep
        arhoe[db, k, ix, di, iz] *= keep
    for j in range(arhoq.shape[1]):
        arhoq[rb, j, ix, ri, iz] += q * arhoq[db, j, ix, di, iz]
        arhoq[db, j, ix, di, iz] *= keep
    return released


@njit(cache=True, parallel=True)
def settle_void(alpha, arho, arhoe, arhoq, momentum, energy, neighbor, block_dx, gravity, block_work, counts):
    """Compact every column of cells along mesh axis 1 downwards (gravity ``gravity`` > 0, m/s^2,
    along -axis 1; 2d-planar, every block on one level); see the module docstring.

    Fields ``(NB, C, NX, NY, 1)`` with ghosts: ``alpha`` (-), ``arho`` alpha_k rho_k (kg/m^3),
    ``arhoe`` alpha_k rho_k e_k (J/m^3), ``arhoq`` the transported scalars, ``momentum`` (kg/(m^2 s)),
    ``energy`` the total energy density (J/m^3).  ``neighbor[NB, 3, 2]`` the block neighbours
    (a negative code at a domain face).  ``block_work[b]`` receives the potential energy released
    in block b's cells (J per m of depth), ``counts[b]`` the transfers into them.

    Per column, from the floor up, the receiver r is the lowest cell not yet full that is in
    contact with the material below it, and each cell d above it in turn gives it material
    until r is full (then r moves up) or d is empty (then the next d gives): a cell that held
    no material (fill below PHI_VOID) breaks the contact, and the receiver starts again above
    it.  The fall height of a transfer is (d - r - phi_r) dx, the gap between the top of the
    receiver's material and the bottom of the donor's cell.
    """
    nb, nmat, nx, ny, nz = alpha.shape
    rows = ny - 2 * GHOST
    for i in prange(nb):
        b0 = np.int64(i)
        if neighbor[b0, 1, 0] >= 0:
            continue
        dx = block_dx[b0, 1]
        vol = block_dx[b0, 0] * dx
        chain = 0
        b = b0
        while b >= 0:
            chain += 1
            b = neighbor[b, 1, 1]
        cell_block = np.empty(chain * rows, np.int64)
        cell_row = np.empty(chain * rows, np.int64)
        b = b0
        n = 0
        while b >= 0:
            for iy in range(GHOST, ny - GHOST):
                cell_block[n] = b
                cell_row[n] = iy
                n += 1
            b = neighbor[b, 1, 1]
        for ix in range(GHOST, nx - GHOST):
            r = 0
            for d in range(n):
                db = cell_block[d]
                di = cell_row[d]
                f_d = _fill(alpha, db, ix, di, 0)
                if f_d < PHI_VOID:
                    r = d + 1
                    continue
                while r < d:
                    rb = cell_block[r]
                    ri = cell_row[r]
                    f_r = _fill(alpha, rb, ix, ri, 0)
                    if f_r >= 1.0 - FULL_GAP:
                        r += 1
                        continue
                    gap = 1.0 - f_r
                    q = min(gap / f_d, 1.0)
                    released = _transfer(alpha, arho, arhoe, arhoq, momentum, energy, rb, ri, db, di, ix, 0, q,
                                         gravity * max(d - r - f_r, 0.0) * dx)
                    block_work[rb] += released * vol
                    counts[rb] += 1
                    if q >= 1.0:
                        break
                    f_d = _fill(alpha, db, ix, di, 0)
