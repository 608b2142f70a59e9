"""Grady-Kipp fracture of a porous material (docs/strength.md, "Porous bodies"): flaws counted per
unit volume of matrix, damage from the bulk stress and the porous moduli, compaction and fracture in
one run, budgets closed; a porosity block with alpha0 = 1 changes nothing; the config accepts it."""

import numpy as np
import pytest
from scipy import stats

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.budget import conservation_budget
from impactpipe.hydro.eos import pack_eos, reference_densities
from impactpipe.hydro.eos.porosity import pack_porosity, wave_speed_ratio
from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.problems.common import preset_material
from impactpipe.hydro.problems.impact import sphere_fraction
from impactpipe.hydro.strength import MaterialStrength, pack_strength
from impactpipe.hydro.strength.flaws import flaw_nodes
from impactpipe.hydro.strength.parameters import pack_damage
from impactpipe.hydro.parallel.distributed import WholeMesh
from impactpipe.pipeline.presets import resolve_damage, resolve_strength

M_BASALT, K_BASALT = 8.5, 3.0e39
ALPHA0 = 1.5
POROSITY = {"alpha0": ALPHA0, "eps_e": -2.0e-3, "kappa": 0.98, "alpha_x": 1.0, "chi": 0.5}


def porous_basalt(damage: dict, porosity: dict | None = POROSITY) -> dict:
    """Tillotson basalt with GEO weak strength (Y_T 10 MPa) and a Grady-Kipp ``damage`` block (over
    the basalt preset, E given: 53.1 GPa for the matrix), porous with ``porosity`` (none if None)."""
    material = preset_material("basalt")
    if porosity is not None:
        material["eos"] = {**material["eos"], "porosity": porosity}
    material["strength"] = {**resolve_strength("geo", "weak", {"Y_T": 1.0e7}),
                            "damage": resolve_damage({"model": "grady_kipp", "preset": "basalt", **damage})}
    return material


# ------------------------------------------------------------------ (a) flaw statistics


def test_porous_body_draws_its_flaws_per_unit_matrix_volume_by_the_weibull_law():
    """A porous basalt disc (alpha0 = 1.5, radius 0.05 m on a 2-D planar mesh of 96^2 cells, 1 m
    deep; partly filled cells at its edge) gets its flaws over its matrix volume
    V_m = sum v_i f_i / alpha0: the node strains are those of V_m, the body's flaws below each
    node are floor(k V_m eps^m), and the flaws of 16 sectors and of the full cells are spread
    in proportion to their matrix volume (chi-square).  Against the bulk volume V = alpha0 V_m
    the law is off by 50 %, many standard deviations.  Measured: the sums exact; sector
    chi-square p = 0.50 (mid node, 449 flaws) and 0.21 (last node, 43 921); dispersion of the full cells' counts
    p = 0.93; the bulk-volume law 85.6 sqrt(k V eps^m) above the body's at the last node."""
    material = porous_basalt({})
    mesh = BlockMesh.uniform("2d-planar", [-0.06, -0.06], [0.06, 0.06], [96, 96], [("outflow", "outflow")] * 2, 16)
    eos = pack_eos([material["eos"]])
    rows = pack_porosity([material["eos"]], eos)
    state = HydroState.empty(mesh, 1)
    fill = sphere_fraction(mesh, np.zeros(2), 0.05, 4)
    state.set_material(mesh, fill, 0, eos, reference_densities(eos)[0] / ALPHA0, np.zeros(3), specific_energy=0.0)
    strength = MaterialStrength(pack_strength([material["strength"]]), mesh, 1,
                                pack_damage([material["strength"]["damage"]]), rows)
    strength.prepare_state(state, WholeMesh())
    nq, ns = strength.nq, strength.ns
    arho = mesh.interior(state.arho)[:, 0]
    q = mesh.interior(state.arhoq)
    # the distension is in place, alpha0 everywhere the disc is
    has = arho > 0.0
    assert np.allclose(q[:, nq - 2][has] / arho[has], ALPHA0, rtol=1e-15)
    volume = mesh.cell_volumes().reshape(arho.shape)
    cells = np.flatnonzero((mesh.interior(state.alpha)[:, 0] > 0.0) & has)
    matrix_volume = (volume * mesh.interior(state.alpha)[:, 0]).ravel()[cells] / ALPHA0
    v_m = matrix_volume.sum()
    n_tot = int(np.ceil(cells.size * np.log(cells.size)))
    assert np.allclose(strength.flaw_strains[0], flaw_nodes(v_m, n_tot, M_BASALT, K_BASALT), rtol=1e-12)
    counts = np.stack([(volume * q[:, ns + 1 + j]).ravel()[cells] for j in range(8)])  # flaws below node j
    assert np.allclose(counts, np.round(counts), atol=1e-6)
    counts = np.round(counts).astype(np.int64)
    strains = np.array(strength.flaw_strains[0])
    expected = np.floor(K_BASALT * v_m * strains ** M_BASALT * (1.0 + 1e-12))
    assert (counts.sum(axis=1) == expected).all()
    mid = 4
    bulk_law = ALPHA0 * K_BASALT * v_m * strains[-1] ** M_BASALT
    off = (bulk_law - counts[-1].sum()) / np.sqrt(bulk_law)
    print(f"bulk-volume law above the body's at the last node: {off:.1f} sqrt(k V eps^m)")
    assert off > 10.0
    # sectors: counts against the matrix volume's share
    xy = mesh.cell_centers()
    centres = np.stack([xy[:, 0].ravel()[cells], xy[:, 1].ravel()[cells]], axis=1)
    sector = np.minimum((np.arctan2(centres[:, 1], centres[:, 0]) + np.pi) / (2.0 * np.pi) * 16, 15).astype(int)
    share = np.bincount(sector, matrix_volume, 16) / v_m
    for j in (mid, 7):
        observed = np.bincount(sector, counts[j], 16)
        p = stats.chisquare(observed, share * observed.sum()).pvalue
        print(f"sectors, node {j}: {observed.sum()} flaws, chi-square p = {p:.3f}")
        assert p > 1.0e-3
    # full cells: equal matrix volumes, so their counts are multinomial with equal cells (dispersion test)
    full = matrix_volume > 0.999 * matrix_volume.max()
    last = counts[7][full]
    dispersion = ((last - last.mean()) ** 2).sum() / last.mean()
    p = stats.chi2.sf(dispersion, last.size - 1)
    print(f"dispersion of {last.size} full cells' counts: p = {p:.3f}")
    assert 1.0e-3 < p < 1.0 - 1.0e-3


# ------------------------------------------------------------------ (b) a porous plate impact


FLYER, TARGET = 5.0e-3, 15.0e-3
MANY_FLAWS = {"flaw_count": 100_000, "flaw_seed": 1, "flaw_cross_section": 1.0e-8, "active_flaw_limit": False}


def plate_impact(material: dict, velocity: float, cells: int = 200, end_time: float = 1.2e-5):
    """A 5 mm plate of ``material`` at ``velocity`` (m/s) on a 15 mm plate of the same at rest (1-D).
    Returns (simulation, totals at the start, the largest tension -p + S_ii (Pa) each cell bore)."""
    sim = PROBLEMS["planar_impact"].setup({"flyer": {"material": "rock", "velocity": velocity, "thickness": FLYER},
                                           "target": {"material": "rock", "thickness": TARGET}, "cells": cells,
                                           "margin": 0.1}, {"rock": material})
    before = sim.totals()
    tension = np.zeros(sim.mesh.nblocks * sim.mesh.interior_shape[0])
    while sim.time < end_time:
        sim.step(dt_max=end_time - sim.time)
        snap = sim.snapshot()
        p = snap.pressure.reshape(-1)
        for c in ("xx", "yy", "zz"):
            tension = np.maximum(tension, -p + snap.extra[f"deviatoric_stress_{c}"].reshape(-1))
    return sim, before, tension


def porous_young_modulus(material: dict) -> float:
    """The porous Young modulus (Pa) at rest, alpha = alpha0: the given matrix E times h^2 / alpha0."""
    h = wave_speed_ratio(pack_porosity([material["eos"]], pack_eos([material["eos"]]))[0], ALPHA0)
    return material["strength"]["damage"]["young_modulus"] * h * h / ALPHA0


def test_porous_plates_compact_fracture_where_the_tension_passes_the_flaws_and_close_their_budgets():
    """Two porous basalt plates (alpha0 = 1.5, chi = 0.5, GEO weak with Y_T 10 MPa, Grady-Kipp
    basalt, 1e5 flaws for a bar of 1e-8 m^2) meet at 20 m/s: the compression wave compacts
    both plates near the contact past their elastic limit, the rarefactions from their free
    surfaces meet in the target and break it.  Mass to 1e-12, momentum within what the floors
    removed, energy within what they added and removed (to 1e-12 of the total); the cells
    within 2 mm of the contact compacted; cells whose largest borne tension (end of step) stayed
    below 0.7 E_p eps_1 (E_p the porous Young modulus at rest, eps_1 the body's weakest flaw)
    undamaged (D < 1e-6), the broken cells (D > 0.5) past it, all below half the onset E eps_1
    of the matrix E (6 times E_p), which would not have activated them.  Measured: mass exact,
    energy 2.2e-16; distension 1.4854-1.4948 near the contact; 23 cells broken at 5.3-10.8 mm
    with largest tensions 2.16-4.80 MPa, onset E_p eps_1 = 2.91 MPa (matrix 17.5 MPa).
    """
    material = porous_basalt(MANY_FLAWS)
    sim, before, tension = plate_impact(material, 20.0)
    after = sim.totals()
    assert after["mass_with_outflow"] == pytest.approx(before["mass"], rel=1e-12)
    assert abs(conservation_budget(before, after, sim.floor_amounts)["momentum_x_unaccounted"]) < 1e-12
    amounts = sim.floor_amounts
    added = (amounts["energy_added_by_floors"] - amounts["energy_removed_by_void_cleanup"]
             - amounts["energy_removed_by_velocity_limit"] - amounts["energy_removed_by_energy_limit"])
    assert abs(after["energy_with_outflow"] - before["energy"] - added) < 1e-12 * before["energy"]
    counts = sim.floor_counts
    assert counts["grady_kipp_fractured"] > 0 and counts["tensile_failure"] == 0
    snap = sim.snapshot()
    x = snap.centers[:, 0].reshape(-1)
    dist = snap.extra["distension"].reshape(-1)
    damage = snap.extra["damage"].reshape(-1)
    mass = snap.density.reshape(-1) > 0.0
    inside = mass & (np.abs(x) > 1.0e-3) & (x > -FLYER + 1.0e-3) & (x < TARGET - 1.0e-3)
    # compacted past the elastic limit near the contact (the pores of the elastic regime reopen behind)
    shocked = mass & (np.abs(x) < 2.0e-3)
    assert 1.0 < dist[shocked].min() and dist[shocked].max() < ALPHA0 - 0.004
    eps_1 = sim.strength.flaw_strains[0][0]
    onset = porous_young_modulus(material) * eps_1
    assert (damage[inside & (tension < 0.7 * onset)] < 1.0e-6).all()
    broken = inside & (damage > 0.5)
    print(f"mass {after['mass_with_outflow'] / before['mass'] - 1:.2e}, energy "
          f"{(after['energy_with_outflow'] - before['energy'] - added) / before['energy']:.2e}, distension "
          f"{dist[shocked].min():.4f}-{dist[shocked].max():.4f}, broken {broken.sum()} cells at "
          f"{x[broken].min() * 1e3:.2f}-{x[broken].max() * 1e3:.2f} mm, onset {onset / 1e6:.2f} MPa (matrix "
          f"{material['strength']['damage']['young_modulus'] * eps_1 / 1e6:.2f}), largest tension of the broken "
          f"{tension[broken].min() / 1e6:.2f}-{tension[broken].max() / 1e6:.2f} MPa, damaged "
          f"{(inside & (damage > 0.0)).sum()} of {inside.sum()}")
    assert broken.sum() >= 3
    assert (tension[broken] > 0.7 * onset).all()
    matrix_onset = material["strength"]["damage"]["young_modulus"] * eps_1
    assert (tension[broken] < 0.5 * matrix_onset).all()


def test_a_porosity_block_with_alpha0_one_changes_nothing():
    """Compact basalt (alpha0 = 1 in its porosity block) with Grady-Kipp: the plate impact ends bit for
    bit where the run without a porosity block does (no material is porous: the scene is not)."""
    runs = []
    for porosity in (None, {**POROSITY, "alpha0": 1.0, "chi": 1.0}):
        sim, _, _ = plate_impact(porous_basalt(MANY_FLAWS, porosity), 40.0, cells=64, end_time=3.0e-6)
        runs.append(sim)
    assert runs[1].porosity is None
    for name, array in runs[0].state.arrays().items():
        assert np.array_equal(array, getattr(runs[1].state, name)), name


# ------------------------------------------------------------------ (c) the config


def test_the_config_accepts_a_porous_material_with_grady_kipp_damage():
    """A porous rubble target with Grady-Kipp damage validates and builds a Simulation whose
    scalars carry the flaws and the distension (NS + 2 + 8 flaw slots + 1)."""
    from impactpipe.pipeline.config import parse_config

    text = """name: x
scene:
  problem: planar_impact
  flyer: {material: rubble, thickness: 0.01, velocity: 10.0}
  target: {material: rubble, thickness: 0.03}
  cells: 64
materials:
  rubble:
    eos: {model: tillotson, preset: basalt}
    strength: {model: geo, preset: weak, damage: basalt}
    porosity: basalt
"""
    cfg = parse_config(text, source="c.yaml")
    sim = PROBLEMS["planar_impact"].setup(cfg.scene.model_dump(exclude={"problem", "geometry"}),
                                          cfg.resolved_materials())
    assert sim.porosity is not None and sim.grady_kipp is not None and sim.grady_kipp[0]
    assert sim.strength.nq == sim.strength.ns + 2 + 8 + 1
    mesh, nq = sim.mesh, sim.strength.nq
    arho = mesh.interior(sim.state.arho)[:, 0]
    q = mesh.interior(sim.state.arhoq)
    has = arho > 0.0
    assert np.allclose(q[:, nq - 2][has] / arho[has], 1.5)
    assert (q[:, sim.strength.ns + 1 + 7][has] > 0.0).any()
