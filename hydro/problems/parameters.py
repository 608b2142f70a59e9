"""Declared problem parameters: default, type, bounds, units and meaning of each, in plain Python.

Each problem module lists the parameters of its scene in ``PARAMETERS`` (name ->
:class:`Parameter` or :class:`Record`), in the order a scene states them.  That is the one
place a parameter is defined: the module's ``setup`` fills in what a call leaves out from it
(:func:`setup_defaults`), and the pipeline builds the config schema of the scene from it, so
a key, its default and its bounds cannot differ between the library and the config file.

A parameter has two defaults because the library and a run configuration serve different
readers: ``default`` is what a scene takes when it leaves the key out (:data:`REQUIRED`: a
scene must state it), ``example`` is what ``setup`` takes when a call leaves the key out and
the scene has no default (the textbook case that tests and benchmarks run: Sod's two states,
an ideal gas named "gas").  A scene must state a material or an initial state explicitly; a
direct call of ``setup`` runs the textbook case.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


class _Required:
    """Type of :data:`REQUIRED`."""

    def __repr__(self) -> str:
        return "REQUIRED"


#: The default of a parameter a scene must state.
REQUIRED: Any = _Required()

#: The value types a parameter may have.
KINDS = (float, int, bool, str)


@dataclass(frozen=True)
class Parameter:
    """One scalar parameter of a problem.

    ``default``: the value a scene takes when it leaves the key out (:data:`REQUIRED`: none).
    ``kind``: float, int, bool or str.  ``gt``, ``ge``, ``lt``, ``le``: bounds (None: none).
    ``units``: SI units of the value ("" for a pure number or a name).  ``description``:
    what it is.  ``example``: what ``setup`` takes when a call leaves the key out, where the
    scene has no default (:data:`REQUIRED`: ``setup`` takes ``default``).
    """

    default: Any = REQUIRED
    kind: type = float
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    units: str = ""
    description: str = ""
    example: Any = REQUIRED

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise TypeError(f"kind must be one of {[k.__name__ for k in KINDS]} (got {self.kind!r})")

    @property
    def required(self) -> bool:
        """True when a scene must state the parameter."""
        return self.default is REQUIRED

    def bounds(self) -> dict[str, float]:
        """The bounds that are set, as ``{"gt": 0.0, ...}``."""
        return {op: value for op, value in (("gt", self.gt), ("ge", self.ge), ("lt", self.lt), ("le", self.le))
                if value is not None}

    def violations(self, value: Any) -> list[str]:
        """One ``must be > 0 (got -1)`` message per bound ``value`` breaks."""
        tests = {"gt": (">", lambda b: value > b), "ge": (">=", lambda b: value >= b),
                 "lt": ("<", lambda b: value < b), "le": ("<=", lambda b: value <= b)}
        return [f"must be {tests[op][0]} {bound:g} (got {value})"
                for op, bound in self.bounds().items() if not tests[op][1](bound)]


@dataclass(frozen=True)
class Record:
    """A nested mapping of parameters: a material state, a plate, a body.

    ``name`` names the kind of record (records of one kind share ``fields``); ``fields`` maps
    each key to its :class:`Parameter`.  ``default``: :data:`REQUIRED` (a scene must state the
    record) or None (optional; absent means none, e.g. void around a slab).  ``example``: the
    mapping ``setup`` takes when a call leaves the record out (:data:`REQUIRED`: ``default``).
    """

    name: str
    fields: dict[str, Parameter] = field(default_factory=dict)
    default: Any = REQUIRED
    description: str = ""
    example: Any = REQUIRED

    def __post_init__(self) -> None:
        if self.default is not REQUIRED and self.default is not None:
            raise ValueError(f"{self.name}: a record's default is REQUIRED or None (got {self.default!r})")

    @property
    def required(self) -> bool:
        """True when a scene must state the record."""
        return self.default is REQUIRED


def setup_defaults(parameters: dict[str, Parameter | Record]) -> dict[str, Any]:
    """The values ``setup`` takes for keys a call leaves out: each ``example``, else its ``default``.

    Parameters with neither are left out.
    """
    out: dict[str, Any] = {}
    for name, param in parameters.items():
        value = param.example if param.example is not REQUIRED else param.default
        if value is not REQUIRED:
            out[name] = dict(value) if isinstance(value, dict) else value
    return out


def violations(parameters: dict[str, Parameter | Record], values: dict[str, Any]) -> list[str]:
    """``key: must be > 0 (got -1)`` for each bound a value in ``values`` breaks (records as ``key.field``)."""
    messages: list[str] = []
    for name, param in parameters.items():
        value = values.get(name)
        if isinstance(param, Record):
            if isinstance(value, dict):
                messages.extend(f"{name}.{msg}" for msg in violations(param.fields, value))
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            messages.extend(f"{name}: {msg}" for msg in param.violations(value))
    return messages
