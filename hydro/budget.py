"""The hydro stage's conservation budget: what the mesh holds, what left it, what the floors changed."""

from __future__ import annotations

from typing import Any


#: Floor amounts that change the mesh totals, with the sign of their change (added +1, removed -1).
COUNTED_CHANGES = {
    "mass": (("mass_added_by_floors", 1.0), ("mass_removed_by_void_cleanup", -1.0)),
    "energy": (("energy_added_by_floors", 1.0), ("energy_removed_by_void_cleanup", -1.0),
               ("energy_removed_by_velocity_limit", -1.0), ("energy_removed_by_energy_limit", -1.0)),
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
    for axis, name in enumerate("xyz"):
        out[f"momentum_{name}_initial"] = float(initial["momentum"][axis])
        out[f"momentum_{name}_on_mesh"] = float(final["momentum"][axis])
        out[f"momentum_{name}_left_mesh"] = float(final["outflow_momentum"][axis])
    out.update({f"floor_{key}": float(value) for key, value in floors.items()})
    return out
