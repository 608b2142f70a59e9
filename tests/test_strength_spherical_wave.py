"""A spherical elastic wave in r-z and in 3D against the exact solution: the tangential (hoop)
tension behind a diverging compressive wave, which breaks brittle targets, and every stress
component of the multi-dimensional strength update (:mod:`impactpipe.hydro.exact.spherical_elastic`)."""

import math

import numpy as np
import pytest

from impactpipe.hydro.eos import pressure_sound_speed
from impactpipe.hydro.exact.spherical_elastic import spherical_elastic_wave
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.problems.common import adaptive_mesh, material_list, new_simulation, preset_material

WIDTH = 1.0          # m, the initial pulse's radius
SPEED = 4.0          # m/s, its velocity amplitude: strains of 1e-4 keep the solid linear
POISSON = 0.25


def _wave_run(geometry: str, cells_per_width: int, crossings: float):
    """Run the pulse ``crossings`` w / c_L in an octant (r-z: a quadrant) with mirror planes
    through its centre; returns the L1 errors of sigma_RR, sigma_TT, P and v_R (each over the
    exact field's L1 norm, cells with R > w / 4, volume-weighted) and the largest tangential
    tension, measured and exact (Pa)."""
    ndim = 3 if geometry == "3d" else 2
    block = 8 if ndim == 3 else 16
    n = math.ceil(3.5 * cells_per_width / block) * block
    length = n * WIDTH / cells_per_width
    basalt = preset_material("basalt")
    basalt["strength"] = {"model": "von_mises", "yield_strength": 1e13, "poisson": POISSON, "Y_T": 1e13}
    names, specs, eos = material_list({"basalt": basalt}, ["basalt"])
    mesh = adaptive_mesh(geometry, [0.0] * ndim, [length] * ndim, [n] * ndim, [("reflecting", "outflow")] * ndim,
                         block, 1)
    centers = mesh.cell_centers()
    radius = np.sqrt(sum(centers[:, i] ** 2 for i in range(ndim)))
    s = np.minimum(radius / WIDTH, 1.0)
    velocity = np.zeros((mesh.nblocks, 3) + mesh.interior_shape)
    for i in range(ndim):
        velocity[:, i] = SPEED * s * (1.0 - s * s) ** 3 * centers[:, i] / radius
    state = HydroState.empty(mesh, 1)
    rho0 = basalt["eos"]["rho0"]
    state.set_material(mesh, 1.0, 0, eos, rho0, velocity, specific_energy=0.0)
    sim = new_simulation(mesh, names, specs, state, 0.4, tensile_strength=[1e13], strength=[basalt["strength"]])
    _, c2, _ = pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, rho0, 0.0)
    bulk = rho0 * c2
    shear = 3.0 * (1.0 - 2.0 * POISSON) / (2.0 * (1.0 + POISSON)) * bulk
    end = crossings * WIDTH / math.sqrt((bulk + 4.0 * shear / 3.0) / rho0)
    sim.run(end)

    snap = sim.snapshot()
    x = [snap.centers[:, i].reshape(-1) for i in range(ndim)]
    r = np.sqrt(sum(xi ** 2 for xi in x))
    unit = [xi / r for xi in x]
    stress = {key[len("deviatoric_stress_"):]: value.reshape(-1) for key, value in snap.extra.items()
              if key.startswith("deviatoric_stress_")}
    axes = "xyz"
    s_rr = sum(stress[axes[i] * 2] * unit[i] ** 2 for i in range(ndim))
    for i in range(ndim):
        for j in range(i + 1, ndim):
            s_rr = s_rr + 2.0 * stress[axes[i] + axes[j]] * unit[i] * unit[j]
    # r-z: the hoop component is a tangential one; 3D: the mean of the two tangential ones
    s_tt = stress["zz"] if ndim == 2 else 0.5 * (stress["xx"] + stress["yy"] + stress["zz"] - s_rr)
    v_r = sum(snap.velocity[:, i].reshape(-1) * unit[i] for i in range(ndim))
    p = snap.pressure.reshape(-1)
    exact = spherical_elastic_wave(r, end, SPEED, WIDTH, rho0, bulk, shear)
    used = r > 0.25 * WIDTH
    volume = snap.volumes[used]

    def l1(measured, wanted):
        return float(np.sum(np.abs(measured - wanted)[used] * volume) / np.sum(np.abs(wanted)[used] * volume))

    errors = {"sigma_RR": l1(s_rr - p, exact.radial_deviator - exact.pressure),
              "sigma_TT": l1(s_tt - p, exact.tangential_deviator - exact.pressure),
              "pressure": l1(p, exact.pressure), "velocity": l1(v_r, exact.velocity)}
    tension = (float((s_tt - p)[used].max()), float((exact.tangential_deviator - exact.pressure)[used].max()))
    return errors, tension


def test_exact_wave_obeys_momentum_and_starts_from_its_initial_velocity():
    """The closed forms: v(R, 0) = v0(R) with no displacement or stress, and
    rho v_t = d sigma_RR / dR + 2 (sigma_RR - sigma_TT) / R at a later time (finite differences)."""
    rho, bulk, shear = 2700.0, 2.67e10, 1.6e10
    r = np.linspace(0.05, 3.5, 4001)
    start = spherical_elastic_wave(r, 0.0, SPEED, WIDTH, rho, bulk, shear)
    s = np.minimum(r, 1.0)
    assert np.max(np.abs(start.velocity - SPEED * s * (1 - s * s) ** 3)) < 1e-14 * SPEED
    assert np.max(np.abs(start.pressure)) == 0.0 and np.max(np.abs(start.displacement)) == 0.0
    t, h = 3.0e-4, 1.0e-8
    now = spherical_elastic_wave(r, t, SPEED, WIDTH, rho, bulk, shear)
    later = spherical_elastic_wave(r, t + h, SPEED, WIDTH, rho, bulk, shear)
    earlier = spherical_elastic_wave(r, t - h, SPEED, WIDTH, rho, bulk, shear)
    acceleration = (later.velocity - earlier.velocity) / (2.0 * h)
    rr = now.radial_deviator - now.pressure
    tt = now.tangential_deviator - now.pressure
    residual = rho * acceleration - (np.gradient(rr, r) + 2.0 * (rr - tt) / r)
    assert np.max(np.abs(residual[5:-5])) < 1e-3 * np.max(np.abs(rho * acceleration))
    assert np.max(np.abs((later.displacement - earlier.displacement) / (2.0 * h) - now.velocity)) < 1e-6 * SPEED


@pytest.mark.parametrize("geometry, coarse, crossings, bound", [("2d-cylindrical", 16, 2.0, 0.08),
                                                                ("3d", 8, 1.0, 0.11)])
def test_spherical_elastic_wave_converges_to_the_exact_stress(geometry, coarse, crossings, bound):
    """Every stress component, the pressure and the velocity converge to the exact wave (L1 error
    at least 1.8x smaller per doubling, below ``bound`` on the finer mesh), and the largest
    tangential tension is within 5 % of the exact one on the finer mesh."""
    coarse_errors, (coarse_tension, coarse_exact) = _wave_run(geometry, coarse, crossings)
    fine_errors, (tension, exact_tension) = _wave_run(geometry, 2 * coarse, crossings)
    print(f"{geometry} {coarse} / {2 * coarse} cells per width: L1 errors "
          + ", ".join(f"{name} {coarse_errors[name]:.3f} / {error:.3f}" for name, error in fine_errors.items())
          + f"; largest tangential tension against the exact {coarse_tension / coarse_exact - 1.0:+.1%} / "
          f"{tension / exact_tension - 1.0:+.1%}")
    for name, error in fine_errors.items():
        assert error < bound, (name, error)
        assert coarse_errors[name] > 1.8 * error, (name, coarse_errors[name], error)
    assert exact_tension > 0.0
    assert tension == pytest.approx(exact_tension, rel=0.05)
