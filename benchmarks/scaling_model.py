"""Projected strong and weak scaling of one hydro run over many MPI ranks, from measured costs.

The model follows what the code does in this version (:mod:`impactpipe.hydro.parallel`):

* Decomposition.  The run's mesh is the code's own: the uniform
  :class:`~impactpipe.hydro.mesh.blocks.BlockMesh` of the config
  (:func:`impactpipe.hydro.problems.common.adaptive_mesh` with one level), in the code's
  block order.  Rank r owns the contiguous range ``cuts[r] .. cuts[r + 1] - 1`` of that
  order, cut by :func:`~impactpipe.hydro.parallel.decomposition.owned_ranges` with one cost
  per block (the code's cut weighs the measured cost of material, void and mixed blocks of
  the current state, which a uniform box does not vary), so a rank owns
  W_r = floor or ceil(NB / P) blocks of n_b = B^d cells.  The faces between ranks are
  counted, per rank and axis, from the mesh's neighbour table (``mesh.neighbor``) and the
  owners of the blocks (:func:`face_counts`): whatever block order the mesh has, the model
  follows it.  With the order of this version (a Morton curve) a rank's blocks are a
  compact group.
* Exchange.  Before every ghost fill along axis d, each block face whose neighbour another
  rank owns costs one strip each way (:func:`~impactpipe.hydro.parallel.decomposition.exchange_routes`):
  GHOST = 2 layers of B^(d-1) interior cells of c float64 components,
  s = 8 GHOST B^(d-1) c bytes.  A step fills the state's ghosts once per axis (c = 3M + 4 +
  M NQ, M materials, NQ transported scalars per material: 0 without strength, NS + 2 with
  it, NS = 4 stress components in 2D and 6 in 3D), one message per peer rank and axis.  With
  strength the step fills the work arrays' ghosts three more times
  (:mod:`impactpipe.hydro.strength.model`): after loading the stress, the velocities, fill
  and stress; after the half kick, the velocities; after the stress update, the stress;
  each without the slots no kernel reads in a ghost (in 2D S_zz, in r-z v_theta too), its
  runs of consecutive slots along every axis packed into one message per peer rank
  (:func:`exchange_components`: in r-z 6 of 8 slots, 2 of 3 and 3 of 4; in 3D 10, 3 and 6;
  the peers of a rank along any axis, :func:`fill_peers`).  The code overlaps the
  exchanges of a uniform mesh with the kernels of the blocks that need no other rank's
  strips; the model gives the step with the exchanges blocking and the bound an overlap
  can reach (below).
* Reductions.  One allreduce for the time step, one per sweep for the failure check, and
  with strength one for the non-finite momentum check: R = 1 + d (+ 1) per step, each
  alpha ceil(log2 P) s.
* Outputs.  Every LOG_INTERVAL-th step's log line (its peak pressure,
  :meth:`~impactpipe.hydro.solver.Simulation.max_pressure`): each rank computes the
  thermodynamics of its own cells, then one allreduce (MAX).  Every snapshot: every rank
  receives every block (Allgatherv of the whole padded state, S_tot bytes) and computes the
  thermodynamics of every cell.

Time of one step on P ranks (s), the slowest rank setting each phase:

    t_compute  = max_r W_r n_b c_cell
    t_exchange = sum over the axes d of the state's fill
                 max_r [ m_rd (alpha + c_msg) + 2 f_rd s_0d c_pack + f_on_rd s_0d / beta_shm ]
                 + max_n f_off_nd s_0d / beta_link
               + sum over the work arrays' fills k of
                 max_r [ m_r (alpha + c_msg) + sum_d (2 f_rd s_kd c_pack + f_on_rd s_kd / beta_shm) ]
                 + max_n sum_d f_off_nd s_kd / beta_link
    t_reduce   = R alpha ceil(log2 P)

with f_rd the rank's block faces along d whose neighbour another rank owns (f_on_rd of them
to ranks on its own node, f_off_nd the faces of node n's ranks to other nodes), m_rd its
peers along d, m_r its peers along any axis, c_cell (s) the measured compute cost of a cell-update on one core, c_pack
(s/B) the measured cost of packing and unpacking a byte of strips, c_msg (s) the measured
fixed cost of one message (posting, the packing call, the unpacking of the reply), alpha (s) the latency,
beta_shm (B/s) the on-node bandwidth of one rank and beta_link (B/s) the bandwidth of one
node's link, which all the node's off-node strips share.  The latency and transfer terms (not
c_pack and c_msg) are what overlapping the exchange with the interior's sweep could hide:
t_step = t_compute + t_exchange + t_reduce without overlap (the code),
max(t_compute, t_network) + t_pack + t_reduce with it (a projection).  A run of n steps
and n_snap snapshots takes

    T_P = n t_step + (n / LOG_INTERVAL) (max_r W_r n_b c_snap + alpha ceil(log2 P))
          + n_snap (S_tot / min(beta_link, beta_shm) + alpha ceil(log2 P) + max_r W_r n_b c_snap)

(N cells, c_snap (s) the fields of one cell of a snapshot, taken for the log line's too; each
rank computes its own blocks' fields and rank 0 gathers them: S_tot, the padded state's bytes,
bounds the interior fields gathered from above and passes rank 0's link once), one rank
T_1 = n N c_cell + (n / LOG_INTERVAL + n_snap) N c_snap, and the parallel efficiency is
E = T_1 / (P T_P).  Strong scaling keeps the mesh; weak scaling keeps N / P by refining the
mesh.  The steps to hand-off n grow with the cells per projectile radius as measured on two
coarse uniform meshes (:func:`step_growth`).  Not modelled: adaptive meshes (their coarse/fine exchanges and the gather of every block before
each regrid), rank 0 writing the snapshots, the cost estimate's error in the cut of an
impact's blocks, and memory: every rank holds the whole state.

    python benchmarks/scaling_model.py --measured ONE.json TWO.json ONE_8.json TWO_8.json \\
        --steps STEPS_8C.json STEPS_OBLIQUE.json --json [--runs case8c-160 oblique45-20]

(JSON documents of benchmarks/mpi_scaling.py on 1 and 2 ranks, and of
benchmarks/handoff_steps.py; docs/performance.md, "Several MPI ranks".)
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.parallel.decomposition import owned_ranges, owners
from impactpipe.hydro.problems.common import adaptive_mesh
from impactpipe.hydro.solver import LOG_INTERVAL
from impactpipe.hydro.strength.model import slot_runs, work_ghost_reads
from impactpipe.hydro.strength.update import WK_S, WK_V, stress_slots

#: Bytes of one exchanged value (float64).
WORD = 8
CONFIGS = Path(__file__).resolve().parents[1] / "configs"
#: The projected runs: config, overrides (uniform mesh, the named resolution), the measured case
#: whose cost per cell-update stands for the run's, and the block edge that case must have.
RUNS = {
    "case8c-160": (CONFIGS / "reference" / "case8c.yaml",
                   {"hydro.cells_per_projectile_radius": 160, "hydro.max_levels": 1}, "2d-cyl-strength"),
    "oblique45-20": (CONFIGS / "oblique45.yaml",
                     {"hydro.cells_per_projectile_radius": 20, "hydro.max_levels": 1, "hydro.block_cells": 8},
                     "3d-two-material"),
}
RANKS = (64, 256, 1024)
#: Materials of an impact's state: the target and the projectile (hydro.problems.impact).
IMPACT_MATERIALS = 2
#: Geometry of the mesh that stands for a measured case's in :func:`check_measured` (the neighbour
#: table, all the check needs, depends on the block counts and the periodic axes only).
CHECK_GEOMETRY = {2: "2d-planar", 3: "3d"}
#: The measured cases in r-z, whose work-array fills leave out v_theta (:func:`exchange_components`).
CASE_GEOMETRY = {"2d-cyl-tillotson": "2d-cylindrical", "2d-cyl-strength": "2d-cylindrical",
                 "2d-cyl-fracture": "2d-cylindrical"}


@dataclass(frozen=True)
class Interconnect:
    """A cluster's network: ``latency_s`` alpha (s), ``link_bytes_per_s`` beta_link (B/s, one
    node's link), ``ranks_per_node``, ``shm_bytes_per_s`` beta_shm (B/s, one rank's on-node
    messages)."""

    latency_s: float
    link_bytes_per_s: float
    ranks_per_node: int
    shm_bytes_per_s: float


@dataclass(frozen=True)
class Costs:
    """Measured on one core: ``cell_update_s`` c_cell (s per cell-update), ``pack_s_per_byte``
    c_pack (s per byte sent or received), ``message_s`` c_msg (s per message sent, with the
    unpacking of the one received from the same peer: the fixed cost of a strip message),
    ``snapshot_s_per_cell`` c_snap (s per cell)."""

    cell_update_s: float
    pack_s_per_byte: float
    message_s: float
    snapshot_s_per_cell: float


def block_cells_of(mesh: BlockMesh) -> int:
    """Interior cells of one block, n_b = B^d."""
    return int(np.prod(mesh.interior_shape))


def strip_values(mesh: BlockMesh, axis: int, components: int) -> int:
    """Values of one strip along ``axis``: GHOST x the block's interior cells across the other
    axes (B^(d-1)) x ``components``."""
    return int(mesh.ghost[axis]) * block_cells_of(mesh) // mesh.interior_shape[axis] * components


def padded_state_bytes(mesh: BlockMesh, components: int) -> int:
    """Bytes of the whole state with its ghosts, S_tot = 8 c NB (B + 2 GHOST)^d."""
    return WORD * components * mesh.nblocks * int(np.prod(mesh.padded_shape))


def exchange_components(ndim: int, geometry_code: int, nmat: int, strength: bool) -> list[int]:
    """Float64 components per strip cell of each of one step's ghost fills: first the state's
    (3M + 4 + M NQ, NQ = NS + 2 with strength; one message per peer rank and axis), then, with
    strength, the three fills of the work arrays (:mod:`impactpipe.hydro.strength.model`):
    velocities, fill and stress (slots WK_V .. WK_S + NS - 1), velocities (WK_V .. WK_V + 2)
    and stress (WK_S .. WK_S + NS - 1), each without the slots no kernel reads in a ghost, its
    runs of consecutive slots along every axis in one message per peer rank
    (:func:`~impactpipe.hydro.strength.model.work_ghost_reads`,
    :func:`~impactpipe.hydro.strength.model.slot_runs`)."""
    if not strength:
        return [3 * nmat + 4]
    ns = stress_slots(ndim)
    _, skipped = work_ghost_reads(ndim, geometry_code, False)
    fills = (slice(WK_V, WK_S + ns), slice(WK_V, WK_V + 3), slice(WK_S, WK_S + ns))
    return [3 * nmat + 4 + nmat * (ns + 2)] + [sum(run.stop - run.start for run in slot_runs(fill, skipped))
                                               for fill in fills]


def reductions_per_step(ndim: int, strength: bool) -> int:
    """Allreduces of one step, R: the time step, the failure check after each of the d sweeps,
    and with strength the non-finite momentum check."""
    return 1 + ndim + int(strength)


def cuts_for(mesh: BlockMesh, nranks: int) -> np.ndarray:
    """The cut points of ``nranks`` ranks over the mesh's block order with one cost per block."""
    return owned_ranges(np.ones(mesh.nblocks, dtype=np.int64), nranks)


def face_counts(mesh: BlockMesh, cuts: np.ndarray, ranks_per_node: int) -> list[dict]:
    """Per used axis d: ``faces`` (P,) f_rd, ``on_node`` (P,) f_on_rd, ``peers`` (P,) m_rd and
    ``node_off`` (nodes,) f_off_nd.

    A face is a (block, side) whose neighbour in ``mesh.neighbor`` another rank owns; its
    block's owner sends that block's strip, as the exchange plan of the code does
    (:func:`~impactpipe.hydro.parallel.decomposition.exchange_routes`).  Nodes hold
    ``ranks_per_node`` consecutive ranks.  Vectorised over the blocks (numpy, no loop over blocks).
    """
    if mesh.adaptive:
        raise ValueError("the model counts the faces of a uniform mesh; an adaptive one has coarse/fine exchanges too")
    nranks = len(cuts) - 1
    owner = owners(cuts)
    node_of = np.arange(nranks) // ranks_per_node
    nnodes = int(node_of[-1]) + 1
    out = []
    for axis in range(mesh.ndim):
        neighbour = mesh.neighbor[:, axis, :].ravel()
        block = np.repeat(np.arange(mesh.nblocks), 2)
        inside = neighbour >= 0
        sender, receiver = owner[block[inside]], owner[neighbour[inside]]
        apart = sender != receiver
        sender, receiver = sender[apart], receiver[apart]
        off = node_of[sender] != node_of[receiver]
        pairs = np.unique(np.minimum(sender, receiver) * nranks + np.maximum(sender, receiver))
        out.append({
            "faces": np.bincount(sender, minlength=nranks),
            "on_node": np.bincount(sender[~off], minlength=nranks),
            "peers": np.bincount(np.concatenate([pairs // nranks, pairs % nranks]), minlength=nranks),
            "node_off": np.bincount(node_of[sender[off]], minlength=nnodes),
        })
    return out


def fill_peers(mesh: BlockMesh, cuts: np.ndarray) -> np.ndarray:
    """(P,) m_r: the ranks that share a block face with rank r along some axis, the peers of a
    fill along every axis in one message per peer (the work arrays' fills,
    :func:`~impactpipe.hydro.parallel.decomposition.every_axis_routes`).  Vectorised over the blocks."""
    nranks = len(cuts) - 1
    owner = owners(cuts)
    neighbour = mesh.neighbor[:, :mesh.ndim, :].ravel()
    block = np.repeat(np.arange(mesh.nblocks), 2 * mesh.ndim)
    inside = neighbour >= 0
    sender, receiver = owner[block[inside]], owner[neighbour[inside]]
    apart = sender != receiver
    pairs = np.unique(np.minimum(sender[apart], receiver[apart]) * nranks + np.maximum(sender[apart], receiver[apart]))
    return np.bincount(np.concatenate([pairs // nranks, pairs % nranks]), minlength=nranks)


def step_time(mesh: BlockMesh, components: list[int], reductions: int, costs: Costs, net: Interconnect,
              cuts: np.ndarray) -> dict:
    """The terms of one step's time (s) on the ranks of ``cuts`` (module docstring):
    ``compute``, ``pack``, ``network`` (latency and transfer of the strips), ``reduce``
    (``reductions`` allreduces).  ``components``: the state's fill (a message per peer and
    axis), then the work arrays' (a message per peer for every axis), :func:`exchange_components`."""
    nranks = len(cuts) - 1
    compute = int(np.diff(cuts).max()) * block_cells_of(mesh) * costs.cell_update_s
    pack = network = 0.0
    if nranks > 1:
        faces = list(enumerate(face_counts(mesh, cuts, net.ranks_per_node)))
        state, *work = components
        messages = [(state, [axis_faces], axis_faces[1]["peers"]) for axis_faces in faces]
        messages += [(c, faces, fill_peers(mesh, cuts)) for c in work]
        for c, axes, peers in messages:
            packing, moving = message_time(mesh, c, axes, peers, costs, net)
            pack += packing
            network += moving
    reduce = reductions * tree_latency(net, nranks)
    return {"compute": compute, "pack": pack, "network": network, "reduce": reduce}


def message_time(mesh: BlockMesh, components: int, axes: list[tuple[int, dict]], peers: np.ndarray, costs: Costs,
                 net: Interconnect) -> tuple[float, float]:
    """(packing, network) (s) of a fill whose strips of ``components`` values per cell along the
    ``axes`` ((axis, :func:`face_counts` of it) pairs) travel in one message to each of a rank's
    ``peers`` (P,): the slowest rank's packing and fixed message costs, and its latency and
    on-node transfer plus the busiest node link's transfer."""
    packing = peers * costs.message_s
    moving = peers * net.latency_s
    link = 0.0
    for axis, faces in axes:
        strip = WORD * strip_values(mesh, axis, components)
        packing = packing + 2 * faces["faces"] * strip * costs.pack_s_per_byte
        moving = moving + faces["on_node"] * strip / net.shm_bytes_per_s
        link = link + faces["node_off"] * strip / net.link_bytes_per_s
    slowest = int(np.argmax(packing + moving))
    return float(packing[slowest]), float(moving[slowest] + np.max(link))


def tree_latency(net: Interconnect, nranks: int) -> float:
    """Latency of one allreduce over ``nranks`` ranks, alpha ceil(log2 P) (s); 0 on one rank."""
    return net.latency_s * math.ceil(math.log2(nranks)) if nranks > 1 else 0.0


#: How a run's outputs are made: this version's (each rank computes its own blocks' snapshot
#: fields and log-line pressures; rank 0 gathers the snapshots, one reduction per log line).
OUTPUTS = ("this-version",)


def output_time(mesh: BlockMesh, state_components: int, costs: Costs, net: Interconnect, cuts: np.ndarray,
                steps: float, snapshots: int, outputs: str) -> float:
    """Time (s) of a run's outputs on the ranks of ``cuts``: steps / LOG_INTERVAL log lines, each
    max_r W_r n_b c_snap + alpha ceil(log2 P) (own blocks, one MAX allreduce), and ``snapshots``
    snapshots made as ``outputs`` (:data:`OUTPUTS`) says: the fields of the rank's own blocks,
    max_r W_r n_b c_snap, and a gather to rank 0 bounded by S_tot / min(beta_link, beta_shm) +
    alpha ceil(log2 P) (none on one rank)."""
    nranks = len(cuts) - 1
    reduce = tree_latency(net, nranks)
    gather = 0.0 if nranks == 1 else (
        padded_state_bytes(mesh, state_components) / min(net.link_bytes_per_s, net.shm_bytes_per_s) + reduce)
    own = int(np.diff(cuts).max()) * block_cells_of(mesh) * costs.snapshot_s_per_cell
    logs = steps / LOG_INTERVAL * (own + reduce)
    if outputs not in OUTPUTS:
        raise ValueError(f"outputs must be one of {OUTPUTS}, got {outputs!r}")
    return logs + snapshots * (gather + own)


def run_time(mesh: BlockMesh, components: list[int], reductions: int, costs: Costs, net: Interconnect,
             nranks: int, steps: float, snapshots: int) -> dict:
    """Wall time (s) of ``steps`` steps and ``snapshots`` snapshots on ``nranks`` ranks, and the
    efficiency E = T_1 / (P T_P), per way of making the snapshots (:data:`OUTPUTS`), without
    overlap of the exchange (``wall_s``, ``efficiency``: the code) and with it
    (``*_overlapped``: a projection).  ``components``: the fills of a step, the state's first."""
    cuts = cuts_for(mesh, nranks)
    t = step_time(mesh, components, reductions, costs, net, cuts)
    serial = (steps * mesh.ncells * costs.cell_update_s
              + (snapshots + steps / LOG_INTERVAL) * mesh.ncells * costs.snapshot_s_per_cell)
    plain = steps * (t["compute"] + t["pack"] + t["network"] + t["reduce"])
    overlapped = steps * (max(t["compute"], t["network"]) + t["pack"] + t["reduce"])
    row = {"ranks": nranks, "cells": mesh.ncells, "blocks_per_rank": mesh.nblocks / nranks,
           "imbalance": int(np.diff(cuts).max()) * nranks / mesh.nblocks, "steps": steps, "step_terms_s": t,
           "state_bytes_per_rank": padded_state_bytes(mesh, components[0])}
    for outputs in OUTPUTS:
        extra = output_time(mesh, components[0], costs, net, cuts, steps, snapshots, outputs)
        row[outputs] = {"outputs_s": extra, "wall_s": plain + extra, "efficiency": serial / (nranks * (plain + extra)),
                        "wall_overlapped_s": overlapped + extra,
                        "efficiency_overlapped": serial / (nranks * (overlapped + extra))}
    return row


def step_growth(document: dict) -> tuple[float, float, float]:
    """(n1, s1, p) of a benchmarks/handoff_steps.py document: its finest run's cells per projectile
    radius n1 and steps s1, and the exponent p = ln(s1 / s0) / ln(n1 / n0) against the next
    finest run (n0, s0); p = 1 (dt proportional to dx at a fixed signal speed) with one run."""
    runs = sorted(document["runs"], key=lambda run: run["cells_per_projectile_radius"])
    n1, s1 = runs[-1]["cells_per_projectile_radius"], runs[-1]["steps"]
    if len(runs) == 1:
        return n1, s1, 1.0
    n0, s0 = runs[-2]["cells_per_projectile_radius"], runs[-2]["steps"]
    return n1, s1, math.log(s1 / s0) / math.log(n1 / n0)


def handoff_steps(document: dict, cells_per_radius: float) -> float:
    """Steps to hand-off at ``cells_per_radius`` n: s1 (n / n1)^p (:func:`step_growth`)."""
    n1, s1, p = step_growth(document)
    return s1 * (cells_per_radius / n1) ** p


def run_mesh(config_path: Path, overrides: dict) -> tuple[BlockMesh, dict]:
    """The uniform impact mesh of a config with ``overrides`` as the code builds it
    (:func:`impactpipe.hydro.problems.common.adaptive_mesh` with one level over the box of
    pipeline.derived), and the derived values."""
    from impactpipe.pipeline import derived, load_config

    config = load_config(config_path, overrides=overrides)
    values = derived.derive(config)
    domain = values["domain"]
    mesh = adaptive_mesh(values["geometry"], domain["lo"], domain["hi"], domain["cells"],
                         [tuple(pair) for pair in domain["boundaries"]], domain["block_cells"], 1)
    values["snapshots"] = len(derived.snapshot_times(config, float(values["end_time"])))
    values["strength_on"] = any(choice["enabled"] for choice in values["strength"].values())
    return mesh, values


def costs_from(measured: list[dict], case: str, block_cells: int) -> Costs:
    """c_cell and c_snap from the one-rank measurements of ``case`` on ``block_cells`` blocks (the
    medians over the documents), c_pack and c_msg from every two-rank measurement of the
    documents (:func:`exchange_costs`)."""

    def results(ranks: int) -> list[dict]:
        return [r for document in measured if document["ranks"] == ranks for r in document["results"]
                if r["case"] == case and r["block_cells"] == block_cells and "skipped" not in r]

    one, two = results(1), results(2)
    if not one or not two:
        raise ValueError(f"{case} on {block_cells}-cell blocks needs one-rank and two-rank measurements")
    pack, message = exchange_costs(measured)
    return Costs(float(np.median([r["ranks"][0]["compute_s_per_cell_update"] for r in one])), pack, message,
                 float(np.median([r["ranks"][0]["snapshot_s"] / r["cells"] for r in one])))


def exchange_costs(measured: list[dict]) -> tuple[float, float]:
    """(c_pack, c_msg): the least-squares fit of every rank's exchange time less its waits per
    step, exchange - Waitall = c_msg messages + c_pack bytes (sent and received), over the
    two-rank results of every case in ``measured``.  The cases must differ in bytes per message
    (the 3D box's few large strips and the 2D impact's many small ones) for both to be found."""
    rows = [(rank["messages_sent"], rank["bytes_sent"] + rank["bytes_received"], rank["exchange_s"] - rank["wait_s"])
            for document in measured if document["ranks"] == 2 for r in document["results"] if "skipped" not in r
            for rank in r["ranks"]]
    a = np.array([[messages, nbytes] for messages, nbytes, _ in rows], dtype=float)
    if np.linalg.matrix_rank(a) < 2:
        raise ValueError("c_pack and c_msg need two-rank measurements of cases with different bytes per message")
    (message, pack), *_ = np.linalg.lstsq(a, np.array([t for *_, t in rows]), rcond=None)
    return float(pack), float(message)


def project(measured: list[dict], steps: dict[str, dict], net: Interconnect) -> dict:
    """Strong and weak scaling of the runs of RUNS named in ``steps`` at RANKS (weak: N / P of
    the run at 256 ranks)."""
    out = {}
    for name in steps:
        config_path, overrides, case = RUNS[name]
        mesh, values = run_mesh(config_path, overrides)
        n = overrides["hydro.cells_per_projectile_radius"]
        strength = values["strength_on"]
        components = exchange_components(mesh.ndim, mesh.geometry_code, IMPACT_MATERIALS, strength)
        reductions = reductions_per_step(mesh.ndim, strength)
        costs = costs_from(measured, case, mesh.block_cells)
        rows = {"strong": [], "weak": []}
        for mode in rows:
            for nranks in RANKS:
                resolution = n * (nranks / 256) ** (1 / mesh.ndim) if mode == "weak" else n
                grown = mesh if mode == "strong" else run_mesh(
                    config_path, {**overrides, "hydro.cells_per_projectile_radius": resolution})[0]
                count = handoff_steps(steps[name], resolution)
                row = run_time(grown, components, reductions, costs, net, nranks, count, values["snapshots"])
                rows[mode].append({"cells_per_projectile_radius": resolution, **row})
        out[name] = {"config": str(config_path.relative_to(CONFIGS.parent)), "overrides": overrides,
                     "cost_case": case, "costs": costs.__dict__, "exchange_components": components,
                     "reductions_per_step": reductions, "end_time": values["end_time"],
                     "snapshots": values["snapshots"], "blocks_per_axis": mesh.blocks_per_axis[:mesh.ndim].tolist(),
                     "block_cells": mesh.block_cells, "step_growth": step_growth(steps[name]),
                     "cell_updates": mesh.ncells * handoff_steps(steps[name], n), **rows}
    return out


def check_measured(measured: list[dict]) -> list[dict]:
    """The model's bytes and messages sent per step and rank for every measured multi-rank case
    (the case's mesh and cut; the state's fill a message per axis and peer, each work-array fill
    a message per peer, :func:`exchange_components`, :func:`fill_peers`), and its allreduces,
    beside the counted ones: the formulas against the code."""
    rows = []
    for document in measured:
        for r in document["results"]:
            if document["ranks"] < 2 or "skipped" in r:
                continue
            ndim = len(r["blocks_per_axis"])
            cells = [n * r["block_cells"] for n in r["blocks_per_axis"]]
            boundaries = [("periodic",) * 2 if periodic else ("outflow",) * 2 for periodic in r["periodic"]]
            geometry = CASE_GEOMETRY.get(r["case"], CHECK_GEOMETRY[ndim])
            if geometry == "2d-cylindrical":
                boundaries[0] = ("reflecting", "outflow")
            mesh = BlockMesh.uniform(geometry, [0.0] * ndim, [1.0] * ndim, cells, boundaries, r["block_cells"])
            cuts = np.concatenate([[0], np.cumsum([rank["blocks"] for rank in r["ranks"]])])
            components = exchange_components(ndim, mesh.geometry_code, r["materials"], r["strength"])
            faces = face_counts(mesh, cuts, len(cuts))
            model = sum(WORD * strip_values(mesh, axis, c) * f["faces"]
                        for axis, f in enumerate(faces) for c in components)
            rows.append({"case": r["case"], "block_cells": r["block_cells"], "ranks": document["ranks"],
                         "exchange_components": components,
                         "model_bytes_sent": model.tolist(),
                         "measured_bytes_sent": [rank["bytes_sent"] for rank in r["ranks"]],
                         "model_messages_sent": (sum(f["peers"] for f in faces)
                                                 + (len(components) - 1) * fill_peers(mesh, cuts)).tolist(),
                         "measured_messages_sent": [rank["messages_sent"] for rank in r["ranks"]],
                         "model_allreduces": reductions_per_step(ndim, r["strength"]),
                         "measured_allreduces": [rank["allreduces"] for rank in r["ranks"]]})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--measured", nargs="+", required=True, help="benchmarks/mpi_scaling.py --json documents")
    parser.add_argument("--steps", nargs="+", required=True, metavar="STEPS",
                        help="benchmarks/handoff_steps.py --json documents of the runs, in the order of --runs")
    parser.add_argument("--runs", nargs="+", choices=list(RUNS), default=list(RUNS),
                        help=f"the runs to project (default: {' '.join(RUNS)})")
    parser.add_argument("--latency", type=float, default=1.5e-6, help="alpha (s), default 1.5e-6")
    parser.add_argument("--link-bandwidth", type=float, default=12.5e9, help="beta_link (B/s), default 12.5e9")
    parser.add_argument("--ranks-per-node", type=int, default=64, help="default 64")
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    args = parser.parse_args()
    measured = [json.loads(Path(path).read_text()) for path in args.measured]
    if len(args.steps) != len(args.runs):
        raise SystemExit(f"--steps needs one document per run of --runs ({len(args.runs)})")
    steps = dict(zip(args.runs, (json.loads(Path(path).read_text()) for path in args.steps)))
    links = [d["pingpong"] for d in measured if d.get("pingpong")]
    if not links:
        raise SystemExit("no two-rank measurement with a ping-pong (the on-node bandwidth)")
    net = Interconnect(args.latency, args.link_bandwidth, args.ranks_per_node,
                       float(np.median([link["bandwidth_bytes_per_s"] for link in links])))
    report = {"interconnect": net.__dict__, "check": check_measured(measured), "runs": project(measured, steps, net)}
    if args.json:
        print(json.dumps(report, indent=2, default=float))
        return
    for row in report["check"]:
        print(f"check {row['case']} ({row['block_cells']}-cell blocks, {row['ranks']} ranks): bytes sent per step "
              f"{row['model_bytes_sent']} modelled, {row['measured_bytes_sent']} counted; messages "
              f"{row['model_messages_sent']} modelled, {row['measured_messages_sent']} counted")
    for name, run in report["runs"].items():
        print(f"{name}: {run['cell_updates']:.3g} cell-updates, c_cell {run['costs']['cell_update_s']:.3g} s")
        for mode in ("strong", "weak"):
            for row in run[mode]:
                cases = ", ".join(f"{outputs} {row[outputs]['efficiency']:.2f} ({row[outputs]['wall_s'] / 3600:.3g} h)"
                                  for outputs in OUTPUTS)
                print(f"  {mode:6s} {row['ranks']:5d} ranks {row['cells']:.3g} cells: E {cases}; overlapped "
                      f"{row['this-version']['efficiency_overlapped']:.2f}")


if __name__ == "__main__":
    main()
