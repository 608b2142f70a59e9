"""Compiled collision resolution for REBOUND: merge, conditional merge and bounce.

REBOUND calls a collision resolver as ``int resolve(struct reb_simulation* r,
struct reb_collision c)`` for every pair its collision search reports (each pair twice
for the tree searches, once per direction) and removes particle ``p1`` if the return
value has bit 0 set and ``p2`` if it has bit 1 set (0 keep both, 1 remove p1, 2 remove
p2, 3 remove both).

The resolver here is a numba ``cfunc`` that reads and writes the particles in place
through the simulation pointer.  ``struct reb_collision`` (p1, p2, ghost-box vec6d, ri:
72 bytes) is passed *by value*; a numba cfunc cannot declare a struct argument, so a
three-instruction LLVM trampoline, compiled with llvmlite for the host's C calling
convention (x86-64 System V: the struct is copied onto the stack, ``byval``; AArch64 and
Windows x64: a pointer to a caller copy), forwards ``(sim, &collision, context)`` to the
cfunc.  The context is an int64 array holding the physical parameters (through the
address of a float64 array), the spin array, the merge-event buffer and counters.

Particle identity: every REBOUND particle carries ``slot + 1`` in its ``ap`` pointer field
(slot = row of the hand-off particle in the initial arrays), set by the driver when a
simulation is built or loaded (the Simulationarchive does not store ``ap``).

Physics (SI units; particle 1 and 2 with masses m1, m2, radii r1, r2, positions x1, x2,
velocities v1, v2, spin angular momenta S1, S2 in kg m^2/s; M = m1 + m2,
mu = m1 m2 / M, d = |x2 - x1|, n = (x2 - x1) / d, v = v2 - v1, v_n = (v . n) n,
v_t = v - v_n):

Every model resolves only pairs in approaching contact (``contact_geometry``): a reported
pair that moves apart (REBOUND's line search reports every pair whose path came within
contact during the step, e.g. the overlapping neighbours of a hand-off) is left alone and
counted.  Merging such pairs would glue an expanding cloud into one body within a few steps
(runaway merging, docs/nbody.md "Unbound hand-offs").

* merge: one particle at the centre of mass with mass M, velocity
  (m1 v1 + m2 v2) / M, radius (r1^3 + r2^3)^(1/3) (summed volume) and spin
  S = S1 + S2 + mu (x1 - x2) x (v1 - v2), the orbital angular momentum of the pair about
  its centre of mass, so linear and total angular momentum are conserved exactly.  The
  more massive particle (the lower slot on a tie) survives and keeps its identity, as in
  pkdgrav.  Every merger is written to the event buffer as (survivor slot, absorbed
  slot, time).
* bounce, v' = -eps_n v_n + eps_t v_t, applied as equal and opposite impulses
  J = mu (v' - v) on particle 2 and -J on particle 1 (h = length of the last step, read
  from ``sim->dt_last_done``; s = time since the pair's straight relative path
  r(t') = r - v (t - t') entered contact, the larger root of |r - v s| = r1 + r2;
  a = a2 - a1 the relative acceleration of the step's force evaluation, REBOUND's
  ``ax, ay, az``):

  - contact entered during the step (0 <= s <= h; REBOUND's line search reports such a
    pair even if it has passed through the contact and separates at the step end): the
    pair is bounced at its contact point, normal n_c = (r - v s) / (r1 + r2), with its
    velocity there, u = v - a s (the leapfrog's kick a h acts on the whole step, but only
    a (h - s) of it came before the contact), if it approached there (u . n_c < 0), and
    both particles are moved on from the contact with their new velocities,
    x_k -> x_k + s dv_k.  The new relative velocity is u' + a s, u' the bounced u.
    Reflecting v itself, as this resolver first did, reflected the pull a s that gravity
    gives after the contact as well: an elastic cloud gained 5 % of |E_0| in 12 t_dyn,
    first order in the step (docs/nbody.md).  No position change beyond the drift;
    momentum and (eps_t = 1) angular momentum exact; with eps_t < 1 the pair's orbital
    angular momentum changes by r_c x J (r_c = r - v s) and the spins take the opposite,
    shared r1 : r2 as the contact torques are (spin does not feed back into the contact
    velocity).  A pair that did not approach at the contact by u but approaches now by v
    (|v . n_c| < |a . n_c| s: slower than what gravity adds in a step, a resting contact)
    is bounced with v the same way.  If the pull after the contact would turn the bounced
    pair back towards the contact by the step's end, it ends the step at rest in contact
    along n_c (its normal relative velocity 0, its distance r1 + r2), so the mirrored
    report sees it separating;
  - overlap older than the step (s > h: a pair pushed into overlap by another pair's
    resolution, a resting contact, an overlap present at the start) and approaching
    (v . n < 0, n = r / d): bounced about n and pushed apart along n, centre of mass
    fixed (``push_apart``).  The push's potential energy, the pair's own
    G m1 m2 (1/d - 1/d') plus that in the field of all the other mass (``push_cost``), is
    paid from the incoming normal kinetic energy; the tangential relative velocity is
    scaled by d / d', which keeps the pair's orbital angular momentum, and the kinetic
    energy that frees goes into the outgoing normal motion.  An overlap that arose
    during the run is pushed to contact, d' = r1 + r2, whatever it costs, so overlaps
    never accumulate (resting contacts would otherwise sink towards the point-mass
    singularity); what its kinetic energy did not pay is accumulated in
    ``params[PARAM_PUSH_ENERGY]``.  A pair that has overlapped since t = 0 (the hand-off's,
    registered with ``set_handoff_overlaps``) is pushed only as far as its kinetic energy
    pays, so separating it adds no energy, but at least back to its distance at t = 0;
    it is no longer treated so once it has reached contact;
  - otherwise (separating, or no contact in the step) the pair is left alone, so the
    mirrored report of a pair just bounced changes nothing.

  ``params[PARAM_KINETIC]`` accumulates the exact change of the translational kinetic energy
  made by the resolver (bounces, pushes and mergers, J), the diagnostic
  ``collision_kinetic_energy_change``.
* conditional merge: merge if |v| < v_esc = sqrt(2 G M / (r1 + r2)), else bounce.
"""

from __future__ import annotations

import ctypes
import math

import llvmlite.binding as llvm
import numpy as np
import rebound
from numba import carray, cfunc, njit, types
from numba.extending import intrinsic

COLLISION_MODELS = ("merge", "conditional_merge", "bounce")
MODEL_CODES = {"merge": 0, "conditional_merge": 1, "bounce": 2}

# reb_particle layout in 8-byte words (checked against rebound's ctypes definition below).
P_STRIDE = 14
P_X, P_Y, P_Z, P_VX, P_VY, P_VZ = 0, 1, 2, 3, 4, 5
P_AX, P_AY, P_AZ = 6, 7, 8
P_M, P_R, P_AP = 9, 10, 12
# reb_simulation layout in 8-byte words: t, N, particles.
S_T = rebound.Simulation.t.offset // 8
S_N = rebound.Simulation.N.offset // 8
S_PARTICLES = rebound.Simulation._particles.offset // 8
S_DT_LAST = rebound.Simulation.dt_last_done.offset // 8
S_G = rebound.Simulation.G.offset // 8
S_WORDS = S_PARTICLES + 1

# Context (int64 array) layout.
CTX_PARAMS = 0        # address of float64 params (PARAM_* below)
CTX_SPIN = 1          # address of float64 spin (n_slots, 3), kg m^2/s
CTX_EVENTS = 2        # address of int64 merge events (capacity, 2): survivor, absorbed slot
CTX_EVENT_TIME = 3    # address of float64 merge event times (capacity,), s
CTX_CAPACITY = 4      # capacity of the event buffer
CTX_N_EVENTS = 5      # merge events written since the last drain
CTX_MODEL = 6         # MODEL_CODES value
CTX_N_MERGE = 7       # cumulative mergers
CTX_N_BOUNCE = 8      # cumulative bounces
CTX_N_SEPARATING = 9  # cumulative reports of pairs left alone (separating or no contact in the step)
CTX_OVERFLOW = 10     # 1 if a merger found the event buffer full (it was not performed)
CTX_N_OVERLAP = 11    # cumulative bounces of pairs overlapping since before the step (pushed apart)
CTX_PARTICLE_STEPS = 12  # cumulative sum over steps of the particles the step integrated (step counter)
CTX_HANDOFF_KEYS = 13    # address of int64 sorted keys s1 * n_slots + s2 (s1 < s2) of the pairs overlapping at t = 0
CTX_HANDOFF_OPEN = 14    # address of int64 flags: 1 while that pair has not yet been separated to contact
CTX_N_HANDOFF = 15       # number of those keys
CTX_HANDOFF_FLOOR = 16   # address of float64 distances (m) of those pairs at t = 0
CTX_LEN = 17

# Params (float64 array) layout.
PARAM_G = 0              # m^3 kg^-1 s^-2
PARAM_EPS_N = 1
PARAM_EPS_T = 2
PARAM_KINETIC = 3        # cumulative change of the translational kinetic energy made by the resolver (J)
PARAM_PUSH_ENERGY = 4    # cumulative potential energy pushes added beyond what the pushed pairs paid (J)
PARAM_LEN = 5

PUSH_BISECTIONS = 60     # halvings of the push length in a limited push (to 2^-60 of it)
EXACT_PUSH_FRACTION = 0.01  # limited pushes longer than this x (r1 + r2) price the other mass exactly
EXACT_PUSH_ITERATIONS = 3   # chord updates of that price

PARTICLE_DTYPE = np.dtype(
    {
        "names": ["x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az", "m", "r", "name", "ap", "sim"],
        "formats": ["f8"] * 11 + ["u8", "i8", "u8"],
        "offsets": [8 * k for k in range(14)],
        "itemsize": 8 * P_STRIDE,
    }
)


def _check_layout() -> None:
    """Fail at import if the installed REBOUND's structures differ from the constants above."""
    expected = {"x": P_X, "y": P_Y, "z": P_Z, "vx": P_VX, "vy": P_VY, "vz": P_VZ,
                "ax": P_AX, "ay": P_AY, "az": P_AZ, "m": P_M, "r": P_R, "ap": P_AP}
    for name, word in expected.items():
        if getattr(rebound.Particle, name).offset != 8 * word:
            raise ImportError(f"unsupported REBOUND particle layout (field {name}); rebound {rebound.__version__}")
    if ctypes.sizeof(rebound.Particle) != 8 * P_STRIDE:
        raise ImportError(f"unsupported REBOUND particle size; rebound {rebound.__version__}")
    if rebound.Simulation.N.size != 8:
        raise ImportError(f"unsupported REBOUND simulation layout (N is not 8 bytes); rebound {rebound.__version__}")
    c = rebound.simulation.CollisionS
    if (c.p1.offset, c.p2.offset, ctypes.sizeof(c)) != (0, 8, 72):
        raise ImportError(f"unsupported REBOUND reb_collision layout; rebound {rebound.__version__}")


_check_layout()


@intrinsic
def _void_as_i64(typingctx, ptr):
    sig = types.CPointer(types.int64)(ptr)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(signature.return_type))

    return sig, codegen


@intrinsic
def _void_as_f64(typingctx, ptr):
    sig = types.CPointer(types.float64)(ptr)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(signature.return_type))

    return sig, codegen


@intrinsic
def _addr_as_i64(typingctx, addr):
    sig = types.CPointer(types.int64)(addr)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_value_type(signature.return_type))

    return sig, codegen


@intrinsic
def _addr_as_f64(typingctx, addr):
    sig = types.CPointer(types.float64)(addr)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], context.get_value_type(signature.return_type))

    return sig, codegen


@njit(cache=True)
def _spin_kick(spin, s1, s2, r1, r2, lx, ly, lz):
    """Add the angular momentum (lx, ly, lz) (kg m^2/s) to the spins of slots s1, s2, shared r1 : r2."""
    w1 = r1 / (r1 + r2)
    w2 = 1.0 - w1
    spin[3 * s1] += w1 * lx
    spin[3 * s1 + 1] += w1 * ly
    spin[3 * s1 + 2] += w1 * lz
    spin[3 * s2] += w2 * lx
    spin[3 * s2 + 1] += w2 * ly
    spin[3 * s2 + 2] += w2 * lz


@njit(cache=True)
def merge_pair(pf, pw, i, j, spin, params, t, ctx, events, event_time):
    """Merge particles i and j (indices into the particle words) into the more massive one.

    Writes the merged state (centre of mass, summed mass and volume, spin including the
    pair's orbital angular momentum) into the survivor and returns the REBOUND code that
    removes the other: 1 if i is absorbed, 2 if j is.  Records (survivor slot, absorbed
    slot, t) in the event buffer.  Returns 0 without merging if the buffer is full.
    """
    n_ev = ctx[CTX_N_EVENTS]
    if n_ev >= ctx[CTX_CAPACITY]:
        ctx[CTX_OVERFLOW] = 1
        return 0
    b1 = i * P_STRIDE
    b2 = j * P_STRIDE
    s1 = pw[b1 + P_AP] - 1
    s2 = pw[b2 + P_AP] - 1
    m1 = pf[b1 + P_M]
    m2 = pf[b2 + P_M]
    keep_first = m1 > m2 or (m1 == m2 and s1 < s2)
    bs = b1 if keep_first else b2
    ss = s1 if keep_first else s2
    sa = s2 if keep_first else s1
    mt = m1 + m2
    mu = m1 * m2 / mt
    rx = pf[b1 + P_X] - pf[b2 + P_X]
    ry = pf[b1 + P_Y] - pf[b2 + P_Y]
    rz = pf[b1 + P_Z] - pf[b2 + P_Z]
    ux = pf[b1 + P_VX] - pf[b2 + P_VX]
    uy = pf[b1 + P_VY] - pf[b2 + P_VY]
    uz = pf[b1 + P_VZ] - pf[b2 + P_VZ]
    params[PARAM_KINETIC] -= 0.5 * mu * (ux * ux + uy * uy + uz * uz)
    lx = mu * (ry * uz - rz * uy)
    ly = mu * (rz * ux - rx * uz)
    lz = mu * (rx * uy - ry * ux)
    for k in range(6):
        pf[bs + k] = (m1 * pf[b1 + k] + m2 * pf[b2 + k]) / mt
    r1 = pf[b1 + P_R]
    r2 = pf[b2 + P_R]
    pf[bs + P_R] = (r1 * r1 * r1 + r2 * r2 * r2) ** (1.0 / 3.0)
    pf[bs + P_M] = mt
    spin[3 * ss] += spin[3 * sa] + lx
    spin[3 * ss + 1] += spin[3 * sa + 1] + ly
    spin[3 * ss + 2] += spin[3 * sa + 2] + lz
    spin[3 * sa] = 0.0
    spin[3 * sa + 1] = 0.0
    spin[3 * sa + 2] = 0.0
    events[2 * n_ev] = ss
    events[2 * n_ev + 1] = sa
    event_time[n_ev] = t
    ctx[CTX_N_EVENTS] = n_ev + 1
    ctx[CTX_N_MERGE] += 1
    return 2 if keep_first else 1


@njit(cache=True)
def push_cost(gmm, mu, c, a_sep, delta):
    """Potential energy (J) of pushing a pair at distance c (m) apart by delta (m) along its
    line of centres, centre of mass fixed:

        U(delta) = G m1 m2 (1/c - 1/(c + delta)) - mu a_sep delta

    with gmm = G m1 m2 (J m), mu the reduced mass (kg) and a_sep (m/s^2) the pair's relative
    acceleration along the outward normal by all the other mass (first order in delta).
    """
    return gmm * delta / (c * (c + delta)) - mu * a_sep * delta


@njit(cache=True)
def push_apart(gmm, mu, c, contact, floor, bn, tt, a_sep, eps_n, limited):
    """Push of an overlap older than the step: (shift (m), outgoing normal speed (m/s), factor f
    on the tangential relative velocity, potential energy added beyond what was paid (J)).

    The pair (distance c < contact, incoming normal speed bn < 0, tangential speed^2 tt after
    the tangential restitution, m^2/s^2) is pushed apart by shift along n.  The push's
    potential energy U = ``push_cost`` is paid from the incoming normal kinetic energy
    K_in = mu bn^2 / 2; eps_n restitutes what is left; f = c / (c + shift) keeps the pair's
    orbital angular momentum and the tangential kinetic energy this frees, mu tt (1 - f^2) / 2,
    goes into the outgoing normal motion:

        mu un'^2 / 2 = eps_n^2 max(K_in - U, 0) + mu tt (1 - f^2) / 2

    Not limited (an overlap that arose during the run, e.g. a resting contact; floor = contact):
    shift = contact - c.  Limited (a pair overlapping since t = 0 at distance floor < contact):
    to contact if K_in pays it, else the largest shift K_in pays (bisection of U(shift) = K_in),
    but at least back to floor: such a pair never ends a step deeper than it started.  What
    K_in does not pay, max(U - K_in, 0), is returned as the energy the push added.
    """
    full = contact - c
    k_in = 0.5 * mu * bn * bn
    cost = push_cost(gmm, mu, c, a_sep, full)
    shift = full
    if cost > k_in and limited:
        lo = 0.0
        hi = full
        for _ in range(PUSH_BISECTIONS):
            mid = 0.5 * (lo + hi)
            if push_cost(gmm, mu, c, a_sep, mid) > k_in:
                hi = mid
            else:
                lo = mid
        shift = max(lo, floor - c)
        cost = push_cost(gmm, mu, c, a_sep, shift)
    f = c / (c + shift)
    k_out = eps_n * eps_n * max(k_in - cost, 0.0) + 0.5 * mu * tt * (1.0 - f * f)
    return shift, math.sqrt(2.0 * k_out / mu), f, max(cost - k_in, 0.0)


@njit(cache=True)
def separating_acceleration(pf, b1, b2, gm, h, nx, ny, nz):
    """Relative acceleration (m/s^2) along n of particle words b2 and b1 by all the other mass.

    REBOUND's accelerations a_k (``ax, ay, az``) of the step are evaluated at the mid-step
    positions, x_k - v_k h / 2 in the drift-kick-drift leapfrog; the pair's own attraction
    there, -gm r_m / |r_m|^3 with r_m = r - v h / 2 and gm = G (m1 + m2), is taken off:

        a_sep = (a_2 - a_1 + gm r_m / |r_m|^3) . n
    """
    rx = pf[b2 + P_X] - pf[b1 + P_X] - 0.5 * h * (pf[b2 + P_VX] - pf[b1 + P_VX])
    ry = pf[b2 + P_Y] - pf[b1 + P_Y] - 0.5 * h * (pf[b2 + P_VY] - pf[b1 + P_VY])
    rz = pf[b2 + P_Z] - pf[b1 + P_Z] - 0.5 * h * (pf[b2 + P_VZ] - pf[b1 + P_VZ])
    d2 = rx * rx + ry * ry + rz * rz
    own = gm / (d2 * math.sqrt(d2)) if d2 > 0.0 else 0.0
    return ((pf[b2 + P_AX] - pf[b1 + P_AX] + own * rx) * nx + (pf[b2 + P_AY] - pf[b1 + P_AY] + own * ry) * ny
            + (pf[b2 + P_AZ] - pf[b1 + P_AZ] + own * rz) * nz)


@njit(cache=True)
def _moved_potential(pf, b, skip, g, dx, dy, dz):
    """Change (J) of the potential energy of particle word b with every particle but words b and
    skip when b moves by (dx, dy, dz) (m): -G m_b sum_k m_k (1/|x_b + d - x_k| - 1/|x_b - x_k|)."""
    u = 0.0
    for bk in range(0, pf.shape[0], P_STRIDE):
        if bk == b or bk == skip:
            continue
        rx = pf[b + P_X] - pf[bk + P_X]
        ry = pf[b + P_Y] - pf[bk + P_Y]
        rz = pf[b + P_Z] - pf[bk + P_Z]
        before = 1.0 / math.sqrt(rx * rx + ry * ry + rz * rz)
        rx += dx
        ry += dy
        rz += dz
        u -= pf[bk + P_M] * (1.0 / math.sqrt(rx * rx + ry * ry + rz * rz) - before)
    return g * pf[b + P_M] * u


@njit(cache=True)
def push_pair(pf, b1, b2, g, g_sim, h, c, contact, floor, nx, ny, nz, bn, tt, eps_n, limited):
    """``push_apart`` of particle words b1, b2 (distance c along n), with the other mass priced.

    The other mass enters through a_sep: first ``separating_acceleration`` (first order in the
    shift).  A limited push longer than EXACT_PUSH_FRACTION (r1 + r2) prices it exactly: the
    pair's potential energy change with every other particle, dU (direct sum, O(N)), for the
    shift just found gives the chord a_sep = -dU / (mu shift), and the push is solved again
    (EXACT_PUSH_ITERATIONS times).  Without it the first-order price underestimated what
    separating the deep overlaps of a cold cloud cost by 5e-4 of its energy (docs/nbody.md).
    ``g`` prices the energy (J), ``g_sim`` is the G of REBOUND's accelerations.
    """
    m1 = pf[b1 + P_M]
    m2 = pf[b2 + P_M]
    mt = m1 + m2
    mu = m1 * m2 / mt
    a_sep = separating_acceleration(pf, b1, b2, g_sim * mt, h, nx, ny, nz)
    out = push_apart(g * m1 * m2, mu, c, contact, floor, bn, tt, a_sep, eps_n, limited)
    for _ in range(EXACT_PUSH_ITERATIONS if limited else 0):
        shift = out[0]
        if shift <= EXACT_PUSH_FRACTION * contact:
            break
        du = (_moved_potential(pf, b1, b2, g, -m2 / mt * shift * nx, -m2 / mt * shift * ny, -m2 / mt * shift * nz)
              + _moved_potential(pf, b2, b1, g, m1 / mt * shift * nx, m1 / mt * shift * ny, m1 / mt * shift * nz))
        out = push_apart(g * m1 * m2, mu, c, contact, floor, bn, tt, -du / (mu * shift), eps_n, True)
    return out


@njit(cache=True)
def _handoff_pair(ctx, s1, s2):
    """Index of slots (s1, s2) among the still open pairs overlapping at t = 0, or -1."""
    n = ctx[CTX_N_HANDOFF]
    if n == 0:
        return -1
    key = min(s1, s2) * ctx[CTX_CAPACITY] + max(s1, s2)
    keys = carray(_addr_as_i64(ctx[CTX_HANDOFF_KEYS]), n)
    k = np.searchsorted(keys, key)
    if k < n and keys[k] == key and carray(_addr_as_i64(ctx[CTX_HANDOFF_OPEN]), n)[k] == 1:
        return k
    return -1


NO_CONTACT = -2.0   # contact_geometry: the pair is left alone
OLD_OVERLAP = -1.0  # contact_geometry: overlapping since before the step


@njit(cache=True)
def contact_geometry(pf, i, j, h):
    """Where and when particles i and j touched in the last step of length h (s), and how fast.

    With r = x_j - x_i, v = v_j - v_i and a = a_j - a_i (the relative acceleration of the
    step's force evaluation, REBOUND's ``ax, ay, az``), s is the time since the straight
    relative path r - v s' entered contact, the larger root of |r - v s| = r_i + r_j, and
    u = v - a s the relative velocity at that moment (the part a s of the step's kick that
    gravity gave after the contact is taken off).  Returns (s, c, nx, ny, nz, bx, by, bz):

    - s in [0, h], c = r_i + r_j, n the unit vector of r - v s, b = u: the pair entered
      contact during the step and approached there (u . n < 0);
    - the same s, c, n with b = v: it entered contact during the step, did not approach
      there by u, but approaches now (v . n < 0), i.e. |v . n| < |a . n| s: a contact slower
      than what gravity adds within one step (a resting contact), bounced with its present
      velocity;
    - s = OLD_OVERLAP, c = |r|, n = r / |r|, b = v: the pair overlapped before the step and
      approaches now;
    - s = NO_CONTACT otherwise (separating, or no contact within the step).
    """
    b1 = i * P_STRIDE
    b2 = j * P_STRIDE
    dx = pf[b2 + P_X] - pf[b1 + P_X]
    dy = pf[b2 + P_Y] - pf[b1 + P_Y]
    dz = pf[b2 + P_Z] - pf[b1 + P_Z]
    vx = pf[b2 + P_VX] - pf[b1 + P_VX]
    vy = pf[b2 + P_VY] - pf[b1 + P_VY]
    vz = pf[b2 + P_VZ] - pf[b1 + P_VZ]
    contact = pf[b1 + P_R] + pf[b2 + P_R]
    d2 = dx * dx + dy * dy + dz * dz
    uu = vx * vx + vy * vy + vz * vz
    ru = dx * vx + dy * vy + dz * vz
    overlap = d2 < contact * contact
    s = NO_CONTACT
    if uu > 0.0 and (overlap or ru > 0.0):
        disc = ru * ru - uu * (d2 - contact * contact)
        if disc >= 0.0:
            s_in = (ru + math.sqrt(disc)) / uu
            if s_in <= h:
                s = max(s_in, 0.0)
    if s >= 0.0:
        cx = dx - vx * s
        cy = dy - vy * s
        cz = dz - vz * s
    elif overlap:
        s = OLD_OVERLAP
        cx = dx
        cy = dy
        cz = dz
    else:
        return NO_CONTACT, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    c = math.sqrt(cx * cx + cy * cy + cz * cz)
    if not c > 0.0:
        return NO_CONTACT, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    nx = cx / c
    ny = cy / c
    nz = cz / c
    if s >= 0.0:
        ux = vx - s * (pf[b2 + P_AX] - pf[b1 + P_AX])
        uy = vy - s * (pf[b2 + P_AY] - pf[b1 + P_AY])
        uz = vz - s * (pf[b2 + P_AZ] - pf[b1 + P_AZ])
        if ux * nx + uy * ny + uz * nz < 0.0:
            return s, c, nx, ny, nz, ux, uy, uz
    if vx * nx + vy * ny + vz * nz < 0.0:
        return s, c, nx, ny, nz, vx, vy, vz
    return NO_CONTACT, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0


@njit(cache=True)
def bounce_pair(pf, pw, i, j, spin, params, ctx, h, g_sim):
    """Bounce of particles i and j, v' = -eps_n v_n + eps_t v_t (the three cases of the module doc).

    ``params``: the ``PARAM_*`` layout; ``h`` is the length of the last step (s), ``g_sim`` the
    G of REBOUND's accelerations.  Contact entered within the step (time s <= h ago along the
    straight relative path): bounce at the contact point with the velocity there, then
    x_k += s dv_k.  Overlap older than the step and approaching: bounce about the current
    normal and push apart (``push_pair``).  Otherwise nothing.  Counters:
    ``ctx[CTX_N_BOUNCE]``, ``ctx[CTX_N_OVERLAP]`` (the pushed ones), ``ctx[CTX_N_SEPARATING]``.
    Returns 0 (both particles stay).
    """
    g = params[PARAM_G]
    eps_n = params[PARAM_EPS_N]
    eps_t = params[PARAM_EPS_T]
    b1 = i * P_STRIDE
    b2 = j * P_STRIDE
    m1 = pf[b1 + P_M]
    m2 = pf[b2 + P_M]
    r1 = pf[b1 + P_R]
    r2 = pf[b2 + P_R]
    vx = pf[b2 + P_VX] - pf[b1 + P_VX]
    vy = pf[b2 + P_VY] - pf[b1 + P_VY]
    vz = pf[b2 + P_VZ] - pf[b1 + P_VZ]
    contact = r1 + r2
    s, c, nx, ny, nz, bx, by, bz = contact_geometry(pf, i, j, h)
    if s == NO_CONTACT:
        ctx[CTX_N_SEPARATING] += 1
        return 0
    uu = vx * vx + vy * vy + vz * vz
    bn = bx * nx + by * ny + bz * nz
    cx = c * nx
    cy = c * ny
    cz = c * nz
    mt = m1 + m2
    mu = m1 * m2 / mt
    un_new = -eps_n * bn
    tx = eps_t * (bx - bn * nx)
    ty = eps_t * (by - bn * ny)
    tz = eps_t * (bz - bn * nz)
    shift = 0.0
    if s >= 0.0:
        # The normal velocity the step's pull after the contact, (v - b) . n, adds to the bounce: if
        # it turns the pair back towards the contact by the step's end, the pair ends the step at
        # rest in contact along n instead (x += s dv then ends it exactly at contact), so the
        # mirrored report of the pair sees it separating and leaves it alone.
        un_new = max(un_new, -((vx - bx) * nx + (vy - by) * ny + (vz - bz) * nz))
    if s < 0.0:
        # Overlap older than the step: pushed apart along n (centre of mass fixed), paid from
        # the incoming normal kinetic energy; an overlap present since t = 0 only as far as
        # that pays (but back to its depth at t = 0), and it is closed once at contact.
        ctx[CTX_N_OVERLAP] += 1
        k = _handoff_pair(ctx, pw[b1 + P_AP] - 1, pw[b2 + P_AP] - 1)
        floor = carray(_addr_as_f64(ctx[CTX_HANDOFF_FLOOR]), ctx[CTX_N_HANDOFF])[k] if k >= 0 else contact
        shift, un_new, f, unpaid = push_pair(pf, b1, b2, g, g_sim, h, c, contact, floor, nx, ny, nz, bn,
                                             tx * tx + ty * ty + tz * tz, eps_n, k >= 0)
        if k >= 0 and shift >= contact - c:
            carray(_addr_as_i64(ctx[CTX_HANDOFF_OPEN]), ctx[CTX_N_HANDOFF])[k] = 0
        params[PARAM_PUSH_ENERGY] += unpaid
        # Keep the pair's orbital angular momentum mu c n x v_t: v_t -> v_t c / (c + shift).
        tx *= f
        ty *= f
        tz *= f
    ctx[CTX_N_BOUNCE] += 1
    # New relative velocity now: the bounced one plus what the step gave after the contact, v - b.
    wx = un_new * nx + tx + vx - bx
    wy = un_new * ny + ty + vy - by
    wz = un_new * nz + tz + vz - bz
    params[PARAM_KINETIC] += 0.5 * mu * (wx * wx + wy * wy + wz * wz - uu)
    # Impulse on particle 2 (kg m/s); -J on particle 1.
    jx = mu * (wx - vx)
    jy = mu * (wy - vy)
    jz = mu * (wz - vz)
    pf[b1 + P_VX] -= jx / m1
    pf[b1 + P_VY] -= jy / m1
    pf[b1 + P_VZ] -= jz / m1
    pf[b2 + P_VX] += jx / m2
    pf[b2 + P_VY] += jy / m2
    pf[b2 + P_VZ] += jz / m2
    if s > 0.0:
        # Moved forward from the contact with the new velocities: x_k += s dv_k.
        pf[b1 + P_X] -= s * jx / m1
        pf[b1 + P_Y] -= s * jy / m1
        pf[b1 + P_Z] -= s * jz / m1
        pf[b2 + P_X] += s * jx / m2
        pf[b2 + P_Y] += s * jy / m2
        pf[b2 + P_Z] += s * jz / m2
    elif shift > 0.0:
        pf[b1 + P_X] -= m2 / mt * shift * nx
        pf[b1 + P_Y] -= m2 / mt * shift * ny
        pf[b1 + P_Z] -= m2 / mt * shift * nz
        pf[b2 + P_X] += m1 / mt * shift * nx
        pf[b2 + P_Y] += m1 / mt * shift * ny
        pf[b2 + P_Z] += m1 / mt * shift * nz
    # Change of the pair's orbital angular momentum, non-zero only through tangential
    # restitution (eps_t < 1): c n x J at the contact (fresh), mu ((c + shift) n x w - c n x v)
    # (old overlap); the spins take the opposite.
    if s >= 0.0:
        lx = cy * jz - cz * jy
        ly = cz * jx - cx * jz
        lz = cx * jy - cy * jx
    else:
        lx = mu * ((c + shift) * (ny * wz - nz * wy) - c * (ny * vz - nz * vy))
        ly = mu * ((c + shift) * (nz * wx - nx * wz) - c * (nz * vx - nx * vz))
        lz = mu * ((c + shift) * (nx * wy - ny * wx) - c * (nx * vy - ny * vx))
    if eps_t < 1.0:
        _spin_kick(spin, pw[b1 + P_AP] - 1, pw[b2 + P_AP] - 1, r1, r2, -lx, -ly, -lz)
    return 0


@cfunc(types.int32(types.voidptr, types.voidptr, types.voidptr), cache=True)
def _resolve(simp, collp, ctxp):
    sim_words = carray(_void_as_i64(simp), S_WORDS)
    sim_f = carray(_void_as_f64(simp), max(S_T, S_DT_LAST, S_G) + 1)
    t = sim_f[S_T]
    h = sim_f[S_DT_LAST]
    n = sim_words[S_N]
    addr = sim_words[S_PARTICLES]
    pf = carray(_addr_as_f64(addr), n * P_STRIDE)
    pw = carray(_addr_as_i64(addr), n * P_STRIDE)
    coll = carray(_void_as_i64(collp), 2)
    i = coll[0]
    j = coll[1]
    ctx = carray(_void_as_i64(ctxp), CTX_LEN)
    params = carray(_addr_as_f64(ctx[CTX_PARAMS]), PARAM_LEN)
    n_slots_words = ctx[CTX_CAPACITY]
    spin = carray(_addr_as_f64(ctx[CTX_SPIN]), 3 * n_slots_words)
    events = carray(_addr_as_i64(ctx[CTX_EVENTS]), 2 * n_slots_words)
    event_time = carray(_addr_as_f64(ctx[CTX_EVENT_TIME]), n_slots_words)
    model = ctx[CTX_MODEL]
    if contact_geometry(pf, i, j, h)[0] == NO_CONTACT:
        ctx[CTX_N_SEPARATING] += 1
        return 0
    if model == 0:
        return merge_pair(pf, pw, i, j, spin, params, t, ctx, events, event_time)
    if model == 1:
        b1 = i * P_STRIDE
        b2 = j * P_STRIDE
        vx = pf[b2 + P_VX] - pf[b1 + P_VX]
        vy = pf[b2 + P_VY] - pf[b1 + P_VY]
        vz = pf[b2 + P_VZ] - pf[b1 + P_VZ]
        v_esc2 = 2.0 * params[PARAM_G] * (pf[b1 + P_M] + pf[b2 + P_M]) / (pf[b1 + P_R] + pf[b2 + P_R])
        if vx * vx + vy * vy + vz * vz < v_esc2:
            return merge_pair(pf, pw, i, j, spin, params, t, ctx, events, event_time)
    return bounce_pair(pf, pw, i, j, spin, params, ctx, h, sim_f[S_G])


_COLLISION_IR = "{i64, i64, [6 x double], i64}"


def _calling_convention() -> str:
    triple = llvm.get_default_triple()
    if triple.startswith("x86_64") and "windows" not in triple:
        return "byval"
    if triple.startswith(("aarch64", "arm64")) or (triple.startswith("x86_64") and "windows" in triple):
        return "pointer"
    raise RuntimeError(f"no collision-resolver trampoline for target {triple}")


class CollisionResolver:
    """The compiled resolver of one simulation run and the buffers it writes.

    Attributes:
        spin: (n_slots, 3) spin angular momentum per hand-off slot (kg m^2/s).
        events: (n_slots, 2) merge events (survivor slot, absorbed slot) since the last
            :meth:`drain_events`; event_time: (n_slots,) their times (s).
        ctx: the int64 context array (counters at ``CTX_N_MERGE``, ``CTX_N_BOUNCE``,
            ``CTX_N_OVERLAP``, ``CTX_N_SEPARATING``, ``CTX_PARTICLE_STEPS``).
        params: float64, ``PARAM_*`` layout: G, eps_n, eps_t, the cumulative kinetic-energy change
            made by the resolver (J) and the cumulative energy added by pushes of run-time
            overlaps beyond what they paid (J).
        handoff_keys, handoff_floor, handoff_open: the pairs overlapping at t = 0 (keys
            s1 * n_slots + s2, s1 < s2, sorted), their distances then (m) and whether each is
            still unseparated (1) or has reached contact (0), set by :meth:`set_handoff_overlaps`.
        address: the C function address to assign to ``sim.collision_resolve``.
        step_counter: the C function address :meth:`attach` assigns to
            ``sim.post_timestep_modifications``: adds ``sim->N`` to ``ctx[CTX_PARTICLE_STEPS]``
            once per step, after the step's drift and kicks and before its collision search
            (so a step counts the particles it integrated; mergers count from the next step).
    """

    def __init__(self, n_slots: int, model: str, restitution_normal: float,
                 restitution_tangential: float, g: float):
        if model not in MODEL_CODES:
            raise ValueError(f"collision_model must be one of {COLLISION_MODELS} (got {model!r})")
        self.params = np.zeros(PARAM_LEN, dtype=np.float64)
        self.params[[PARAM_G, PARAM_EPS_N, PARAM_EPS_T]] = g, restitution_normal, restitution_tangential
        self.spin = np.zeros((n_slots, 3), dtype=np.float64)
        self.events = np.zeros((n_slots, 2), dtype=np.int64)
        self.event_time = np.zeros(n_slots, dtype=np.float64)
        self.ctx = np.zeros(CTX_LEN, dtype=np.int64)
        self.ctx[CTX_PARAMS] = self.params.ctypes.data
        self.ctx[CTX_SPIN] = self.spin.ctypes.data
        self.ctx[CTX_EVENTS] = self.events.ctypes.data
        self.ctx[CTX_EVENT_TIME] = self.event_time.ctypes.data
        self.ctx[CTX_CAPACITY] = n_slots
        self.ctx[CTX_MODEL] = MODEL_CODES[model]
        self.n_slots = n_slots
        self.set_handoff_overlaps(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0))
        self._engine, self.address, self.step_counter = _build_trampoline(self.ctx.ctypes.data)

    def attach(self, sim: rebound.Simulation) -> None:
        """Set this resolver as ``sim``'s collision resolver and its particle-step counter as the
        post-step hook (again after loading an archive: REBOUND stores no function pointers)."""
        sim.collision_resolve = self.address
        sim.post_timestep_modifications = self.step_counter

    def set_handoff_overlaps(self, slot1: np.ndarray, slot2: np.ndarray, distance: np.ndarray,
                             is_open: np.ndarray | None = None) -> None:
        """Register the pairs (slot1[k], slot2[k]) overlapping at t = 0 at ``distance`` (m), all open
        unless ``is_open`` (a resumed run's flags) says otherwise."""
        lo = np.minimum(slot1, slot2).astype(np.int64)
        hi = np.maximum(slot1, slot2).astype(np.int64)
        keys = lo * self.n_slots + hi
        order = np.argsort(keys)
        if np.any(np.diff(keys[order]) == 0):
            raise ValueError("a pair is registered twice")
        # one spare element each: valid addresses when there are no pairs
        self.handoff_keys = np.append(keys[order], 0)
        self.handoff_floor = np.append(np.asarray(distance, dtype=np.float64)[order], 0.0)
        flags = np.ones(keys.size, dtype=np.int64) if is_open is None else np.asarray(is_open, dtype=np.int64)[order]
        self.handoff_open = np.append(flags, 0)
        self.ctx[CTX_HANDOFF_KEYS] = self.handoff_keys.ctypes.data
        self.ctx[CTX_HANDOFF_OPEN] = self.handoff_open.ctypes.data
        self.ctx[CTX_HANDOFF_FLOOR] = self.handoff_floor.ctypes.data
        self.ctx[CTX_N_HANDOFF] = keys.size

    def close_separated(self, slots: np.ndarray, position: np.ndarray, radius: np.ndarray) -> int:
        """Close the open t = 0 overlap pairs now at or beyond contact, or no longer both present.

        ``slots``, ``position`` (m), ``radius`` (m) of the particles in the simulation.  Returns
        the number of pairs still open.
        """
        n = int(self.ctx[CTX_N_HANDOFF])
        open_k = np.flatnonzero(self.handoff_open[:n])
        if open_k.size == 0:
            return 0
        row = np.full(self.n_slots, -1, dtype=np.int64)
        row[slots] = np.arange(len(slots))
        i = row[self.handoff_keys[open_k] // self.n_slots]
        j = row[self.handoff_keys[open_k] % self.n_slots]
        present = (i >= 0) & (j >= 0)
        apart = np.ones(open_k.size, dtype=bool)
        apart[present] = (np.linalg.norm(position[i[present]] - position[j[present]], axis=1)
                          >= radius[i[present]] + radius[j[present]])
        self.handoff_open[open_k[apart]] = 0
        return int(open_k.size - apart.sum())

    def drain_events(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the merge events (slots (k, 2), times (k,)) since the last call; resets the buffer."""
        if self.ctx[CTX_OVERFLOW]:
            raise RuntimeError("merge event buffer overflow: a merger was skipped")
        k = int(self.ctx[CTX_N_EVENTS])
        out = self.events[:k].copy(), self.event_time[:k].copy()
        self.ctx[CTX_N_EVENTS] = 0
        return out

    def resolve(self, sim: rebound.Simulation, p1: int, p2: int) -> int:
        """Call the compiled resolver on the pair (p1, p2) of ``sim`` now (tests, diagnostics).

        The step length it uses is ``sim.dt_last_done`` (0 before the first step).
        """
        fn = rebound.simulation.COLRFF(self.address)
        coll = rebound.simulation.CollisionS()
        coll.p1 = p1
        coll.p2 = p2
        return int(fn(ctypes.byref(sim), coll))


def _build_trampoline(ctx_address: int):
    """Compile ``int32 f(reb_simulation*, reb_collision by value)`` calling the cfunc with the context,
    and ``void g(reb_simulation*)`` adding ``sim->N`` to ``ctx[CTX_PARTICLE_STEPS]``.

    Returns the execution engine (keep it alive) and the addresses of f and g.
    """
    llvm.initialize_native_target()
    llvm.initialize_native_asmprinter()
    attr = f" byval({_COLLISION_IR}) align 8" if _calling_convention() == "byval" else ""
    text = f"""
define i32 @impactpipe_resolve(ptr %sim, ptr{attr} %coll) {{
  %f = inttoptr i64 {_resolve.address} to ptr
  %ctx = inttoptr i64 {ctx_address} to ptr
  %r = call i32 %f(ptr %sim, ptr %coll, ptr %ctx)
  ret i32 %r
}}

define void @impactpipe_count_step(ptr %sim) {{
  %np = getelementptr i8, ptr %sim, i64 {rebound.Simulation.N.offset}
  %n = load i64, ptr %np, align 8
  %cp = inttoptr i64 {ctx_address + 8 * CTX_PARTICLE_STEPS} to ptr
  %c = load i64, ptr %cp, align 8
  %s = add i64 %c, %n
  store i64 %s, ptr %cp, align 8
  ret void
}}
"""
    module = llvm.parse_assembly(text)
    module.verify()
    machine = llvm.Target.from_default_triple().create_target_machine()
    engine = llvm.create_mcjit_compiler(module, machine)
    engine.finalize_object()
    return (engine, engine.get_function_address("impactpipe_resolve"),
            engine.get_function_address("impactpipe_count_step"))


def particle_view(sim: rebound.Simulation) -> np.ndarray:
    """A writable structured numpy view (``PARTICLE_DTYPE``) of ``sim``'s particles, zero-copy.

    Valid until particles are added or removed.
    """
    n = sim.N
    if n == 0:
        return np.zeros(0, dtype=PARTICLE_DTYPE)
    addr = ctypes.cast(sim._particles, ctypes.c_void_p).value
    buf = (ctypes.c_char * (n * PARTICLE_DTYPE.itemsize)).from_address(addr)
    return np.frombuffer(buf, dtype=PARTICLE_DTYPE)
