"""Surface-layer pressure of the yield strength (impactpipe.hydro.strength.update, step 4): a
cohesionless material in a partly filled surface cell holds the friction of the layer it forms."""

import math

import numpy as np
import pytest

from impactpipe.hydro import BlockMesh, HydroState, Simulation
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.problems.common import preset_material

G, DT, MU, FILL = 10.0, 1.0e-4, math.tan(math.radians(25.0)), 0.5


def _sheared_layer(surface_gravity: bool):
    """8^2 box of 1 m cells: rows z < 4 m full of cohesionless basalt, row 4 filled FILL, void above,
    all at zero pressure in the shear v_x = z (1/s); one strength update of DT.  Returns the
    simulation, the cell fields and the mask of the partly filled cells."""
    mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [8.0, 8.0], [8, 8], [("outflow", "outflow")] * 2, 8)
    material = preset_material("basalt")
    spec = material["eos"]
    centres = mesh.cell_centers()
    z = centres[:, 1]
    fraction = np.where(z < 4.0, 1.0, np.where(z < 5.0, FILL, 0.0))
    velocity = np.zeros((mesh.nblocks, 3) + mesh.interior_shape)
    velocity[:, 0] = z
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, fraction, 0, pack_eos([spec]), spec["rho0"], velocity, pressure=0.0)
    strength = {"model": "geo", "Y0": 0.0, "Y_M": 1.0e12, "Y_T": 0.0, "mu_i": MU, "poisson": 0.3,
                "T_melt": 1.0e9, "xi": 1.2}  # no thermal softening at room temperature
    sim = Simulation(mesh, ["basalt"], [spec], state, strength=[strength])
    if surface_gravity:
        sim.strength.set_surface_layer_pressure([0.0, -G, 0.0])
    sim.strength.load_stress(sim.state, sim.eos, sim.partition)
    sim.strength.update(sim.state, DT, sim.eos, sim.partition)
    return sim, sim.strength.cell_fields(sim.state), (fraction > 0.0) & (fraction < 1.0), spec["rho0"]


def test_partly_filled_cell_yields_at_the_friction_of_its_layer():
    """With gravity g: sqrt(3 J2) of the material = sqrt(3) mu rho0 g (FILL dx) / 2 (the GEO yield at
    the layer's mid-depth pressure); the mixture's von Mises stress is FILL times that.  Without:
    zero (no pressure, no cohesion)."""
    sim, fields, surface, rho0 = _sheared_layer(True)
    layer = 0.5 * rho0 * G * FILL * 1.0
    expected = FILL * math.sqrt(3.0) * MU * layer
    np.testing.assert_allclose(fields["von_mises_stress"][surface], expected, rtol=1e-6)
    assert sim.strength.count_totals["surface_layer_pressure"] == int(surface.sum())
    sim, fields, surface, _ = _sheared_layer(False)
    assert np.abs(fields["von_mises_stress"][surface]).max() == 0.0
    assert sim.strength.count_totals["surface_layer_pressure"] == 0
