"""Block mesh: neighbour table, ghost filling and cell geometry."""

import numpy as np
import pytest

from impactpipe.hydro.mesh.boundary import fill_ghosts
from impactpipe.hydro import HydroState, Simulation
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.mesh.blocks import GHOST, OUTFLOW, REFLECTING, BlockMesh, uniform_block_cells

GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}


def test_neighbour_table_2d_periodic_and_walls():
    boundaries = [("periodic", "periodic"), ("reflecting", "outflow")]
    mesh = BlockMesh.uniform("2d-planar", [0, 0], [1, 2], [32, 64], boundaries, 16)
    assert mesh.nblocks == 2 * 4
    # block 0 (ix=0, iy=0): x-low wraps to block 1, y-low is a wall, y-high is block 2
    assert mesh.neighbor[0, 0, 0] == 1 and mesh.neighbor[0, 0, 1] == 1
    assert mesh.neighbor[0, 1, 0] == REFLECTING and mesh.neighbor[0, 1, 1] == 2
    assert mesh.neighbor[7, 1, 1] == OUTFLOW
    assert mesh.padded_shape == (16 + 2 * GHOST, 16 + 2 * GHOST, 1)


def test_cell_volumes_cylindrical_sum_to_cylinder():
    mesh = BlockMesh.uniform("2d-cylindrical", [0, -1], [2, 3], [32, 64], [("reflecting", "outflow")] * 2, 16)
    assert mesh.cell_volumes().sum() == pytest.approx(np.pi * 2**2 * 4, rel=1e-13)


def test_ghost_fill_kinds_along_x():
    mesh = BlockMesh.uniform("1d-planar", [0], [1], [16], [("reflecting", "outflow")], 8)
    field = np.zeros((2, 2) + mesh.padded_shape)
    interior = mesh.interior(field)
    interior[:, 0, :, 0, 0] = np.arange(16).reshape(2, 8) + 1.0
    interior[:, 1] = interior[:, 0]
    fill_ghosts(field, mesh.neighbor, mesh.neighbor_level, 0, GHOST, 1, 0, mesh.nblocks)
    g = GHOST
    # block 0 low side: mirror with the flipped component negated
    assert field[0, 0, g - 1, 0, 0] == 1.0 and field[0, 0, g - 2, 0, 0] == 2.0
    assert field[0, 1, g - 1, 0, 0] == -1.0
    # between blocks: copies of the neighbour's interior
    assert field[0, 0, g + 8, 0, 0] == 9.0 and field[1, 0, g - 1, 0, 0] == 8.0
    # block 1 high side: outflow, zero gradient
    assert field[1, 0, g + 8, 0, 0] == 16.0 and field[1, 0, g + 9, 0, 0] == 16.0


def test_bad_mesh_inputs_raise():
    with pytest.raises(ValueError, match="multiple"):
        BlockMesh.uniform("1d-planar", [0], [1], [20], [("outflow", "outflow")], 8)
    with pytest.raises(ValueError, match="periodic"):
        BlockMesh.uniform("1d-planar", [0], [1], [16], [("periodic", "outflow")], 8)
    with pytest.raises(ValueError, match="axis"):
        BlockMesh.uniform("2d-cylindrical", [0, 0], [1, 1], [16, 16], [("outflow", "outflow")] * 2, 16)


def test_uniform_block_cells_rule():
    """Largest edge that divides the cells and leaves 64 blocks; adaptive meshes keep the default."""
    assert uniform_block_cells(2, [512, 512]) == 64
    assert uniform_block_cells(2, [256, 256]) == 32
    assert uniform_block_cells(2, [128, 128]) == 16
    assert uniform_block_cells(2, [544, 784]) == 16
    assert uniform_block_cells(3, [128, 128, 128]) == 16
    assert uniform_block_cells(3, [48, 48, 48]) == 8
    bc = [("periodic", "periodic")] * 2
    assert BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [256, 256], bc).block_cells == 32
    assert BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [256, 256], bc, max_level=1).block_cells == 16
    assert BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [256, 256], bc, block_cells=8).block_cells == 8


def test_block_edge_leaves_the_answer_unchanged():
    """The same periodic gas box on 16^2, 32^2 and 64^2 blocks: bit for bit the same state after 6 steps."""
    n = 64
    eos = pack_eos([GAS])
    results = []
    for edge in (16, 32, 64):
        mesh = BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [n, n], [("periodic", "periodic")] * 2, edge)
        c = mesh.cell_centers()
        state = HydroState.empty(mesh, 1)
        rho = 1.0 + 0.3 * np.sin(2 * np.pi * c[:, 0]) * np.cos(2 * np.pi * c[:, 1])
        zero = np.zeros_like(c[:, 0])
        vel = np.stack([0.3 + 0.2 * np.sin(2 * np.pi * c[:, 1]), zero, zero], axis=1)
        state.set_material(mesh, 1.0, 0, eos, rho, vel, pressure=1.0 + 0.1 * np.cos(2 * np.pi * c[:, 0]))
        sim = Simulation(mesh, ["gas"], [GAS], state)
        for _ in range(6):
            sim.step()
        results.append((sim.time, sim.snapshot()))
    t0, s0 = results[0]
    key0 = np.lexsort(s0.centers.T)
    for t, s in results[1:]:
        assert t == t0
        key = np.lexsort(s.centers.T)
        np.testing.assert_array_equal(s.centers[key], s0.centers[key0])
        for name in ("density", "pressure", "velocity", "specific_internal_energy"):
            np.testing.assert_array_equal(s.fields[name][key], s0.fields[name][key0])
