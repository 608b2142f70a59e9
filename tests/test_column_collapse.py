"""External gravity and the granular column collapse (docs/validation.md, "Granular column collapse")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.gravity import ExternalGravity
from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.problems import column_collapse
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.budget import conservation_budget
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.solver import HydroFailure, Simulation
from impactpipe.pipeline.config import ConfigError, parse_config

G = 9.81
HEIGHT = 1000.0
#: sqrt(H0 / g), the collapse's time unit (s).
TAU = math.sqrt(HEIGHT / G)


def granular(cohesion: float = 2.0e5) -> dict:
    """Basalt EOS with a Drucker-Prager strength: sqrt(J2) <= Y0 + tan(25 deg) P, no tension."""
    material = preset_material("basalt")
    material["strength"] = {"model": "geo", "Y0": cohesion, "Y_M": 1.0e12, "Y_T": 0.0,
                            "mu_i": math.tan(math.radians(25.0)), "poisson": 0.3, "T_melt": 1474.0, "xi": 1.2}
    return material


def test_gravity_kick_adds_rho_g_dt_and_its_work_to_the_bulk_motion_only():
    mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [4.0, 4.0], [8, 8], [("outflow", "outflow")] * 2, 4)
    eos = pack_eos([preset_material("basalt")["eos"]])
    state = HydroState.empty(mesh, 1)
    rng = np.random.default_rng(3)
    shape = (mesh.nblocks, 3) + mesh.interior_shape
    velocity = rng.normal(0.0, 5.0, shape)
    velocity[:, 2] = 0.0
    state.set_material(mesh, 0.5, 0, eos, 2700.0, velocity, specific_energy=1.0e3)
    rho = mesh.interior(state.arho).sum(axis=1)

    def internal_energy():
        return mesh.interior(state.energy)[:, 0] - 0.5 * (mesh.interior(state.momentum) ** 2).sum(axis=1) / rho

    internal_before = internal_energy()
    momentum_before = mesh.interior(state.momentum).copy()
    energy_before = float((mesh.interior(state.energy)[:, 0] * mesh.cell_volumes()).sum())
    gravity = ExternalGravity([0.0, -G, 0.0], mesh)
    dt = 0.01
    gravity.advance(state, dt, mesh.block_lo, mesh.block_dx)
    gravity.advance(state, dt, mesh.block_lo, mesh.block_dx)
    kick = mesh.interior(state.momentum) - momentum_before
    np.testing.assert_allclose(kick[:, 1], -2.0 * rho * G * dt, rtol=1e-13)
    assert np.abs(kick[:, 0]).max() == 0.0
    np.testing.assert_allclose(internal_energy(), internal_before, rtol=1e-11)
    energy_after = float((mesh.interior(state.energy)[:, 0] * mesh.cell_volumes()).sum())
    assert gravity.work == pytest.approx(energy_after - energy_before, abs=1e-13 * energy_before)
    assert gravity.work != 0.0


def test_gravity_rejects_components_the_geometry_cannot_carry():
    cyl = BlockMesh.uniform("2d-cylindrical", [0.0, 0.0], [1.0, 1.0], [4, 4],
                            [("reflecting", "outflow"), ("outflow", "outflow")], 4)
    with pytest.raises(ValueError, match="g_r must be 0"):
        ExternalGravity([1.0, -G, 0.0], cyl)
    with pytest.raises(ValueError, match="does not use"):
        ExternalGravity([0.0, -G, 1.0], cyl)
    assert ExternalGravity([0.0, -G, 0.0], cyl).work == 0.0


def test_budget_counts_the_work_of_gravity():
    initial = {"mass": 1.0, "energy": 10.0, "momentum": np.zeros(3)}
    final = {"mass": 1.0, "energy": 14.0, "momentum": np.array([0.0, -2.0, 0.0]), "outflow_mass": 0.0,
             "outflow_energy": 1.0, "outflow_momentum": np.zeros(3)}
    budget = conservation_budget(initial, final, {}, gravity_work=5.0)
    assert budget["energy_added_by_gravity"] == 5.0
    assert budget["energy_error"] == 0.0
    assert conservation_budget(initial, final, {})["energy_error"] == pytest.approx(0.5)


def scene_yaml(**hydro) -> str:
    lines = "".join(f"  {key}: {value}\n" for key, value in hydro.items())
    return ("name: cc\nscene:\n  problem: column_collapse\n  material: sand\n  height: 1000.0\n  width: 500.0\n"
            "materials:\n  sand:\n    eos: {model: tillotson, preset: basalt}\n"
            "    strength: {model: geo, Y0: 2.0e5, Y_M: 1.0e12, Y_T: 0.0, mu_i: 0.4663, poisson: 0.3}\n"
            + (f"hydro:\n{lines}" if lines else ""))


def test_config_accepts_the_scene_and_refuses_a_large_courant_number_and_an_unknown_material():
    config = parse_config(scene_yaml())
    assert (config.scene.height, config.scene.width, config.scene.gravity) == (1000.0, 500.0, 9.81)
    assert config.hydro.cfl == 0.4
    with pytest.raises(ConfigError) as err:
        parse_config(scene_yaml(cfl=0.5))
    assert "hydro.cfl: must be <= 0.4 for the column_collapse scene (got 0.5)" in str(err.value)
    with pytest.raises(ConfigError) as err:
        parse_config(scene_yaml().replace("material: sand", "material: snad"))
    assert "scene.material: 'snad' is not defined under materials (defined: sand); did you mean 'sand'?" in str(err.value)
    with pytest.raises(ConfigError, match="cells_per_height: must be >= 4"):
        parse_config(scene_yaml().replace("width: 500.0", "width: 500.0\n  cells_per_height: 2"))


def test_the_front_at_a_thickness_fixed_in_length_and_at_a_share_of_the_volume():
    """A block 1000 m thick to x = 1000 m and a sheet 30 m thick to x = 2000 m (dx = 62.5 m)."""
    dx = 62.5
    x = (np.arange(48) + 0.5) * dx
    thickness = np.where(x < 1000.0, 1000.0, np.where(x < 2000.0, 30.0, 0.0))
    deposit = {"x": x, "thickness": thickness, "dx": dx}
    # half a cell (31.25 m) and 0.05 H0 (50 m) end the deposit at the block, plus dx h / threshold
    # for the sheet's first column; 0.02 H0 (20 m) counts the sheet
    assert column_collapse.front_at_thickness(deposit, 0.5 * dx) == pytest.approx(1000.0 + dx * 30.0 / 31.25)
    assert column_collapse.front_at_thickness(deposit, 50.0) == pytest.approx(1000.0 + dx * 30.0 / 50.0)
    assert column_collapse.front_at_thickness(deposit, 20.0) == pytest.approx(2000.0)
    # volume 1.03e6 m^2: 95 % lies inside the block, 99 % reaches 19 700 m^2 / 30 m into the sheet
    assert column_collapse.front_by_volume(deposit, 0.95) == pytest.approx(978.5)
    assert column_collapse.front_by_volume(deposit, 0.99) == pytest.approx(1000.0 + 19700.0 / 30.0)


def test_setup_starts_in_hydrostatic_equilibrium_with_the_column_in_place():
    sim = column_collapse.setup({"material": "sand", "height": HEIGHT, "width": 500.0, "cells_per_height": 8},
                                {"sand": granular()}, cfl=0.2)
    snap = sim.snapshot()
    deposit = column_collapse.deposit(snap)
    assert deposit["runout"] == pytest.approx(500.0, abs=1e-9)
    assert deposit["height"] == pytest.approx(HEIGHT, rel=1e-12)
    assert deposit["centroid"] == pytest.approx(250.0, rel=1e-12)
    assert column_collapse.front_at_thickness(deposit, 0.02 * HEIGHT) == pytest.approx(500.0, abs=1e-9)
    assert column_collapse.front_by_volume(deposit, 0.95) == pytest.approx(475.0, rel=1e-12)
    z = sim.mesh.cell_centers()[:, 1]
    inside = snap.volume_fraction[:, 0] == 1.0
    np.testing.assert_allclose(snap.pressure[inside], 2700.0 * G * (HEIGHT - z[inside]), rtol=1e-9)
    assert sim.strength.rough_walls == [(column_collapse.VERTICAL_AXIS, 0)]
    with pytest.raises(ValueError, match="cfl: must be <= 0.4"):
        column_collapse.setup({"material": "sand"}, {"sand": granular()}, cfl=0.5)


def cohesionless_collapse(width: float, samples: int, interval: float):
    """Run a cohesionless column of ``width`` (m) at 16 cells per height and Courant number 0.4,
    sampling every ``interval`` (s) ``samples`` times: (samples of (time in units of TAU, kinetic
    energy, deposit), the initial totals, the simulation)."""
    sim = column_collapse.setup({"material": "sand", "height": HEIGHT, "width": width, "cells_per_height": 16},
                                {"sand": granular(cohesion=0.0)}, cfl=0.4)
    initial = sim.totals()
    out = []
    for k in range(1, samples + 1):
        sim.run(k * interval)
        snap = sim.snapshot()
        out.append((sim.time / TAU, column_collapse.kinetic_energy(snap), column_collapse.deposit(snap)))
    return out, initial, sim


@pytest.fixture(scope="module")
def collapse():
    """Cohesionless column (Y0 = 0) of aspect ratio 1 at 16 cells per height, Courant number 0.4, run to 8 TAU.

    Returns the samples (time in units of TAU, kinetic energy, deposit) every TAU / 4, the
    initial totals, the simulation and L0.
    """
    width = HEIGHT
    samples, initial, sim = cohesionless_collapse(width, samples=32, interval=TAU / 4)
    return samples, initial, sim, width


def test_column_comes_to_rest_and_stays_at_rest(collapse):
    """Measured: the peak at 1.5 TAU; KE below 1e-3 of it from 5.25 TAU on, at most 2.4e-4 of it
    over [6, 8] TAU and 2.8e-5 at 8 TAU; the front does not move over [6, 8] TAU."""
    samples, _, _, width = collapse
    times = np.array([t for t, _, _ in samples])
    kinetic = np.array([k for _, k, _ in samples])
    peak = kinetic.max()
    assert 0.5 < times[np.argmax(kinetic)] < 3.0
    late = times >= 6.0
    assert kinetic[late].max() < 1.0e-3 * peak
    # no creep: over the last 2 TAU the front moves less than one cell, L0 / 16 (measured 0)
    runouts = [d["runout"] for t, _, d in samples if t >= 6.0]
    assert 0.0 <= runouts[-1] - runouts[0] < width / 16


def test_deposit_against_the_laboratory_scaling_laws(collapse):
    """Run-out (L_f - L0) / L0 within 35 % and height H_f / L0 within 25 % of the quasi-2d laws at a = 1.

    Measured at 8 TAU: run-out 1.562 (law 1.2, +30 %), height 0.821 (law 1.0, -18 %), the same
    to 0.6 % at Courant numbers 0.2 and 0.1 (docs/validation.md).  The laws' prefactors depend
    on the granular material (Balmforth & Kerswell 2005 found the run-out prefactor to vary
    with the friction angle between their four materials); the issue's 15 % is not met yet:
    the bounds catch a change of the deposit, not agreement with the law.
    """
    samples, _, _, width = collapse
    final = samples[-1][2]
    aspect = HEIGHT / width
    runout = (final["runout"] - width) / width
    assert runout == pytest.approx(column_collapse.scaling_runout(aspect), rel=0.35)
    assert final["height"] / width == pytest.approx(column_collapse.scaling_height(aspect), rel=0.25)


def test_collapse_conserves_mass_and_closes_the_energy_budget(collapse):
    """Measured: mass (mesh + outflow) to 5e-16; energy error 9.7e-5 of the gravity work."""
    _, initial, sim, _ = collapse
    final = sim.totals()
    assert final["mass_with_outflow"] == pytest.approx(initial["mass"], rel=1e-12)
    assert final["outflow_mass"] == 0.0
    budget = conservation_budget(initial, final, sim.floor_amounts, sim.gravity.work)
    assert sim.gravity.work > 0.0
    assert abs(budget["energy_error"] * initial["energy"]) < 1e-3 * sim.gravity.work
    # gravity acts along y and its impulse is not accumulated: only x momentum is budgeted, to
    # round-off of the momentum the gravity work could give the column, sqrt(2 M W)
    assert "momentum_y_error" not in budget
    unaccounted = abs(budget["momentum_x_unaccounted"]) * budget["momentum_scale"]
    assert unaccounted < 1e-12 * np.sqrt(2.0 * initial["mass"] * sim.gravity.work), budget


def test_a_deposit_that_reaches_the_end_of_the_mesh_grows_it_and_runs_as_on_the_longer_mesh():
    """With scene.room = 0.01 the mesh ends 4 cells (0.5 L0) past the column; the front gets there
    after TAU and the mesh grows along x instead of losing material, so the run ends as it would
    have on the grown mesh from the start: the same deposit, every cell within 1e-3 of its
    field's scale (measured 6e-4: the sliver of the front that filled the last column to less
    than EDGE_FILL left through the outflow face before the growth, 5e-8 of the mass)."""
    params = {"material": "sand", "height": HEIGHT, "width": HEIGHT, "cells_per_height": 8}
    sim = column_collapse.setup({**params, "room": 0.01}, {"sand": granular(cohesion=0.0)}, block_cells=4, cfl=0.4)
    assert sim.mesh.domain_hi[0] == pytest.approx(1.5 * HEIGHT)
    initial = sim.totals()
    sim.run(3.0 * TAU)
    assert sim.growths >= 1 and sim.mesh.domain_hi[0] > 1.5 * HEIGHT
    final = sim.totals()
    assert final["outflow_mass"] < 1e-6 * initial["mass"]
    assert abs(final["mass_with_outflow"] - initial["mass"]) < 1e-12 * initial["mass"]
    length = float(sim.mesh.domain_hi[0])
    room = (length / HEIGHT - 1.0) / column_collapse.scaling_runout(1.0) * 0.999
    long = column_collapse.setup({**params, "room": room}, {"sand": granular(cohesion=0.0)}, block_cells=4, cfl=0.4)
    assert long.mesh.domain_hi[0] == pytest.approx(length)
    long.run(3.0 * TAU)
    assert long.step_count == sim.step_count
    by_corner = {tuple(lo): b for b, lo in enumerate(long.mesh.block_lo)}
    pairs = np.array([(b, by_corner[tuple(lo)]) for b, lo in enumerate(sim.mesh.block_lo)])
    for name in ("alpha", "arho", "momentum", "energy"):
        grown = sim.mesh.interior(getattr(sim.state, name))[pairs[:, 0]]
        whole = long.mesh.interior(getattr(long.state, name))[pairs[:, 1]]
        assert np.abs(grown - whole).max() < 1e-3 * np.abs(whole).max(), name
    grown, whole = column_collapse.deposit(sim.snapshot()), column_collapse.deposit(long.snapshot())
    assert grown["runout"] == whole["runout"]
    assert grown["height"] == pytest.approx(whole["height"], rel=1e-4)
    assert grown["centroid"] == pytest.approx(whole["centroid"], rel=1e-4)


def test_a_deposit_that_would_leave_a_mesh_that_cannot_grow_stops_the_run_with_a_clear_error(monkeypatch):
    """Where the mesh may not grow (here: already at its limit) the run stops with a message naming
    ``room`` instead of losing material."""
    monkeypatch.setattr(column_collapse, "GROWTH_LIMIT", 1.0)
    sim = column_collapse.setup({"material": "sand", "height": HEIGHT, "width": HEIGHT, "cells_per_height": 8,
                                 "room": 0.01}, {"sand": granular(cohesion=0.0)}, block_cells=4, cfl=0.4)
    initial = sim.totals()
    with pytest.raises(HydroFailure, match="the deposit reached the far edge of the mesh, x = 1500 m.*scene.room"):
        sim.run(6.0 * TAU)
    assert TAU < sim.time < 6.0 * TAU
    assert sim.totals()["outflow_mass"] < 1e-6 * initial["mass"]


def test_tall_cohesionless_column_stops_inside_the_mesh():
    """Aspect ratio 6 (L0 = H0 / 6, 2.7 cells wide) at 16 cells per height, Courant number 0.4, to 10 TAU.

    The column falls and spreads and comes to rest by the issue's criteria: its front still
    (moving less than a quarter of a cell) over the last 2 TAU and the kinetic energy there
    below 1e-4 of its peak (measured: the front still, at most 6.2e-5; 2.5e-4 at Courant number
    0.2 with the tensile limit between the sweeps, 1.25e-3 before the sweeps' pressure predictor
    used the bulk modulus).  Without the surface-layer pressure and the hourglass viscosity it
    crept on past 8 TAU.  No material lost; the run-out short of the law's (measured 3.500,
    44 % short, at this resolution; docs/validation.md, "Granular column collapse") and the
    height within 25 % of the law (measured 1.952, +7 %)."""
    aspect = 6.0
    width = HEIGHT / aspect
    samples, initial, sim = cohesionless_collapse(width, samples=20, interval=TAU / 2)
    kinetic = np.array([e for _, e, _ in samples])
    late = np.array([t for t, _, _ in samples]) >= 8.0 - 1e-9
    assert kinetic[late].max() < 1.0e-4 * kinetic.max()
    fronts = [d["runout"] for t, _, d in samples if t >= 8.0 - 1e-9]
    assert 0.0 <= fronts[-1] - fronts[0] < 0.25 * HEIGHT / 16  # measured 0
    runout = (fronts[-1] - width) / width
    assert 0.0 < runout < column_collapse.scaling_runout(aspect)
    assert samples[-1][2]["height"] / width == pytest.approx(column_collapse.scaling_height(aspect), rel=0.25)
    final = sim.totals()
    assert final["outflow_mass"] == 0.0
    assert final["mass_with_outflow"] == pytest.approx(initial["mass"], rel=1e-12)


def test_deposit_does_not_depend_on_the_courant_number():
    """Aspect ratio 1, cohesionless, 8 cells per H0, to 8 TAU at Courant numbers 0.4 (the scene's
    MAX_CFL) and 0.1: the deposit's centroid within 0.5 % and the run-out within a cell (measured
    centroid 0.7097 and 0.7086 L0, 0.16 %, run-out 0.750 at both).  When the sweeps' pressure
    predictor used the longitudinal modulus K + 4G/3 (a viscosity G dt / 3 on shearing flows) the
    centroids were 0.6733 and 0.6970 L0 (3.4 %), and with the tensile limit between the sweeps
    0.7015 and 0.7059 L0; docs/validation.md, "Granular column collapse"."""
    deposits = []
    for cfl in (0.4, 0.1):
        sim = column_collapse.setup({"material": "sand", "height": HEIGHT, "width": HEIGHT, "cells_per_height": 8},
                                    {"sand": granular(cohesion=0.0)}, cfl=cfl)
        sim.run(8.0 * TAU)
        deposits.append(column_collapse.deposit(sim.snapshot()))
    assert deposits[0]["centroid"] == pytest.approx(deposits[1]["centroid"], rel=0.005)
    assert abs(deposits[0]["runout"] - deposits[1]["runout"]) < HEIGHT / 8


def test_step_tensile_limit_opens_void_until_the_material_is_back_at_its_limit():
    """hydro.scheme.step_tension.open_void_in_tension on Tillotson basalt stretched to 0.999 rho0 at
    e = 0 (P = -26.7 MPa, the column's excursions are below 16 MPa): with Y_T = 1e6 Pa the volume
    fraction falls until P(rho', e) is back at -Y_T, not below it and above it by at most 0.5 % of
    the excursion (measured 0.30 %: one Newton step from below overshoots by a second-order amount,
    3 % at 0.99 rho0), alpha rho and alpha rho e unchanged and the cell counted; cells in
    compression and at rho0 are left alone."""
    from impactpipe.hydro.eos import pressure_sound_speed
    from impactpipe.hydro.mesh.blocks import GHOST
    from impactpipe.hydro.scheme.pencil_layout import FLOOR_TENSILE_LIMIT, NFLOOR
    from impactpipe.hydro.scheme.step_tension import open_void_in_tension

    basalt = preset_material("basalt")["eos"]
    eos = pack_eos([basalt])
    rho0 = basalt["rho0"]
    n = 3 + 2 * GHOST
    alpha, arho, arhoe = np.zeros((1, 1, n, 1, 1)), np.zeros((1, 1, n, 1, 1)), np.zeros((1, 1, n, 1, 1))
    cells = [GHOST, GHOST + 1, GHOST + 2]
    for c, rho in zip(cells, (0.999 * rho0, 1.01 * rho0, rho0)):
        alpha[0, 0, c], arho[0, 0, c] = 1.0, rho
    arhoq = np.zeros((1, 0, n, 1, 1))
    floors = np.zeros((1, NFLOOR), dtype=np.int64)
    y_t = 1.0e6
    before = (arho.copy(), arhoe.copy())
    p_start = pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, 0.999 * rho0, 0.0)[0]
    open_void_in_tension(alpha, arho, arhoe, arhoq, eos.kind, eos.params, eos.table, np.array([y_t]), floors, 0, 1)
    rho_new = arho[0, 0, cells[0], 0, 0] / alpha[0, 0, cells[0], 0, 0]
    p_new = pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, rho_new, 0.0)[0]
    assert alpha[0, 0, cells[0], 0, 0] < 1.0
    assert -y_t <= p_new <= -y_t + 0.005 * (-y_t - p_start)
    assert alpha[0, 0, cells[1], 0, 0] == 1.0 and alpha[0, 0, cells[2], 0, 0] == 1.0
    np.testing.assert_array_equal(arho, before[0])
    np.testing.assert_array_equal(arhoe, before[1])
    assert floors[0, FLOOR_TENSILE_LIMIT] == 1


def test_settle_void_compacts_each_column_downwards_and_conserves_mass_momentum_and_energy():
    """hydro.scheme.settling.settle_void on one column of 16 cells in 4 blocks: the fills 0.5, 0.3,
    1, 0.6 from the floor up, then a void cell, then 0.4 (material resting on nothing), become
    1, 1, 0.4, 0, 0, 0.4; mass, momentum and total energy are conserved to round-off, the
    potential energy released (the work of gravity returned) is positive and in the total energy,
    and the kinetic energy lost in merging the velocities is in the internal energy."""
    from impactpipe.hydro.scheme.settling import settle_void

    mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [4.0, 64.0], [4, 16], [("reflecting", "outflow")] * 2, 4)
    eos = pack_eos([preset_material("basalt")["eos"]])
    row = np.floor(mesh.cell_centers()[:, 1] / 4.0).astype(int)
    fills = np.zeros(16)
    fills[:6] = [0.5, 0.3, 1.0, 0.6, 0.0, 0.4]
    velocity = np.zeros((mesh.nblocks, 3) + mesh.interior_shape)
    velocity[:, 0] = 3.0 * row
    velocity[:, 1] = -1.0
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, fills[row], 0, eos, 2700.0, velocity, pressure=0.0)
    volume = 4.0  # 1 m x 4 m cells, per m of depth

    def totals():
        return (mesh.interior(state.arho).sum() * volume, mesh.interior(state.momentum).sum(axis=(0, 2, 3, 4)) * volume,
                mesh.interior(state.energy).sum() * volume)

    before = totals()
    work = np.zeros(mesh.nblocks)
    counts = np.zeros(mesh.nblocks, np.int64)
    settle_void(state.alpha, state.arho, state.arhoe, state.arhoq, state.momentum, state.energy, mesh.neighbor,
                mesh.block_dx, G, work, counts)
    after = totals()
    fill = mesh.interior(state.alpha)[:, 0]
    column = np.array([fill[row == j].mean() for j in range(16)])
    np.testing.assert_allclose(column[:7], [1.0, 1.0, 0.4, 0.0, 0.0, 0.4, 0.0], atol=1e-12)
    assert after[0] == pytest.approx(before[0], rel=1e-14)
    np.testing.assert_allclose(after[1], before[1], rtol=1e-13, atol=1e-9 * abs(before[1]).max())
    assert work.sum() > 0.0
    assert after[2] - before[2] == pytest.approx(work.sum(), rel=1e-9)
    rho = mesh.interior(state.arho)[:, 0]
    kinetic = 0.5 * (mesh.interior(state.momentum) ** 2).sum(axis=1) / np.where(rho > 0.0, rho, 1.0)
    internal = mesh.interior(state.arhoe)[:, 0]
    np.testing.assert_allclose(mesh.interior(state.energy)[:, 0], internal + kinetic, rtol=1e-12,
                               atol=1e-9 * mesh.interior(state.energy).max())
    assert counts.sum() > 0


def test_with_void_settling_the_deposit_changes_less_with_resolution(tmp_path):
    """Aspect ratio 1, cohesionless, Courant number 0.4, to 8 TAU with ``scene.settling``: the
    deposit's centroid at 8 and 16 cells per H0 within 12 % (measured 0.6791 and 0.7409 L0, 9.1 %;
    without the settling 0.7097 and 0.8891 L0, 25 %) and the run-outs within 0.4 L0 (measured 0.750
    and 1.000 L0; without 0.750 and 1.562); docs/validation.md, "Void settling"."""
    deposits = []
    for cells in (8, 16):
        sim = column_collapse.setup({"material": "sand", "height": HEIGHT, "width": HEIGHT, "cells_per_height": cells,
                                     "settling": True}, {"sand": granular(cohesion=0.0)}, cfl=0.4)
        sim.run(8.0 * TAU)
        deposits.append(column_collapse.deposit(sim.snapshot()))
        assert sim.settled_cells > 0 and sim.floor_counts["void_settling"] == sim.settled_cells
    sim.save_checkpoint(tmp_path / "settled.h5")
    assert Simulation.from_checkpoint(tmp_path / "settled.h5").settled_cells == sim.settled_cells
    assert deposits[0]["centroid"] == pytest.approx(deposits[1]["centroid"], rel=0.12)
    assert abs(deposits[0]["runout"] - deposits[1]["runout"]) < 0.4 * HEIGHT


def test_with_the_face_shear_stress_instead_of_the_hourglass_viscosity_the_column_stops_near_the_laws():
    """Aspect ratio 1, cohesionless, 16 cells per H0, Courant number 0.4, to 8 TAU with
    ``scene.face_shear`` and ``hourglass: 0``: at rest (kinetic energy below 1e-4 of its peak at
    8 TAU, measured 7.4e-6; the front still over [6, 8] TAU, measured still for 4.75 TAU), run-out
    and height within 15 % of the laws (measured 1.125 and 0.918 L0, -6 % and -8 %; the hourglass
    viscosity off without it: 1.789 and 0.791, +49 % and -21 %); docs/validation.md, "The odd-even
    mode at its source"."""
    sim = column_collapse.setup({"material": "sand", "height": HEIGHT, "width": HEIGHT, "cells_per_height": 16,
                                 "hourglass": 0.0, "face_shear": True}, {"sand": granular(cohesion=0.0)}, cfl=0.4)
    assert sim.strength.hourglass[0] == 0.0 and sim.strength.face is not None
    peak, runouts = 0.0, []
    for k in range(1, 33):
        sim.run(k * TAU / 4)
        snap = sim.snapshot()
        energy = column_collapse.kinetic_energy(snap)
        peak = max(peak, energy)
        if k >= 24:
            runouts.append(column_collapse.deposit(snap)["runout"])
    deposit = column_collapse.deposit(snap)
    assert energy < 1.0e-4 * peak
    assert runouts[-1] - runouts[0] < HEIGHT / 16
    law_runout, law_height = column_collapse.scaling_runout(1.0), column_collapse.scaling_height(1.0)
    assert (deposit["runout"] - HEIGHT) / HEIGHT == pytest.approx(law_runout, rel=0.15)
    assert deposit["height"] / HEIGHT == pytest.approx(law_height, rel=0.15)
