"""The cut of the block order into owned ranges, the exchange plan between ranks and the
tracers' neighbourhood (:mod:`impactpipe.hydro.parallel.decomposition`); numpy only, no MPI."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from impactpipe.hydro.amr.plans import axis_plans
from impactpipe.hydro.amr.regrid import plan_leaves, remesh
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.parallel.decomposition import (
    TRACER_REACH,
    every_axis_routes,
    exchange_routes,
    field_overlap_groups,
    level_field_routes,
    level_state_routes,
    neighbourhood_routes,
    overlap_groups,
    owned_ranges,
    owners,
    prolongation_stencil,
    restriction_stencil,
    touching_blocks,
)
from impactpipe.hydro.problems.common import adaptive_mesh


@pytest.mark.parametrize("nranks", [1, 2, 3, 4, 7])
def test_owned_ranges_cover_every_block_once_in_balanced_contiguous_ranges(nranks):
    costs = np.random.default_rng(27).choice([16, 160, 40], size=50)
    cuts = owned_ranges(costs, nranks)
    assert cuts[0] == 0 and cuts[-1] == len(costs) and len(cuts) == nranks + 1
    assert (np.diff(cuts) >= 1).all()  # contiguous, every block once, every rank at least one
    sums = np.add.reduceat(costs, cuts[:-1])
    assert sums.sum() == costs.sum()
    assert np.abs(sums - costs.sum() / nranks).max() <= costs.max()
    assert np.array_equal(cuts, owned_ranges(costs.copy(), nranks))


def test_void_blocks_are_cheap_so_a_rank_takes_more_of_them():
    costs = np.array([1] * 8 + [10] * 4)
    assert owned_ranges(costs, 2).tolist() == [0, 10, 12]


def test_more_ranks_than_blocks_is_an_error():
    with pytest.raises(ValueError, match="3 MPI ranks but the mesh has only 2 blocks"):
        owned_ranges(np.ones(2, dtype=np.int64), 3)


def test_the_exchange_plan_delivers_every_ghost_source_from_another_rank():
    """2d-planar, 4 x 3 blocks, periodic along x: the strips a rank receives are exactly the
    interior cells its owned blocks' ghosts copy from blocks of other ranks, and what one rank
    sends another is what that one receives."""
    mesh = adaptive_mesh("2d-planar", [0.0, 0.0], [1.0, 0.75], [16, 12], [("periodic", "periodic"),
                                                                           ("outflow", "reflecting")], 4, 1)
    g, n, (px, py, pz) = int(mesh.ghost[0]), mesh.interior_shape[0], mesh.padded_shape
    cuts = owned_ranges(np.ones(mesh.nblocks, dtype=np.int64), 3)
    owner = owners(cuts)
    plans = {rank: exchange_routes(mesh, cuts, rank) for rank in range(3)}
    for rank in range(3):
        for axis in range(2):
            expected = set()
            for b in range(cuts[rank], cuts[rank + 1]):
                for side in range(2):
                    nbr = int(mesh.neighbor[b, axis, side])
                    if nbr < 0 or owner[nbr] == rank:
                        continue
                    strip = range(n, n + g) if side == 0 else range(g, 2 * g)
                    for i in strip:
                        for j in range(g, g + n):
                            ix, iy = (i, j) if axis == 0 else (j, i)
                            expected.add((nbr, (ix * py + iy) * pz))
            received = {(int(b), int(c)) for route in plans[rank][axis]
                        for b, c in zip(route.receive.blocks, route.receive.cells)}
            assert received == expected
            for route in plans[rank][axis]:
                back = next(r for r in plans[route.peer][axis] if r.peer == rank)
                assert np.array_equal(route.send.blocks, back.receive.blocks)
                assert np.array_equal(route.send.cells, back.receive.cells)
    assert plans[0][2] == []


def test_a_fill_along_every_axis_sends_each_peer_its_strips_of_both_axes_in_one_message():
    """2d-planar, 4 x 3 blocks, periodic along x, on 4 ranks: the joined routes (the stress step's
    work-array fills) have one route per peer that borders the rank along some axis, whose
    strips are that peer's strips along x, then along y; every cell is an interior cell (no
    ghost that another axis's fill writes), and what one rank sends another receives.  Rank 0
    borders ranks 1 and 2 along both axes: 2 messages where a message per axis made 4."""
    mesh = adaptive_mesh("2d-planar", [0.0, 0.0], [1.0, 0.75], [16, 12], [("periodic", "periodic"),
                                                                           ("outflow", "reflecting")], 4, 1)
    g, n, (px, py, pz) = int(mesh.ghost[0]), mesh.interior_shape[0], mesh.padded_shape
    cuts = owned_ranges(np.ones(mesh.nblocks, dtype=np.int64), 4)
    plans = {rank: exchange_routes(mesh, cuts, rank) for rank in range(4)}
    joined = {rank: every_axis_routes(plans[rank]) for rank in range(4)}
    for rank in range(4):
        peers = sorted({route.peer for axis in range(3) for route in plans[rank][axis]})
        assert [route.peer for route in joined[rank]] == peers
        for route in joined[rank]:
            along = [r for axis in range(3) for r in plans[rank][axis] if r.peer == route.peer]
            for direction in ("send", "receive"):
                strips = getattr(route, direction)
                parts = [getattr(r, direction) for r in along]
                assert np.array_equal(strips.blocks, np.concatenate([part.blocks for part in parts]))
                assert np.array_equal(strips.cells, np.concatenate([part.cells for part in parts]))
            ix, iy = route.send.cells // (py * pz), route.send.cells // pz % py
            assert ((g <= ix) & (ix < g + n) & (g <= iy) & (iy < g + n)).all()
            back = next(r for r in joined[route.peer] if r.peer == rank)
            assert np.array_equal(route.send.blocks, back.receive.blocks)
            assert np.array_equal(route.send.cells, back.receive.cells)
    assert sum(len(route.send.cells) for route in joined[0]) == sum(
        len(route.send.cells) for axis in range(3) for route in plans[0][axis])
    assert [len(plans[0][axis]) for axis in range(3)] == [2, 2, 0] and len(joined[0]) == 2


def test_the_runs_of_components_of_a_fill_travel_in_one_buffer_one_run_after_another():
    """The stress step's fill of the work slots 0-1, 3-5 and 7 (v_theta and S_zz stay home) is
    one message per peer: the strips' flat indices are each run's, run by run, and a message
    holds those 6 of the 8 components' values of every strip cell."""
    mesh = adaptive_mesh("2d-planar", [0.0, 0.0], [1.0, 0.75], [16, 12], [("periodic", "periodic"),
                                                                           ("outflow", "reflecting")], 4, 1)
    work = np.arange(mesh.nblocks * 8 * int(np.prod(mesh.padded_shape)), dtype=float).reshape(
        (mesh.nblocks, 8) + mesh.padded_shape)
    runs = (slice(0, 2), slice(3, 6), slice(7, 8))
    strips = exchange_routes(mesh, owned_ranges(np.ones(mesh.nblocks, dtype=np.int64), 3), 0)[0][0].send
    indices = strips.indices(work, runs)
    assert np.array_equal(indices, np.concatenate([strips.indices(work, (run,)) for run in runs]))
    packed = work.reshape(-1)[indices].reshape(6, -1)
    for row, component in enumerate([0, 1, 3, 4, 5, 7]):
        assert np.array_equal(packed[row], work[:, component].reshape(mesh.nblocks, -1)[strips.blocks, strips.cells])
    assert indices.size == 6 * len(strips.cells) == strips.values(work, runs)


def test_the_stress_step_s_inner_blocks_have_no_face_towards_another_rank_on_any_axis():
    """2d-planar, 8 x 6 blocks, periodic along x, on 3 ranks: a rank's inner blocks (the stress
    step's kernels run on them while the strips travel) are exactly its blocks none of whose
    neighbours along x or y another rank owns; with the edge blocks they are its range, in order."""
    mesh = adaptive_mesh("2d-planar", [0.0, 0.0], [1.0, 0.75], [32, 24], [("periodic", "periodic"),
                                                                           ("outflow", "reflecting")], 4, 1)
    cuts = owned_ranges(np.ones(mesh.nblocks, dtype=np.int64), 3)
    owner = owners(cuts)
    for rank in range(3):
        inner, edge = field_overlap_groups(mesh, cuts, rank)
        assert np.array_equal(np.sort(np.concatenate([inner, edge])), np.arange(cuts[rank], cuts[rank + 1]))
        assert (np.diff(inner) > 0).all() and (np.diff(edge) > 0).all()
        for b in range(cuts[rank], cuts[rank + 1]):
            foreign = [int(n) for n in mesh.neighbor[b, :2].ravel() if n >= 0 and owner[n] != rank]
            assert (b in edge) == bool(foreign)
    assert sum(field_overlap_groups(mesh, cuts, rank)[0].size for rank in range(3)) > 0


def corner_refined_mesh(geometry: str = "2d-planar", boundary: tuple[str, str] = ("outflow", "outflow"),
                        cells: int = 32):
    """A unit box of ``cells`` cells per axis at the finest of three levels in blocks of 4 cells
    per axis, refined twice at the corner block at the origin (2d-planar, 32^2: 2 x 2 root
    blocks, 10 blocks)."""
    ndim = 3 if geometry == "3d" else 2
    mesh = adaptive_mesh(geometry, [0.0] * ndim, [1.0] * ndim, [cells] * ndim, [boundary] * ndim, 4, 3)
    for _ in range(2):
        refine = np.zeros(mesh.nblocks, dtype=bool)
        refine[np.argmin(mesh.block_lo[:, :ndim].sum(axis=1))] = True
        mesh, _ = remesh(mesh, HydroState.empty(mesh, 1), plan_leaves(mesh, refine, np.zeros_like(refine)))
    return mesh


#: Adaptive meshes of the tests of the coarse/fine exchanges: (geometry, boundary, cells per axis).
ADAPTIVE_MESHES = [("2d-planar", ("outflow", "outflow"), 32), ("2d-cylindrical", ("reflecting", "outflow"), 32),
                   ("2d-planar", ("periodic", "periodic"), 64), ("3d", ("outflow", "outflow"), 32)]


def test_on_an_adaptive_mesh_the_blocks_filled_from_other_ranks_are_swept_after_the_strips():
    """2d-planar, two levels around one corner block, on 2 and 3 ranks: a rank's edge blocks
    along an axis are those with a neighbour of another rank across a face between blocks of
    one level and those that a row of the axis's restriction or prolongation fills from another
    rank's block (their ghosts are completed after the wait); some blocks that such rows fill
    from the rank's own blocks, or read, are inner."""
    mesh = corner_refined_mesh()
    inner_touched = 0
    for nranks in (2, 3):
        cuts = owned_ranges(np.ones(mesh.nblocks, dtype=np.int64), nranks)
        owner = owners(cuts)
        for axis in range(2):
            plans = axis_plans(mesh, axis)
            rows = np.concatenate([plans[name][:, [0, 4]] for name in ("restrict", "prolong")])
            from_ranks = set(rows[owner[rows[:, 0]] != owner[rows[:, 1]], 0].tolist())
            assert from_ranks
            for rank in range(nranks):
                inner, edge = overlap_groups(mesh, cuts, rank)[axis]
                for b in range(cuts[rank], cuts[rank + 1]):
                    foreign = any(n >= 0 and owner[n] != rank and level == 0
                                  for n, level in zip(mesh.neighbor[b, axis], mesh.neighbor_level[b, axis]))
                    assert (b - cuts[rank] in edge) == (foreign or b in from_ranks)
                assert inner.size + edge.size == cuts[rank + 1] - cuts[rank]
                inner_touched += len(set(rows.ravel().tolist()) & set((inner + cuts[rank]).tolist()))
    assert inner_touched > 0


def received_keys(mesh, routes) -> dict[int, set[int]]:
    """Per peer: block * (cells per block) + padded flat cell of every cell a rank receives."""
    per_block = int(np.prod(mesh.padded_shape))
    return {route.peer: set((route.receive.blocks * per_block + route.receive.cells).tolist()) for route in routes}


def read_keys(mesh, plan: np.ndarray, stencil: np.ndarray) -> np.ndarray:
    """(rows, stencil) block * (cells per block) + padded flat cell of every cell a plan's rows read."""
    padded = np.array(mesh.padded_shape)
    cells = plan[:, None, 5:8] + stencil[None, :, :]
    return plan[:, 4:5] * int(padded.prod()) + (cells[..., 0] * padded[1] + cells[..., 1]) * padded[2] + cells[..., 2]


def interior(mesh, keys: np.ndarray, axes) -> np.ndarray:
    """Whether each cell of ``keys`` lies in the interior along every axis of ``axes``."""
    padded = np.array(mesh.padded_shape)
    flat = np.asarray(keys) % int(padded.prod())
    index = [flat // (padded[1] * padded[2]), flat // padded[2] % padded[1], flat % padded[2]]
    return np.all([(index[d] >= mesh.ghost[d]) & (index[d] < padded[d] - mesh.ghost[d]) for d in axes], axis=0)


@pytest.mark.parametrize(("geometry", "boundary", "cells"), ADAPTIVE_MESHES)
@pytest.mark.parametrize("nranks", [2, 3, 4])
def test_on_an_adaptive_mesh_the_stress_step_s_inner_blocks_need_no_other_rank_s_cells(geometry, boundary, cells,
                                                                                       nranks):
    """Two levels around one corner block, on 2-4 ranks: a rank's edge blocks for the stress step
    are those with a neighbour of another rank across a face between blocks of one level and
    those that a row of a restriction or prolongation fills from another rank's block; some are
    inner.  The one message per peer of a derived field's fills (level_field_routes) holds only
    interior cells, and every cell that such a row reads: the restriction's fine cells, the
    coarse cell a fine ghost copies."""
    mesh = corner_refined_mesh(geometry, boundary, cells)
    used = range(mesh.ndim)
    cuts = owned_ranges(np.ones(mesh.nblocks, dtype=np.int64), nranks)
    owner = owners(cuts)
    inner_blocks = filled_from_ranks = 0
    for rank in range(nranks):
        routes = level_field_routes(mesh, cuts, rank, exchange_routes(mesh, cuts, rank))
        received = received_keys(mesh, routes)
        remote_rows = set()
        for axis in used:
            plans = axis_plans(mesh, axis)
            for name, stencil in (("restrict", restriction_stencil(mesh)), ("prolong", np.zeros((1, 3), int))):
                rows = plans[name][(owner[plans[name][:, 0]] == rank) & (owner[plans[name][:, 4]] != rank)]
                remote_rows |= set(rows[:, 0].tolist())
                for row, keys in zip(rows, read_keys(mesh, rows, stencil)):
                    assert set(keys.tolist()) <= received[owner[row[4]]]
        for keys in received.values():
            assert interior(mesh, sorted(keys), used).all()
        inner, edge = field_overlap_groups(mesh, cuts, rank)
        assert np.array_equal(np.sort(np.concatenate([inner, edge])), np.arange(cuts[rank], cuts[rank + 1]))
        for b in range(cuts[rank], cuts[rank + 1]):
            foreign = any(n >= 0 and owner[n] != rank and level == 0
                          for n, level in zip(mesh.neighbor[b, used].ravel(), mesh.neighbor_level[b, used].ravel()))
            assert (b in edge) == (foreign or b in remote_rows)
        inner_blocks += inner.size
        filled_from_ranks += len(remote_rows)
    assert inner_blocks > 0 and filled_from_ranks > 0


@pytest.mark.parametrize(("geometry", "boundary", "cells"), ADAPTIVE_MESHES)
@pytest.mark.parametrize("nranks", [2, 3, 4])
def test_on_an_adaptive_mesh_the_state_s_prolongation_reads_no_ghost_it_waits_for(geometry, boundary, cells, nranks):
    """Two levels around one corner block, on 2-4 ranks: before the state's fill along an axis a
    rank receives (level_state_routes, one message per peer) every cell of other ranks' blocks
    that its prolongation reads but the coarse ghosts toward its finer blocks; those it
    restricts itself (BlockRanges.plans' restrict_borrowed) from its own fine cells, the rows
    of the whole restriction that set them."""
    from types import SimpleNamespace

    from impactpipe.hydro.parallel.distributed import BlockRanges

    mesh = corner_refined_mesh(geometry, boundary, cells)
    cuts = owned_ranges(np.ones(mesh.nblocks, dtype=np.int64), nranks)
    owner = owners(cuts)
    borrowed_rows = 0
    for rank in range(nranks):
        partition = BlockRanges(SimpleNamespace(rank=rank, size=nranks), mesh, cuts)
        for axis in range(mesh.ndim):
            received = received_keys(mesh, level_state_routes(mesh, cuts, rank, exchange_routes(mesh, cuts, rank),
                                                               axis))
            plans = partition.plans(mesh, axis)
            borrowed = plans["restrict_borrowed"]
            assert (owner[borrowed[:, 4]] == rank).all() and (owner[borrowed[:, 0]] != rank).all()
            restricted = set(read_keys(mesh, borrowed[:, [4, 5, 6, 7, 0, 1, 2, 3]], np.zeros((1, 3), int)).ravel()
                             .tolist())
            rows = plans["prolong_away"]
            for row, keys in zip(rows, read_keys(mesh, rows, prolongation_stencil(mesh))):
                inside = interior(mesh, keys, [axis])
                assert set(keys[inside].tolist()) <= received[owner[row[4]]]
                assert inside.sum() == len(keys) - 1 and set(keys[~inside].tolist()) <= restricted
            whole = axis_plans(mesh, axis)["restrict"]
            assert len({tuple(r) for r in borrowed.tolist()} - {tuple(r) for r in whole.tolist()}) == 0
            borrowed_rows += len(borrowed)
    assert borrowed_rows > 0


@pytest.mark.parametrize("geometry", ["2d-planar", "3d"])
def test_the_tracers_neighbourhood_is_every_foreign_cell_within_reach_of_a_rank_s_blocks(geometry):
    """Periodic along x, outflow / reflecting elsewhere: the cells a rank receives are exactly the
    interior cells of other ranks' blocks within TRACER_REACH (across faces, edges, corners and
    the periodic faces) of a cell of its own blocks, and what one rank sends another is what
    that one receives."""
    ndim = 2 if geometry == "2d-planar" else 3
    cells = [16, 12, 8][:ndim]
    boundaries = [("periodic", "periodic"), ("outflow", "reflecting"), ("outflow", "outflow")][:ndim]
    mesh = adaptive_mesh(geometry, [0.0] * ndim, [c / 16 for c in cells], cells, boundaries, 4, 1)
    n, g, (px, py, pz) = 4, mesh.ghost, mesh.padded_shape
    block_at = {tuple(int(i) for i in mesh.block_index[b]): b for b in range(mesh.nblocks)}
    nranks = 3
    cuts = owned_ranges(np.ones(mesh.nblocks, dtype=np.int64), nranks)
    owner = owners(cuts)
    plans = {rank: neighbourhood_routes(mesh, cuts, rank) for rank in range(nranks)}
    for rank in range(nranks):
        expected = set()
        for b in range(cuts[rank], cuts[rank + 1]):
            for local in itertools.product(range(n), repeat=ndim):
                cell = [int(mesh.block_index[b, d]) * n + local[d] for d in range(ndim)]
                for step in itertools.product(range(-TRACER_REACH, TRACER_REACH + 1), repeat=ndim):
                    near = [cell[d] + step[d] for d in range(ndim)]
                    near[0] %= cells[0]
                    if any(not 0 <= near[d] < cells[d] for d in range(ndim)):
                        continue
                    nb = block_at[tuple(c // n for c in near) + (0,) * (3 - ndim)]
                    if owner[nb] != rank:
                        i = [near[d] % n + g[d] for d in range(ndim)] + [0] * (3 - ndim)
                        expected.add((nb, (i[0] * py + i[1]) * pz + i[2]))
        received = [(int(b), int(c)) for route in plans[rank]
                    for b, c in zip(route.receive.blocks, route.receive.cells)]
        assert len(received) == len(set(received))
        assert set(received) == expected
        for route in plans[rank]:
            back = next(r for r in plans[route.peer] if r.peer == rank)
            assert np.array_equal(route.send.blocks, back.receive.blocks)
            assert np.array_equal(route.send.cells, back.receive.cells)


@pytest.mark.parametrize(("geometry", "boundary"), [("2d-cylindrical", ("reflecting", "outflow")),
                                                    ("2d-planar", ("periodic", "periodic")),
                                                    ("3d", ("outflow", "outflow"))])
def test_touching_blocks_of_an_adaptive_mesh_are_every_pair_of_touching_boxes(geometry, boundary):
    """Against a brute-force test of every pair of boxes (nearest periodic image), on a mesh
    with two levels of refinement around one corner block."""
    ndim = 3 if geometry == "3d" else 2
    mesh = adaptive_mesh(geometry, [0.0] * ndim, [1.0] * ndim, [32] * ndim, [boundary] * ndim, 4, 3)
    for _ in range(2):
        refine = np.zeros(mesh.nblocks, dtype=bool)
        refine[np.argmin(mesh.block_lo[:, :ndim].sum(axis=1))] = True
        mesh, _ = remesh(mesh, HydroState.empty(mesh, 1), plan_leaves(mesh, refine, np.zeros_like(refine)))
    assert mesh.block_level.max() == 2
    lo = mesh.block_lo[:, :ndim]
    hi = lo + mesh.block_dx[:, :ndim] * 4
    periodic = boundary[0] == "periodic"
    want = set()
    for a, b in itertools.permutations(range(mesh.nblocks), 2):
        gaps = []
        for d in range(ndim):
            gap = max(lo[a, d] - hi[b, d], lo[b, d] - hi[a, d], 0.0)
            if periodic:
                gap = min(gap, max(lo[a, d] + 1.0 - hi[b, d], lo[b, d] - hi[a, d] - 1.0, 0.0),
                          max(lo[a, d] - 1.0 - hi[b, d], lo[b, d] - hi[a, d] + 1.0, 0.0))
            gaps.append(gap)
        if max(gaps) < 1e-12:
            want.add((a, b))
    got = set(zip(*(x.tolist() for x in touching_blocks(mesh))))
    assert got == want
