"""Building the REBOUND simulation: time-step rule, box, particles (SI units).

Time-step rule (leapfrog, fixed step, only ever reduced during a run):

    dt = min( t_dyn / steps_per_dynamical_time ,  f * r_min / v_rel_max )
    t_dyn     = 1 / sqrt(G rho_bulk)
    v_rel_max = 2 max_i |v_i - v_com| + v_esc,   v_esc = sqrt(2 G M / R),
    R         = (3 M / (4 pi rho_bulk))^(1/3)

Two particles approach each other at most at the sum of their speeds in the centre-of-mass
frame, plus what gravity adds on the way, bounded by the escape speed of all the mass
packed at bulk density.  With f <= 1 the relative displacement of any pair in one step is
at most r_min <= (r_i + r_j) / 2, so a head-on pair cannot cross the window in which it
overlaps while still approaching without a step ending inside it (the condition REBOUND's
``tree`` collision search needs; ``linetree`` checks the straight path over the whole step
and needs it only for bounces to see the pair before it separates).  The first term keeps
orbits resolved: a circular orbit at the surface of a body of density rho_bulk has period
sqrt(3 pi) t_dyn ~ 3.1 t_dyn.
"""

from __future__ import annotations

import math

import numpy as np
import rebound
from numba import njit

G = 6.674e-11  # m^3 kg^-1 s^-2
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


def collision_time_step(mass, radius, velocity, *, bulk_density: float,
                        steps_per_dynamical_time: float = 100.0,
                        collision_step_fraction: float = 0.5, collision_search: str = "tree",
                        collision_model: str = "bounce") -> float:
    """The leapfrog step (s): min(t_dyn / n, f L / v_rel_max).

    L = r_min for the ``tree`` search, which sees a pair only while it overlaps, and for the
    models that bounce (resting contacts need steps short against a particle).  Perfect
    merging with the ``linetree`` search, which checks every pair's straight relative path
    over the whole step and so misses no contact at any step length, uses
    L = R_packed = (3 M / (4 pi rho))^(1/3), the radius of all the mass at bulk density, which
    keeps each straight path short against the body: with km/s ejecta and 40 m particles the
    r_min term was 0.017 s, 1e5 times shorter than t_dyn / 100, and case 8c's N-body stage
    would have taken hours.
    """
    if not 0 < collision_step_fraction <= 1:
        raise ValueError(f"collision_step_fraction must be in (0, 1] (got {collision_step_fraction})")
    if not steps_per_dynamical_time > 0:
        raise ValueError(f"steps_per_dynamical_time must be > 0 (got {steps_per_dynamical_time})")
    t_dyn = dynamical_time(bulk_density)
    if collision_search == "linetree" and collision_model == "merge":
        length = (3.0 * float(np.sum(mass)) / (4.0 * math.pi * bulk_density)) ** (1.0 / 3.0)
    else:
        length = float(np.min(radius))
    v_rel = relative_speed_bound(mass, velocity, bulk_density)
    return min(t_dyn / steps_per_dynamical_time, collision_step_fraction * length / v_rel)


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
