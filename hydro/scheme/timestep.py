"""The CFL time step and the cell thermodynamics of the mixture for the snapshots.

Time step (split scheme, every sweep must satisfy its own Courant condition):

    dt = cfl / max_cells max_d (|u_d| + c) / dx_d

with the cell signal speed c = sqrt(K / rho) of the equal-strain mixture, K = sum_k alpha_k
rho_k c_k^2 over the materials present and per material the longitudinal speed

    c_k^2 = c_K,k^2 + 4 G_k / (3 rho_k)        (:func:`impactpipe.hydro.scheme.mixture.signal_speed_squared`)

the bulk sound speed from the EOS plus the shear modulus term of material strength (G_k = 0
for a strengthless material; ``shear_modulus`` arguments are the (M, 2) shear table of
:mod:`impactpipe.hydro.strength.parameters`: G_k = shear[k, 0] + shear[k, 1] rho_k c_K,k^2).
The cell thermodynamics gather the cell's mixture with :func:`impactpipe.hydro.scheme.mixture.mixture_state`;
the time step sums the same terms material by material (:func:`max_signal_rate`).
"""

from __future__ import annotations

import numpy as np
from numba import get_thread_id, njit, prange

from impactpipe.hydro.eos import IDEAL_GAS, pressure_sound_speed_in_line, reference_density
from impactpipe.hydro.eos.ideal_gas import ideal_gas_pressure_sound_speed
from impactpipe.hydro.eos.porosity import ALPHA0
from impactpipe.hydro.mesh.blocks import ghost_widths
from impactpipe.hydro.scheme.mixture import ALPHA_MIN, mixture_state, signal_speed_squared

#: Material volume fraction below which a cell counts as void (no signal, no Riemann state).
PHI_VOID = 1.0e-6


# allocates nothing: compiled without reference counting (docs/performance.md, "Compile time")
@njit(cache=True, parallel=True, _nrt=False)
def max_signal_rate(alpha, arho, arhoe, mom, block_dx, eos_kind, eos_params, eos_table, shear_modulus, ndim, work,
                    out, arhoq=None, porosity=None, void=None):
    """Per block, the largest max_d (|u_d| + c) / dx_d (1/s) over non-void interior cells, into ``out[NB]``.

    c = sqrt(K / rho) with the sums of :func:`impactpipe.hydro.scheme.mixture.mixture_state`,

        rho = sum_k alpha_k rho_k,  phi = sum_k alpha_k,  K = sum_k alpha_k rho_k c_k^2

    (c_k^2 the material's signal speed squared, :func:`impactpipe.hydro.scheme.mixture.
    signal_speed_squared`, over the present materials: alpha_k > ALPHA_MIN and alpha_k rho_k > 0),
    accumulated in the same order, so the rate is the one of the per-cell gather bit for bit
    (tests/test_hydro_timestep.py).  The sums run material by material over a block's cells
    into the per-thread ``work[thread, 0:3]`` (rho, phi, K; shape (threads, 3, nx, ny, nz)), so
    the EOS model is chosen once per material and block rather than once per cell; ideal gas
    and Tillotson are called in place (:func:`impactpipe.hydro.eos.pressure_sound_speed_in_line`).  Cells with rho <= 0 or phi < PHI_VOID carry no
    signal.  ``mom`` is the momentum density (kg/m^2/s), ``block_dx`` the cell sizes (m).
    A 2D mesh's arrays (nz = 1) are read as (NB, M, 1, nx, ny), so that the innermost loop runs
    along the block's rows (the same cells and sums).
    With ``porosity`` (the (M, NPOROSITY) rows of :func:`impactpipe.hydro.eos.porosity.pack_porosity`)
    a porous material's sound speed is its solid's at the matrix density, alpha rho_k, the
    distension alpha from the transported scalars ``arhoq`` (as in the gather); None, and
    ``arhoq`` is not read.  ``void`` (uint8, (NB,), or None): the blocks known to be void
    (:func:`impactpipe.hydro.mesh.last_good.void_blocks`), whose rate is 0 (none of their cells
    has rho > 0) without a look at their cells.  A mesh of one material takes one pass per
    block with cubic cells (:func:`_single_material_rate`, the same rate bit for bit).  With
    cubic cells a cell counts its largest |m_d|: where a momentum component is NaN (a state the
    sweeps report as failed) the cell may count none of its components, where the per-axis
    rates would count the others.
    """
    nb, nmat, nx, ny, nz = alpha.shape
    nq = 0
    if arhoq is not None:
        nq = arhoq.shape[1] // nmat
    if nz == 1:
        alpha = alpha.reshape((nb, nmat, 1, nx, ny))
        arho = arho.reshape((nb, nmat, 1, nx, ny))
        arhoe = arhoe.reshape((nb, nmat, 1, nx, ny))
        mom = mom.reshape((nb, mom.shape[1], 1, nx, ny))
        work = work.reshape((work.shape[0], 3, 1, nx, ny))
        if arhoq is not None:
            arhoq = arhoq.reshape((nb, arhoq.shape[1], 1, nx, ny))
        nx, ny, nz = 1, nx, ny
    gx, gy, gz = ghost_widths(nx, ny, nz)
    for b in prange(nb):
        if void is not None:
            if void[b] != 0:
                out[b] = 0.0
                continue
        w = work[get_thread_id()]
        cubic = True
        for d in range(1, ndim):
            if block_dx[b, d] != block_dx[b, 0]:
                cubic = False
        if nmat == 1 and cubic:
            out[b] = _single_material_rate(alpha, arho, arhoe, arhoq, mom, b, eos_kind[0], eos_params[0], eos_table,
                                           shear_modulus[0], porosity, nq, ndim, (gx, gy, gz), (nx, ny, nz),
                                           block_dx[b, 0])
            continue
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    w[0, ix, iy, iz] = 0.0
                    w[1, ix, iy, iz] = 0.0
                    w[2, ix, iy, iz] = 0.0
        for k in range(nmat):
            kind = eos_kind[k]
            row = eos_params[k]
            shear = shear_modulus[k]
            sheared = shear[0] != 0.0 or shear[1] != 0.0
            rho0 = reference_density(kind, row, eos_table)
            for ix in range(gx, nx - gx):
                for iy in range(gy, ny - gy):
                    for iz in range(gz, nz - gz):
                        a = alpha[b, k, ix, iy, iz]
                        ar = arho[b, k, ix, iy, iz]
                        w[0, ix, iy, iz] += ar
                        w[1, ix, iy, iz] += a
                        if not (a > ALPHA_MIN and ar > 0.0):
                            continue
                        rk = ar / a
                        ek = arhoe[b, k, ix, iy, iz] / ar
                        if porosity is not None:
                            if porosity[k, ALPHA0] > 1.0:
                                dist = arhoq[b, nq * k + nq - 2, ix, iy, iz] / ar
                                pk, c2, flag = pressure_sound_speed_in_line(kind, row, eos_table, dist * rk, ek)
                                w[2, ix, iy, iz] += ar * (signal_speed_squared(c2, rk, shear, rho0 / dist)
                                                          if sheared else c2)
                                continue
                        pk, c2, flag = pressure_sound_speed_in_line(kind, row, eos_table, rk, ek)
                        w[2, ix, iy, iz] += ar * (signal_speed_squared(c2, rk, shear, rho0) if sheared else c2)
        # the largest |u_d| + c over the cells, divided by dx_d once per block: x -> x / dx_d
        # (dx_d > 0) and x -> x / rho + c are monotone in IEEE arithmetic, so the largest
        # quotient is the quotient of the largest, bit for bit; with cubic cells the largest
        # |m_d| of a cell is the one that counts (3 of a cell's 5 divisions in 2D, 5 of 7 in 3D)
        if cubic:
            # the cells' largest |u_d| + c on the bits of their int64 views (_single_material_rate)
            largest = np.int64(0)
            for ix in range(gx, nx - gx):
                for iy in range(gy, ny - gy):
                    for iz in range(gz, nz - gz):
                        rho = w[0, ix, iy, iz]
                        x = _largest_speed(mom, b, ix, iy, iz, ndim) / rho + np.sqrt(w[2, ix, iy, iz] / rho)
                        if rho <= 0.0 or w[1, ix, iy, iz] < PHI_VOID or x != x:
                            x = 0.0
                        bits = np.float64(x).view(np.int64)
                        if bits > largest:
                            largest = bits
            out[b] = np.int64(largest).view(np.float64) / block_dx[b, 0]
            continue
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    rho = w[0, ix, iy, iz]
                    if rho <= 0.0 or w[1, ix, iy, iz] < PHI_VOID:
                        continue
                    c = np.sqrt(w[2, ix, iy, iz] / rho)
                    x = abs(mom[b, 0, ix, iy, iz]) / rho + c
                    if x > s0:
                        s0 = x
                    if ndim > 1:
                        x = abs(mom[b, 1, ix, iy, iz]) / rho + c
                        if x > s1:
                            s1 = x
                    if ndim > 2:
                        x = abs(mom[b, 2, ix, iy, iz]) / rho + c
                        if x > s2:
                            s2 = x
        rate = s0 / block_dx[b, 0]
        if ndim > 1 and s1 / block_dx[b, 1] > rate:
            rate = s1 / block_dx[b, 1]
        if ndim > 2 and s2 / block_dx[b, 2] > rate:
            rate = s2 / block_dx[b, 2]
        out[b] = rate


@njit(cache=True, inline="always")
def _single_material_rate(alpha, arho, arhoe, arhoq, mom, b, kind, row, eos_table, shear, porosity, nq, ndim, lo, n,
                          dx):
    """:func:`max_signal_rate` of block b of a mesh with one material and cubic cells of size
    ``dx`` (m), bit for bit, in one pass: rho = alpha rho and phi = alpha (the sums over one
    material), and per cell x = max_d |m_d| / rho + c, or 0 where the cell is skipped (rho <= 0,
    phi < PHI_VOID) or x is NaN (which the comparison of :func:`max_signal_rate` passes over);
    the largest x is found by the bits of its int64 view (x >= +0.0, where the order of the
    bits is the order of the numbers: a reduction that vectorises, where one over floats does
    not without the compiler's fast-math), then divided by dx.  An ideal gas
    without shear modulus or pores evaluates its sound speed in every cell and keeps it where
    the material is present (arithmetic without branches: the loop vectorises); other
    materials evaluate their EOS where present only.  ``lo``, ``n``: the first interior index
    and the padded length per axis, as :func:`max_signal_rate` reads the block.
    """
    gx, gy, gz = lo
    nx, ny, nz = n
    sheared = shear[0] != 0.0 or shear[1] != 0.0
    rho0 = reference_density(kind, row, eos_table)
    porous = False
    if porosity is not None:
        porous = porosity[0, ALPHA0] > 1.0
    largest = np.int64(0)
    if kind == IDEAL_GAS and not sheared and not porous:
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    a = alpha[b, 0, ix, iy, iz]
                    ar = arho[b, 0, ix, iy, iz]
                    pk, c2 = ideal_gas_pressure_sound_speed(row, ar / a, arhoe[b, 0, ix, iy, iz] / ar)
                    w2 = 0.0
                    w2 += ar * c2
                    if not (a > ALPHA_MIN and ar > 0.0):
                        w2 = 0.0
                    x = _largest_speed(mom, b, ix, iy, iz, ndim) / ar + np.sqrt(w2 / ar)
                    if ar <= 0.0 or a < PHI_VOID or x != x:
                        x = 0.0
                    bits = np.float64(x).view(np.int64)
                    if bits > largest:
                        largest = bits
    else:
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    a = alpha[b, 0, ix, iy, iz]
                    ar = arho[b, 0, ix, iy, iz]
                    x = 0.0
                    if not (ar <= 0.0 or a < PHI_VOID):
                        w2 = 0.0
                        if a > ALPHA_MIN:
                            rk = ar / a
                            ek = arhoe[b, 0, ix, iy, iz] / ar
                            if porous:
                                dist = 1.0
                                if porosity is not None:  # always, where porous: the branch types arhoq
                                    dist = arhoq[b, nq - 2, ix, iy, iz] / ar
                                pk, c2, flag = pressure_sound_speed_in_line(kind, row, eos_table, dist * rk, ek)
                                w2 += ar * (signal_speed_squared(c2, rk, shear, rho0 / dist) if sheared else c2)
                            else:
                                pk, c2, flag = pressure_sound_speed_in_line(kind, row, eos_table, rk, ek)
                                w2 += ar * (signal_speed_squared(c2, rk, shear, rho0) if sheared else c2)
                        x = _largest_speed(mom, b, ix, iy, iz, ndim) / ar + np.sqrt(w2 / ar)
                        if x != x:
                            x = 0.0
                    bits = np.float64(x).view(np.int64)
                    if bits > largest:
                        largest = bits
    return np.int64(largest).view(np.float64) / dx


@njit(cache=True, inline="always")
def _largest_speed(mom, b, ix, iy, iz, ndim):
    """max_d |m_d| (kg/m^2/s) of a cell over the mesh's ``ndim`` axes, without a loop over them
    (a loop inside the loop over the cells keeps the compiler from vectorising that one)."""
    m = abs(mom[b, 0, ix, iy, iz])
    m1 = abs(mom[b, 1, ix, iy, iz]) if ndim > 1 else 0.0
    m2 = abs(mom[b, 2, ix, iy, iz]) if ndim > 2 else 0.0
    if m1 > m:
        m = m1
    if m2 > m:
        m = m2
    return m


def allocate_rate_work(threads: int, padded_shape) -> np.ndarray:
    """Per-thread work array of :func:`max_signal_rate`: (threads, 3, nx, ny, nz) float64."""
    return np.zeros((threads, 3) + tuple(padded_shape))


@njit(cache=True, parallel=True)
def cell_thermodynamics(alpha, arho, arhoe, arhoq, eos_kind, eos_params, eos_table, shear_modulus, tensile_strength,
                        pressure, sound_speed, specific_energy, temp, grady_kipp=None, porosity=None):
    """Interior-cell mixture thermodynamics into ``(NB, nx, ny, nz)`` outputs.

    From :func:`impactpipe.hydro.scheme.mixture.mixture_state`: pressure = sum_k alpha_k max(p_k,
    -Y_T,k (1 - D_k)) (Pa), the material pressures limited by the tensile strengths left by
    the damage D_k as in the sweeps (Grady-Kipp materials, ``grady_kipp``: (1 - D_k) of their
    tension); sound_speed = sqrt(sum_k alpha_k rho_k c_k^2 / rho) (m/s),
    the equal-strain mixture's; specific_energy = sum_k alpha_k rho_k e_k / rho (J/kg);
    temp = sum_k alpha_k rho_k T_k / rho (K), porous materials (``porosity``) at their distension.  Void
    cells get zeros.
    """
    nb, nmat, nx, ny, nz = alpha.shape
    gx, gy, gz = ghost_widths(nx, ny, nz)
    for b in prange(nb):
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    rho, phi, p, kmod, eint, tmass, clamps, limits = mixture_state(
                        alpha, arho, arhoe, arhoq, b, ix, iy, iz, eos_kind, eos_params, eos_table, shear_modulus,
                        tensile_strength, True, None, 0, 0, grady_kipp, porosity)
                    jx = ix - gx
                    jy = iy - gy
                    jz = iz - gz
                    pressure[b, jx, jy, jz] = p
                    sound_speed[b, jx, jy, jz] = np.sqrt(kmod / rho) if rho > 0.0 else 0.0
                    specific_energy[b, jx, jy, jz] = eint / rho if rho > 0.0 else 0.0
                    temp[b, jx, jy, jz] = tmass / rho if rho > 0.0 else 0.0
