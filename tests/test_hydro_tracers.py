"""Lagrangian tracers (hydro/tracers/): transport, integrator order, peaks, void, exits, I/O,
adaptive meshes (locate, level-aware stencil, regrids)."""

import h5py
import numpy as np
import pytest

from impactpipe.hydro import PROBLEMS, BlockMesh, HydroState, Simulation, read_tracers, write_tracers
from impactpipe.hydro.amr.regrid import RefinementRule, refine_to
from impactpipe.hydro.eos import pack_eos, temperature
from impactpipe.hydro.exact.impedance import planar_impact_state
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.tracers.locate import locate
from impactpipe.hydro.tracers.motion import TRACER_UNITS, Tracers, interpolate_velocity
from impactpipe.hydro.tracers.placement import place_on_grid, place_on_rays

GAS_SPEC = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}
GASES = {"heavy": {"eos": GAS_SPEC}, "light": {"eos": {"model": "ideal_gas", "gamma": 1.67, "cv": 3000.0}}}
BASALT = {"basalt": preset_material("basalt")}


def _lattice(lo, hi, counts):
    """(N, 3) cell-centred lattice points in the box [lo, hi] (unused axes 0)."""
    axes = [lo[d] + (np.arange(n) + 0.5) / n * (hi[d] - lo[d]) for d, n in enumerate(counts)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(counts))
    out = np.zeros((pts.shape[0], 3))
    out[:, : len(counts)] = pts
    return out


def _held_field_sim(mesh, velocity, density=1.0):
    """A one-gas Simulation on ``mesh`` with the cell velocity ``velocity`` (NB, 3, nx, ny, nz)."""
    eos = pack_eos([GAS_SPEC])
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, eos, density, velocity, pressure=1.0)
    return Simulation(mesh, ["gas"], [GAS_SPEC], state)


def _advance_held(sim, tracers, dt, steps):
    """Move ``tracers`` through the hooks ``steps`` times over a velocity field held fixed (no sweeps)."""
    for _ in range(steps):
        tracers.before_step(sim)
        sim.time += dt
        tracers.after_step(sim, dt)


@pytest.mark.parametrize("geometry", ["2d-planar", "3d"])
def test_uniform_flow_is_followed_exactly(geometry):
    """Tracers of both materials of a moving two-gas slab move by v t (periodic box)."""
    cells = 64 if geometry == "2d-planar" else 32
    sim = PROBLEMS["interface_advection"].setup({"cells": cells}, GASES, geometry=geometry)
    mesh = sim.mesh
    ndim = mesh.ndim
    pos = _lattice(mesh.domain_lo, mesh.domain_hi, [23] + [3] * (ndim - 1))
    inner = (pos[:, 0] >= 0.25) & (pos[:, 0] < 0.75)
    tracers = Tracers(pos, np.where(inner, 0, 1))
    sim.tracers = tracers
    end = 0.3
    sim.run(end)
    shift = (tracers.position[:, 0] - tracers.initial_position[:, 0]) % 1.0
    assert np.abs(shift / end - 1.0).max() < 1e-10
    np.testing.assert_allclose(tracers.position[:, 1:], tracers.initial_position[:, 1:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(tracers.velocity[:, 0], 1.0, rtol=1e-10)
    assert not tracers.exited.any()
    # uniform pressure: every tracer recorded p = 1 Pa (and the gas's temperature)
    np.testing.assert_allclose(tracers.peak_pressure, 1.0, rtol=1e-10)
    assert np.isfinite(tracers.peak_temperature).all()


def _rotation_error(steps_per_turn, omega=2.0):
    mesh = BlockMesh.uniform("2d-planar", [-1.0, -1.0], [1.0, 1.0], [64, 64], [("outflow", "outflow")] * 2, 16)
    c = mesh.cell_centers()
    vel = np.zeros_like(c)
    vel[:, 0] = -omega * c[:, 1]
    vel[:, 1] = omega * c[:, 0]
    sim = _held_field_sim(mesh, vel)
    radius = 0.8
    rr, th = np.meshgrid(np.linspace(0.1, radius, 8), np.linspace(0.0, 2 * np.pi, 13)[:-1] + 0.1)
    pos = np.stack([rr.ravel() * np.cos(th.ravel()), rr.ravel() * np.sin(th.ravel())], axis=1)
    tracers = Tracers(pos, np.zeros(len(pos), dtype=int))
    dt = 2.0 * np.pi / omega / steps_per_turn
    _advance_held(sim, tracers, dt, steps_per_turn)
    return float(np.abs(tracers.position - tracers.initial_position).max() / radius), sim, dt


def test_rigid_rotation_returns_after_one_turn_second_order():
    """Heun over a held rigid rotation: back to the start within 1e-3 R after one turn at a
    CFL-like step (0.4 dx / max |v|), and the error falls as dt^2."""
    dx = 2.0 / 64
    omega = 2.0
    steps = int(np.ceil(2.0 * np.pi / omega / (0.4 * dx / (omega * np.sqrt(2.0)))))
    err, sim, dt = _rotation_error(steps, omega)
    assert err < 1e-3
    err_half, _, _ = _rotation_error(2 * steps, omega)
    assert err / err_half > 3.5
    # the interpolated field of a linear velocity in uniform density is exact, block edges and corners included
    rng = np.random.default_rng(3)
    pts = rng.uniform(-0.99, 0.99, (400, 2))
    pts[:8] = [[-0.5, -0.5], [0.0, 0.0], [0.5, 0.0], [0.0, 0.5], [-0.5, 0.5], [0.5, -0.5], [0.01, 0.01], [0.99, 0.0]]
    v = interpolate_velocity(sim, pts, np.zeros(len(pts), dtype=int))
    inner = np.abs(pts).max(axis=1) < 1.0 - 0.5 * dx  # outflow faces: zero-gradient edge cells
    np.testing.assert_allclose(v[inner, 0], -omega * pts[inner, 1], rtol=0, atol=1e-13)
    np.testing.assert_allclose(v[inner, 1], omega * pts[inner, 0], rtol=0, atol=1e-13)


def test_peak_pressure_in_planar_impact_matches_impedance_matching():
    """Basalt on basalt at 2 km/s: tracers away from the free surfaces record the shocked
    pressure (3 %) and temperature (3 % away from the contact) and ride the shocked flow."""
    velocity, end = 2000.0, 1.0e-4
    sim = PROBLEMS["planar_impact"].setup({"flyer": {"material": "basalt", "velocity": velocity},
                                           "target": {"material": "basalt"}, "cells": 400, "end_time": end},
                                          BASALT)
    x0 = np.concatenate([np.linspace(-0.3, -0.05, 11), np.linspace(0.05, 0.3, 11)])
    tracers = Tracers(x0[:, None], np.zeros(x0.size, dtype=int))
    sim.tracers = tracers
    sim.run(end)
    exact = planar_impact_state(BASALT["basalt"]["eos"], BASALT["basalt"]["eos"], velocity)
    assert np.abs(tracers.peak_pressure / exact.pressure - 1.0).max() < 0.03
    eos = pack_eos([BASALT["basalt"]["eos"]])
    t_exact = temperature(eos.kind[0], eos.params[0], eos.table, exact.target.density, exact.target.energy)
    far = np.abs(x0) > 0.1
    assert np.abs(tracers.peak_temperature[far] / t_exact - 1.0).max() < 0.03
    # shock arrival t_a, then the tracer moves at the contact speed u
    u = exact.particle_velocity
    arrival = np.where(x0 > 0, x0 / exact.target.shock_velocity, -x0 / exact.flyer.shock_velocity)
    expected = np.where(x0 > 0, x0, x0 + velocity * arrival) + u * (end - arrival)
    dx = sim.mesh.min_cell_size()
    assert np.abs(tracers.position[:, 0] - expected).max() < 0.5 * dx
    assert (tracers.peak_pressure_time >= 0.9 * arrival).all()
    np.testing.assert_allclose(tracers.velocity[:, 0], u, rtol=0.02)


@pytest.mark.parametrize("speed", [0.0, 1000.0])
def test_tracers_next_to_void_stay_in_their_material(speed):
    """A basalt slab in void (mixed edge cells, p = 0): at rest the tracers do not move at all;
    moving, they move by v t to round-off and stay inside the slab, edge cells included."""
    cells = 64
    dx = 1.0 / cells
    params = {"cells": cells, "slab_lo": 0.25 + 0.4 * dx, "slab_hi": 0.75 - 0.3 * dx, "velocity": speed,
              "inner": {"material": "basalt", "density": 2700.0}, "outer": None,
              "pressure": 0.0}
    sim = PROBLEMS["interface_advection"].setup(params, BASALT, geometry="2d-planar")
    lo, hi = params["slab_lo"], params["slab_hi"]
    x = np.concatenate([np.linspace(lo + 1e-6, lo + 2 * dx, 6), np.linspace(0.3, 0.7, 5),
                        np.linspace(hi - 2 * dx, hi - 1e-6, 6)])
    pos = np.stack([x, np.full(x.size, 0.3 * sim.mesh.domain_hi[1])], axis=1)
    tracers = Tracers(pos, np.zeros(x.size, dtype=int))
    sim.tracers = tracers
    steps = sim.run(1.0e-3, max_steps=100)
    moved = tracers.position[:, 0] - tracers.initial_position[:, 0]
    if speed == 0.0:
        assert steps == 100
        np.testing.assert_array_equal(tracers.position, tracers.initial_position)
    else:
        np.testing.assert_allclose(moved, speed * sim.time, rtol=1e-10)
        assert speed * sim.time > 2 * dx  # crossed cells, so void-side stencils were met
    assert (tracers.position[:, 0] > lo + speed * sim.time).all()
    assert (tracers.position[:, 0] < hi + speed * sim.time).all()
    np.testing.assert_allclose(tracers.peak_pressure, 0.0, atol=1.0)


def _cylinder_mesh():
    return BlockMesh.uniform("2d-cylindrical", [0.0, 0.0], [1.0, 2.0], [32, 64],
                             [("reflecting", "outflow"), ("outflow", "outflow")], 16)


def test_exit_flags_time_velocity_and_ballistic_motion():
    """Held field v = (c r, 1) in r-z: tracers leave through z = 2 at t = 2 - z0, keep their
    exit velocity, then move ballistically."""
    mesh = _cylinder_mesh()
    c = 0.3
    vel = np.zeros((mesh.nblocks, 3) + mesh.interior_shape)
    vel[:, 0] = c * mesh.cell_centers()[:, 0]
    vel[:, 1] = 1.0
    sim = _held_field_sim(mesh, vel)
    pos = _lattice([0.05, 0.5], [0.4, 1.9], [4, 8])
    tracers = Tracers(pos, np.zeros(len(pos), dtype=int))
    dt, steps = 0.01, 180
    _advance_held(sim, tracers, dt, steps)
    end = dt * steps
    z0, r0 = pos[:, 1], pos[:, 0]
    t_exit = 2.0 - z0
    assert tracers.exited.all()
    np.testing.assert_allclose(tracers.exit_time, t_exit, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tracers.position[:, 1], z0 + end, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tracers.velocity[:, 1], 1.0, rtol=1e-12)
    # v_r at exit: the step mean of c r(t), r = r0 exp(c t)
    np.testing.assert_allclose(tracers.velocity[:, 0], c * r0 * np.exp(c * t_exit), rtol=3e-3)
    r_exit = r0 * np.exp(c * t_exit)
    np.testing.assert_allclose(tracers.position[:, 0], r_exit + tracers.velocity[:, 0] * (end - t_exit), rtol=2e-3)
    to = tracers.to_tracer_set()
    assert len(to) == len(pos) and to.exited.all()


def test_axis_reflection_in_cylindrical_geometry():
    """A tracer driven through r = 0 in one step comes back mirrored with v_r negated.

    Cells (dx = 1/32) hold v_r = -5 in the first column and -0.5 elsewhere; from r = 1.5 dx
    with dt = 2.8 dx: v_n = -0.5, x* = 0.1 dx where v = 0.4 (+5) + 0.6 (-5) = -1 (mirror
    cell), so r_{n+1} = 1.5 dx - 1.4 dx (1.5) = -0.6 dx -> 0.6 dx, v_r = +0.75.
    """
    mesh = _cylinder_mesh()
    dx = mesh.min_cell_size()
    vel = np.zeros((mesh.nblocks, 3) + mesh.interior_shape)
    r = mesh.cell_centers()[:, 0]
    vel[:, 0] = np.where(r < dx, -5.0, -0.5)
    sim = _held_field_sim(mesh, vel)
    tracers = Tracers([[1.5 * dx, 20.5 * dx]], [0])
    _advance_held(sim, tracers, 2.8 * dx, 1)
    assert tracers.position[0, 0] == pytest.approx(0.6 * dx, rel=1e-12)
    assert tracers.velocity[0, 0] == pytest.approx(0.75, rel=1e-12)
    assert tracers.position[0, 1] == 20.5 * dx and not tracers.exited[0]


def _impact_with_tracers():
    """Thin plates (0.2 m): the shocked target's rear flies off through the outflow end by 1.2e-4 s."""
    sim = PROBLEMS["planar_impact"].setup({"flyer": {"thickness": 0.2}, "target": {"thickness": 0.2},
                                           "cells": 160, "end_time": 1.2e-4}, BASALT)
    x0 = np.linspace(-0.19, 0.19, 40)
    tracers = Tracers(x0[:, None], np.zeros(x0.size, dtype=int), history_interval=2.0e-5, end_time=1.0e-4)
    sim.tracers = tracers
    return sim, tracers


def test_checkpoint_continues_bit_for_bit_and_failed_step_restores(tmp_path):
    sim, ref = _impact_with_tracers()
    sim.run(5.0e-5)  # same step sequence as the checkpointed run
    sim.run(1.2e-4)
    assert ref.exited.any() and np.isfinite(ref.exit_time[ref.exited]).all()
    sim2, _ = _impact_with_tracers()
    sim2.run(5.0e-5)
    sim2.save_checkpoint(tmp_path / "ckpt.h5")
    restored = Simulation.from_checkpoint(tmp_path / "ckpt.h5")
    restored.run(1.2e-4)
    for name in TRACER_UNITS:
        np.testing.assert_array_equal(getattr(restored.tracers, name), getattr(ref, name))
    for a, b in zip(restored.tracers.history, ref.history):
        np.testing.assert_array_equal(a, b)
    assert ref.history[0].size >= 6
    # a step undone by restore_last_good puts the tracer records back
    before = {name: getattr(restored.tracers, name).copy() for name in TRACER_UNITS}
    count = restored.tracers.history_count
    restored.step()
    restored.restore_last_good()
    for name in TRACER_UNITS:
        np.testing.assert_array_equal(getattr(restored.tracers, name), before[name])
    assert restored.tracers.history_count == count


def test_write_read_round_trip_with_units(tmp_path):
    sim, tracers = _impact_with_tracers()
    sim.run(6.0e-5)
    path = tmp_path / "hydro.h5"
    with h5py.File(path, "w") as fh:
        fh.create_group("snapshots")
    assert read_tracers(path) is None
    with h5py.File(path, "a") as fh:
        write_tracers(fh, tracers)
        write_tracers(fh, tracers)  # replaces
    back = read_tracers(path)
    for name in TRACER_UNITS:
        np.testing.assert_array_equal(getattr(back, name), getattr(tracers, name))
    assert back.exited.dtype == np.bool_
    with h5py.File(path, "r") as fh:
        grp = fh["tracers"]
        assert all("units" in grp[name].attrs for name in grp)
        assert grp["peak_pressure"].attrs["units"] == "Pa" and grp["position"].attrs["units"] == "m"
        np.testing.assert_array_equal(grp["history_position"][()], tracers.history[1])
    with h5py.File(tmp_path / "set.h5", "w") as fh:
        write_tracers(fh, tracers.to_tracer_set())
    np.testing.assert_array_equal(read_tracers(tmp_path / "set.h5").peak_pressure, tracers.peak_pressure)


def test_placement_and_locate():
    radius, rp = 1000.0, 100.0
    pos, mat = place_on_rays((0.0, radius), radius, 0.0, projectile_radius=rp, projectile_center_z=radius + rp)
    target, proj = pos[mat == 0], pos[mat == 1]
    assert len(target) == 900 and len(proj) > 20
    assert (target[:, 0] > 0).all() and (np.hypot(target[:, 0], target[:, 1]) < radius).all()
    assert (np.hypot(proj[:, 0], proj[:, 1] - radius - rp) < rp).all() and (proj[:, 0] > 0).all()
    # 30 rays, 30 tracers each, evenly spaced along each ray's chord 2 R cos(theta)
    ray = target[:30]
    step = np.hypot(*np.diff(ray[:, :2], axis=0).T)
    theta = 0.25 * np.pi / 30
    np.testing.assert_allclose(step, 2 * radius * np.cos(theta) / 30, rtol=1e-12)
    pos3, mat3 = place_on_grid([0, 0, 0], radius, [0, 0, radius + rp], rp, spacing=100.0)
    n_target = (mat3 == 0).sum()
    assert abs(n_target / (4 / 3 * np.pi * radius**3 / 100.0**3) - 1) < 0.05
    assert (mat3 == 1).sum() > 200
    # locate: every cell centre lies in its own block, points outside give -1
    mesh = _cylinder_mesh()
    centres = np.moveaxis(mesh.cell_centers(), 1, -1).reshape(mesh.nblocks, -1, 3)
    blocks = locate(mesh, centres.reshape(-1, 3)).reshape(mesh.nblocks, -1)
    assert (blocks == np.arange(mesh.nblocks)[:, None]).all()
    np.testing.assert_array_equal(locate(mesh, [[0.5, -0.1, 0.0], [1.5, 1.0, 0.0]]), [-1, -1])


# ---------------------------------------------------------------------------- adaptive mesh


def _box_level(mesh, lo, hi, level):
    """(NB,) ``level`` for the blocks overlapping the box [lo, hi] (m), 0 elsewhere."""
    nd = mesh.ndim
    overlap = ((mesh.block_lo[:, :nd] < hi) & (mesh.block_hi[:, :nd] > lo)).all(axis=1)
    return np.where(overlap, level, 0)


def _box_rule(lo, hi, interval):
    """Refinement by one level-1 box only (no indicators), regrid every ``interval`` steps."""
    return RefinementRule(interval=interval, interfaces="off", pressure_jump=None, density_jump=None,
                          boxes=((tuple(lo), tuple(hi), 1),))


ADAPTIVE_MESHES = {
    # three levels: a level-2 patch in a level-1 ring, and a level-1 patch
    "2d-planar": (("2d-planar", [-1.0, -1.0], [1.0, 1.0], [32, 32], [("outflow", "outflow")] * 2, 8, 2),
                  lambda m: np.maximum(_box_level(m, [-0.3, -0.2], [0.1, 0.4], 2),
                                       _box_level(m, [0.5, -0.9], [0.9, -0.5], 1))),
    "2d-cylindrical": (("2d-cylindrical", [0.0, 0.0], [1.0, 1.0], [32, 32],
                        [("reflecting", "outflow"), ("outflow", "outflow")], 8, 2),
                       lambda m: _box_level(m, [0.0, 0.3], [0.2, 0.5], 2)),
    "3d": (("3d", [0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [16, 16, 16], [("outflow", "outflow")] * 3, 8, 1),
           lambda m: _box_level(m, [0.3, 0.3, 0.3], [0.45, 0.45, 0.45], 1)),
}


@pytest.mark.parametrize("geometry", sorted(ADAPTIVE_MESHES))
def test_adaptive_locate_and_linear_field_exact(geometry):
    """On a refined mesh every cell centre is located in its own block, and the interpolated
    linear velocity field (uniform density) is exact to round-off everywhere, coarse/fine faces,
    edges and corners included (the stencil drops to the coarser level there)."""
    args, wanted = ADAPTIVE_MESHES[geometry]
    mesh = refine_to(BlockMesh.uniform(*args[:6], max_level=args[6]), wanted)
    nd = mesh.ndim
    assert len(np.unique(mesh.block_level)) >= 2
    centres = np.moveaxis(mesh.cell_centers(), 1, -1).reshape(mesh.nblocks, -1, 3)
    blocks = locate(mesh, centres.reshape(-1, 3)).reshape(mesh.nblocks, -1)
    assert (blocks == np.arange(mesh.nblocks)[:, None]).all()
    gradient = np.array([[0.3, -2.0, 0.7], [1.5, 0.2, -0.4], [0.5, 0.9, 0.1]])[:nd, :nd]
    offset = 0.25
    if geometry == "2d-cylindrical":  # v_r odd in r at the axis
        gradient, offset = np.diag([0.3, 0.7]), 0.0
    c = mesh.cell_centers()
    vel = np.zeros_like(c)
    vel[:, :nd] = np.einsum("ij,bj...->bi...", gradient, c[:, :nd]) + offset
    sim = _held_field_sim(mesh, vel, density=2.0)
    rng = np.random.default_rng(5)
    pts = rng.uniform(mesh.domain_lo[:nd], mesh.domain_hi[:nd], (4000, nd))
    faces = mesh.block_lo[rng.integers(0, mesh.nblocks, 1000), :nd]  # on block faces, edges and corners
    pts = np.concatenate([pts, faces])
    dx0 = mesh.root_cell_size[:nd]
    inner = np.ones(len(pts), dtype=bool)  # outflow faces: zero-gradient edge cells
    for d, (low, high) in enumerate(mesh.boundaries):
        inner &= (low != "outflow") | (pts[:, d] > mesh.domain_lo[d] + 0.5 * dx0[d])
        inner &= (high != "outflow") | (pts[:, d] < mesh.domain_hi[d] - 0.5 * dx0[d])
    pts = pts[inner]
    v = interpolate_velocity(sim, pts, np.zeros(len(pts), dtype=int))
    np.testing.assert_allclose(v[:, :nd], pts @ gradient.T + offset, rtol=0, atol=1e-13)


def test_uniform_flow_on_adaptive_mesh_with_moving_refinement():
    """Uniform gas moving at (1, 0.5) m/s in a periodic box, two levels, a level-1 box moving at
    (-4, 2) m/s and regrids every 2 steps: tracers cross coarse/fine faces (by their motion and
    by regrids) and move by v t to round-off.

    Tolerance: the tracer velocity is a convex combination of cell velocities, so the error
    of x is at most t max|u_c - u| (max over cells and steps, measured) plus one rounding of
    x (<= 1 m) per step, 2^-52 each."""
    u = np.array([1.0, 0.5, 0.0])
    box_velocity = np.array([-4.0, 2.0])

    def box(t):
        lo = (np.array([0.3, 0.2]) + box_velocity * t) % 1.0
        return lo, np.minimum(lo + 0.35, 1.0)

    mesh = BlockMesh.uniform("2d-planar", [0.0, 0.0], [1.0, 1.0], [32, 32], [("periodic", "periodic")] * 2, 8,
                             max_level=1)
    mesh = refine_to(mesh, lambda m: _box_level(m, *box(0.0), 1))
    eos = pack_eos([GAS_SPEC])
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, eos, 1.0, u, pressure=1.0)
    pos = _lattice([0.0, 0.0], [1.0, 1.0], [12, 12])
    tracers = Tracers(pos, np.zeros(len(pos), dtype=int))
    sim = Simulation(mesh, ["gas"], [GAS_SPEC], state, tracers=tracers, refinement=_box_rule(*box(0.0), 2))
    level = None
    crossed = regridded = 0
    worst = 0.0
    while sim.time < 0.25:
        sim.refinement = _box_rule(*box(sim.time), 2)
        regrids = sim.regrids
        sim.step()
        m, st = sim.mesh, sim.state
        worst = max(worst, float(np.abs(m.interior(st.momentum)[:, :2] / m.interior(st.arho).sum(axis=1)[:, None]
                                        - u[None, :2, None, None, None]).max()))
        new_level = m.block_level[tracers.owning_block]
        if level is not None:
            changed = int((new_level != level).sum())
            if sim.regrids == regrids:
                crossed += changed
            else:
                regridded += changed
        level = new_level
        assert (tracers.owning_block >= 0).all()
    assert sim.regrids >= 6 and crossed >= 20 and regridded >= 100
    assert set(np.unique(sim.mesh.block_level)) == {0, 1}
    shift = tracers.position[:, :2] - tracers.initial_position[:, :2] - u[:2] * sim.time
    error = np.abs((shift + 0.5) % 1.0 - 0.5).max()
    assert error <= sim.time * worst + sim.step_count * 2.0**-52
    assert error < 1e-13
    np.testing.assert_allclose(tracers.velocity, np.broadcast_to(u, tracers.velocity.shape), rtol=0, atol=1e-13)
    np.testing.assert_allclose(tracers.peak_pressure, 1.0, rtol=1e-12)
    assert not tracers.exited.any()
    print(f"steps {sim.step_count} regrids {sim.regrids} crossings {crossed} by regrids {regridded} "
          f"max |u_c - u| {worst:.2e} error {error:.2e}")


def test_rigid_rotation_on_adaptive_mesh_with_regrids():
    """Held rigid rotation on a two-level mesh whose level-1 box counter-rotates (regrid every
    20 steps): tracers cross coarse/fine faces and regrids and return within 1e-3 R after one
    turn at dt = 0.4 dx_fine / max|v|.  The regrids move the linear field exactly (conservative
    prolongation and restriction are exact for linear data away from the outflow faces)."""
    omega, radius = 2.0, 0.8
    mesh = BlockMesh.uniform("2d-planar", [-1.0, -1.0], [1.0, 1.0], [32, 32], [("outflow", "outflow")] * 2, 8,
                             max_level=1)

    def box(t):
        centre = 0.45 * np.array([np.cos(-omega * t), np.sin(-omega * t)])
        return centre - 0.3, centre + 0.3

    mesh = refine_to(mesh, lambda m: _box_level(m, *box(0.0), 1))
    c = mesh.cell_centers()
    vel = np.zeros_like(c)
    vel[:, 0] = -omega * c[:, 1]
    vel[:, 1] = omega * c[:, 0]
    sim = _held_field_sim(mesh, vel)
    rr, th = np.meshgrid(np.linspace(0.1, radius, 8), np.linspace(0.0, 2 * np.pi, 13)[:-1] + 0.1)
    pos = np.stack([rr.ravel() * np.cos(th.ravel()), rr.ravel() * np.sin(th.ravel())], axis=1)
    tracers = sim.tracers = Tracers(pos, np.zeros(len(pos), dtype=int))
    dx = mesh.min_cell_size()
    steps = int(np.ceil(2.0 * np.pi / omega / (0.4 * dx / (omega * np.sqrt(2.0)))))
    dt = 2.0 * np.pi / omega / steps
    levels_seen = np.zeros((len(pos), 2), dtype=bool)
    for n in range(steps):
        if n % 20 == 0:
            sim.refinement = _box_rule(*box(sim.time), 20)
            sim.regrid()
        _advance_held(sim, tracers, dt, 1)
        levels_seen[np.arange(len(pos)), sim.mesh.block_level[tracers.owning_block]] = True
    error = np.abs(tracers.position - tracers.initial_position).max() / radius
    assert sim.regrids >= 10 and levels_seen.all(axis=1).sum() > len(pos) // 2
    assert error < 1e-3
    print(f"steps {steps} regrids {sim.regrids} tracers on both levels {levels_seen.all(axis=1).sum()} / {len(pos)} "
          f"error / R {error:.2e}")


def test_regrid_keeps_tracers_and_their_records():
    """Refining and then coarsening a region under the tracers (both renumber the blocks) keeps
    every position, velocity, peak and exit record bit for bit; each tracer on the mesh is
    re-found in the new leaf holding it, an exited tracer stays off the mesh, and stepping on
    continues."""
    mesh = BlockMesh.uniform("2d-planar", [-1.0, -1.0], [1.0, 1.0], [32, 32], [("outflow", "outflow")] * 2, 8,
                             max_level=1)
    c = mesh.cell_centers()
    vel = np.zeros_like(c)
    vel[:, 0] = -2.0 * c[:, 1]
    vel[:, 1] = 2.0 * c[:, 0]
    eos = pack_eos([GAS_SPEC])
    state = HydroState.empty(mesh, 1)
    state.set_material(mesh, 1.0, 0, eos, 1.0, vel, pressure=4.0 + c[:, 0] + 2.0 * c[:, 1])
    sim = Simulation(mesh, ["gas"], [GAS_SPEC], state)
    pos = np.concatenate([_lattice([-0.6, -0.6], [0.6, 0.6], [15, 15])[:, :2], [[0.95, 0.95]]])
    tracers = sim.tracers = Tracers(pos, np.zeros(len(pos), dtype=int))
    _advance_held(sim, tracers, 0.05, 3)
    assert tracers.exited.sum() == 1 and np.isfinite(tracers.peak_pressure).all()
    assert np.unique(tracers.peak_pressure).size > 40  # distinct records (cell pressures) to keep
    for rule in (_box_rule([-0.5, -0.6], [0.3, 0.2], 1), _box_rule([2.0, 2.0], [3.0, 3.0], 1)):
        before = {name: getattr(tracers, name).copy() for name in TRACER_UNITS}
        old_blocks, old_mesh = tracers.owning_block, sim.mesh
        sim.refinement = rule
        assert sim.regrid()
        for name in TRACER_UNITS:
            np.testing.assert_array_equal(getattr(tracers, name), before[name])
        blocks, mesh = tracers.owning_block, sim.mesh
        on = ~tracers.exited
        np.testing.assert_array_equal(blocks[~on], -1)
        assert (blocks[on] >= 0).all()
        x = tracers.position[on, :2]
        assert ((mesh.block_lo[blocks[on], :2] <= x) & (x <= mesh.block_hi[blocks[on], :2])).all()
        assert (mesh.block_level[blocks[on]] != old_mesh.block_level[old_blocks[on]]).any()
    assert sim.regrids == 2 and (sim.mesh.block_level == 0).all()
    peak = tracers.peak_pressure.copy()
    _advance_held(sim, tracers, 0.05, 2)
    moved = (tracers.position[on] != before["position"][on]).any(axis=1)
    assert (tracers.peak_pressure >= peak).all() and moved.sum() == on.sum() - 1  # all but the one at the centre
    # the stencil keeps a refined cell's children in one block only if block_cells is a multiple of 4
    odd = BlockMesh.uniform("2d-planar", [0.0, 0.0], [1.0, 1.0], [12, 12], [("outflow", "outflow")] * 2, 6,
                            max_level=1)
    odd = refine_to(odd, lambda m: np.where(np.arange(m.nblocks) == 0, 1, 0))
    with pytest.raises(ValueError, match="divisible by 4"):
        Tracers([[0.5, 0.5]], [0]).mesh_changed(odd)
