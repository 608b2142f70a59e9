"""Intact fragments as single N-body spheres at the hand-off.

A run with material strength can leave, at the hand-off, connected regions of material that
has not failed (damage below a threshold): the fragments of docs/analysis.md, "Fragments".
Cut into block spheres, such a fragment becomes many particles that the N-body stage treats
as loose rubble; as one body it moves as the coherent piece it is.  The orchestrator finds the
fragments (:func:`impactpipe.analysis.fragments.find_fragments`) and gives a label per cell,
the fragment the cell belongs to or -1; :func:`split_intact_bodies` makes each labelled
fragment one sphere and takes its cells out of their blocks, whose spheres carry the rest:

    m = sum_c m_c,   x = sum_c m_c x_c / m,   v = sum_c m_c v_c / m,
    a = (3 m / (4 pi rho_T))^(1/3),

with m_c, x_c, v_c the cells' masses (kg), centres of mass (m) and velocities (m/s), and a the
radius (m) of a sphere of the fragment's mass at the target's bulk density rho_T (kg/m^3).

2d-cylindrical (r, z): a fragment is a body of revolution.  One that reaches the axis (one of
its cells has r_lo = 0) becomes one sphere on the axis, at (0, 0, zbar) with velocity
(0, 0, P_z / m); its scalar radial momentum sum_c m_c v_r,c (its expansion about the axis) has
no place on a sphere there and is reported as ``radial_momentum``, as is the kinetic energy
of the motion inside each fragment (``kinetic_energy`` holds the cells' sum).  A fragment that
does not reach the axis is a ring: it stays with its blocks (counted in ``rings_left``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from impactpipe.handoff.moments import cell_distension_excess
from impactpipe.hydro.output.snapshot import Snapshot


@dataclass
class IntactBodies:
    """The F intact fragments made single spheres (M materials; output 3D Cartesian frame).

    Attributes:
        mass: (F,) kg.
        position: (F, 3) centres of mass (m).
        velocity: (F, 3) mass-weighted velocities (m/s).
        radius: (F,) radius of the sphere of mass m at the target's bulk density (m).
        material_mass: (F, M) mass of each material (kg).
        kinetic_energy: (F,) sum_c m_c |v_c|^2 / 2 over the fragment's cells (J).
        radial_momentum: (F,) 2d-cylindrical: sum_c m_c v_r,c, not carried by the sphere on
            the axis (kg m/s); 0 in 3d.
        cells: (F,) cells of each fragment.
        rings_left: 2d-cylindrical fragments that do not reach the axis, left to their blocks.
        distension_excess: (F,) sum_c m_por,c (d_c - 1) over the fragment's cells (kg): its
            mass-weighted distension is 1 + this / mass (:mod:`impactpipe.handoff.moments`).
    """

    mass: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    radius: np.ndarray
    material_mass: np.ndarray
    kinetic_energy: np.ndarray
    radial_momentum: np.ndarray
    cells: np.ndarray
    rings_left: int
    distension_excess: np.ndarray

    @classmethod
    def none(cls, n_materials: int) -> "IntactBodies":
        """No fragment made a single sphere."""
        return cls(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, n_materials)),
                   np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64), 0, np.zeros(0))

    @property
    def count(self) -> int:
        """Number of fragments made single spheres."""
        return int(self.mass.size)

    @property
    def internal_kinetic_energy(self) -> float:
        """Kinetic energy of the motion inside the fragments, which their spheres do not carry (J):
        sum_c m_c |v_c|^2 / 2 - sum_f m_f |v_f|^2 / 2 (in 2d-cylindrical, with their radial motion)."""
        return float(self.kinetic_energy.sum() - 0.5 * (self.mass * (self.velocity**2).sum(axis=1)).sum())


def split_intact_bodies(snapshot: Snapshot, label: np.ndarray, bulk_density: float,
                        porous: np.ndarray | None = None) -> tuple[Snapshot, IntactBodies]:
    """(the snapshot without the fragments' cells, the fragments as spheres); module docstring.

    Args:
        snapshot: the hand-off snapshot (a half-domain 3d run already mirrored).
        label: (NB, nx, ny, nz) int, the fragment of each cell (0, 1, ...) or -1.
        bulk_density: rho_T, the density of the fragments' spheres (kg/m^3).
        porous: (M,) booleans of the porous materials, or None
            (:func:`impactpipe.handoff.moments.cell_distension_excess`).
    """
    label = np.asarray(label, dtype=np.int64)
    if label.shape != snapshot.pressure.shape:
        raise ValueError(f"label must have the snapshot's cell shape {snapshot.pressure.shape}, got {label.shape}")
    if not (np.isfinite(bulk_density) and bulk_density > 0.0):
        raise ValueError(f"bulk_density must be positive and finite (got {bulk_density})")
    ndim = snapshot.ndim
    cylindrical = snapshot.geometry == "2d-cylindrical"
    n_materials = snapshot.partial_density.shape[1]
    count = int(label.max()) + 1 if label.size else 0
    rings_left = 0
    if cylindrical and count:
        on_axis = np.zeros(count, dtype=bool)
        first_column = label[:, 0][snapshot.block_lo[:, 0] == 0.0]
        on_axis[first_column[first_column >= 0]] = True
        rings_left = int(count - on_axis.sum())
        renumber = np.full(count + 1, -1, dtype=np.int64)
        renumber[:count][on_axis] = np.arange(int(on_axis.sum()))
        label = renumber[label]
        count = int(on_axis.sum())
    cells = label >= 0
    volume = snapshot.block_cell_volumes()
    material_cell_mass = snapshot.partial_density * volume[:, None]
    which = label[cells]
    material_mass = np.stack([np.bincount(which, weights=material_cell_mass[:, k][cells], minlength=count)
                              for k in range(n_materials)], axis=1).reshape(count, n_materials)
    cell_mass = material_cell_mass.sum(axis=1)[cells]
    mass = material_mass.sum(axis=1)
    if np.any(mass <= 0.0):
        raise ValueError("every labelled fragment must hold mass")
    coords = snapshot.block_cell_centers()[:, :ndim]
    if cylindrical:
        edges = snapshot.cell_edges(0)
        r_lo, r_hi = edges[:, :-1], edges[:, 1:]
        coords[:, 0] = ((2.0 / 3.0) * (r_hi**3 - r_lo**3) / (r_hi**2 - r_lo**2))[:, :, None, None]
    velocity = snapshot.velocity[:, :ndim]

    def mean(field: np.ndarray) -> np.ndarray:
        return np.stack([np.bincount(which, weights=cell_mass * field[:, d][cells], minlength=count)
                         for d in range(ndim)], axis=1) / mass[:, None]

    centre, mean_velocity = mean(coords), mean(velocity)
    position = np.zeros((count, 3))
    body_velocity = np.zeros((count, 3))
    if cylindrical:
        position[:, 2], body_velocity[:, 2] = centre[:, 1], mean_velocity[:, 1]
        radial_momentum = mass * mean_velocity[:, 0]
    else:
        position[:, :ndim], body_velocity[:, :ndim] = centre, mean_velocity
        radial_momentum = np.zeros(count)
    speed2 = (velocity**2).sum(axis=1)[cells]
    excess = cell_distension_excess(snapshot, porous)
    bodies = IntactBodies(
        mass=mass,
        position=position,
        velocity=body_velocity,
        radius=np.cbrt(3.0 * mass / (4.0 * np.pi * bulk_density)),
        material_mass=material_mass,
        kinetic_energy=0.5 * np.bincount(which, weights=cell_mass * speed2, minlength=count),
        radial_momentum=radial_momentum,
        cells=np.bincount(which, minlength=count),
        rings_left=rings_left,
        distension_excess=np.zeros(count) if excess is None else np.bincount(which, weights=excess[cells],
                                                                              minlength=count),
    )
    keep = ~cells[:, None]
    rest = replace(snapshot, partial_density=np.where(keep, snapshot.partial_density, 0.0),
                   volume_fraction=np.where(keep, snapshot.volume_fraction, 0.0))
    return rest, bodies
