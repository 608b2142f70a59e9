"""The hydro stage's conservation budget: what the mesh holds, what left it, what the floors changed."""

from __future__ import annotations

from typing import Any

import numpy as np


#: Floor amounts that change the mesh totals, with the sign of their change (added +1, removed -1).
COUNTED_CHANGES = {
    "mass": (("mass_added_by_floors", 1.0), ("mass_removed_by_void_cleanup", -1.0)),
    "energy": (("energy_added_by_floors", 1.0), ("energy_removed_by_void_cleanup", -1.0),
               ("energy_removed_by_velocity_limit", -1.0), ("energy_removed_by_energy_limit", -1.0)),
    **{f"momentum_{name}": ((f"momentum_{name}_removed_by_void_cleanup", -1.0),
                            (f"momentum_{name}_removed_by_velocity_limit", -1.0)) for name in "xyz"},
}


def conservation_budget(initial: dict[str, Any], final: dict[str, Any], floors: dict[str, float],
                        gravity_work: float = 0.0) -> dict[str, float]:
    """Mass, momentum and energy: at the start, on the mesh at the end, what left it, what floors changed (SI).

    ``*_error`` is (mesh + left - initial - added) relative to the initial value: what the
    scheme failed to conserve, floors included; ``added`` is the work done by external
    gravity for the energy (``energy_added_by_gravity``, J; :mod:`impactpipe.hydro.gravity`)
    and 0 for the mass.  A run starting with zero energy is measured against the gravity work.
    ``*_unaccounted`` is the same with every counted change of the floors (``floors``, the
    solver's ``floor_amounts``; :data:`COUNTED_CHANGES`) taken back: zero up to round-off
    when nothing changed the totals uncounted.

    Momentum (kg m/s), per global component c (x, y, z; in 2d-cylindrical r, z, theta):
    ``momentum_c_error`` = (P_c,mesh + P_c,left - P_c,initial) / S and ``momentum_c_unaccounted``
    the same with the signed amounts the void cleanup and the small-cell velocity limit took
    off component c added back (``momentum_c_removed_by_void_cleanup``, ``..._by_velocity_limit``).
    The scale S (``momentum_scale``, kg m/s) is the initial sum over the cells of |rho u| V
    (``momentum_magnitude`` of :meth:`~impactpipe.hydro.solver.Simulation.totals`): a component
    may start at zero (a box at rest on the whole, the transverse components of an impact), and
    for one moving body S is its momentum; the final sum for a run that starts at rest, 1 when
    nothing moves at either end.  Both are reported only for the
    components the run conserves (``momentum_conserved`` of the totals, omitted otherwise):
    all three in 3d and 2d-planar (z stays 0 there), only z (the ``y`` keys) in
    2d-cylindrical (the r-sweep's hoop pressure p / r is a source of r momentum; theta is
    zero); under external gravity not the components along g, and none under self-gravity
    (neither's impulse is accumulated, only its work).
    """
    out: dict[str, float] = {"energy_added_by_gravity": float(gravity_work)}
    for key in ("mass", "energy"):
        added = gravity_work if key == "energy" else 0.0
        out[f"{key}_initial"] = float(initial[key])
        out[f"{key}_on_mesh"] = float(final[key])
        out[f"{key}_left_mesh"] = float(final[f"outflow_{key}"])
        scale = abs(float(initial[key])) or abs(added) or 1.0
        change = final[key] + final[f"outflow_{key}"] - initial[key] - added
        out[f"{key}_error"] = float(change / scale)
        counted = sum(sign * floors.get(name, 0.0) for name, sign in COUNTED_CHANGES[key])
        out[f"{key}_unaccounted"] = float((change - counted) / scale)
    conserved = final.get("momentum_conserved", (False, False, False))
    scale = (float(initial.get("momentum_magnitude", np.linalg.norm(initial["momentum"])))
             or float(final.get("momentum_magnitude", 0.0)) or 1.0)
    out["momentum_scale"] = scale
    for axis, name in enumerate("xyz"):
        key = f"momentum_{name}"
        out[f"{key}_initial"] = float(initial["momentum"][axis])
        out[f"{key}_on_mesh"] = float(final["momentum"][axis])
        out[f"{key}_left_mesh"] = float(final["outflow_momentum"][axis])
        if conserved[axis]:
            change = final["momentum"][axis] + final["outflow_momentum"][axis] - initial["momentum"][axis]
            out[f"{key}_error"] = float(change / scale)
            counted = sum(sign * floors.get(amount, 0.0) for amount, sign in COUNTED_CHANGES[key])
            out[f"{key}_unaccounted"] = float((change - counted) / scale)
    out.update({f"floor_{key}": float(value) for key, value in floors.items()})
    return out
