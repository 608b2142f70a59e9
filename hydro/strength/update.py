"""The per-cell strength update: velocity gradient, Jaumann elastic update, tensile failure,
yield and damage, for every material with a yield model (one operator-split step of dt).

Per-material scalars live in the state's ``arhoq[NB, M * NQ, ...]`` as mass-weighted amounts
alpha_k rho_k q_k,j (transported by the sweeps with the material's mass flux), slot j of
material k at ``k * NQ + j``: the deviatoric stress components (Pa; NS = 3, 4 or 6 of
(xx, yy, zz, xy, xz, yz) in 1, 2 or 3 dimensions; in 2d-cylindrical slot 2 is the hoop
component S_thth), the equivalent plastic strain (-) at ``NS``, with Grady-Kipp fracture in the
scene (some material's damage model ``grady_kipp``) its flaws at ``NS + 1 .. NS + NFLAW``, and
the damage D (-) last, at ``NQ - 1`` (NQ = NS + 2, or NS + 2 + NFLAW with fracture;
:func:`scalar_slots`).  The flaws are the cell's cumulative law per unit mass at the
material's NFLAW node strains eps_j (:mod:`impactpipe.hydro.strength.flaws`,
:func:`~impactpipe.hydro.strength.flaws.flaw_law_per_mass`): C_j, the flaws per kg active at
eps_j.  Stored as alpha_k rho_k C_j (flaws per m^3 of cell), they are amounts like the others:
the sweeps, the AMR transfers, the regrid and the reflecting (mirror-plane) ghosts move them
with the mass and conserve the body's flaws below every node; the law of a mixture is the sum
of its parts' laws.

Velocity gradient L_ij = d v_i / d x_j (1/s) from the cell velocities: central differences,
one-sided next to a void cell, zero between two void cells; in 2d-cylindrical the hoop
rate L_thth = v_r / r at the cell centre.  Per material k present in the cell:

1. G_k = G_const + (G/K) rho_k c_K,k^2 (:mod:`impactpipe.hydro.strength.parameters`);
2. tensile failure: when the EOS pressure p_k < -Y_T (1 - D) the material fails (D = 1,
   counted once as ``tensile_failure``); from then on its yield strength in tension is zero
   (the tensile taper of :mod:`impactpipe.hydro.strength.yield_strength` with Y_T (1 - D)).
   The sweeps limit its mean stress to -Y_T (1 - D), zero once failed, and open void
   instead of stretching it (docs/hydro.md, "Tensile limit";
   :func:`impactpipe.hydro.scheme.mixture.damaged_tensile_strength`).
   Grady-Kipp materials (``damage_model[k] == GRADY_KIPP``) do not fail at a fixed stress:
   the matrix pressure p_m = max(p_k, -Y_T) (p_k itself without Y_T) is borne as
   p_b = p_m in compression and (1 - D) p_m in tension (as the sweeps do,
   :func:`impactpipe.hydro.scheme.mixture.damaged_tension`); from the largest principal
   stress of -p_b I + S the damage grows by one step of
   :func:`impactpipe.hydro.strength.fracture.damage_step` at the rate
   c_g (4 pi rho_k n_act,m / 3)^(1/3), n_act,m the active flaws per kg at the matrix strain
   sigma_max / ((1 - D) E) (:mod:`impactpipe.hydro.strength.fracture`), up to the active share
   of the cell's flaws n_act,m / n_tot,m with the active-flaw limit (``grady_kipp_flaw_limited``
   counts the steps where it held D below the unlimited step); the stored deviator
   (the one the material bears) is scaled by (1 - D_new) / (1 - D_old) and the Jaumann update
   uses the shear modulus (1 - D) G, so S stays (1 - D) times the intact matrix's
   (von Mises, GEO; ROCK carries its damage in its yield curve instead, Y = (1 - D) Y_i + D Y_d,
   and keeps S and G).  ``grady_kipp_fractured`` counts the steps where D reached 1.
   A porous Grady-Kipp material (distension alpha, :func:`update_stress`) takes the bulk
   quantities: p_m = max(p_k, -Y_T / alpha) (the matrix's P_s >= -Y_T spread over the bulk),
   the strain sigma_max / ((1 - D) E) with E the porous Young modulus 9 K G / (3 K + G) of the
   porous bulk modulus K = rho_k c_s^2(alpha rho_k) h(alpha)^2 and the porous G of step 1 (a
   given E is scaled by h^2 / alpha, the ratio of the porous bulk modulus to the matrix's), and
   the crack speed 0.4 sqrt(K / rho_k + 4 G / (3 rho_k)) of the porous longitudinal wave; its
   flaws per kg are those of its matrix volume (:mod:`impactpipe.hydro.strength.model`);
3. S <- Jaumann update (:func:`impactpipe.hydro.strength.elastic.jaumann_update`);
4. Y = yield_strength(p_held, T_k, D) at the pressure the material bears,
   p_held = max(p_k, -Y_T (1 - D)) (the sweeps hold it there by opening void: failed
   material at p_k < 0 bears p = 0, where GEO keeps its cohesion Y0; Grady-Kipp:
   von Mises and GEO yield at (1 - D) Y(p_m, T_k, 0), the damaged share of the intact
   matrix's strength, ROCK at Y(p_b, T_k, D); a porous material at the matrix pressure,
   Y_s(alpha p, ...) / alpha as without Grady-Kipp), T_k from the EOS (T_k and Y are evaluated only
   where the updated S is not zero: with S = 0 there is nothing to return, as Y >= 0), and
   Y = 0 for material expanded below STRENGTH_MIN_DENSITY_FRACTION of its reference density
   (fragmented or vapour: a deviatoric stress held by it would put S:D / rho_k of work into
   very little mass); with a surface gravity g (:meth:`impactpipe.hydro.strength.model.
   MaterialStrength.set_surface_layer_pressure`) p_held in a cell with void (fill phi < 1) is
   at least rho_k |g| h / 2, h = phi times the cell's extent along g: the pressure at mid-depth
   of the layer the cell holds, which the free-surface closure relaxes to zero (counted as
   ``surface_layer_pressure``); a GEO material with a ``grain_diameter`` takes its friction
   mu(I) = mu_s + (mu_2 - mu_s) / (I0 / I + 1) at the inertial number
   I = gamma_dot d / sqrt(alpha p_held / (alpha rho_k)) of the cell's shear rate
   gamma_dot = sqrt(2 D_dev:D_dev) (1/s, D = (L + L^T) / 2) instead of mu_i = mu_s
   (:func:`impactpipe.hydro.strength.yield_strength.inertial_friction`);
   radial return to sqrt(3 J2) <= Y (``yield_return``), equivalent
   plastic strain += d eps_p; ROCK: D += d eps_p / eps_f(p_held);
5. internal energy alpha_k rho_k e_k += dt alpha_k (S_k,old + S_k,new) / 2 : D_rate (stress
   power; elastic and plastic work).  The momentum kicks around this update use S_old for the
   first half step and S_new for the second (docs/strength.md, "Time integration"), so the
   mean stress is the one that does the work on the bulk motion and the internal energy stays
   consistent with the conservative stress fluxes.

The cell's mixture deviatoric stress S = sum_k alpha_k S_k (void and strengthless materials
carry none) goes to ``work`` for the stress-divergence fluxes.
"""

from __future__ import annotations

import math

import numpy as np

from numba import njit, prange

from impactpipe.hydro.eos import pressure_not_negative, pressure_sound_speed_in_line, temperature_in_line
from impactpipe.hydro.eos.porosity import ALPHA0, wave_speed_ratio
from impactpipe.hydro.mesh.blocks import CYLINDRICAL, ghost_widths
from impactpipe.hydro.mesh.last_good import RECORD_CLEAR, RECORD_VOID
from impactpipe.hydro.scheme.mixture import ALPHA_MIN, DISTENDED_FRACTION
from impactpipe.hydro.strength.damage import shear_damage_increment
from impactpipe.hydro.strength.elastic import jaumann_update, radial_return
from impactpipe.hydro.strength.fracture import (
    active_fraction, crack_speed, cumulative_flaws, damage_growth_rate_of_density, damage_step, damaged_pressure,
    largest_principal_stress, tensile_strain, young_modulus,
)
from impactpipe.hydro.strength.parameters import (
    ACTIVE_LIMIT, FLAW_NODES, GRAIN_D, GRADY_KIPP, I0, MU_2, MU_I, NODE0, NONE, P_BD, P_BP, ROCK, WEIBULL_M, YOUNG,
)
from impactpipe.hydro.strength.yield_strength import (
    SQRT3, equivalent_yield_stress, inertial_friction, yield_strength_friction,
)
from impactpipe.hydro.scheme.timestep import PHI_VOID

# work array slots (``work[NB, NWORK, NX, NY, NZ]``)
WK_V = 0            # + axis: cell velocity (m/s)
WK_PHI = 3          # material fill of a cell holding material (phi >= PHI_VOID and rho > 0):
                    # min(sum_k alpha_k, sum_k alpha_k rho_k / rho0_k); 0 in void cells
WK_S = 4            # + slot: mixture deviatoric stress (xx, yy, zz, xy, xz, yz) (Pa)
NWORK = 10
# with the face shear stress only (work arrays of NWORK_FACE slots), written by update_stress:
WK_Y = 10           # the cell's shear strength sum_k alpha_k Y_eq,k / sqrt(3) (Pa)
WK_L = 11           # + gradient_slot(d, i): its off-diagonal velocity gradients L_di = d v_d / d x_i (1/s)
NWORK_FACE = 17


@njit(inline="always")
def gradient_slot(d, i):
    """Offset from ``WK_L`` of the off-diagonal velocity gradient L_di (d != i): 0 .. 5."""
    return 2 * d + (i if i < d else i - 1)


# counter slots (``counts[NB, NCOUNT]``) and amount slots (``amounts[NB, NSAMOUNT]``)
CNT_YIELD = 0
CNT_TENSILE_FAILURE = 1
CNT_LOW_DENSITY = 2
CNT_FRACTURED = 3
CNT_FLAW_LIMITED = 4
CNT_SURFACE_LAYER = 5
NCOUNT = 6
COUNT_NAMES = ("yield_return", "tensile_failure", "strength_dropped_below_min_density", "grady_kipp_fractured",
               "grady_kipp_flaw_limited", "surface_layer_pressure")
AMT_PLASTIC_WORK = 0
NSAMOUNT = 1
AMOUNT_NAMES = ("stress_work",)

#: Material below this fraction of its reference density carries no deviatoric stress (the
#: sweeps' and the time step's signal speed drop the shear term there too).
STRENGTH_MIN_DENSITY_FRACTION = DISTENDED_FRACTION


#: Flaw slots after the plastic strain (NS + 1 .. NS + NFLAW), present with Grady-Kipp fracture.
NFLAW = FLAW_NODES


def stress_slots(ndim: int) -> int:
    """Number of stored deviatoric stress components NS in ``ndim`` dimensions."""
    return {1: 3, 2: 4, 3: 6}[ndim]


def scalar_slots(ndim: int, fracture: bool, porous: bool = False) -> int:
    """Transported scalars per material NQ: NS stress components, plastic strain, damage, with
    Grady-Kipp ``fracture`` the NFLAW flaw slots, and in a ``porous`` scene the distension just
    before the damage (:mod:`impactpipe.hydro.eos.porosity`)."""
    return stress_slots(ndim) + 2 + (NFLAW if fracture else 0) + (1 if porous else 0)


# allocates nothing: compiled without reference counting (docs/performance.md, "Compile time")
@njit(cache=True, parallel=True, _nrt=False)
def cell_velocity_and_stress(alpha, arho, arhoq, mom, rho0, model, ns, work, blocks, holds, has_mass,
                             stressed_blocks, record):
    """Velocity, material fill and mixture deviatoric stress of the interior cells of the
    ``blocks`` listed (int64) into ``work`` (ghosts are filled from them afterwards), into
    ``holds[b]`` whether block b has a cell that holds material (1) or not (0): the kernels of
    the stress step read no ghost of a block without one, so its ghosts need no filling;
    and into ``has_mass[b]`` whether some cell of block b has mass, rho > 0 (1) or not (0):
    a cell without mass holds no transported scalars (every kernel that removes a material's
    last mass zeroes them), so :func:`update_stress` has nothing to do in a block without;
    and into ``stressed_blocks[b]`` whether some interior cell of block b has a mixture stress
    component other than 0 (1) or not (0): the stress divergence skips a block without one
    when its ghosts carry none either
    (:func:`impactpipe.hydro.strength.divergence.apply_stress_divergence`).

    A cell's fill is min(phi, sum_k alpha_k rho_k / rho0_k), phi = sum_k alpha_k
    (``rho0[M]`` the materials' reference densities, kg/m^3; materials without one, rho0 = 0,
    count by volume): material expanded far below rho0 fills a cell by volume but is as light
    as a spray, and the stress tractions scale with it, so its acceleration stays that of a
    full cell.  A cell holds material when rho = sum_k alpha_k rho_k > 0 and its fill is at
    least PHI_VOID; its velocity is v = (rho v) / rho (m/s).  Other cells (void, and spray
    thinner than PHI_VOID by mass) get velocity, fill and stress 0: no traction acts on them.
    (A fill floored at PHI_VOID instead overstated the traction on thinner spray by its ratio
    to the true fill and drove cells of 1e-6 kg/m^3 to 1e5 m/s in a laboratory impact.)

    Mixture stress S = sum_k alpha_k S_k (Pa), S_k = (alpha_k rho_k S_k) / (alpha_k rho_k)
    from the transported amounts ``arhoq`` (its first ``ns`` slots per material); cells without the material and strengthless
    materials add nothing.  This is the stress the first half of the momentum kick uses.

    Only the first ``ns`` stress slots are written; the others (components a 1-D or 2-D mesh
    does not carry) stay zero.  A cell whose fill in ``work`` is already 0 has zero velocity
    and stress there (every kernel that writes ``work`` keeps that so), and stays untouched
    when it is still void: most of the mesh is void in an impact, and skipping the stores
    saves their memory traffic.  ``record`` (uint8, (NB,), or empty: none): the record of the
    last sweep (:data:`impactpipe.hydro.mesh.last_good.RECORD_VOID`), a block whose entry is
    RECORD_VOID was void at the start of the step and no sweep wrote to it: it is passed over
    without a look at its cells (no cell holds material; the fills in ``work`` are 0 already,
    left so when the block was last looked at, void as now), half of an impact's blocks.  A
    block whose entry is RECORD_CLEAR holds +0.0 in every transported scalar: each of its
    mixture stresses, a sum of a / (a rho) times +0.0 with a / (a rho) finite and > 0 (the
    sweeps discard a solid's partial density long before its inverse could overflow), is +0.0,
    and is stored so without reading the scalars.
    """
    nb, nmat, nx, ny, nz = alpha.shape
    nq = arhoq.shape[1] // nmat
    gx, gy, gz = ghost_widths(nx, ny, nz)
    recorded = record.shape[0] > 0
    for i in prange(blocks.shape[0]):
        b = blocks[i]
        if recorded and record[b] == RECORD_VOID:
            holds[b] = 0
            has_mass[b] = 0
            stressed_blocks[b] = 0
            continue
        held = 0
        massive = 0
        carries = False
        # scalars +0.0 throughout: every mixture stress is +0.0, summed without a read
        clear = recorded and record[b] == RECORD_CLEAR
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    rho = 0.0
                    phi = 0.0
                    solid = 0.0
                    for k in range(nmat):
                        ar = arho[b, k, ix, iy, iz]
                        rho += ar
                        phi += alpha[b, k, ix, iy, iz]
                        r0 = rho0[k]
                        solid += ar / r0 if r0 > 0.0 else alpha[b, k, ix, iy, iz]
                    fill = min(phi, solid)
                    if rho > 0.0:
                        massive = 1
                    if not (rho > 0.0 and fill >= PHI_VOID):
                        if work[b, WK_PHI, ix, iy, iz] != 0.0:
                            for d in range(3):
                                work[b, WK_V + d, ix, iy, iz] = 0.0
                            work[b, WK_PHI, ix, iy, iz] = 0.0
                            for c in range(ns):
                                work[b, WK_S + c, ix, iy, iz] = 0.0
                        continue
                    held = 1
                    for d in range(3):
                        work[b, WK_V + d, ix, iy, iz] = mom[b, d, ix, iy, iz] / rho
                    work[b, WK_PHI, ix, iy, iz] = fill
                    s0 = s1 = s2 = s3 = s4 = s5 = 0.0
                    for k in range(nmat if not clear else 0):
                        ar = arho[b, k, ix, iy, iz]
                        a = alpha[b, k, ix, iy, iz]
                        if model[k] == NONE or not (a > ALPHA_MIN and ar > 0.0):
                            continue
                        scale = a / ar
                        q = k * nq
                        s0 += scale * arhoq[b, q, ix, iy, iz]
                        s1 += scale * arhoq[b, q + 1, ix, iy, iz]
                        s2 += scale * arhoq[b, q + 2, ix, iy, iz]
                        if ns > 3:
                            s3 += scale * arhoq[b, q + 3, ix, iy, iz]
                        if ns > 4:
                            s4 += scale * arhoq[b, q + 4, ix, iy, iz]
                            s5 += scale * arhoq[b, q + 5, ix, iy, iz]
                    _store_stress(work, b, ix, iy, iz, ns, s0, s1, s2, s3, s4, s5)
                    carries = carries or _nonzero(s0, s1, s2, s3, s4, s5)
        holds[b] = held
        has_mass[b] = massive
        stressed_blocks[b] = 1 if carries else 0


@njit(cache=True, inline="always")
def _nonzero(s0, s1, s2, s3, s4, s5):
    """Whether some of the stress components (xx, yy, zz, xy, xz, yz) (Pa) is not 0."""
    return s0 != 0.0 or s1 != 0.0 or s2 != 0.0 or s3 != 0.0 or s4 != 0.0 or s5 != 0.0


@njit(cache=True, inline="always")
def _positive_zeros(s0, s1, s2, s3, s4, s5):
    """Whether each of the stress components (Pa) is +0.0 (its sign bit clear: -0.0 is not)."""
    return (s0 == 0.0 and s1 == 0.0 and s2 == 0.0 and s3 == 0.0 and s4 == 0.0 and s5 == 0.0
            and math.copysign(1.0, s0) > 0.0 and math.copysign(1.0, s1) > 0.0 and math.copysign(1.0, s2) > 0.0
            and math.copysign(1.0, s3) > 0.0 and math.copysign(1.0, s4) > 0.0 and math.copysign(1.0, s5) > 0.0)


@njit(cache=True, inline="always")
def _store_stress(work, b, ix, iy, iz, ns, s0, s1, s2, s3, s4, s5):
    """Write the first ``ns`` of the mixture stress components (xx, yy, zz, xy, xz, yz) (Pa) into ``work``."""
    work[b, WK_S, ix, iy, iz] = s0
    work[b, WK_S + 1, ix, iy, iz] = s1
    work[b, WK_S + 2, ix, iy, iz] = s2
    if ns > 3:
        work[b, WK_S + 3, ix, iy, iz] = s3
    if ns > 4:
        work[b, WK_S + 4, ix, iy, iz] = s4
        work[b, WK_S + 5, ix, iy, iz] = s5


@njit(cache=True, inline="always")
def _clear_scalars(arhoq, b, first, count, ix, iy, iz):
    """Set ``arhoq[b, first .. first + count - 1]`` of a cell to +0.0, storing only the values
    that are not +0.0 already (a void cell's or absent material's scalars nearly always are:
    the skipped stores are memory traffic saved, the result is the same bit for bit)."""
    for q in range(first, first + count):
        v = arhoq[b, q, ix, iy, iz]
        if v != 0.0 or math.copysign(1.0, v) < 0.0:
            arhoq[b, q, ix, iy, iz] = 0.0


@njit(cache=True, inline="always")
def _clear_strength_scalars(arhoq, b, first, nq, porous, ix, iy, iz):
    """:func:`_clear_scalars` of a material's ``nq`` scalars from ``first``, keeping a ``porous``
    material's distension (slot ``nq - 2``, :mod:`impactpipe.hydro.eos.porosity`): a trace of it
    in a void cell is still porous material, and the sweeps divide by its distension."""
    if porous:
        _clear_scalars(arhoq, b, first, nq - 2, ix, iy, iz)
        _clear_scalars(arhoq, b, first + nq - 1, 1, ix, iy, iz)
    else:
        _clear_scalars(arhoq, b, first, nq, ix, iy, iz)


@njit(cache=True, parallel=True)
def cell_velocities(arho, mom, work, blocks, unchanged):
    """New velocities v = (rho v) / rho (m/s), rho = sum_k alpha_k rho_k, of the interior cells
    of the ``blocks`` listed (int64) that hold material
    (``work`` fill > 0, set by :func:`cell_velocity_and_stress`; the momentum kicks move no
    mass, so the fills stay).  A block with ``unchanged[b]`` not 0 (uint8, (NB,), or empty:
    none) is passed over: its momentum is the one :func:`cell_velocity_and_stress` divided, and
    its velocities are these quotients already, bit for bit (the same sums and division)."""
    nb, nmat, nx, ny, nz = arho.shape
    gx, gy, gz = ghost_widths(nx, ny, nz)
    skips = unchanged.shape[0] > 0
    for i in prange(blocks.shape[0]):
        b = blocks[i]
        if skips and unchanged[b] != 0:
            continue
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    if work[b, WK_PHI, ix, iy, iz] <= 0.0:
                        continue
                    rho = 0.0
                    for k in range(nmat):
                        rho += arho[b, k, ix, iy, iz]
                    for d in range(3):
                        work[b, WK_V + d, ix, iy, iz] = mom[b, d, ix, iy, iz] / rho


@njit(cache=True, parallel=True)
def snapshot_stress_fields(alpha, arho, arhoq, model, ns, nq, lo, hi, out):
    """The strength fields of a snapshot for the interior cells of blocks ``lo .. hi - 1`` into
    ``out`` (ns + 3, NB, nx, ny, nz), zeros on entry: ``out[j]``, j < ``ns``, the mixture's
    deviatoric stress sum_k alpha_k S_k,j (Pa), ``out[ns]`` its von Mises stress sqrt(3/2 S:S)
    (Pa), ``out[ns + 1]`` and ``out[ns + 2]`` the plastic strain and the damage (-), means over
    the materials with a yield model (``model[k]`` not 0) weighted by their partial densities
    (0 where they have none), each sum taken material after material."""
    nb, nmat, nx, ny, nz = alpha.shape
    gx, gy, gz = ghost_widths(nx, ny, nz)
    for b in prange(lo, hi):
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    jx, jy, jz = ix - gx, iy - gy, iz - gz
                    eps = 0.0
                    dmg = 0.0
                    mass = 0.0
                    for k in range(nmat):
                        if model[k] == 0:
                            continue
                        ar = arho[b, k, ix, iy, iz]
                        if ar > 0.0:
                            for j in range(ns):
                                out[j, b, jx, jy, jz] += alpha[b, k, ix, iy, iz] * arhoq[b, k * nq + j, ix, iy, iz] / ar
                        eps += arhoq[b, k * nq + ns, ix, iy, iz]
                        dmg += arhoq[b, k * nq + nq - 1, ix, iy, iz]
                        mass += ar
                    normal = 0.0
                    for j in range(3):
                        normal += out[j, b, jx, jy, jz] * out[j, b, jx, jy, jz]
                    shear = 0.0
                    for j in range(3, ns):
                        shear += out[j, b, jx, jy, jz] * out[j, b, jx, jy, jz]
                    out[ns, b, jx, jy, jz] = math.sqrt(1.5 * (normal + 2.0 * shear))
                    out[ns + 1, b, jx, jy, jz] = eps / mass if mass > 0.0 else 0.0
                    out[ns + 2, b, jx, jy, jz] = dmg / mass if mass > 0.0 else 0.0


@njit(cache=True, inline="always")
def _derivative(work, b, comp, ix, iy, iz, axis, dx):
    """d v_comp / d x_axis at a cell: central, one-sided next to void, 0 between void cells (1/s).
    A velocity difference of +-0 is returned as it is: divided by the cell size (> 0) it gives
    the same +-0, and a cell at rest among its neighbours, most of an impact's target early on,
    spares its divisions."""
    jx0, jy0, jz0 = ix, iy, iz
    jx1, jy1, jz1 = ix, iy, iz
    if axis == 0:
        jx0 -= 1
        jx1 += 1
    elif axis == 1:
        jy0 -= 1
        jy1 += 1
    else:
        jz0 -= 1
        jz1 += 1
    lo = work[b, WK_PHI, jx0, jy0, jz0] > 0.0
    hi = work[b, WK_PHI, jx1, jy1, jz1] > 0.0
    if lo and hi:
        dv = work[b, WK_V + comp, jx1, jy1, jz1] - work[b, WK_V + comp, jx0, jy0, jz0]
        return dv / (2.0 * dx) if dv != 0.0 else dv
    if hi:
        dv = work[b, WK_V + comp, jx1, jy1, jz1] - work[b, WK_V + comp, ix, iy, iz]
        return dv / dx if dv != 0.0 else dv
    if lo:
        dv = work[b, WK_V + comp, ix, iy, iz] - work[b, WK_V + comp, jx0, jy0, jz0]
        return dv / dx if dv != 0.0 else dv
    return 0.0


@njit(cache=True, inline="always")
def _shear_rate(lxx, lxy, lxz, lyx, lyy, lyz, lzx, lzy, lzz):
    """The shear rate gamma_dot = sqrt(2 D_dev:D_dev) = 2 sqrt(J2(D_dev)) (1/s) of the velocity
    gradient L (D = (L + L^T) / 2; in 2d-cylindrical lzz is the hoop rate v_r / r)."""
    third = (lxx + lyy + lzz) / 3.0
    dxx = lxx - third
    dyy = lyy - third
    dzz = lzz - third
    dxy = 0.5 * (lxy + lyx)
    dxz = 0.5 * (lxz + lzx)
    dyz = 0.5 * (lyz + lzy)
    return math.sqrt(2.0 * (dxx * dxx + dyy * dyy + dzz * dzz + 2.0 * (dxy * dxy + dxz * dxz + dyz * dyz)))


@njit(cache=True, inline="always")
def _friction(params, pressure, density, lxx, lxy, lxz, lyx, lyy, lyz, lzx, lzy, lzz):
    """The intact friction coefficient of a material row: mu_i, or with a grain diameter (GEO's
    mu(I) friction) mu(I) at the matrix pressure (Pa) and density (kg/m^3) and the cell's shear
    rate (:func:`impactpipe.hydro.strength.yield_strength.inertial_friction`)."""
    if params[GRAIN_D] <= 0.0:
        return params[MU_I]
    return inertial_friction(params[MU_I], params[MU_2], params[I0], params[GRAIN_D],
                             _shear_rate(lxx, lxy, lxz, lyx, lyy, lyz, lzx, lzy, lzz), pressure, density)


@njit(cache=True, inline="always")
def _surface_layer_pressure(rho, fill, gravity, dxs):
    """Pressure (Pa) at mid-depth of the layer a cell with void holds: rho |g| h / 2, h = fill times
    the cell's extent along g, sum_d |g_d| dx_d / |g| (m); rho (kg/m^3), ``gravity`` g (m/s^2)."""
    extent = abs(gravity[0]) * dxs[0] + abs(gravity[1]) * dxs[1] + abs(gravity[2]) * dxs[2]
    return 0.5 * rho * fill * extent


@njit(cache=True, inline="always")
def _grady_kipp_damage(damage, pressure, sxx, syy, szz, sxy, sxz, syz, rho, c2_bulk, shear_modulus, arhoq, b, first,
                       ix, iy, iz, inv_mass, weibull_m, young, limited, node_x, dt):
    """Damage after one Grady-Kipp step of ``dt`` (s) (module docstring, step 2).

    ``pressure`` the borne pressure p_b and S the borne deviator (Pa), rho the material density
    (kg/m^3), c2_bulk its bulk modulus over rho (m^2/s^2: the EOS sound speed squared, a porous
    material's c_s^2 h^2), ``shear_modulus`` the intact G (Pa); the flaw law per kg is read from ``arhoq[b, first .. first + NFLAW - 1]`` times
    ``inv_mass`` = 1 / (alpha_k rho_k), at the nodes eps_j^m = ``node_x``.  E = ``young`` (Pa), or 9 K G / (3 K + G) when 0;
    the crack speed is 0.4 of the intact longitudinal speed sqrt(c_K^2 + 4 G / (3 rho)).  With
    ``limited`` (> 0) D grows to at most n_act,m / n_tot,m, the active share of the cell's flaws
    (its law at the strain over its law beyond the last node; Benz & Asphaug 1995).  Returns
    (D, whether the limit held D below the unlimited step).
    """
    bulk = rho * max(c2_bulk, 0.0)
    e = young if young > 0.0 else young_modulus(shear_modulus, bulk)
    sigma_max = largest_principal_stress(pressure, sxx, syy, szz, sxy, sxz, syz)
    strain = tensile_strain(sigma_max, damage, e)
    if strain <= 0.0:
        return damage, False
    n_active = cumulative_flaws(strain ** weibull_m, node_x, arhoq, first, b, ix, iy, iz, inv_mass)
    c_p = (max(c2_bulk, 0.0) + 4.0 * shear_modulus / (3.0 * rho)) ** 0.5
    rate = damage_growth_rate_of_density(rho * n_active, crack_speed(c_p))
    if limited > 0.0:
        n_total = arhoq[b, first + node_x.shape[0] - 1, ix, iy, iz] * inv_mass
        capped = damage_step(damage, rate, dt, active_fraction(n_active, n_total))
        if capped < damage_step(damage, rate, dt):
            return capped, True
        return capped, False
    return damage_step(damage, rate, dt), False


@njit(cache=True, inline="always")
def _rests_unstressed(work, alpha, arho, arhoe, amounts, b, ndim, model, eos_kind, eos_params, rho0, tensile_strength):
    """Whether the stress step of block b, whose transported scalars are +0.0 (no stress, plastic
    strain or damage), would leave everything as it is: every velocity of its interior cells and
    of the ghost layers beside its faces (what the velocity gradients read) is +0.0, so every
    L_ij is +0.0; each material with a yield model present in a cell holding material has
    Y_T >= 0 and a pressure certain to be >= 0 (:func:`impactpipe.hydro.eos.pressure_not_negative`)
    at rho_k >= STRENGTH_MIN_DENSITY_FRACTION rho0_k, the cell being at rest and unstressed in
    :func:`update_stress`'s sense (it skips the EOS; nothing fails, yields or is counted); and
    the energies it adds the stress power to are not -0.0: the power is +0.0, and +0.0 added
    to anything but -0.0 leaves its bits (the stress work ``amounts[b, AMT_PLASTIC_WORK]``, each
    alpha_k rho_k e_k).  A non-porous scene without surface-layer pressure or stored strength."""
    nb, nmat, nx, ny, nz = alpha.shape
    w0 = amounts[b, AMT_PLASTIC_WORK]
    if w0 == 0.0 and math.copysign(1.0, w0) < 0.0:
        return False
    gx, gy, gz = ghost_widths(nx, ny, nz)
    ex, ey, ez = min(gx, 1), min(gy, 1), min(gz, 1)
    # the interior cells and the first ghost layer beside each face (not the corners)
    if not _velocities_zero(work, b, gx, nx - gx, gy, ny - gy, gz, nz - gz):
        return False
    if ex and not (_velocities_zero(work, b, gx - 1, gx, gy, ny - gy, gz, nz - gz)
                   and _velocities_zero(work, b, nx - gx, nx - gx + 1, gy, ny - gy, gz, nz - gz)):
        return False
    if ey and not (_velocities_zero(work, b, gx, nx - gx, gy - 1, gy, gz, nz - gz)
                   and _velocities_zero(work, b, gx, nx - gx, ny - gy, ny - gy + 1, gz, nz - gz)):
        return False
    if ez and not (_velocities_zero(work, b, gx, nx - gx, gy, ny - gy, gz - 1, gz)
                   and _velocities_zero(work, b, gx, nx - gx, gy, ny - gy, nz - gz, nz - gz + 1)):
        return False
    for ix in range(gx, nx - gx):
        for iy in range(gy, ny - gy):
            for iz in range(gz, nz - gz):
                if work[b, WK_PHI, ix, iy, iz] <= 0.0:
                    continue
                for k in range(nmat):
                    if model[k] == NONE:
                        continue
                    a = alpha[b, k, ix, iy, iz]
                    ar = arho[b, k, ix, iy, iz]
                    if not (a > ALPHA_MIN and ar > 0.0):
                        continue
                    e_density = arhoe[b, k, ix, iy, iz]
                    rk = ar / a
                    if (tensile_strength[k] < 0.0 or (e_density == 0.0 and math.copysign(1.0, e_density) < 0.0)
                            or rk < STRENGTH_MIN_DENSITY_FRACTION * rho0[k]
                            or not pressure_not_negative(eos_kind[k], eos_params[k], rk, e_density * (1.0 / ar))):
                        return False
    return True


@njit(cache=True, inline="always")
def _strength_scalars_clear(arhoq, work, alpha, arho, b, ns, model):
    """Whether block b's interior would pass as clear to :func:`_rests_unstressed` in a Grady-Kipp
    scene, where the flaws (slots NS + 1 .. NS + NFLAW of each material) are not zero wherever the
    material is: every scalar the stress step reads or clears is +0.0 (its bits), that is the stress
    (slots 0 .. NS - 1), plastic strain (NS) and damage (NQ - 1) of each material with a yield model
    present in a cell holding material, and every scalar of a void cell (fill 0 in ``work``) and of
    an absent material with a yield model, which the step would set to +0.0.  Its flaws it neither
    reads nor writes at rest: a material at rest and unstressed does not reach the Grady-Kipp
    damage (:func:`update_stress`).  Not for a porous scene (a distension is not zero)."""
    nb, nmat, nx, ny, nz = alpha.shape
    nq = arhoq.shape[1] // nmat
    gx, gy, gz = ghost_widths(nx, ny, nz)
    bits = 0
    for ix in range(gx, nx - gx):
        for iy in range(gy, ny - gy):
            for iz in range(gz, nz - gz):
                void = work[b, WK_PHI, ix, iy, iz] <= 0.0
                for k in range(nmat):
                    if model[k] == NONE and not void:
                        continue
                    base = k * nq
                    present = alpha[b, k, ix, iy, iz] > ALPHA_MIN and arho[b, k, ix, iy, iz] > 0.0
                    if present and not void:
                        for q in range(base, base + ns + 1):
                            bits |= np.float64(arhoq[b, q, ix, iy, iz]).view(np.int64)
                        bits |= np.float64(arhoq[b, base + nq - 1, ix, iy, iz]).view(np.int64)
                    else:
                        for q in range(base, base + nq):
                            bits |= np.float64(arhoq[b, q, ix, iy, iz]).view(np.int64)
                if bits != 0:
                    return False
    return True


@njit(cache=True, inline="always")
def _velocities_zero(work, b, x0, x1, y0, y1, z0, z1):
    """Whether the velocities in the work arrays of block b's cells [x0, x1) x [y0, y1) x [z0, z1)
    are +0.0 (their bits: -0.0 is not)."""
    bits = 0
    for d in range(3):
        for ix in range(x0, x1):
            for iy in range(y0, y1):
                for iz in range(z0, z1):
                    bits |= np.float64(work[b, WK_V + d, ix, iy, iz]).view(np.int64)
    return bits == 0


# allocates nothing: compiled without reference counting (docs/performance.md, "Compile time")
@njit(cache=True, parallel=True, _nrt=False)
def update_stress(dt, geometry, ndim, alpha, arho, arhoe, arhoq, block_lo, block_dx, eos_kind, eos_params,
                  eos_table, rho0, model, params, shear, tensile_strength, work, counts, amounts, blocks,
                  damage_model, damage_params, surface_gravity, porosity, has_mass, stressed_blocks, store_strength,
                  record, scalar_stamp):
    """One strength step of ``dt`` (s) for every interior cell of the ``blocks`` listed (int64:
    a process's range, or one refinement level's); see the module docstring.
    ``porosity[M, NPOROSITY]``: the porosity rows (:func:`impactpipe.hydro.eos.porosity.pack_porosity`);
    a material whose alpha_0 is not above 1 is not porous (a scene without porosity passes
    rows of ones, as the sweeps get them).  A porous material k (alpha_0 > 1, distension alpha
    from the second-to-last of its scalars) is its matrix's strength carried by the bulk: its
    EOS pressure p_k = P_s / alpha and temperature at the matrix density alpha rho_k, its shear
    modulus from the porous bulk modulus G = G_0 + (G/K) rho_k c_s^2(alpha rho_k) h(alpha)^2
    (h the elastic wave-speed ratio, :func:`impactpipe.hydro.eos.porosity.wave_speed_ratio`; 1
    without ``chi``), its tensile limit
    -Y_T (1 - D) / alpha (the matrix's P_s >= -Y_T (1 - D)) and its yield strength
    Y = Y_s(alpha p_held, T, D) / alpha (the matrix's yield curve at the matrix pressure, spread
    over the bulk); the low-density cut compares the matrix density alpha rho_k with rho0_k.
    A porous Grady-Kipp material grows its damage with the porous moduli and the bulk stress
    (module docstring, step 2) and yields at (1 - D) Y_s(alpha p_m, T, 0) / alpha (von Mises,
    GEO) or Y_s(alpha p_b, T, D) / alpha (ROCK).
    ``rho0[M]``: the materials' reference densities (kg/m^3, :func:`impactpipe.hydro.eos.
    reference_densities`).  ``damage_model[M]``, ``damage_params[M, NDAMAGE]``: the tensile
    damage models and their Weibull parameters (:func:`impactpipe.hydro.strength.parameters.
    pack_damage`); where no material fractures by Grady-Kipp (every one fails instantly),
    ``arhoq`` has no flaw slots.
    ``surface_gravity``: the gravity g (m/s^2, three components) of the surface-layer pressure
    (step 4), or an empty array: none.
    ``has_mass[NB]`` (uint8): the blocks with mass (:func:`cell_velocity_and_stress`); the others are
    skipped (their cells hold no scalars to clear).
    ``stressed_blocks[NB]`` (uint8): written, whether block b's new mixture stress has a
    component other than 0 in some interior cell (1) or not (0), as
    :func:`cell_velocity_and_stress` records it for the first half kick.
    ``store_strength`` (bool): also write each cell's shear strength, the sqrt(J2) yield limit
    k = sum_k alpha_k Y_eq,k / sqrt(3) (Pa, fill-weighted like S; Y_eq the sqrt(3 J2) bound of
    step 4, evaluated then in every material, stressed or not) into ``work[:, WK_Y]`` and the
    off-diagonal velocity gradients L_di (1/s) into ``work[:, WK_L + gradient_slot(d, i)]``, for
    the face shear stress (:mod:`impactpipe.hydro.strength.face_shear`; the work arrays then have
    NWORK_FACE slots).

    A material without deviatoric stress (each component +0.0) in a cell at rest among its
    neighbours (every L_ij is 0), where the pressure is certain to be >= 0 without evaluating
    the EOS (:func:`impactpipe.hydro.eos.pressure_not_negative`: Tillotson at rho >= rho0 with
    e >= 0), skips the EOS when neither the surface-layer pressure nor ``store_strength`` needs
    it: it cannot fail in tension (p_k >= 0 >= -Y_T (1 - D)), a Grady-Kipp material's damage
    cannot grow (its largest principal stress is -p_k <= 0, so its tensile strain is 0), and
    the Jaumann update of S = +0.0 with L = 0 and a finite G is +0.0 whatever G, so the step
    leaves the state and the counters bit for bit as the evaluation would.  Early in an impact
    most of the target is such a cell.

    A whole block passes over its cells where the last sweep's ``record`` (uint8, (NB,), or
    empty: none; :data:`impactpipe.hydro.mesh.last_good.RECORD_CLEAR`) says its transported
    scalars are +0.0 and :func:`_rests_unstressed` finds every cell such a cell at rest (its
    velocities +0.0, ghosts included): the step would store the +0.0 each scalar holds and add
    +0.0 to the energy and the work.  ``scalar_stamp`` (int64, (NB,), or empty: none): raised
    by one for every block the step does not pass over, where it may write a scalar
    (:mod:`impactpipe.hydro.mesh.scalar_stamps`).

    ``work`` holds the velocities and fills with ghosts (:func:`cell_velocity_and_stress`);
    its first ``ns`` stress slots are written for the interior cells that hold material (a
    void cell's stay zero, as :func:`cell_velocity_and_stress` left them).  The scalars of
    void cells and absent materials are set to zero, stored only where they are not zero
    already (a porous material's distension excepted).  Counters accumulate per block.
    """
    nb, nmat, nx, ny, nz = alpha.shape
    nq = arhoq.shape[1] // nmat
    ns = 3 if ndim == 1 else (4 if ndim == 2 else 6)
    gx, gy, gz = ghost_widths(nx, ny, nz)
    cylindrical = geometry == CYLINDRICAL
    # without a porous material a void cell's scalars are cleared in one loop
    porous_scene = False
    for m in range(nmat):
        porous_scene = porous_scene or porosity[m, ALPHA0] > 1.0
    with_gravity = surface_gravity.shape[0] > 0
    recorded = record.shape[0] > 0 and not (porous_scene or with_gravity or store_strength)
    # with Grady-Kipp fracture no block holding material is clear (its flaws are not zero): its
    # blocks are tested for the scalars the step reads instead
    fracture_scene = False
    for m in range(nmat):
        fracture_scene = fracture_scene or damage_model[m] == GRADY_KIPP
    stamped = scalar_stamp.shape[0] > 0
    for i in prange(blocks.shape[0]):
        b = blocks[i]
        if has_mass[b] == 0:
            stressed_blocks[b] = 0
            continue
        if recorded and (record[b] == RECORD_CLEAR or fracture_scene) and _rests_unstressed(
                work, alpha, arho, arhoe, amounts, b, ndim, model, eos_kind, eos_params, rho0, tensile_strength) and (
                record[b] == RECORD_CLEAR or _strength_scalars_clear(arhoq, work, alpha, arho, b, ns, model)):
            stressed_blocks[b] = 0
            continue
        if stamped:
            scalar_stamp[b] += 1
        carries = False
        dxs = (block_dx[b, 0], block_dx[b, 1], block_dx[b, 2])
        for ix in range(gx, nx - gx):
            for iy in range(gy, ny - gy):
                for iz in range(gz, nz - gz):
                    if work[b, WK_PHI, ix, iy, iz] <= 0.0:
                        # void: its stress in work is zero already (cell_velocity_and_stress)
                        if not porous_scene:
                            _clear_scalars(arhoq, b, 0, nmat * nq, ix, iy, iz)
                        else:
                            for k in range(nmat):
                                _clear_strength_scalars(arhoq, b, k * nq, nq, porosity[k, ALPHA0] > 1.0, ix, iy, iz)
                        continue
                    s0 = s1 = s2 = s3 = s4 = s5 = 0.0
                    strength = 0.0
                    # velocity gradient L[i][j] = d v_i / d x_j
                    lxx = lxy = lxz = lyx = lyy = lyz = lzx = lzy = lzz = 0.0
                    lxx = _derivative(work, b, 0, ix, iy, iz, 0, dxs[0])
                    lyx = _derivative(work, b, 1, ix, iy, iz, 0, dxs[0])
                    lzx = _derivative(work, b, 2, ix, iy, iz, 0, dxs[0])
                    if ndim > 1:
                        lxy = _derivative(work, b, 0, ix, iy, iz, 1, dxs[1])
                        lyy = _derivative(work, b, 1, ix, iy, iz, 1, dxs[1])
                        lzy = _derivative(work, b, 2, ix, iy, iz, 1, dxs[1])
                    if ndim > 2:
                        lxz = _derivative(work, b, 0, ix, iy, iz, 2, dxs[2])
                        lyz = _derivative(work, b, 1, ix, iy, iz, 2, dxs[2])
                        lzz = _derivative(work, b, 2, ix, iy, iz, 2, dxs[2])
                    vol = dxs[0] * (dxs[1] if ndim > 1 else 1.0) * (dxs[2] if ndim > 2 else 1.0)
                    if cylindrical:
                        r = block_lo[b, 0] + (ix - gx + 0.5) * dxs[0]
                        lzz = work[b, WK_V, ix, iy, iz] / r
                        # no theta velocity, no theta derivatives
                        lzx = lzy = lxz = lyz = 0.0
                        vol *= 2.0 * 3.141592653589793 * r
                    # a cell at rest among its neighbours (every L_ij is 0) whose unstressed materials
                    # may skip their EOS (no surface-layer pressure or stored strength needs it)
                    at_rest = (not store_strength and not with_gravity and lxx == 0.0 and lxy == 0.0 and lxz == 0.0
                               and lyx == 0.0 and lyy == 0.0 and lyz == 0.0 and lzx == 0.0 and lzy == 0.0
                               and lzz == 0.0)
                    for k in range(nmat):
                        if model[k] == NONE:
                            continue
                        base = k * nq
                        a = alpha[b, k, ix, iy, iz]
                        ar = arho[b, k, ix, iy, iz]
                        if not (a > ALPHA_MIN and ar > 0.0):
                            _clear_strength_scalars(arhoq, b, base, nq, porosity[k, ALPHA0] > 1.0, ix, iy, iz)
                            continue
                        inv = 1.0 / ar
                        sxx = arhoq[b, base, ix, iy, iz] * inv
                        syy = arhoq[b, base + 1, ix, iy, iz] * inv
                        szz = arhoq[b, base + 2, ix, iy, iz] * inv
                        sxy = arhoq[b, base + 3, ix, iy, iz] * inv if ns > 3 else 0.0
                        sxz = arhoq[b, base + 4, ix, iy, iz] * inv if ns > 4 else 0.0
                        syz = arhoq[b, base + 5, ix, iy, iz] * inv if ns > 5 else 0.0
                        eps_p = arhoq[b, base + ns, ix, iy, iz] * inv
                        dmg = arhoq[b, base + nq - 1, ix, iy, iz] * inv
                        rk = ar / a
                        ek = arhoe[b, k, ix, iy, iz] * inv
                        dist = 1.0
                        stiffness = 1.0
                        # Y_T / dist, the division left out where dist is 1.0 (the same number)
                        y_t = tensile_strength[k]
                        if porosity[k, ALPHA0] > 1.0:
                            dist = arhoq[b, base + nq - 2, ix, iy, iz] * inv
                            h = wave_speed_ratio(porosity[k], dist)
                            stiffness = h * h
                            y_t = tensile_strength[k] / dist
                        gradual = damage_model[k] == GRADY_KIPP
                        if (at_rest and y_t >= 0.0 and _positive_zeros(sxx, syy, szz, sxy, sxz, syz)
                                and pressure_not_negative(eos_kind[k], eos_params[k], dist * rk, ek)):
                            # at rest and unstressed, where the pressure is certain to be >= 0: the
                            # EOS, which G, the tensile-failure test, the Grady-Kipp damage and the
                            # Jaumann update would take, is not evaluated (update_stress docstring);
                            # S and D stay as they are, as those leave them
                            pk = 0.0
                            g = 0.0
                            p_matrix = pk
                            sxx0, syy0, szz0, sxy0, sxz0, syz0 = sxx, syy, szz, sxy, sxz, syz
                        else:
                            pk, c2b, flag = pressure_sound_speed_in_line(eos_kind[k], eos_params[k], eos_table,
                                                                         dist * rk, ek)
                            pk /= dist
                            g = shear[k, 0] + shear[k, 1] * rk * max(c2b, 0.0) * stiffness
                            p_matrix = pk
                            if gradual:
                                # Grady-Kipp: damage grows from the active flaws; S and G soften with it.
                                # A porous material: the matrix's tension cap spread over the bulk, and the
                                # porous moduli (bulk rho c_s^2 h^2, the porous G, a given E times h^2 / alpha)
                                if tensile_strength[k] > 0.0:
                                    p_matrix = max(pk, -y_t)
                                d_new, flaw_limited = _grady_kipp_damage(
                                    dmg, damaged_pressure(p_matrix, dmg), sxx, syy, szz, sxy, sxz, syz, rk,
                                    c2b * stiffness, g, arhoq, b, base + ns + 1, ix, iy, iz, inv,
                                    damage_params[k, WEIBULL_M], damage_params[k, YOUNG] * stiffness / dist,
                                    damage_params[k, ACTIVE_LIMIT], damage_params[k, NODE0:], dt)
                                if flaw_limited:
                                    counts[b, CNT_FLAW_LIMITED] += 1
                                if d_new > dmg:
                                    if model[k] != ROCK:
                                        keep = (1.0 - d_new) / (1.0 - dmg)
                                        sxx, syy, szz, sxy, sxz, syz = (sxx * keep, syy * keep, szz * keep, sxy * keep,
                                                                        sxz * keep, syz * keep)
                                    if d_new >= 1.0:
                                        counts[b, CNT_FRACTURED] += 1
                                    dmg = d_new
                                if model[k] != ROCK:
                                    g *= 1.0 - dmg
                            elif pk < -y_t * (1.0 - dmg):
                                # tensile failure (the sweeps then hold its tension at -Y_T (1 - D))
                                if dmg < 1.0:
                                    counts[b, CNT_TENSILE_FAILURE] += 1
                                    dmg = 1.0
                            sxx0, syy0, szz0, sxy0, sxz0, syz0 = sxx, syy, szz, sxy, sxz, syz
                            sxx, syy, szz, sxy, sxz, syz = jaumann_update(
                                sxx, syy, szz, sxy, sxz, syz, lxx, lxy, lxz, lyx, lyy, lyz, lzx, lzy, lzz, dt, g)
                            if ns < 6:
                                sxz = syz = 0.0
                            if ns < 4:
                                sxy = 0.0
                        # a material without deviatoric stress does not yield whatever its yield
                        # strength (>= 0): its temperature and yield strength are not evaluated
                        stressed = (sxx != 0.0 or syy != 0.0 or szz != 0.0 or sxy != 0.0 or sxz != 0.0
                                    or syz != 0.0)
                        # the mean stress the material bears: no more tension than it still holds,
                        # as in the sweeps, which open void instead of stretching it further
                        y = 0.0
                        if gradual and model[k] != ROCK:
                            p_held = damaged_pressure(p_matrix, dmg)
                            if stressed or store_strength:
                                tk = temperature_in_line(eos_kind[k], eos_params[k], eos_table, dist * rk, ek)
                                mu = _friction(params[k], dist * p_matrix, dist * rk,
                                               lxx, lxy, lxz, lyx, lyy, lyz, lzx, lzy, lzz)
                                y = (1.0 - dmg) * equivalent_yield_stress(
                                    model[k], yield_strength_friction(model[k], params[k], dist * p_matrix, tk, 0.0,
                                                                      mu)) / dist
                        else:
                            p_held = damaged_pressure(p_matrix, dmg) if gradual else max(pk, -y_t * (1.0 - dmg))
                            if with_gravity and work[b, WK_PHI, ix, iy, iz] < 1.0:
                                layer = _surface_layer_pressure(rk, work[b, WK_PHI, ix, iy, iz], surface_gravity, dxs)
                                if layer > p_held:
                                    p_held = layer
                                    counts[b, CNT_SURFACE_LAYER] += 1
                            if stressed or store_strength:
                                tk = temperature_in_line(eos_kind[k], eos_params[k], eos_table, dist * rk, ek)
                                mu = _friction(params[k], dist * p_held, dist * rk,
                                               lxx, lxy, lxz, lyx, lyy, lyz, lzx, lzy, lzz)
                                y = equivalent_yield_stress(model[k], yield_strength_friction(
                                    model[k], params[k], dist * p_held, tk, dmg, mu)) / dist
                        if dist * rk < STRENGTH_MIN_DENSITY_FRACTION * rho0[k]:
                            y = 0.0
                            counts[b, CNT_LOW_DENSITY] += 1
                        # without deviatoric stress y is 0 (or its cut to 0), and the return would
                        # find sqrt(3 J2) = 0 <= y and leave S as it is
                        returned = False
                        dep = 0.0
                        if stressed or store_strength:
                            sxx, syy, szz, sxy, sxz, syz, dep, returned = radial_return(sxx, syy, szz, sxy, sxz, syz,
                                                                                        y, g)
                        if returned:
                            counts[b, CNT_YIELD] += 1
                            eps_p += dep
                            if model[k] == ROCK and dmg < 1.0:
                                dmg = min(1.0, dmg + shear_damage_increment(dep, p_held, params[k, P_BD],
                                                                            params[k, P_BP]))
                        power = 0.5 * ((sxx + sxx0) * lxx + (syy + syy0) * lyy + (szz + szz0) * lzz
                                       + (sxy + sxy0) * (lxy + lyx) + (sxz + sxz0) * (lxz + lzx)
                                       + (syz + syz0) * (lyz + lzy))
                        work_done = dt * a * power
                        arhoe[b, k, ix, iy, iz] += work_done
                        amounts[b, AMT_PLASTIC_WORK] += work_done * vol
                        arhoq[b, base, ix, iy, iz] = ar * sxx
                        arhoq[b, base + 1, ix, iy, iz] = ar * syy
                        arhoq[b, base + 2, ix, iy, iz] = ar * szz
                        if ns > 3:
                            arhoq[b, base + 3, ix, iy, iz] = ar * sxy
                        if ns > 4:
                            arhoq[b, base + 4, ix, iy, iz] = ar * sxz
                            arhoq[b, base + 5, ix, iy, iz] = ar * syz
                        arhoq[b, base + ns, ix, iy, iz] = ar * eps_p
                        arhoq[b, base + nq - 1, ix, iy, iz] = ar * dmg
                        s0 += a * sxx
                        s1 += a * syy
                        s2 += a * szz
                        s3 += a * sxy
                        s4 += a * sxz
                        s5 += a * syz
                        strength += a * y
                    _store_stress(work, b, ix, iy, iz, ns, s0, s1, s2, s3, s4, s5)
                    if store_strength:
                        work[b, WK_Y, ix, iy, iz] = strength / SQRT3
                        work[b, WK_L + gradient_slot(0, 1), ix, iy, iz] = lxy
                        work[b, WK_L + gradient_slot(1, 0), ix, iy, iz] = lyx
                        work[b, WK_L + gradient_slot(0, 2), ix, iy, iz] = lxz
                        work[b, WK_L + gradient_slot(2, 0), ix, iy, iz] = lzx
                        work[b, WK_L + gradient_slot(1, 2), ix, iy, iz] = lyz
                        work[b, WK_L + gradient_slot(2, 1), ix, iy, iz] = lzy
                    carries = carries or _nonzero(s0, s1, s2, s3, s4, s5)
        stressed_blocks[b] = 1 if carries else 0
