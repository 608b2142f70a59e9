"""Where the mesh refines: per-block indicators of interfaces, shocks and user boxes.

For every interior cell and used axis d, with its neighbours i - 1 and i + 1 along d (ghosts
filled), three indicators are evaluated and their maxima over a block's cells returned:

- interface: max_k |alpha_k,i+1 - alpha_k,i-1| and |phi_i+1 - phi_i-1| (phi = sum_k alpha_k,
  so void counts) above INTERFACE_JUMP = 0.1: a material interface or a free surface crosses
  the cell;
- pressure jump: |p_i+1 - p_i-1| / (|p_i+1| + |p_i-1| + p_floor) where material fills both
  neighbours (sum_k alpha_k >= PHI_SECOND_ORDER), the relative pressure difference across
  the cell (1 at a shock into material at rest, ~0 in smooth flow; the step to zero at a
  loaded free surface belongs to the interface indicator);
  ``p_floor`` (Pa, a fraction of the largest |p| of the run) keeps round-off and the
  acoustic noise left behind a decayed shock out;
- density jump: |rho_i+1 - rho_i-1| / (rho_i+1 + rho_i-1) where one material fills both
  neighbours (alpha_k >= PHI_SECOND_ORDER): compressions within a material; the density
  steps at interfaces and free surfaces belong to the interface indicator.

An interface is ``active`` where its block moves or is loaded: the block's largest |p| or
speed exceeds ``activity_floor`` (default: ``pressure_floor``) times the largest |p| of the
run / the largest speed on the mesh.  The free surface of a body
at rest (or far from anything that happens) then does not hold the finest level; with
``interfaces: all`` every interface does.

A block is refined when an indicator exceeds its threshold (interface: INTERFACE_JUMP) and
may be coarsened when every enabled indicator stays below half of it (hysteresis, so a block
does not flip between levels every regrid).  The indicators look one cell beyond the block
(its ghosts).  A jump also refines neighbouring blocks, so that a moving shock stays inside
refined blocks until the next regrid: every neighbour (``buffer: block``), or with ``buffer:
reach`` only those across the faces, edges and corners the jump lies within ``margin``
cells of, the distance a wave crosses between two regrids (:func:`block_indicators` records
the jumps near each face; :func:`impactpipe.hydro.amr.regrid.block_wants`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from impactpipe.hydro.mesh.blocks import ghost_widths
from impactpipe.hydro.mesh.cells import shifted_cell
from impactpipe.hydro.scheme.mixture import mixture_state
from impactpipe.hydro.scheme.pencil_layout import PHI_SECOND_ORDER

#: A volume fraction changing by more than this across a cell marks an interface or free
#: surface (not the percent-level void that tensile failure opens inside a body).
INTERFACE_JUMP = 0.1
#: Indicator columns of :func:`block_indicators`: the three jumps, then the block's largest
#: |p| (Pa) and speed (m/s).
IND_INTERFACE, IND_PRESSURE, IND_DENSITY, IND_MAX_PRESSURE, IND_MAX_SPEED = range(5)
NINDICATOR = 5


@njit(cache=True, parallel=True)
def mixture_pressure(alpha, arho, arhoe, arhoq, eos_kind, eos_params, eos_table, shear_modulus, tensile_strength,
                     out, grady_kipp=None, porosity=None, void=None):
    """Pressure sum_k alpha_k p_k (Pa) of the interior cells and their face neighbours in the first
    ghost layer, what :func:`block_indicators` reads, into ``out[NB, NX, NY, NZ]``; the other
    cells (the second ghost layer, the corners) keep what ``out`` holds.

    The mixture pressure of :func:`impactpipe.hydro.scheme.mixture.mixture_state`: p_k is limited by
    the tension material k still holds, Y_T,k (1 - D_k), as in the sweeps (and scaled by 1 - D_k for
    the Grady-Kipp materials of ``grady_kipp``), porous materials (``porosity``) at their distension.
    Blocks b with ``void[b]`` != 0 (uint8, when given; void ghosts included,
    :func:`impactpipe.hydro.mesh.last_good.void_blocks`) are skipped: their pressure is 0.0, as
    ``out`` must hold there already.
    """
    nb, nmat, nx, ny, nz = alpha.shape
    gx, gy, gz = ghost_widths(nx, ny, nz)
    for b in prange(nb):
        if void is not None and void[b] != 0:
            continue
        for ix in range(max(gx - 1, 0), nx - max(gx - 1, 0)):
            outside_x = (ix < gx) + (ix >= nx - gx)
            for iy in range(max(gy - 1, 0), ny - max(gy - 1, 0)):
                outside_xy = outside_x + (iy < gy) + (iy >= ny - gy)
                if outside_xy > 1:
                    continue
                for iz in range(max(gz - 1, 0), nz - max(gz - 1, 0)):
                    if outside_xy + (iz < gz) + (iz >= nz - gz) > 1:
                        continue
                    rho, phi, p, kmod, eint, tmass, clamps, limits = mixture_state(
                        alpha, arho, arhoe, arhoq, b, ix, iy, iz, eos_kind, eos_params, eos_table, shear_modulus,
                        tensile_strength, False, None, 0, 0, grady_kipp, porosity)
                    out[b, ix, iy, iz] = p


@njit(cache=True, parallel=True)
def block_indicators(alpha, arho, mom, pressure, ndim, p_floor, margin, out, near, void=None):
    """Per block the largest interface, pressure-jump and density-jump indicators, |p| (Pa) and speed
    (m/s) into ``out[NB, 5]``, and into ``near[NB, 3, 2, 2]`` (axis, side 0 = low / 1 = high, jump 0 =
    pressure / 1 = density) the largest jumps of the cells within ``margin`` cells of each face (the
    cells 0 .. margin - 1 counted from it).  Blocks b with ``void[b]`` != 0 (uint8, when given: void
    ghosts included, pressure 0.0) are skipped, their indicators all 0.0, as ``out`` and ``near``
    must hold there already."""
    nb, nmat, nx, ny, nz = alpha.shape
    gx, gy, gz = ghost_widths(nx, ny, nz)
    for b in prange(nb):
        if void is not None and void[b] != 0:
            continue
        # the block's own arrays: three or four indices per read instead of five
        ab = alpha[b]
        rb = arho[b]
        mb = mom[b]
        pb = pressure[b]
        face = 0.0
        pjump = 0.0
        rjump = 0.0
        pmax = 0.0
        vmax = 0.0
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    pmax = max(pmax, abs(pb[ix, iy, iz]))
                    rho = 0.0
                    for k in range(nmat):
                        rho += rb[k, ix, iy, iz]
                    if rho > 0.0:
                        speed2 = (mb[0, ix, iy, iz] ** 2 + mb[1, ix, iy, iz] ** 2
                                  + mb[2, ix, iy, iz] ** 2)
                        vmax = max(vmax, np.sqrt(speed2) / rho)
                    cell_p = 0.0
                    cell_r = 0.0
                    for d in range(ndim):
                        lx, ly, lz = shifted_cell(ix, iy, iz, d, -1)
                        hx, hy, hz = shifted_cell(ix, iy, iz, d, 1)
                        phi_l = 0.0
                        phi_h = 0.0
                        rho_l = 0.0
                        rho_h = 0.0
                        same = False
                        for k in range(nmat):
                            al = ab[k, lx, ly, lz]
                            ah = ab[k, hx, hy, hz]
                            same = same or (al >= PHI_SECOND_ORDER and ah >= PHI_SECOND_ORDER)
                            face = max(face, abs(ah - al))
                            phi_l += al
                            phi_h += ah
                            rho_l += rb[k, lx, ly, lz]
                            rho_h += rb[k, hx, hy, hz]
                        face = max(face, abs(phi_h - phi_l))
                        if phi_l >= PHI_SECOND_ORDER and phi_h >= PHI_SECOND_ORDER:
                            p_l = pb[lx, ly, lz]
                            p_h = pb[hx, hy, hz]
                            cell_p = max(cell_p, abs(p_h - p_l) / (abs(p_h) + abs(p_l) + p_floor))
                        if same:
                            cell_r = max(cell_r, abs(rho_h - rho_l) / (rho_h + rho_l))
                    pjump = max(pjump, cell_p)
                    rjump = max(rjump, cell_r)
                    if cell_p > 0.0 or cell_r > 0.0:
                        for d in range(ndim):
                            if d == 0:
                                low, high = ix - gx, nx - gx - 1 - ix
                            elif d == 1:
                                low, high = iy - gy, ny - gy - 1 - iy
                            else:
                                low, high = iz - gz, nz - gz - 1 - iz
                            if low < margin:
                                near[b, d, 0, 0] = max(near[b, d, 0, 0], cell_p)
                                near[b, d, 0, 1] = max(near[b, d, 0, 1], cell_r)
                            if high < margin:
                                near[b, d, 1, 0] = max(near[b, d, 1, 0], cell_p)
                                near[b, d, 1, 1] = max(near[b, d, 1, 1], cell_r)
        out[b, IND_INTERFACE] = face
        out[b, IND_PRESSURE] = pjump
        out[b, IND_DENSITY] = rjump
        out[b, IND_MAX_PRESSURE] = pmax
        out[b, IND_MAX_SPEED] = vmax


def box_levels(block_lo: np.ndarray, block_hi: np.ndarray, ndim: int, boxes) -> np.ndarray:
    """(NB,) the finest level any user box asks of each block (0 where none overlaps it).

    ``boxes`` is a list of (lo (ndim,), hi (ndim,), level) with lo, hi in m.
    """
    want = np.zeros(len(block_lo), dtype=np.int64)
    for lo, hi, level in boxes:
        lo = np.asarray(lo, dtype=float)[:ndim]
        hi = np.asarray(hi, dtype=float)[:ndim]
        overlap = ((block_lo[:, :ndim] < hi) & (block_hi[:, :ndim] > lo)).all(axis=1)
        want = np.where(overlap, np.maximum(want, int(level)), want)
    return want
