"""The ``damage`` block of a material's strength: parsed, resolved with presets and passed to the
hydro Simulation as plain parameters (bad input: tests/configs/broken/damage_*.yaml)."""

import numpy as np

from impactpipe.hydro import PROBLEMS
from impactpipe.hydro.strength.parameters import GRADY_KIPP, INSTANT, WEIBULL_K, WEIBULL_M, YOUNG
from impactpipe.pipeline.config import parse_config

SCENE = """name: x
scene:
  problem: planar_impact
  flyer: {material: rock, thickness: 0.01, velocity: 10.0}
  target: {material: rock, thickness: 0.03}
  cells: 64
materials:
  rock:
    eos: {model: tillotson, preset: basalt}
    strength: STRENGTH
"""


def resolved(strength: str) -> dict:
    return parse_config(SCENE.replace("STRENGTH", strength), source="c.yaml").resolved_materials()["rock"]


def test_damage_preset_name_and_block_resolve_to_the_weibull_parameters():
    by_name = resolved("{model: geo, preset: weak, damage: basalt}")["strength"]["damage"]
    assert by_name == {"model": "grady_kipp", "weibull_m": 8.5, "weibull_k": 3.0e39, "young_modulus": 53.1e9}
    block = resolved("{model: geo, preset: weak, damage: {model: grady_kipp, preset: basalt, weibull_m: 6.0, "
                     "flaw_seed: 4, flaw_count: 1000}}")["strength"]["damage"]
    assert block["weibull_m"] == 6.0 and block["weibull_k"] == 3.0e39
    assert block["flaw_seed"] == 4 and block["flaw_count"] == 1000
    assert "damage" not in resolved("{model: geo, preset: weak}")["strength"]
    assert resolved("{model: geo, preset: weak, damage: {model: instant}}")["strength"]["damage"] == {
        "model": "instant"}


def test_damage_block_reaches_the_simulation():
    """The resolved materials build a Simulation whose material fractures by Grady-Kipp (flaws in the
    state, (1 - D) tension in the sweeps); without the block, instant failure and no flaw slots."""
    cfg = parse_config(SCENE.replace("STRENGTH", "{model: geo, preset: weak, damage: basalt}"), source="c.yaml")
    scene = cfg.scene.model_dump(exclude={"problem", "geometry"})
    sim = PROBLEMS["planar_impact"].setup(scene, cfg.resolved_materials())
    damage = sim.strength.damage
    assert damage.model[0] == GRADY_KIPP
    assert (damage.params[0, [WEIBULL_M, WEIBULL_K, YOUNG]] == [8.5, 3.0e39, 53.1e9]).all()
    assert sim.grady_kipp is not None and sim.grady_kipp[0]
    assert sim.strength.nq == sim.strength.ns + 2 + 8
    assert np.isclose(sum(sim.strength.flaw_strains[0][-1:]), max(sim.strength.flaw_strains[0]))
    plain = parse_config(SCENE.replace("STRENGTH", "{model: geo, preset: weak}"), source="c.yaml")
    sim = PROBLEMS["planar_impact"].setup(plain.scene.model_dump(exclude={"problem", "geometry"}), plain.resolved_materials())
    assert sim.strength.damage.model[0] == INSTANT and sim.grady_kipp is None
    assert sim.strength.nq == sim.strength.ns + 2
