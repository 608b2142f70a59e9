"""Material strength with local time stepping per refinement level (``time_stepping = "per_level"``,
hydro/amr/subcycle.py): one level is the global step bit for bit; on an adaptive r-z impact with
GEO strength the budgets close and the fields follow the global step's; what per_level still
refuses with strength."""

import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.budget import conservation_budget
from impactpipe.hydro.problems.common import preset_material
from impactpipe.pipeline.presets import resolve_damage, resolve_strength

#: The small impact of these tests: basalt (Tillotson, GEO ``weak``), R_P = 100 m at 3 km/s onto
#: R_T = 1 km, 2d-cylindrical.
IMPACT = {"target": {"material": "basalt", "radius": 1000.0},
          "projectile": {"material": "basalt", "radius": 100.0, "velocity": 3000.0}}


def _impact(levels, cells, mode, end_time, damage=None):
    """The GEO-weak impact on ``levels`` levels, ``cells`` per R_P, stepped by ``mode``."""
    materials = {"basalt": preset_material("basalt")}
    materials["basalt"]["strength"] = resolve_strength("geo", "weak", {})
    if damage is not None:
        materials["basalt"]["strength"]["damage"] = resolve_damage(damage)
    sim = PROBLEMS["impact"].setup({**IMPACT, "cells_per_projectile_radius": cells, "levels": levels,
                                    "end_time": end_time}, materials, geometry="2d-cylindrical")
    sim.time_stepping = mode
    return sim


def _strength_box(mode, levels=3, cells=32):
    """A periodic 2d-planar box (1 km, ``cells``^2 root cells) of basalt (Tillotson, GEO ``weak``)
    streaming along (100, 50) m/s with a 2 GPa pressure pulse off centre: elastic-plastic waves
    with shear stresses cross the level faces, every cell full (no void, no floors)."""
    from impactpipe.hydro import BlockMesh, HydroState, Simulation
    from impactpipe.hydro.amr.regrid import RefinementRule
    from impactpipe.hydro.eos import pack_eos

    mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [1000.0, 1000.0], [cells, cells],
                             [("periodic", "periodic")] * 2, 8, max_level=levels - 1)
    spec = preset_material("basalt")["eos"]
    c = mesh.cell_centers()
    pulse = np.exp(-((c[:, 0] - 350.0) ** 2 + (c[:, 1] - 600.0) ** 2) / 60.0 ** 2)
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, pack_eos([spec]), spec["rho0"] * (1.0 + 0.02 * pulse),
                       np.array([100.0, 50.0, 0.0]), pressure=1.0e6 + 2.0e9 * pulse)
    return Simulation(mesh, ["basalt"], [spec], state, strength=[resolve_strength("geo", "weak", {})],
                      refinement=RefinementRule(interval=2, density_jump=None, pressure_floor=0.05),
                      time_stepping=mode)


def _binned(sim, values, bins):
    """Volume-weighted means of the interior-cell ``values`` (NB, nx, ny, 1) of ``sim`` over a
    ``bins``^2 grid of its domain (the cells by their centres), and the bins' volumes (m^3)."""
    mesh = sim.mesh
    centres = mesh.cell_centers()
    r, z = centres[:, 0].reshape(-1), centres[:, 1].reshape(-1)
    volume = mesh.cell_volumes().reshape(-1)
    edges = [np.linspace(mesh.domain_lo[d], mesh.domain_hi[d], bins + 1) for d in range(2)]
    weight, _, _ = np.histogram2d(r, z, edges, weights=volume)
    amount, _, _ = np.histogram2d(r, z, edges, weights=volume * values.reshape(-1))
    return amount / np.where(weight > 0.0, weight, 1.0), weight


def _relative_l1(a, b, field, reference=0.0, bins=32):
    """sum V |f_a - f_b| / sum V |f_b - reference| of ``field(sim)`` binned over ``bins``^2
    (:func:`_binned`): the difference of two runs against how far ``b`` moved from ``reference``
    (binned, or 0)."""
    fa, volume = _binned(a, field(a), bins)
    fb, _ = _binned(b, field(b), bins)
    return float((volume * np.abs(fa - fb)).sum() / (volume * np.abs(fb - reference)).sum())


def test_one_level_per_level_with_strength_is_the_global_step_bit_for_bit():
    """On a uniform mesh the per-level strength step (the kernels over the level's block list) is
    the global step's: every state array, the boundary amounts and the strength counters."""
    runs = []
    for mode in ("global", "per_level"):
        sim = _impact(1, 4, mode, 1.0)
        sim.run(1.0, max_steps=12)
        runs.append(sim)
    glob, per_level = runs
    assert per_level.cell_updates == glob.cell_updates and per_level.time == glob.time
    for name, array in glob.state.arrays().items():
        assert np.array_equal(glob.mesh.interior(array), per_level.mesh.interior(per_level.state.arrays()[name])), name
    assert np.array_equal(glob.boundary, per_level.boundary)
    assert np.array_equal(glob.strength.counts, per_level.strength.counts)
    assert np.array_equal(glob.strength.amounts, per_level.strength.amounts)
    assert glob.floor_counts["yield_return"] > 0


def test_closed_box_with_strength_per_level_conserves_every_amount():
    """The basalt box of :func:`_strength_box` on 3 levels, 40 root steps (t = 0.118 s; 8 / 224
    blocks on levels 1 / 2 at the end, 87 refined and 15 coarsened): mass, both momentum
    components and energy to 1e-14 of their scale (measured 1.8e-16, 3.4e-16, 0).  Without the
    stress kicks' amounts in the flux registers: momentum 1.2e-7, energy 1.8e-7 after 20."""
    sim = _strength_box("per_level")
    start = sim.totals()
    sim.run(1.0e9, max_steps=40)
    end = sim.totals()
    assert sim.blocks_refined > 20 and sim.blocks_coarsened > 5 and len(set(sim.mesh.block_level)) >= 2
    assert sim.floor_counts["yield_return"] > 0 and sim.floor_counts["tensile_failure"] > 0
    assert sum(sim.floor_amounts.get(name, 0.0) for name in ("mass_added_by_floors", "mass_removed_by_void_cleanup",
                                                              "energy_added_by_floors")) == 0.0
    assert abs(end["mass"] - start["mass"]) < 1e-14 * start["mass"]
    scale = np.abs(start["momentum"]).max()
    assert np.abs(end["momentum"] - start["momentum"]).max() < 1e-14 * scale
    assert abs(end["energy"] - start["energy"]) < 1e-14 * start["energy"]


def test_impact_with_strength_per_level_closes_its_budgets_and_follows_the_global_step():
    """The GEO-weak impact, 8 cells per R_P, 3 levels, to t = 0.1 s per level and globally.

    Per level (38 root steps, 3 taken again, against 154 steps): mass and energy unaccounted
    8.3e-17 and 1.9e-16 (asserted 1e-14; the global step 2.3e-16, -3.2e-17); the floors add
    1.2e-8 kg (global 5.6e-9 kg), no register correction needs redistributing.  The z momentum
    changes by 6.7e-3 of the projectile's in both modes (per level 6.707e-3, global 6.578e-3):
    not a per-level effect (asserted: within 10 % of the global change), and the void cleanup's
    and the velocity limit's signed z amounts account for it (z momentum unaccounted asserted
    1e-13).  Binned on a 32^2 grid, the density differs from the global run's by an L1 of 2.5e-3
    of the global run's density
    change and the von Mises stress by 3.5e-3 of its L1 (asserted 1e-2 and 2e-2): less than the
    global step differs from itself at cfl 0.3 instead of 0.4 (9.6e-3 and 2.2e-2), the size of
    the time-integration error at this resolution."""
    runs = {}
    for mode in ("per_level", "global"):
        sim = _impact(3, 8, mode, 0.1)
        initial = sim.totals()
        start_density = _binned(sim, sim.snapshot().density, 32)[0]
        sim.run(0.1)
        budget = conservation_budget(initial, sim.totals(), sim.floor_amounts)
        assert abs(budget["mass_unaccounted"]) < 1e-14 and abs(budget["energy_unaccounted"]) < 1e-14, (mode, budget)
        assert abs(budget["momentum_y_unaccounted"]) < 1e-13, (mode, budget)
        runs[mode] = (sim, budget["momentum_y_error"])
    (per_level, dpz), (glob, dpz_global) = runs["per_level"], runs["global"]
    assert per_level.time == glob.time and per_level.step_count < 0.3 * glob.step_count
    assert per_level.mesh.block_level.max() == 2 and per_level.floor_counts["yield_return"] > 0
    assert per_level.floor_amounts["mass_added_by_floors"] < 1e-6
    assert per_level.floor_counts["register_redistribution"] == 0
    assert abs(dpz - dpz_global) < 0.1 * abs(dpz_global)
    density = _relative_l1(per_level, glob, lambda s: s.snapshot().density, start_density)
    stress = _relative_l1(per_level, glob, lambda s: s.snapshot().extra["von_mises_stress"])
    assert density < 1e-2 and stress < 2e-2, (density, stress)


def test_per_level_refuses_what_it_does_not_carry_with_strength():
    """Grady-Kipp fracture and the column collapse's options do not step per level yet: refused by name."""
    sim = _impact(2, 4, "global", 0.1)
    sim.strength.hourglass = (0.5, 1.0e7)
    sim.time_stepping = "per_level"
    with pytest.raises(ValueError, match="per_level does not support the hourglass viscosity yet"):
        sim.check_time_stepping()
    sim.strength.hourglass = (0.0, 0.0)
    sim.step_tensile_limit = True
    with pytest.raises(ValueError, match="per_level does not support the step-end tensile limit"):
        sim.check_time_stepping()
    damage = {"model": "grady_kipp", "preset": "basalt"}
    with pytest.raises(ValueError, match="per_level does not support grady_kipp fracture yet"):
        _impact(2, 4, "per_level", 0.1, damage).check_time_stepping()
