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

* merge: one particle at the centre of mass with mass M, velocity
  (m1 v1 + m2 v2) / M, radius (r1^3 + r2^3)^(1/3) (summed volume) and spin
  S = S1 + S2 + mu (x1 - x2) x (v1 - v2), the orbital angular momentum of the pair about
  its centre of mass, so linear and total angular momentum are conserved exactly.  The
  more massive particle (the lower slot on a tie) survives and keeps its identity, as in
  pkdgrav.  Every merger is written to the event buffer as (survivor slot, absorbed
  slot, time).
* bounce (only for an approaching pair, v . n < 0; the mirrored report of a pair already
  bounced is separating and its velocities are left alone): v' = -eps_n v_n + eps_t v_t,
  applied as equal and opposite impulses J = mu (v' - v) on particle 2 and -J on
  particle 1.  With eps_t < 1 the tangential impulse changes the orbital angular momentum
  by d n x J; the opposite amount goes into the spins, shared in proportion r1 : r2 as
  the contact torques are (spin does not feed back into the contact velocity).
  An overlapping pair (d < r1 + r2; approaching and bounced, or already separating) is
  pushed apart along n to contact, s = r1 + r2 - d (centre of mass fixed), so overlaps
  never accumulate (resting contacts would otherwise sink towards the point-mass
  singularity).  The push raises the pair's potential energy by
  dU = G m1 m2 (1/d - 1/(r1 + r2)).  It is paid first from the incoming normal kinetic
  energy mu v_n^2 / 2 (the energy the pair gained by moving into the overlap during the
  step, which an exact hard-sphere contact would not have had), then from the outgoing
  normal kinetic energy; only what is left over (resting contacts) adds energy, and it is
  accumulated in ``params[3]`` and reported as the diagnostic ``contact_energy_added``.
  The tangential relative velocity is scaled by d / (r1 + r2), which keeps the pair's
  orbital angular momentum about its centre of mass and only removes energy.
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
P_M, P_R, P_AP = 9, 10, 12
# reb_simulation layout in 8-byte words: t, N, particles.
S_T = rebound.Simulation.t.offset // 8
S_N = rebound.Simulation.N.offset // 8
S_PARTICLES = rebound.Simulation._particles.offset // 8
S_WORDS = S_PARTICLES + 1

# Context (int64 array) layout.
CTX_PARAMS = 0        # address of float64 params [G, eps_n, eps_t, contact energy added (J)]
CTX_SPIN = 1          # address of float64 spin (n_slots, 3), kg m^2/s
CTX_EVENTS = 2        # address of int64 merge events (capacity, 2): survivor, absorbed slot
CTX_EVENT_TIME = 3    # address of float64 merge event times (capacity,), s
CTX_CAPACITY = 4      # capacity of the event buffer
CTX_N_EVENTS = 5      # merge events written since the last drain
CTX_MODEL = 6         # MODEL_CODES value
CTX_N_MERGE = 7       # cumulative mergers
CTX_N_BOUNCE = 8      # cumulative bounces
CTX_N_SEPARATING = 9  # cumulative reports of separating pairs left alone
CTX_OVERFLOW = 10     # 1 if a merger found the event buffer full (it was not performed)
CTX_LEN = 11

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
                "m": P_M, "r": P_R, "ap": P_AP}
    for name, word in expected.items():
        if getattr(rebound.Particle, name).offset != 8 * word:
            raise ImportError(f"unsupported REBOUND particle layout (field {name}); rebound {rebound.__version__}")
    if ctypes.sizeof(rebound.Particle) != 8 * P_STRIDE:
        raise ImportError(f"unsupported REBOUND particle size; rebound {rebound.__version__}")
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
def merge_pair(pf, pw, i, j, spin, t, ctx, events, event_time):
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
def bounce_pair(pf, pw, i, j, spin, params, ctx):
    """Inelastic bounce of particles i and j: v' = -eps_n v_n + eps_t v_t (see module doc).

    ``params`` = [G, eps_n, eps_t, contact energy added (J, accumulated)].  An approaching
    pair (v . n < 0) bounces; a separating pair keeps its velocities (counted in
    ``ctx[CTX_N_SEPARATING]``).  Either way an overlapping pair is then pushed to contact.
    Returns 0 (both particles stay).
    """
    g = params[0]
    eps_n = params[1]
    eps_t = params[2]
    b1 = i * P_STRIDE
    b2 = j * P_STRIDE
    m1 = pf[b1 + P_M]
    m2 = pf[b2 + P_M]
    r1 = pf[b1 + P_R]
    r2 = pf[b2 + P_R]
    dx = pf[b2 + P_X] - pf[b1 + P_X]
    dy = pf[b2 + P_Y] - pf[b1 + P_Y]
    dz = pf[b2 + P_Z] - pf[b1 + P_Z]
    d = math.sqrt(dx * dx + dy * dy + dz * dz)
    if not d > 0.0:
        return 0
    vx = pf[b2 + P_VX] - pf[b1 + P_VX]
    vy = pf[b2 + P_VY] - pf[b1 + P_VY]
    vz = pf[b2 + P_VZ] - pf[b1 + P_VZ]
    nx = dx / d
    ny = dy / d
    nz = dz / d
    un = vx * nx + vy * ny + vz * nz
    mt = m1 + m2
    mu = m1 * m2 / mt
    contact = r1 + r2
    shift = contact - d if d < contact else 0.0
    # Potential-energy rise of pushing the pair to contact (J), paid from normal kinetic energy.
    du = g * m1 * m2 * (1.0 / d - 1.0 / contact) if shift > 0.0 else 0.0
    # Relative velocity after the contact: normal speed along +n and tangential part.
    if un < 0.0:
        paid = min(du, 0.5 * mu * un * un)
        du -= paid
        un_new = eps_n * math.sqrt(max(un * un - 2.0 * paid / mu, 0.0))
        tx = eps_t * (vx - un * nx)
        ty = eps_t * (vy - un * ny)
        tz = eps_t * (vz - un * nz)
        ctx[CTX_N_BOUNCE] += 1
    else:
        un_new = un
        tx = vx - un * nx
        ty = vy - un * ny
        tz = vz - un * nz
        ctx[CTX_N_SEPARATING] += 1
    if shift > 0.0:
        paid = min(du, 0.5 * mu * un_new * un_new)
        un_new = math.sqrt(max(un_new * un_new - 2.0 * paid / mu, 0.0))
        params[3] += du - paid
        # Keep the pair's orbital angular momentum mu d n x v_t: v_t -> v_t d / (d + s).
        f = d / contact
        tx *= f
        ty *= f
        tz *= f
    wx = un_new * nx + tx
    wy = un_new * ny + ty
    wz = un_new * nz + tz
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
    if shift > 0.0:
        pf[b1 + P_X] -= m2 / mt * shift * nx
        pf[b1 + P_Y] -= m2 / mt * shift * ny
        pf[b1 + P_Z] -= m2 / mt * shift * nz
        pf[b2 + P_X] += m1 / mt * shift * nx
        pf[b2 + P_Y] += m1 / mt * shift * ny
        pf[b2 + P_Z] += m1 / mt * shift * nz
    # Change of the pair's orbital angular momentum mu (d + s) n x w - mu d n x v, non-zero only
    # through tangential restitution (eps_t < 1); the spins take the opposite.
    lx = mu * ((d + shift) * (ny * wz - nz * wy) - d * (ny * vz - nz * vy))
    ly = mu * ((d + shift) * (nz * wx - nx * wz) - d * (nz * vx - nx * vz))
    lz = mu * ((d + shift) * (nx * wy - ny * wx) - d * (nx * vy - ny * vx))
    if lx != 0.0 or ly != 0.0 or lz != 0.0:
        _spin_kick(spin, pw[b1 + P_AP] - 1, pw[b2 + P_AP] - 1, r1, r2, -lx, -ly, -lz)
    return 0


@cfunc(types.int32(types.voidptr, types.voidptr, types.voidptr), cache=True)
def _resolve(simp, collp, ctxp):
    sim_words = carray(_void_as_i64(simp), S_WORDS)
    t = carray(_void_as_f64(simp), S_T + 1)[S_T]
    n = sim_words[S_N]
    addr = sim_words[S_PARTICLES]
    pf = carray(_addr_as_f64(addr), n * P_STRIDE)
    pw = carray(_addr_as_i64(addr), n * P_STRIDE)
    coll = carray(_void_as_i64(collp), 2)
    i = coll[0]
    j = coll[1]
    ctx = carray(_void_as_i64(ctxp), CTX_LEN)
    params = carray(_addr_as_f64(ctx[CTX_PARAMS]), 4)
    n_slots_words = ctx[CTX_CAPACITY]
    spin = carray(_addr_as_f64(ctx[CTX_SPIN]), 3 * n_slots_words)
    events = carray(_addr_as_i64(ctx[CTX_EVENTS]), 2 * n_slots_words)
    event_time = carray(_addr_as_f64(ctx[CTX_EVENT_TIME]), n_slots_words)
    model = ctx[CTX_MODEL]
    g = params[0]
    if model == 0:
        return merge_pair(pf, pw, i, j, spin, t, ctx, events, event_time)
    if model == 1:
        b1 = i * P_STRIDE
        b2 = j * P_STRIDE
        vx = pf[b2 + P_VX] - pf[b1 + P_VX]
        vy = pf[b2 + P_VY] - pf[b1 + P_VY]
        vz = pf[b2 + P_VZ] - pf[b1 + P_VZ]
        v_esc2 = 2.0 * g * (pf[b1 + P_M] + pf[b2 + P_M]) / (pf[b1 + P_R] + pf[b2 + P_R])
        if vx * vx + vy * vy + vz * vz < v_esc2:
            return merge_pair(pf, pw, i, j, spin, t, ctx, events, event_time)
    return bounce_pair(pf, pw, i, j, spin, params, ctx)


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
            ``CTX_N_SEPARATING``).
        address: the C function address to assign to ``sim.collision_resolve``.
    """

    def __init__(self, n_slots: int, model: str, restitution_normal: float,
                 restitution_tangential: float, g: float):
        if model not in MODEL_CODES:
            raise ValueError(f"collision_model must be one of {COLLISION_MODELS} (got {model!r})")
        self.params = np.array([g, restitution_normal, restitution_tangential, 0.0], dtype=np.float64)
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
        self._engine, self.address = _build_trampoline(self.ctx.ctypes.data)

    def attach(self, sim: rebound.Simulation) -> None:
        """Set this resolver as ``sim``'s collision resolver (again after loading an archive)."""
        sim.collision_resolve = self.address

    def drain_events(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the merge events (slots (k, 2), times (k,)) since the last call; resets the buffer."""
        if self.ctx[CTX_OVERFLOW]:
            raise RuntimeError("merge event buffer overflow: a merger was skipped")
        k = int(self.ctx[CTX_N_EVENTS])
        out = self.events[:k].copy(), self.event_time[:k].copy()
        self.ctx[CTX_N_EVENTS] = 0
        return out

    def resolve(self, sim: rebound.Simulation, p1: int, p2: int) -> int:
        """Call the compiled resolver on the pair (p1, p2) of ``sim`` now (tests, diagnostics)."""
        fn = rebound.simulation.COLRFF(self.address)
        coll = rebound.simulation.CollisionS()
        coll.p1 = p1
        coll.p2 = p2
        return int(fn(ctypes.byref(sim), coll))


def _build_trampoline(ctx_address: int):
    """Compile ``int32 f(reb_simulation*, reb_collision by value)`` calling the cfunc with the context."""
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
"""
    module = llvm.parse_assembly(text)
    module.verify()
    machine = llvm.Target.from_default_triple().create_target_machine()
    engine = llvm.create_mcjit_compiler(module, machine)
    engine.finalize_object()
    return engine, engine.get_function_address("impactpipe_resolve")


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
