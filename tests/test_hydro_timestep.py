"""The CFL rate kernel against the cell-by-cell mixture gather it restructures."""

import numba
import numpy as np
import pytest
from numba import njit

from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.eos.porosity import ALPHA0, NPOROSITY
from impactpipe.hydro.mesh.blocks import GHOST
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.scheme.mixture import mixture_state
from impactpipe.hydro.scheme.timestep import PHI_VOID, allocate_rate_work, max_signal_rate

ALUMINIUM = {"model": "mie_gruneisen", "rho0": 2790.0, "c0": 5330.0, "s": 1.34, "gamma0": 2.0, "cv": 900.0}
GAS = {"model": "ideal_gas", "gamma": 1.4, "cv": 718.0}


@njit
def rate_by_cell(alpha, arho, arhoe, arhoq, mom, block_dx, eos_kind, eos_params, eos_table, shear, tensile, ndim,
                 out):
    """The rate as every other kernel gathers a cell: mixture_state per cell, then (|u| + c) / dx."""
    nb, nmat, nx, ny, nz = alpha.shape
    g = GHOST
    for b in range(nb):
        rate = 0.0
        for ix in range(g, nx - g):
            for iy in range(g, ny - g):
                for iz in range(g if nz > 1 else 0, nz - g if nz > 1 else 1):
                    rho, phi, p, kmod, eint, tmass, clamps, limits = mixture_state(
                        alpha, arho, arhoe, arhoq, b, ix, iy, iz, eos_kind, eos_params, eos_table, shear, tensile,
                        False, None, 0, 0)
                    if rho <= 0.0 or phi < PHI_VOID:
                        continue
                    c = np.sqrt(kmod / rho)
                    for d in range(ndim):
                        rate = max(rate, (abs(mom[b, d, ix, iy, iz]) / rho + c) / block_dx[b, d])
        out[b] = rate


def random_mixture(rng, nb, shape, rho0):
    """Cells of three materials: full, mixed, partly void, void and trace amounts (alpha 1e-11)."""
    nmat = len(rho0)
    alpha = rng.dirichlet(np.ones(nmat + 1), size=(nb,) + shape)[..., :nmat]
    alpha = np.moveaxis(alpha, -1, 1).copy()
    kind = rng.integers(0, 5, size=alpha.shape)
    alpha[kind == 0] = 0.0
    alpha[kind == 1] = 1e-11
    alpha[:, 0][kind[:, 0] == 2] = 1.0
    rho = np.array(rho0)[None, :, None, None, None] * rng.uniform(0.3, 1.6, size=alpha.shape)
    arho = alpha * rho
    arhoe = arho * rng.uniform(0.0, 2e6, size=alpha.shape)
    mom = rng.normal(0.0, 1e6, size=(nb, 3) + shape)
    return alpha, arho, arhoe, mom


def test_rate_kernel_equals_the_per_cell_mixture_gather_bit_for_bit():
    rng = np.random.default_rng(3)
    materials = [preset_material("basalt")["eos"], ALUMINIUM, GAS]
    eos = pack_eos(materials)
    shear = np.array([[0.0, 0.6], [2.6e10, 0.0], [0.0, 0.0]])
    tensile = np.array([1e7, 3e8, 0.0])
    for shape, ndim in (((20, 20, 1), 2), ((12, 12, 12), 3)):
        nb = 6
        alpha, arho, arhoe, mom = random_mixture(rng, nb, shape, [2700.0, 2790.0, 1.2])
        dx = rng.uniform(0.5, 2.0, size=(nb, 3))
        dx[: nb // 2] = dx[: nb // 2, :1]  # cubic cells (the kernel's shorter path) and others
        expected, got = np.zeros(nb), np.zeros(nb)
        rate_by_cell(alpha, arho, arhoe, np.zeros((nb, 0) + shape), mom, dx, eos.kind, eos.params, eos.table,
                     shear, tensile, ndim, expected)
        max_signal_rate(alpha, arho, arhoe, mom, dx, eos.kind, eos.params, eos.table, shear, ndim,
                        allocate_rate_work(numba.config.NUMBA_NUM_THREADS, shape), got)
        assert np.all(expected > 0.0)
        assert np.array_equal(got, expected)


@pytest.mark.parametrize("material", ["ideal gas", "tillotson", "tillotson with shear", "porous tillotson"])
def test_single_material_pass_equals_the_summing_passes_bit_for_bit(material):
    """A mesh of one material takes its own one-pass loop (cubic cells); the same cells with a
    second material absent everywhere (alpha = alpha rho = 0) take the summing passes."""
    rng = np.random.default_rng(11)
    spec = GAS if material == "ideal gas" else preset_material("basalt")["eos"]
    rho0 = 1.2 if material == "ideal gas" else 2700.0
    eos, padded = pack_eos([spec]), pack_eos([spec, GAS])
    shear = np.array([[2.6e10, 0.6]]) if material == "tillotson with shear" else np.zeros((1, 2))
    for shape, ndim in (((20, 20, 1), 2), ((12, 12, 12), 3)):
        nb = 6
        alpha, arho, arhoe, mom = random_mixture(rng, nb, shape, [rho0])
        alpha[:, :, 4, 5] = np.nan  # a broken cell is passed over as the summing passes pass it
        dx = np.repeat(rng.uniform(0.5, 2.0, size=(nb, 1)), 3, axis=1)
        porosity = arhoq = None
        if material == "porous tillotson":
            porosity = np.zeros((1, NPOROSITY))
            porosity[0, ALPHA0] = 1.5
            arhoq = np.stack([(arho * rng.uniform(1.0, 1.5, size=arho.shape))[:, 0], np.zeros_like(arho[:, 0])], axis=1)
        got, expected = np.zeros(nb), np.zeros(nb)
        max_signal_rate(alpha, arho, arhoe, mom, dx, eos.kind, eos.params, eos.table, shear, ndim,
                        allocate_rate_work(numba.config.NUMBA_NUM_THREADS, shape), got, arhoq, porosity)
        zero = np.zeros_like(alpha)
        two = [np.concatenate([f, zero], axis=1) for f in (alpha, arho, arhoe)]
        if porosity is not None:
            arhoq2 = np.concatenate([arhoq, np.zeros_like(arhoq)], axis=1)
            porosity2 = np.concatenate([porosity, np.zeros((1, NPOROSITY))])
            porosity2[1, ALPHA0] = 1.0
        else:
            arhoq2 = porosity2 = None
        max_signal_rate(*two, mom, dx, padded.kind, padded.params, padded.table, np.concatenate([shear, [[0.0, 0.0]]]),
                        ndim, allocate_rate_work(numba.config.NUMBA_NUM_THREADS, shape), expected, arhoq2, porosity2)
        assert np.all(expected > 0.0)
        assert np.array_equal(got.view(np.int64), expected.view(np.int64))
