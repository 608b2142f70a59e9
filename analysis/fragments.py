"""Fragments of a broken body: connected regions of intact material, their masses, speeds and shapes.

Benz & Asphaug (1994) and the laboratory comparisons after them take the fragments of a body
broken in a hydrocode to be the connected regions of material that is not fully damaged.
Here the caller marks each cell of the mesh intact or not (damage below a threshold, enough
material in it: :func:`intact_cells`); two intact cells belong to one fragment when they
share a face, across a coarse/fine face of an adaptive mesh too (:func:`face_neighbours`);
cells that touch only at an edge or a corner are not joined.

Per fragment, over its cells c of mass m_c (kg), centre x_c and widths w_c (m), velocity
v_c (m/s):

- mass M = sum_c m_c, centre X = sum_c m_c x_c / M, velocity V = sum_c m_c v_c / M;
- shape: the semi-axes a >= b >= c (m) of the uniform ellipsoid (in 2 dimensions the uniform
  ellipse) with the fragment's second moments: a_i = sqrt((n + 2) lambda_i), lambda_i the
  eigenvalues of C = sum_c m_c [(x_c - X)(x_c - X)^T + diag(w_c^2) / 12] / M and n the number
  of dimensions (a uniform ellipsoid has <x_i^2> = a_i^2 / 5, an ellipse a_i^2 / 4, and a
  cell of widths w adds w_i^2 / 12 about its own centre).

In 2d-cylindrical snapshots a cell is an annulus and a fragment a ring: its mass is the
ring's, its velocity the mass-weighted (v_r, v_z) of its cross-section (the speed of the
pieces it would break into) and its shape that of the cross-section, weighted by mass.

The laboratory experiment the fracture model is compared with, Nakamura & Fujiwara (1991)
(a 6 cm basalt sphere hit off-centre by a 7 mm nylon sphere at 3.2 km/s), is
:data:`NAKAMURA_FUJIWARA_1991`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

#: Relative tolerance on coordinates when deciding that two cells share a face.
FACE_TOLERANCE = 1.0e-6


@dataclass(frozen=True)
class LaboratoryFragmentation:
    """Measured fragments of a laboratory impact (SI).

    Attributes:
        reference: the publication.
        target_mass: M_T (kg).
        largest_fraction: mass of the largest fragment over M_T (-).
        largest_speed: speed of the largest fragment (m/s).
        speed_coefficient, speed_exponent: the speeds of the other fragments,
            V = speed_coefficient (m / M_T)^speed_exponent (m/s).
    """

    reference: str
    target_mass: float
    largest_fraction: float
    largest_speed: float
    speed_coefficient: float
    speed_exponent: float

    def fragment_speed(self, mass_fraction: np.ndarray) -> np.ndarray:
        """The fitted speed V (m/s) of fragments of mass fraction m / M_T (-)."""
        return self.speed_coefficient * np.asarray(mass_fraction, dtype=float) ** self.speed_exponent


#: Nakamura & Fujiwara (1991): a 303 g, 6 cm basalt sphere hit 30 degrees off-centre by a 0.213 g
#: nylon sphere at 3.2 km/s; largest fragment 0.31 M_T at 1.35 m/s, the others V = 6.4 (m / M_T)^-0.155 m/s.
NAKAMURA_FUJIWARA_1991 = LaboratoryFragmentation(
    reference="Nakamura & Fujiwara (1991), Icarus 92, 132",
    target_mass=0.303,
    largest_fraction=0.31,
    largest_speed=1.35,
    speed_coefficient=6.4,
    speed_exponent=-0.155,
)


@dataclass
class Fragments:
    """The fragments of one body, largest first (F fragments of N cells).

    Attributes:
        mass: (F,) fragment masses (kg).
        center: (F, 3) centres of mass (m).
        velocity: (F, 3) velocities (m/s).
        semi_axes: (F, 3) semi-axes a >= b >= c of the equivalent uniform ellipsoid (m;
            the third is 0 in 2 dimensions).
        cells: (F,) number of cells of each fragment.
        label: (N,) the fragment of each cell (index into the arrays above), -1 where the cell
            is not intact.
    """

    mass: np.ndarray
    center: np.ndarray
    velocity: np.ndarray
    semi_axes: np.ndarray
    cells: np.ndarray
    label: np.ndarray

    @property
    def count(self) -> int:
        """Number of fragments."""
        return int(self.mass.size)

    @property
    def speed(self) -> np.ndarray:
        """(F,) fragment speeds |V| (m/s)."""
        return np.linalg.norm(self.velocity, axis=1)

    def as_datasets(self, target_mass: float) -> dict:
        """The fragments as ``{name: (value, units, description)}`` for
        :func:`impactpipe.analysis.io.write_analysis`; ``target_mass`` M_T (kg)."""
        return {
            "target_mass": (target_mass, "kg", "M_T, the mass the fractions refer to"),
            "mass": (self.mass, "kg", "fragment masses, largest first"),
            "mass_fraction": (self.mass / target_mass, "dimensionless", "m / M_T"),
            "center": (self.center, "m", "centres of mass"),
            "velocity": (self.velocity, "m/s", "mass-weighted velocities"),
            "speed": (self.speed, "m/s", "|velocity|"),
            "semi_axes": (self.semi_axes, "m", "a >= b >= c of the uniform ellipsoid with the same second moments"),
            "cells": (self.cells, "dimensionless", "cells per fragment"),
        }


def intact_cells(fill: np.ndarray, damage: np.ndarray, min_fill: float = 0.5, max_damage: float = 0.99) -> np.ndarray:
    """Cells that belong to a fragment: material fill (the volume fraction of the body's
    materials, -) of at least ``min_fill`` and damage D (-) below ``max_damage``."""
    if not 0.0 < min_fill <= 1.0:
        raise ValueError(f"min_fill must lie in (0, 1], got {min_fill}")
    if not 0.0 < max_damage <= 1.0:
        raise ValueError(f"max_damage must lie in (0, 1], got {max_damage}")
    return (np.asarray(fill) >= min_fill) & (np.asarray(damage) < max_damage)


def face_neighbours(center: np.ndarray, width: np.ndarray, ndim: int) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j), i != j, of cells that share a face (part of one, for cells of different sizes).

    ``center`` (N, 3) and ``width`` (N, 3) are cell centres and edge lengths (m) of the leaf
    cells of a block mesh; the first ``ndim`` axes are used.  Two boxes share a face when
    along one axis the distance of their centres is the sum of their half-widths and along
    every other axis less than it (a corner or edge contact is not a face).  Cells are
    grouped by size; each pair of groups is searched with a k-d tree in the maximum norm.
    """
    center = np.asarray(center, dtype=float)[:, :ndim]
    half = 0.5 * np.asarray(width, dtype=float)[:, :ndim]
    if center.shape[0] == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    scale = half.max(axis=0)
    if (scale <= 0.0).any():
        raise ValueError("cell widths must be > 0 along every used axis")
    center = center / scale
    half = half / scale
    sizes, group = np.unique(np.round(half, 9), axis=0, return_inverse=True)
    group = group.ravel()
    members = [np.flatnonzero(group == g) for g in range(len(sizes))]
    trees = [cKDTree(center[m]) for m in members]
    first, second = [], []
    for a in range(len(sizes)):
        for b in range(a, len(sizes)):
            reach = float((sizes[a] + sizes[b]).max()) * (1.0 + FACE_TOLERANCE)
            pairs = trees[a].sparse_distance_matrix(trees[b], reach, p=np.inf, output_type="coo_matrix")
            i = members[a][pairs.row]
            j = members[b][pairs.col]
            keep = i < j if a == b else np.ones(i.size, dtype=bool)
            i, j = i[keep], j[keep]
            gap = np.abs(center[i] - center[j])
            touch = half[i] + half[j]
            tol = FACE_TOLERANCE * touch
            on_face = np.abs(gap - touch) <= tol
            overlap = gap < touch - tol
            face = (on_face.sum(axis=1) == 1) & ((on_face | overlap).all(axis=1))
            first.append(i[face])
            second.append(j[face])
    return np.concatenate(first), np.concatenate(second)


def connected_regions(center: np.ndarray, width: np.ndarray, ndim: int) -> tuple[int, np.ndarray]:
    """(number of regions, (N,) region of each cell) of the cells joined through shared faces."""
    n = center.shape[0]
    i, j = face_neighbours(center, width, ndim)
    graph = coo_matrix((np.ones(i.size, dtype=np.int8), (i, j)), shape=(n, n)).tocsr()
    count, label = connected_components(graph, directed=False)
    return int(count), label


def find_fragments(center: np.ndarray, width: np.ndarray, mass: np.ndarray, velocity: np.ndarray,
                   intact: np.ndarray, ndim: int) -> Fragments:
    """The fragments of the ``intact`` cells (module docstring), largest first.

    Args:
        center, width: (N, 3) cell centres and edge lengths (m).
        mass: (N,) mass of the body's materials in each cell (kg).
        velocity: (N, 3) cell velocities (m/s).
        intact: (N,) bool, the cells that can belong to a fragment (:func:`intact_cells`).
        ndim: number of used axes (1, 2 or 3).
    """
    center = np.asarray(center, dtype=float)
    width = np.asarray(width, dtype=float)
    mass = np.asarray(mass, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    cells = np.flatnonzero(np.asarray(intact, dtype=bool) & (mass > 0.0))
    label = np.full(center.shape[0], -1, dtype=np.int64)
    count, region = connected_regions(center[cells], width[cells], ndim)
    m = mass[cells]
    total = np.bincount(region, weights=m, minlength=count)
    order = np.argsort(-total, kind="stable")
    rank = np.empty(count, dtype=np.int64)
    rank[order] = np.arange(count)
    region = rank[region]
    total = total[order]
    label[cells] = region

    def mean(values):
        return np.stack([np.bincount(region, weights=m * values[:, d], minlength=count) for d in range(3)],
                        axis=1) / total[:, None]

    x = center[cells]
    com = mean(x)
    vel = mean(velocity[cells])
    offset = x - com[region]
    moments = np.zeros((count, 3, 3))
    for p in range(ndim):
        for q in range(p, ndim):
            value = offset[:, p] * offset[:, q]
            if p == q:
                value = value + width[cells, p] ** 2 / 12.0
            moments[:, p, q] = moments[:, q, p] = np.bincount(region, weights=m * value, minlength=count) / total
    eigen = np.clip(np.linalg.eigvalsh(moments)[:, ::-1], 0.0, None)
    semi_axes = np.sqrt((ndim + 2.0) * eigen)
    semi_axes[:, ndim:] = 0.0
    return Fragments(mass=total, center=com, velocity=vel, semi_axes=semi_axes,
                     cells=np.bincount(region, minlength=count), label=label)


def cumulative_number(mass: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(masses in decreasing order, N(>= m)): the cumulative mass distribution of fragments."""
    ordered = np.sort(np.asarray(mass, dtype=float))[::-1]
    return ordered, np.arange(1, ordered.size + 1)
