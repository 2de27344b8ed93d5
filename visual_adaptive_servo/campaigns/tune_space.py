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

"""The search space of ``vas tune``: which controller parameters vary, over which ranges.

A space file is a YAML mapping of dimension -> range (the shipped default is
``config/tune/default_space.yaml``)::

    controller_node.alpha: {low: 2.0, high: 60.0, log: true}       # the value itself
    scale.controller_node.Gamma_z: {low: 0.03, high: 3.0, log: true}  # x the file's value
    controller_node.latency_compensation: {choices: [true, false]}

``controller_node.NAME`` (or ``set.controller_node.NAME``) sets a number parameter;
``scale.controller_node.NAME`` multiplies the configuration's value (a number or a
list, e.g. a diagonal gain) -- the ``set.``/``scale.`` factors of a campaign spec
(:mod:`.spec`), which realise them.  ``choices`` lists the values of an option.
``when_file_sets: NAME`` / ``unless_file_sets: NAME`` keep a dimension only for a
configuration file that gives (does not give) ``controller_node.NAME`` itself: the
default space tunes ``Gamma_d_normalized`` where Gamma_d comes from it, and scales
Gamma_d where the file lists Gamma_d.

Everything is checked against the controller's parameter specs
(:data:`~visual_adaptive_servo.config.controller.CONTROLLER_PARAMS`) before any run:
each range's ends must be valid values (a scaled list at both ends, element-wise),
and the controller configuration must validate with each dimension at either end.
Theorem 1's alpha > gamma/3 is kept by sampling: gamma first, then alpha from
``(gamma/3, alpha's high]`` (with its low when that is larger), so every trial is a
configuration the theorem covers and no trial of the budget is spent on a refused
one; a space in which some gamma leaves no alpha is refused.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass

import numpy as np
import yaml

from ..config.controller import CONTROLLER_PARAMS, ControllerConfig
from ..models.resources import OWN_SHARE
from ..schema import CONTROLLER_SECTION, ConfigError

DEFAULT_SPACE = os.path.join(OWN_SHARE["config"], "tune", "default_space.yaml")
#: parameters the randomized run conditions set (the initial estimates): not gains
CONDITION_PARAMS = ("a_z_perp_init", "a_z_init", "a_d_init")
#: alpha is drawn above gamma/3 by this relative margin (Theorem 1 is strict)
THEOREM_MARGIN = 1e-6
_SPECS = {s.name: s for s in CONTROLLER_PARAMS}
_RANGE_KEYS = {"low", "high", "log"}
_CONDITION_KEYS = ("when_file_sets", "unless_file_sets")


class SpaceError(ConfigError):
    """A search space breaks a rule (the message names the space file and the dimension)."""


@dataclass(frozen=True)
class Dimension:
    """One dimension of the space.

    ``mode`` is ``set`` (the parameter's value) or ``scale`` (the configuration's
    value times the drawn factor); ``param`` the controller parameter's name;
    ``low``/``high``/``log`` a range, or ``choices`` the values of an option.
    """

    key: str
    mode: str
    param: str
    low: float = math.nan
    high: float = math.nan
    log: bool = False
    choices: tuple = ()

    @property
    def factor(self):
        """The campaign factor that realises a drawn value (:func:`.spec.resolve_overrides`)."""
        return f"{self.mode}.{CONTROLLER_SECTION}.{self.param}"

    @property
    def target(self):
        return f"{CONTROLLER_SECTION}.{self.param}"

    def describe(self):
        if self.choices:
            return f"one of {list(self.choices)}"
        scale = "log" if self.log else "linear"
        what = "x the file's value" if self.mode == "scale" else ""
        return f"[{self.low:g}, {self.high:g}] {scale} {what}".rstrip()


@dataclass(frozen=True)
class SearchSpace:
    """A validated space: its dimensions in sampling order (gamma before alpha)."""

    path: str
    dimensions: tuple
    dropped: tuple = ()         # (key, why) of dimensions left out (default space only)

    def fingerprint(self):
        body = [(d.key, d.mode, d.param, d.low, d.high, d.log, list(d.choices))
                for d in self.dimensions]
        return hashlib.sha256(json.dumps(body, default=str).encode()).hexdigest()

    def by_param(self, param):
        return next((d for d in self.dimensions if d.mode == "set" and d.param == param), None)

    def suggest(self, trial, base_values):
        """Draw a trial's values (Optuna ``trial.suggest_*``); returns {factor: value}.

        ``base_values``: the configuration's controller parameters (the partner of
        alpha or gamma when only one of them is tuned).
        """
        drawn = {}
        for d in self.dimensions:
            if d.choices:
                value = trial.suggest_categorical(d.key, list(d.choices))
            else:
                low = d.low
                if d.mode == "set" and d.param == "alpha":
                    gamma = drawn.get(f"set.{CONTROLLER_SECTION}.gamma", base_values["gamma"])
                    low = max(low, alpha_floor(gamma))
                value = trial.suggest_float(d.key, low, d.high, log=d.log)
            drawn[d.factor] = value
        return drawn

    def defaults(self, base_values):
        """The configuration's own values as a trial's params ({key: value}), into the space.

        Returns (params, notes): a value outside its range is moved to the nearest
        end (``notes`` says which); an option whose value is not a choice is left out
        (Optuna draws it).
        """
        params, notes, chosen = {}, [], dict(base_values)
        for d in self.dimensions:
            if d.choices:
                value = base_values[d.param]
                if value in d.choices:
                    params[d.key] = value
                else:
                    notes.append(f"{d.key}: the file's {value!r} is not a choice (drawn)")
                continue
            value = 1.0 if d.mode == "scale" else float(base_values[d.param])
            low = d.low
            if d.mode == "set" and d.param == "alpha":
                low = max(low, alpha_floor(chosen["gamma"]))
            clipped = min(max(value, low), d.high)
            if clipped != value:
                notes.append(f"{d.key}: the file's {value:g} is outside {d.describe()}, "
                             f"{clipped:g} tried instead")
            params[d.key] = clipped
            if d.mode == "set":
                chosen[d.param] = clipped
        return params, notes


def alpha_floor(gamma):
    """The smallest alpha drawn with ``gamma``: just above gamma/3 (Theorem 1)."""
    return gamma / 3.0 * (1.0 + THEOREM_MARGIN)


def _fail(path, key, message):
    raise SpaceError(f"{path}: {key}: {message}")


def _is_number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def _parse_key(path, key):
    """(mode, param) of a space key; refuses unknown, structural and condition parameters."""
    mode, rest = "set", key
    for prefix in ("set.", "scale."):
        if key.startswith(prefix):
            mode, rest = prefix[:-1], key[len(prefix):]
    section, _, param = rest.partition(".")
    if section != CONTROLLER_SECTION or not param:
        _fail(path, key, f"expected {CONTROLLER_SECTION}.NAME or scale.{CONTROLLER_SECTION}.NAME"
                         " (the controller's gains are tuned, not the simulated world)")
    spec = _SPECS.get(param)
    if spec is None:
        _fail(path, key, f"{param} is not a parameter of {CONTROLLER_SECTION} "
                         "(see config/controller.py)")
    if spec.structure:
        _fail(path, key, f"{param} defines the model's structure, it is not a gain")
    if param in CONDITION_PARAMS:
        _fail(path, key, f"{param} is drawn by the randomized runs (estimate errors), "
                         "it is not a gain")
    if mode == "scale" and param in ("alpha", "gamma"):
        _fail(path, key, f"tune {CONTROLLER_SECTION}.{param} itself (Theorem 1's "
                         "alpha > gamma/3 is kept on the values)")
    return mode, param, spec


def _file_condition(path, key, body, file_params):
    """Why the dimension does not apply to this file ('' when it does)."""
    for condition in _CONDITION_KEYS:
        name = body.get(condition)
        if name is None:
            continue
        if not isinstance(name, str) or name not in _SPECS:
            _fail(path, f"{key}.{condition}", f"must name a parameter of {CONTROLLER_SECTION}, "
                                              f"got {name!r}")
        given = name in file_params
        if given != (condition == "when_file_sets"):
            return (f"the file {'sets' if given else 'does not set'} {CONTROLLER_SECTION}."
                    f"{name} ({condition})")
    return ""


def _parse_dimension(path, key, body):
    mode, param, spec = _parse_key(path, key)
    if not isinstance(body, dict) or not body:
        _fail(path, key, f"must be {{low: L, high: H, log: true|false}} or {{choices: [...]}}, "
                         f"got {body!r}")
    body = {k: v for k, v in body.items() if k not in _CONDITION_KEYS}
    if "choices" in body:
        if set(body) != {"choices"}:
            _fail(path, key, "choices takes no other key")
        choices = body["choices"]
        if mode != "set" or not isinstance(choices, list) or len(choices) < 2:
            _fail(path, key, f"choices must be a list of at least two values of "
                             f"{CONTROLLER_SECTION}.{param}, got {choices!r}")
        if param in ("alpha", "gamma"):
            _fail(path, key, "takes a range {low, high} (Theorem 1 is kept on ranges)")
        return Dimension(key, mode, param, choices=tuple(choices))
    unknown = sorted(set(map(str, body)) - _RANGE_KEYS)
    if unknown:
        _fail(path, key, f"unknown key {unknown[0]!r} (keys: low, high, log; or choices; "
                         "when_file_sets, unless_file_sets)")
    low, high, log = body.get("low"), body.get("high"), body.get("log", False)
    if not (_is_number(low) and _is_number(high)) or not low < high:
        _fail(path, key, f"needs numbers low < high, got low={low!r}, high={high!r}")
    if not isinstance(log, bool):
        _fail(path, key, f"log must be true or false, got {log!r}")
    if log and low <= 0:
        _fail(path, key, f"a log range needs low > 0, got {low!r}")
    if mode == "scale":
        if low <= 0:
            _fail(path, key, f"a scale factor must be > 0, got low={low!r}")
        if spec.kind not in ("float", "float_list"):
            _fail(path, key, f"{param} is a {spec.kind}, not a number or a list of numbers")
    elif spec.kind != "float":
        hint = (f"; tune scale.{CONTROLLER_SECTION}.{param} (x the file's values) instead"
                if spec.kind == "float_list" else "; give choices instead")
        _fail(path, key, f"{param} is a {spec.kind}, a range sets a number{hint}")
    return Dimension(key, mode, param, float(low), float(high), log)


def _range_text(spec):
    low = "-inf" if spec.low is None else f"{spec.low:g}"
    high = "inf" if spec.high is None else f"{spec.high:g}"
    return f"[{low}, {high}]"


def _check_ends(path, d, base_values):
    """Both ends of a range are valid values of the parameter (a scaled list element-wise)."""
    spec = _SPECS[d.param]
    for end, factor in (("low", d.low), ("high", d.high)):
        values = (np.atleast_1d(np.asarray(base_values[d.param], dtype=float)) * factor
                  if d.mode == "scale" else np.array([factor]))
        bad = [v for v in values if (spec.low is not None and v < spec.low)
               or (spec.high is not None and v > spec.high)]
        if bad:
            what = (f"x the file's value gives {bad[0]:g}" if d.mode == "scale"
                    else f"= {factor:g}")
            _fail(path, d.key, f"{end} {what}, outside {d.target}'s valid range "
                               f"{_range_text(spec)}")


def _check_theorem(path, dims, base_values):
    alpha, gamma = dims.get("alpha"), dims.get("gamma")
    if alpha is not None and gamma is not None:
        if not alpha.high > gamma.high / 3.0:
            _fail(path, gamma.key, f"high {gamma.high:g} needs alpha > {gamma.high / 3:g} "
                                   f"(Theorem 1: alpha > gamma/3) but alpha's high is "
                                   f"{alpha.high:g}; lower gamma's high or raise alpha's")
    elif alpha is not None:
        gamma_value = base_values["gamma"]
        if not alpha.high > gamma_value / 3.0:
            _fail(path, alpha.key, f"high {alpha.high:g} is not above gamma/3 = "
                                   f"{gamma_value / 3:g} with the file's gamma {gamma_value:g} "
                                   "(Theorem 1: alpha > gamma/3)")
    elif gamma is not None:
        alpha_value = base_values["alpha"]
        if not gamma.high < 3.0 * alpha_value:
            _fail(path, gamma.key, f"high {gamma.high:g} breaks Theorem 1 with the file's alpha "
                                   f"{alpha_value:g} (needs gamma < 3 alpha = "
                                   f"{3 * alpha_value:g}); tune alpha too or lower the high")


def _validate_config(path, d, file_params, base_values, model, search_dirs):
    """The controller's whole configuration validates with ``d`` at either end."""
    if d.param in ("alpha", "gamma"):
        return      # their pair is _check_theorem's; their ranges are _check_ends'
    for end in (d.choices or (d.low, d.high)):
        params = dict(file_params)
        if d.mode == "scale":
            params[d.param] = (np.asarray(base_values[d.param], dtype=float) * end).tolist()
        else:
            params[d.param] = end
        try:
            ControllerConfig.from_params(params, search_dirs=search_dirs, model=model)
        except ConfigError as exc:
            _fail(path, d.key, f"with {end!r} the configuration is refused: {exc}")


#: the controller parameters whose only role is to set other parameters' defaults (gamma also
#: sets alpha's, but is a gain itself)
DEFAULT_ONLY = ("Gamma_d_normalized",)


def shadowing(d, file_params, model, search_dirs):
    """The parameters whose explicit values in the file make ``d`` ineffective, or ().

    A parameter that only sets other parameters' defaults (``Gamma_d_normalized``
    sets Gamma_d's) does nothing when the file gives those explicitly.  Found by
    resolving the controller without the file's explicit computed parameters, at
    both ends of ``d``: the computed defaults that change are the ones ``d`` feeds.
    """
    if d.mode != "set" or d.choices or d.param not in DEFAULT_ONLY:
        return ()
    computed = {s.name for s in CONTROLLER_PARAMS if s.computed}
    free = {k: v for k, v in file_params.items() if k not in computed}
    try:
        ends = [ControllerConfig.from_params({**free, d.param: value}, search_dirs=search_dirs,
                                             model=model).params
                for value in (d.low, d.high)]
    except ConfigError:
        return ()
    fed = [name for name in sorted(computed) if name != d.param
           and not np.array_equal(np.asarray(ends[0][name]), np.asarray(ends[1][name]))]
    if fed and all(name in file_params for name in fed):
        return tuple(fed)
    return ()


def load_space(path, scenario, file_params, drop_shadowed=False):
    """Read and validate a space file against a base configuration.

    Parameters
    ----------
    path : str
        The space YAML.
    scenario : config.Scenario
        The validated base configuration (its resolved controller values and model).
    file_params : dict
        The controller parameters the configuration file gives explicitly (flat).
    drop_shadowed : bool
        Leave out (instead of refusing) a dimension the file makes ineffective
        (:func:`shadowing`): the shipped default space has to suit every file.
    """
    path = os.path.abspath(path)
    try:
        with open(path, encoding="utf-8") as handle:
            raw = yaml.safe_load(handle)
    except OSError as exc:
        raise SpaceError(f"--space {path}: cannot read it: {exc.strerror}") from None
    except yaml.YAMLError as exc:
        raise SpaceError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(raw, dict) or not raw:
        raise SpaceError(f"{path}: must be a mapping of {CONTROLLER_SECTION}.NAME: "
                         "{low, high, log} (or {choices: [...]})")
    base_values = scenario.controller.params
    model = scenario.controller.model
    search_dirs = scenario.controller.search_dirs
    dims, targets, dropped = {}, {}, []
    for key, body in raw.items():
        d = _parse_dimension(path, str(key), body)
        skip = _file_condition(path, d.key, body, file_params)
        if skip:
            dropped.append((d.key, skip))
            continue
        if d.param in targets:
            _fail(path, d.key, f"{d.target} is also tuned by {targets[d.param]}")
        targets[d.param] = d.key
        dims[d.param] = d
    _check_theorem(path, dims, base_values)
    for d in list(dims.values()):
        if not d.choices:
            _check_ends(path, d, base_values)
        _validate_config(path, d, file_params, base_values, model, search_dirs)
        fed = shadowing(d, file_params, model, search_dirs)
        if fed:
            why = (f"only sets the default of {', '.join(fed)}, which the configuration gives "
                   f"explicitly: remove {', '.join(fed)} from the file to tune it")
            if not drop_shadowed:
                _fail(path, d.key, why)
            dropped.append((d.key, why))
            del dims[d.param]
    if not dims:
        raise SpaceError(f"{path}: no dimension left to tune")
    order = sorted(dims.values(), key=lambda d: (d.param != "gamma", d.param != "alpha"))
    return SearchSpace(path, tuple(order), tuple(dropped))
