"""Where an impact's kinetic energy goes: by region, by time window and by operation of the step.

Runs the hydro stage of a 2d-cylindrical impact config (default configs/reference/case9a.yaml)
exactly as the pipeline builds it (:func:`impactpipe.pipeline.adapters.hydro.build_simulation`),
at ``--cells`` cells per projectile radius, to its end time (the hand-off), and measures the
kinetic and internal energy on the mesh before and after every operation of every step
through :attr:`impactpipe.hydro.solver.Simulation.observer`:

    python benchmarks/energy_budget.py --cells 10 --out runs/energy_budget/case9a_10.json
    python benchmarks/energy_budget.py --table runs/energy_budget/case9a_{5,10,20,40}.json

Energies (J), per cell, split between the materials k of the cell by mass share
w_k = alpha_k rho_k / rho:

- kinetic K_k = w_k |m|^2 / (2 rho) V (m the momentum density, V the cell volume);
- internal U_k = (alpha_k rho_k e_k + w_k (E - |m|^2 / (2 rho) - sum_j alpha_j rho_j e_j)) V, so
  that sum_k (K_k + U_k) = E V (after a regrid the materials' internal energies and E - K
  differ until the next sweep reconciles them);
- heat H_k = U_k - alpha_k rho_k V e_cold(max(rho_k, rho0_k)), the internal energy above the
  cold compression curve of the Tillotson EOS (:func:`impactpipe.hydro.eos.tillotson.
  tillotson_cold_energy`; zero below rho0, where a strengthless material opens void rather
  than store tension).  A reversible compression changes U but hardly H; dissipation, physical
  (shocks) or numerical, raises H.

Regions (cell centres in the r-z plane; target centred at the origin, radius R_T; impact point
(0, R_T); R_P the projectile radius; d the distance from the impact point, R the distance from
the target's centre):

- ``projectile``: all projectile material (material 1), wherever it is;
- ``near field``: target material (material 0) with R <= R_T and d < NEAR_FIELD * R_P;
- ``wall+curtain``: target material outside the near field that is above the original surface
  (R > R_T: the ejecta curtain, the rim) or in the band WALL_BAND * R_P below it on the impact
  hemisphere (z > 0, R > R_T - WALL_BAND R_P: where the crater wall and the excavation flow
  run along the surface);
- ``far field``: the rest of the target material (R <= R_T, deeper or on the far hemisphere).

Regions are fixed in space, so an operation's change of a region's energy includes what the
flow carries across the region's edge; the mesh totals have no such term.

Operations of a step (:meth:`Simulation.step`): ``regrid`` (refine / coarsen, every
``refinement.interval`` steps), ``sweep r`` and ``sweep z`` (the directional sweeps, floors and
void cleanup included), ``reflux r`` / ``reflux z`` (coarse cells beside finer blocks take the
fine fluxes), ``sources`` (strength and gravity, absent in a strengthless scene without
gravity) and ``ghosts`` (ghost filling; must change nothing on the interior, a check).  For
each sweep the cells are also split by the sweep kernel's reconstruction rule
(:data:`impactpipe.hydro.scheme.pencil_layout.PHI_SECOND_ORDER`), evaluated on the state the
sweep starts from:

- ``bulk``: the cell and its two neighbours along the sweep each filled to PHI_SECOND_ORDER or
  more by one material: the second-order MUSCL-Hancock path (where the positivity fallback
  may still drop a face to first order, counted as ``first_order_fallback``);
- ``surface``: one of the three filled below PHI_SECOND_ORDER by all materials together (free
  surfaces, opened cracks, spray): first order, and the void closure and relaxation, the
  small-cell limits and the cleanups act there;
- ``mixed``: the rest: full cells where two materials meet (the projectile-target interface),
  first order with the mixed-cell volume closure.

The classes exchange energy across their common edge during a sweep as the regions do, so the
sweep's dissipation is measured locally: before each sweep every material's heat density is
put into the transported scalars (:func:`load_heat`; the sweep carries them with the
material's mass flux at the donor cell's specific heat), and after it the heat a cell holds
above what was carried in is the heat ``produced`` there (J), summed by class and region.  It
is transport-free, sums to the sweep's change of the mesh's heat, and counts dissipation
(shock heating, physical or numerical) as positive; the thermal pressure of hot expanding
material (the Gruneisen term, large in the first second) does work and counts as negative.
``class_mass`` is the mean mass (kg) of each class and region over the window's sweeps.  The floors' energy amounts (``floor_amounts`` of the solver) and the energy
leaving through the domain boundary are recorded per operation.

The history also gives the target material's mass and kinetic energy by the fill of its cell
(sum_k alpha_k, bins FILL_EDGES): how much of the target the first-order rule for partly void
cells covers.

The heat rides in the state's transported scalars (zero damage slot included), so the run is
bit for bit the pipeline's; scenes with strength, which use those scalars, are refused.

Time windows: the step's start time in [0, 0.5), [0.5, 3), [3, end) s (``--windows``).  The
output JSON holds the region totals at ``--times`` and at each window edge, and per window and
operation the changes of every total.  A partial JSON is written at every window edge, so a
long run that is stopped leaves its finished windows.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numba
import numpy as np
from numba import njit

from impactpipe.hydro.amr.transfer import allocate_face_flux
from impactpipe.hydro.eos import TILLOTSON
from impactpipe.hydro.eos.tillotson import tillotson_cold_energy
from impactpipe.hydro.mesh.blocks import GHOST
from impactpipe.hydro.scheme.pencil_layout import (
    AMOUNT_NAMES,
    BND_ENERGY,
    FLOOR_NAMES,
    PHI_SECOND_ORDER,
    allocate_scratch,
)
from impactpipe.pipeline.adapters.hydro import build_simulation
from impactpipe.pipeline.config import load_config
from impactpipe.pipeline.convergence import richardson
from impactpipe.pipeline.derived import derive, snapshot_times

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "reference" / "case9a.yaml"
REGIONS = ("projectile", "near field", "wall+curtain", "far field")
QUANTITIES = ("mass", "kinetic", "internal", "heat")
CLASSES = ("bulk", "mixed", "surface")
#: Radius of the near field about the impact point, in projectile radii.
NEAR_FIELD = 4.0
#: Depth of the crater-wall band below the original surface, in projectile radii.
WALL_BAND = 2.0
WINDOWS = (0.5, 3.0)
TIMES = (0.1, 0.25, 0.5, 1.0, 2.0, 3.0, 5.0, 10.0, 20.0)
#: Edges of the fill bins of the history's ``fill`` (the last is the sweep's second-order threshold).
FILL_EDGES = (0.5, 0.9, 0.99, PHI_SECOND_ORDER)
#: Transported scalars per material that carry the heat through the sweeps (heat, damage slot).
HEAT_COLUMNS = 2
OPERATIONS = ("regrid", "ghosts", "sweep r", "sweep z", "reflux r", "reflux z", "sources")
AXIS_NAMES = "rz"


@njit(cache=True)
def tally(alpha, arho, arhoe, mom, energy, block_lo, block_dx, target_radius, projectile_radius, eos_kind,
          eos_params, rho0, cls, class_mode, class_axis, arhoq, by_region, by_class, produced, inside):
    """Add the cells' energies into ``by_region[4, 4]``, ``by_class[3, 4, 4]``, ``produced[3, 4]``, ``inside[3]``.

    2d-cylindrical state arrays ``(NB, C, NX, NY, 1)`` with ghosts; ``by_region[region, q]``
    with q = mass (kg), kinetic, internal, heat (J) (module docstring); ``by_class[c, region,
    q]`` the same by sweep class c (0 bulk, 1 mixed, 2 surface) of ``cls[NB, NX, NY]``, which
    ``class_mode`` 1 first computes along ``class_axis`` (ghosts filled along it), 2 uses as
    is and 0 skips; with ``class_mode`` 2, ``produced[c, region]`` the heat (J) above what the
    sweep carried in with the mass, sum_k (H_k - arhoq[k HEAT_COLUMNS] V) (:func:`load_heat`);
    ``inside`` the mass (kg), axial momentum (kg m/s) and kinetic energy (J) of all material
    within the target radius.
    """
    nb, nmat, nx, ny, _ = alpha.shape
    g = GHOST
    near2 = (NEAR_FIELD * projectile_radius) ** 2
    band_r = target_radius - WALL_BAND * projectile_radius
    for b in range(nb):
        dr = block_dx[b, 0]
        dz = block_dx[b, 1]
        for i in range(g, nx - g):
            r_lo = block_lo[b, 0] + (i - g) * dr
            r = r_lo + 0.5 * dr
            vol = math.pi * ((r_lo + dr) ** 2 - r_lo ** 2) * dz
            for j in range(g, ny - g):
                z = block_lo[b, 1] + (j - g + 0.5) * dz
                if class_mode == 1:
                    c = 0
                    for s in range(-1, 2):
                        ii = i + s if class_axis == 0 else i
                        jj = j + s if class_axis == 1 else j
                        single = False
                        phi = 0.0
                        for k in range(nmat):
                            phi += alpha[b, k, ii, jj, 0]
                            if alpha[b, k, ii, jj, 0] >= PHI_SECOND_ORDER:
                                single = True
                        if phi < PHI_SECOND_ORDER:
                            c = 2
                        elif not single and c == 0:
                            c = 1
                    cls[b, i, j] = c
                rho = 0.0
                esum = 0.0
                for k in range(nmat):
                    rho += arho[b, k, i, j, 0]
                    esum += arhoe[b, k, i, j, 0]
                if rho <= 0.0:
                    continue
                m2 = mom[b, 0, i, j, 0] ** 2 + mom[b, 1, i, j, 0] ** 2 + mom[b, 2, i, j, 0] ** 2
                kin = 0.5 * m2 / rho
                resid = energy[b, 0, i, j, 0] - kin - esum
                big_r = math.sqrt(r * r + z * z)
                if big_r < target_radius:
                    inside[0] += rho * vol
                    inside[1] += mom[b, 1, i, j, 0] * vol
                    inside[2] += kin * vol
                near = r * r + (z - target_radius) ** 2 < near2 and big_r <= target_radius
                for k in range(nmat):
                    ar = arho[b, k, i, j, 0]
                    if ar <= 0.0:
                        continue
                    w = ar / rho
                    u = (arhoe[b, k, i, j, 0] + w * resid) * vol
                    cold = 0.0
                    if eos_kind[k] == TILLOTSON and alpha[b, k, i, j, 0] > 0.0:
                        rk = max(ar / alpha[b, k, i, j, 0], rho0[k])
                        cold = tillotson_cold_energy(eos_params[k], rk)
                    if k == 1:
                        region = 0
                    elif near:
                        region = 1
                    elif big_r > target_radius or (z > 0.0 and big_r > band_r):
                        region = 2
                    else:
                        region = 3
                    values = (ar * vol, w * kin * vol, u, u - ar * vol * cold)
                    for q in range(4):
                        by_region[region, q] += values[q]
                        if class_mode != 0:
                            by_class[cls[b, i, j], region, q] += values[q]
                    if class_mode == 2:
                        produced[cls[b, i, j], region] += values[3] - arhoq[b, HEAT_COLUMNS * k, i, j, 0] * vol


@njit(cache=True)
def load_heat(alpha, arho, arhoe, mom, energy, eos_kind, eos_params, rho0, arhoq):
    """Put each material's heat density alpha_k rho_k h_k (J/m^3) into column HEAT_COLUMNS k of ``arhoq``.

    Every cell, ghosts included; h_k = (U_k - alpha_k rho_k V e_cold) / (alpha_k rho_k V) as in
    :func:`tally`.  Column HEAT_COLUMNS k + 1 (the slot the sweep reads as damage) stays 0, so
    the sweep's physics is unchanged and it carries the heat with each material's mass flux at
    the donor cell's h_k.
    """
    nb, nmat, nx, ny, _ = alpha.shape
    for b in range(nb):
        for i in range(nx):
            for j in range(ny):
                rho = 0.0
                esum = 0.0
                for k in range(nmat):
                    rho += arho[b, k, i, j, 0]
                    esum += arhoe[b, k, i, j, 0]
                for k in range(nmat):
                    arhoq[b, HEAT_COLUMNS * k, i, j, 0] = 0.0
                    arhoq[b, HEAT_COLUMNS * k + 1, i, j, 0] = 0.0
                if rho <= 0.0:
                    continue
                m2 = mom[b, 0, i, j, 0] ** 2 + mom[b, 1, i, j, 0] ** 2 + mom[b, 2, i, j, 0] ** 2
                resid = energy[b, 0, i, j, 0] - 0.5 * m2 / rho - esum
                for k in range(nmat):
                    ar = arho[b, k, i, j, 0]
                    if ar <= 0.0:
                        continue
                    cold = 0.0
                    if eos_kind[k] == TILLOTSON and alpha[b, k, i, j, 0] > 0.0:
                        cold = tillotson_cold_energy(eos_params[k], max(ar / alpha[b, k, i, j, 0], rho0[k]))
                    arhoq[b, HEAT_COLUMNS * k, i, j, 0] = arhoe[b, k, i, j, 0] + ar / rho * resid - ar * cold


class EnergyBudget:
    """The observer of module docstring: totals before and after every operation, summed per window."""

    def __init__(self, sim, target_radius: float, projectile_radius: float, windows: tuple[float, ...]):
        if sim.mesh.geometry != "2d-cylindrical":
            raise ValueError("the energy budget measures 2d-cylindrical impacts")
        self.sim = sim
        self.target_radius = target_radius
        self.projectile_radius = projectile_radius
        self.edges = (0.0,) + tuple(windows) + (math.inf,)
        if sim.strength is not None:
            raise ValueError("the energy budget carries its heat in the transported scalars, which strength uses")
        self.rho0 = np.array([sim.eos.params[k, 0] if sim.eos.kind[k] == TILLOTSON else 0.0
                              for k in range(sim.state.nmat)])
        st, mesh = sim.state, sim.mesh
        st.arhoq = np.zeros((mesh.nblocks, HEAT_COLUMNS * st.nmat) + mesh.padded_shape)
        sim._scratch = allocate_scratch(numba.config.NUMBA_NUM_THREADS, st.nmat, max(mesh.padded_shape), HEAT_COLUMNS)
        sim._face_flux = allocate_face_flux(mesh.nblocks if mesh.adaptive else 0, mesh.padded_shape, mesh.ndim,
                                            st.nmat, st.arhoq.shape[1])
        self.windows = [self._empty_window(lo, hi) for lo, hi in zip(self.edges[:-1], self.edges[1:])]
        self.cls = np.zeros((1, 1, 1), dtype=np.int64)
        self.last = self.measure()
        self.class_before = None
        self.window = 0
        self.steps = 0

    @staticmethod
    def _empty_window(lo: float, hi: float) -> dict:
        return {"start": lo, "end": hi, "steps": 0, "operations": {
            op: {"by_region": np.zeros((4, 4)), "by_class": np.zeros((3, 4, 4)), "produced": np.zeros((3, 4)),
                 "class_mass": np.zeros((3, 4)), "sweeps": 0, "amounts": np.zeros(len(AMOUNT_NAMES)),
                 "floors": np.zeros(len(FLOOR_NAMES), dtype=np.int64), "outflow_energy": 0.0}
            for op in OPERATIONS}}

    def measure(self, class_mode: int = 0, class_axis: int = -1) -> dict:
        """The totals of the current state: region sums, class sums (``class_mode``), counters."""
        sim, st = self.sim, self.sim.state
        by_region = np.zeros((4, 4))
        by_class = np.zeros((3, 4, 4))
        produced = np.zeros((3, 4))
        inside = np.zeros(3)
        if class_mode == 1 and self.cls.shape != st.alpha.shape[:1] + st.alpha.shape[2:4]:
            self.cls = np.zeros(st.alpha.shape[:1] + st.alpha.shape[2:4], dtype=np.int64)
        tally(st.alpha, st.arho, st.arhoe, st.momentum, st.energy, sim.mesh.block_lo, sim.mesh.block_dx,
              self.target_radius, self.projectile_radius, sim.eos.kind, sim.eos.params, self.rho0, self.cls,
              class_mode, class_axis, st.arhoq, by_region, by_class, produced, inside)
        return {"by_region": by_region, "by_class": by_class, "produced": produced, "inside": inside,
                "amounts": sim.amounts.sum(axis=0), "floors": sim.floors.sum(axis=0),
                "outflow_energy": float(sim.boundary[:, BND_ENERGY].sum())}

    def begin_step(self) -> None:
        """Choose the window of the step about to start (by its start time)."""
        while self.sim.time >= self.edges[self.window + 1] * (1.0 - 1e-12):
            self.window += 1
        self.windows[self.window]["steps"] += 1

    def __call__(self, event: str, axis: int) -> None:
        if event == "ghosts":
            st = self.sim.state
            load_heat(st.alpha, st.arho, st.arhoe, st.momentum, st.energy, self.sim.eos.kind, self.sim.eos.params,
                      self.rho0, st.arhoq)
            now = self.measure(class_mode=1, class_axis=axis)
            self.class_before = now["by_class"]
        elif event == "sweep":
            now = self.measure(class_mode=2)
        else:
            now = self.measure()
        op = event if axis < 0 or event == "ghosts" else f"{event} {AXIS_NAMES[axis]}"
        acc = self.windows[self.window]["operations"][op]
        acc["by_region"] += now["by_region"] - self.last["by_region"]
        if event == "sweep":
            acc["by_class"] += now["by_class"] - self.class_before
            acc["produced"] += now["produced"]
            acc["class_mass"] += self.class_before[:, :, 0]
            acc["sweeps"] += 1
        acc["amounts"] += now["amounts"] - self.last["amounts"]
        acc["floors"] += now["floors"] - self.last["floors"]
        acc["outflow_energy"] += now["outflow_energy"] - self.last["outflow_energy"]
        self.last = now

    def record(self) -> dict:
        """The current totals as a JSON-ready history entry (``fill``: :meth:`fill_histogram`)."""
        now = self.measure()
        mass, pz, kin = now["inside"]
        return {"time": self.sim.time, "by_region": now["by_region"].tolist(),
                "target_kinetic_energy": float(kin - 0.5 * pz * pz / mass) if mass > 0 else 0.0,
                "fill": self.fill_histogram()}

    def fill_histogram(self) -> list[list[float]]:
        """Target material's mass (kg) and kinetic energy (J) by its cell's fill sum_k alpha_k, bins FILL_EDGES."""
        mesh, st = self.sim.mesh, self.sim.state
        vol = mesh.cell_volumes()
        arho = mesh.interior(st.arho)
        rho = arho.sum(axis=1)
        fill = mesh.interior(st.alpha).sum(axis=1)
        kin = 0.5 * (mesh.interior(st.momentum) ** 2).sum(axis=1) / np.where(rho > 0, rho, 1.0)
        target_mass = arho[:, 0] * vol
        target_kin = np.where(rho > 0, arho[:, 0] / np.where(rho > 0, rho, 1.0), 0.0) * kin * vol
        index = np.searchsorted(FILL_EDGES, fill, side="right")
        return [np.bincount(index.ravel(), weights=w.ravel(), minlength=len(FILL_EDGES) + 1).tolist()
                for w in (target_mass, target_kin)]

    def windows_json(self) -> list[dict]:
        out = []
        for w in self.windows:
            ops = {}
            for op, acc in w["operations"].items():
                ops[op] = {"by_region": acc["by_region"].tolist(), "by_class": acc["by_class"].tolist(),
                           "produced": acc["produced"].tolist(),
                           "class_mass": (acc["class_mass"] / max(acc["sweeps"], 1)).tolist(),
                           "amounts": dict(zip(AMOUNT_NAMES, acc["amounts"].tolist())),
                           "floors": dict(zip(FLOOR_NAMES, acc["floors"].tolist())),
                           "outflow_energy": acc["outflow_energy"]}
            out.append({"start": w["start"], "end": min(w["end"], self.sim.time), "steps": w["steps"],
                        "operations": ops})
        return out


def run(config_path: Path, cells: float, out: Path, windows: tuple[float, ...], times: tuple[float, ...]) -> dict:
    """Run the config at ``cells`` cells per projectile radius with the budget attached; write ``out``."""
    config = load_config(config_path, overrides={"hydro.cells_per_projectile_radius": cells})
    values = derive(config)
    sim = build_simulation(config, values)
    end = float(values["end_time"])
    scene = config.scene
    budget = EnergyBudget(sim, scene.target.radius, scene.projectile.radius, windows)
    sim.observer = budget
    stops = sorted(set(t for t in list(snapshot_times(config, end)) + list(windows) + list(times) if 0 < t <= end))
    result = {"config": str(config_path), "cells_per_projectile_radius": cells, "levels": int(values["levels"]),
              "end_time": end, "regions": REGIONS, "quantities": QUANTITIES, "classes": CLASSES,
              "near_field_radii": NEAR_FIELD, "wall_band_radii": WALL_BAND, "history": [budget.record()]}
    started = time.perf_counter()
    for stop in stops:
        while sim.time < stop * (1.0 - 1e-14):
            budget.begin_step()
            sim.step(dt_max=stop - sim.time)
        sim.time = stop
        result["history"].append(budget.record())
        result.update(steps=sim.step_count, cell_updates=int(sim.cell_updates),
                      wall_seconds=time.perf_counter() - started, windows=budget.windows_json())
        write_json(out, result)
        print(f"t = {stop:g} s: {sim.step_count} steps, {sim.cell_updates:.3g} cell-updates, "
              f"{time.perf_counter() - started:.0f} s, target K within R_T "
              f"{result['history'][-1]['target_kinetic_energy']:.4g} J", flush=True)
    return result


def _row(label: str, values) -> str:
    return "| " + label + " | " + " | ".join(values) + " |"


def _at_time(runs: list[dict], t: float, cell) -> list[str]:
    """``cell(history entry)`` of each run at time ``t`` ("" where a run has none)."""
    out = []
    for run in runs:
        entry = next((h for h in run["history"] if abs(h["time"] - t) < 1e-9), None)
        out.append("" if entry is None else cell(entry))
    return out


def _in_window(runs: list[dict], iw: int, cell) -> list[str]:
    """``cell(operations of window iw)`` of each run ("" where a run has not reached it)."""
    return [cell(run["windows"][iw]["operations"]) if iw < len(run["windows"]) else "" for run in runs]


def _heat(ops: dict, names) -> float:
    return sum(np.array(ops[op]["by_region"])[:, 3].sum() for op in names)


def _produced(ops: dict, c: int) -> str:
    sweeps = [ops[op] for op in ("sweep r", "sweep z")]
    mass = sum(np.array(o["class_mass"]) for o in sweeps)
    share = mass[c].sum() / mass.sum() if mass.sum() > 0 else float("nan")
    return f"{sum(np.array(o['produced'])[c].sum() for o in sweeps) / 1e18:+.3f} ({share:.2f})"


def _floors(ops: dict) -> str:
    removed = sum(a["energy_removed_by_void_cleanup"] + a["energy_removed_by_velocity_limit"]
                  + a["energy_removed_by_energy_limit"] - a["energy_added_by_floors"]
                  for a in (ops[op]["amounts"] for op in OPERATIONS))
    return f"{removed / 1e18:+.4f}"


def _kinetic_change(ops: dict, names) -> str:
    d = sum(np.array(ops[op]["by_region"]) for op in names)
    return f"{d[1:, 1].sum() / 1e18:+.3f} / {d[0, 1] / 1e18:+.3f}"


def _fill_share(entry: dict, ib: int) -> str:
    m, k = (np.array(v) for v in entry["fill"])
    return f"{m[ib] / m.sum():.3f} ({k[ib] / k.sum():.3f})"


def print_tables(runs: list[dict]) -> None:
    """Markdown tables of finished (or partial) runs, one column per run (docs/accuracy.md)."""
    runs = sorted(runs, key=lambda r: r["cells_per_projectile_radius"])
    head = [f"{r['cells_per_projectile_radius']:g}" for r in runs]
    rule = _row("---", ["---"] * len(runs))
    print(_row("cells / R_P", head))
    print(rule)
    print(_row("steps (time reached, s)", [f"{r['steps']} ({r['history'][-1]['time']:g})" for r in runs]))
    print(_row("wall (s)", [f"{r['wall_seconds']:.0f}" for r in runs]))
    edges = [w["start"] for w in runs[0]["windows"]] + [runs[0]["end_time"]]
    windows = [f"{lo:g}-{hi:g}" for lo, hi in zip(edges[:-1], edges[1:])]
    print("\nKinetic energy / heat (1e18 J) by region at the window edges:\n")
    print(_row("t (s) | region", head))
    print(rule)
    for t in edges[1:]:
        for i, name in enumerate(REGIONS):
            print(_row(f"{t:g} | {name}", _at_time(runs, t, lambda h, i=i: f"{h['by_region'][i][1] / 1e18:.3f} / "
                                                                           f"{h['by_region'][i][3] / 1e18:.3f}")))
        print(_row(f"{t:g} | all material", _at_time(
            runs, t, lambda h: f"{sum(row[1] for row in h['by_region']) / 1e18:.3f} / "
                               f"{sum(row[3] for row in h['by_region']) / 1e18:.3f}")))
        print(_row(f"{t:g} | K within R_T, centre-of-mass frame",
                   _at_time(runs, t, lambda h: f"{h['target_kinetic_energy'] / 1e18:.3f}")))
    print("\nChange of the kinetic energy (1e18 J, target / projectile material) and counted floors by operation:\n")
    print(_row("window (s) | operation", head))
    print(rule)
    groups = (("sweeps", ("sweep r", "sweep z")), ("AMR regrid", ("regrid",)), ("AMR reflux", ("reflux r", "reflux z")),
              ("sources", ("sources",)), ("ghost filling", ("ghosts",)))
    for iw, label in enumerate(windows):
        for name, ops in groups:
            if any(np.any(r["windows"][iw]["operations"][op]["by_region"]) for r in runs if iw < len(r["windows"])
                   for op in ops):
                print(_row(f"{label} | {name}", _in_window(runs, iw, lambda o, ops=ops: _kinetic_change(o, ops))))
        print(_row(f"{label} | energy removed by floors, cleanup and limits", _in_window(runs, iw, _floors)))
    print("\nHeat produced in the sweeps (1e18 J) by class, and the class's mean share of the mass:\n")
    print(_row("window (s) | class", head))
    print(rule)
    for iw, label in enumerate(windows):
        for c, name in enumerate(CLASSES):
            print(_row(f"{label} | {name}", _in_window(runs, iw, lambda o, c=c: _produced(o, c))))
        print(_row(f"{label} | AMR regrid and reflux (change of the heat)", _in_window(
            runs, iw, lambda o: f"{_heat(o, ('regrid', 'reflux r', 'reflux z')) / 1e18:+.3f}")))
    print("\nTarget mass (kinetic energy) share by the fill of its cell:\n")
    bins = ["< 0.5", "0.5-0.9", "0.9-0.99", f"0.99-{PHI_SECOND_ORDER:g}", f">= {PHI_SECOND_ORDER:g}"]
    print(_row("t (s) | fill", head))
    print(rule)
    for t in edges[1:]:
        for ib, name in enumerate(bins):
            print(_row(f"{t:g} | {name}", _at_time(runs, t, lambda h, ib=ib: _fill_share(h, ib))))
    done = [r for r in runs if abs(r["history"][-1]["time"] - r["end_time"]) < 1e-9]
    if len(done) >= 3:
        h = np.array([1.0 / r["cells_per_projectile_radius"] for r in done])
        f = np.array([r["history"][-1]["target_kinetic_energy"] for r in done])
        for first in range(len(done) - 2):
            est = richardson(h[first:first + 3], f[first:first + 3])
            rungs = "/".join(f"{1 / x:g}" for x in h[first:first + 3])
            print(f"\nK within R_T at {done[0]['end_time']:g} s over {rungs} cells: {est.status}, order "
                  f"{est.order:.2f}, extrapolated {est.value:.4g} J")


def write_json(path: Path, data: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=1))
    tmp.replace(path)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=CONFIG)
    parser.add_argument("--cells", type=float, help="cells per projectile radius")
    parser.add_argument("--out", type=Path, help="output JSON")
    parser.add_argument("--windows", default=",".join(f"{t:g}" for t in WINDOWS),
                        help="inner edges of the time windows (s), comma-separated")
    parser.add_argument("--times", default=",".join(f"{t:g}" for t in TIMES),
                        help="times (s) at which the region totals are recorded")
    parser.add_argument("--table", nargs="+", type=Path, metavar="JSON", help="print the tables of finished runs")
    args = parser.parse_args(argv)
    if args.table:
        print_tables([json.loads(p.read_text()) for p in args.table])
        return
    if args.cells is None or args.out is None:
        parser.error("--cells and --out are needed to run (or --table to print)")
    windows = tuple(float(t) for t in args.windows.split(","))
    times = tuple(float(t) for t in args.times.split(","))
    run(args.config, args.cells, args.out, windows, times)


if __name__ == "__main__":
    sys.exit(main())
