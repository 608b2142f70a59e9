"""Initial tracer layouts: rays from the impact point and cubic lattices filling spheres."""

from __future__ import annotations

import math

import numpy as np

from impactpipe.hydro.tracers.locate import as_positions

def place_on_rays(impact_point, target_radius: float, target_center_z: float, n_rays: int = 30,
                  count: int = 900, projectile_radius: float | None = None,
                  projectile_center_z: float | None = None, projectile_cells: int = 4):
    """Tracers for a head-on 2d-cylindrical impact: rays through the target plus a projectile grid.

    Target (material 0): ``n_rays`` rays leave the impact point (r = 0, z_i) on the axis,
    at angles theta_i = (i + 1/2) pi / (2 n_rays), i = 0..n_rays-1, from the direction
    pointing at the target centre (0, z_c) towards +r.  Ray i carries m = count / n_rays
    tracers at distances s_j = (j + 1/2) L_i / m, j = 0..m-1, with L_i the chord to the far
    surface, L = |h| cos theta + sqrt(R^2 - h^2 sin^2 theta), h = z_i - z_c (2 R cos theta
    for an impact point on the surface).  Positions (s sin theta, z_i - sign(h) s cos theta, 0);
    equal numbers per ray put more tracers near the impact point, where the peak pressure
    falls fastest.  The impact point must lie on the axis inside or on the target (|h| <= R);
    with z_i = z_c the rays point to -z.

    Projectile (material 1, when ``projectile_radius`` is given): cell-centred points of a
    square grid of spacing R_p / ``projectile_cells`` in the half-disk r > 0 of the projectile
    centred at (0, ``projectile_center_z``).

    Returns (positions (N, 3) m, materials (N,) int64).
    """
    r_i, z_i = (float(v) for v in impact_point)
    radius = float(target_radius)
    h = z_i - float(target_center_z)
    if r_i != 0.0:
        raise ValueError("place_on_rays: the impact point must be on the symmetry axis (r = 0)")
    if abs(h) > radius:
        raise ValueError("place_on_rays: the impact point lies outside the target")
    if n_rays < 1 or count < n_rays or count % n_rays:
        raise ValueError(f"count ({count}) must be a positive multiple of n_rays ({n_rays})")
    per_ray = count // n_rays
    toward = -1.0 if h >= 0.0 else 1.0
    theta = (np.arange(n_rays) + 0.5) * (0.5 * np.pi / n_rays)
    chord = abs(h) * np.cos(theta) + np.sqrt(radius**2 - h**2 * np.sin(theta) ** 2)
    s = (np.arange(per_ray) + 0.5)[None, :] / per_ray * chord[:, None]
    pos = np.zeros((count, 3))
    pos[:, 0] = (s * np.sin(theta)[:, None]).ravel()
    pos[:, 1] = (z_i + toward * s * np.cos(theta)[:, None]).ravel()
    mats = np.zeros(count, dtype=np.int64)
    if projectile_radius is None:
        return pos, mats
    if projectile_center_z is None:
        raise ValueError("place_on_rays: projectile_center_z is needed with projectile_radius")
    n = int(projectile_cells)
    step = float(projectile_radius) / n
    r = (np.arange(n) + 0.5) * step
    z = float(projectile_center_z) + (np.arange(2 * n) + 0.5 - n) * step
    rr, zz = np.meshgrid(r, z, indexing="ij")
    keep = rr**2 + (zz - float(projectile_center_z)) ** 2 < float(projectile_radius) ** 2
    proj = np.zeros((int(keep.sum()), 3))
    proj[:, 0] = rr[keep]
    proj[:, 1] = zz[keep]
    return np.concatenate([pos, proj]), np.concatenate([mats, np.ones(proj.shape[0], dtype=np.int64)])


def _ball_lattice(center, radius: float, spacing: float) -> np.ndarray:
    """Cell-centred lattice points of ``spacing`` (m) strictly inside the ball (disk) of ``radius``."""
    center = np.asarray(center, dtype=float)
    n = int(math.ceil(radius / spacing))
    axis = (np.arange(2 * n) + 0.5 - n) * spacing
    grid = np.stack(np.meshgrid(*([axis] * center.size), indexing="ij"), axis=-1).reshape(-1, center.size)
    return center + grid[(grid**2).sum(axis=1) < radius**2]


def place_on_grid(target_center, target_radius: float, projectile_center, projectile_radius: float,
                  spacing: float, projectile_spacing: float | None = None):
    """Tracers on uniform grids filling the target (material 0) and the projectile (material 1).

    For 3d (centres with 3 components; 2 components give a 2d-planar layout).  Each body
    gets the cell-centred points c + (i + 1/2 - n) h (per axis, n = ceil(R / h)) inside its
    sphere, h = ``spacing`` for the target and ``projectile_spacing`` (default
    min(spacing, R_p / 4)) for the projectile, so a small projectile still carries tracers.

    Returns (positions (N, 3) m, materials (N,) int64).
    """
    if spacing <= 0.0:
        raise ValueError("spacing must be > 0")
    h_p = min(spacing, projectile_radius / 4.0) if projectile_spacing is None else float(projectile_spacing)
    target = _ball_lattice(target_center, float(target_radius), float(spacing))
    proj = _ball_lattice(projectile_center, float(projectile_radius), h_p)
    pos = as_positions(np.concatenate([target, proj]))
    mats = np.concatenate([np.zeros(len(target), dtype=np.int64), np.ones(len(proj), dtype=np.int64)])
    return pos, mats
