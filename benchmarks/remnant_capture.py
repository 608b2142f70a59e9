"""Which hand-off mass ends in the largest remnant: the N-body stage's share of M_lr/M_T.

Reads the finished runs of an ``impactpipe convergence`` directory and, for every rung of its
ladder (the run directories ``KEY=VALUE_seed=N-HASH``, one ladder per directory; with
``--handoff-times`` ``KEY=VALUE_time=T_seed=N-HASH``, one row per value and time, labelled
``VALUE/T``), compares each hand-off particle's state with its fate:

    impactpipe convergence configs/reference/case9a.yaml --workers 1 \\
        --vary hydro.cells_per_projectile_radius=5,10,20,40 --seeds 5 --out runs/case9a-convergence
    python benchmarks/remnant_capture.py runs/case9a-convergence

Per particle i (mass m_i, kg; hand-off position and velocity, SI): the ratio
s_i = |v_i - V| / v_esc,i of its speed in the centre-of-mass frame to its escape speed from all
the other particles, with the exact potential (:func:`impactpipe.nbody.diagnostics.
escape_speed_ratio`): s_i < 1 is gravitationally bound at hand-off, collisions aside.  Its
fate comes from the N-body result: kept (a member of a body still in the simulation at the
end, which under merging is the largest remnant and what is bound to it) or escaped.  An
escaped body is "mixed" if it holds a hand-off particle with s >= 1 (bound mass carried off by
merging with unbound mass), "bound-only" otherwise.

Printed per rung, as fractions of the hand-off mass averaged over the rung's seeds: the bound
mass, the kept mass (with its standard error over seeds), the kept part of the bound mass, the
bound mass that left in mixed and in bound-only bodies, and the kept fraction of the mass in
bins of s; then the state of the bound mass at hand-off, in the centre-of-mass frame of all
the particles (position X, velocity V): its kinetic energy K_b = sum_bound m_i |v_i - V|^2 / 2
(J) and its mass-weighted mean radial speed <v_r> = sum_bound m_i (v_i - V).(x_i - X) /
|x_i - X| / sum_bound m_i (m/s; positive: the bound mass is moving apart).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import h5py
import numpy as np

from impactpipe.nbody.diagnostics import escape_speed_ratio

#: Bins of |v - V| / v_esc at hand-off.
SPEED_BINS = np.array([0.0, 0.3, 0.6, 0.8, 1.0, 1.25, 1.5, 2.0, 4.0, np.inf])


def bound_motion(position, velocity, mass, bound):
    """(K_b (J), <v_r> (m/s)) of the bound particles, in the centre-of-mass frame of all
    particles (module docstring); positions (N, 3) m, velocities (N, 3) m/s, masses (N,) kg."""
    total = mass.sum()
    rel_x = position - (mass[:, None] * position).sum(axis=0) / total
    rel_v = velocity - (mass[:, None] * velocity).sum(axis=0) / total
    m = mass[bound]
    kinetic = 0.5 * float((m * (rel_v[bound] ** 2).sum(axis=1)).sum())
    distance = np.linalg.norm(rel_x[bound], axis=1)
    radial = (rel_v[bound] * rel_x[bound]).sum(axis=1) / np.where(distance > 0.0, distance, 1.0)
    return kinetic, float((m * radial).sum() / m.sum()) if m.sum() > 0.0 else float("nan")


def particle_fates(run: Path):
    """(mass (kg), speed / escape speed, kept, bound mass carried off by mixed bodies (kg),
    bound mass escaped in bound-only bodies (kg), (K_b (J), <v_r> (m/s)) of
    :func:`bound_motion`) of one finished run directory."""
    with h5py.File(run / "handoff.h5") as f:
        p = f["particles"]
        mass, ids = p["mass"][:], p["id"][:]
        position, velocity = p["position"][:], p["velocity"][:]
        ratio = escape_speed_ratio(position, velocity, mass)
    with h5py.File(run / "nbody.h5") as f:
        kept = np.isin(ids, f["members"][:])
        members, offsets = f["escaped_members"][:], f["escaped_members_offset"][:]
    index = {int(i): k for k, i in enumerate(ids)}
    bound = ratio < 1.0
    mixed = alone = 0.0
    for b in range(len(offsets) - 1):
        k = np.array([index[int(i)] for i in members[offsets[b]:offsets[b + 1]]])
        carried = float(mass[k][bound[k]].sum())
        if bound[k].all():
            alone += carried
        else:
            mixed += carried
    return mass, ratio, kept, mixed, alone, bound_motion(position, velocity, mass, bound)


def rung_table(directory: Path) -> str:
    """The per-rung table of the module docstring for the runs under ``directory``/runs."""
    rungs: dict[tuple[float, ...], list] = {}
    for run in sorted((directory / "runs").iterdir()):
        found = re.match(r"(.+?)_seed=\d+[_-]", run.name)
        values = tuple(float(v) for v in re.findall(r"=([0-9.eE+-]+)(?=_|$)", found.group(1))) if found else ()
        if values and (run / "nbody.h5").exists():
            rungs.setdefault(values, []).append(particle_fates(run))
    nbins = len(SPEED_BINS) - 1
    lines = ["rung   seeds  bound  kept (sem)       kept of bound  carried off (mixed / bound-only)"
             "  K_b (J)    <v_r> (m/s)"
             "  kept fraction per bin of |v - V| / v_esc: " + " ".join(f"{b:g}" for b in SPEED_BINS[1:-1])]
    for values, runs in sorted(rungs.items()):
        rows = []
        in_bin = np.zeros(nbins)
        kept_in_bin = np.zeros(nbins)
        for mass, ratio, kept, mixed, alone, (kinetic, radial) in runs:
            total = mass.sum()
            bound = ratio < 1.0
            rows.append([(mass * bound).sum() / total, (mass * kept).sum() / total,
                         (mass * kept * bound).sum() / total, mixed / total, alone / total, kinetic, radial])
            which = np.digitize(ratio, SPEED_BINS) - 1
            in_bin += np.bincount(which, mass, nbins) / total
            kept_in_bin += np.bincount(which, mass * kept, nbins) / total
        rows = np.array(rows)
        mean = rows.mean(axis=0)
        sem = rows[:, 1].std(ddof=1) / np.sqrt(len(rows)) if len(rows) > 1 else float("nan")
        share = np.divide(kept_in_bin, in_bin, out=np.full(nbins, np.nan), where=in_bin > 0)
        label = "/".join(f"{v:g}" for v in values)
        lines.append(f"{label:>5s}  {len(runs):5d}  {mean[0]:.3f}  {mean[1]:.3f} ({sem:.3f})  {mean[2]:.3f}"
                     f"          {mean[3]:.3f} / {mean[4]:.3f}                    "
                     f"{mean[5]:.3e}  {mean[6]:5.2f}        "
                     + " ".join(f"{v:.2f}" for v in share))
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("directory", type=Path, nargs="+", help="convergence or sweep output directories")
    args = parser.parse_args()
    for directory in args.directory:
        print(f"== {directory}")
        print(rung_table(directory))


if __name__ == "__main__":
    main()
