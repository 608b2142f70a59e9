"""Gravitational reaccumulation of hand-off particles with REBOUND (SI units).

The run (see docs/nbody.md for the full description):

1. Particles are moved to their centre-of-mass frame (the offset is added back to every
   output) and put in one open REBOUND root box of half-width ``box_factor`` times the
   cloud's extent.  Leapfrog with the time step of :mod:`impactpipe.nbody.simulation`,
   tree gravity with ``opening_angle``, ``linetree`` (or ``tree``) collision search, and
   the compiled resolver of :mod:`impactpipe.nbody.resolver`.
2. The simulation advances in chunks that end at output times (every ``output_interval``)
   or earlier, so that no particle can reach the box edge within a chunk:
   chunk <= 0.5 min_i (h - |x_i|) / |v_i| with h the box half-width, and at most
   MAX_CHUNK_STEPS steps, so that the escape removal and the time-step rule below act soon
   after fast ejecta leave (with km/s ejecta the first output interval alone can be 1e5
   collision-limited steps).
3. Between chunks: merge events go into the provenance map (union-find); particles beyond
   h/2 on escape orbits (``diagnostics.escaping``) are removed as escaped, particles beyond
   0.9 h that are not are removed as ``left_box`` (with a warning), and any particle REBOUND
   removed by itself is recorded as ``lost`` (with a warning): nothing leaves silently.
   After a removal the frame is re-centred on the remaining centre of mass.  The energy
   the removed particles take out is accumulated (``escaped_energy``), and the pairs that
   overlapped at t = 0 and are now at or beyond contact are closed (``resolver``: until
   then they are pushed apart only as far as their own kinetic energy pays).  If the
   particles now move faster than the time-step rule assumed, the step is reduced.
4. At output times the diagnostics are recorded and the stop criteria checked
   (``no_particles_left`` as soon as a removal leaves the simulation empty, with a last
   diagnostics row; an empty hand-off returns that status at once, without diagnostics):
   ``equilibrium`` when the mass orbiting the largest remnant (``diagnostics`` module) is
   below ``max_orbiting_fraction`` M_lr and t >= ``min_dynamical_times`` t_dyn;
   ``stable_orbits`` when more mass orbits, but the particle count and the orbiting mass have
   not changed for ``max_quiet_dynamical_times`` t_dyn (and t >= ``min_dynamical_times``
   t_dyn): a satellite in a stable orbit, which would otherwise keep the run going forever;
   ``time_cap`` at the first output time >= ``max_sim_time``; ``wall_cap`` at the first
   chunk end after ``max_wall_seconds`` of wall time in this call.
5. With ``archive_path``, a Simulationarchive snapshot is appended at the start, at every
   chunk end past the next multiple of ``archive_interval`` and when the run stops,
   followed by a sidecar ``<archive_path>.state.npz`` (written atomically) with the
   provenance map, the slot of every particle in snapshot order (REBOUND 5.2 stores
   particle names as pointers, which dangle after loading, so names are not used),
   spins, escapes, merge log, diagnostics and schedule.  The live simulation is then
   replaced by the snapshot read back, so an uninterrupted run and one resumed from any
   snapshot pass through the same loaded states.  A later call with the same particles
   and parameters and ``resume=True`` (after an exception, a kill or a cap) continues
   from the last snapshot and reproduces the uninterrupted run bit for bit.
6. Cost counters: ``steps`` is REBOUND's ``steps_done`` (stored in the snapshots) and
   ``particle_steps`` the sum over steps of the particles each step integrated, counted
   by the compiled post-step hook of :mod:`impactpipe.nbody.resolver` and carried in the
   sidecar; both continue across resumes.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import time as _time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import rebound

from impactpipe.handoff.particles import ParticleSet
from impactpipe.storage import atomic_path

from . import diagnostics as dg
from .resolver import (CTX_N_BOUNCE, CTX_N_HANDOFF, CTX_N_MERGE, CTX_N_OVERLAP, CTX_N_SEPARATING, CTX_PARTICLE_STEPS,
                       MODEL_CODES, PARAM_KINETIC, PARAM_PUSH_ENERGY, CollisionResolver, particle_view)
from .result import ESCAPE_ORBIT, LEFT_BOX, LOST, NO_PARTICLES_LEFT, STABLE_ORBITS, TERMINAL_STATUSES, NBodyResult
from .simulation import G, build_simulation, collision_time_step, dynamical_time, weighted_mean

log = logging.getLogger(__name__)

ESCAPE_RADIUS_FACTOR = 2.0    # escape test beyond this many initial cloud extents from the centre of mass
BOX_GUARD_FRACTION = 0.9      # particles beyond this fraction are removed (left_box)
CHUNK_EDGE_FRACTION = 0.5     # chunk <= this * (distance to box edge) / speed
MAX_CHUNK_STEPS = 2000        # chunk <= this many steps, so escapers leave and dt grows back soon
UNBOUND_WARNING_FRACTION = 0.5  # warn when more of the hand-off mass than this is on escape orbits at t = 0
NEAR_ESCAPE_RATIO = 0.6       # initial_near_escape_mass: speed between this and 1 times the escape speed
SIDECAR_FORMAT = 3            # 3: contact-time impact velocity, energy-limited pushes of t = 0 overlaps, energy account
_VECTOR_DIAGNOSTICS = ("momentum", "angular_momentum", "spin_angular_momentum",
                       "escaped_momentum", "escaped_angular_momentum")


class ArchiveMismatch(ValueError):
    """The archive holds a run of other particles or parameters, or was written by another version."""


def reaccumulate(
    particles: ParticleSet,
    *,
    bulk_density: float,
    collision_model: str = "merge",
    restitution_normal: float = 0.5,
    restitution_tangential: float = 1.0,
    opening_angle: float = 0.5,
    min_dynamical_times: float = 50.0,
    max_orbiting_fraction: float = 0.1,
    max_quiet_dynamical_times: float = 200.0,
    max_sim_time: float | None = None,
    max_wall_seconds: float | None = None,
    archive_path: str | os.PathLike | None = None,
    archive_interval: float | None = None,
    seed: int = 1,
    progress: Callable[[float], None] | None = None,
    resume: bool = True,
    output_interval: float | None = None,
    collision_search: str = "linetree",
    steps_per_dynamical_time: float = 100.0,
    collision_step_fraction: float = 0.5,
    box_factor: float = 10.0,
) -> NBodyResult:
    """Run gravitational reaccumulation of ``particles`` until equilibrium or a cap.

    Args:
        particles: hand-off particles (SI units).
        bulk_density: kg/m^3, sets t_dyn = 1 / sqrt(G rho) and the packed escape speed of
            the time-step rule.
        collision_model: 'merge', 'conditional_merge' or 'bounce' (see ``resolver``).
        restitution_normal, restitution_tangential: eps_n, eps_t in [0, 1] for bounces.
        opening_angle: Barnes-Hut opening angle (rad).
        min_dynamical_times: least simulated time, in t_dyn, before equilibrium can stop.
        max_orbiting_fraction: equilibrium when orbiting mass < this fraction of M_lr.
        max_quiet_dynamical_times: stop with ``stable_orbits`` when the particle count and the
            orbiting mass have not changed for this many t_dyn (:func:`_unchanged_since`).
        max_sim_time: s; stop (``time_cap``) at the first output time at or past it.
        max_wall_seconds: s of wall time in this call; stop (``wall_cap``) at the next chunk end.
        archive_path: Simulationarchive file for checkpoints (None: no checkpoints).
        archive_interval: s between snapshots (default 5 t_dyn).
        seed: REBOUND ``rand_seed`` (order in which collisions of a step are resolved).
        progress: called with the simulated time (s) after every chunk.
        resume: continue from ``archive_path`` if it holds a run of the same particles
            and parameters; False starts over and replaces it.
        output_interval: s between diagnostics and equilibrium checks (default t_dyn / 2).
        collision_search: 'linetree' (straight paths over the step) or 'tree' (overlaps
            at the end of the step).
        steps_per_dynamical_time, collision_step_fraction: the time-step rule
            dt = min(t_dyn / steps_per_dynamical_time, collision_step_fraction r_min / v_rel_max).
        box_factor: box half-width over the cloud's extent about its centre of mass.

    Returns:
        The final state, provenance, escapes, diagnostics and cost counters.  An empty
        ``particles`` (or a run whose removals leave no particle) ends with status
        ``no_particles_left``.

    Raises:
        ArchiveMismatch: ``resume`` and ``archive_path`` holds a run of other particles or
            parameters, or a sidecar of another format.
    """
    wall_start = _time.monotonic()
    if collision_model not in MODEL_CODES:
        raise ValueError(f"collision_model must be one of {tuple(MODEL_CODES)} (got {collision_model!r})")
    for name, value in (("restitution_normal", restitution_normal), ("restitution_tangential", restitution_tangential)):
        if not 0.0 <= value <= 1.0:
            raise ValueError(f"{name} must be in [0, 1] (got {value})")
    if not 0.0 < max_orbiting_fraction <= 1.0:
        raise ValueError(f"max_orbiting_fraction must be in (0, 1] (got {max_orbiting_fraction})")
    if not max_quiet_dynamical_times > 0.0:
        raise ValueError(f"max_quiet_dynamical_times must be > 0 (got {max_quiet_dynamical_times})")
    if not box_factor > 1.0:
        raise ValueError(f"box_factor must be > 1 (got {box_factor})")
    if np.unique(particles.id).size != len(particles):
        raise ValueError("particle ids are not unique")
    t_dyn = dynamical_time(bulk_density)
    if len(particles) == 0:
        log.warning("nbody: the hand-off has no particles; nothing to simulate (status %s)", NO_PARTICLES_LEFT)
        return _empty_result(t_dyn, collision_model)
    output_interval = 0.5 * t_dyn if output_interval is None else float(output_interval)
    archive_interval = 5.0 * t_dyn if archive_interval is None else float(archive_interval)
    if not (output_interval > 0 and archive_interval > 0):
        raise ValueError("output_interval and archive_interval must be > 0 s")
    params = {
        "collision_model": collision_model, "restitution_normal": float(restitution_normal),
        "restitution_tangential": float(restitution_tangential), "opening_angle": float(opening_angle),
        "bulk_density": float(bulk_density), "seed": int(seed), "output_interval": output_interval,
        "archive_interval": archive_interval, "collision_search": collision_search,
        "steps_per_dynamical_time": float(steps_per_dynamical_time),
        "collision_step_fraction": float(collision_step_fraction), "box_factor": float(box_factor),
    }
    run = _Run(particles, params, t_dyn)
    archive = Path(archive_path) if archive_path is not None else None
    sidecar = Path(str(archive) + ".state.npz") if archive is not None else None
    if archive is not None and resume and sidecar.exists():
        run.load(archive, sidecar)
        log.info("resumed from %s at t = %.6g s", archive, run.sim.t)
    else:
        run.start()
        run.record_diagnostics()
        if archive is not None:
            sidecar.unlink(missing_ok=True)
            run.checkpoint(archive, sidecar, first=True)

    while run.status is None:
        t_target = min(run.next_output, run.chunk_end_by_box(), run.sim.t + MAX_CHUNK_STEPS * run.sim.dt)
        run.advance(t_target)
        t = run.sim.t
        if run.sim.N == 0:
            run.status = NO_PARTICLES_LEFT
            run.record_diagnostics()
            log.warning("nbody: every particle was removed (escaped, left the box or lost) by t = %.6g s; "
                        "no remnant", t)
        elif t >= run.next_output:
            run.record_diagnostics()
            while run.next_output <= t:
                run.next_output += output_interval
            d = run.diag
            settled = t >= min_dynamical_times * t_dyn
            if settled and d["orbiting_mass"][-1] < max_orbiting_fraction * d["remnant_mass"][-1]:
                run.status = "equilibrium"
            elif settled and t - _unchanged_since(d) >= max_quiet_dynamical_times * t_dyn:
                run.status = STABLE_ORBITS
                log.warning("nbody: %.3g M_lr still orbits the largest remnant (%d particles left), unchanged "
                            "for %.3g t_dyn: stopped as stable orbits", d["orbiting_mass"][-1] /
                            d["remnant_mass"][-1], run.sim.N, (t - _unchanged_since(d)) / t_dyn)
            elif max_sim_time is not None and t >= max_sim_time:
                run.status = "time_cap"
        if progress is not None:
            progress(t)
        if run.status is None and max_wall_seconds is not None and \
                _time.monotonic() - wall_start >= max_wall_seconds:
            run.status = "wall_cap"
        if archive is not None and (run.status is not None or t >= run.next_archive):
            while run.next_archive <= t:
                run.next_archive += archive_interval
            run.checkpoint(archive, sidecar)
    log.info("nbody stopped: %s at t = %.6g s (%.3g t_dyn), N = %d, %d steps, %d particle-steps", run.status,
             run.sim.t, run.sim.t / t_dyn, run.sim.N, run.sim.steps_done, run.resolver.ctx[CTX_PARTICLE_STEPS])
    return run.result()


def _unchanged_since(diag: dict[str, list]) -> float:
    """Time (s) of the earliest diagnostics output from which on the particle count and the
    orbiting mass equal their latest values (exact comparison: without a merger, escape or
    change of orbit the orbiting mass is the same sum of the same particle masses)."""
    n, orbiting, times = diag["n_particles"], diag["orbiting_mass"], diag["time"]
    i = len(times) - 1
    while i > 0 and n[i - 1] == n[-1] and orbiting[i - 1] == orbiting[-1]:
        i -= 1
    return float(times[i])


class _Run:
    """State of one reaccumulation run: the simulation, resolver and bookkeeping."""

    def __init__(self, particles: ParticleSet, params: dict, t_dyn: float):
        self.p = particles
        self.params = params
        self.t_dyn = t_dyn
        self.slot_ids = np.asarray(particles.id, dtype=np.int64)
        n0 = len(particles)
        self.parent = np.arange(n0, dtype=np.int64)
        self.resolver = CollisionResolver(n0, params["collision_model"], params["restitution_normal"],
                                          params["restitution_tangential"], G)
        self.fingerprint = _fingerprint(particles, params)
        self.status: str | None = None
        self.particle_steps_known = True
        self.escaped = {k: [] for k in ("slot", "mass", "momentum", "position", "velocity", "spin", "time", "reason")}
        self.merges = {"time": [], "survivor": [], "absorbed": []}
        self.diag: dict[str, list] = {}
        m0 = np.asarray(particles.mass, float)
        ratio = dg.escape_speed_ratio(np.asarray(particles.position, float), np.asarray(particles.velocity, float), m0)
        self.initial_unbound_mass = float(m0[ratio >= 1.0].sum())
        self.initial_near_escape_mass = float(m0[(ratio >= NEAR_ESCAPE_RATIO) & (ratio < 1.0)].sum())
        unbound_fraction = self.initial_unbound_mass / float(np.sum(particles.mass))
        if unbound_fraction > UNBOUND_WARNING_FRACTION:
            log.warning("%.3g of the hand-off mass is on escape orbits at t = 0 (two-body energy relative to "
                        "all the other mass >= 0): without mergers it disperses unless collisions dissipate "
                        "its energy, while perfect merging glues touching particles whatever their speed "
                        "(docs/nbody.md, unbound hand-offs)", unbound_fraction)
        else:
            log.info("%.3g of the hand-off mass is on escape orbits at t = 0", unbound_fraction)
        log.info("%.3g of the hand-off mass moves at %g-1 times its escape speed at t = 0 (the mass whose fate "
                 "the reaccumulation decides; docs/nbody.md)", self.initial_near_escape_mass / float(m0.sum()),
                 NEAR_ESCAPE_RATIO)

    # --- set-up -------------------------------------------------------------------
    def start(self) -> None:
        p = self.p
        m = np.asarray(p.mass, float)
        x = np.asarray(p.position, float)
        v = np.asarray(p.velocity, float)
        r = np.asarray(p.radius, float)
        x_com = weighted_mean(m, x)
        v_com = weighted_mean(m, v)
        extent = float(np.max(np.linalg.norm(x - x_com, axis=1) + r))
        self.box_half_width = self.params["box_factor"] * extent
        self.escape_radius = ESCAPE_RADIUS_FACTOR * extent
        self.origin_ref = x_com
        self.frame_velocity = v_com
        self.t_ref = 0.0
        dt = collision_time_step(m, r, v, bulk_density=self.params["bulk_density"],
                                 steps_per_dynamical_time=self.params["steps_per_dynamical_time"],
                                 collision_step_fraction=self.params["collision_step_fraction"],
                                 collision_search=self.params["collision_search"],
                                 collision_model=self.params["collision_model"], position=x)
        self.sim = build_simulation(x - x_com, v - v_com, m, r, dt=dt,
                                    opening_angle=self.params["opening_angle"],
                                    collision_search=self.params["collision_search"],
                                    box_half_width=self.box_half_width, seed=self.params["seed"])
        particle_view(self.sim)["ap"] = np.arange(len(m)) + 1
        self.resolver.attach(self.sim)
        self.next_output = self.params["output_interval"]
        self.next_archive = self.params["archive_interval"]
        self.initial_overlaps = dg.overlaps(x, r, m)
        pair_i, pair_j, pair_d = dg.overlapping_pairs(x, r)
        self.resolver.set_handoff_overlaps(pair_i, pair_j, pair_d)
        self.handoff_open = int(pair_i.size)
        self.escaped_energy = 0.0
        if self.initial_overlaps[0]:
            log.warning("%d particle pairs overlap at t = 0 (deepest %.3f of the radii sum; separating each on "
                        "its own would cost %.4g J of potential energy)", *self.initial_overlaps)
        self._remember_state()

    def load(self, archive: Path, sidecar: Path) -> None:
        with np.load(sidecar, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arrays = {k: z[k] for k in z.files if k != "meta"}
        if meta.get("format") != SIDECAR_FORMAT:
            raise ArchiveMismatch(f"{sidecar} was written by another version of the N-body stage (sidecar format "
                                  f"{meta.get('format', 1)}, this one writes {SIDECAR_FORMAT}); pass resume=False "
                                  "to start over")
        if meta["fingerprint"] != self.fingerprint:
            raise ArchiveMismatch(f"{archive} holds a run of other particles or parameters; pass resume=False to "
                                  "start over")
        if meta["status"] == NO_PARTICLES_LEFT:  # no snapshot of the empty end state (see checkpoint)
            self.sim = rebound.Simulation()
            self.sim.t, self.sim.dt, self.sim.steps_done = meta["t"], meta["dt"], meta["steps_done"]
        else:
            self._read_snapshot(archive, meta["t"], arrays["snapshot_slots"])
        self.resolver.spin[:] = arrays["spin"]
        self.resolver.ctx[CTX_N_MERGE] = meta["n_merge"]
        self.resolver.ctx[CTX_N_BOUNCE] = meta["n_bounce"]
        self.resolver.ctx[CTX_N_SEPARATING] = meta["n_separating"]
        self.resolver.params[PARAM_KINETIC] = meta["collision_kinetic_energy_change"]
        self.resolver.params[PARAM_PUSH_ENERGY] = meta["overlap_push_energy"]
        keys = arrays["handoff_keys"]
        n0 = len(self.slot_ids)
        self.resolver.set_handoff_overlaps(keys // n0, keys % n0, arrays["handoff_floor"], arrays["handoff_open"])
        self.handoff_open = int(arrays["handoff_open"].sum())
        self.escaped_energy = meta["escaped_energy"]
        self.resolver.ctx[CTX_N_OVERLAP] = meta["n_overlap_push"]
        # sidecars written before the counter existed lack it: the count is then unknown (-1)
        self.particle_steps_known = "particle_steps" in meta
        self.resolver.ctx[CTX_PARTICLE_STEPS] = meta.get("particle_steps", 0)
        self.parent[:] = arrays["parent"]
        self.box_half_width = meta["box_half_width"]
        self.escape_radius = meta["escape_radius"]
        self.origin_ref = np.array(meta["origin_ref"])
        self.frame_velocity = np.array(meta["frame_velocity"])
        self.t_ref = meta["t_ref"]
        self.initial_overlaps = tuple(meta["initial_overlaps"])
        self.next_output = meta["next_output"]
        self.next_archive = meta["next_archive"]
        self.status = meta["status"] if meta["status"] in TERMINAL_STATUSES else None
        for k in self.escaped:
            self.escaped[k] = list(arrays["escaped_" + k])
        for k in self.merges:
            self.merges[k] = list(arrays["merge_" + k])
        self.diag = {k[5:]: list(arrays[k]) for k in arrays if k.startswith("diag_")}
        self._remember_state()

    def _read_snapshot(self, archive: Path, t: float, slots: np.ndarray) -> None:
        """Replace the simulation by the last snapshot at time t (s); ``slots`` in particle order."""
        sa = rebound.Simulationarchive(str(archive), process_warnings=False)
        index = max(k for k in range(len(sa)) if sa.t[k] == t)
        self.sim = sa[index]
        del sa
        view = particle_view(self.sim)
        if len(view) != len(slots):
            raise ValueError(f"{archive}: snapshot at t = {t} s does not match its sidecar")
        view["ap"] = slots + 1
        view["name"] = 0  # the stored name pointers are not valid in this process
        self.resolver.attach(self.sim)

    def checkpoint(self, archive: Path, sidecar: Path, first: bool = False) -> None:
        """Append a snapshot to the archive, write the sidecar that refers to it, read it back.

        The live simulation is replaced by the snapshot just written: REBOUND rebuilds its
        tree on loading, which can change the order in which the pairs of one step are
        resolved, so an uninterrupted run continues from the same loaded state a resumed
        run starts from, and both follow the same path bit for bit.

        A run that ended without particles writes the sidecar alone (REBOUND 5.2 cannot read
        back a snapshot of an empty simulation); its time, step and step count are in the sidecar.
        """
        snapshot_slots = particle_view(self.sim)["ap"] - 1
        if self.sim.N:
            self.sim.save_to_file(str(archive), delete_file=first)
        meta = {
            "format": SIDECAR_FORMAT, "fingerprint": self.fingerprint, "t": self.sim.t, "status": self.status,
            "dt": self.sim.dt, "steps_done": int(self.sim.steps_done),
            "n_merge": int(self.resolver.ctx[CTX_N_MERGE]), "n_bounce": int(self.resolver.ctx[CTX_N_BOUNCE]),
            "n_separating": int(self.resolver.ctx[CTX_N_SEPARATING]),
            "collision_kinetic_energy_change": float(self.resolver.params[PARAM_KINETIC]),
            "overlap_push_energy": float(self.resolver.params[PARAM_PUSH_ENERGY]),
            "escaped_energy": self.escaped_energy,
            "n_overlap_push": int(self.resolver.ctx[CTX_N_OVERLAP]),
            **({"particle_steps": int(self.resolver.ctx[CTX_PARTICLE_STEPS])} if self.particle_steps_known else {}),
            "box_half_width": self.box_half_width, "escape_radius": self.escape_radius,
            "origin_ref": self.origin_ref.tolist(),
            "frame_velocity": self.frame_velocity.tolist(), "t_ref": self.t_ref,
            "initial_overlaps": list(self.initial_overlaps),
            "next_output": self.next_output, "next_archive": self.next_archive,
        }
        n_handoff = int(self.resolver.ctx[CTX_N_HANDOFF])
        arrays = {"meta": np.array(json.dumps(meta)), "spin": self.resolver.spin, "parent": self.parent,
                  "snapshot_slots": snapshot_slots, "handoff_keys": self.resolver.handoff_keys[:n_handoff],
                  "handoff_floor": self.resolver.handoff_floor[:n_handoff],
                  "handoff_open": self.resolver.handoff_open[:n_handoff]}
        for k, v in self._escaped_arrays().items():
            arrays["escaped_" + k] = v
        for k, v in self._merge_arrays().items():
            arrays["merge_" + k] = v
        for k, v in self._diag_arrays().items():
            arrays["diag_" + k] = v
        with atomic_path(sidecar) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)
        if self.sim.N:
            self._read_snapshot(archive, self.sim.t, snapshot_slots)

    # --- frame and state ---------------------------------------------------------------
    def origin(self, t: float) -> np.ndarray:
        """Position (m) of the simulation frame's origin in the hand-off frame at time t."""
        return self.origin_ref + self.frame_velocity * (t - self.t_ref)

    def _arrays(self):
        view = particle_view(self.sim)
        x = np.stack([view["x"], view["y"], view["z"]], axis=1)
        v = np.stack([view["vx"], view["vy"], view["vz"]], axis=1)
        return view["ap"] - 1, view["m"].copy(), view["r"].copy(), x, v

    def _remember_state(self) -> None:
        self.last_slots, self.last_m, _, self.last_x, self.last_v = self._arrays()
        self.last_t = self.sim.t
        self.last_origin = self.origin(self.sim.t)
        self.last_frame_velocity = self.frame_velocity.copy()

    def chunk_end_by_box(self) -> float:
        """Latest chunk end (s) at which no particle can have reached the box edge."""
        _, _, _, x, v = self._arrays()
        speed = np.linalg.norm(v, axis=1)
        room = self.box_half_width - np.linalg.norm(x, axis=1)
        moving = speed > 0
        if not moving.any():
            return math.inf
        return self.sim.t + max(CHUNK_EDGE_FRACTION * float(np.min(room[moving] / speed[moving])), self.sim.dt)

    # --- one chunk -----------------------------------------------------------------
    def advance(self, t_target: float) -> None:
        self.sim.integrate(t_target, exact_finish_time=0)
        t = self.sim.t
        events, times = self.resolver.drain_events()
        self.parent[events[:, 1]] = events[:, 0]
        self.merges["time"].extend(times)
        self.merges["survivor"].extend(events[:, 0])
        self.merges["absorbed"].extend(events[:, 1])
        slots, m, r, x, v = self._arrays()
        lost = np.setdiff1d(self.last_slots, np.concatenate([slots, events[:, 1]]))
        if lost.size:
            log.warning("%d particle(s) left the REBOUND box inside a chunk; recorded as lost "
                        "with their state at t = %.6g s", lost.size, self.last_t)
            rows = np.searchsorted(self.last_slots, lost, sorter=np.argsort(self.last_slots))
            rows = np.argsort(self.last_slots)[rows]
            for k in rows:
                self._record_escape(self.last_slots[k], self.last_m[k], self.last_x[k] + self.last_origin,
                                    self.last_v[k] + self.last_frame_velocity, self.last_t, LOST)
        esc = dg.escaping(x, v, m, self.escape_radius)
        guard = (np.linalg.norm(x, axis=1) > BOX_GUARD_FRACTION * self.box_half_width) & ~esc
        if guard.any():
            log.warning("%d bound particle(s) reached %.2f of the box half-width at t = %.6g s; "
                        "removed as left_box", int(guard.sum()), BOX_GUARD_FRACTION, t)
        remove = np.flatnonzero(esc | guard)
        if remove.size:
            self.escaped_energy += dg.removal_energy(x, v + self.frame_velocity, m, r, self.resolver.spin[slots],
                                                     esc | guard)
        origin = self.origin(t)
        for k in remove:
            self._record_escape(slots[k], m[k], x[k] + origin, v[k] + self.frame_velocity, t,
                                ESCAPE_ORBIT if esc[k] else LEFT_BOX)
        with warnings.catch_warnings():  # REBOUND warns when the last one goes; reaccumulate reports it
            warnings.filterwarnings("ignore", "Last particle removed", RuntimeWarning)
            for k in remove[::-1]:
                self.sim.remove(int(k))
        if self.sim.N == 0:  # no frame to re-centre, no step to choose: the run ends
            self._remember_state()
            return
        if remove.size or lost.size:
            self._recentre()
        if self.handoff_open:
            slots, _, r, x, _ = self._arrays()
            self.handoff_open = self.resolver.close_separated(slots, x, r)
        self._check_time_step()
        self._remember_state()

    def _record_escape(self, slot, mass, position, velocity, t, reason) -> None:
        e = self.escaped
        e["slot"].append(int(slot))
        e["mass"].append(float(mass))
        e["momentum"].append(mass * velocity)
        e["position"].append(position)
        e["velocity"].append(velocity)
        e["spin"].append(self.resolver.spin[slot].copy())
        e["time"].append(float(t))
        e["reason"].append(int(reason))

    def _recentre(self) -> None:
        """Move the frame to the centre of mass of the remaining particles (Galilean shift)."""
        _, m, _, x, v = self._arrays()
        t = self.sim.t
        shift_x = weighted_mean(m, x)
        shift_v = weighted_mean(m, v)
        view = particle_view(self.sim)
        self.origin_ref = self.origin(t) + shift_x
        self.frame_velocity = self.frame_velocity + shift_v
        self.t_ref = t
        for c, s in zip(("x", "y", "z", "vx", "vy", "vz"), np.concatenate([shift_x, shift_v])):
            view[c] -= s

    def _check_time_step(self) -> None:
        _, m, r, x, v = self._arrays()
        dt = collision_time_step(m, r, v, bulk_density=self.params["bulk_density"],
                                 steps_per_dynamical_time=self.params["steps_per_dynamical_time"],
                                 collision_step_fraction=self.params["collision_step_fraction"],
                                 collision_search=self.params["collision_search"],
                                 collision_model=self.params["collision_model"], position=x)
        if dt < self.sim.dt or dt > 2.0 * self.sim.dt:
            log.debug("time step %s from %.4g s to %.4g s at t = %.6g s",
                     "reduced" if dt < self.sim.dt else "raised", self.sim.dt, dt, self.sim.t)
            self.sim.dt = dt

    # --- diagnostics and result ----------------------------------------------------------
    def record_diagnostics(self) -> None:
        slots, m, r, x, v = self._arrays()
        t = self.sim.t
        xo = x + self.origin(t)
        vo = v + self.frame_velocity
        q = dg.conserved_quantities(xo, vo, m, r, self.resolver.spin[slots])
        m_lr, m_orb, _ = dg.remnant_and_orbiting(x, v, m, r)
        n_over, deepest, _ = dg.overlaps(x, r, m)
        esc = self._escaped_arrays()
        l_esc = (np.cross(esc["position"], esc["momentum"]).sum(axis=0) + esc["spin"].sum(axis=0))
        row = {
            "time": t, "n_particles": len(m), **q,
            "escaped_mass": esc["mass"].sum(), "escaped_momentum": esc["momentum"].sum(axis=0),
            "escaped_angular_momentum": l_esc,
            "n_merge": int(self.resolver.ctx[CTX_N_MERGE]), "n_bounce": int(self.resolver.ctx[CTX_N_BOUNCE]),
            "largest_mass": float(m.max()) if len(m) else 0.0, "remnant_mass": m_lr, "orbiting_mass": m_orb,
            "time_step": self.sim.dt,
            "escaped_energy": self.escaped_energy,
            "collision_kinetic_energy_change": float(self.resolver.params[PARAM_KINETIC]),
            "n_overlap_push": int(self.resolver.ctx[CTX_N_OVERLAP]),
            "overlap_push_energy": float(self.resolver.params[PARAM_PUSH_ENERGY]),
            "handoff_overlaps_open": self.handoff_open,
            "overlapping_pairs": n_over, "max_overlap": deepest,
        }
        for k, val in row.items():
            self.diag.setdefault(k, []).append(val)
        log.debug("t = %.6g s (%.3g t_dyn), N = %d, M_lr = %.4g kg, orbiting = %.3g M_lr, merges %d, bounces %d",
                 t, t / self.t_dyn, len(m), m_lr, m_orb / m_lr if m_lr > 0 else 0.0, row["n_merge"],
                 row["n_bounce"])

    def _escaped_arrays(self) -> dict[str, np.ndarray]:
        e = self.escaped
        return {
            "slot": np.array(e["slot"], dtype=np.int64), "mass": np.array(e["mass"], dtype=float),
            "momentum": np.array(e["momentum"], dtype=float).reshape(-1, 3),
            "position": np.array(e["position"], dtype=float).reshape(-1, 3),
            "velocity": np.array(e["velocity"], dtype=float).reshape(-1, 3),
            "spin": np.array(e["spin"], dtype=float).reshape(-1, 3),
            "time": np.array(e["time"], dtype=float), "reason": np.array(e["reason"], dtype=np.int8),
        }

    def _merge_arrays(self) -> dict[str, np.ndarray]:
        return {"time": np.array(self.merges["time"], dtype=float),
                "survivor": np.array(self.merges["survivor"], dtype=np.int64),
                "absorbed": np.array(self.merges["absorbed"], dtype=np.int64)}

    def _diag_arrays(self) -> dict[str, np.ndarray]:
        out = {}
        for k, values in self.diag.items():
            arr = np.array(values)
            out[k] = arr.reshape(-1, 3) if k in _VECTOR_DIAGNOSTICS else arr
        return out

    def result(self) -> NBodyResult:
        slots, m, r, x, v = self._arrays()
        t = self.sim.t
        roots = _roots(self.parent)
        esc = self._escaped_arrays()
        off, mem = _members_csr(roots, slots, self.slot_ids)
        eoff, emem = _members_csr(roots, esc["slot"], self.slot_ids)
        merges = self._merge_arrays()
        return NBodyResult(
            id=self.slot_ids[slots], mass=m, radius=r, position=x + self.origin(t),
            velocity=v + self.frame_velocity, spin=self.resolver.spin[slots].copy(),
            members_offset=off, members=mem,
            escaped_id=self.slot_ids[esc["slot"]], escaped_mass=esc["mass"], escaped_momentum=esc["momentum"],
            escaped_position=esc["position"], escaped_velocity=esc["velocity"], escaped_spin=esc["spin"],
            escaped_time=esc["time"], escaped_reason=esc["reason"],
            escaped_members_offset=eoff, escaped_members=emem,
            merge_time=merges["time"], merge_survivor=self.slot_ids[merges["survivor"]],
            merge_absorbed=self.slot_ids[merges["absorbed"]],
            diagnostics=self._diag_arrays(), status=self.status, time=float(t),
            dynamical_time=self.t_dyn, time_step=float(self.sim.dt),
            collision_model=self.params["collision_model"],
            initial_overlapping_pairs=int(self.initial_overlaps[0]),
            initial_overlap_energy=float(self.initial_overlaps[2]),
            initial_unbound_mass=self.initial_unbound_mass,
            initial_near_escape_mass=self.initial_near_escape_mass,
            steps=int(self.sim.steps_done),
            particle_steps=int(self.resolver.ctx[CTX_PARTICLE_STEPS]) if self.particle_steps_known else -1,
        )


def _empty_result(t_dyn: float, collision_model: str) -> NBodyResult:
    """The result of a run without particles: no final particles, escapes, mergers or diagnostics."""
    ids = np.zeros(0, dtype=np.int64)
    scalars = np.zeros(0)
    vectors = np.zeros((0, 3))
    offsets = np.zeros(1, dtype=np.int64)
    return NBodyResult(
        id=ids, mass=scalars, radius=scalars, position=vectors, velocity=vectors, spin=vectors,
        members_offset=offsets, members=ids,
        escaped_id=ids, escaped_mass=scalars, escaped_momentum=vectors, escaped_position=vectors,
        escaped_velocity=vectors, escaped_spin=vectors, escaped_time=scalars,
        escaped_reason=np.zeros(0, dtype=np.int8), escaped_members_offset=offsets, escaped_members=ids,
        merge_time=scalars, merge_survivor=ids, merge_absorbed=ids,
        status=NO_PARTICLES_LEFT, time=0.0, dynamical_time=t_dyn, time_step=0.0, collision_model=collision_model,
        steps=0, particle_steps=0,
    )


def _roots(parent: np.ndarray) -> np.ndarray:
    """Root of every slot in the merge forest parent[absorbed] = survivor (pointer jumping)."""
    roots = parent.copy()
    while True:
        nxt = roots[roots]
        if np.array_equal(nxt, roots):
            return roots
        roots = nxt


def _members_csr(roots: np.ndarray, heads: np.ndarray, slot_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CSR (offsets, ids): the hand-off ids whose root is heads[k], sorted, for each k."""
    order = np.argsort(roots, kind="stable")
    sorted_roots = roots[order]
    start = np.searchsorted(sorted_roots, heads, side="left")
    stop = np.searchsorted(sorted_roots, heads, side="right")
    offsets = np.zeros(len(heads) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(stop - start)
    members = np.concatenate([np.sort(slot_ids[order[a:b]]) for a, b in zip(start, stop)]) \
        if len(heads) else np.zeros(0, dtype=np.int64)
    return offsets, members.astype(np.int64)


def _fingerprint(particles: ParticleSet, params: dict) -> str:
    h = hashlib.sha256()
    for name in ("id", "mass", "radius", "position", "velocity"):
        h.update(np.ascontiguousarray(getattr(particles, name)).tobytes())
    h.update(json.dumps(params, sort_keys=True).encode())
    return h.hexdigest()
