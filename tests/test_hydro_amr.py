"""Adaptive mesh refinement: balance, exact conservation through regrids, level faces, and Sod, Noh and Sedov
on 3 levels against their exact solutions, as accurate as on the uniform mesh of the finest cells."""

import itertools

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS, BlockMesh, HydroState, Simulation
from impactpipe.hydro.amr.regrid import RefinementRule, refine_to
from impactpipe.hydro.amr.transfer import _offset, _reflux_cell
from impactpipe.hydro.budget import conservation_budget
from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.exact.noh import noh_solution
from impactpipe.hydro.exact.riemann import exact_riemann
from impactpipe.hydro.exact.sedov import sedov_solution
from impactpipe.hydro.mesh.blocks import GHOST
from impactpipe.hydro.scheme.pencil_layout import (AMOUNT_MASS_FLOOR, AMOUNT_MASS_VOID, FLOOR_PARTIAL_DENSITY,
                                                   FLOOR_VOID_CLEANUP, NAMOUNT, NFLOOR)

GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}
HEAVY = {"model": "ideal_gas", "gamma": 1.6, "cv": 300.0}


def _corner_refined(geometry="2d-planar", levels=3):
    """A mesh refined towards the origin corner as far as ``levels`` allows."""
    ndim = 3 if geometry == "3d" else 2
    mesh = BlockMesh.uniform(geometry, [0.0] * ndim, [1.0] * ndim, [32] * ndim,
                             [("reflecting", "outflow")] * ndim, 8, max_level=levels)
    return refine_to(mesh, lambda m: np.where((m.block_lo[:, :ndim] < 0.01).all(axis=1), levels, 0))


@pytest.mark.parametrize("geometry", ["2d-planar", "3d"])
def test_refined_leaves_tile_the_domain_2_to_1_balanced(geometry):
    mesh = _corner_refined(geometry)
    ndim = mesh.ndim
    assert mesh.block_level.max() == 3
    assert mesh.cell_volumes().sum() == pytest.approx(1.0, rel=1e-13)
    # every leaf's face, edge and corner neighbours are within one level
    for b in range(mesh.nblocks):
        lvl, idx = mesh.block_level[b], mesh.block_index[b]
        for offset in itertools.product((-1, 0, 1), repeat=ndim):
            probe = np.zeros(3, dtype=np.int64)
            probe[:ndim] = idx[:ndim] + np.array(offset)
            extent = mesh.blocks_at_level(lvl)[0]
            if not any(offset) or (probe < 0).any() or (probe >= extent).any():
                continue
            holders = [mesh.lookup([lvl - up], [probe >> up])[0] for up in range(lvl + 1)]
            found = [h for h in holders if h >= 0]
            if found:
                assert abs(mesh.block_level[found[0]] - lvl) <= 1
            else:  # subdivided: its children touching block b must be leaves one level finer
                touching = [c for c in itertools.product((0, 1), repeat=ndim)
                            if all(o == 0 or c[d] == (1 if o < 0 else 0) for d, o in enumerate(offset))]
                kids = [np.concatenate([2 * probe[:ndim] + np.array(c), np.zeros(3 - ndim, int)]) for c in touching]
                assert (mesh.lookup([lvl + 1] * len(kids), kids) >= 0).all()
    # the neighbour tables agree with the levels
    inside = mesh.neighbor >= 0
    nbr_level = np.where(inside, mesh.block_level[np.maximum(mesh.neighbor, 0)], 0)
    assert np.array_equal(np.where(inside, nbr_level - mesh.block_level[:, None, None], 0), mesh.neighbor_level)


def _disc_and_pulse(mesh, eos, nmat):
    """A gas streaming diagonally at 1 m/s with a pressure pulse and (nmat 2) a disc 20x denser."""
    c = mesh.cell_centers()
    x, y = c[:, 0], c[:, 1]
    state = HydroState.empty(mesh, nmat)
    u0 = np.array([1.0, 0.5, 0.0])
    p = 1.0 + 2.0 * np.exp(-((x - 0.7) ** 2 + (y - 0.6) ** 2) / 0.003)
    state.set_material(mesh, 1.0, 0, eos, 1.0, u0, pressure=p)
    if nmat == 2:
        disc = ((x - 0.3) ** 2 + (y - 0.3) ** 2) < 0.02
        state.set_material(mesh, disc.astype(float), 1, eos, 20.0, u0, pressure=p)
    return state


@pytest.mark.parametrize("boundary, nmat", [("periodic", 2), ("reflecting", 1)])
def test_closed_box_conserves_through_refinement_and_coarsening(boundary, nmat):
    mesh = BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [16, 16], [(boundary, boundary)] * 2, 8, max_level=2)
    specs = [GAS, HEAVY][:nmat]
    sim = Simulation(mesh, ["a", "b"][:nmat], specs, _disc_and_pulse(mesh, pack_eos(specs), nmat),
                     refinement=RefinementRule(interval=2))
    start = sim.totals()
    sim.run(100.0, max_steps=1000)
    end = sim.totals()
    assert sim.step_count == 1000
    assert sim.blocks_refined > 20 and sim.blocks_coarsened > 20
    assert_closed_box_conserves(sim, start, end, "momentum_with_outflow")


def dense_disc_state(mesh):
    """(state, u0): gas at rho 1 and p 1 with a disc (radius sqrt(0.02) about (0.3, 0.3)) of the
    HEAVY material 1e3 times denser at the same pressure, everything moving at u0 = (1, 0.5)."""
    eos = pack_eos([GAS, HEAVY])
    state = HydroState.empty(mesh, 2)
    c = mesh.cell_centers()
    u0 = np.array([1.0, 0.5, 0.0])
    state.set_material(mesh, 1.0, 0, eos, 1.0, u0, pressure=1.0)
    disc = (((c[:, 0] - 0.3) ** 2 + (c[:, 1] - 0.3) ** 2) < 0.02).astype(float)
    state.set_material(mesh, disc, 1, eos, 1000.0, u0, pressure=1.0)
    return state, u0


def assert_closed_box_conserves(sim, start: dict, end: dict, momentum: str = "momentum") -> None:
    """Mass, the ``momentum`` total and energy of a closed box from ``sim.totals()`` at ``start``
    and ``end`` to 1e-12, net of what the floors added or the void cleanup removed (counted),
    and the floors' mass below 1e-6 of the total."""
    removed = sim.floor_amounts["mass_removed_by_void_cleanup"] - sim.floor_amounts["mass_added_by_floors"]
    assert abs(end["mass"] + removed - start["mass"]) < 1e-12 * start["mass"]
    assert abs(removed) < 1e-6 * start["mass"]
    scale = start["energy"]
    assert np.abs(end[momentum] - start["momentum"]).max() < 1e-12 * scale
    added = sim.floor_amounts["energy_added_by_floors"] - sim.floor_amounts["energy_removed_by_void_cleanup"]
    assert abs(end["energy"] - start["energy"] - added) < 1e-12 * scale


def test_moving_interface_crosses_level_boundaries_at_uniform_pressure_and_velocity():
    """A dense disc (1e3 x the surrounding gas) advected diagonally through a periodic box.

    The interface refines; the refined region follows the disc, so the interface keeps
    crossing coarse/fine faces, and after about 490 steps the periodic seam.  Measured
    (docs/hydro.md, "Moving interfaces across level faces"): |p - 1| <= 9.5e-9 at every
    hundredth step up to 900, |u - u0| <= 3.8e-9.  With ghost offsets across the seam off by
    the box length, density-keeping refluxes and trace densities changed by the
    prolongation it was 1.4e-7 after 400 steps and 1.1e-5 after 800.
    """
    mesh = BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [32, 32], [("periodic", "periodic")] * 2, 8, max_level=2)
    state, u0 = dense_disc_state(mesh)
    sim = Simulation(mesh, ["gas", "heavy"], [GAS, HEAVY], state, refinement=RefinementRule(interval=2))
    for _ in range(8):
        sim.run(100.0, max_steps=100)
        snap = sim.snapshot()
        assert np.abs(snap.pressure - 1.0).max() < 1e-8
        assert np.abs(snap.velocity[:, 0] - u0[0]).max() < 1e-8
        assert np.abs(snap.velocity[:, 1] - u0[1]).max() < 1e-8
    assert sim.step_count == 800
    assert sim.time > 1.0, "the disc has crossed the periodic seam"
    assert sim.regrids > 100 and set(np.unique(snap.block_level)) == {1, 2}


def test_prolongation_offset_across_a_periodic_seam_lies_inside_the_parent():
    """A fine block ending at x = 1 of a periodic unit box fills its high ghosts from the coarse
    cell [0, 1/64) at x = 0: the children sit at -1/4 and +1/4 of that cell, not 63.75."""
    fine_lo, fine_dx, coarse_dx = 1.0 - 8 / 128, 1 / 128, 1 / 64
    assert _offset(0.0, coarse_dx, GHOST, fine_lo, fine_dx, GHOST + 8, False) == pytest.approx(-0.25)
    assert _offset(0.0, coarse_dx, GHOST, fine_lo, fine_dx, GHOST + 9, False) == pytest.approx(0.25)
    assert _offset(0.5, coarse_dx, GHOST, 0.5, fine_dx, GHOST + 1, False) == pytest.approx(0.25)


#: Largest ratio of an adaptive run's density L1 error to that of the uniform run of its finest cells.
ERROR_FACTOR = 1.3
GAS_14 = {"gas": {"eos": GAS}}
GAS_53 = {"gas": {"eos": {"model": "ideal_gas", "gamma": 5.0 / 3.0, "cv": 718.0}}}


def _density_l1(sim, exact_density):
    """Volume-weighted mean |rho - rho_exact| (kg/m^3) of ``sim`` against ``exact_density(centres)``."""
    snap = sim.snapshot()
    exact = exact_density(snap.centers)
    return float((np.abs(snap.density.reshape(-1) - exact) * snap.volumes).sum() / snap.volumes.sum())


def _conserved_run(problem, params, materials, geometry, block_cells):
    """The problem's Simulation run to ``params["end_time"]``, mass and energy checked to round-off.

    Conserved: the totals on the mesh plus what left it, less what the floors counted
    (:func:`impactpipe.hydro.budget.conservation_budget`, ``*_unaccounted``).
    """
    sim = PROBLEMS[problem].setup(params, materials, geometry=geometry, block_cells=block_cells)
    initial = sim.totals()
    sim.run(params["end_time"])
    budget = conservation_budget(initial, sim.totals(), sim.floor_amounts)
    assert abs(budget["mass_unaccounted"]) < 1e-13 and abs(budget["energy_unaccounted"]) < 1e-13, budget
    return sim


def _adaptive_against_uniform(problem, params, materials, geometry, levels, exact_density, block_cells=None):
    """(adaptive, uniform) Simulations of ``problem`` on ``levels`` levels and uniform at the same finest cell.

    Both conserve mass and energy to round-off; the adaptive mesh refined and coarsened during
    the run and ends on several levels; its density L1 error against ``exact_density`` is at most
    ERROR_FACTOR times the uniform run's.
    """
    adaptive, uniform = (_conserved_run(problem, {**params, "levels": n}, materials, geometry, block_cells)
                         for n in (levels, 1))
    assert adaptive.mesh.min_cell_size() == uniform.mesh.min_cell_size()
    assert adaptive.blocks_refined > 0 and adaptive.blocks_coarsened > 0
    per_level = np.bincount(adaptive.mesh.block_level, minlength=levels)
    assert per_level[-1] > 0 and per_level[:-1].sum() > 0, per_level
    assert _density_l1(adaptive, exact_density) < ERROR_FACTOR * _density_l1(uniform, exact_density)
    return adaptive, uniform


#: Each problem's textbook case at a small resolution: (resolution keys, names of its materials).
SMALL_CASES = {
    "impact": ({"cells_per_projectile_radius": 2}, ["basalt"]),
    "shock_tube": ({"cells": 64}, ["gas"]),
    "sedov": ({"cells": 64}, ["gas"]),
    "planar_impact": ({"cells": 64}, ["basalt"]),
    "advection": ({"cells": 64}, ["gas"]),
    "noh": ({"cells": 64}, ["gas"]),
    "interface_advection": ({"cells": 64}, ["heavy", "light"]),
    "column_collapse": ({"cells_per_height": 8}, ["sand"]),
    "hydrostatic_body": ({"cells_per_radius": 8, "body": {"material": "basalt", "radius": 5.0e4}}, ["basalt"]),
}


def _small_case_materials(used):
    """Basalt (Tillotson), the column collapse's granular basalt, an ideal gas for the other names."""
    from test_column_collapse import granular

    from impactpipe.hydro.problems.common import preset_material

    kinds = {"basalt": preset_material("basalt"), "sand": granular()}
    return {name: kinds.get(name, {"eos": GAS}) for name in used}


@pytest.mark.parametrize("problem", list(PROBLEMS))
def test_every_problem_starts_refined_where_its_rule_asks_at_the_uniform_finest_cell(problem):
    """On 3 levels each problem's finest cell is its uniform mesh's cell, root cells 4 times wider;
    setup leaves no block its refinement rule would still refine, and 8 steps keep the mass."""
    resolution, used = SMALL_CASES[problem]
    materials = _small_case_materials(used)
    uniform, adaptive = (PROBLEMS[problem].setup({**resolution, "levels": n}, materials) for n in (1, 3))
    assert adaptive.mesh.max_level == 2 and uniform.mesh.max_level == 0
    finest = uniform.mesh.min_cell_size()
    assert np.allclose(adaptive.mesh.root_cell_size[:adaptive.mesh.ndim], 4 * finest, rtol=1e-12, atol=0.0)
    assert not adaptive.refinement_flags()[0][adaptive.mesh.block_level < 2].any()
    mass = adaptive.totals()["mass"]
    adaptive.run(np.inf, max_steps=8)
    assert adaptive.totals()["mass_with_outflow"] == pytest.approx(mass, rel=1e-12)


def test_sod_2d_three_levels_matches_uniform():
    """Sod along x in 2d-planar, 256 finest cells: density L1 error 0.98 x the uniform run's (2.03e-3 / 2.06e-3)."""
    left, right = (1.0, 0.0, 1.0), (0.125, 0.0, 0.1)
    _adaptive_against_uniform("shock_tube", {"cells": 256, "end_time": 0.2}, GAS_14, "2d-planar", 3,
                              lambda c: exact_riemann(c[:, 0], 0.2, 0.5, left, right, 1.4)[0], block_cells=8)


@pytest.mark.parametrize("geometry, nu, cells", [("1d-planar", 1, 256), ("2d-cylindrical", 3, 64)])
def test_noh_three_levels_matches_uniform(geometry, nu, cells):
    """Noh at t = 0.6: density L1 error 0.99 x the uniform run's in 1d-planar (256 finest cells),
    1.10 x in 2d-cylindrical (64^2; in both runs mostly the inflow, whose growing density the
    zero-gradient outer boundary misses)."""
    def exact(c):
        return noh_solution(np.sqrt((c ** 2).sum(axis=1)), 0.6, 5.0 / 3.0, nu)[0]

    _adaptive_against_uniform("noh", {"cells": cells, "end_time": 0.6}, GAS_53, geometry, 3, exact, block_cells=8)


def _sedov_density(end_time):
    """Exact Sedov density (kg/m^3) at cell centres ``c`` (m) for E = 1 J, rho = 1 kg/m^3, gamma 1.4."""
    return lambda c: sedov_solution(1.4, 3).profiles(np.sqrt((c ** 2).sum(axis=1)), end_time, 1.0, 1.0)[0]


def _sedov_adaptive_against_uniform(geometry, cells, end_time, deposit):
    """Sedov on 3 levels and on the uniform finest mesh: (adaptive, uniform) Simulations after ``end_time``."""
    adaptive, uniform = _adaptive_against_uniform(
        "sedov", {"cells": cells, "end_time": end_time, "deposit_cells": deposit}, GAS_14, geometry, 3,
        _sedov_density(end_time))
    exact = sedov_solution(1.4, 3).shock_radius(1.0, 1.0, end_time)
    from test_hydro_sedov import _shock_radii

    radii = _shock_radii(adaptive.snapshot(), adaptive.mesh.min_cell_size())
    assert np.abs(radii / exact - 1.0).max() < 0.02
    return adaptive, uniform


def test_sedov_cylindrical_three_levels_matches_uniform_at_a_fraction_of_the_cost():
    adaptive, uniform = _sedov_adaptive_against_uniform("2d-cylindrical", 128, 0.1, 3.5)
    assert adaptive.cell_updates < 0.5 * uniform.cell_updates


@pytest.mark.validation
def test_sedov_3d_three_levels_matches_uniform_at_a_fraction_of_the_cost():
    """64^3 finest cells: about 5 minutes of each on 2 cores."""
    adaptive, uniform = _sedov_adaptive_against_uniform("3d", 64, 0.3, 2.0)
    assert adaptive.cell_updates < 0.3 * uniform.cell_updates


def test_adaptive_checkpoint_continues_bit_for_bit(tmp_path):
    mesh = BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [32, 32], [("periodic", "periodic")] * 2, 8, max_level=2)
    sim = Simulation(mesh, ["a", "b"], [GAS, HEAVY], _disc_and_pulse(mesh, pack_eos([GAS, HEAVY]), 2),
                     refinement=RefinementRule(interval=3))
    sim.run(100.0, max_steps=7)
    sim.save_checkpoint(tmp_path / "c.h5")
    again = Simulation.from_checkpoint(tmp_path / "c.h5")
    assert again.refinement == sim.refinement and again.mesh.nblocks == sim.mesh.nblocks
    sim.run(100.0, max_steps=20)
    again.run(100.0, max_steps=20)
    assert np.array_equal(again.mesh.block_id, sim.mesh.block_id)
    assert np.array_equal(again.snapshot().pressure, sim.snapshot().pressure)


def test_observer_sees_each_operation_of_a_step_in_order_and_changes_nothing():
    mesh = BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [32, 32], [("periodic", "periodic")] * 2, 8, max_level=2)
    runs = []
    for watched in (False, True):
        sim = Simulation(mesh, ["a", "b"], [GAS, HEAVY], _disc_and_pulse(mesh, pack_eos([GAS, HEAVY]), 2),
                         refinement=RefinementRule(interval=3))
        events = []
        if watched:
            sim.observer = lambda event, axis: events.append((sim.step_count, event, axis, sim.state.energy.sum()))
        sim.run(100.0, max_steps=4)
        runs.append((sim, events))
    (plain, _), (watched, events) = runs
    assert np.array_equal(plain.snapshot().pressure, watched.snapshot().pressure)
    per_step = [[(event, axis) for step, event, axis, _ in events if step == n] for n in range(4)]
    assert per_step[0] == [("regrid", -1), ("ghosts", 0), ("sweep", 0), ("reflux", 0), ("ghosts", 1), ("sweep", 1),
                           ("reflux", 1)]
    assert per_step[1] == [("regrid", -1), ("ghosts", 1), ("sweep", 1), ("reflux", 1), ("ghosts", 0), ("sweep", 0),
                           ("reflux", 0)]
    assert any(a[3] != b[3] for a, b in zip(events, events[1:]) if b[1] == "sweep")


def test_refinement_pressure_is_limited_by_the_damaged_tensile_strength():
    """The criteria's mixture pressure holds a material in tension at -Y_T (1 - D), as the sweeps do.

    One basalt cell row stretched to 0.99 rho0 at zero internal energy (Tillotson P ~ -2.7e8
    Pa), damage D = 0, 0.5, 1 in the transported damage column: -Y_T, -Y_T / 2, 0, in the interior
    cell and the first ghost layer (the cells the indicators read).
    """
    from impactpipe.hydro.amr.criteria import mixture_pressure
    from impactpipe.hydro.problems.common import preset_material
    from impactpipe.hydro.scheme.timestep import cell_thermodynamics

    spec = preset_material("basalt")["eos"]
    eos = pack_eos([spec])
    rho = 0.99 * spec["rho0"]
    y_t = 1.0e7
    damage = np.array([0.0, 0.5, 1.0])
    shape = (3, 1, 5, 1, 1)
    alpha = np.ones(shape)
    arho = np.full(shape, rho)
    arhoe = np.zeros(shape)
    arhoq = np.zeros((3, 2, 5, 1, 1))
    arhoq[:, 1] = (damage * rho)[:, None, None, None]
    out = np.zeros((3, 5, 1, 1))
    shear = np.zeros((1, 2))
    mixture_pressure(alpha, arho, arhoe, arhoq, eos.kind, eos.params, eos.table, shear, np.array([y_t]), out)
    np.testing.assert_allclose(out[:, 1:4, 0, 0], (-y_t * (1.0 - damage))[:, None] * np.ones(3), rtol=1e-14, atol=0.0)
    p, c, e, t = (np.zeros((3, 1, 1, 1)) for _ in range(4))
    cell_thermodynamics(alpha, arho, arhoe, arhoq, eos.kind, eos.params, eos.table, shear, np.array([y_t]), p, c, e, t)
    np.testing.assert_array_equal(p[:, 0, 0, 0], out[:, 2, 0, 0])


def _one_cell_correction(arho_before, mass_change, energy_change, stress_change):
    """A cell (volume 1 m^3) with void holding two materials (2 scalars each) corrected through its
    low face by the given amounts of material 0 (``_reflux_cell``); returns the arrays."""
    nmat, nq = 2, 2
    alpha = np.zeros((1, nmat, 1, 1, 1))
    alpha[0, :, 0, 0, 0] = (0.3, 0.2)
    arho = np.zeros_like(alpha)
    arho[0, :, 0, 0, 0] = (arho_before, 500.0)
    arhoe = arho * 1.0e5
    arhoq = np.zeros((1, nmat * nq, 1, 1, 1))
    arhoq[0, :, 0, 0, 0] = (arho_before * 2.0e6, arho_before * 0.1, 500.0 * 1.0e6, 500.0 * 0.2)
    mom = np.zeros((1, 3, 1, 1, 1))
    mom[0, 0, 0, 0, 0] = 1.0e3
    energy = np.full((1, 1, 1, 1, 1), 5.0e7)
    delta = np.zeros(3 * nmat + 4 + nmat * nq)
    delta[nmat] = mass_change
    delta[2 * nmat] = energy_change
    delta[3 * nmat + 4] = stress_change
    floors = np.zeros((1, NFLOOR), dtype=np.int64)
    amounts = np.zeros((1, NAMOUNT))
    _reflux_cell(0, 0, 0, 0, 0, 1.0, delta, alpha, arho, arhoe, arhoq, mom, energy, floors, amounts)
    return alpha, arho, arhoe, arhoq, mom, energy, floors, amounts


def test_a_reflux_that_empties_a_material_leaves_no_energy_or_scalars_on_its_residue():
    """A correction that takes nearly all of a material (its residue below EMPTIED_FRACTION of what
    it had: round-off of two nearly equal amounts) or more than all of it removes the material
    with its internal energy and transported scalars, counts the residue, and leaves the cell's
    momentum and total energy as they were; a correction that leaves a real amount keeps the
    amounts it carried.  Before, the residue kept whatever energy and scalar amounts the
    correction left: 2.8e17 J/kg on 2.2e-16 kg/m^3 of basalt in case 8c per level, which the
    next sweep turned into a negative density."""
    arho_before = 2.0
    residue = 2.2e-16
    for change, counted in ((residue - arho_before, FLOOR_VOID_CLEANUP), (-2.5, FLOOR_PARTIAL_DENSITY)):
        alpha, arho, arhoe, arhoq, mom, energy, floors, amounts = _one_cell_correction(arho_before, change, -1.0e5, 1.0)
        assert alpha[0, 0, 0, 0, 0] == 0.0 and arho[0, 0, 0, 0, 0] == 0.0 and arhoe[0, 0, 0, 0, 0] == 0.0
        assert (arhoq[0, :2, 0, 0, 0] == 0.0).all()
        assert (arhoq[0, 2:, 0, 0, 0] == (5.0e8, 100.0)).all() and arho[0, 1, 0, 0, 0] == 500.0
        assert floors[0, counted] == 1 and floors.sum() == 1
        assert mom[0, 0, 0, 0, 0] == 1.0e3 and energy[0, 0, 0, 0, 0] == 5.0e7
    assert amounts[0, AMOUNT_MASS_FLOOR] == pytest.approx(0.5)
    _, _, _, _, _, _, _, amounts = _one_cell_correction(arho_before, residue - arho_before, -1.0e5, 1.0)
    assert amounts[0, AMOUNT_MASS_VOID] == pytest.approx(residue, rel=0.5)
    alpha, arho, arhoe, arhoq, _, _, floors, _ = _one_cell_correction(arho_before, -1.0, -1.0e5, 1.0)
    assert arho[0, 0, 0, 0, 0] == 1.0 and arhoe[0, 0, 0, 0, 0] == 1.0e5 and arhoq[0, 0, 0, 0, 0] == 4.0e6 + 1.0
    assert floors.sum() == 0


@pytest.mark.parametrize("cell, reached", [((8, 8), set()), ((1, 8), {(0, 1)}), ((14, 8), {(2, 1)}),
                                           ((1, 1), {(0, 1), (1, 0), (0, 0)}), ((8, 14), {(1, 2)})])
def test_buffer_reach_refines_only_the_neighbours_a_jump_lies_near(cell, reached):
    """A pressure spike (p = 2 in one cell of gas at p = 1, jump indicator 1/3 > 0.2) in root block
    (1, 1) of a 4 x 4 block mesh (16^2 cells each, one finer level).  With ``buffer: block`` the
    block and its 8 neighbours ask for level 1; with ``buffer: reach`` (reach 3 cells) the block
    and only the neighbours across the faces and corners the spike's stencil (the cell and its
    4 face neighbours) lies within 3 cells of."""
    from impactpipe.hydro.amr.regrid import block_wants
    from impactpipe.hydro.mesh.boundary import fill_state_ghosts

    mesh = BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [64, 64], [("reflecting", "reflecting")] * 2, 16,
                             max_level=1)
    eos = pack_eos([GAS])
    pressure = np.ones((mesh.nblocks, 16, 16, 1))
    spike = mesh.lookup([0], [[1, 1, 0]])[0]
    pressure[spike, cell[0], cell[1], 0] = 2.0
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, eos, 1.0, np.zeros(3), pressure=pressure)
    for axis in range(2):
        fill_state_ghosts(state, mesh, axis)
    index = {tuple(int(i) for i in mesh.block_index[b, :2]): b for b in range(mesh.nblocks)}
    ring = {(1 + i, 1 + j) for i in (-1, 0, 1) for j in (-1, 0, 1)}
    for buffer, expected in (("block", ring), ("reach", {(1, 1)} | reached)):
        rule = RefinementRule(buffer=buffer)
        wants = block_wants(mesh, state, eos, np.zeros((1, 2)), np.zeros(1), rule, reach=3)
        assert {key for key, b in index.items() if wants.want[b] == 1} == expected
        assert {key for key, b in index.items() if wants.keep[b] == 1} == expected


@pytest.mark.parametrize("depth, level", [(None, 0), (0, 3), (1, 2), (2, 1), (5, 0)])
def test_material_depth_keeps_blocks_holding_material_near_the_finest_level(depth, level):
    """A uniform slab of gas at rest filling x < 0.25 of a 4 x 4 root-block mesh (16^2 cells each,
    3 finer levels), void elsewhere, no jump anywhere: with ``material_depth`` d every block
    holding material (the first block column) or reading it in a ghost (the second) asks for
    level max(3 - d, 0), to refine to and to keep; with None and in the void blocks beyond,
    level 0 (interfaces are off here; outflow faces, whose ghosts copy the void as +0.0)."""
    from impactpipe.hydro.amr.regrid import block_wants
    from impactpipe.hydro.mesh.boundary import fill_state_ghosts

    mesh = BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [64, 64], [("outflow", "outflow")] * 2, 16,
                             max_level=3)
    eos = pack_eos([GAS])
    state = HydroState.empty(mesh, 1)
    slab = (mesh.cell_centers()[:, 0] < 0.25).astype(float)
    state.set_material(mesh, slab, 0, eos, 1.0, np.zeros(3), pressure=1.0)
    for axis in range(2):
        fill_state_ghosts(state, mesh, axis)
    rule = RefinementRule(interfaces="off", material_depth=depth)
    wants = block_wants(mesh, state, eos, np.zeros((1, 2)), np.zeros(1), rule)
    column = mesh.block_index[:, 0]
    for wanted in (wants.want, wants.keep, wants.material):
        assert (wanted[column <= 1] == level).all()
        assert (wanted[column >= 2] == 0).all()


def test_material_depth_must_not_be_negative():
    """A negative ``material_depth`` is refused by the rule (and by the config:
    tests/configs/broken/amr_material_depth.yaml)."""
    with pytest.raises(ValueError, match="material_depth"):
        RefinementRule(material_depth=-1)


@pytest.mark.parametrize("pressure_floor, activity_floor, active", [(1e-3, None, False), (1e-5, None, True),
                                                                    (1e-5, 1e-3, False), (1e-3, 1e-5, True)])
def test_activity_floor_sets_which_interfaces_hold_the_finest_level(pressure_floor, activity_floor, active):
    """A dense disc at rest at p = 1 in gas at p = 1, the run's largest |p| so far 1e4: under
    ``interfaces: active`` the disc's edge asks for the finest level where its blocks' |p| = 1
    exceeds activity_floor x 1e4 (``pressure_floor`` when ``activity_floor`` is None), one level
    coarser where it does not."""
    from impactpipe.hydro.amr.regrid import block_wants
    from impactpipe.hydro.mesh.boundary import fill_state_ghosts

    mesh = BlockMesh.uniform("2d-planar", [0, 0], [1, 1], [32, 32], [("reflecting", "reflecting")] * 2, 8,
                             max_level=2)
    state, _ = dense_disc_state(mesh)
    state.momentum[:] = 0.0
    eos = pack_eos([GAS, HEAVY])
    for axis in range(2):
        fill_state_ghosts(state, mesh, axis)
    rule = RefinementRule(interfaces="active", pressure_floor=pressure_floor, activity_floor=activity_floor)
    wants = block_wants(mesh, state, eos, np.zeros((2, 2)), np.zeros(2), rule, peak_pressure=1.0e4)
    edge = wants.indicators[:, 0] > 0.1
    assert edge.sum() == 4
    assert (wants.active[edge] == active).all()
    assert (wants.face[edge] == (2 if active else 1)).all()
