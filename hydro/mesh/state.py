"""Conserved multi-material state on the block mesh (structure of arrays over blocks).

Arrays, shape ``(NB, C, NX, NY, NZ)`` with ghosts (see :mod:`impactpipe.hydro.mesh.blocks`):

=========  ======  ============================================  ===========
name       C       meaning                                       units
=========  ======  ============================================  ===========
alpha      M       volume fraction alpha_k                       -
arho       M       partial density alpha_k rho_k                 kg/m^3
arhoe      M       material internal energy alpha_k rho_k e_k    J/m^3
momentum   3       rho u (2d-cylindrical: (rho v_r, rho v_z, 0)) kg/(m^2 s)
energy     1       total energy rho (e + |u|^2 / 2)              J/m^3
arhoq      M NQ    mass-weighted per-material scalars            kg/m^3 x [q]
                   alpha_k rho_k q_k,j (column k NQ + j)
=========  ======  ============================================  ===========

``arhoq`` carries what a material transports with its mass: with strength, the deviatoric
stress components (Pa), the equivalent plastic strain and the damage (-) of each material
(:mod:`impactpipe.hydro.strength.update`).  Without strength NQ = 0 and it holds nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from impactpipe.hydro.eos import energy_from_pressure
from impactpipe.hydro.mesh.blocks import BlockMesh

FIELDS = ("alpha", "arho", "arhoe", "momentum", "energy", "arhoq")


@dataclass
class HydroState:
    """The conserved fields of every block, ghosts included."""

    alpha: np.ndarray
    arho: np.ndarray
    arhoe: np.ndarray
    momentum: np.ndarray
    energy: np.ndarray
    arhoq: np.ndarray

    @classmethod
    def empty(cls, mesh: BlockMesh, nmat: int, nq: int = 0) -> "HydroState":
        """All-void state (zeros) for ``nmat`` materials with ``nq`` transported scalars each."""
        return cls(**{name: np.zeros(shape) for name, shape in cls.shapes(mesh, nmat, nq).items()})

    @staticmethod
    def shapes(mesh: BlockMesh, nmat: int, nq: int = 0) -> dict[str, tuple[int, ...]]:
        """The shape (NB, C, NX, NY, NZ) of each field, by name, for ``nmat`` materials with ``nq``
        transported scalars each on ``mesh``."""
        lead = (mesh.nblocks,)
        pad = mesh.padded_shape
        columns = {"alpha": nmat, "arho": nmat, "arhoe": nmat, "momentum": 3, "energy": 1, "arhoq": nmat * nq}
        return {name: lead + (columns[name],) + pad for name in FIELDS}

    @property
    def nmat(self) -> int:
        """Number of materials M."""
        return int(self.alpha.shape[1])

    def arrays(self) -> dict[str, np.ndarray]:
        """The field arrays by name."""
        return {name: getattr(self, name) for name in FIELDS}

    def copy_from(self, other: "HydroState") -> None:
        """Copy every field of ``other`` into this state's arrays (no allocation)."""
        for name in FIELDS:
            np.copyto(getattr(self, name), getattr(other, name))

    def copy(self) -> "HydroState":
        """A deep copy."""
        return HydroState(**{name: arr.copy() for name, arr in self.arrays().items()})

    def set_material(self, mesh: BlockMesh, fraction, material: int, eos, density, velocity,
                     pressure=None, specific_energy=None, distension: float = 1.0) -> None:
        """Put material ``material`` into the interior cells where ``fraction`` > 0.

        ``fraction`` (volume fraction, -), ``density`` (kg/m^3), ``pressure`` (Pa) or
        ``specific_energy`` (J/kg) are scalars or arrays broadcastable to (NB, nx, ny, nz);
        ``density`` is the bulk density rho and ``pressure`` the porous pressure
        P = P_s(alpha rho, e) / alpha of a material at ``distension`` alpha (-, 1 without pores;
        :mod:`impactpipe.hydro.eos.porosity`), so e solves P_s(alpha rho, e) = alpha P (the
        distension itself is not stored here: the :class:`~impactpipe.hydro.solver.Simulation`
        starts every porous material at its alpha_0); ``velocity`` (m/s) is a (3,) vector or an
        array broadcastable to (NB, 3, nx, ny, nz).
        Those cells are rebuilt: the material fills ``fraction`` of them and other materials keep
        their partial amounts scaled by ``1 - fraction``.  A cell that held no other matter, or
        held it at ``velocity`` already, moves at ``velocity``.  A cell whose other matter moves
        otherwise (a projectile's cells that overlap the target it touches) takes the sum of the
        two momenta, m = (1 - f) m_old + f rho v, and the kinetic energy that this merge loses,
        (1 - f) K_old + f rho |v|^2 / 2 - |m|^2 / (2 rho_cell), heats the cell's materials by the
        same specific energy, so that the momentum and the total energy of the placed body and
        of what it overlaps are exactly those asked for: a cell moving wholly at ``velocity``
        would give the overlapped matter the body's speed and add its momentum and kinetic
        energy to the impact (a third of the projectile's at one cell per projectile radius in
        the laboratory impact, docs/validation.md).
        ``eos`` is the packed :class:`impactpipe.hydro.eos.EOSArrays`.
        """
        shape = (mesh.nblocks,) + mesh.interior_shape
        fraction = np.clip(np.broadcast_to(np.asarray(fraction, dtype=float), shape), 0.0, 1.0)
        density = np.broadcast_to(np.asarray(density, dtype=float), shape)
        if specific_energy is None:
            pres = np.broadcast_to(np.asarray(pressure, dtype=float), shape)
            kind, params, table = eos.kind[material], eos.params[material], eos.table
            specific_energy = np.array([
                energy_from_pressure(kind, params, table, distension * r, distension * p)
                for r, p in zip(density.ravel(), pres.ravel())
            ]).reshape(shape)
        specific_energy = np.broadcast_to(np.asarray(specific_energy, dtype=float), shape)
        velocity = np.asarray(velocity, dtype=float)
        if velocity.ndim == 1:
            velocity = velocity.reshape((1, 3, 1, 1, 1))
        velocity = np.broadcast_to(velocity, (mesh.nblocks, 3) + mesh.interior_shape)
        sel = fraction > 0.0
        alpha = mesh.interior(self.alpha)
        arho = mesh.interior(self.arho)
        arhoe = mesh.interior(self.arhoe)
        mom = mesh.interior(self.momentum)
        rho_before = arho.sum(axis=1)
        mom_before = mom.copy()
        moving_apart = (sel & (fraction < 1.0) & (rho_before > 0.0)
                        & (mom_before != rho_before[:, None] * velocity).any(axis=1))
        keep = np.where(sel, 1.0 - fraction, 1.0)
        for k in range(self.nmat):
            alpha[:, k] *= keep
            arho[:, k] *= keep
            arhoe[:, k] *= keep
        arhoq = mesh.interior(self.arhoq)
        arhoq *= keep[:, None]
        alpha[:, material] += fraction
        arho[:, material] += fraction * density
        arhoe[:, material] += fraction * density * specific_energy
        rho = arho.sum(axis=1)
        placed = fraction * density
        for d in range(3):
            merged = keep * mom_before[:, d] + placed * velocity[:, d]
            mom[:, d] = np.where(moving_apart, merged, np.where(sel, rho * velocity[:, d], mom[:, d]))
        kinetic = 0.5 * rho * (velocity**2).sum(axis=1)
        if moving_apart.any():
            with np.errstate(invalid="ignore", divide="ignore"):
                kinetic_before = 0.5 * (mom_before**2).sum(axis=1) / rho_before
                merged_kinetic = 0.5 * (mom**2).sum(axis=1) / rho
            parts = keep * kinetic_before + 0.5 * placed * (velocity**2).sum(axis=1)
            heat = np.where(moving_apart, np.maximum(parts - merged_kinetic, 0.0), 0.0)
            for k in range(self.nmat):
                arhoe[:, k] += np.where(moving_apart, heat * arho[:, k] / np.where(moving_apart, rho, 1.0), 0.0)
            kinetic = np.where(moving_apart, merged_kinetic, kinetic)
        energy = mesh.interior(self.energy)
        energy[:, 0] = np.where(sel, arhoe.sum(axis=1) + kinetic, energy[:, 0])
