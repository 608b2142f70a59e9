"""The checks a config passes before any work: one function for ``impactpipe validate``,
``impactpipe run``, the Python :func:`impactpipe.pipeline.stages.run` and sweep points.

Schema and cross-field errors are raised while the config loads
(:mod:`impactpipe.pipeline.config`); what needs the derived values (the mesh levels, the
geometry, the hand-off time) is checked here by
:func:`impactpipe.pipeline.derived.capability_errors`, and each message is given the
``file:line: key: message`` form of the loading errors.
"""

from __future__ import annotations

import re
from typing import Any

import yaml

from . import derived
from .config import Config, ConfigError, _LineFinder


def check(config: Config) -> dict[str, Any]:
    """The derived values of ``config`` (:func:`impactpipe.pipeline.derived.derive`); a request
    this version cannot carry out raises ConfigError with one located line per problem."""
    values = derived.derive(config)
    errors = derived.capability_errors(config, values)
    if errors:
        raise ConfigError(located(config, errors))
    return values


def warnings(config: Config, values: dict[str, Any]) -> list[str]:
    """Physics the config asks for that is not modelled, resolutions too coarse to trust and
    time stepping not yet sound for the scene, as ``file: warning: key: message`` lines."""
    return [f"{config._source}: warning: {message}"
            for message in (derived.physics_warnings(values) + derived.resolution_warnings(config)
                            + derived.time_stepping_warnings(config))]


def located(config: Config, messages: list[str]) -> list[str]:
    """``key: message`` lines as ``file:line: key: message``, the line of ``key`` in the config's
    YAML (its nearest given parent where the key took its default)."""
    try:
        root = yaml.compose(config._source_text) if config._source_text else None
    except yaml.YAMLError:
        root = None
    lines = _LineFinder(config._source, root)
    out = []
    for message in messages:
        key, _, text = message.partition(": ")
        line = lines.line(key_path(key)) if text else None
        out.append(f"{config._source}:{line}: {message}" if line else f"{config._source}: {message}")
    return out


def key_path(dotted: str) -> tuple:
    """``"hydro.refinement.boxes[0].level"`` as ``("hydro", "refinement", "boxes", 0, "level")``."""
    loc: list = []
    for part in dotted.split("."):
        name, *indices = re.split(r"\[(\d+)\]", part)
        loc.append(name)
        loc.extend(int(i) for i in indices if i)
    return tuple(loc)
