"""Stress divergence of the deviatoric stress as conservative face fluxes.

With sigma = -P I + S, the hydro sweeps carry -P I; this kernel adds S:

    d(rho v_i)/dt = d S_ij / d x_j        d E / dt = d (S_ij v_i) / d x_j

in flux form over each cell's faces (A face area, V cell volume, n = +-1 on the high/low face):

    (rho v_i) += dt / V sum_faces n A S_id,face        E += dt / V sum_faces n A S_id,face v_i,face

with v_face the mean of the two cells' velocities and

    S_face = min(phi_L, phi_R) (S_L / phi_L + S_R / phi_R) / 2

where S = sum_k alpha_k S_k is a cell's mixture stress and phi its material fill,
min(sum_k alpha_k, sum_k alpha_k rho_k / rho0_k) (``work`` from :mod:`impactpipe.hydro.strength.update`, ghosts filled): the mean stress
of the material on both sides acting over the part of the face that material covers on
both sides.  S_face = 0 where either side is void (traction-free surface); a partly filled
surface cell (small phi) gets a traction in proportion to its mass, so its acceleration
stays that of a full cell (without the factor, a cell filled 1e-5 next to a full one was
driven to 16 km/s in a 3 km/s impact).  Both blocks of a face compute the same face value, so
momentum and energy are conserved to round-off.  In 2d-cylindrical (r, z, theta) the r
faces have A = 2 pi r dz and the radial momentum gets the hoop term
-S_thth (A_{i+1/2} - A_{i-1/2}) / V (the discrete -S_thth / r, the same area difference as
the radial pressure source of the sweeps).  What crosses domain faces (wall impulse
included) is added to the boundary counters like the sweeps' fluxes.  Through a block face
whose neighbour is at another refinement level the amounts -dt A S_id (momentum) and
-dt A S_id v_i (energy) are stored in ``face_flux[d]`` (the sweeps' column layout, momentum
from column ``col0``) so that the coarse side can be refluxed
(:func:`impactpipe.hydro.amr.transfer.reflux`).  On 1-D and 2-D meshes the stress has no
S_zd components (their work slots stay zero), so the kernel neither reads them nor the
third velocity, and leaves the third momentum alone: the same sums without the terms
that are zero.
"""

from __future__ import annotations

from numba import njit, prange

from impactpipe.hydro.mesh.blocks import CYLINDRICAL, GHOST, ghost_widths
from impactpipe.hydro.strength.update import WK_PHI, WK_S, WK_V
from impactpipe.hydro.scheme.pencil_layout import BND_ENERGY, BND_MOMENTUM


@njit(cache=True, inline="always")
def stress_slot(i, j):
    """Slot of S_ij in (xx, yy, zz, xy, xz, yz)."""
    if i == j:
        return i
    if i + j == 1:
        return 3
    if i + j == 2:
        return 4
    return 5


@njit(cache=True, inline="always")
def _face_geometry(cylindrical, d, r0, i, dx0, dx1, dx2, h):
    """(A_lo / V, A_hi / V (1/m), A_lo, A_hi (m^2)) of the low and high faces along axis ``d``
    of a cell in row ``i`` (interior index along axis 0) of a block whose axis-0 edge is at
    ``r0`` (m), cell sizes ``dx0 .. dx2`` (m), ``h`` the size along ``d``."""
    pi = 3.141592653589793
    if cylindrical and d == 0:
        r_lo = r0 + i * dx0
        r_hi = r_lo + dx0
        return (2.0 * r_lo / (r_hi * r_hi - r_lo * r_lo), 2.0 * r_hi / (r_hi * r_hi - r_lo * r_lo),
                2.0 * pi * r_lo * dx1, 2.0 * pi * r_hi * dx1)
    if cylindrical:
        r_lo = r0 + i * dx0
        r_hi = r_lo + dx0
        ring = pi * (r_hi * r_hi - r_lo * r_lo)
        return 1.0 / dx1, 1.0 / dx1, ring, ring
    area = dx0 * dx1 * dx2 / h
    return 1.0 / h, 1.0 / h, area, area


@njit(cache=True, inline="always")
def _face_stress(ndim, work, b, ix, iy, iz, d, side, phi_c):
    """The stress on the face on ``side`` (0 low, 1 high) along axis ``d`` of the cell
    (ix, iy, iz) of block b, fill ``phi_c`` > 0: (1.0 where the neighbour holds material, else
    0.0 and no stress, the traction S_face components t0, t1, t2 (Pa) along the face normal,
    t.v_face (W/m^2)).  The same numbers from either cell of the face (the sums are symmetric),
    so momentum and energy are conserved to round-off.  Called with constant ``d`` and ``side``,
    so the slots and indices are fixed at compile time."""
    jx, jy, jz = ix, iy, iz
    step = 1 if side == 1 else -1
    if d == 0:
        jx += step
    elif d == 1:
        jy += step
    else:
        jz += step
    phi_n = work[b, WK_PHI, jx, jy, jz]
    if phi_n <= 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0
    # 0.5 min(phi_c, phi_n) / phi: exactly 0.5 on the emptier side (no division)
    shared = min(phi_c, phi_n)
    wc = 0.5 if shared == phi_c else 0.5 * shared / phi_c
    wn = 0.5 if shared == phi_n else 0.5 * shared / phi_n
    t0 = (wc * work[b, WK_S + stress_slot(0, d), ix, iy, iz]
          + wn * work[b, WK_S + stress_slot(0, d), jx, jy, jz])
    t1 = (wc * work[b, WK_S + stress_slot(1, d), ix, iy, iz]
          + wn * work[b, WK_S + stress_slot(1, d), jx, jy, jz])
    v0 = 0.5 * (work[b, WK_V, ix, iy, iz] + work[b, WK_V, jx, jy, jz])
    v1 = 0.5 * (work[b, WK_V + 1, ix, iy, iz] + work[b, WK_V + 1, jx, jy, jz])
    t2 = 0.0
    v2 = 0.0
    if ndim > 2:
        t2 = (wc * work[b, WK_S + stress_slot(2, d), ix, iy, iz]
              + wn * work[b, WK_S + stress_slot(2, d), jx, jy, jz])
        v2 = 0.5 * (work[b, WK_V + 2, ix, iy, iz] + work[b, WK_V + 2, jx, jy, jz])
    return 1.0, t0, t1, t2, t0 * v0 + t1 * v1 + t2 * v2


@njit(cache=True, inline="always")
def _add_face(dt, b, ix, iy, iz, d, side, face, geo, edge, neighbor, neighbor_level, boundary, face_flux, col0,
              d_mom0, d_mom1, d_mom2, d_e):
    """Add the flux of the ``face`` values (:func:`_face_stress`) through the face on ``side``
    along axis ``d`` of the cell (ix, iy, iz) of block b to its momentum and energy changes
    (d_mom0, d_mom1, d_mom2, d_e), which it returns; ``geo`` the faces' geometry along ``d``
    (:func:`_face_geometry`), ``edge`` whether the face is a block face.  What crosses a domain
    face goes to ``boundary``, what crosses a block face to another refinement level to
    ``face_flux`` (module docstring)."""
    carries, t0, t1, t2, power = face
    if carries == 0.0:
        return d_mom0, d_mom1, d_mom2, d_e
    inv_lo, inv_hi, area_lo, area_hi = geo
    w = dt * (inv_hi if side == 1 else -inv_lo)
    d_mom0 += w * t0
    d_mom1 += w * t1
    d_mom2 += w * t2
    d_e += w * power
    # domain faces: what leaves (flux -S n A dt) is counted
    if edge and neighbor[b, d, side] < 0:
        wa = -dt * (area_hi if side == 1 else -area_lo)
        boundary[b, BND_MOMENTUM] += wa * t0
        boundary[b, BND_MOMENTUM + 1] += wa * t1
        boundary[b, BND_MOMENTUM + 2] += wa * t2
        boundary[b, BND_ENERGY] += wa * power
    elif edge and neighbor_level[b, d, side] != 0:
        amount = -dt * (area_hi if side == 1 else area_lo)
        j1 = iy if d == 0 else ix
        j2 = iy if d == 2 else iz
        face_flux[d, b, side, col0, j1, j2] = amount * t0
        face_flux[d, b, side, col0 + 1, j1, j2] = amount * t1
        face_flux[d, b, side, col0 + 2, j1, j2] = amount * t2
        face_flux[d, b, side, col0 + 3, j1, j2] = amount * power
    return d_mom0, d_mom1, d_mom2, d_e


@njit(cache=True, inline="always")
def _ghosts_carry_stress(work, b, ns, nx, ny, nz):
    """Whether a stress slot of ``work`` (the first ``ns``) is not 0 in a cell of the first
    ghost layer of block b beside its interior faces (the ghosts the face stresses of
    :func:`_face_stress` read; a ghost left unfilled holds a stale value, which at worst makes
    the block be kicked)."""
    gx, gy, gz = ghost_widths(nx, ny, nz)
    for c in range(WK_S, WK_S + ns):
        if nx > 1:
            for ix in (gx - 1, nx - gx):
                for iy in range(gy, ny - gy):
                    for iz in range(gz, nz - gz):
                        if work[b, c, ix, iy, iz] != 0.0:
                            return True
        if ny > 1:
            for ix in range(gx, nx - gx):
                for iy in (gy - 1, ny - gy):
                    for iz in range(gz, nz - gz):
                        if work[b, c, ix, iy, iz] != 0.0:
                            return True
        if nz > 1:
            for ix in range(gx, nx - gx):
                for iy in range(gy, ny - gy):
                    for iz in (gz - 1, nz - gz):
                        if work[b, c, ix, iy, iz] != 0.0:
                            return True
    return False


@njit(cache=True)
def quiet_blocks(stressed_blocks, holds, neighbor, neighbor_level, ndim, lo, hi, quiet, stress_ghosts):
    """For the blocks b of ``lo .. hi - 1`` (a process's range), ``quiet[b]`` = 1 where no cell
    whose stress the kick of block b reads carries one, else 0: block b carries none
    (``stressed_blocks[b] == 0``, :func:`impactpipe.hydro.strength.update.cell_velocity_and_stress`
    or :func:`impactpipe.hydro.strength.update.update_stress`), and along each of the ``ndim``
    axes each side's first ghost layer is copied from a block that carries none: b itself at a
    domain face (``neighbor`` < 0: a copy or a mirror of its own cells), or a same-level
    neighbour in ``lo .. hi - 1`` with ``stressed_blocks`` 0.  A neighbour at another refinement
    level or of another process counts as stressed.  ``stress_ghosts[b]``: ``holds[b]`` where b
    is not quiet, else 0, the blocks whose stress ghosts :func:`apply_stress_divergence` reads
    (it skips a quiet block before reading any)."""
    for b in range(lo, hi):
        calm = stressed_blocks[b] == 0
        for d in range(ndim):
            for side in range(2):
                nbr = neighbor[b, d, side]
                if nbr >= 0 and not (neighbor_level[b, d, side] == 0 and lo <= nbr < hi
                                     and stressed_blocks[nbr] == 0):
                    calm = False
        quiet[b] = 1 if calm else 0
        stress_ghosts[b] = 0 if calm else holds[b]


@njit(cache=True, _nrt=False)
def zero_face_flux_columns(face_flux, neighbor_level, ndim, blocks, col0, ncols):
    """Zero the columns ``col0 .. col0 + ncols - 1`` of the coarse/fine face amounts
    ``face_flux`` (axis, NB, side, column, N1, N2) on the faces of the ``blocks`` listed (int64)
    that border another refinement level (``neighbor_level[b, axis, side]`` not 0): where
    :func:`apply_stress_divergence` writes them (only for the cells that carry stress), and
    all that the flux registers read, cleared before a level's kick."""
    n1 = face_flux.shape[4]
    n2 = face_flux.shape[5]
    for a in range(ndim):
        for i in range(blocks.shape[0]):
            b = blocks[i]
            for side in range(2):
                if neighbor_level[b, a, side] == 0:
                    continue
                for c in range(col0, col0 + ncols):
                    for j in range(n1):
                        for k in range(n2):
                            face_flux[a, b, side, c, j, k] = 0.0


# allocates nothing: compiled without reference counting (docs/performance.md, "Compile time")
@njit(cache=True, parallel=True, _nrt=False)
def apply_stress_divergence(dt, geometry, ndim, mom, energy, block_lo, block_dx, neighbor, neighbor_level, work,
                            boundary, face_flux, col0, blocks, stressed_blocks, quiet=None):
    """Add the deviatoric stress fluxes over dt (s) to the momentum and total energy of the
    ``blocks`` listed (int64: a process's range, or one refinement level's); see the module
    docstring.  A cell sums its faces low then high along axis 0, then along 1 and 2, one call
    of :func:`_face_stress` and :func:`_add_face` per face with the axis and side as constants.

    ``stressed_blocks[NB]`` (uint8, from :func:`impactpipe.hydro.strength.update.cell_velocity_and_stress`
    or :func:`impactpipe.hydro.strength.update.update_stress`): a block whose interior
    cells carry no stress (``stressed_blocks[b] == 0``) and whose first ghost layer carries none
    either (:func:`_ghosts_carry_stress`) is skipped.  Every face stress of its cells is then
    +-0, so the kick would add dt A S = +0.0 to their momentum and energy: skipping it leaves
    them as they are, bit for bit (but for a momentum of -0.0, which the addition would
    turn into +0.0).  ``quiet[NB]`` (uint8, :func:`quiet_blocks`), when given: a block with
    ``quiet[b]`` 1 is skipped without reading its ghosts, which need not be filled then.  The
    flags say that its cells and the cells its first ghost layer copies carry no stress, so
    the ghost test would skip it too."""
    nb, nw, nx, ny, nz = work.shape
    gx, gy, gz = ghost_widths(nx, ny, nz)
    ns = 3 if ndim == 1 else (4 if ndim == 2 else 6)
    cylindrical = geometry == CYLINDRICAL
    for i in prange(blocks.shape[0]):
        b = blocks[i]
        if quiet is not None and quiet[b] != 0:
            continue
        if stressed_blocks[b] == 0 and not _ghosts_carry_stress(work, b, ns, nx, ny, nz):
            continue
        dx0 = block_dx[b, 0]
        dx1 = block_dx[b, 1] if ndim > 1 else 1.0
        dx2 = block_dx[b, 2] if ndim > 2 else 1.0
        for ix in range(gx, nx - gx):
            # the faces' geometry depends on ix alone: once per row of cells
            geo0 = _face_geometry(cylindrical, 0, block_lo[b, 0], ix - gx, dx0, dx1, dx2, block_dx[b, 0])
            geo1 = geo0
            geo2 = geo0
            if ndim > 1:
                geo1 = _face_geometry(cylindrical, 1, block_lo[b, 0], ix - gx, dx0, dx1, dx2, block_dx[b, 1])
            if ndim > 2:
                geo2 = _face_geometry(cylindrical, 2, block_lo[b, 0], ix - gx, dx0, dx1, dx2, block_dx[b, 2])
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    phi_c = work[b, WK_PHI, ix, iy, iz]
                    if phi_c <= 0.0:
                        continue
                    dm0 = 0.0
                    dm1 = 0.0
                    dm2 = 0.0
                    de = 0.0
                    dm0, dm1, dm2, de = _add_face(dt, b, ix, iy, iz, 0, 0,
                                                  _face_stress(ndim, work, b, ix, iy, iz, 0, 0, phi_c), geo0,
                                                  ix == GHOST, neighbor, neighbor_level, boundary, face_flux, col0,
                                                  dm0, dm1, dm2, de)
                    dm0, dm1, dm2, de = _add_face(dt, b, ix, iy, iz, 0, 1,
                                                  _face_stress(ndim, work, b, ix, iy, iz, 0, 1, phi_c), geo0,
                                                  ix == nx - GHOST - 1, neighbor, neighbor_level, boundary,
                                                  face_flux, col0, dm0, dm1, dm2, de)
                    if ndim > 1:
                        dm0, dm1, dm2, de = _add_face(dt, b, ix, iy, iz, 1, 0,
                                                      _face_stress(ndim, work, b, ix, iy, iz, 1, 0, phi_c), geo1,
                                                      iy == GHOST, neighbor, neighbor_level, boundary, face_flux,
                                                      col0, dm0, dm1, dm2, de)
                        dm0, dm1, dm2, de = _add_face(dt, b, ix, iy, iz, 1, 1,
                                                      _face_stress(ndim, work, b, ix, iy, iz, 1, 1, phi_c), geo1,
                                                      iy == ny - GHOST - 1, neighbor, neighbor_level, boundary,
                                                      face_flux, col0, dm0, dm1, dm2, de)
                    if ndim > 2:
                        dm0, dm1, dm2, de = _add_face(dt, b, ix, iy, iz, 2, 0,
                                                      _face_stress(ndim, work, b, ix, iy, iz, 2, 0, phi_c), geo2,
                                                      iz == GHOST, neighbor, neighbor_level, boundary, face_flux,
                                                      col0, dm0, dm1, dm2, de)
                        dm0, dm1, dm2, de = _add_face(dt, b, ix, iy, iz, 2, 1,
                                                      _face_stress(ndim, work, b, ix, iy, iz, 2, 1, phi_c), geo2,
                                                      iz == nz - GHOST - 1, neighbor, neighbor_level, boundary,
                                                      face_flux, col0, dm0, dm1, dm2, de)
                    if cylindrical:
                        r_lo = block_lo[b, 0] + (ix - gx) * dx0
                        r_hi = r_lo + dx0
                        dm0 -= dt * work[b, WK_S + 2, ix, iy, iz] * 2.0 * (r_hi - r_lo) / (r_hi * r_hi - r_lo * r_lo)
                    mom[b, 0, ix, iy, iz] += dm0
                    mom[b, 1, ix, iy, iz] += dm1
                    if ndim > 2:
                        mom[b, 2, ix, iy, iz] += dm2
                    energy[b, 0, ix, iy, iz] += de
