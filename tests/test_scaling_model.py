"""benchmarks/scaling_model.py: the formulas of the MPI scaling projection, and its face counts
against the code's exchange plan and a brute-force count, on small meshes."""

import importlib.util
import itertools
import sys
from pathlib import Path

import numpy as np
import pytest

from impactpipe.hydro.mesh.blocks import GEOMETRY_CODES, GHOST, BlockMesh
from impactpipe.hydro.parallel.decomposition import every_axis_routes, exchange_routes
from impactpipe.hydro.strength.model import slot_runs

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("scaling_model", ROOT / "benchmarks" / "scaling_model.py")
sm = importlib.util.module_from_spec(_spec)
sys.modules["scaling_model"] = sm  # dataclasses look their module up
_spec.loader.exec_module(sm)

COSTS = sm.Costs(cell_update_s=4e-7, pack_s_per_byte=1e-10, message_s=2e-5, snapshot_s_per_cell=5e-8)
NET = sm.Interconnect(latency_s=1.5e-6, link_bytes_per_s=12.5e9, ranks_per_node=4, shm_bytes_per_s=5e9)


def box(blocks, block_cells, periodic):
    """A uniform Cartesian mesh of ``blocks`` blocks per axis (2D or 3D) in the code's block order."""
    ndim = len(blocks)
    kinds = [("periodic",) * 2 if p else ("outflow",) * 2 for p in periodic]
    return BlockMesh.uniform({2: "2d-planar", 3: "3d"}[ndim], [0.0] * ndim, [1.0] * ndim,
                             [n * block_cells for n in blocks], kinds, block_cells)


def x_fastest_box(blocks, block_cells):
    """The same box with its blocks in x-fastest order (then y, then z): a block order other than
    the code's Morton order, cut into slabs."""
    ndim = len(blocks)
    index = np.array([i[::-1] + (0,) * (3 - ndim) for i in itertools.product(*(range(n) for n in blocks[::-1]))])
    return BlockMesh.from_leaves({2: "2d-planar", 3: "3d"}[ndim], np.zeros(3), np.r_[np.ones(ndim), np.zeros(3 - ndim)],
                                 list(blocks) + [1] * (3 - ndim), block_cells, [("outflow", "outflow")] * ndim,
                                 np.zeros(len(index), dtype=np.int64), index, 0)


def brute_force_faces(mesh, cuts, ranks_per_node):
    """Per axis: faces, on_node, peers and node_off by a loop over every block's position and its
    two neighbours along the axis (the periodic image across a periodic face)."""
    nranks = len(cuts) - 1
    owner = {tuple(mesh.block_index[b, :mesh.ndim]): int(np.searchsorted(cuts, b, side="right")) - 1
             for b in range(mesh.nblocks)}
    n = mesh.blocks_per_axis[:mesh.ndim]
    out = []
    for axis in range(mesh.ndim):
        faces, on_node, node_off = np.zeros(nranks, int), np.zeros(nranks, int), {}
        peers = [set() for _ in range(nranks)]
        for position, rank in owner.items():
            for step in (-1, 1):
                there = list(position)
                there[axis] += step
                if not 0 <= there[axis] < n[axis]:
                    if mesh.boundaries[axis][0] != "periodic":
                        continue
                    there[axis] %= n[axis]
                other = owner[tuple(there)]
                if other == rank:
                    continue
                faces[rank] += 1
                peers[rank].add(other)
                peers[other].add(rank)
                if rank // ranks_per_node == other // ranks_per_node:
                    on_node[rank] += 1
                else:
                    node_off[rank // ranks_per_node] = node_off.get(rank // ranks_per_node, 0) + 1
        nodes = (nranks - 1) // ranks_per_node + 1
        out.append({"faces": faces.tolist(), "on_node": on_node.tolist(), "peers": [len(p) for p in peers],
                    "node_off": [node_off.get(k, 0) for k in range(nodes)]})
    return out


def as_lists(counts):
    return [{key: value.tolist() for key, value in axis.items()} for axis in counts]


@pytest.mark.parametrize("blocks, periodic, nranks, per_node", [
    ((6, 5, 4), (False, True, True), 7, 3),     # ranges that end inside rows and planes
    ((6, 5, 4), (True, False, False), 16, 4),   # fewer blocks per rank than a row of blocks
    ((9, 7), (False, False), 5, 2),
    ((9, 7), (True, True), 13, 4),
])
def test_face_counts_of_the_real_cut_match_a_brute_force_count_and_the_exchange_plan(blocks, periodic, nranks,
                                                                                        per_node):
    """The vectorised count over mesh.neighbor equals a loop over block positions, and its faces
    and peers are the strips and routes of the code's exchange plan, rank by rank; the peers
    along any axis are the routes of a fill along every axis in one message per peer."""
    mesh = box(blocks, 4, periodic)
    cuts = sm.cuts_for(mesh, nranks)
    counts = sm.face_counts(mesh, cuts, per_node)
    assert as_lists(counts) == brute_force_faces(mesh, cuts, per_node)
    strip_cells = {axis: sm.strip_values(mesh, axis, 1) for axis in range(mesh.ndim)}
    peers = sm.fill_peers(mesh, cuts)
    for rank in range(nranks):
        routes = exchange_routes(mesh, cuts, rank)
        assert len(every_axis_routes(routes)) == peers[rank]
        assert peers[rank] == len({route.peer for axis_routes in routes for route in axis_routes})
        for axis in range(mesh.ndim):
            sent = sum(len(route.send.cells) for route in routes[axis])
            assert sent == counts[axis]["faces"][rank] * strip_cells[axis]
            assert len(routes[axis]) == counts[axis]["peers"][rank]


def test_the_counts_follow_the_block_order_of_the_mesh():
    """In the code's Morton order eight ranks of an 8^3-block box own 4^3-block cubes: three
    faces of 16 blocks each, one along each axis, where the x-fastest order cuts slabs of one
    plane (two faces of 64 along z)."""
    morton = box((8, 8, 8), 4, (False, False, False))
    counts = sm.face_counts(morton, sm.cuts_for(morton, 8), ranks_per_node=8)
    assert [axis["faces"].tolist() for axis in counts] == [[16] * 8] * 3
    assert as_lists(counts) == brute_force_faces(morton, sm.cuts_for(morton, 8), 8)
    slabs = x_fastest_box((8, 8, 8), 4)
    z = sm.face_counts(slabs, sm.cuts_for(slabs, 8), ranks_per_node=8)[2]
    assert z["faces"].tolist() == [64] + [128] * 6 + [64]
    cuts = sm.cuts_for(slabs, 8)
    assert as_lists(sm.face_counts(slabs, cuts, 8)) == brute_force_faces(slabs, cuts, 8)


def test_one_rank_has_no_traffic_and_efficiency_one():
    mesh = box((8, 4, 6), 8, (False, False, False))
    row = sm.run_time(mesh, [10], 4, COSTS, NET, 1, steps=1000, snapshots=20)
    assert row["step_terms_s"] == {"compute": pytest.approx(mesh.ncells * 4e-7), "pack": 0.0, "network": 0.0,
                                   "reduce": 0.0}
    for outputs in sm.OUTPUTS:
        assert row[outputs]["efficiency"] == pytest.approx(1.0)
        assert row[outputs]["efficiency_overlapped"] == pytest.approx(1.0)


def test_two_slabs_exchange_one_plane_of_strips_each_way():
    """Two ranks on 4 x 4 x 4 blocks of 8^3: one plane of 16 block faces along z, each a strip
    of GHOST x 8^2 cells; nothing along x and y; a periodic z doubles it (two planes, same peer)."""
    mesh = box((4, 4, 4), 8, (False, False, False))
    x, y, z = sm.face_counts(mesh, sm.cuts_for(mesh, 2), ranks_per_node=2)
    assert x["faces"].tolist() == y["faces"].tolist() == [0, 0]
    assert z["faces"].tolist() == [16, 16] and z["peers"].tolist() == [1, 1] and z["on_node"].tolist() == [16, 16]
    assert sm.strip_values(mesh, 2, 10) == GHOST * 64 * 10
    periodic = box((4, 4, 4), 8, (False, False, True))
    assert sm.face_counts(periodic, sm.cuts_for(periodic, 2), 2)[2]["faces"].tolist() == [32, 32]
    assert sm.face_counts(periodic, sm.cuts_for(periodic, 2), 2)[2]["peers"].tolist() == [1, 1]


def test_off_node_faces_are_those_between_nodes():
    """Eight slabs of one plane each, two ranks per node: of the 7 planes of faces between ranks,
    3 lie between nodes; the inner nodes' links carry two planes, the end nodes' one."""
    mesh = box((2, 2, 8), 4, (False, False, False))
    z = sm.face_counts(mesh, sm.cuts_for(mesh, 8), ranks_per_node=2)[2]
    assert z["faces"].tolist() == [4] + [8] * 6 + [4]
    assert z["node_off"].tolist() == [4, 8, 8, 4]
    assert (z["faces"] - z["on_node"]).sum() == 2 * 3 * 4


def test_slabs_keep_their_surface_while_their_volume_falls():
    """In x-fastest order ranks own slabs of whole block planes (16, 4, 1 of 64): the compute per
    rank falls as 1 / P, the strips a middle rank packs stay two planes of 64 faces."""
    mesh = x_fastest_box((8, 8, 64), 8)
    terms = {p: sm.step_time(mesh, [10], 4, COSTS, NET, sm.cuts_for(mesh, p)) for p in (4, 16, 64)}
    assert terms[16]["compute"] == pytest.approx(terms[4]["compute"] / 4)
    assert terms[64]["pack"] == pytest.approx(terms[16]["pack"]) == pytest.approx(terms[4]["pack"])


def test_load_imbalance_follows_whole_blocks():
    mesh = box((5, 1), 16, (False, False))
    row = sm.run_time(mesh, [7], 3, COSTS, NET, 4, steps=10, snapshots=0)
    assert row["imbalance"] == pytest.approx(2 * 4 / 5)
    assert row["step_terms_s"]["compute"] == pytest.approx(2 * 16 ** 2 * 4e-7)


def test_exchange_components_count_the_state_and_the_three_strength_fills_one_message_each():
    """State 3M + 4 + M (NS + 2) = 22 values per strip cell in 2D; the work arrays' fills of
    velocities + fill + stress, velocities, stress, each one message (for every axis) of the
    slots a kernel reads in a ghost: in r-z without v_theta and S_zz (runs 2, 3, 1; 2; 2, 1 packed: 6; 2; 3),
    in plane 2D without S_zz (7; 3; 3), in 3D every slot (10; 3; 6)."""
    rz, planar, cube = GEOMETRY_CODES["2d-cylindrical"], GEOMETRY_CODES["2d-planar"], GEOMETRY_CODES["3d"]
    assert sm.exchange_components(3, cube, 2, strength=False) == [10]
    assert sm.exchange_components(2, rz, 2, strength=True) == [22, 6, 2, 3]
    assert sm.exchange_components(2, planar, 2, strength=True) == [22, 7, 3, 3]
    assert sm.exchange_components(3, cube, 2, strength=True) == [3 * 2 + 4 + 2 * 8, 10, 3, 6]


def test_the_check_counts_the_bytes_and_messages_the_r_z_impact_with_strength_sends_on_two_ranks():
    """benchmarks/mpi_scaling.py's 2d-cyl-strength on two ranks (32 x 75 blocks of 16^2, 1104 and
    1296 blocks) counts 337 920 B in 5 messages per step and rank: one message per axis for the
    state's fill (2) and one for both axes for each of the three work-array fills (3)."""
    ranks = [{"blocks": blocks, "bytes_sent": 337920, "messages_sent": 5, "allreduces": 4} for blocks in (1104, 1296)]
    document = {"ranks": 2, "results": [{"case": "2d-cyl-strength", "block_cells": 16, "blocks_per_axis": [32, 75],
                                         "periodic": [False, False], "materials": 2, "strength": True,
                                         "ranks": ranks}]}
    (row,) = sm.check_measured([document])
    assert row["exchange_components"] == [22, 6, 2, 3]
    assert row["model_bytes_sent"] == row["measured_bytes_sent"] == [337920, 337920]
    assert row["model_messages_sent"] == row["measured_messages_sent"] == [5, 5]
    assert row["model_allreduces"] == 4


def test_slot_runs_leave_out_the_skipped_slots():
    assert slot_runs(slice(0, 8), frozenset({2, 6})) == (slice(0, 2), slice(3, 6), slice(7, 8))
    assert slot_runs(slice(4, 8), frozenset({6})) == (slice(4, 6), slice(7, 8))
    assert slot_runs(slice(0, 3), frozenset({2})) == (slice(0, 2),)
    assert slot_runs(slice(4, 10), frozenset()) == (slice(4, 10),)


def test_exchange_costs_separate_the_cost_per_message_from_the_cost_per_byte():
    """Two cases, few large strips and many small ones, timed as c_msg messages + c_pack bytes:
    the fit returns both."""

    def document(case, messages, sent):
        rank = {"messages_sent": messages, "bytes_sent": sent, "bytes_received": sent,
                "exchange_s": 3e-3 + messages * 8e-5 + 2 * sent * 6e-10, "wait_s": 3e-3}
        return {"ranks": 2, "results": [{"case": case, "ranks": [rank, rank]}]}

    pack, message = sm.exchange_costs([document("3d", 1, 5242880), document("2d", 8, 337920)])
    assert pack == pytest.approx(6e-10) and message == pytest.approx(8e-5)
    with pytest.raises(ValueError, match="different bytes per message"):
        sm.exchange_costs([document("3d", 1, 5242880)])


def test_each_message_costs_its_fixed_share_of_the_packing():
    mesh = box((4, 4, 4), 8, (False, False, False))
    cuts = sm.cuts_for(mesh, 2)
    one = sm.step_time(mesh, [10], 4, COSTS, NET, cuts)["pack"]
    two = sm.step_time(mesh, [5, 5], 4, COSTS, NET, cuts)["pack"]
    assert two - one == pytest.approx(COSTS.message_s)


def test_a_work_array_fill_sends_every_axis_in_one_message_per_peer():
    """Two ranks of a 4 x 4-block box cut after 5 blocks border each other along x and y: the
    state's fill sends a message per axis, a work-array fill (the second component) the same
    strips in one: one c_msg less than a second state-like fill."""
    mesh = box((4, 4), 8, (False, False))
    cuts = np.array([0, 5, 16])
    counts = sm.face_counts(mesh, cuts, 2)
    assert [axis["peers"].tolist() for axis in counts] == [[1, 1], [1, 1]]
    assert sm.fill_peers(mesh, cuts).tolist() == [1, 1]
    one = sm.step_time(mesh, [10], 3, COSTS, NET, cuts)["pack"]
    two = sm.step_time(mesh, [10, 10], 3, COSTS, NET, cuts)["pack"]
    assert two - 2 * one == pytest.approx(-COSTS.message_s)


def test_reductions_are_the_time_step_the_sweeps_and_the_strength_check():
    assert sm.reductions_per_step(2, strength=False) == 3
    assert sm.reductions_per_step(2, strength=True) == 4
    assert sm.reductions_per_step(3, strength=False) == 4


def test_overlap_hides_the_network_but_not_the_packing():
    mesh = box((4, 4, 16), 8, (False, False, False))
    row = sm.run_time(mesh, [10], 4, COSTS, NET, 16, steps=100, snapshots=0)
    t, this = row["step_terms_s"], row["this-version"]
    assert this["wall_s"] - this["outputs_s"] == pytest.approx(100 * (t["compute"] + t["pack"] + t["network"] + t["reduce"]))
    assert this["wall_overlapped_s"] - this["outputs_s"] == pytest.approx(
        100 * (max(t["compute"], t["network"]) + t["pack"] + t["reduce"]))
    assert row["this-version"]["efficiency_overlapped"] >= row["this-version"]["efficiency"]
    assert np.isclose(t["reduce"], 4 * 1.5e-6 * 4)


def test_log_lines_and_snapshots_compute_own_blocks_and_gather_to_rank_zero():
    """Each of the 3 log lines computes a rank's own cells (N / 16) and one allreduce; each of the
    2 snapshots computes the rank's own cells and gathers at most S_tot = 8 c NB (B + 4)^3."""
    mesh = box((4, 4, 16), 8, (False, False, False))
    cuts = sm.cuts_for(mesh, 16)
    gather = 8 * 10 * 256 * 12 ** 3 / 5e9 + 1.5e-6 * 4
    logs = 3 * (mesh.ncells / 16 * 5e-8 + 1.5e-6 * 4)
    this = sm.output_time(mesh, 10, COSTS, NET, cuts, 300, 2, "this-version")
    assert this == pytest.approx(logs + 2 * (gather + mesh.ncells / 16 * 5e-8))
    assert sm.output_time(mesh, 10, COSTS, NET, sm.cuts_for(mesh, 1), 300, 2, "this-version") == pytest.approx(
        5 * mesh.ncells * 5e-8)


def test_steps_grow_as_the_power_through_the_two_finest_runs():
    document = {"runs": [{"cells_per_projectile_radius": 10, "steps": 2000},
                         {"cells_per_projectile_radius": 5, "steps": 800},
                         {"cells_per_projectile_radius": 2.5, "steps": 100}]}
    n1, s1, p = sm.step_growth(document)
    assert (n1, s1) == (10, 2000) and p == pytest.approx(np.log2(2.5))
    assert sm.handoff_steps(document, 40) == pytest.approx(2000 * 2.5 ** 2)
    assert sm.handoff_steps({"runs": document["runs"][:1]}, 40) == pytest.approx(2000 * 4)
