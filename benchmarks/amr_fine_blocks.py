"""What keeps blocks fine: per refinement rule, why each block of the two finest levels stays there.

Runs the hydro stage of a config (default configs/reference/case8c.yaml) with the adaptive
mesh (a step per level unless ``--time-stepping global``) and stops at each of ``--times``
(s).  There it evaluates the refinement rule as a regrid would
(:func:`~impactpipe.hydro.amr.regrid.block_wants`, then the 2:1 balanced plan of
:func:`~impactpipe.hydro.amr.regrid.plan_leaves`) and sorts the blocks of the finest level L
and of level L - 1 by the first reason that holds them there:

- interface: the block's own interface indicator keeps its level (``interfaces``: at L where
  the block is active, at L - 1 where it is quiet);
- pressure jump, density jump: the block's own jump indicator is above half its threshold
  (a jump keeps the finest level only);
- neighbour's jump: a jump in a neighbouring block (the buffer around shocks, ``buffer``);
- siblings: the block may coarsen but a block of its sibling group may not (or is not a leaf);
- balance: the whole group may coarsen but its parent would be two levels from a neighbour;
- refines, coarsens: the regrid would refine or coarsen it now.

Beside those counts it prints the run's largest |p| (the scale of ``pressure_floor``), the
largest |p| and speed on the mesh now, and, for the blocks held by an active interface, how
many have their largest |p| and speed above 1e-3, 1e-2 and 1e-1 of the mesh's current
largest (what an activity threshold relative to now rather than to the run would keep).
At the end it sums over the stopping times the blocks of each reason and level weighted by
their level's substeps per root step (2^level): the share of the cell-updates per root step
that each reason holds, an estimate of what a rule freeing those blocks would save (one
level coarser halves their share, and the blocks it frees may still be held by balance).

    NUMBA_NUM_THREADS=1 python benchmarks/amr_fine_blocks.py [--cells-per-projectile-radius 10]
        [--times 2 6 12] [--interfaces all|active|off] [--override KEY=VALUE ...] [--json]

``--override hydro.refinement.pressure_floor=0.01`` (repeatable, values read as YAML) sets
any config key, so candidate rules are compared on the same scene.  The run's last step
before each stop is shortened to end there, so it is not the uninterrupted run step for step
(case 8c at 10 cells: 471 root steps to 12 s with twelve stops, 468 without).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from impactpipe.hydro.amr.criteria import IND_DENSITY, IND_MAX_PRESSURE, IND_MAX_SPEED, IND_PRESSURE
from impactpipe.hydro.amr.regrid import block_wants, plan_leaves
from impactpipe.hydro.mesh.boundary import fill_state_ghosts
from amr_reference import _simulation, overrides_of

REASONS = ("interface", "pressure jump", "density jump", "neighbour's jump", "siblings", "balance", "refines",
           "coarsens")
FRACTIONS = (1e-3, 1e-2, 1e-1)


def classify(sim) -> dict:
    """The reasons of the module docstring for the blocks of the two finest levels of ``sim`` now."""
    mesh, rule = sim.mesh, sim.refinement
    for axis in range(mesh.ndim):
        fill_state_ghosts(sim.state, mesh, axis)
    w = block_wants(mesh, sim.state, sim.eos, sim.shear_modulus, sim.tensile_strength, rule, sim.peak_pressure,
                    sim.grady_kipp, sim.porosity, sim.regrid_reach())
    level, finest = mesh.block_level, mesh.max_level
    refine = ((w.want > level) | (w.boxes > level)) & (level < finest)
    coarsen = (w.keep < level) & (w.boxes < level) & (level > 0)
    plan = plan_leaves(mesh, refine, coarsen)
    merged = np.zeros(mesh.nblocks, dtype=bool)
    if plan is not None and len(plan["parents"]):
        merged[plan["parents"][:, 1]] = True
    groups: dict[tuple, list[int]] = {}
    for b in range(mesh.nblocks):
        groups.setdefault((int(level[b]),) + tuple(int(i) >> 1 for i in mesh.block_index[b]), []).append(b)
    full_group = 2 ** mesh.ndim
    ind = w.indicators
    half_p = 0.5 * (rule.pressure_jump if rule.pressure_jump is not None else np.inf)
    half_rho = 0.5 * (rule.density_jump if rule.density_jump is not None else np.inf)
    now_p = float(ind[:, IND_MAX_PRESSURE].max(initial=0.0))
    now_v = float(ind[:, IND_MAX_SPEED].max(initial=0.0))
    out = {"blocks_per_level": np.bincount(level, minlength=finest + 1).tolist(), "peak_pressure": w.peak_pressure,
           "pressure_now": now_p, "speed_now": now_v, "levels": {}}
    for lv in (finest, finest - 1):
        counts = dict.fromkeys(REASONS, 0)
        active = {f: [0, 0] for f in FRACTIONS}
        for b in np.nonzero(level == lv)[0]:
            if refine[b]:
                reason = "refines"
            elif merged[b]:
                reason = "coarsens"
            elif w.face_keep[b] >= lv:
                reason = "interface"
                if w.active[b] and w.face_keep[b] == finest:
                    for f in FRACTIONS:
                        active[f][0] += ind[b, IND_MAX_PRESSURE] > f * now_p
                        active[f][1] += ind[b, IND_MAX_SPEED] > f * now_v
            elif ind[b, IND_PRESSURE] > half_p and w.shock_keep[b] >= lv:
                reason = "pressure jump"
            elif ind[b, IND_DENSITY] > half_rho and w.shock_keep[b] >= lv:
                reason = "density jump"
            elif w.keep[b] >= lv:
                reason = "neighbour's jump"
            else:
                group = groups[(int(lv),) + tuple(int(i) >> 1 for i in mesh.block_index[b])]
                reason = "balance" if len(group) == full_group and coarsen[group].all() else "siblings"
            counts[reason] += 1
        out["levels"][int(lv)] = {"reasons": counts,
                                  "active_interface_above": {f"{f:g}": {"pressure": int(a[0]), "speed": int(a[1])}
                                                             for f, a in active.items()}}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="configs/reference/case8c.yaml")
    parser.add_argument("--cells-per-projectile-radius", type=int, default=None)
    parser.add_argument("--time-stepping", choices=["global", "per_level"], default="per_level")
    parser.add_argument("--interfaces", choices=["all", "active", "off"], default="active")
    parser.add_argument("--times", type=float, nargs="+", default=[2.0, 6.0, 12.0], help="s, increasing")
    parser.add_argument("--override", action="append", default=[], help="KEY=VALUE (dotted config key, YAML value)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    sim, _ = _simulation(args.config, None, args.time_stepping, args.cells_per_projectile_radius, args.interfaces,
                         overrides_of(args))
    results = {}
    for t in args.times:
        sim.run(t)
        results[t] = classify(sim) | {"cell_updates": int(sim.cell_updates), "steps": sim.step_count}
        if args.json:
            continue
        r = results[t]
        print(f"t = {t:g} s: {r['steps']} steps, {r['cell_updates']:.3e} cell-updates, blocks per level "
              f"{r['blocks_per_level']}; largest |p| of the run {r['peak_pressure']:.3e} Pa, now "
              f"{r['pressure_now']:.3e} Pa, speed now {r['speed_now']:.3e} m/s")
        for lv, entry in r["levels"].items():
            print(f"  level {lv}: " + ", ".join(f"{k} {v}" for k, v in entry["reasons"].items()))
            if lv == max(r["levels"]):
                print("    active interfaces with |p|, speed above a fraction of now's largest: " + ", ".join(
                    f"{f}: {a['pressure']}, {a['speed']}" for f, a in entry["active_interface_above"].items()))
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print("share of the cell-updates per root step, summed over the times: "
          + ", ".join(f"level {lv} {reason} {share:.1%}" for (lv, reason), share in weighted_shares(results).items()
                      if share > 0.0))


def weighted_shares(results: dict) -> dict:
    """{(level, reason): share} of the blocks' cell-updates per root step (2^level each), over all times."""
    total = 0.0
    shares: dict[tuple, float] = {}
    for r in results.values():
        total += sum(n * 2 ** lv for lv, n in enumerate(r["blocks_per_level"]))
        for lv, entry in r["levels"].items():
            for reason, n in entry["reasons"].items():
                shares[(lv, reason)] = shares.get((lv, reason), 0.0) + n * 2 ** lv
    return {key: value / total for key, value in shares.items()}


if __name__ == "__main__":
    main()
