"""benchmarks/scaling_model.py: the formulas of the MPI scaling projection on hand-made meshes."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("scaling_model", ROOT / "benchmarks" / "scaling_model.py")
sm = importlib.util.module_from_spec(_spec)
sys.modules["scaling_model"] = sm  # dataclasses look their module up
_spec.loader.exec_module(sm)

COSTS = sm.Costs(cell_update_s=4e-7, pack_s_per_byte=1e-10, snapshot_s_per_cell=5e-8)
NET = sm.Interconnect(latency_s=1.5e-6, link_bytes_per_s=12.5e9, ranks_per_node=4, shm_bytes_per_s=5e9)


def test_one_rank_has_no_traffic_and_efficiency_one():
    mesh = sm.Mesh((8, 4, 6), 8, (False, False, False))
    row = sm.run_time(mesh, [10], 10, COSTS, NET, 1, steps=1000, snapshots=20)
    assert row["step_terms_s"] == {"compute": pytest.approx(mesh.cells * 4e-7), "pack": 0.0, "network": 0.0,
                                   "reduce": 0.0}
    for outputs in sm.OUTPUTS:
        assert row[outputs]["efficiency"] == pytest.approx(1.0)
        assert row[outputs]["efficiency_overlapped"] == pytest.approx(1.0)


def test_two_slabs_exchange_one_plane_of_strips_each_way():
    """Two ranks on 4 x 4 x 4 blocks of 8^3: one plane of 16 block faces along z, each a strip
    of GHOST x 8^2 cells; nothing along x and y; a periodic z doubles it (two planes, same peer)."""
    mesh = sm.Mesh((4, 4, 4), 8, (False, False, False))
    x, y, z = sm.face_counts(mesh, sm.cuts_for(mesh, 2), ranks_per_node=2)
    assert x["faces"].tolist() == y["faces"].tolist() == [0, 0]
    assert z["faces"].tolist() == [16, 16] and z["peers"].tolist() == [1, 1] and z["on_node"].tolist() == [16, 16]
    assert mesh.strip_values(10) == 2 * 64 * 10
    periodic = sm.Mesh((4, 4, 4), 8, (False, False, True))
    assert sm.face_counts(periodic, sm.cuts_for(periodic, 2), 2)[2]["faces"].tolist() == [32, 32]
    assert sm.face_counts(periodic, sm.cuts_for(periodic, 2), 2)[2]["peers"].tolist() == [1, 1]


def test_off_node_faces_are_those_between_nodes():
    """Eight slabs of one plane each, two ranks per node: of the 7 planes of faces between ranks,
    3 lie between nodes; the inner nodes' links carry two planes, the end nodes' one."""
    mesh = sm.Mesh((2, 2, 8), 4, (False, False, False))
    z = sm.face_counts(mesh, sm.cuts_for(mesh, 8), ranks_per_node=2)[2]
    assert z["faces"].tolist() == [4] + [8] * 6 + [4]
    assert z["node_off"].tolist() == [4, 8, 8, 4]
    assert (z["faces"] - z["on_node"]).sum() == 2 * 3 * 4


def test_slabs_keep_their_surface_while_their_volume_falls():
    """Ranks own slabs of whole block planes (16, 4, 1 of 64): the compute per rank falls as 1 / P,
    the strips a middle rank packs stay two planes of 64 faces."""
    mesh = sm.Mesh((8, 8, 64), 8, (False, False, False))
    terms = {p: sm.step_time(mesh, [10], COSTS, NET, sm.cuts_for(mesh, p)) for p in (4, 16, 64)}
    assert terms[16]["compute"] == pytest.approx(terms[4]["compute"] / 4)
    assert terms[64]["pack"] == pytest.approx(terms[16]["pack"]) == pytest.approx(terms[4]["pack"])


def test_load_imbalance_follows_whole_blocks():
    mesh = sm.Mesh((5, 1), 16, (False, False))
    row = sm.run_time(mesh, [7], 7, COSTS, NET, 4, steps=10, snapshots=0)
    assert row["imbalance"] == pytest.approx(2 * 4 / 5)
    assert row["step_terms_s"]["compute"] == pytest.approx(2 * 16 ** 2 * 4e-7)


def test_exchange_components_count_the_state_and_the_strength_fills():
    assert sm.exchange_components(3, 2, strength=False) == [10]
    assert sm.exchange_components(2, 2, strength=True) == [3 * 2 + 4 + 2 * 6, 2 * 2 + 3, 4, 3, 4]


def test_overlap_hides_the_network_but_not_the_packing():
    mesh = sm.Mesh((4, 4, 16), 8, (False, False, False))
    row = sm.run_time(mesh, [10], 10, COSTS, NET, 16, steps=100, snapshots=0)
    t, this = row["step_terms_s"], row["this-version"]
    assert this["wall_s"] - this["outputs_s"] == pytest.approx(100 * (t["compute"] + t["pack"] + t["network"] + t["reduce"]))
    assert this["wall_overlapped_s"] - this["outputs_s"] == pytest.approx(
        100 * (max(t["compute"], t["network"]) + t["pack"] + t["reduce"]))
    assert row["this-version"]["efficiency_overlapped"] >= row["this-version"]["efficiency"]
    assert np.isclose(t["reduce"], 4 * 1.5e-6 * 4)


def test_outputs_gather_the_whole_state_and_compute_every_cell_on_every_rank():
    """This version: each of the 2 snapshots and 3 log lines moves S_tot = 8 c NB (B + 4)^3 and
    computes N cells; distributed outputs compute the rank's own cells, the log lines gather nothing."""
    mesh = sm.Mesh((4, 4, 16), 8, (False, False, False))
    cuts = sm.cuts_for(mesh, 16)
    gather = 8 * 10 * 256 * 12 ** 3 / 5e9 + 1.5e-6 * 4
    this = sm.output_time(mesh, 10, COSTS, NET, cuts, 300, 2, "this-version")
    assert this == pytest.approx(5 * (gather + mesh.cells * 5e-8))
    local = sm.output_time(mesh, 10, COSTS, NET, cuts, 300, 2, "local-log")
    assert local == pytest.approx(3 * (mesh.cells / 16 * 5e-8 + 1.5e-6 * 4) + 2 * (gather + mesh.cells * 5e-8))
    spread = sm.output_time(mesh, 10, COSTS, NET, cuts, 300, 2, "distributed")
    assert spread == pytest.approx(3 * (mesh.cells / 16 * 5e-8 + 1.5e-6 * 4) + 2 * (gather + mesh.cells / 16 * 5e-8))


def test_steps_grow_as_the_power_through_the_two_finest_runs():
    document = {"runs": [{"cells_per_projectile_radius": 10, "steps": 2000},
                         {"cells_per_projectile_radius": 5, "steps": 800},
                         {"cells_per_projectile_radius": 2.5, "steps": 100}]}
    n1, s1, p = sm.step_growth(document)
    assert (n1, s1) == (10, 2000) and p == pytest.approx(np.log2(2.5))
    assert sm.handoff_steps(document, 40) == pytest.approx(2000 * 2.5 ** 2)
    assert sm.handoff_steps({"runs": document["runs"][:1]}, 40) == pytest.approx(2000 * 4)
