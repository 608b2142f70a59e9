"""Projected strong and weak scaling of one hydro run over many MPI ranks, from measured costs.

The model follows what the code does in this version (:mod:`impactpipe.hydro.parallel`):

* Decomposition.  Rank r owns the contiguous range ``cuts[r] .. cuts[r + 1] - 1`` of the block
  order (x fastest, then y, then z), cut by :func:`~impactpipe.hydro.parallel.decomposition.owned_ranges`
  in whole blocks; here every block is given the same cost, so a rank owns
  W_r = floor or ceil(NB / P) blocks of B^d cells.  Its subdomain is a slab of the slowest
  axis (part of a plane once NB / P is below a plane of blocks), not a cube: its surface
  does not shrink with P the way a cube's would, and the model counts it block face by
  block face (:func:`face_counts`).
* Exchange.  Before every ghost fill along axis d, each block face whose neighbour another rank
  owns costs one strip each way: GHOST = 2 layers of B^(d-1) interior cells of c float64
  components, s = 8 GHOST B^(d-1) c bytes; one message per peer rank and axis.  A step fills
  the ghosts of the state once per axis (c = 3M + 4 + M NQ, M materials, NQ transported
  scalars per material: 0 without strength, NS + 2 with it, NS = 4 stress components in 2D and
  6 in 3D); with strength the serial code fills four more per axis (alpha, partial densities
  and momentum, c = 2M + 3; the stress, NS; the momentum, 3; the stress again, NS:
  :mod:`impactpipe.hydro.strength.model`), which the model counts as four more exchanges
  (:func:`exchange_components`).  The exchanges are blocking: nothing overlaps them.
* Reductions.  One Allreduce for the time step and one per sweep for the failure check:
  1 + d per step, each alpha ceil(log2 P) s.
* Outputs.  Before every snapshot and every LOG_INTERVAL-th step's log line (its peak pressure),
  every rank receives every block (Allgatherv of the whole padded state, S_tot bytes) and
  computes the thermodynamics of every cell.

Time of one step on P ranks (s), the slowest rank setting each phase:

    t_compute  = max_r W_r B^d c_cell
    t_exchange = sum over exchanges k and axes d of
                 max_r [ m_rd alpha + 2 f_rd s_kd c_pack + f_on_rd s_kd / beta_shm ]
                 + max_n f_off_nd s_kd / beta_link
    t_reduce   = (1 + d) alpha ceil(log2 P)

with f_rd the rank's block faces along d whose neighbour another rank owns (f_on_rd of them on
its own node, f_off_nd the node's faces to other nodes), m_rd its peers along d, c_cell (s)
the measured compute cost of a cell-update on one core, c_pack (s/B) the measured cost of
packing and unpacking a byte of strips, alpha (s) the latency, beta_shm (B/s) the on-node
bandwidth of one rank and beta_link (B/s) the bandwidth of one node's link, which all the
node's off-node strips share.  The latency and transfer terms (not c_pack) are what
overlapping the exchange with the interior's sweep could hide: t_step = t_compute + t_exchange
+ t_reduce without overlap, max(t_compute, t_network) + t_pack + t_reduce with it.  A run of
n steps with g = n_snap + n / LOG_INTERVAL gathers takes

    T_P = n t_step + g (S_tot / min(beta_link, beta_shm) + alpha ceil(log2 P) + N c_snap)

(N cells, c_snap (s) the thermodynamics of one cell of a snapshot; a ring Allgatherv moves
S_tot through each rank and each node's link once), one rank
T_1 = n N c_cell + g N c_snap, and the parallel efficiency is E = T_1 / (P T_P).  Strong
scaling keeps the mesh; weak scaling keeps N / P by refining the mesh.  The steps to hand-off
n grow with the cells per projectile radius as measured on two coarse uniform meshes
(:func:`step_growth`).  Two other ways of making the outputs, not the code of this version,
are projected beside it (:data:`OUTPUTS`, :func:`output_time`): a log line that reduces the
ranks' own peak pressures, and snapshots whose thermodynamics each rank computes over its own
blocks.  Not modelled: rank 0 writing the snapshots, the cost estimate's error in the cut of
an impact's blocks (void cells are cheaper), and memory: every rank holds the whole state.

    python benchmarks/scaling_model.py --measured ONE.json TWO.json ONE_8.json TWO_8.json \\
        --steps STEPS_8C.json STEPS_OBLIQUE.json --json

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

from impactpipe.hydro.mesh.blocks import GHOST
from impactpipe.hydro.parallel.decomposition import owned_ranges, owners
from impactpipe.hydro.solver import LOG_INTERVAL

#: Bytes of one exchanged value (float64).
WORD = 8
#: Stored deviatoric stress components per dimension (:func:`impactpipe.hydro.strength.update.stress_slots`).
STRESS_SLOTS = {2: 4, 3: 6}
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
    c_pack (s per byte sent or received), ``snapshot_s_per_cell`` c_snap (s per cell)."""

    cell_update_s: float
    pack_s_per_byte: float
    snapshot_s_per_cell: float


@dataclass(frozen=True)
class Mesh:
    """A uniform block mesh: ``blocks_per_axis`` (x, y[, z]), ``block_cells`` B, ``periodic`` per axis."""

    blocks_per_axis: tuple[int, ...]
    block_cells: int
    periodic: tuple[bool, ...]

    @property
    def ndim(self) -> int:
        return len(self.blocks_per_axis)

    @property
    def nblocks(self) -> int:
        return int(np.prod(self.blocks_per_axis))

    @property
    def cells(self) -> int:
        return self.nblocks * self.block_cells ** self.ndim

    def strip_values(self, components: int) -> int:
        """Values of one strip: GHOST B^(d-1) cells x ``components``."""
        return GHOST * self.block_cells ** (self.ndim - 1) * components

    def padded_state_bytes(self, components: int) -> int:
        """Bytes of the whole state with its ghosts, S_tot = 8 c NB (B + 2 GHOST)^d."""
        return WORD * components * self.nblocks * (self.block_cells + 2 * GHOST) ** self.ndim


def exchange_components(ndim: int, nmat: int, strength: bool) -> list[int]:
    """Float64 components per cell of each exchange along one axis in one step: the state
    (3M + 4 + M NQ) and, with strength, the four fills of :mod:`impactpipe.hydro.strength.model`
    (2M + 3, NS, 3, NS)."""
    if not strength:
        return [3 * nmat + 4]
    ns = STRESS_SLOTS[ndim]
    return [3 * nmat + 4 + nmat * (ns + 2), 2 * nmat + 3, ns, 3, ns]


def cuts_for(mesh: Mesh, nranks: int) -> np.ndarray:
    """The cut points of ``nranks`` ranks over the block order with one cost per block."""
    return owned_ranges(np.ones(mesh.nblocks, dtype=np.int64), nranks)


def face_counts(mesh: Mesh, cuts: np.ndarray, ranks_per_node: int) -> list[dict]:
    """Per axis d: ``faces`` (P,) f_rd, ``on_node`` (P,) f_on_rd, ``peers`` (P,) m_rd and
    ``node_off`` (nodes,) f_off_nd (block faces along d whose neighbour another rank owns; a
    node's faces to ranks on other nodes, nodes of ``ranks_per_node`` consecutive ranks)."""
    nranks = len(cuts) - 1
    grid = owners(cuts).reshape(mesh.blocks_per_axis[::-1])
    node_of = np.arange(nranks) // ranks_per_node
    out = []
    for d in range(mesh.ndim):
        along = mesh.ndim - 1 - d
        if mesh.periodic[d]:
            a, b = grid, np.roll(grid, -1, axis=along)
        else:
            n = grid.shape[along]
            a, b = np.take(grid, range(n - 1), axis=along), np.take(grid, range(1, n), axis=along)
        cross = a != b
        a, b = a[cross], b[cross]
        off = node_of[a] != node_of[b]
        pairs = np.unique(np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1), axis=0).reshape(-1, 2)
        out.append({
            "faces": np.bincount(a, minlength=nranks) + np.bincount(b, minlength=nranks),
            "on_node": np.bincount(a[~off], minlength=nranks) + np.bincount(b[~off], minlength=nranks),
            "peers": np.bincount(pairs.ravel(), minlength=nranks),
            "node_off": (np.bincount(node_of[a[off]], minlength=node_of[-1] + 1)
                         + np.bincount(node_of[b[off]], minlength=node_of[-1] + 1)),
        })
    return out


def step_time(mesh: Mesh, components: list[int], costs: Costs, net: Interconnect, cuts: np.ndarray) -> dict:
    """The terms of one step's time (s) on the ranks of ``cuts`` (module docstring):
    ``compute``, ``pack``, ``network`` (latency and transfer of the strips), ``reduce``."""
    nranks = len(cuts) - 1
    compute = int(np.diff(cuts).max()) * mesh.block_cells ** mesh.ndim * costs.cell_update_s
    pack = network = 0.0
    if nranks > 1:
        for faces in face_counts(mesh, cuts, net.ranks_per_node):
            for c in components:
                strip = WORD * mesh.strip_values(c)
                packing = 2 * faces["faces"] * strip * costs.pack_s_per_byte
                moving = faces["peers"] * net.latency_s + faces["on_node"] * strip / net.shm_bytes_per_s
                slowest = int(np.argmax(packing + moving))
                pack += packing[slowest]
                network += moving[slowest] + faces["node_off"].max() * strip / net.link_bytes_per_s
    reduce = (1 + mesh.ndim) * net.latency_s * math.ceil(math.log2(nranks)) if nranks > 1 else 0.0
    return {"compute": compute, "pack": pack, "network": network, "reduce": reduce}


#: How a run's outputs are made: this version (every snapshot and every LOG_INTERVAL-th log line
#: gathers every block, and every rank computes the thermodynamics of every cell); "local-log"
#: (the log line reduces the ranks' own peak pressures); "distributed" (besides, each rank computes
#: a snapshot's thermodynamics over its own blocks before the gather).  Only the first is the code.
OUTPUTS = ("this-version", "local-log", "distributed")


def output_time(mesh: Mesh, state_components: int, costs: Costs, net: Interconnect, cuts: np.ndarray,
                steps: float, snapshots: int, outputs: str) -> float:
    """Time (s) of a run's outputs on the ranks of ``cuts``: ``snapshots`` snapshots and
    steps / LOG_INTERVAL log lines, made as ``outputs`` (:data:`OUTPUTS`) says.

    A gather costs S_tot / min(beta_link, beta_shm) + alpha ceil(log2 P) (none on one rank), the
    thermodynamics N c_snap on every rank, or max_r W_r B^d c_snap where each rank does its own.
    """
    nranks = len(cuts) - 1
    logs = steps / LOG_INTERVAL
    reduce = net.latency_s * math.ceil(math.log2(nranks)) if nranks > 1 else 0.0
    gather = mesh.padded_state_bytes(state_components) / min(net.link_bytes_per_s, net.shm_bytes_per_s) + reduce
    if nranks == 1:
        gather = 0.0
    whole = mesh.cells * costs.snapshot_s_per_cell
    own = int(np.diff(cuts).max()) * mesh.block_cells ** mesh.ndim * costs.snapshot_s_per_cell
    if outputs == "this-version":
        return (snapshots + logs) * (gather + whole)
    log_lines = logs * (own + reduce)
    return log_lines + snapshots * (gather + (whole if outputs == "local-log" else own))


def run_time(mesh: Mesh, components: list[int], state_components: int, costs: Costs, net: Interconnect,
             nranks: int, steps: float, snapshots: int) -> dict:
    """Wall time (s) of ``steps`` steps and ``snapshots`` snapshots on ``nranks`` ranks, and the
    efficiency E = T_1 / (P T_P), per way of making the outputs (:data:`OUTPUTS`), without
    overlap of the exchange (``wall_s``, ``efficiency``) and with it (``*_overlapped``)."""
    cuts = cuts_for(mesh, nranks)
    t = step_time(mesh, components, costs, net, cuts)
    serial = (steps * mesh.cells * costs.cell_update_s
              + (snapshots + steps / LOG_INTERVAL) * mesh.cells * costs.snapshot_s_per_cell)
    plain = steps * (t["compute"] + t["pack"] + t["network"] + t["reduce"])
    overlapped = steps * (max(t["compute"], t["network"]) + t["pack"] + t["reduce"])
    row = {"ranks": nranks, "cells": mesh.cells, "blocks_per_rank": mesh.nblocks / nranks,
           "imbalance": int(np.diff(cuts).max()) * nranks / mesh.nblocks, "steps": steps, "step_terms_s": t,
           "state_bytes_per_rank": mesh.padded_state_bytes(state_components)}
    for outputs in OUTPUTS:
        extra = output_time(mesh, state_components, costs, net, cuts, steps, snapshots, outputs)
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


def run_mesh(config_path: Path, overrides: dict) -> tuple[Mesh, dict]:
    """The uniform impact mesh of a config with ``overrides`` (pipeline.derived), and the derived values."""
    from impactpipe.pipeline import derived, load_config

    config = load_config(config_path, overrides=overrides)
    values = derived.derive(config)
    domain = values["domain"]
    block = domain["block_cells"]
    periodic = tuple(pair[0] == "periodic" for pair in domain["boundaries"])
    mesh = Mesh(tuple(n // block for n in domain["cells"]), block, periodic)
    values["snapshots"] = len(derived.snapshot_times(config, float(values["end_time"])))
    values["strength_on"] = any(choice["enabled"] for choice in values["strength"].values())
    return mesh, values


def costs_from(measured: list[dict], case: str, block_cells: int) -> Costs:
    """c_cell and c_snap from the one-rank measurements of ``case`` on ``block_cells`` blocks,
    c_pack from the two-rank ones (2d-cyl-tillotson's for a 2D case the ranks skipped): the
    medians over the documents and ranks."""

    def results(ranks: int, name: str) -> list[dict]:
        return [r for document in measured if document["ranks"] == ranks for r in document["results"]
                if r["case"] == name and r["block_cells"] == block_cells and "skipped" not in r]

    one = results(1, case)
    if not one:
        raise ValueError(f"no one-rank measurement of {case} on {block_cells}-cell blocks")
    two = results(2, case) or results(2, "2d-cyl-tillotson" if case.startswith("2d") else case)
    if not two:
        raise ValueError(f"no two-rank measurement for the packing cost of {case}")
    pack = [(rank["exchange_s"] - rank["wait_s"]) / (rank["bytes_sent"] + rank["bytes_received"])
            for r in two for rank in r["ranks"]]
    return Costs(float(np.median([r["ranks"][0]["compute_s_per_cell_update"] for r in one])), float(np.median(pack)),
                 float(np.median([r["ranks"][0]["snapshot_s"] / r["cells"] for r in one])))


def project(measured: list[dict], steps: dict[str, dict], net: Interconnect) -> dict:
    """Strong and weak scaling of every run of RUNS at RANKS (weak: N / P of the run at 256 ranks)."""
    out = {}
    for name, (config_path, overrides, case) in RUNS.items():
        mesh, values = run_mesh(config_path, overrides)
        n = overrides["hydro.cells_per_projectile_radius"]
        components = exchange_components(mesh.ndim, IMPACT_MATERIALS, values["strength_on"])
        costs = costs_from(measured, case, mesh.block_cells)
        state_components = components[0]
        rows = {"strong": [], "weak": []}
        for mode in rows:
            for nranks in RANKS:
                resolution = n * (nranks / 256) ** (1 / mesh.ndim) if mode == "weak" else n
                grown = mesh if mode == "strong" else run_mesh(
                    config_path, {**overrides, "hydro.cells_per_projectile_radius": resolution})[0]
                count = handoff_steps(steps[name], resolution)
                row = run_time(grown, components, state_components, costs, net, nranks, count, values["snapshots"])
                rows[mode].append({"cells_per_projectile_radius": resolution, **row})
        out[name] = {"config": str(config_path.relative_to(CONFIGS.parent)), "overrides": overrides,
                     "cost_case": case, "costs": costs.__dict__, "exchange_components": components,
                     "end_time": values["end_time"], "blocks_per_axis": mesh.blocks_per_axis,
                     "block_cells": mesh.block_cells, "step_growth": step_growth(steps[name]),
                     "cell_updates": mesh.cells * handoff_steps(steps[name], n),
                     **rows}
    return out


def check_measured(measured: list[dict]) -> list[dict]:
    """The model's bytes per step and rank for every measured multi-rank case (its own cuts and
    mesh), beside the counted bytes: the surface formula against the code."""
    rows = []
    for document in measured:
        for r in document["results"]:
            if document["ranks"] < 2 or "skipped" in r:
                continue
            mesh = Mesh(tuple(r["blocks_per_axis"]), r["block_cells"], tuple(r["periodic"]))
            cuts = np.concatenate([[0], np.cumsum([rank["blocks"] for rank in r["ranks"]])])
            faces = face_counts(mesh, cuts, len(cuts))
            model = sum(WORD * mesh.strip_values(r["components"]) * f["faces"] for f in faces)
            rows.append({"case": r["case"], "block_cells": r["block_cells"], "ranks": document["ranks"],
                         "model_bytes_sent": model.tolist(),
                         "measured_bytes_sent": [rank["bytes_sent"] for rank in r["ranks"]]})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--measured", nargs="+", required=True, help="benchmarks/mpi_scaling.py --json documents")
    parser.add_argument("--steps", nargs=2, required=True, metavar=("CASE8C", "OBLIQUE45"),
                        help="benchmarks/handoff_steps.py --json documents of the two configs")
    parser.add_argument("--latency", type=float, default=1.5e-6, help="alpha (s), default 1.5e-6")
    parser.add_argument("--link-bandwidth", type=float, default=12.5e9, help="beta_link (B/s), default 12.5e9")
    parser.add_argument("--ranks-per-node", type=int, default=64, help="default 64")
    parser.add_argument("--json", action="store_true", help="print one JSON document")
    args = parser.parse_args()
    measured = [json.loads(Path(path).read_text()) for path in args.measured]
    steps = dict(zip(RUNS, (json.loads(Path(path).read_text()) for path in args.steps)))
    links = [d["pingpong"] for d in measured if d.get("pingpong")]
    if not links:
        raise SystemExit("no two-rank measurement with a ping-pong (the on-node bandwidth)")
    net = Interconnect(args.latency, args.link_bandwidth, args.ranks_per_node,
                       float(np.median([link["bandwidth_bytes_per_s"] for link in links])))
    report = {"interconnect": net.__dict__, "check": check_measured(measured), "runs": project(measured, steps, net)}
    if args.json:
        print(json.dumps(report, indent=2, default=float))
        return
    for name, run in report["runs"].items():
        print(f"{name}: {run['cell_updates']:.3g} cell-updates, c_cell {run['costs']['cell_update_s']:.3g} s")
        for mode in ("strong", "weak"):
            for row in run[mode]:
                cases = ", ".join(f"{outputs} {row[outputs]['efficiency']:.2f} ({row[outputs]['wall_s'] / 3600:.3g} h)"
                                  for outputs in OUTPUTS)
                print(f"  {mode:6s} {row['ranks']:5d} ranks {row['cells']:.3g} cells: E {cases}; distributed and "
                      f"overlapped {row['distributed']['efficiency_overlapped']:.2f}")


if __name__ == "__main__":
    main()
