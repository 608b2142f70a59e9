"""Grady-Kipp fracture in the hydro stage (docs/strength.md, "Fracture with Weibull flaws").

Issue 28, verification through the real hydro update (sweeps and strength step):
(a) a 1-D box stretched uniformly breaks at a stress that grows as eps_dot^(3/(m+3));
(b) a flyer plate spalls a target plate at the depth and time of the wave diagram, the same
plane at two resolutions; (c) a flawed body translated through a periodic box keeps its flaw
count and its Weibull law.
"""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.solver import Simulation
from impactpipe.hydro.strength.flaws import activation_strain, assign_flaws, flaw_law_per_mass, flaw_nodes
from impactpipe.hydro.strength.fracture import cumulative_flaws
from impactpipe.hydro.strength.parameters import FLAW_NODES, NODE0
from impactpipe.pipeline.presets import resolve_damage, resolve_strength

M_BASALT, K_BASALT = 8.5, 3.0e39
RHO0 = 2700.0
#: basalt_lab moduli: Tillotson A = 26.7 GPa as the bulk modulus, G = 23.09 GPa
BULK, SHEAR = 26.7e9, 23.09e9
LONGITUDINAL_MODULUS = BULK + 4.0 * SHEAR / 3.0
C_L = np.sqrt(LONGITUDINAL_MODULUS / RHO0)


#: the spall scenes' flaws: 1e5 for a bar of 1e-8 m^2 (the same draw statistics at every
#: resolution), 290-570 per cell (220 for the checkpoint test's 2e4), many enough for the
#: continuum rate law; with that many the active-flaw limit of Benz & Asphaug (a device for
#: particles of a few flaws each) would hold a cell's damage to the share of its flaws active,
#: so it is off
MANY_FLAWS = {"flaw_count": 100_000, "flaw_seed": 1, "flaw_cross_section": 1.0e-8, "active_flaw_limit": False}


def lab_basalt(damage: dict, y_t: float = 1.0e9) -> dict:
    """Tillotson basalt with the von Mises lab strength, Y_T = ``y_t`` (the tension cap of the
    intact material) and the Grady-Kipp ``damage`` block (over the basalt preset)."""
    material = preset_material("basalt")
    strength = resolve_strength("von_mises", "basalt_lab", {"Y_T": y_t})
    strength["damage"] = resolve_damage({"model": "grady_kipp", "preset": "basalt", **damage})
    material["strength"] = strength
    return material


def set_continuum_flaws(sim: Simulation, weibull_m: float, weibull_k: float) -> None:
    """Give every cell the body's law itself, n_act,m = (k / rho0) eps^m, with nodes from
    eps = 1e-5 to 1e-2 (beyond every strain reached): the continuum limit of many flaws per cell
    (the kernel bar of tests/test_fracture.py); the law is linear in eps^m, so exact between nodes."""
    mesh, st = sim.mesh, sim.strength
    node_x = np.geomspace(1.0e-5, 1.0e-2, FLAW_NODES) ** weibull_m
    st.damage.params[0, NODE0:] = node_x
    arho = mesh.interior(sim.state.arho)[:, 0]
    q = mesh.interior(sim.state.arhoq)
    for j in range(FLAW_NODES):
        q[:, st.ns + 1 + j] = arho * weibull_k / RHO0 * node_x[j]


# ------------------------------------------------------------------ (a) strain-rate law


def pulled_box(rate: float, cells: int = 256, steps: int = 300) -> tuple[float, float]:
    """(peak tension sigma_xx (Pa), final damage) of the central cell of a 1-D basalt box whose
    velocity is u = eps_dot x (outflow ends), continuum flaws.  The box is 3 c_L t_end long, so
    the ends' disturbance does not reach the centre before t_end = 2.5 times the expected
    fracture time sigma / (M eps_dot)."""
    m, k = M_BASALT, K_BASALT
    sigma_guess = 4.95e6 * (rate / 10.0) ** (3.0 / (m + 3.0))
    t_end = 2.5 * sigma_guess / (LONGITUDINAL_MODULUS * rate)
    length = 3.0 * C_L * t_end
    material = lab_basalt({"active_flaw_limit": False})
    mesh = BlockMesh.uniform("1d-planar", [-length / 2], [length / 2], [cells], [("outflow", "outflow")])
    eos = pack_eos([material["eos"]])
    state = HydroState.empty(mesh, 1)
    x = mesh.cell_centers()[:, 0]
    velocity = np.zeros((mesh.nblocks, 3) + mesh.interior_shape)
    velocity[:, 0] = rate * x
    state.set_material(mesh, 1.0, 0, eos, RHO0, velocity, specific_energy=0.0)
    sim = Simulation(mesh, ["basalt"], [material["eos"]], state, cfl=0.4, strength=[material["strength"]])
    set_continuum_flaws(sim, m, k)
    centre = int(np.argmin(np.abs(x.reshape(-1))))
    peak = 0.0
    while sim.time < t_end:
        sim.step(dt_max=min(t_end / steps, t_end - sim.time))
        snap = sim.snapshot()
        sigma = -snap.pressure.reshape(-1)[centre] + snap.extra["deviatoric_stress_xx"].reshape(-1)[centre]
        peak = max(peak, sigma)
    return peak, float(snap.extra["damage"].reshape(-1)[centre])


def test_pulled_box_breaks_at_a_stress_growing_as_strain_rate_to_3_over_m_plus_3():
    """Through the sweeps and the strength step: the peak of sigma_xx = -p + S_xx in a box
    stretched at 1e1 .. 1e4 /s (uniaxial strain, so the longitudinal modulus instead of E).
    Measured: 4.75, 8.66, 15.8, 28.8 MPa; exponent 0.2608 against 3/(m+3) = 0.2609."""
    rates = np.array([1.0e1, 1.0e2, 1.0e3, 1.0e4])
    results = [pulled_box(r) for r in rates]
    peaks = np.array([p for p, _ in results])
    assert all(d == 1.0 for _, d in results)
    exponent = np.polyfit(np.log(rates), np.log(peaks), 1)[0]
    expected = 3.0 / (M_BASALT + 3.0)
    assert abs(exponent / expected - 1.0) < 0.10
    # a stress-limited failure instead (a fixed Y_T) would give exponent 0
    assert 4.0e6 < peaks[0] < 6.0e6


# ------------------------------------------------------------------ (b) spall


FLYER, TARGET = 5.0e-3, 15.0e-3


def spall(cells: int, velocity: float = 6.0, end_time: float = 6.0e-6):
    """A 5 mm basalt flyer at ``velocity`` (m/s) on a 15 mm basalt target (1-D), Grady-Kipp with
    1e5 flaws drawn for a bar of 1e-8 m^2 cross-section (the same draw statistics at both
    resolutions).  Returns (time, position) of the first target cell inside the target (x > 1 mm,
    away from the contact) to reach D = 1 and the final snapshot."""
    material = lab_basalt(MANY_FLAWS)
    sim = PROBLEMS["planar_impact"].setup({"flyer": {"material": "basalt", "velocity": velocity, "thickness": FLYER},
                                           "target": {"material": "basalt", "thickness": TARGET}, "cells": cells,
                                           "margin": 0.1}, {"basalt": material})
    mesh, nq = sim.mesh, sim.strength.nq
    x = mesh.cell_centers()[:, 0].reshape(-1)
    inside = x > 1.0e-3
    first = None
    while sim.time < end_time:
        sim.step(dt_max=end_time - sim.time)
        if first is None:
            arho = mesh.interior(sim.state.arho)[:, 0].reshape(-1)
            damage = mesh.interior(sim.state.arhoq)[:, nq - 1].reshape(-1) / np.where(arho > 0.0, arho, 1.0)
            broken = inside & (damage >= 1.0)
            if broken.any():
                first = (sim.time, float(x[broken].mean()))
    return first, sim


def test_spall_plane_at_the_wave_diagram_depth_and_time_at_two_resolutions():
    """The rarefactions from the flyer's back and the target's back meet at depth h_f below the
    target's free surface, x = h_t - h_f = 10 mm, at t = (h_t + h_f) / c_L = 4.33 us (acoustic
    wave diagram; 6 m/s, 37 MPa of tension).  The first failure inside the target is there, a
    little after (the Grady-Kipp growth time), at 200 and 400 cells, within one coarse cell of each
    other.  Measured: 10.12 mm at 4.50 us (200 cells, dx = 0.115 mm), 10.06 mm at 4.46 us
    (400 cells, dx = 0.0575 mm)."""
    t_wave = (TARGET + FLYER) / C_L
    x_wave = TARGET - FLYER
    planes = {}
    for cells in (200, 400):
        first, sim = spall(cells)
        assert first is not None
        t, x = first
        dx = float(sim.mesh.block_dx[0, 0])
        assert t_wave < t < t_wave + 0.5e-6
        assert abs(x - x_wave) <= 2.0 * dx
        planes[cells] = (x, dx)
        assert sim.floor_counts["grady_kipp_fractured"] > 0
        assert sim.floor_counts["tensile_failure"] == 0
        snap = sim.snapshot()
        xs = snap.centers[:, 0].reshape(-1)
        damage = snap.extra["damage"].reshape(-1)
        # the first half of the target (away from the contact) is intact: the layer is where the
        # tension met, not everywhere
        assert damage[(xs > 1.0e-3) & (xs < 4.0e-3)].max() < 0.5
    (x_coarse, dx_coarse), (x_fine, _) = planes[200], planes[400]
    assert abs(x_coarse - x_fine) <= dx_coarse


# ------------------------------------------------------------------ (c) flaws carried by advection


def body_law(sim: Simulation, strains: np.ndarray, cross_section: float) -> np.ndarray:
    """Active flaws of material 0 at each strain, summed over the cells of a 1-D mesh standing
    for a bar of ``cross_section`` (m^2): sum_i M_i n_act,m,i."""
    mesh, st = sim.mesh, sim.strength
    vol = (mesh.cell_volumes() * cross_section).reshape((mesh.nblocks,) + mesh.interior_shape)
    q = mesh.interior(sim.state.arhoq)
    m = st.damage.params[0, 0]
    node_x = st.damage.params[0, NODE0:]
    out = []
    for e in strains:
        total = 0.0
        for b in range(mesh.nblocks):
            for ix in range(mesh.interior_shape[0]):
                total += vol[b, ix, 0, 0] * cumulative_flaws(e ** m, node_x, q, st.ns + 1, b, ix, 0, 0, 1.0)
        out.append(total)
    return np.array(out)


@pytest.mark.parametrize("cells", [64, 256])
def test_translated_body_keeps_its_flaw_count_and_weibull_law(cells):
    """A basalt slab (half of a periodic 1-D box of 0.1 m, standing for 0.1 m^2 in the flaw draw)
    moving at 100 m/s crosses the box once (its cells mixed with their neighbours by the
    first-order transport, a spread of about sqrt(N) cells): the body's flaws below every node
    strain (its law at the nodes, all its flaws at the last) are conserved to round-off, and at the
    strains where 10, 50 and 90 % of its flaws are active, the law stays within 3 sqrt(k V eps^m)
    of the Weibull law k V eps^m, as drawn; no damage grows.  Measured (units of
    sqrt(k V eps^m), 10 / 50 / 90 %): -0.19 / -0.09 / -0.01 (64 cells) and -0.09 / -0.01 / -0.00
    (256 cells), the same before and after: the law is linear in the carried amounts, so
    conserved at every strain, not only at the nodes."""
    length = 0.1
    material = lab_basalt({"flaw_seed": 3, "flaw_cross_section": 0.1})
    mesh = BlockMesh.uniform("1d-planar", [0.0], [length], [cells], [("periodic", "periodic")])
    eos = pack_eos([material["eos"]])
    state = HydroState.empty(mesh, 1)
    x = mesh.cell_centers()[:, 0]
    slab = ((x > 0.25 * length) & (x < 0.75 * length)).astype(float)
    speed = 100.0
    state.set_material(mesh, slab, 0, eos, RHO0, np.array([speed, 0.0, 0.0]), specific_energy=0.0)
    sim = Simulation(mesh, ["basalt"], [material["eos"]], state, cfl=0.4, strength=[material["strength"]])
    volume = 0.5 * length * 0.1
    nodes = np.array(sim.strength.flaw_strains[0])
    n_tot = round(float(body_law(sim, nodes[-1:], 0.1)[0]))
    strains = activation_strain(np.array([0.1, 0.5, 0.9]) * n_tot, volume, M_BASALT, K_BASALT)
    expected = K_BASALT * volume * strains ** M_BASALT
    at_nodes = body_law(sim, nodes, 0.1)
    drawn = (body_law(sim, strains, 0.1) - expected) / np.sqrt(expected)
    sim.run(length / speed)
    assert body_law(sim, nodes, 0.1) == pytest.approx(at_nodes, rel=1e-10)
    crossed = (body_law(sim, strains, 0.1) - expected) / np.sqrt(expected)
    assert np.all(np.abs(drawn) <= 3.0)
    assert np.all(np.abs(crossed) <= 3.0)
    assert sim.snapshot().extra["damage"].max() < 1.0e-12


# ------------------------------------------------------------------ flaw laws per unit mass


def test_flaw_law_per_mass_counts_each_cells_flaws_below_the_nodes():
    """The cumulative law per unit mass times each cell's mass is the cell's number of flaws at or
    below each node (the last node is the body's last flaw: every flaw); summed over the cells it is
    the body's law at the nodes, j(eps) = floor(k V eps^m); splitting a cell's mass in two halves
    its law (amounts per unit mass)."""
    rng = np.random.default_rng(7)
    cells = np.full(1000, 1.0e-6)
    volume = 1.0e-3
    n_tot = 20_000
    nodes = flaw_nodes(volume, n_tot, M_BASALT, K_BASALT)
    assert nodes[0] == pytest.approx(activation_strain(1, volume, M_BASALT, K_BASALT))
    assert nodes[-1] == pytest.approx(activation_strain(n_tot, volume, M_BASALT, K_BASALT))
    flaws = assign_flaws(cells, volume, M_BASALT, K_BASALT, rng, n_flaws=n_tot, node_strains=nodes)
    mass = RHO0 * cells
    law = flaw_law_per_mass(flaws, mass)
    assert law.shape == (1000, FLAW_NODES)
    assert (law[:, -1] * mass) == pytest.approx(flaws.count, rel=1e-12)
    assert (law * mass[:, None]).sum(axis=0) == pytest.approx(
        np.floor(K_BASALT * volume * nodes ** M_BASALT * (1 + 1e-12)), rel=1e-12)
    weakest_below = flaws.eps_min <= nodes[0]
    assert ((law[:, 0] * mass > 0.5) == (weakest_below & (flaws.count > 0))).all()
    with pytest.raises(ValueError):
        flaw_law_per_mass(assign_flaws(cells, volume, M_BASALT, K_BASALT, rng), mass)


def test_checkpoint_resumes_fracture_bit_for_bit(tmp_path):
    """The flaws are state and their node strains are in the saved strength spec: a spall run saved
    mid-way (damage growing) and resumed ends bit for bit where the uninterrupted run does."""
    material = lab_basalt({**MANY_FLAWS, "flaw_count": 20_000, "flaw_seed": 2})
    params = {"flyer": {"material": "basalt", "velocity": 6.0, "thickness": FLYER},
              "target": {"material": "basalt", "thickness": TARGET}, "cells": 104, "margin": 0.1}
    sim = PROBLEMS["planar_impact"].setup(params, {"basalt": material})
    sim.run(4.4e-6)
    sim.save_checkpoint(tmp_path / "c.h5")
    sim.run(5.0e-6)
    resumed = Simulation.from_checkpoint(tmp_path / "c.h5")
    assert resumed.strength.flaw_strains == {} and resumed.grady_kipp is not None
    assert (resumed.strength.damage.params == sim.strength.damage.params).all()
    resumed.run(5.0e-6)
    assert sim.floor_counts["grady_kipp_fractured"] > 0
    for name, array in sim.state.arrays().items():
        assert np.array_equal(array, resumed.state.arrays()[name]), name


def test_adaptive_mesh_carries_the_flaws_through_regrids():
    """The spall scene on a 2-level adaptive mesh (finest 200 cells): the plates' flaws below every
    node strain are conserved through the regrids (prolongation, restriction, remap) to round-off,
    and the first failure inside the target is where the uniform mesh puts it, within two finest
    cells.  Measured: 21 regrids; 9.98 mm at 4.55 us (finest dx 0.11 mm)."""
    material = lab_basalt(MANY_FLAWS)
    sim = PROBLEMS["planar_impact"].setup({"flyer": {"material": "basalt", "velocity": 6.0, "thickness": FLYER},
                                           "target": {"material": "basalt", "thickness": TARGET}, "cells": 208,
                                           "margin": 0.1, "levels": 2}, {"basalt": material})

    def flaws_below_nodes():
        mesh, st = sim.mesh, sim.strength
        vol = mesh.cell_volumes()
        q = mesh.interior(sim.state.arhoq)
        return np.array([(q[:, st.ns + 1 + j] * vol).sum() for j in range(FLAW_NODES)])

    start = flaws_below_nodes()
    first = None
    while sim.time < 6.0e-6:
        sim.step(dt_max=6.0e-6 - sim.time)
        if first is None:
            mesh, nq = sim.mesh, sim.strength.nq
            x = mesh.cell_centers()[:, 0].reshape(-1)
            arho = mesh.interior(sim.state.arho)[:, 0].reshape(-1)
            damage = mesh.interior(sim.state.arhoq)[:, nq - 1].reshape(-1) / np.where(arho > 0.0, arho, 1.0)
            broken = (x > 1.0e-3) & (damage >= 1.0)
            if broken.any():
                first = (sim.time, float(x[broken].mean()))
    assert sim.regrids > 0
    assert flaws_below_nodes() == pytest.approx(start, rel=1e-10)
    dx = float(sim.mesh.block_dx[:, 0].min())
    assert first is not None and abs(first[1] - (TARGET - FLYER)) <= 2.0 * dx
