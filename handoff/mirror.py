"""The full body from a half-domain 3d run: mirror the snapshot and tracers across y = 0.

An oblique impact in the x-z plane is symmetric under the reflection y -> -y, so the hydro
stage computes only y >= 0 with a reflecting plane at y = 0 (hydro/problems/impact.py).
The hand-off must give the N-body stage the whole body.  Each leaf block b (y in
[y_lo, y_hi], y_lo >= 0) gets a mirror block b' with

    y in [-y_hi, -y_lo],   cells reversed along y,   v_y' = -v_y,
    S_xy' = -S_xy,  S_yz' = -S_yz  (deviatoric stress; the other components, the scalars
                                   and the per-material fields are even under the mirror),
    id' = id + (max id + 1),

and each tracer t a mirror tracer t' with y, initial y and v_y negated and
id' = id + (max id + 1) (the same records otherwise).  The blocks-to-spheres rules then run
on the mirrored snapshot unchanged, so with M, P the computed half's mass and momentum:

    mass:      M_full = 2 M
    momentum:  P_full = (2 P_x, 0, 2 P_z)     (P_y and -P_y cancel, to round-off)

and the mirror sphere of block b is the reflection of b's sphere (same mass and radius,
position (x, -y, z), velocity (v_x, -v_y, v_z)) before the velocity noise, which is drawn
independently for every particle.  The y = 0 wall impulse that the half-domain run counts
in its ``outflow_momentum`` is the force between the two halves: it cancels in the full body.
"""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np

from impactpipe.hydro.output.snapshot import Snapshot, TracerSet

#: Snapshot ``extra`` fields that change sign under y -> -y (hydro/output/io.py EXTRA_UNITS names).
ODD_EXTRA_FIELDS = ("deviatoric_stress_xy", "deviatoric_stress_yz")

#: TracerSet vector fields whose y component changes sign.
_TRACER_VECTORS = ("initial_position", "position", "velocity")


def mirror_across_y0(snapshot: Snapshot, tracers: TracerSet | None = None) -> tuple[Snapshot, TracerSet | None]:
    """The half-domain snapshot (and tracers) joined with their mirror images across y = 0.

    Args:
        snapshot: a 3d snapshot whose blocks all lie in y >= 0.
        tracers: its tracer set, or None.

    Returns:
        (snapshot with 2 NB blocks: the originals then their mirrors; tracer set with 2 N
        tracers: the originals then their mirrors, or None).
    """
    if snapshot.geometry != "3d":
        raise ValueError(f"mirroring across y = 0 needs a 3d snapshot (got {snapshot.geometry!r})")
    if snapshot.block_lo.shape[0] and snapshot.block_lo[:, 1].min() < 0.0:
        raise ValueError(f"mirroring across y = 0 needs a half-domain snapshot (blocks in y >= 0); a block starts "
                         f"at y = {snapshot.block_lo[:, 1].min():.6g} m")
    lo, hi = snapshot.block_lo.copy(), snapshot.block_hi.copy()
    lo[:, 1], hi[:, 1] = -snapshot.block_hi[:, 1], -snapshot.block_lo[:, 1]
    velocity = snapshot.velocity[..., ::-1, :].copy()
    velocity[:, 1] *= -1.0

    def joined(arr: np.ndarray, mirrored: np.ndarray) -> np.ndarray:
        return np.concatenate([arr, mirrored])

    def flipped(arr: np.ndarray) -> np.ndarray:
        """Cells reversed along y (the second-to-last axis of every block-shaped array)."""
        return arr[..., ::-1, :]

    extra = {}
    for name, arr in snapshot.extra.items():
        sign = -1.0 if name in ODD_EXTRA_FIELDS else 1.0
        extra[name] = joined(arr, sign * flipped(arr))
    offset = int(snapshot.block_id.max()) + 1 if snapshot.block_id.size else 0
    full = replace(
        snapshot,
        block_lo=joined(snapshot.block_lo, lo),
        block_hi=joined(snapshot.block_hi, hi),
        block_level=joined(snapshot.block_level, snapshot.block_level),
        block_id=joined(snapshot.block_id, snapshot.block_id + offset),
        partial_density=joined(snapshot.partial_density, flipped(snapshot.partial_density)),
        volume_fraction=joined(snapshot.volume_fraction, flipped(snapshot.volume_fraction)),
        velocity=joined(snapshot.velocity, velocity),
        specific_internal_energy=joined(snapshot.specific_internal_energy,
                                        flipped(snapshot.specific_internal_energy)),
        pressure=joined(snapshot.pressure, flipped(snapshot.pressure)),
        temperature=joined(snapshot.temperature, flipped(snapshot.temperature)),
        sound_speed=joined(snapshot.sound_speed, flipped(snapshot.sound_speed)),
        extra=extra,
    )
    return full, (None if tracers is None else _mirror_tracers(tracers))


def _mirror_tracers(tracers: TracerSet) -> TracerSet:
    """``tracers`` followed by their mirror images (y, initial y and v_y negated, ids offset)."""
    values = {}
    for f in fields(TracerSet):
        arr = np.asarray(getattr(tracers, f.name))
        mirrored = arr.copy()
        if f.name in _TRACER_VECTORS:
            mirrored[:, 1] *= -1.0
        elif f.name == "id":
            mirrored = arr + (int(arr.max()) + 1 if arr.size else 0)
        values[f.name] = np.concatenate([arr, mirrored])
    return TracerSet(**values)
