"""Face shear stress (impactpipe.hydro.strength.face_shear): the odd-even mode strains the face
stress by G dt gamma and meets the traction it predicts, a linear velocity field strains every
face alike and exerts no net force, the face's Coulomb yield holds |T| to its shear strength,
the stress stays when the motion stops (elastic), and momentum and energy are conserved."""

import numpy as np
import pytest

from impactpipe.hydro import BlockMesh, HydroState, Simulation
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.strength.face_shear import apply_face_shear, update_face_shear
from impactpipe.hydro.strength.update import WK_L, WK_V, WK_Y, gradient_slot
from impactpipe.pipeline.presets import resolve_strength

G, DT = 2.0e10, 1.0e-4
#: face slots d * ndim + i of the 2-D mesh: x-faces carry T_y, z-faces T_x
X_FACES, Z_FACES = 1, 2


def _box(boundary: str, velocity_of, shear_stress: float = 0.0, strength: float = 1.0e12):
    """(Simulation, mesh): 2d-planar 16^2 box of 1 m cells of basalt at rest density with the
    velocity ``velocity_of(x, z)`` (m/s, a (3, ...) array), GEO strength with the face shear
    stress (modulus G), the deviatoric stress S_xy = ``shear_stress`` (Pa) and the shear
    strength ``strength`` (Pa, the work slot WK_Y) everywhere, ghosts filled; the faces start
    at T = NaN (carrying none yet)."""
    mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [16.0, 16.0], [16, 16], [(boundary, boundary)] * 2, 8)
    spec = preset_material("basalt")["eos"]
    centres = mesh.cell_centers()
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, pack_eos([spec]), spec["rho0"], velocity_of(centres[:, 0], centres[:, 1]),
                       pressure=1.0e6)
    sim = Simulation(mesh, ["basalt"], [spec], state, strength=[resolve_strength("geo", "strong", {})])
    sim.strength.set_face_shear(G)
    sim.state.arhoq[:, 3] = sim.state.arho[:, 0] * shear_stress
    sim.strength.load_stress(sim.state, sim.eos, sim.partition)
    sim.strength.work[:, WK_Y] = strength
    return sim, mesh


def _update(sim, mesh):
    update_face_shear(DT, mesh.ndim, G, mesh.block_dx, mesh.neighbor, mesh.neighbor_level, sim.strength.work,
                      sim.strength.face, 0, mesh.nblocks)


def _apply(sim, mesh):
    """One kick of DT with the face stresses; returns (momentum before, after), interior."""
    before = mesh.interior(sim.state.momentum).copy()
    apply_face_shear(DT, mesh.ndim, sim.state.momentum, sim.state.energy, mesh.block_dx, mesh.neighbor,
                     mesh.neighbor_level, sim.strength.work, sim.strength.face, sim.boundary, 0, mesh.nblocks)
    return before, mesh.interior(sim.state.momentum).copy()


def _odd_even(speed):
    def velocity(x, z):
        v = np.zeros((x.shape[0], 3) + x.shape[1:])
        v[:, 0] = speed * np.where(np.floor(z) % 2 == 0, 1.0, -1.0)
        return v
    return velocity


def test_a_face_starts_at_the_cells_mean_shear():
    """The first update of a face gives it the cells' mean shear s, with no strain rate added."""
    sim, mesh = _box("periodic", _odd_even(2.0), shear_stress=3.0e5)
    _update(sim, mesh)
    np.testing.assert_allclose(mesh.interior(sim.strength.face)[:, [X_FACES, Z_FACES]], 3.0e5, rtol=1e-12)


def test_odd_even_mode_strains_the_face_stress_and_conserves_momentum_and_energy():
    """v_x = V (-1)^j along z: each z-face's T_x = G DT (v_j+1 - v_j) / dx = -+2 G DT V / dx, so
    rho v_x changes by -4 G DT^2 v / dx^2 per kick; total momentum and energy stay (periodic box)."""
    sim, mesh = _box("periodic", _odd_even(2.0))
    sim.strength.face[...] = 0.0
    _update(sim, mesh)
    face = mesh.interior(sim.strength.face)
    v = mesh.interior(sim.strength.work)[:, WK_V]
    z_up = np.roll(v, -1, axis=2)  # v_j+1 within a block's interior (the last row checked apart)
    np.testing.assert_allclose(face[:, Z_FACES, :, :-1], G * DT * (z_up - v)[:, :, :-1], rtol=1e-12)
    assert np.abs(face[:, X_FACES]).max() == 0.0  # v_y is zero and v_x does not change along x
    volume = mesh.cell_volumes()
    energy_before = float((mesh.interior(sim.state.energy)[:, 0] * volume).sum())
    before, after = _apply(sim, mesh)
    np.testing.assert_allclose(after[:, 0] - before[:, 0], -4.0 * G * DT * DT * v, rtol=1e-12)
    assert np.abs(after[:, 1:] - before[:, 1:]).max() == 0.0
    assert abs(float(((after - before)[:, 0] * volume).sum())) < 1e-12 * np.abs(before[:, 0] * volume).sum()
    energy_after = float((mesh.interior(sim.state.energy)[:, 0] * volume).sum())
    assert energy_after == pytest.approx(energy_before, rel=1e-14)


def test_linear_velocity_field_strains_every_face_alike_and_exerts_no_net_force():
    """Shear and stretch v = (0.3 z + 0.1 x, -0.2 x): gamma = 0.3 - 0.2 = 0.1 /s on every face, the
    engineering shear rate a cell sees; cells two or more from the outflow edges keep their momentum."""

    def linear(x, z):
        v = np.zeros((x.shape[0], 3) + x.shape[1:])
        v[:, 0] = 0.3 * z + 0.1 * x
        v[:, 1] = -0.2 * x
        return v

    sim, mesh = _box("outflow", linear)
    sim.strength.face[...] = 0.0
    # the cells' gradients d v_x / d z and d v_z / d x, as the stress update stores them
    sim.strength.work[:, WK_L + gradient_slot(0, 1)] = 0.3
    sim.strength.work[:, WK_L + gradient_slot(1, 0)] = -0.2
    _update(sim, mesh)
    centres = mesh.cell_centers()
    inner = ((centres[:, 0] > 2.0) & (centres[:, 0] < 13.0) & (centres[:, 1] > 2.0) & (centres[:, 1] < 13.0))
    face = mesh.interior(sim.strength.face)
    np.testing.assert_allclose(face[:, X_FACES][inner], G * DT * 0.1, rtol=1e-9)
    np.testing.assert_allclose(face[:, Z_FACES][inner], G * DT * 0.1, rtol=1e-9)
    before, after = _apply(sim, mesh)
    inner = inner & (centres[:, 0] > 3.0) & (centres[:, 1] > 3.0)
    assert np.abs(after - before).max(axis=1)[inner].max() < 1e-9 * G * DT * DT


def test_face_yield_holds_the_stress_to_the_shear_strength_and_the_stress_stays_at_rest():
    """With S_xy = s and shear strength k the odd-even mode's z-faces yield at |T| = k and push with
    T - s; with the motion stopped a second update keeps T (elastic memory) and the kick still acts."""
    s, k = 3.0e5, 1.0e6
    sim, mesh = _box("periodic", _odd_even(2.0), shear_stress=s, strength=k)
    _update(sim, mesh)
    _update(sim, mesh)
    np.testing.assert_allclose(np.abs(mesh.interior(sim.strength.face)[:, Z_FACES]), k, rtol=1e-12)
    held = sim.strength.face.copy()
    sim.strength.work[:, WK_V:WK_V + 3] = 0.0
    _update(sim, mesh)
    np.testing.assert_array_equal(sim.strength.face, held)
    before, after = _apply(sim, mesh)
    np.testing.assert_allclose(np.abs(after[:, 0] - before[:, 0]), 2.0 * k * DT, rtol=1e-12)
