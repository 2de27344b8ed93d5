# Copyright 2026 visual_adaptive_servo contributors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""Parameter schemas: how every parameter set of the package is declared and validated.

A section of a ROS-style parameter file (``sim_node``, ``controller_node``,
``feature_detector``) is a tuple of :class:`ParamSpec`; :func:`resolve_params`
checks a flat parameter dict against it (names, types, bounds) and fills the
defaults, structure parameters first.  The specs themselves live in
:mod:`.config` (one module per section); the ROS nodes declare their parameters
from the same specs (:mod:`.ros.params`).  Every error is a :class:`ConfigError`
that names ``section.parameter`` and the rule.

This module imports numpy only: the control law, the detector and the nodes use
its error type and the section names without loading any configuration.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

SIM_SECTION = "sim_node"
CONTROLLER_SECTION = "controller_node"
DETECTOR_SECTION = "feature_detector"
TIMING_MODES = ("lockstep", "realtime")
INF = math.inf


class ConfigError(ValueError):
    """A configuration value is missing, unknown or breaks a rule (message names it)."""


@dataclass(frozen=True)
class ParamSpec:
    """One declared parameter.

    ``default`` is a value or a callable ``default(structure, values)`` of the
    structure (the model, or the simulator's arm: n, m, joint names) and of the
    values resolved so far, for lengths that depend on n, m or the parameter
    counts and for estimates computed from other parameters.  ``kind`` is one
    of ``float``, ``int``, ``bool``, ``str``, ``float_list``, ``str_list``.
    ``low``/``high`` are inclusive bounds applied to every element.
    ``runtime`` marks parameters that may safely change while running;
    ``structure`` those that define the model (read first).  ``optional``: the
    value may be None (left out: derived later, e.g. a gain designed at the first
    joint sample).  ``scalar``: a ``float_list`` that also takes one number, the
    same for every entry (a diagonal gain); :func:`require_length` expands it.
    """

    name: str
    default: Any
    kind: str
    description: str
    low: float | None = None
    high: float | None = None
    runtime: bool = False
    structure: bool = False
    optional: bool = False
    scalar: bool = False

    @property
    def computed(self):
        """The default depends on the structure or on other parameters."""
        return callable(self.default)

    def default_for(self, structure, values):
        return self.default(structure, values) if callable(self.default) else self.default


def _to_value(spec, value, section):
    where = f"{section}.{spec.name}"
    kind = spec.kind
    if value is None and spec.optional:
        return None
    if (kind == "float_list" and spec.scalar and not isinstance(value, bool)
            and isinstance(value, (int, float, np.number))):
        value = [value]             # one number for every entry: require_length expands it
    if kind == "str":
        if not isinstance(value, str):
            raise ConfigError(f"{where}: must be a string, got {value!r}")
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: must be true or false, got {value!r}")
        return value
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ConfigError(f"{where}: must be an integer, got {value!r}")
        _check_range(spec, [value], where)
        return int(value)
    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
            raise ConfigError(f"{where}: must be a number, got {value!r}")
        value = float(value)
        if math.isnan(value):
            raise ConfigError(f"{where}: must not be NaN")
        _check_range(spec, [value], where)
        return value
    if kind == "str_list":
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise ConfigError(f"{where}: must be a list of strings, got {value!r}")
        return tuple(value)
    if kind == "float_list":
        if isinstance(value, np.ndarray) and value.ndim != 1:
            value = value.reshape(-1)
        if not isinstance(value, (list, tuple, np.ndarray)) or any(
                isinstance(v, bool) or not isinstance(v, (int, float, np.number)) for v in value):
            raise ConfigError(f"{where}: must be a list of numbers, got {value!r}")
        arr = np.array(value, dtype=float)
        if np.isnan(arr).any():
            raise ConfigError(f"{where}: must not contain NaN")
        _check_range(spec, arr, where)
        arr.setflags(write=False)
        return arr
    raise AssertionError(kind)


def _check_range(spec, values, where):
    for v in values:
        if spec.low is not None and v < spec.low:
            raise ConfigError(f"{where}: must be >= {spec.low}, got {v}")
        if spec.high is not None and v > spec.high:
            raise ConfigError(f"{where}: must be <= {spec.high}, got {v}")


def did_you_mean(unknown, known):
    """'' or ' (did you mean a for b, ...?)': the nearest known name of each unknown one."""
    pairs = []
    for name in unknown:
        near = difflib.get_close_matches(name, list(known), n=1, cutoff=0.75)
        if near:
            pairs.append(f"{near[0]} for {name}")
    return f" (did you mean {', '.join(pairs)}?)" if pairs else ""


def resolve_params(specs, params, section, build_structure):
    """Check names and types of a flat parameter dict and fill defaults, structure first.

    ``build_structure(values)`` turns the structure parameters into the object the
    computed defaults need (a model, or the simulator's arm); a ValueError it raises
    becomes a ConfigError.  Returns ``(structure, values)``.
    """
    specs_by_name = {s.name: s for s in specs}
    unknown = sorted(set(params) - set(specs_by_name))
    if unknown:
        raise ConfigError(f"{section}: unknown parameter(s) {unknown}"
                          + did_you_mean(unknown, specs_by_name))
    values = {}
    ordered = ([s for s in specs if s.structure] + [s for s in specs if not s.structure
                                                    and not s.computed]
               + [s for s in specs if not s.structure and s.computed])
    structure = None
    for spec in ordered:
        if spec.computed and structure is None:
            try:
                structure = build_structure(values)
            except (ValueError, FileNotFoundError) as exc:
                text = str(exc)
                raise ConfigError(text if text.startswith(section) else
                                  f"{section}.{text}") from None
        if spec.name in params:
            raw = params[spec.name]
        else:
            try:
                raw = spec.default_for(structure, values)
            except ValueError as exc:
                raise ConfigError(f"{section}.{spec.name}: no default: {exc}") from None
        values[spec.name] = _to_value(spec, raw, section)
    if structure is None:
        structure = build_structure(values)
    return structure, values


def require_length(values, name, length, section, scalar=False):
    """``values[name]`` has ``length`` entries (ConfigError naming it otherwise).

    With ``scalar``, one entry stands for all and is expanded in ``values``; None
    (an optional parameter left out) passes.
    """
    if values[name] is None:
        return
    if scalar and len(values[name]) == 1 and length != 1:
        arr = np.full(length, values[name][0])
        arr.setflags(write=False)
        values[name] = arr
    if len(values[name]) != length:
        raise ConfigError(f"{section}.{name}: needs {length} values, got {len(values[name])}")


def require_finite(values, name, section):
    """Every entry of ``values[name]`` is finite (ConfigError naming it otherwise)."""
    if values[name] is not None and not np.all(np.isfinite(values[name])):
        raise ConfigError(f"{section}.{name}: must be finite, "
                          f"{failing_entries(values[name], ~np.isfinite(values[name]))}")


def failing_entries(values, failing):
    """Which entries of a list parameter break a rule, for an error message.

    ``failing``: a boolean mask over ``values`` with at least one True.  A list of a
    few entries is shown whole (plain numbers, not numpy's reprs); a long one (a
    7-joint arm's 66 kinematic gains) by its first failing entry and a count.
    """
    values = np.asarray(values, dtype=float)
    bad = np.flatnonzero(failing)
    if values.size <= 8:
        return f"got {[float(v) for v in values]}"
    first = int(bad[0])
    text = f"entry {first} (counted from 0) is {float(values[first])}"
    if bad.size > 1:
        text += f", and {bad.size - 1} more of the {values.size} entries"
    return text


@dataclass(frozen=True, eq=False)
class ValidatedParams:
    """A complete, validated parameter dict, read as attributes or items."""

    params: dict = field(repr=False)

    def __getattr__(self, name):
        try:
            return self.__dict__["params"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __getitem__(self, name):
        return self.params[name]
