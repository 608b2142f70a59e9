"""Gravitationally bound remnants of a reaccumulated particle cloud.

Two definitions of a remnant, chosen with ``mode``:

``"aggregate"`` (for bouncing / non-merging collision models)
    1. Friends-of-friends on touching spheres: particles i and j are linked when
       ``|x_i - x_j| <= link_factor * (r_i + r_j)``; linked components are the
       candidate aggregates.
    2. Unbinding (the SKID idea): particle i of a candidate group G (mass M_G,
       centre-of-mass velocity V_G) has the specific two-body energy of its motion
       relative to the rest of the group,

           e_i = 0.5 M_G / (M_G - m_i) |v_i - V_G|^2 + phi_G(x_i)      [J/kg]

       with phi_G(x_i) the gravitational potential at the centre of i from the
       other members.  (The kinetic term is 0.5 mu |v_i - V_rest|^2 / m_i with
       mu = m_i M_rest / M_G, rewritten with V_G; for m_i << M_G it is the usual
       0.5 |v_i - V_G|^2, and for two particles it is exact: they are bound
       below their mutual escape speed.)  While some e_i > 0, the particle with
       the largest e_i is removed, V_G and phi_G are updated, and the test is
       repeated (one particle at a time: removing a particle moves V_G, so
       removing all positive-energy particles at once can over-remove).  A single
       particle is bound by definition.
    3. The removed particles are grouped again by touching (step 1 on them alone)
       and each such group is unbound in turn, so a clump that leaves a larger
       group together survives as its own aggregate.
    The remnant is the self-bound touching aggregate.  Particles outside it that
    are gravitationally bound to it (satellites, orbiting or still accreting
    debris, particles removed from another group) are not members; they are
    counted in ``bound_mass`` / ``bound_members``, the aggregate plus everything
    bound to it (step "bound system" below), which is the quantity the N-body
    stop criterion (mass orbiting or accreting < 10% of M_lr) refers to.

``"merge"`` (for perfect / conditional merging)
    The most massive particle plus everything gravitationally bound to it
    (bound system with the particle as seed).  The second remnant is found the
    same way among the particles not in the first, and so on.

Bound system of a seed set S (iterative): a particle k outside the seed belongs
to the system when its two-body energy relative to the rest of the system is
negative, ``0.5 M_S / M_rest |v_k - V_S|^2 + phi_S(x_k) < 0`` (M_rest = M_S - m_k
if k is in the current system, else M_rest = M_S and the factor is
M_S / (M_S + m_k)), with V_S, M_S and phi_S the centre-of-mass velocity, mass
and potential of the current system (seed plus the particles found bound so
far, k itself excluded from phi_S).  The system is rebuilt from the seed and the
particles bound to it until it no longer changes, or at most ``max_iterations``
times (a warning is logged when the cap is reached).

Potential of a member j at distance d from its centre (uniform sphere of mass
m_j and radius r_j, so overlapping particles give a finite potential):

    phi_j(d) = -G m_j / d                            for d >= r_j
    phi_j(d) = -G m_j (3 r_j^2 - d^2) / (2 r_j^3)    for d <  r_j

Potentials are direct sums (O(n^2) per group), numba-compiled; the bound-system
update costs O(N) per particle that joins or leaves.

Remnant properties (SI): mass, member count, centre of mass, velocity, bulk
radius ``R = (sum r_i^3 / phi_pack)^(1/3)`` from the member volumes and the
packing fraction ``phi_pack`` (default 0.64, random close packing of equal
spheres: the remnant is a rubble pile whose bulk volume is the grain volume over
the packing fraction), bulk density ``M / (4/3 pi R^3)`` (= phi_pack times the
particles' mean density), extent ``max |x_i - X| + r_i``, orbital angular
momentum about the centre of mass ``L = sum m_i (x_i - X) x (v_i - V)``, the
inertia tensor of the member centres ``I = sum m_i (|s_i|^2 1 - s_i s_i^T)``
(s_i = x_i - X), angular velocity ``omega = I^+ L`` (pseudo-inverse, so two
particles or a line of particles give the rotation about the perpendicular
axes) and spin period ``2 pi / |omega|`` (inf when L = 0).  The N-body particles
carry no spin of their own, so L and I are both the orbital parts, and a rigid
rotation omega is recovered exactly.
"""

from __future__ import annotations

import heapq
import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit, prange
from scipy.constants import G as G_SI
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

logger = logging.getLogger(__name__)

MODES = ("aggregate", "merge")
DEFAULT_PACKING_FRACTION = 0.64


@njit(cache=True)
def _sphere_potential(d, m, r, G):
    """Potential (J/kg) at distance d (m) from the centre of a uniform sphere (m kg, r m)."""
    if d >= r:
        return -G * m / d
    return -G * m * (3.0 * r * r - d * d) / (2.0 * r * r * r)


@njit(cache=True, parallel=True)
def _add_potential(phi, targets, sources, pos, mass, radius, G, sign):
    """phi[i] += sign * sum_{j in sources, j != i} phi_j(|x_i - x_j|) for i in targets.

    ``targets`` must not repeat an index (each thread writes its own phi[i]).
    """
    for ii in prange(targets.shape[0]):
        i = targets[ii]
        acc = 0.0
        for jj in range(sources.shape[0]):
            j = sources[jj]
            if j == i:
                continue
            dx = pos[i, 0] - pos[j, 0]
            dy = pos[i, 1] - pos[j, 1]
            dz = pos[i, 2] - pos[j, 2]
            d = np.sqrt(dx * dx + dy * dy + dz * dz)
            acc += _sphere_potential(d, mass[j], radius[j], G)
        phi[i] += sign * acc


@njit(cache=True)
def _unbind(members, pos, vel, mass, radius, G, phi):
    """Remove the most unbound member, one at a time, until all are bound.

    ``phi[members]`` must hold each member's potential from the other members on
    entry; it is updated in place as members are removed.  Returns a boolean mask
    over ``members``: True for the bound core.
    """
    n = members.shape[0]
    alive = np.ones(n, dtype=np.bool_)
    m_tot = 0.0
    p = np.zeros(3)
    for k in range(n):
        i = members[k]
        m_tot += mass[i]
        for c in range(3):
            p[c] += mass[i] * vel[i, c]
    n_alive = n
    while n_alive > 1:
        worst = -1
        worst_e = 0.0
        for k in range(n):
            if not alive[k]:
                continue
            i = members[k]
            ke = 0.0
            for c in range(3):
                dv = vel[i, c] - p[c] / m_tot
                ke += dv * dv
            e = 0.5 * ke * m_tot / (m_tot - mass[i]) + phi[i]
            if e > worst_e:
                worst_e = e
                worst = k
        if worst < 0:
            break
        alive[worst] = False
        n_alive -= 1
        i = members[worst]
        m_tot -= mass[i]
        for c in range(3):
            p[c] -= mass[i] * vel[i, c]
        for k in range(n):
            if alive[k]:
                j = members[k]
                dx = pos[j, 0] - pos[i, 0]
                dy = pos[j, 1] - pos[i, 1]
                dz = pos[j, 2] - pos[i, 2]
                d = np.sqrt(dx * dx + dy * dy + dz * dz)
                phi[j] -= _sphere_potential(d, mass[i], radius[i], G)
    return alive


def touching_groups(position: np.ndarray, radius: np.ndarray, link_factor: float = 1.0) -> np.ndarray:
    """Friends-of-friends labels of touching spheres.

    Particles i and j are linked when ``|x_i - x_j| <= link_factor * (r_i + r_j)``;
    the labels are the connected components of that graph.

    Candidate pairs come from k-d trees over radius classes (factor 2 in radius per
    class), each pair of classes searched with the largest link distance of the
    two classes, so a few large particles do not inflate the search radius for
    all the small ones.

    Args:
        position: (N, 3) centres (m).
        radius: (N,) radii (m), > 0.
        link_factor: multiple of the sum of radii that counts as touching.

    Returns:
        (N,) int64 component label per particle (0 .. n_groups - 1).
    """
    position = np.asarray(position, dtype=float)
    radius = np.asarray(radius, dtype=float)
    n = radius.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    r_min = radius.min()
    cls = np.floor(np.log2(radius / r_min)).astype(np.int64)
    classes = np.unique(cls)
    index = {c: np.flatnonzero(cls == c) for c in classes}
    trees = {c: cKDTree(position[index[c]]) for c in classes}
    rmax = {c: radius[index[c]].max() for c in classes}
    rows, cols = [], []
    for a_pos, a in enumerate(classes):
        for b in classes[a_pos:]:
            reach = link_factor * (rmax[a] + rmax[b])
            if a == b:
                pairs = trees[a].query_pairs(reach, output_type="ndarray")
                i = index[a][pairs[:, 0]]
                j = index[a][pairs[:, 1]]
            else:
                sdm = trees[a].sparse_distance_matrix(trees[b], reach, output_type="ndarray")
                i = index[a][sdm["i"]]
                j = index[b][sdm["j"]]
            d = np.linalg.norm(position[i] - position[j], axis=1)
            keep = d <= link_factor * (radius[i] + radius[j])
            rows.append(i[keep])
            cols.append(j[keep])
    rows_a = np.concatenate(rows)
    cols_a = np.concatenate(cols)
    graph = coo_matrix((np.ones(rows_a.shape[0]), (rows_a, cols_a)), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    return labels.astype(np.int64)


@dataclass(frozen=True)
class Remnant:
    """One remnant (SI units).

    Attributes:
        members: int64 indices of the member particles in the input arrays.
        mass: total member mass (kg).
        n_particles: number of members.
        com: (3,) centre of mass (m).
        velocity: (3,) centre-of-mass velocity (m/s).
        bulk_radius: (sum r_i^3 / packing_fraction)^(1/3) (m).
        extent: max |x_i - com| + r_i (m).
        bulk_density: mass / (4/3 pi bulk_radius^3) (kg/m^3).
        angular_momentum: (3,) orbital angular momentum about the COM (kg m^2/s).
        angular_velocity: (3,) I^+ L (rad/s).
        spin_period: 2 pi / |angular_velocity| (s); inf without rotation.
        bound_members: indices of the members plus every particle bound to them.
        bound_mass: mass of ``bound_members`` (kg).
        mass_fraction: mass / target_mass (NaN when no target mass was given).
    """

    members: np.ndarray
    mass: float
    n_particles: int
    com: np.ndarray
    velocity: np.ndarray
    bulk_radius: float
    extent: float
    bulk_density: float
    angular_momentum: np.ndarray
    angular_velocity: np.ndarray
    spin_period: float
    bound_members: np.ndarray
    bound_mass: float
    mass_fraction: float


@dataclass(frozen=True)
class RemnantResult:
    """Remnants sorted by decreasing mass, with the settings that defined them.

    Attributes:
        remnants: the ``n_remnants`` most massive remnants (fewer if there are fewer).
        label: (N,) index into ``remnants`` of the remnant each particle belongs to, -1 if none.
        mode: "aggregate" or "merge".
        packing_fraction: packing fraction used for bulk radius and density.
        link_factor: touching criterion used by "aggregate" mode.
        total_mass: mass of all input particles (kg).
        target_mass: M_T (kg) or None.
        converged: False if a bound-system iteration reached ``max_iterations``.
    """

    remnants: tuple[Remnant, ...]
    label: np.ndarray
    mode: str
    packing_fraction: float
    link_factor: float
    total_mass: float
    target_mass: float | None
    converged: bool = True

    @property
    def largest(self) -> Remnant | None:
        """The largest remnant (None for an empty particle set)."""
        return self.remnants[0] if self.remnants else None

    @property
    def second_largest(self) -> Remnant | None:
        """The second-largest remnant, or None."""
        return self.remnants[1] if len(self.remnants) > 1 else None

    @property
    def mlr_over_mt(self) -> float:
        """M_lr / M_T (0 when there is no remnant, e.g. every particle escaped; NaN without a target mass)."""
        if self.target_mass is None:
            return float("nan")
        return 0.0 if self.largest is None else self.largest.mass / self.target_mass

    @property
    def mslr_over_mt(self) -> float:
        """M_slr / M_T (0 when there is no second remnant; NaN without a target mass)."""
        if self.target_mass is None:
            return float("nan")
        return 0.0 if self.second_largest is None else self.second_largest.mass / self.target_mass

    def as_datasets(self) -> dict[str, Any]:
        """The result as a ``write_analysis`` group: (array, units, description) leaves.

        Member lists are stored in CSR form: members of remnant k are
        ``members[members_offset[k]:members_offset[k + 1]]`` (likewise ``bound_members``).
        """
        rem = self.remnants

        def stack(name, shape):
            return np.array([getattr(r, name) for r in rem], dtype=float).reshape((len(rem),) + shape)

        def csr(name):
            lists = [getattr(r, name) for r in rem]
            offset = np.concatenate([[0], np.cumsum([len(x) for x in lists])]).astype(np.int64)
            flat = np.concatenate(lists).astype(np.int64) if lists else np.zeros(0, dtype=np.int64)
            return offset, flat

        m_off, m_flat = csr("members")
        b_off, b_flat = csr("bound_members")
        nan = float("nan")
        return {
            "mass": (stack("mass", ()), "kg", "remnant mass, sorted by decreasing mass"),
            "n_particles": (np.array([r.n_particles for r in rem], dtype=np.int64), "dimensionless",
                            "member particles"),
            "com": (stack("com", (3,)), "m", "centre of mass"),
            "velocity": (stack("velocity", (3,)), "m/s", "centre-of-mass velocity"),
            "bulk_radius": (stack("bulk_radius", ()), "m",
                            "(sum r_i^3 / packing_fraction)^(1/3)"),
            "extent": (stack("extent", ()), "m", "max |x_i - com| + r_i"),
            "bulk_density": (stack("bulk_density", ()), "kg/m**3", "mass / (4/3 pi bulk_radius^3)"),
            "angular_momentum": (stack("angular_momentum", (3,)), "kg*m**2/s",
                                 "orbital angular momentum of the members about the COM"),
            "angular_velocity": (stack("angular_velocity", (3,)), "rad/s", "pinv(I) L"),
            "spin_period": (stack("spin_period", ()), "s", "2 pi / |omega|"),
            "bound_mass": (stack("bound_mass", ()), "kg", "remnant plus particles bound to it"),
            "mass_fraction": (stack("mass_fraction", ()), "dimensionless", "mass / M_T"),
            "members_offset": (m_off, "dimensionless", "CSR offsets into members"),
            "members": (m_flat, "dimensionless", "particle indices of the members"),
            "bound_members_offset": (b_off, "dimensionless", "CSR offsets into bound_members"),
            "bound_members": (b_flat, "dimensionless", "particle indices of the bound systems"),
            "label": (self.label, "dimensionless", "remnant index per particle, -1 for none"),
            "mlr_over_mt": (self.mlr_over_mt, "dimensionless", "M_lr / M_T"),
            "mslr_over_mt": (self.mslr_over_mt, "dimensionless", "M_slr / M_T"),
            "total_mass": (self.total_mass, "kg", "mass of all particles"),
            "target_mass": (nan if self.target_mass is None else self.target_mass, "kg", "M_T"),
            "packing_fraction": (self.packing_fraction, "dimensionless",
                                 "packing fraction assumed for bulk radius and density"),
            "link_factor": (self.link_factor, "dimensionless",
                            "touching: |x_i - x_j| <= link_factor (r_i + r_j)"),
            "mode": (np.bytes_(self.mode), "dimensionless", "aggregate or merge"),
            "converged": (np.int8(self.converged), "dimensionless", "1 if all iterations converged"),
        }


class _Cloud:
    """Particle arrays plus the potential bookkeeping shared by the finders."""

    def __init__(self, mass, radius, position, velocity, G):
        self.mass = np.ascontiguousarray(mass, dtype=float)
        self.radius = np.ascontiguousarray(radius, dtype=float)
        self.pos = np.ascontiguousarray(position, dtype=float)
        self.vel = np.ascontiguousarray(velocity, dtype=float)
        self.G = float(G)
        self.n = self.mass.shape[0]
        self.all_index = np.arange(self.n, dtype=np.int64)

    def bound_core(self, members: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Split ``members`` into its self-bound core and the removed particles."""
        if members.shape[0] == 1:
            return members, members[:0]
        phi = np.zeros(self.n)
        _add_potential(phi, members, members, self.pos, self.mass, self.radius, self.G, 1.0)
        alive = _unbind(members, self.pos, self.vel, self.mass, self.radius, self.G, phi)
        return members[alive], members[~alive]

    def bound_system(self, seed: np.ndarray, candidates: np.ndarray, max_iterations: int) -> tuple[np.ndarray, bool]:
        """Seed plus the candidates gravitationally bound to it (iterated to a fixed point).

        Returns the sorted member indices and whether the iteration converged.
        """
        in_system = np.zeros(self.n, dtype=bool)
        in_system[seed] = True
        is_seed = in_system.copy()
        cand = candidates[~is_seed[candidates]]
        phi = np.zeros(self.n)
        targets = np.concatenate([seed, cand])
        _add_potential(phi, targets, seed, self.pos, self.mass, self.radius, self.G, 1.0)
        for _ in range(max_iterations):
            members = np.flatnonzero(in_system)
            m = self.mass[members]
            v_sys = (m[:, None] * self.vel[members]).sum(axis=0) / m.sum()
            m_sys = m.sum()
            m_k = self.mass[cand]
            factor = m_sys / np.where(in_system[cand], m_sys - m_k, m_sys + m_k)
            e = 0.5 * factor * np.sum((self.vel[cand] - v_sys) ** 2, axis=1) + phi[cand]
            now = np.zeros(self.n, dtype=bool)
            now[cand[e < 0.0]] = True
            was = in_system.copy()
            was[is_seed] = False
            added = np.flatnonzero(now & ~was)
            removed = np.flatnonzero(was & ~now)
            if added.size == 0 and removed.size == 0:
                return np.flatnonzero(in_system), True
            if added.size:
                _add_potential(phi, targets, added, self.pos, self.mass, self.radius, self.G, 1.0)
            if removed.size:
                _add_potential(phi, targets, removed, self.pos, self.mass, self.radius, self.G, -1.0)
            in_system[added] = True
            in_system[removed] = False
        logger.warning("bound-system iteration did not converge in %d iterations (seed of %d particles)",
                       max_iterations, seed.shape[0])
        return np.flatnonzero(in_system), False

    def describe(self, members, bound_members, packing_fraction, target_mass) -> Remnant:
        """Remnant properties of ``members`` (see the module docstring for the definitions)."""
        m = self.mass[members]
        r = self.radius[members]
        x = self.pos[members]
        v = self.vel[members]
        mass = float(m.sum())
        com = (m[:, None] * x).sum(axis=0) / mass
        vcom = (m[:, None] * v).sum(axis=0) / mass
        s = x - com
        u = v - vcom
        ang = np.cross(s, u).T @ m
        s2 = np.sum(s * s, axis=1)
        inertia = np.eye(3) * np.sum(m * s2) - (s.T * m) @ s
        omega = np.linalg.pinv(inertia) @ ang
        w = float(np.linalg.norm(omega))
        bulk_radius = float((np.sum(r**3) / packing_fraction) ** (1.0 / 3.0))
        return Remnant(
            members=np.sort(members).astype(np.int64),
            mass=mass,
            n_particles=int(members.shape[0]),
            com=com,
            velocity=vcom,
            bulk_radius=bulk_radius,
            extent=float(np.max(np.sqrt(s2) + r)),
            bulk_density=mass / (4.0 / 3.0 * np.pi * bulk_radius**3),
            angular_momentum=ang,
            angular_velocity=omega,
            spin_period=2.0 * np.pi / w if w > 0.0 else float("inf"),
            bound_members=np.asarray(bound_members, dtype=np.int64),
            bound_mass=float(self.mass[bound_members].sum()),
            mass_fraction=mass / target_mass if target_mass else float("nan"),
        )


def find_remnants(
    mass: np.ndarray,
    radius: np.ndarray,
    position: np.ndarray,
    velocity: np.ndarray,
    *,
    G: float = G_SI,
    link_factor: float = 1.0,
    max_iterations: int = 100,
    mode: str = "aggregate",
    n_remnants: int = 5,
    packing_fraction: float = DEFAULT_PACKING_FRACTION,
    target_mass: float | None = None,
) -> RemnantResult:
    """Find the most massive gravitationally bound remnants (see the module docstring).

    Args:
        mass: (N,) particle masses (kg), > 0.
        radius: (N,) particle radii (m), > 0.
        position: (N, 3) positions (m).
        velocity: (N, 3) velocities (m/s).
        G: gravitational constant (m^3 kg^-1 s^-2).
        link_factor: touching criterion ``|x_i - x_j| <= link_factor (r_i + r_j)``
            ("aggregate" mode).
        max_iterations: cap on the bound-system iterations.
        mode: "aggregate" (touching, self-bound aggregates) or "merge" (largest
            particle plus what is bound to it).
        n_remnants: how many remnants to characterise, most massive first.
        packing_fraction: volume fraction of grains in a remnant, in (0, 1].
        target_mass: M_T (kg) for the mass fractions M_lr/M_T, M_slr/M_T.

    Returns:
        RemnantResult with the remnants sorted by decreasing mass.
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if not 0.0 < packing_fraction <= 1.0:
        raise ValueError(f"packing_fraction must be in (0, 1], got {packing_fraction}")
    if n_remnants < 1 or max_iterations < 1:
        raise ValueError("n_remnants and max_iterations must be >= 1")
    cloud = _Cloud(mass, radius, position, velocity, G)
    if cloud.pos.shape != (cloud.n, 3) or cloud.vel.shape != (cloud.n, 3) or cloud.radius.shape != (cloud.n,):
        raise ValueError("mass (N,), radius (N,), position (N, 3) and velocity (N, 3) must agree")
    if cloud.n and (np.any(cloud.mass <= 0.0) or np.any(cloud.radius <= 0.0)):
        raise ValueError("masses and radii must be positive")

    converged = True
    if mode == "aggregate":
        cores = _aggregate_cores(cloud, link_factor, n_remnants)
        remnants = []
        for core in cores:
            system, ok = cloud.bound_system(core, cloud.all_index, max_iterations)
            converged &= ok
            remnants.append(cloud.describe(core, system, packing_fraction, target_mass))
    else:
        remnants = []
        free = np.ones(cloud.n, dtype=bool)
        while len(remnants) < n_remnants and free.any():
            candidates = np.flatnonzero(free)
            seed = candidates[[np.argmax(cloud.mass[candidates])]]
            system, ok = cloud.bound_system(seed, candidates, max_iterations)
            converged &= ok
            remnants.append(cloud.describe(system, system, packing_fraction, target_mass))
            free[system] = False
        remnants.sort(key=lambda r: -r.mass)

    label = np.full(cloud.n, -1, dtype=np.int64)
    for k, rem in enumerate(remnants):
        label[rem.members] = k
    return RemnantResult(
        remnants=tuple(remnants),
        label=label,
        mode=mode,
        packing_fraction=float(packing_fraction),
        link_factor=float(link_factor),
        total_mass=float(cloud.mass.sum()),
        target_mass=None if target_mass is None else float(target_mass),
        converged=converged,
    )


def _aggregate_cores(cloud: _Cloud, link_factor: float, n_keep: int) -> list[np.ndarray]:
    """The ``n_keep`` most massive self-bound touching aggregates, most massive first.

    Candidate groups sit in a max-heap keyed by mass; a group's bound core is never
    heavier than the group, so the search stops once the heaviest pending group is
    lighter than the n_keep-th core found.
    """
    heap: list[tuple[float, int, np.ndarray]] = []
    counter = 0

    def push_groups(idx: np.ndarray) -> None:
        nonlocal counter
        labels = touching_groups(cloud.pos[idx], cloud.radius[idx], link_factor)
        order = np.argsort(labels, kind="stable")
        bounds = np.flatnonzero(np.diff(labels[order])) + 1
        for group in np.split(idx[order], bounds):
            heapq.heappush(heap, (-float(cloud.mass[group].sum()), counter, group))
            counter += 1

    if cloud.n:
        push_groups(cloud.all_index)
    cores: list[tuple[float, np.ndarray]] = []
    while heap:
        neg_mass, _, group = heapq.heappop(heap)
        if len(cores) >= n_keep and -neg_mass <= cores[-1][0]:
            break
        core, removed = cloud.bound_core(group)
        if removed.size:
            push_groups(removed)
        cores.append((float(cloud.mass[core].sum()), core))
        cores.sort(key=lambda c: -c[0])
        del cores[n_keep:]
    return [c for _, c in cores]
