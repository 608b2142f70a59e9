"""Building the REBOUND simulation: time-step rule, box, particles (SI units).

Time-step rule (leapfrog, fixed step between checks, see ``collision_time_step``):

    dt = min( t_dyn / steps_per_dynamical_time ,  f * L / v )
    t_dyn     = 1 / sqrt(G rho_bulk)
    v_rel_max = 2 max_i |v_i - v_com| + v_esc,   v_esc = sqrt(2 G M / R),
    R         = (3 M / (4 pi rho_bulk))^(1/3)

Two particles approach each other at most at the sum of their speeds in the centre-of-mass
frame, plus what gravity adds on the way, bounded by the escape speed of all the mass
packed at bulk density.  With the ``tree`` collision search, which sees a pair only while it
overlaps, L = r_min and v = v_rel_max: with f <= 1 the relative displacement of any pair in
one step is at most r_min <= (r_i + r_j) / 2, so a head-on pair cannot cross the window in
which it overlaps while still approaching without a step ending inside it.  ``linetree``
checks every pair's straight relative path over the whole step and finds each contact at any
step length; it needs short steps only where particles touch (below).  The first term keeps
orbits resolved: a circular orbit at the surface of a body of density rho_bulk has period
sqrt(3 pi) t_dyn ~ 3.1 t_dyn.
"""

from __future__ import annotations

import math

import numpy as np
import rebound
from scipy.constants import G
from numba import njit
from scipy.spatial import cKDTree

COLLISION_SEARCHES = ("linetree", "tree")


@njit(cache=True)
def weighted_mean(weight, values):
    """sum_i w_i a_i / sum_i w_i for (N,) weights and (N, 3) values, summed in index order.

    A plain sequential loop: the result does not depend on memory alignment (as numpy's
    vectorised reductions can), so quantities that feed back into the simulation are
    reproduced bit for bit by a resumed run.
    """
    total = 0.0
    acc = np.zeros(3)
    for i in range(weight.shape[0]):
        total += weight[i]
        for k in range(3):
            acc[k] += weight[i] * values[i, k]
    return acc / total


def dynamical_time(bulk_density: float) -> float:
    """t_dyn = 1 / sqrt(G rho) (s) for a bulk density rho (kg/m^3)."""
    if not bulk_density > 0:
        raise ValueError(f"bulk_density must be > 0 kg/m^3 (got {bulk_density})")
    return 1.0 / math.sqrt(G * bulk_density)


def relative_speed_bound(mass: np.ndarray, velocity: np.ndarray, bulk_density: float) -> float:
    """v_rel_max = 2 max |v_i - v_com| + sqrt(2 G M / R), R = (3 M / (4 pi rho))^(1/3) (m/s)."""
    mass = np.ascontiguousarray(mass, dtype=float)
    velocity = np.ascontiguousarray(velocity, dtype=float).reshape(-1, 3)
    m_tot = float(mass.sum())
    v_com = weighted_mean(mass, velocity)
    v_max = float(np.sqrt(((velocity - v_com) ** 2).sum(axis=1)).max())
    r_packed = (3.0 * m_tot / (4.0 * math.pi * bulk_density)) ** (1.0 / 3.0)
    return 2.0 * v_max + math.sqrt(2.0 * G * m_tot / r_packed)


def contact_speed(position: np.ndarray, velocity: np.ndarray, radius: np.ndarray, reach: float) -> float:
    """The largest relative speed |v_i - v_j| (m/s) of the pairs within ``reach`` (m) of contact,
    |x_i - x_j| < r_i + r_j + reach; 0 without such pairs.

    A k-d tree (scipy) finds the pairs: all pairs closer than 2 r_q + reach, r_q the 90th
    percentile of the radii, and the neighbours within r_i + r_max + reach of each larger
    particle, then the distances are checked.
    """
    position = np.asarray(position, dtype=float).reshape(-1, 3)
    velocity = np.asarray(velocity, dtype=float).reshape(-1, 3)
    radius = np.asarray(radius, dtype=float)
    if radius.size < 2:
        return 0.0
    tree = cKDTree(position)
    r_q = float(np.quantile(radius, 0.9))
    pairs = tree.query_pairs(2.0 * r_q + reach, output_type="ndarray")
    large = np.flatnonzero(radius > r_q)
    if large.size:
        lists = tree.query_ball_point(position[large], radius[large] + float(radius.max()) + reach)
        counts = np.fromiter((len(found) for found in lists), dtype=np.intp, count=large.size)
        others = np.fromiter((k for found in lists for k in found), dtype=np.intp, count=int(counts.sum()))
        pairs = np.concatenate([pairs.reshape(-1, 2), np.column_stack([np.repeat(large, counts), others])])
    i, j = pairs[:, 0], pairs[:, 1]
    near = (i != j) & (np.linalg.norm(position[i] - position[j], axis=1) < radius[i] + radius[j] + reach)
    if not near.any():
        return 0.0
    return float(np.linalg.norm(velocity[i[near]] - velocity[j[near]], axis=1).max())


def collision_time_step(mass, radius, velocity, *, bulk_density: float,
                        steps_per_dynamical_time: float = 100.0,
                        collision_step_fraction: float = 0.5, collision_search: str = "tree",
                        collision_model: str = "bounce", position=None) -> float:
    """The leapfrog step (s): min(t_dyn / n, f L / v) (module docstring).

    - ``tree`` search: L = r_min, v = v_rel_max.
    - ``linetree`` with perfect merging: L = R_packed = (3 M / (4 pi rho))^(1/3), the radius of
      all the mass at bulk density, v = v_rel_max, which keeps each straight path short against
      the body: with km/s ejecta and 40 m particles the r_min term was 0.017 s, 1e5 times
      shorter than t_dyn / 100, and case 8c's N-body stage would have taken hours.
    - ``linetree`` with the models that bounce (``position`` required): the same path term, and
      resting and grazing contacts resolved, L = r_min against the contact speed

          v_c = max(2 min(v_max, v_esc) + v_esc, contact_speed within r_min of contact)
          dt  = min(t_dyn / n, f R_packed / v_rel_max, f r_min / v_c)

      with v_max = max_i |v_i - v_com| and v_esc the packed escape speed.  For a cloud slower
      than v_esc this is the ``tree`` rule; particles faster than v_esc (ejecta) count only
      through the pairs they form near contact.  A pair in or near contact moves by at most
      f r_min against its partner in one step, so a bounce sees it before it has passed
      through; a pair further apart meets in a step at the contact point the line search
      finds.  On the 10-cell hand-off of case 9a the step at t = 0 is 0.3 s instead of
      0.01 s (docs/nbody.md, "Time step").
    """
    if not 0 < collision_step_fraction <= 1:
        raise ValueError(f"collision_step_fraction must be in (0, 1] (got {collision_step_fraction})")
    if not steps_per_dynamical_time > 0:
        raise ValueError(f"steps_per_dynamical_time must be > 0 (got {steps_per_dynamical_time})")
    t_dyn = dynamical_time(bulk_density)
    v_rel = relative_speed_bound(mass, velocity, bulk_density)
    r_packed = (3.0 * float(np.sum(mass)) / (4.0 * math.pi * bulk_density)) ** (1.0 / 3.0)
    r_min = float(np.min(radius))
    dt = t_dyn / steps_per_dynamical_time
    if collision_search != "linetree":
        return min(dt, collision_step_fraction * r_min / v_rel)
    dt = min(dt, collision_step_fraction * r_packed / v_rel)
    if collision_model == "merge":
        return dt
    if position is None:
        raise ValueError(f"the linetree step of the {collision_model!r} model needs the particle positions")
    v_esc = math.sqrt(2.0 * G * float(np.sum(mass)) / r_packed)
    v_bound = min(v_rel - v_esc, 2.0 * v_esc) + v_esc
    v_contact = max(v_bound, contact_speed(position, velocity, radius, r_min))
    return min(dt, collision_step_fraction * r_min / v_contact)


def build_simulation(position: np.ndarray, velocity: np.ndarray, mass: np.ndarray,
                     radius: np.ndarray, *, dt: float, opening_angle: float,
                     collision_search: str, box_half_width: float, seed: int) -> rebound.Simulation:
    """A leapfrog REBOUND simulation in SI units with tree gravity and open boundaries.

    One root box of side ``2 box_half_width`` (m) centred on the origin.  Particles carry
    no REBOUND ``name``: the Simulationarchive of REBOUND 5.2 stores the name pointers,
    which dangle after loading, so identities travel in an index map (see ``driver``).
    The collision resolver is not set here.
    """
    if collision_search not in COLLISION_SEARCHES:
        raise ValueError(f"collision_search must be one of {COLLISION_SEARCHES} (got {collision_search!r})")
    if not opening_angle > 0:
        raise ValueError(f"opening_angle must be > 0 (got {opening_angle})")
    sim = rebound.Simulation()
    sim.G = G
    sim.integrator = "leapfrog"
    sim.gravity = "tree"
    sim.collision = collision_search
    sim.boundary = "open"
    sim.opening_angle2 = opening_angle * opening_angle
    sim.root_size = 2.0 * box_half_width
    sim.N_root_x = sim.N_root_y = sim.N_root_z = 1
    sim.rand_seed = int(seed)
    sim.dt = dt
    for k in range(len(mass)):
        sim.add(m=float(mass[k]), r=float(radius[k]),
                x=float(position[k, 0]), y=float(position[k, 1]), z=float(position[k, 2]),
                vx=float(velocity[k, 0]), vy=float(velocity[k, 1]), vz=float(velocity[k, 2]))
    return sim
