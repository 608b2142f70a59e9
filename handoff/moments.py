"""Per-block sums of a hydro snapshot for the hand-off, and the merging of fine blocks.

:func:`block_moments` sums each leaf block's cells: with the cell masses
m_c = sum_k alpha_k rho_k V_c (kg) and cell velocities v_c (m/s),

    m = sum_c m_c,   x = sum_c m_c x_c / m,   p = sum_c m_c v_c,   K = sum_c m_c |v_c|^2 / 2,

in mesh components ((x, y, z) in 3d; (r, z) in 2d-cylindrical, where x_c of a cell is its
radial centroid for uniform density, r_c = (2/3)(r_hi^3 - r_lo^3) / (r_hi^2 - r_lo^2)).

:func:`merge_fine_blocks` makes the hand-off see a coarser mesh than the hydro stage ran
(``handoff.particle_resolution``): every leaf block whose smallest edge is below ``edge`` is
merged with the other leaves inside its ancestor block of that edge (the block the mesh
would have had ``log2(edge / block edge)`` levels coarser).  The ancestor's sums are the sums
of its leaves' (mass, momentum, cell kinetic energy and material masses add; the centre of
mass is their mass-weighted mean), so mass and momentum are those of the mesh exactly and
the kinetic energy of the velocity dispersion inside the ancestor is what its sphere does
not carry (``HandoffBudget.unresolved_kinetic_energy``).  Leaves tile the domain, so an
ancestor region is either covered by finer leaves, all merged, or lies inside one leaf at
least ``edge`` wide, which stays as it is.

Porous materials (docs/eos.md, "Porosity"): with ``porous`` (the (M,) mask of the porous
materials) and the snapshot's ``distension`` field d_c (the porous materials' mass-weighted
distension rho_solid / rho of a cell), a block also sums

    E = sum_c m_por,c (d_c - 1)      (kg),   m_por,c = sum_(k porous) alpha_k rho_k V_c,

so that 1 + E / m is the mass-weighted distension of all its mass (a non-porous material
counting alpha = 1), and E adds over merged blocks; without porous materials E = 0.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from impactpipe.hydro.output.snapshot import Snapshot

#: Relative slack when comparing block edges (they are sums of binary fractions of the root edge).
_EDGE_TOLERANCE = 1e-9


@dataclass
class BlockMoments:
    """Per-block sums over cells (NB blocks, M materials), in mesh components.

    material_mass: (NB, M) kg.  mass: (NB,) kg.
    centre: (NB, 3) centre of mass (m): (x, y, z) in 3d, (rbar, zbar, 0) in 2d-cylindrical.
    momentum: (NB, 3) kg m/s: (px, py, pz) in 3d, (P_r, P_z, 0) in 2d-cylindrical.
    kinetic_energy: (NB,) sum_cells m_c |v_c|^2 / 2 (J).
    min_edge: (NB,) smallest block edge on the axes in use (m).
    lo, hi: (NB, 3) block corners (m).
    level: (NB,) refinement level of the block (0 = root).
    block_id: (NB,) the snapshot's block id (a merged block: that of its first leaf).
    distension_excess: (NB,) E = sum_c m_por,c (d_c - 1) (kg): the block's mass-weighted distension
        is 1 + E / m (module docstring); 0 without porous materials.
    """

    material_mass: np.ndarray
    mass: np.ndarray
    centre: np.ndarray
    momentum: np.ndarray
    kinetic_energy: np.ndarray
    min_edge: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    level: np.ndarray
    block_id: np.ndarray
    distension_excess: np.ndarray


def cell_distension_excess(snapshot: Snapshot, porous: np.ndarray | None) -> np.ndarray | None:
    """m_por,c (d_c - 1) (kg) per cell (module docstring), (NB, nx, ny, nz).  ``porous``: (M,)
    booleans of the porous materials, or None; None where there are none (or the snapshot has no
    ``distension`` field)."""
    if porous is None or "distension" not in snapshot.extra or not np.any(porous):
        return None
    mask = np.asarray(porous, dtype=bool)
    porous_mass = snapshot.partial_density[:, mask].sum(axis=1) * snapshot.block_cell_volumes()
    return np.where(porous_mass > 0.0, porous_mass * (snapshot.extra["distension"] - 1.0), 0.0)


def block_moments(snapshot: Snapshot, chunk: int = 2048, porous: np.ndarray | None = None) -> BlockMoments:
    """Mass, centre of mass, momentum, kinetic energy and distension excess (``porous``: the (M,) mask
    of the porous materials, :func:`cell_distension_excess`) of every leaf block.

    Blocks are processed ``chunk`` at a time so that the cell-sized temporaries stay small.
    """
    parts = [_chunk_moments(_block_range(snapshot, start, start + chunk), porous)
             for start in range(0, snapshot.block_lo.shape[0], chunk)]
    if not parts:
        n_materials = snapshot.partial_density.shape[1]
        return BlockMoments(np.zeros((0, n_materials)), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)),
                            np.zeros(0), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)),
                            np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0))
    return BlockMoments(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(BlockMoments)))


def target_kinetic_energy(snapshot: Snapshot, radius: float, chunk: int = 2048) -> float:
    """Kinetic energy (J) of the material within ``radius`` (m) of the mesh's centre of mass X,
    in its centre-of-mass frame (velocity V):

        K_T = sum over cells with |x_c - X| < radius of m_c |v_c - V|^2 / 2,

    x_c the cell centres (in 2d-cylindrical X and V lie on the axis: (0, Z), (0, V_z)).  The
    slow motion of the target after the shock has passed, which the reaccumulation turns into
    escaping or returning mass (docs/accuracy.md).  A half-domain 3d snapshot must be mirrored
    first (:func:`impactpipe.handoff.mirror.mirror_across_y0`).
    """
    ndim = snapshot.ndim
    cylindrical = snapshot.geometry == "2d-cylindrical"
    moments = block_moments(snapshot, chunk)
    mass = moments.mass.sum()
    if mass <= 0.0:
        return 0.0
    centre = (moments.mass[:, None] * moments.centre).sum(axis=0) / mass
    velocity = moments.momentum.sum(axis=0) / mass
    if cylindrical:
        centre[0] = velocity[0] = 0.0
    total = 0.0
    for start in range(0, snapshot.block_lo.shape[0], chunk):
        part = _block_range(snapshot, start, start + chunk)
        cell_mass = part.partial_density.sum(axis=1) * part.block_cell_volumes()
        offset = part.block_cell_centers()[:, :ndim] - centre[:ndim, None, None, None]
        inside = (offset**2).sum(axis=1) < radius**2
        relative = part.velocity[:, :ndim] - velocity[:ndim, None, None, None]
        speed2 = np.where(cell_mass > 0.0, (relative**2).sum(axis=1), 0.0)
        total += 0.5 * float((cell_mass * speed2)[inside].sum())
    return total


def merge_fine_blocks(moments: BlockMoments, ndim: int, edge: float) -> BlockMoments:
    """Merge the blocks narrower than ``edge`` (m) into their ancestors of that edge (module docstring).

    Raises ValueError when ``edge`` is not a power-of-two multiple of a narrower block's edge
    (no ancestor has that edge).
    """
    if not (np.isfinite(edge) and edge > 0.0):
        raise ValueError(f"block edge must be positive and finite (got {edge})")
    fine = moments.min_edge < edge * (1.0 - _EDGE_TOLERANCE)
    if not fine.any():
        return moments
    ratio = edge / moments.min_edge[fine]
    levels_up = np.rint(np.log2(ratio)).astype(np.int64)
    if np.any(np.abs(2.0 ** levels_up - ratio) > _EDGE_TOLERANCE * ratio):
        bad = float(moments.min_edge[fine][np.argmax(np.abs(2.0 ** levels_up - ratio))])
        raise ValueError(f"block edge {edge:g} m is not a power-of-two multiple of the leaf block edge {bad:g} m")
    origin = moments.lo[:, :ndim].min(axis=0)
    extent = (moments.hi - moments.lo)[fine, :ndim] * (2.0 ** levels_up)[:, None]
    ancestor_lo = moments.lo[fine, :ndim].copy()
    ancestor_lo = origin + np.floor((ancestor_lo - origin) / extent + _EDGE_TOLERANCE) * extent
    finest = float(moments.min_edge.min())
    key = np.rint((ancestor_lo - origin) / finest).astype(np.int64)
    _, first, group = np.unique(key, axis=0, return_index=True, return_inverse=True)
    group = group.ravel()
    n_groups = first.size
    fine_index = np.flatnonzero(fine)

    def summed(values: np.ndarray) -> np.ndarray:
        out = np.zeros((n_groups,) + values.shape[1:])
        np.add.at(out, group, values[fine_index])
        return out

    mass = summed(moments.mass)
    weighted = summed(moments.mass[:, None] * moments.centre)
    centre = np.zeros_like(weighted)
    np.divide(weighted, mass[:, None], out=centre, where=mass[:, None] > 0.0)
    lo = moments.lo[fine_index[first]].copy()
    hi = moments.hi[fine_index[first]].copy()
    lo[:, :ndim] = ancestor_lo[first]
    hi[:, :ndim] = ancestor_lo[first] + extent[first]
    merged = BlockMoments(
        material_mass=summed(moments.material_mass), mass=mass, centre=centre, momentum=summed(moments.momentum),
        kinetic_energy=summed(moments.kinetic_energy), min_edge=extent[first].min(axis=1), lo=lo, hi=hi,
        level=moments.level[fine_index[first]] - levels_up[first], block_id=moments.block_id[fine_index[first]],
        distension_excess=summed(moments.distension_excess),
    )
    kept = ~fine
    return BlockMoments(*(np.concatenate([getattr(moments, f.name)[kept], getattr(merged, f.name)])
                          for f in fields(BlockMoments)))


def _block_range(snapshot: Snapshot, start: int, stop: int) -> Snapshot:
    """The blocks start:stop of a snapshot (views of its arrays, no copies)."""
    block = slice(start, stop)
    return replace(
        snapshot,
        block_lo=snapshot.block_lo[block], block_hi=snapshot.block_hi[block],
        block_level=snapshot.block_level[block], block_id=snapshot.block_id[block],
        partial_density=snapshot.partial_density[block], volume_fraction=snapshot.volume_fraction[block],
        velocity=snapshot.velocity[block], specific_internal_energy=snapshot.specific_internal_energy[block],
        pressure=snapshot.pressure[block], temperature=snapshot.temperature[block],
        sound_speed=snapshot.sound_speed[block], extra={name: arr[block] for name, arr in snapshot.extra.items()},
    )


def _chunk_moments(snapshot: Snapshot, porous: np.ndarray | None = None) -> BlockMoments:
    """:func:`block_moments` for all blocks of ``snapshot`` at once."""
    ndim = snapshot.ndim
    volume = snapshot.block_cell_volumes()
    material_cell_mass = snapshot.partial_density * volume[:, None]
    material_mass = material_cell_mass.sum(axis=(2, 3, 4))
    cell_mass = material_cell_mass.sum(axis=1)
    mass = material_mass.sum(axis=1)

    # Velocities of empty cells do not enter (void may carry any value).
    velocity = np.where(cell_mass[:, None] > 0.0, snapshot.velocity[:, :ndim], 0.0)
    if not np.all(np.isfinite(velocity)):
        raise ValueError("snapshot velocity is not finite in cells that hold mass")

    coords = snapshot.block_cell_centers()[:, :ndim]
    if snapshot.geometry == "2d-cylindrical":
        edges = snapshot.cell_edges(0)
        r_lo, r_hi = edges[:, :-1], edges[:, 1:]
        centroid = (2.0 / 3.0) * (r_hi**3 - r_lo**3) / (r_hi**2 - r_lo**2)
        coords[:, 0] = centroid[:, :, None, None]

    weighted = (cell_mass[:, None] * coords).sum(axis=(2, 3, 4))
    centre = np.zeros((mass.shape[0], 3))
    np.divide(weighted, mass[:, None], out=centre[:, :ndim], where=mass[:, None] > 0.0)
    momentum = np.zeros((mass.shape[0], 3))
    momentum[:, :ndim] = (cell_mass[:, None] * velocity).sum(axis=(2, 3, 4))
    kinetic_energy = 0.5 * (cell_mass * (velocity**2).sum(axis=1)).sum(axis=(1, 2, 3))
    extent = (snapshot.block_hi - snapshot.block_lo)[:, :ndim]
    excess = cell_distension_excess(snapshot, porous)
    return BlockMoments(material_mass, mass, centre, momentum, kinetic_energy, extent.min(axis=1),
                        np.asarray(snapshot.block_lo, float), np.asarray(snapshot.block_hi, float),
                        np.asarray(snapshot.block_level, dtype=np.int64), np.asarray(snapshot.block_id, dtype=np.int64),
                        np.zeros(mass.shape[0]) if excess is None else excess.sum(axis=(1, 2, 3)))
