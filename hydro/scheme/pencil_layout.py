"""What the sweep kernel shares with its plain-pencil path: thresholds, counter slots, scratch rows.

The thresholds are the sweep's rules for mixed, partly void and nearly empty cells
(:mod:`impactpipe.hydro.scheme.directional`, module docstring); the counter slots index the per-block
arrays ``floors`` (counts), ``amounts`` (kg, J, kg m/s), ``boundary`` and ``failure`` that
the solver reports; the scratch rows are the per-thread working layout of one pencil.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from impactpipe.hydro.mesh.blocks import GHOST
from impactpipe.hydro.scheme.mixture import MATERIAL_ROWS

#: A face pressure below -TENSION_TOLERANCE * K (K the cell's bulk modulus) from a cell at
#: positive pressure is non-physical: the cell falls back to first order.
TENSION_TOLERANCE = 1.0e-3
#: The reconstruction of a cell's materials (alpha_k, rho_k, e_k) is second order only where
#: the cell and its neighbours along the sweep are filled to PHI_SECOND_ORDER or more and the
#: densities rho_k of the materials present in each differ by at most a factor
#: DENSITY_RATIO_SECOND_ORDER: the contact of two solids (the projectile and the target).
#: Elsewhere the limited slope of a volume fraction takes the face density towards the
#: lighter side (void, or a vapour at 1e-6 of the other's density) while the face pressure
#: keeps the mixture's, and that face state (p > 0 on a vanishing density) gives an
#: unbounded face velocity p / (rho c): 1.3e5 m/s in case 8c next to void, 2.2e5 m/s for
#: ice vapour beside compressed iron in an ice-on-iron impact.
PHI_SECOND_ORDER = 1.0 - 1.0e-3
DENSITY_RATIO_SECOND_ORDER = 2.0
#: The flow (u_n, u_t1, u_t2, p) of a cell is reconstructed at second order where the cell and
#: its neighbours along the sweep are filled to PHI_FLOW_SECOND_ORDER or more (partly void
#: cells at free surfaces and in opened cracks included); the materials of such a cell keep
#: their cell values unless the rule above holds, so its face density is its own.
PHI_FLOW_SECOND_ORDER = 0.9
#: A cell whose materials fill more than 1 - FULL_TOLERANCE of it has no void.
FULL_TOLERANCE = 1.0e-8
#: A mixture density below -FAIL_NEGATIVE_FRACTION * (previous density) is a failure.
FAIL_NEGATIVE_FRACTION = 1.0e-3
#: A cell whose material nearly all left in a sweep (new density below EMPTIED_FRACTION
#: times the old, and volume fraction below PHI_VOID) holds only round-off residue of
#: the fluxes; it becomes void and the residue's mass, momentum and energy are counted.
EMPTIED_FRACTION = 1.0e-8
#: In a cell filled below PHI_SMALL (by volume, or by mass: sum_k alpha_k rho_k / rho0_k)
#: the velocity may not exceed the fastest speed of the material around it (the pencil
#: neighbours and the face speeds): momentum residues of the fluxes would otherwise give the
#: small mass an unbounded velocity.  The momentum and kinetic energy removed are counted.
#: In the same small cells the specific total energy E / rho may not exceed the largest
#: specific total enthalpy (E + max(p, 0)) / rho of the cell and its pencil neighbours before
#: the sweep: mixing cannot exceed it, so only the face work p* s of a full neighbour
#: concentrated into a vanishing mass can, and that is the path by which spray and vapour
#: reached 1e9 - 1e14 J/kg in case 8c.  The energy removed is counted.
PHI_SMALL = 1.0e-3
#: Material thinner than DISCARD_FRACTION of its reference density rho0 is discarded from
#: the cell (as CTH's discard density does): its mass, momentum share and energy are
#: counted with the void cleanup.  Materials without a reference density (gases) are kept.
DISCARD_FRACTION = 1.0e-6

# Floor counter slots (``floors[NB, NFLOOR]``).
FLOOR_ALPHA = 0
FLOOR_PARTIAL_DENSITY = 1
FLOOR_INTERNAL_ENERGY = 2
FLOOR_VOID_CLEANUP = 3
FLOOR_FIRST_ORDER = 4
FLOOR_EOS_CLAMP = 5
FLOOR_VELOCITY_LIMIT = 6
FLOOR_TENSILE_LIMIT = 7
FLOOR_ENERGY_LIMIT = 8
FLOOR_REGISTER_REDISTRIBUTION = 9
NFLOOR = 10
FLOOR_NAMES = ("negative_volume_fraction", "negative_partial_density", "negative_internal_energy",
               "void_cleanup", "first_order_fallback", "eos_clamp", "small_cell_velocity_limit",
               "tensile_limit", "small_cell_energy_limit", "register_redistribution")
# Amount slots (``amounts[NB, NAMOUNT]``): kg, J and kg m/s, summed over the cells.  The
# momentum a floor removes is signed, per global component c (x, y, z; r, z, theta in
# 2d-cylindrical): the slot AMOUNT_MOMENTUM_VOID + c (or AMOUNT_MOMENTUM_LIMITER + c) sums the
# cells' m_c,before - m_c,after times V, which the budget takes back
# (:func:`impactpipe.hydro.budget.conservation_budget`).
AMOUNT_MASS_FLOOR = 0
AMOUNT_ENERGY_FLOOR = 1
AMOUNT_ENERGY_RECONCILED = 2
AMOUNT_ENERGY_VOID = 3
AMOUNT_MASS_VOID = 4
AMOUNT_MOMENTUM_VOID = 5        # + c: slots 5, 6, 7
AMOUNT_MOMENTUM_LIMITER = 8     # + c: slots 8, 9, 10
AMOUNT_ENERGY_LIMITER = 11
AMOUNT_ENERGY_CAP = 12
NAMOUNT = 13
AMOUNT_NAMES = ("mass_added_by_floors", "energy_added_by_floors", "energy_reconciled",
                "energy_removed_by_void_cleanup", "mass_removed_by_void_cleanup",
                "momentum_x_removed_by_void_cleanup", "momentum_y_removed_by_void_cleanup",
                "momentum_z_removed_by_void_cleanup", "momentum_x_removed_by_velocity_limit",
                "momentum_y_removed_by_velocity_limit", "momentum_z_removed_by_velocity_limit",
                "energy_removed_by_velocity_limit", "energy_removed_by_energy_limit")
# Boundary counter slots (``boundary[NB, 5 + M]``): what left the domain (kg, kg m/s, J).
BND_MASS = 0
BND_MOMENTUM = 1
BND_ENERGY = 4
BND_MATERIAL = 5

# Failure record (``failure[NB, 4]``): code, ix, iy, iz.
FAIL_NAN = 1
FAIL_NEGATIVE_DENSITY = 2

# Rows of each cell's record in the per-thread scratch ``sc[cell, row]``: cell values W, face
# states FM/FP, face fluxes F.
W_RHO, W_UN, W_UT1, W_UT2, W_P, W_C, W_K, W_PHI, W_VOL, W_IVL, W_IVR = range(11)
W_MAT = 11          # + W_STRIDE k: alpha_k, rho_k, e_k, p_k, K_k = rho_k c_K,k^2, Y_T,k (1 - D_k)
W_STRIDE = MATERIAL_ROWS    # the per-material rows of hydro.mixture.mixture_state
Q_UN, Q_UT1, Q_UT2, Q_P = range(4)
Q_MAT = 4           # + 3 k: alpha_k, rho_k, e_k
F_MN, F_MT1, F_MT2, F_E, F_S = range(5)
F_MAT = 5           # + 3 k: volume, mass, internal energy; then one row: the face's donor cell (plain pencils)


def scratch_rows(nmat: int, nq: int = 0) -> int:
    """Number of scratch rows per thread for ``nmat`` materials with ``nq`` transported scalars each:
    the W, FM, FP and F rows, a face's donor cell, then the specific scalars and their fluxes."""
    return (W_MAT + W_STRIDE * nmat) + 2 * (Q_MAT + 3 * nmat) + (F_MAT + 3 * nmat) + 1 + 2 * nmat * nq


def allocate_scratch(nthreads: int, nmat: int, pencil_cells: int, nq: int = 0) -> np.ndarray:
    """Per-thread scratch ``(nthreads, pencil_cells + 1, rows)`` for :func:`impactpipe.hydro.scheme.directional.sweep`.

    Cell-major: ``sc[i, row]``, the rows of one cell (or face) side by side, so the loops over a
    pencil's cells advance one pointer rather than one per row (the compiler keeps too many
    row pointers of a row-major scratch on the stack)."""
    return np.zeros((nthreads, pencil_cells + 1, scratch_rows(nmat, nq)))


def transport_ghost_layers(nmat: int, nq: int, porous: bool) -> np.ndarray:
    """Ghost layers (1 or GHOST = 2) of each column of ``arhoq`` (M NQ, int64) the sweep reads.

    The gather reads each material's damage (the last of its NQ scalars) and in a ``porous``
    scene its distension (the one before) in every cell of the pencil, both ghost layers
    included: they set the cell's pressure and tension limit, and the MC slope of the first
    ghost cell takes them from the second.  The other scalars (stress, plastic strain,
    flaws) move at the donor cell's specific value, first order
    (:mod:`impactpipe.hydro.scheme.directional`, step 5): the faces g .. g + n take it from
    the cells g - 1 .. g + n, the first ghost layer at most.  The gather reads them in the
    second layer as well, into scratch rows that no face uses.
    """
    layers = np.ones(nmat * nq, dtype=np.int64)
    for k in range(nmat if nq > 0 else 0):
        layers[nq * k + nq - 1] = GHOST
        if porous:
            layers[nq * k + nq - 2] = GHOST
    return layers


@njit(cache=True, inline="always")
def pencil_cell_index(axis, i, j1, j2):
    """Array indices (ix, iy, iz) of cell ``i`` of the pencil along ``axis`` at transverse indices (j1, j2)."""
    if axis == 0:
        return i, j1, j2
    if axis == 1:
        return j1, i, j2
    return j1, j2, i


@njit(cache=True, inline="always")
def pencil_offset(nx, ny, nz, axis, j1, j2):
    """(offset, stride) of the pencil along ``axis`` at transverse indices (j1, j2) in one column
    of a C-ordered field ``[NB, C, NX, NY, NZ]`` seen as a flat array: cell i of the pencil in
    column c of block b is element ``(b C + c) NX NY NZ + offset + i stride``.

    The plain path indexes the flattened fields this way, with one integer per access
    instead of five (each with its own offset and negative-index check), and without the
    reference counting that a view per pencil costs.
    """
    ix, iy, iz = pencil_cell_index(axis, 0, j1, j2)
    offset = (ix * ny + iy) * nz + iz
    if axis == 0:
        return offset, ny * nz
    if axis == 1:
        return offset, nz
    return offset, 1
