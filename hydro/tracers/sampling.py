"""Tracer kernels that read the mesh: the material velocity at a tracer (adaptive-mesh stencils
across level faces) and the peak pressure and temperature of its cell."""

from __future__ import annotations

import math

from numba import njit, prange

from impactpipe.hydro.eos import pressure_sound_speed, temperature
from impactpipe.hydro.eos.porosity import ALPHA0
from impactpipe.hydro.mesh.blocks import GHOST, REFLECTING
from impactpipe.hydro.scheme.mixture import ALPHA_MIN
from impactpipe.hydro.tracers.locate import PERIODIC

@njit(cache=True, inline="always")
def _cell_block(g, lev, m, block_cells):
    """Index on the level-``m`` block grid of the block covering cell ``g`` of level ``lev``."""
    if m <= lev:
        return (g >> (lev - m)) // block_cells
    return (g << (m - lev)) // block_cells


@njit(cache=True, inline="always")
def _leaf_of_cell(g0, g1, g2, lev, block_cells, root, children):
    """(leaf block, its level m) covering cell (g0, g1, g2) of level ``lev`` (unused axes 0).

    m < lev: the leaf is coarser than the cell; m >= lev: the cell is the 2^(m - lev) cells
    per used axis from g 2^(m - lev) of that leaf (all in it: a stencil spans levels L - 1 to
    L + 1 around a block of level L by the 2:1 balance, so m - lev <= 2, and block_cells is
    a multiple of 4 on a refined mesh, :meth:`Tracers.mesh_changed`).
    """
    i0 = _cell_block(g0, lev, 0, block_cells)
    i1 = _cell_block(g1, lev, 0, block_cells)
    i2 = _cell_block(g2, lev, 0, block_cells)
    code = root[i0, i1, i2]
    m = 0
    while code < 0:
        m += 1
        j0 = _cell_block(g0, lev, m, block_cells)
        j1 = _cell_block(g1, lev, m, block_cells)
        j2 = _cell_block(g2, lev, m, block_cells)
        code = children[-1 - code, (j0 - 2 * i0) + 2 * (j1 - 2 * i1) + 4 * (j2 - 2 * i2)]
        i0, i1, i2 = j0, j1, j2
    return code, m


@njit(cache=True, inline="always")
def _wrap(g, n, low, high):
    """(cell index in [0, n), velocity sign) for cell ``g`` of an axis of ``n`` cells with the
    domain-face codes ``low`` and ``high`` (|g| or g - n at most one cell outside).

    Periodic wraps, reflecting mirrors (g -> -1 - g or 2 n - 1 - g, sign -1), outflow
    repeats the edge cell.
    """
    if g < 0:
        if low == PERIODIC:
            return g + n, 1.0
        if low == REFLECTING:
            return -1 - g, -1.0
        return 0, 1.0
    if g >= n:
        if high == PERIODIC:
            return g - n, 1.0
        if high == REFLECTING:
            return 2 * n - 1 - g, -1.0
        return n - 1, 1.0
    return g, 1.0


@njit(cache=True, inline="always")
def _base(x, b, lev, d, ndim, block_lo, block_dx, block_index, block_level, block_cells):
    """Lower stencil cell and the weight of the upper cell along axis ``d`` on the level-``lev``
    cell grid (lev <= the level of block ``b``), for the point x inside block ``b``.

    The cell index i counts from cell q, the level-lev cell holding the block's first cell
    f = block_index[b, d] block_cells; with r = 2^(level_b - lev) and f = r q + p,
    s = ((x - block_lo) / dx_b + p) / r - 0.5 is the point's position in level-lev cells
    from the centre of cell q: i = floor(s), weight s - i.  On the block's own level
    (r = 1, q = f) this is s = (x - block_lo) / dx_b - 0.5.
    """
    if d >= ndim:
        return 0, 0.0
    shift = block_level[b] - lev
    if shift == 0:
        s = (x - block_lo[b, d]) / block_dx[b, d] - 0.5
    else:
        first = block_index[b, d] * block_cells
        s = ((x - block_lo[b, d]) / block_dx[b, d] + (first - ((first >> shift) << shift))) / (1 << shift) - 0.5
    i = int(math.floor(s))
    return i, s - i


@njit(cache=True)
def _stencil_base(x, y, z, b, lev, ndim, block_lo, block_dx, block_index, block_level, block_cells):
    """(i0, fx, j0, fy, k0, fz): :func:`_base` along the three axes for the point (x, y, z)."""
    i0, fx = _base(x, b, lev, 0, ndim, block_lo, block_dx, block_index, block_level, block_cells)
    j0, fy = _base(y, b, lev, 1, ndim, block_lo, block_dx, block_index, block_level, block_cells)
    k0, fz = _base(z, b, lev, 2, ndim, block_lo, block_dx, block_index, block_level, block_cells)
    return i0, fx, j0, fy, k0, fz


@njit(cache=True, inline="always")
def _global_cell(i, b, lev, d, block_index, block_level, block_cells):
    """Global index on the level-``lev`` cell grid of cell ``i`` counted as in :func:`_base`."""
    return ((block_index[b, d] * block_cells) >> (block_level[b] - lev)) + i


@njit(cache=True, inline="always")
def _corner(c, b, lev, i0, j0, k0, fx, fy, fz, ndim, codes, cells, block_index, block_level, block_cells,
            root, children):
    """Corner ``c`` (bit d set: upper cell along axis d) of the level-``lev`` stencil with lower
    cell (i0, j0, k0) (counted as in :func:`_base`) around a point in block ``b``.

    Returns (block, padded ix, iy, iz, n, multilinear weight, velocity signs sx, sy, sz): the
    corner cell is the n cells per used axis from (ix, iy, iz) of that leaf block (n = 1 on
    the leaf's own level, 2^(m - lev) on a finer leaf of level m), after the domain faces
    (:func:`_wrap`, on the level's ``cells << lev`` cells per axis).  Block -1 when the leaf
    is coarser than ``lev`` (the stencil must drop a level).
    """
    ix, iy, iz = i0, j0, k0
    w = 1.0
    if c & 1:
        ix += 1
        w *= fx
    else:
        w *= 1.0 - fx
    if ndim > 1:
        if c & 2:
            iy += 1
            w *= fy
        else:
            w *= 1.0 - fy
    if ndim > 2:
        if c & 4:
            iz += 1
            w *= fz
        else:
            w *= 1.0 - fz
    gy = GHOST if ndim > 1 else 0
    gz = GHOST if ndim > 2 else 0
    if lev == block_level[b] and 0 <= ix < block_cells and 0 <= iy < block_cells and 0 <= iz < block_cells:
        return b, ix + GHOST, iy + gy, iz + gz, 1, w, 1.0, 1.0, 1.0
    g0, sx = _wrap(_global_cell(ix, b, lev, 0, block_index, block_level, block_cells), cells[0] << lev,
                   codes[0, 0], codes[0, 1])
    g1, sy = 0, 1.0
    g2, sz = 0, 1.0
    if ndim > 1:
        g1, sy = _wrap(_global_cell(iy, b, lev, 1, block_index, block_level, block_cells), cells[1] << lev,
                       codes[1, 0], codes[1, 1])
    if ndim > 2:
        g2, sz = _wrap(_global_cell(iz, b, lev, 2, block_index, block_level, block_cells), cells[2] << lev,
                       codes[2, 0], codes[2, 1])
    blk, m = _leaf_of_cell(g0, g1, g2, lev, block_cells, root, children)
    if m < lev:
        return -1, 0, 0, 0, 0, w, sx, sy, sz
    shift = m - lev
    ix = (g0 << shift) - block_index[blk, 0] * block_cells + GHOST
    iy = (g1 << shift) - block_index[blk, 1] * block_cells + gy if ndim > 1 else 0
    iz = (g2 << shift) - block_index[blk, 2] * block_cells + gz if ndim > 2 else 0
    return blk, ix, iy, iz, 1 << shift, w, sx, sy, sz


@njit(cache=True, inline="always")
def _containing_cell(x, y, z, b, block_lo, block_dx, ncell, ndim):
    """Padded indices of the interior cell of block ``b`` containing (x, y, z)."""
    ix = min(max(int(math.floor((x - block_lo[b, 0]) / block_dx[b, 0])), 0), ncell[0] - 1) + GHOST
    iy = 0
    iz = 0
    if ndim > 1:
        iy = min(max(int(math.floor((y - block_lo[b, 1]) / block_dx[b, 1])), 0), ncell[1] - 1) + GHOST
    if ndim > 2:
        iz = min(max(int(math.floor((z - block_lo[b, 2]) / block_dx[b, 2])), 0), ncell[2] - 1) + GHOST
    return ix, iy, iz


# ---------------------------------------------------------------------------- kernels


@njit(cache=True, inline="always")
def _velocity_terms(arho, momentum, blk, k, ix, iy, iz, w, sx, sy, sz, ndim):
    """(W a u_x, W a u_y, W a u_z, W a) of cell (blk, ix, iy, iz) for material ``k``, u = m / rho
    with the velocity signs applied; zeros where a = arho_k <= 0."""
    a = arho[blk, k, ix, iy, iz]
    if a <= 0.0:
        return 0.0, 0.0, 0.0, 0.0
    rho = 0.0
    for j in range(arho.shape[1]):
        rho += arho[blk, j, ix, iy, iz]
    f = w * a / rho
    t0 = f * sx * momentum[blk, 0, ix, iy, iz]
    t1 = f * sy * momentum[blk, 1, ix, iy, iz] if ndim > 1 else 0.0
    t2 = f * sz * momentum[blk, 2, ix, iy, iz] if ndim > 2 else 0.0
    return t0, t1, t2, w * a


@njit(cache=True)
def _adaptive_velocity_sums(x, y, z, b, k, ndim, block_lo, block_dx, block_index, block_level, block_cells, codes,
                            cells, root, children, arho, momentum):
    """(sum W a u_x, sum W a u_y, sum W a u_z, sum W a) over the level-aware stencil of a point
    in block ``b``: the stencil of the block's level, dropped one level at a time while a corner
    of positive weight lies in a coarser leaf (a stencil of one level keeps multilinear
    interpolation exact for linear fields); a corner on a finer leaf adds its n^ndim cells,
    each with W / n^ndim (their mean stands for the coarser cell)."""
    lev = block_level[b]
    while True:
        i0, fx, j0, fy, k0, fz = _stencil_base(x, y, z, b, lev, ndim, block_lo, block_dx, block_index,
                                                block_level, block_cells)
        num0 = 0.0
        num1 = 0.0
        num2 = 0.0
        den = 0.0
        complete = True
        for c in range(1 << ndim):
            blk, ix, iy, iz, n, w, sx, sy, sz = _corner(c, b, lev, i0, j0, k0, fx, fy, fz, ndim, codes, cells,
                                                        block_index, block_level, block_cells, root, children)
            if w <= 0.0:
                continue
            if blk < 0:
                complete = False
                break
            share = w / n**ndim
            for p in range(n):
                for q in range(n if ndim > 1 else 1):
                    for r in range(n if ndim > 2 else 1):
                        t0, t1, t2, td = _velocity_terms(arho, momentum, blk, k, ix + p, iy + q, iz + r, share, sx,
                                                         sy, sz, ndim)
                        num0 += t0
                        num1 += t1
                        num2 += t2
                        den += td
        if complete:
            return num0, num1, num2, den
        lev -= 1


@njit(cache=True, parallel=True)
def sample_velocity(position, sign, material, skip, block, block_lo, block_dx, block_index, block_level,
                     block_cells, ncell, ndim, codes, cells, root, children, arho, momentum, out):
    """Partial-density-weighted multilinear velocity (m/s) at each point, into ``out[N, 3]``.

    v = sum_c W_c a_c (m_c / rho_c) / sum_c W_c a_c with a_c the partial density of the
    point's material, over the cell-centred stencil of the owning block's level.  When a
    corner of positive weight is not a single cell of that level (it lies in a finer or a
    coarser leaf) the sums come from :func:`_adaptive_velocity_sums`.  The containing cell's
    velocity when the denominator vanishes.  Momentum components beyond ``ndim`` are zero by
    the state's contract and not read.  Component d is multiplied by ``sign[t, d]`` (-1 for
    a point folded through a reflecting face).  Skipped points are left unchanged.
    """
    nmat = arho.shape[1]
    for t in prange(position.shape[0]):
        if skip[t]:
            continue
        b = block[t]
        k = material[t]
        x, y, z = position[t, 0], position[t, 1], position[t, 2]
        lev = block_level[b]
        i0, fx, j0, fy, k0, fz = _stencil_base(x, y, z, b, lev, ndim, block_lo, block_dx, block_index,
                                                block_level, block_cells)
        num0 = 0.0
        num1 = 0.0
        num2 = 0.0
        den = 0.0
        for c in range(1 << ndim):
            blk, ix, iy, iz, n, w, sx, sy, sz = _corner(c, b, lev, i0, j0, k0, fx, fy, fz, ndim, codes, cells,
                                                        block_index, block_level, block_cells, root, children)
            if w <= 0.0:
                continue
            if n != 1:
                num0, num1, num2, den = _adaptive_velocity_sums(x, y, z, b, k, ndim, block_lo, block_dx, block_index,
                                                                block_level, block_cells, codes, cells, root, children,
                                                                arho, momentum)
                break
            t0, t1, t2, td = _velocity_terms(arho, momentum, blk, k, ix, iy, iz, w, sx, sy, sz, ndim)
            num0 += t0
            num1 += t1
            num2 += t2
            den += td
        if den > 0.0:
            v0, v1, v2 = num0 / den, num1 / den, num2 / den
        else:
            ix, iy, iz = _containing_cell(x, y, z, b, block_lo, block_dx, ncell, ndim)
            rho = 0.0
            for j in range(nmat):
                rho += arho[b, j, ix, iy, iz]
            if rho > 0.0:
                v0 = momentum[b, 0, ix, iy, iz] / rho
                v1 = momentum[b, 1, ix, iy, iz] / rho if ndim > 1 else 0.0
                v2 = momentum[b, 2, ix, iy, iz] / rho if ndim > 2 else 0.0
            else:
                v0 = v1 = v2 = 0.0
        out[t, 0] = sign[t, 0] * v0
        out[t, 1] = sign[t, 1] * v1
        out[t, 2] = sign[t, 2] * v2


@njit(cache=True)
def _adaptive_best_cell(x, y, z, b, k, ndim, block_lo, block_dx, block_index, block_level, block_cells, codes, cells,
                        root, children, alpha, arho):
    """(block, padded ix, iy, iz) of the cell with the largest W alpha_k rho_k (alpha_k > ALPHA_MIN)
    over the level-aware stencil of :func:`_adaptive_velocity_sums` (block -1: none)."""
    lev = block_level[b]
    while True:
        i0, fx, j0, fy, k0, fz = _stencil_base(x, y, z, b, lev, ndim, block_lo, block_dx, block_index,
                                                block_level, block_cells)
        best = 0.0
        cb, cx, cy, cz = -1, 0, 0, 0
        complete = True
        for c in range(1 << ndim):
            blk, ix, iy, iz, n, w, _, _, _ = _corner(c, b, lev, i0, j0, k0, fx, fy, fz, ndim, codes, cells,
                                                     block_index, block_level, block_cells, root, children)
            if w <= 0.0:
                continue
            if blk < 0:
                complete = False
                break
            share = w / n**ndim
            for p in range(n):
                for q in range(n if ndim > 1 else 1):
                    for r in range(n if ndim > 2 else 1):
                        score = share * arho[blk, k, ix + p, iy + q, iz + r]
                        if alpha[blk, k, ix + p, iy + q, iz + r] > ALPHA_MIN and score > best:
                            best = score
                            cb, cx, cy, cz = blk, ix + p, iy + q, iz + r
        if complete:
            return cb, cx, cy, cz
        lev -= 1


@njit(cache=True, parallel=True)
def record_peaks(position, material, skip, block, unrecorded_only, time, block_lo, block_dx, block_index,
                  block_level, block_cells, ncell, ndim, codes, cells, root, children, alpha, arho, arhoe, eos_kind,
                  eos_params, eos_table, peak_pressure, peak_pressure_time, peak_temperature, arhoq=None,
                  porosity=None):
    """Update the running peak pressure (Pa, with its time in s) and peak temperature (K).

    The tracer's cell is the containing cell when it holds the tracer's material
    (alpha_k > ALPHA_MIN), else the stencil cell with the largest W_c alpha_k rho_k (the
    stencil of :func:`sample_velocity`; :func:`_adaptive_best_cell` where it spans levels);
    none (material absent from the stencil) means no record this time.  There
    rho_k = arho_k / alpha_k, e_k = arhoe_k / arho_k, p_k = P_k(rho_k, e_k), T_k = T_k(rho_k, e_k).
    With ``unrecorded_only`` only tracers without a record yet (NaN peak time) are sampled.
    A porous material (``porosity`` rows, :mod:`impactpipe.hydro.eos.porosity`; its distension
    alpha from the transported scalars ``arhoq``) has p_k = P_k(alpha rho_k, e_k) / alpha and
    T_k = T_k(alpha rho_k, e_k); without ``porosity`` ``arhoq`` is not read.
    """
    for t in prange(position.shape[0]):
        if skip[t] or (unrecorded_only and not math.isnan(peak_pressure_time[t])):
            continue
        b = block[t]
        k = material[t]
        x, y, z = position[t, 0], position[t, 1], position[t, 2]
        cb = b
        cx, cy, cz = _containing_cell(x, y, z, b, block_lo, block_dx, ncell, ndim)
        if not (alpha[cb, k, cx, cy, cz] > ALPHA_MIN and arho[cb, k, cx, cy, cz] > 0.0):
            lev = block_level[b]
            i0, fx, j0, fy, k0, fz = _stencil_base(x, y, z, b, lev, ndim, block_lo, block_dx, block_index,
                                                    block_level, block_cells)
            best = 0.0
            cb = -1
            for c in range(1 << ndim):
                blk, ix, iy, iz, n, w, _, _, _ = _corner(c, b, lev, i0, j0, k0, fx, fy, fz, ndim, codes, cells,
                                                         block_index, block_level, block_cells, root, children)
                if w <= 0.0:
                    continue
                if n != 1:
                    cb, cx, cy, cz = _adaptive_best_cell(x, y, z, b, k, ndim, block_lo, block_dx, block_index,
                                                         block_level, block_cells, codes, cells, root, children,
                                                         alpha, arho)
                    break
                score = w * arho[blk, k, ix, iy, iz]
                if alpha[blk, k, ix, iy, iz] > ALPHA_MIN and score > best:
                    best = score
                    cb, cx, cy, cz = blk, ix, iy, iz
            if cb < 0:
                continue
        a = alpha[cb, k, cx, cy, cz]
        ar = arho[cb, k, cx, cy, cz]
        rho = ar / a
        e = arhoe[cb, k, cx, cy, cz] / ar
        dist = 1.0
        if porosity is not None:
            if porosity[k, ALPHA0] > 1.0:
                dist = arhoq[cb, (arhoq.shape[1] // alpha.shape[1]) * (k + 1) - 2, cx, cy, cz] / ar
        p, c2, flag = pressure_sound_speed(eos_kind[k], eos_params[k], eos_table, dist * rho, e)
        p /= dist
        temp = temperature(eos_kind[k], eos_params[k], eos_table, dist * rho, e)
        if math.isfinite(p) and not p <= peak_pressure[t]:
            peak_pressure[t] = p
            peak_pressure_time[t] = time
        if math.isfinite(temp) and not temp <= peak_temperature[t]:
            peak_temperature[t] = temp
