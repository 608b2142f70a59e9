"""Leaf blocks to N-body spheres: the hand-off rules of the hybrid method.

Each leaf block of the final hydro snapshot becomes spheres of the N-body stage
(docs/handoff.md states every rule with its default and the reference for it):

3d: one sphere per block,

    m = sum_cells sum_k alpha_k rho_k V_c,   x = sum_cells m_c x_c / m,   v = sum_cells m_c v_c / m,

with the radius of the sphere inscribed in the cube of the block's smallest edge,
a = min(dx, dy, dz) / 2.  A half-domain run (y >= 0, symmetry plane y = 0) is first joined
with its mirror image (``mirror_y0``, handoff/mirror.py), so the spheres are the full body's.

2d-cylindrical (r, z): the block is the annulus r_lo..r_hi x z_lo..z_hi, rotated about the
axis z of the output frame.  With the cell masses m_c (full annuli) and the mass-weighted
cell radii r_c = (2/3)(r_hi^3 - r_lo^3)/(r_hi^2 - r_lo^2) (the radial centroid of a
uniform annular cell):

    m = sum m_c,  rbar = sum m_c r_c / m,  zbar = sum m_c z_c / m,
    P_r = sum m_c v_r,c,  P_z = sum m_c v_z,c,
    a = min(dr, dz) / 2,
    n = floor(pi / arcsin(a / rbar))  if rbar > a   (>= 2),   n = 2  if rbar <= a,

the largest number of spheres of radius a whose centres on the ring of radius rbar do not
overlap (chord 2 rbar sin(pi/n) >= 2a; equal to circumference / diameter, 2 pi rbar / 2a, up
to one for rings much wider than a sphere), and 2 overlapping spheres on a ring narrower
than a sphere radius.  Sphere j of the ring sits at
(rbar cos phi_j, rbar sin phi_j, zbar), phi_j = phi_0 + 2 pi j / n with a random phase
phi_0 ~ U[0, 2 pi / n) per ring, has mass m / n and velocity
(P_r/m cos phi_j, P_r/m sin phi_j, P_z/m).  So the ring carries the block's mass, axial
momentum P_z and radial momentum P_r exactly; its radial momenta cancel as vectors (n >= 2,
which also keeps every sphere off the axis: rbar > 0 for any block with mass).

Both geometries, then:

- density floor: the radius is min(a, (3 m / (4 pi rho_min))^(1/3)), rho_min =
  min_density_fraction x target_bulk_density, so no sphere is lighter than rho_min; masses
  are never changed;
- mass floor: blocks with 0 < m < min_mass_fraction x total_mass make no particle; their
  mass, momentum, kinetic energy and count go to the budget;
- velocity noise: each particle gets a velocity increment of fixed magnitude
  velocity_noise x escape_speed in a direction uniform on the unit sphere (normalised
  standard-normal 3-vectors);
- intact fragments (optional, ``intact_label``): each becomes one sphere of its mass at the
  target's bulk density, after the blocks' spheres, and its cells leave their blocks
  (handoff/bodies.py);
- random numbers: one ``numpy.random.default_rng(seed)``; the ring phases are drawn first
  (block order), then the noise directions (particle order).
"""

from __future__ import annotations

import logging

import numpy as np

from scipy.spatial import cKDTree

from impactpipe.handoff.bodies import IntactBodies, split_intact_bodies
from impactpipe.handoff.budget import HandoffBudget
from impactpipe.handoff.mirror import mirror_across_y0
from impactpipe.handoff.moments import block_moments, merge_fine_blocks
from impactpipe.handoff.particles import ParticleSet
from impactpipe.handoff.tracers import block_tracer_records, fill_from_nearest
from impactpipe.hydro.output.snapshot import Snapshot, TracerSet

log = logging.getLogger(__name__)

SUPPORTED_GEOMETRIES = ("3d", "2d-cylindrical")

# Slack on pi / arcsin(a / rbar) before the floor, so that a ring on which n spheres touch
# exactly (rbar sin(pi/n) = a) gets n spheres despite round-off.
_RING_COUNT_SLACK = 1e-12

# Relative depth below which touching spheres (inscribed spheres of adjacent full blocks)
# do not count as overlapping.
_OVERLAP_TOLERANCE = 1e-9


def ring_sphere_count(ring_radius: np.ndarray, sphere_radius: np.ndarray) -> np.ndarray:
    """Number of spheres on a ring: n = floor(pi / arcsin(a / rbar)) if rbar > a, else 2.

    For rbar > a, the largest n for which spheres of radius a centred on the ring of radius
    rbar do not overlap (2 rbar sin(pi / n) >= 2 a); it is >= 2 since arcsin <= pi / 2.
    Narrower rings get 2 (overlapping) spheres so that the ring's radial momenta cancel.

    Args:
        ring_radius: rbar (m), > 0.
        sphere_radius: a (m), > 0.

    Returns:
        int64 array of n.
    """
    ratio = np.asarray(sphere_radius, dtype=float) / np.asarray(ring_radius, dtype=float)
    count = np.full(ratio.shape, 2, dtype=np.int64)
    wide = ratio < 1.0
    count[wide] = np.floor(np.pi / np.arcsin(ratio[wide]) * (1.0 + _RING_COUNT_SLACK)).astype(np.int64)
    return count


def sphere_overlaps(position: np.ndarray, radius: np.ndarray, radius_bound: np.ndarray) -> tuple[int, float]:
    """Pairs of spheres that overlap, |x_i - x_j| < (r_i + r_j)(1 - 1e-9), and the deepest overlap.

    Spheres are grouped by ``radius_bound`` (an upper bound on each radius with few distinct
    values, here the inscribed radius of the source block), and each pair of groups is
    searched with k-d trees out to the sum of their bounds, so the work stays proportional
    to the number of close pairs.

    Args:
        position: (N, 3) centres (m).
        radius: (N,) radii (m).
        radius_bound: (N,) radius_bound >= radius (m).

    Returns:
        (number of overlapping pairs, largest overlap 1 - |x_i - x_j| / (r_i + r_j), 0 if none).
    """
    bounds, group = np.unique(radius_bound, return_inverse=True)
    members = [np.flatnonzero(group == g) for g in range(bounds.size)]
    trees = [cKDTree(position[m]) for m in members]
    count, deepest = 0, 0.0
    for g in range(bounds.size):
        for h in range(g, bounds.size):
            reach = bounds[g] + bounds[h]
            if g == h:
                pairs = trees[g].query_pairs(reach, output_type="ndarray")
                i, j = members[g][pairs[:, 0]], members[g][pairs[:, 1]]
            else:
                near = trees[g].sparse_distance_matrix(trees[h], reach, output_type="ndarray")
                i, j = members[g][near["i"]], members[h][near["j"]]
            depth = 1.0 - np.linalg.norm(position[i] - position[j], axis=1) / (radius[i] + radius[j])
            overlapping = depth > _OVERLAP_TOLERANCE
            count += int(np.count_nonzero(overlapping))
            if overlapping.any():
                deepest = max(deepest, float(depth[overlapping].max()))
    return count, deepest


def blocks_to_spheres(
    snapshot: Snapshot,
    tracers: TracerSet | None = None,
    *,
    target_bulk_density: float,
    total_mass: float,
    escape_speed: float,
    projectile_material_index: int | None = None,
    porous_materials: np.ndarray | None = None,
    min_density_fraction: float = 0.75,
    min_mass_fraction: float = 4e-7,
    velocity_noise: float = 0.01,
    seed: int = 1,
    mass_left_mesh: float | None = None,
    mirror_y0: bool = False,
    block_edge: float | None = None,
    intact_label: np.ndarray | None = None,
) -> tuple[ParticleSet, HandoffBudget]:
    """Translate the leaf blocks of a hydro snapshot into N-body spheres.

    The rules are in the module docstring and docs/handoff.md.  With ``mirror_y0`` the
    snapshot is a half-domain 3d run (y >= 0, symmetry plane y = 0): it and its tracers are
    first joined with their mirror images (:func:`impactpipe.handoff.mirror.mirror_across_y0`),
    so the particles and the budget describe the full body.

    Args:
        snapshot: the hand-off snapshot, geometry "3d" or "2d-cylindrical".
        tracers: the tracer set at the same time, or None.
        target_bulk_density: the target's original bulk density rho_T (kg/m^3).
        total_mass: M_tot, the mass the mass floor refers to (kg), normally target plus
            projectile.
        escape_speed: the escape speed the velocity noise refers to (m/s).
        projectile_material_index: index of the projectile material in
            ``snapshot.material_names``; None gives projectile_fraction NaN (unknown).
        porous_materials: (M,) booleans, the porous materials of ``snapshot.material_names``
            (docs/eos.md, "Porosity"), or None: each particle's ``distension`` is the
            mass-weighted distension of its material (1 + E / m,
            :mod:`impactpipe.handoff.moments`), 1 without porous materials.
        min_density_fraction: density floor rho_min = min_density_fraction x rho_T.
        min_mass_fraction: blocks below min_mass_fraction x total_mass make no particle.
        velocity_noise: noise speed as a fraction of ``escape_speed``.
        seed: seed of ``numpy.random.default_rng`` (ring phases, then noise).
        mass_left_mesh: mass that left the mesh before hand-off (kg), carried in the budget;
            with ``mirror_y0``, that of the full body (twice the half-domain run's).
        mirror_y0: mirror a half-domain 3d snapshot across y = 0 first.
        block_edge: make the spheres from blocks of at least this edge (m): leaf blocks
            narrower than it are merged into their ancestor of this edge first
            (:func:`impactpipe.handoff.moments.merge_fine_blocks`); None takes the leaf
            blocks as they are.
        intact_label: (NB, nx, ny, nz) int, the intact fragment of each cell (0, 1, ...) or
            -1: each fragment becomes one sphere of its mass at ``target_bulk_density``
            instead of a part of its blocks' spheres (:mod:`impactpipe.handoff.bodies`);
            the ids of those spheres follow the blocks'.  Not with ``mirror_y0``: label the
            mirrored snapshot (:func:`impactpipe.handoff.mirror.mirror_across_y0`).

    Returns:
        The particles (ids 1..N in block order) and the hand-off budget.
    """
    _check_arguments(snapshot, target_bulk_density, total_mass, escape_speed, projectile_material_index,
                     min_density_fraction, min_mass_fraction, velocity_noise, mass_left_mesh)
    if mirror_y0:
        if intact_label is not None:
            raise ValueError("intact_label labels a whole snapshot: mirror it first and pass mirror_y0=False")
        snapshot, tracers = mirror_across_y0(snapshot, tracers)
    bodies = None
    if intact_label is not None:
        snapshot, bodies = split_intact_bodies(snapshot, intact_label, target_bulk_density, porous_materials)
    cylindrical = snapshot.geometry == "2d-cylindrical"
    leaf_moments = block_moments(snapshot, porous=porous_materials)
    moments = leaf_moments if block_edge is None else merge_fine_blocks(leaf_moments, snapshot.ndim, block_edge)
    mass_floor = min_mass_fraction * total_mass
    density_floor = min_density_fraction * target_bulk_density
    noise_speed = velocity_noise * escape_speed
    rng = np.random.default_rng(seed)

    nonempty = moments.mass > 0.0
    kept = np.flatnonzero(nonempty & (moments.mass >= mass_floor))
    dropped = np.flatnonzero(nonempty & (moments.mass < mass_floor))
    block_mass = moments.mass[kept]
    block_velocity = moments.momentum[kept] / block_mass[:, None]
    sphere_radius = 0.5 * moments.min_edge[kept]

    if cylindrical:
        ring_radius = moments.centre[kept, 0]
        per_ring = ring_sphere_count(ring_radius, sphere_radius)
        phase0 = rng.uniform(0.0, 2.0 * np.pi / per_ring)
        source = np.repeat(np.arange(kept.size), per_ring)
        first = np.cumsum(per_ring) - per_ring
        index_in_ring = np.arange(source.size) - first[source]
        phi = phase0[source] + 2.0 * np.pi * index_in_ring / per_ring[source]
        cos_phi, sin_phi = np.cos(phi), np.sin(phi)
        mass = block_mass[source] / per_ring[source]
        position = np.column_stack([ring_radius[source] * cos_phi, ring_radius[source] * sin_phi,
                                    moments.centre[kept, 1][source]])
        v_r = block_velocity[source, 0]
        velocity = np.column_stack([v_r * cos_phi, v_r * sin_phi, block_velocity[source, 1]])
    else:
        source = np.arange(kept.size)
        mass = block_mass
        position = moments.centre[kept].copy()
        velocity = block_velocity
    block = kept[source]

    radius_cap = np.cbrt(3.0 * mass / (4.0 * np.pi * density_floor)) if density_floor > 0.0 else np.inf
    radius = np.minimum(sphere_radius[source], radius_cap)
    shrunk = int(np.count_nonzero(radius < sphere_radius[source]))
    radius_bound = sphere_radius[source]
    if bodies is not None:
        mass = np.concatenate([mass, bodies.mass])
        position = np.concatenate([position, bodies.position])
        velocity = np.concatenate([velocity, bodies.velocity])
        radius = np.concatenate([radius, bodies.radius])
        radius_bound = np.concatenate([radius_bound, bodies.radius])
    n_particles = mass.size
    from_block = np.arange(n_particles) < block.size
    overlapping_pairs, deepest_overlap = sphere_overlaps(position, radius, radius_bound)

    direction = rng.standard_normal((n_particles, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    velocity_with_noise = velocity + noise_speed * direction

    records = block_tracer_records(tracers, moments.lo, moments.hi, snapshot.ndim, moments.material_mass)

    def per_particle(block_values: np.ndarray, body_value) -> np.ndarray:
        """A per-block record for every particle; ``body_value`` for the intact bodies' spheres."""
        out = np.empty((n_particles, *block_values.shape[1:]), dtype=block_values.dtype)
        out[from_block] = block_values[block]
        out[~from_block] = body_value
        return out

    tracer_count = per_particle(records.count, 0)
    peak_pressure_mean = fill_from_nearest(position, per_particle(records.peak_pressure_mean, np.nan), tracer_count > 0)
    if projectile_material_index is None:
        projectile_fraction = np.full(n_particles, np.nan)
    else:
        fraction = np.zeros(moments.mass.size)
        np.divide(moments.material_mass[:, projectile_material_index], moments.mass, out=fraction,
                  where=moments.mass > 0.0)
        projectile_fraction = per_particle(fraction, np.nan)
        if bodies is not None:
            projectile_fraction[~from_block] = bodies.material_mass[:, projectile_material_index] / bodies.mass
    excess_ratio = np.zeros(moments.mass.size)
    np.divide(moments.distension_excess, moments.mass, out=excess_ratio, where=moments.mass > 0.0)
    distension = per_particle(1.0 + excess_ratio, 1.0)
    if bodies is not None:
        distension[~from_block] = 1.0 + bodies.distension_excess / bodies.mass

    particles = ParticleSet(
        id=np.arange(1, n_particles + 1, dtype=np.int64),
        mass=mass,
        radius=radius,
        position=position,
        velocity=velocity_with_noise,
        tracer_count=tracer_count.astype(np.int64),
        peak_pressure_mean=peak_pressure_mean,
        peak_pressure_max=per_particle(records.peak_pressure_max, np.nan),
        origin_position=per_particle(records.origin_position, np.nan),
        projectile_fraction=projectile_fraction,
        distension=distension,
        source_level=per_particle(moments.level, -1),
        source_block=per_particle(moments.block_id, -1),
    )

    def frame_momentum(idx: np.ndarray) -> np.ndarray:
        """Momentum of blocks ``idx`` in the output frame: (0, 0, P_z) for 2d-cylindrical."""
        p = moments.momentum[idx].sum(axis=0)
        return np.array([0.0, 0.0, p[1]]) if cylindrical else p

    def radial_momentum(idx: np.ndarray) -> float | None:
        """Scalar radial momentum sum m_c v_r,c of blocks ``idx`` (2d-cylindrical), else None."""
        return float(moments.momentum[idx, 0].sum()) if cylindrical else None

    if cylindrical:
        ring = position[from_block, :2]
        unit_r = ring / np.hypot(ring[:, 0], ring[:, 1])[:, None]
        particle_radial = float((mass[from_block] * (velocity[from_block, :2] * unit_r).sum(axis=1)).sum())
    else:
        particle_radial = None
    if bodies is None:
        bodies = IntactBodies.none(snapshot.partial_density.shape[1])
    body_momentum = (bodies.mass[:, None] * bodies.velocity).sum(axis=0)
    body_radial = float(bodies.radial_momentum.sum())
    n_tracers = 0 if tracers is None else len(tracers)
    tracers_used = int(records.count[kept].sum())
    all_blocks = np.arange(moments.mass.size)
    budget = HandoffBudget(
        geometry=snapshot.geometry,
        n_blocks=int(leaf_moments.mass.size),
        n_particles=int(n_particles),
        total_mass=float(total_mass),
        mesh_mass=float(moments.mass.sum() + bodies.mass.sum()),
        mesh_momentum=frame_momentum(all_blocks) + body_momentum,
        mesh_kinetic_energy=float(moments.kinetic_energy.sum() + bodies.kinetic_energy.sum()),
        mesh_radial_momentum=None if not cylindrical else radial_momentum(all_blocks) + body_radial,
        particle_mass=float(mass.sum()),
        particle_momentum=(mass[:, None] * velocity).sum(axis=0),
        particle_momentum_with_noise=(mass[:, None] * velocity_with_noise).sum(axis=0),
        particle_kinetic_energy=float(0.5 * (mass * (velocity**2).sum(axis=1)).sum()),
        particle_kinetic_energy_with_noise=float(0.5 * (mass * (velocity_with_noise**2).sum(axis=1)).sum()),
        particle_radial_momentum=particle_radial,
        dropped_mass=float(moments.mass[dropped].sum()),
        dropped_momentum=frame_momentum(dropped),
        dropped_kinetic_energy=float(moments.kinetic_energy[dropped].sum()),
        dropped_radial_momentum=radial_momentum(dropped),
        dropped_count=int(dropped.size),
        radius_shrunk_count=shrunk,
        overlapping_pairs=overlapping_pairs,
        deepest_overlap=deepest_overlap,
        tracers_total=n_tracers,
        tracers_used=tracers_used,
        tracers_exited=records.exited,
        tracers_outside=records.outside,
        tracers_in_dropped=int(records.count.sum()) - tracers_used,
        mass_left_mesh=None if mass_left_mesh is None else float(mass_left_mesh),
        density_floor=float(density_floor),
        mass_floor=float(mass_floor),
        noise_speed=float(noise_speed),
        seed=int(seed),
        mirrored_y0=bool(mirror_y0),
        block_edge=None if block_edge is None else float(block_edge),
        sphere_blocks=int(moments.mass.size),
        intact_bodies=bodies.count,
        intact_mass=float(bodies.mass.sum()),
        intact_radial_momentum=body_radial if cylindrical else None,
        intact_rings_left=bodies.rings_left,
        intact_internal_kinetic_energy=bodies.internal_kinetic_energy,
    )
    # A meshed body's mass differs from the analytic one by its surface discretisation
    # (~1e-4 at 10 cells per radius); more than 1 % above M_tot means a wrong total_mass.
    if budget.mesh_mass > total_mass * 1.01:
        log.warning("mesh mass %.6e kg exceeds total_mass %.6e kg by more than 1 %%", budget.mesh_mass, total_mass)
    if records.outside:
        log.warning("%d tracers not flagged exited lie in no leaf block", records.outside)
    if block_edge is not None:
        log.info("hand-off: %d leaf blocks merged into %d blocks of edge >= %.4g m", budget.n_blocks,
                 budget.sphere_blocks, block_edge)
    if bodies.count or bodies.rings_left:
        log.info("hand-off: %d intact fragments (%.3e kg) made single spheres, discarding %.3e J of motion "
                 "inside them; %d off-axis fragments left to their blocks", bodies.count, budget.intact_mass,
                 budget.intact_internal_kinetic_energy, bodies.rings_left)
    log.info("hand-off: %d blocks -> %d particles; %d blocks dropped (%.3e kg); %d radii shrunk; "
             "%d overlapping pairs (deepest %.2f); %d tracers used", budget.sphere_blocks, n_particles,
             budget.dropped_count, budget.dropped_mass, shrunk, overlapping_pairs, deepest_overlap, tracers_used)
    return particles, budget


def _check_arguments(snapshot, target_bulk_density, total_mass, escape_speed, projectile_material_index,
                     min_density_fraction, min_mass_fraction, velocity_noise, mass_left_mesh) -> None:
    """Raise ValueError for a geometry, snapshot field or parameter the hand-off cannot use."""
    if snapshot.geometry not in SUPPORTED_GEOMETRIES:
        raise ValueError(f"hand-off needs geometry in {SUPPORTED_GEOMETRIES}, got {snapshot.geometry!r}")
    positive = {"target_bulk_density": target_bulk_density, "total_mass": total_mass}
    for name, value in positive.items():
        if not (np.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be positive and finite (got {value})")
    non_negative = {"escape_speed": escape_speed, "min_density_fraction": min_density_fraction,
                    "min_mass_fraction": min_mass_fraction, "velocity_noise": velocity_noise}
    if mass_left_mesh is not None:
        non_negative["mass_left_mesh"] = mass_left_mesh
    for name, value in non_negative.items():
        if not (np.isfinite(value) and value >= 0.0):
            raise ValueError(f"{name} must be >= 0 and finite (got {value})")
    n_materials = snapshot.partial_density.shape[1]
    if projectile_material_index is not None and not 0 <= projectile_material_index < n_materials:
        raise ValueError(f"projectile_material_index must lie in [0, {n_materials - 1}] "
                         f"(got {projectile_material_index})")
    density = snapshot.partial_density
    if not np.all(np.isfinite(density)) or np.any(density < 0.0):
        raise ValueError("snapshot partial_density must be finite and >= 0")
