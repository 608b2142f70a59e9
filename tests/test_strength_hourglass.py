"""Hourglass viscosity (impactpipe.hydro.strength.hourglass): the odd-even mode decays at the
analytic rate up to the cap, a linear velocity field feels nothing, momentum and energy are conserved."""

import numpy as np
import pytest

from impactpipe.hydro import BlockMesh, HydroState, Simulation
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.strength.hourglass import apply_hourglass_viscosity
from impactpipe.pipeline.presets import resolve_strength

C, Z, DT = 0.5, 1.5e7, 1.0e-4


def _box(boundary: str, velocity_of, shear_stress: float = 1.0e9):
    """(Simulation, mesh): 2d-planar 16^2 box of 1 m cells of basalt at rest density with the
    velocity ``velocity_of(x, z)`` (m/s, a (3, ...) array), GEO strength with the hourglass
    viscosity (C, Z) and the deviatoric stress S_xy = ``shear_stress`` (Pa) everywhere (the
    hourglass traction's cap)."""
    mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [16.0, 16.0], [16, 16], [(boundary, boundary)] * 2, 8)
    spec = preset_material("basalt")["eos"]
    centres = mesh.cell_centers()
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, pack_eos([spec]), spec["rho0"], velocity_of(centres[:, 0], centres[:, 1]),
                       pressure=1.0e6)
    sim = Simulation(mesh, ["basalt"], [spec], state, strength=[resolve_strength("geo", "strong", {})])
    # the model then fills the two ghost layers of its work arrays that the hourglass stencil reads
    sim.strength.set_hourglass_viscosity(C, Z)
    sim.state.arhoq[:, 3] = sim.state.arho[:, 0] * shear_stress
    return sim, mesh


def _apply(sim, mesh):
    """One hourglass kick of DT on the simulation's state; returns (momentum before, after), interior."""
    before = mesh.interior(sim.state.momentum).copy()
    sim.strength.load_stress(sim.state, sim.eos, sim.partition)
    apply_hourglass_viscosity(DT, mesh.ndim, C, Z, sim.state.momentum, sim.state.energy, mesh.block_dx,
                              mesh.neighbor, mesh.neighbor_level, sim.strength.work, sim.boundary, 0, mesh.nblocks)
    return before, mesh.interior(sim.state.momentum).copy()


def _odd_even(speed):
    def velocity(x, z):
        v = np.zeros((x.shape[0], 3) + x.shape[1:])
        v[:, 0] = speed * np.where(np.floor(z) % 2 == 0, 1.0, -1.0)
        return v
    return velocity


def test_odd_even_mode_decays_at_the_analytic_rate_and_conserves_momentum_and_energy():
    """v_x = V (-1)^j along z: each face traction is C dx Z (2 V / dx), so rho v_x falls by
    4 C Z DT V / dx per kick in every cell; the total momentum and energy stay (periodic box)."""
    speed = 2.0
    sim, mesh = _box("periodic", _odd_even(speed))
    volume = mesh.cell_volumes()
    energy_before = float((mesh.interior(sim.state.energy)[:, 0] * volume).sum())
    before, after = _apply(sim, mesh)
    expected = -4.0 * C * Z * DT * before[:, 0] / np.abs(before[:, 0]) * speed / 1.0
    np.testing.assert_allclose(after[:, 0] - before[:, 0], expected, rtol=1e-12)
    assert np.abs(after[:, 1:] - before[:, 1:]).max() == 0.0
    assert abs(float(((after - before)[:, 0] * volume).sum())) < 1e-12 * np.abs(before[:, 0] * volume).sum()
    energy_after = float((mesh.interior(sim.state.energy)[:, 0] * volume).sum())
    assert energy_after == pytest.approx(energy_before, rel=1e-14)


def test_linear_velocity_field_feels_no_hourglass_traction():
    """Shear and stretch v = (0.3 z + 0.1 x, -0.2 x): cells two or more from the outflow edges keep their momentum."""

    def linear(x, z):
        v = np.zeros((x.shape[0], 3) + x.shape[1:])
        v[:, 0] = 0.3 * z + 0.1 * x
        v[:, 1] = -0.2 * x
        return v

    sim, mesh = _box("outflow", linear)
    before, after = _apply(sim, mesh)
    centres = mesh.cell_centers()
    inner = ((centres[:, 0] > 2.0) & (centres[:, 0] < 14.0) & (centres[:, 1] > 2.0) & (centres[:, 1] < 14.0))
    change = np.abs(after - before).max(axis=1)[inner]
    assert change.max() < 1e-12 * np.abs(before).max()
    assert np.abs(after - before).max() > 0.0  # the outflow edges' copied ghosts break the linear field


def test_hourglass_traction_is_capped_at_the_shear_stress_the_material_carries():
    """With S_xy = 1e5 Pa (sqrt(J2) = 1e5 Pa, below the viscous traction C Z 2 V = 3e7 Pa) each
    face carries 1e5 Pa: rho v_x changes by 2 DT 1e5 / dx per kick."""
    sim, mesh = _box("periodic", _odd_even(2.0), shear_stress=1.0e5)
    before, after = _apply(sim, mesh)
    np.testing.assert_allclose(after[:, 0] - before[:, 0], -2.0 * DT * 1.0e5 * np.sign(before[:, 0]), rtol=1e-12)
