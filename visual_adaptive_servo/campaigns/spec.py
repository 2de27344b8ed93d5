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

"""Campaign specifications: one YAML file that names many closed-loop runs.

A spec names a base configuration, a duration, and the factors that vary::

    base: paper_3dof.yaml          # relative to the spec file, else the package's config/
    duration: 10.0                 # simulated seconds per run
    fixed:                         # factor values shared by every run (optional)
      set.controller_node.start_blend_time: 2.0
    cases:                         # named sets of factor values (optional)
      - {name: clean, pixel_noise: 0.0}
      - {name: noisy, base: paper_3dof_noisy.yaml, pixel_noise: 1.0}
    grid:                          # cartesian product of lists (optional)
      controller: [observer, velocity-lp]
    random:                        # N reproducible draws (optional)
      runs: 100
      seed: 1
      factors:
        start_offset_px: {uniform: [0.0, 50.0]}
        estimate_scale.a_z: {log_uniform: [0.5, 2.0]}
        seed: {integer: [0, 1000000]}

At least one of ``cases``, ``grid`` and ``random`` is given; together they
multiply: every draw runs every case with every grid combination (draws
outermost, so the cases and controllers of one draw see the same conditions).
That is how ``vas compare`` (a grid of controller x condition, the conditions
as cases) and ``vas robustness`` (named cases) are expressed.  A ``duration``
factor gives one case (or grid level) its own simulated seconds.

Factors (:data:`FACTOR_HELP`):

* ``set.<section.param>``: the parameter's value; ``scale.<section.param>``: the
  base configuration's value (number or list) times the factor;
* ``pixel_noise`` [px] = ``set.sim_node.pixel_noise_std``, ``camera_latency`` [s] =
  ``set.sim_node.camera_latency``, ``seed`` = ``set.sim_node.seed``;
* ``start_offset_px`` [px] (with ``start_offset_angle_deg``, default the direction
  (0.6, -0.8) of ``vas robustness``): joint positions near the initial ones whose
  feature is that far from the trajectory start x_d(0), found by
  :func:`joints_seeing`; ``start_offset_joint`` [rad] (a number or
  one per joint) is then added to the initial positions;
* ``estimate_scale.<a_z_perp|a_z|a_d>``: initial estimate = the model's true
  parameters times the factor;
* ``gain_scale.<K|alpha|gamma|Gamma_d|Gamma_z_perp|Gamma_z>``: the base gain times
  the factor (a gain the base leaves out is derived and then scaled, through
  ``gain_design.scale.<gain>``); ``trajectory.amplitude_scale`` (a_cos, a_sin) and
  ``trajectory.frequency_scale`` (omega) likewise;
* ``controller``: one of
  :data:`~visual_adaptive_servo.control.registry.CONTROLLER_NAMES`; ``base``: another
  base configuration for this run.

Every run resolves to plain ``section.param=value`` overrides, a controller and a
duration: :attr:`Run.command` is the ``vas run`` command line that repeats it.
"""

from __future__ import annotations

import difflib
import hashlib
import itertools
import json
import math
import os
import shlex
from dataclasses import dataclass, field

import numpy as np
import yaml

from ..config.controller import CONTROLLER_PARAMS
from ..config.scenario import load_scenario
from ..config.sim import SIM_PARAMS
from ..control.registry import CONTROLLER_NAMES
from ..control.trajectory import SinusoidTrajectory
from ..models.resources import OWN_SHARE
from ..schema import CONTROLLER_SECTION, ConfigError, SIM_SECTION

PACKAGE_CONFIG = OWN_SHARE["config"]
DEFAULT_CONTROLLER = "observer"
ALIASES = {"pixel_noise": f"{SIM_SECTION}.pixel_noise_std",
           "camera_latency": f"{SIM_SECTION}.camera_latency",
           "seed": f"{SIM_SECTION}.seed"}
ESTIMATES = ("a_z_perp", "a_z", "a_d")
GAINS = ("K", "alpha", "gamma", "Gamma_d", "Gamma_z_perp", "Gamma_z")
TRAJECTORY_SCALES = {"trajectory.amplitude_scale": ("trajectory.a_cos", "trajectory.a_sin"),
                     "trajectory.frequency_scale": ("trajectory.omega",)}
START_KEYS = ("start_offset_px", "start_offset_angle_deg", "start_offset_joint")
ROBUSTNESS_DIRECTION = (0.6, -0.8)
DISTRIBUTIONS = ("uniform", "log_uniform", "choice", "integer")
TOP_LEVEL = ("base", "duration", "description", "fixed", "cases", "grid", "random")
FACTOR_HELP = ("set.<section.param>, scale.<section.param>, pixel_noise, camera_latency, seed, "
               "start_offset_px, start_offset_angle_deg, start_offset_joint, "
               f"estimate_scale.<{'|'.join(ESTIMATES)}>, gain_scale.<{'|'.join(GAINS)}>, "
               "trajectory.amplitude_scale, trajectory.frequency_scale, controller, base, "
               "duration")
_PARAM_NAMES = {SIM_SECTION: {s.name for s in SIM_PARAMS},
                CONTROLLER_SECTION: {s.name for s in CONTROLLER_PARAMS}}
_PARAM_FILES = {SIM_SECTION: "sim.py", CONTROLLER_SECTION: "controller.py"}


class SpecError(ConfigError):
    """A campaign spec breaks a rule (the message names the spec file and the key)."""


@dataclass(frozen=True)
class Run:
    """One resolved run: what ``vas run`` needs to repeat it, and the factor values.

    ``index`` is its place in the campaign's run list (the ``id`` of its row).
    ``factors`` holds the values of the campaign's varying factors (``case`` for the
    case name), in column order.  ``problem`` is set when the factors cannot be
    realised (e.g. no joint positions see the offset start): the run is then
    recorded as failed without being started.
    """

    index: int
    factors: dict = field(compare=False)
    base: str
    duration: float
    controller: str
    overrides: tuple
    problem: str = ""

    @property
    def command(self):
        """The ``vas run`` command line that repeats this run (shell-quoted)."""
        words = ["vas", "run", "--config", self.base, "--duration", repr(self.duration)]
        if self.controller != DEFAULT_CONTROLLER:
            words += ["--controller", self.controller]
        for item in self.overrides:
            words += ["--set", item]
        words += ["--out", f"vas-run-{self.index}", "--no-bag"]
        return " ".join(shlex.quote(w) for w in words)


@dataclass(frozen=True)
class Distribution:
    """One random factor: ``kind`` in :data:`DISTRIBUTIONS` and its arguments."""

    kind: str
    args: tuple

    def draw(self, rng):
        if self.kind == "uniform":
            return float(rng.uniform(*self.args))
        if self.kind == "log_uniform":
            low, high = self.args
            return float(math.exp(rng.uniform(math.log(low), math.log(high))))
        if self.kind == "integer":
            return int(rng.integers(self.args[0], self.args[1] + 1))
        return self.args[int(rng.integers(len(self.args)))]


@dataclass(frozen=True)
class CampaignSpec:
    """A validated campaign spec; :meth:`runs` resolves every run."""

    path: str
    base: str
    duration: float
    fixed: dict
    cases: tuple
    grid: dict
    draws: int
    draw_seed: int
    random: dict
    raw: dict = field(repr=False)

    @property
    def name(self):
        return os.path.splitext(os.path.basename(self.path))[0]

    @property
    def factor_columns(self):
        """Names of the factors that vary from run to run, in column order."""
        columns = ["case"] if self.cases else []
        for case in self.cases:
            columns += [k for k in case if k != "name" and k not in columns]
        return columns + list(self.grid) + list(self.random)

    @property
    def level_factors(self):
        """Factors whose values are levels: case columns, grid factors, random choices."""
        columns = [c for c in self.factor_columns if c not in self.random]
        return columns + [k for k, dist in self.random.items() if dist.kind == "choice"]

    @property
    def sampled_factors(self):
        """Factors drawn at random or laid on the grid (one plot each)."""
        return list(self.grid) + list(self.random)

    def resolve_base(self, name):
        """The path of a base configuration named in the spec."""
        return _resolve_base(name, os.path.dirname(self.path), self.path, "base")

    def bases(self):
        """Every base configuration a run can use (resolved paths)."""
        names = [self.raw["base"], *self.grid.get("base", ()), self.fixed.get("base")]
        names += [c["base"] for c in self.cases if "base" in c]
        names += list(self.random["base"].args) if "base" in self.random else []
        return list(dict.fromkeys(self.resolve_base(n) for n in names if n is not None))

    def fingerprint(self):
        """sha256 of the spec's content and of every base configuration file it uses.

        The content with its keys sorted, plus the order of the random factors and of the
        grid's keys: the draws take the factors in file order (one generator per draw) and
        the grid's product its keys, so the same factors in another order are other runs.
        """
        digest = hashlib.sha256(json.dumps(self.raw, sort_keys=True, default=str).encode())
        digest.update(json.dumps({"random": list(self.random), "grid": list(self.grid)},
                                 default=str).encode())
        for path in self.bases():
            with open(path, "rb") as handle:
                digest.update(hashlib.sha256(handle.read()).digest())
        return digest.hexdigest()

    def factor_sets(self):
        """Yield (varying factor values, all factor values) of every run, in run order."""
        grid_keys = list(self.grid)
        for draw in range(self.draws if self.random else 1):
            rng = np.random.default_rng([self.draw_seed, draw])
            drawn = {key: dist.draw(rng) for key, dist in self.random.items()}
            for case in self.cases or ({},):
                for combo in itertools.product(*self.grid.values()):
                    varying = {"case": case["name"]} if self.cases else {}
                    varying.update({k: v for k, v in case.items() if k != "name"})
                    varying.update(zip(grid_keys, combo))
                    varying.update(drawn)
                    yield varying, {**self.fixed, **varying}

    def runs(self):
        """Every run of the campaign, resolved (:class:`Run`), in run order."""
        scenarios = {}
        runs = []
        for run_id, (varying, factors) in enumerate(self.factor_sets()):
            base = self.resolve_base(factors["base"]) if "base" in factors else self.base
            if base not in scenarios:
                scenarios[base] = load_scenario(base)
            controller = factors.get("controller", DEFAULT_CONTROLLER)
            overrides, problem = resolve_overrides(factors, scenarios[base])
            duration = float(factors.get("duration", self.duration))
            runs.append(Run(run_id, varying, base, duration, controller, overrides, problem))
        return runs


def derived_spec(path, out_path, duration=None, fixed=None):
    """Write a copy of the spec at ``path`` with another duration / extra fixed factors.

    Base configurations named relative to the original spec are made absolute, so the
    copy (written to ``out_path``) names the same files.  Returns ``out_path``.
    """
    with open(path, encoding="utf-8") as handle:
        body = yaml.safe_load(handle)
    spec_dir = os.path.dirname(os.path.abspath(path))

    def absolute(name):
        candidate = os.path.join(spec_dir, name)
        return os.path.abspath(candidate) if os.path.isfile(candidate) else name

    body["base"] = absolute(body["base"])
    for case in body.get("cases", ()):
        if "base" in case:
            case["base"] = absolute(case["base"])
    if "base" in body.get("grid", {}):
        body["grid"]["base"] = [absolute(b) for b in body["grid"]["base"]]
    if duration is not None:
        body["duration"] = float(duration)
    if fixed:
        body.setdefault("fixed", {}).update(fixed)
    os.makedirs(os.path.dirname(os.path.abspath(out_path)), exist_ok=True)
    with open(out_path, "w", encoding="utf-8") as handle:
        yaml.safe_dump(body, handle, sort_keys=False)
    return out_path


def _fail(path, where, message):
    raise SpecError(f"{path}: {where}: {message}")


def _is_number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def _resolve_base(value, spec_dir, path, where):
    if not isinstance(value, str) or not value:
        _fail(path, where, f"must be a configuration file name, got {value!r}")
    for candidate in (os.path.join(spec_dir, value), os.path.join(PACKAGE_CONFIG, value)):
        if os.path.isfile(candidate):
            return os.path.abspath(candidate)
    _fail(path, where, f"{value!r} is neither beside the spec nor in {PACKAGE_CONFIG}")


def _target_param(target, path, where):
    section, _, name = target.partition(".")
    if section not in _PARAM_NAMES or not name:
        _fail(path, where, f"expected {SIM_SECTION}.NAME or {CONTROLLER_SECTION}.NAME, "
                           f"got {target!r}")
    if name not in _PARAM_NAMES[section]:
        close = difflib.get_close_matches(name, _PARAM_NAMES[section], n=3)
        hint = f"did you mean {', '.join(close)}? " if close else ""
        _fail(path, where, f"{target} is not a parameter of {section} ({hint}the parameters: "
                           f"visual_adaptive_servo/config/{_PARAM_FILES[section]})")
    return target


def factor_targets(key, path, where):
    """The parameters a factor writes ('section.param'); refuses unknown factors."""
    if key.startswith(("set.", "scale.")):
        return (_target_param(key.partition(".")[2], path, where),)
    if key in ALIASES:
        return (_target_param(ALIASES[key], path, where),)
    prefix, _, name = key.partition(".")
    if prefix == "estimate_scale" and name in ESTIMATES:
        return (f"{CONTROLLER_SECTION}.{name}_init",)
    if prefix == "gain_scale" and name in GAINS:
        return (f"{CONTROLLER_SECTION}.{name}",)
    if key in TRAJECTORY_SCALES:
        return tuple(f"{CONTROLLER_SECTION}.{t}" for t in TRAJECTORY_SCALES[key])
    if key in START_KEYS:
        return ("start",)
    if key in ("controller", "base", "duration"):
        return (key,)
    _fail(path, where, f"unknown factor {key!r} (factors: {FACTOR_HELP})")


def check_value(key, value, spec_dir, path, where):
    """Validate one factor value; returns it."""
    if key == "base":
        _resolve_base(value, spec_dir, path, where)
    elif key == "controller":
        if value not in CONTROLLER_NAMES:
            _fail(path, where, f"must be one of {list(CONTROLLER_NAMES)}, got {value!r}")
    elif key == "seed":
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**31:
            _fail(path, where, f"must be an integer in [0, 2**31), got {value!r}")
    elif key == "duration":
        if not _is_number(value) or value <= 0:
            _fail(path, where, f"must be a number of seconds > 0, got {value!r}")
    elif key in ("pixel_noise", "camera_latency", "start_offset_px"):
        if not _is_number(value) or value < 0:
            _fail(path, where, f"must be a number >= 0, got {value!r}")
    elif key in ("start_offset_angle_deg",) or key.startswith("scale."):
        if not _is_number(value):
            _fail(path, where, f"must be a finite number, got {value!r}")
    elif key == "start_offset_joint":
        values = value if isinstance(value, list) else [value]
        if not values or not all(_is_number(v) for v in values):
            _fail(path, where, f"must be a number or a list of numbers [rad], got {value!r}")
    elif key.startswith(("estimate_scale.", "gain_scale.", "trajectory.")):
        if not _is_number(value) or value <= 0:
            _fail(path, where, f"must be a number > 0, got {value!r}")
    elif isinstance(value, dict) or value is None:
        _fail(path, where, f"must be a number, string, boolean or list, got {value!r}")
    return value


def _check_distribution(key, body, spec_dir, path, where):
    if not isinstance(body, dict) or len(body) != 1 or next(iter(body)) not in DISTRIBUTIONS:
        _fail(path, where, f"must be one of {{uniform: [low, high]}}, {{log_uniform: "
                           f"[low, high]}}, {{integer: [low, high]}}, {{choice: [values]}}, "
                           f"got {body!r}")
    kind, args = next(iter(body.items()))
    where = f"{where}.{kind}"
    if not isinstance(args, list) or not args:
        _fail(path, where, f"must be a non-empty list, got {args!r}")
    if key in ("controller", "base") and kind != "choice":
        _fail(path, where, f"{key} takes a choice, not a range")
    if key == "seed" and kind not in ("integer", "choice"):
        _fail(path, where, "seed takes {integer: [low, high]} or a choice")
    if kind == "choice":
        return Distribution(kind, tuple(check_value(key, v, spec_dir, path, where)
                                        for v in args))
    if len(args) != 2 or not all(_is_number(v) for v in args) or not args[0] < args[1]:
        _fail(path, where, f"needs [low, high] with low < high, got {args!r}")
    if kind == "log_uniform" and args[0] <= 0:
        _fail(path, where, f"needs 0 < low, got {args!r}")
    if kind == "integer" and not all(isinstance(v, int) for v in args):
        _fail(path, where, f"needs integer bounds, got {args!r}")
    # the bounds must be valid values themselves (the draws lie between them)
    for v in args:
        check_value(key, v, spec_dir, path, where)
    return Distribution(kind, tuple(args))


def _check_factor_map(body, spec_dir, path, where):
    if not isinstance(body, dict) or not body:
        _fail(path, where, f"must be a mapping of factor: value, got {body!r}")
    out = {}
    for key, value in body.items():
        factor_targets(str(key), path, f"{where}.{key}")
        out[str(key)] = check_value(str(key), value, spec_dir, path, f"{where}.{key}")
    return out


def load_spec(path):
    """Read and validate a campaign spec (every error names the file and the key)."""
    path = os.path.abspath(path)
    spec_dir = os.path.dirname(path)
    with open(path, encoding="utf-8") as handle:
        try:
            raw = yaml.safe_load(handle)
        except yaml.YAMLError as exc:
            raise SpecError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(raw, dict):
        raise SpecError(f"{path}: must be a mapping with base, duration and cases, grid "
                        f"or random")
    unknown = sorted(set(map(str, raw)) - set(TOP_LEVEL))
    if unknown:
        _fail(path, unknown[0], f"unknown key (keys: {', '.join(TOP_LEVEL)})")
    if "base" not in raw:
        _fail(path, "base", "missing: the base configuration, e.g. paper_3dof.yaml")
    base = _resolve_base(raw["base"], spec_dir, path, "base")
    duration = raw.get("duration")
    if not _is_number(duration) or duration <= 0:
        _fail(path, "duration", f"must be simulated seconds > 0, got {duration!r}")
    if not any(k in raw for k in ("cases", "grid", "random")):
        _fail(path, "cases/grid/random", "missing: give at least one of them")
    fixed = _check_factor_map(raw["fixed"], spec_dir, path, "fixed") if "fixed" in raw else {}
    cases = _check_cases(raw.get("cases"), spec_dir, path) if "cases" in raw else ()
    grid = _check_grid(raw["grid"], spec_dir, path) if "grid" in raw else {}
    draws, draw_seed, random = (_check_random(raw["random"], spec_dir, path)
                                if "random" in raw else (0, 0, {}))
    spec = CampaignSpec(path, base, float(duration), fixed, cases, grid, draws, draw_seed,
                        random, raw)
    _check_overlaps(spec, path)
    return spec


def _check_cases(body, spec_dir, path):
    if not isinstance(body, list) or not body:
        _fail(path, "cases", f"must be a non-empty list of mappings, got {body!r}")
    cases, names = [], set()
    for i, case in enumerate(body):
        where = f"cases[{i}]"
        if not isinstance(case, dict):
            _fail(path, where, f"must be a mapping with a name and factor values, got {case!r}")
        name = case.get("name")
        if not isinstance(name, str) or not name:
            _fail(path, f"{where}.name", f"missing: every case needs a name, got {name!r}")
        if name in names:
            _fail(path, f"{where}.name", f"{name!r} is used by an earlier case")
        names.add(name)
        rest = {k: v for k, v in case.items() if k != "name"}
        cases.append({"name": name, **(_check_factor_map(rest, spec_dir, path, where)
                                       if rest else {})})
    return tuple(cases)


def _check_grid(body, spec_dir, path):
    if not isinstance(body, dict) or not body:
        _fail(path, "grid", f"must be a mapping of factor: [values], got {body!r}")
    grid = {}
    for key, values in body.items():
        where = f"grid.{key}"
        factor_targets(str(key), path, where)
        if not isinstance(values, list) or not values:
            _fail(path, where, f"must be a non-empty list of values, got {values!r}")
        grid[str(key)] = tuple(check_value(str(key), v, spec_dir, path, f"{where}[{i}]")
                               for i, v in enumerate(values))
    return grid


def _check_random(body, spec_dir, path):
    if not isinstance(body, dict):
        _fail(path, "random", f"must be a mapping with runs, seed and factors, got {body!r}")
    unknown = sorted(set(map(str, body)) - {"runs", "seed", "factors"})
    if unknown:
        _fail(path, f"random.{unknown[0]}", "unknown key (keys: runs, seed, factors)")
    runs = body.get("runs")
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        _fail(path, "random.runs", f"must be an integer >= 1 (the number of draws), got {runs!r}")
    seed = body.get("seed")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        _fail(path, "random.seed", f"must be an integer >= 0 (makes the draws reproducible), "
                                   f"got {seed!r}")
    factors = body.get("factors")
    if not isinstance(factors, dict) or not factors:
        _fail(path, "random.factors", f"must be a mapping of factor: distribution, "
                                      f"got {factors!r}")
    random = {}
    for key, dist in factors.items():
        where = f"random.factors.{key}"
        factor_targets(str(key), path, where)
        random[str(key)] = _check_distribution(str(key), dist, spec_dir, path, where)
    return runs, seed, random


def _check_overlaps(spec, path):
    """One value per factor and per parameter, whatever case a run belongs to."""
    sections = [("fixed", spec.fixed), ("grid", spec.grid), ("random.factors", spec.random)]
    for i, case in enumerate(spec.cases or ({"name": None},)):
        keys = {}
        case_keys = {k: v for k, v in case.items() if k != "name"}
        for where, body in [(f"cases[{i}]", case_keys)] + sections:
            for key in body:
                if key in keys:
                    _fail(path, f"{where}.{key}", f"also given in {keys[key]}")
                keys[key] = where
        targets = {}
        for key, where in keys.items():
            for target in factor_targets(key, path, where):
                if target in targets and target != "start":
                    _fail(path, f"{where}.{key}", f"sets {target}, as {targets[target]} does")
                targets[target] = f"{where}.{key}"
        if "start_offset_angle_deg" in keys and "start_offset_px" not in keys:
            _fail(path, f"{keys['start_offset_angle_deg']}.start_offset_angle_deg",
                  "needs start_offset_px (the distance in that direction)")


def yaml_text(value):
    """``value`` as YAML text that reads back to exactly the same value."""
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if math.isnan(value):
            return ".nan"
        if math.isinf(value):
            return ".inf" if value > 0 else "-.inf"
        return repr(value)      # shortest text that reads back to the same float
    if isinstance(value, str):
        return json.dumps(value)        # a JSON string is a YAML string
    if isinstance(value, (list, tuple, np.ndarray)):
        return "[" + ", ".join(yaml_text(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} as a parameter value")


def _scaled(value, factor):
    if isinstance(value, np.ndarray):
        return (value * factor).tolist()
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value) * factor
    raise TypeError(f"cannot scale {value!r}")


def resolve_overrides(factors, base):
    """``section.param=value`` overrides realising ``factors`` on the base scenario.

    Parameters
    ----------
    factors : dict
        Factor name -> value, validated (one value per parameter).
    base : config.Scenario
        The validated base configuration (values of ``scale.`` factors, the model's
        true parameters, the initial positions and trajectory start).

    Returns
    -------
    (tuple of str, str)
        The overrides sorted by parameter name, and a problem ('' when none).
    """
    params = {SIM_SECTION: base.sim.params, CONTROLLER_SECTION: base.controller.params}
    model = base.controller.model
    values = {}

    def base_value(target):
        section, _, name = target.partition(".")
        return params[section][name]

    for key, value in factors.items():
        prefix, _, rest = key.partition(".")
        if prefix == "set":
            values[rest] = value
        elif prefix == "scale":
            try:
                values[rest] = _scaled(base_value(rest), value)
            except TypeError:
                return (), f"{key}: {rest} is not a number or a list of numbers"
        elif key in ALIASES:
            values[ALIASES[key]] = value
        elif prefix == "estimate_scale":
            values[f"{CONTROLLER_SECTION}.{rest}_init"] = (getattr(model, rest) * value).tolist()
        elif prefix == "gain_scale":
            target = f"{CONTROLLER_SECTION}.{rest}"
            if base_value(target) is None:
                # a gain the base leaves to the design: scale what the design derives
                target = f"{CONTROLLER_SECTION}.gain_design.scale.{rest}"
            values[target] = _scaled(base_value(target), value)
        elif key in TRAJECTORY_SCALES:
            for name in TRAJECTORY_SCALES[key]:
                target = f"{CONTROLLER_SECTION}.{name}"
                values[target] = _scaled(base_value(target), value)
    problem = ""
    if any(k in factors for k in START_KEYS):
        q, problem = _start_positions(factors, values, base, base_value)
        values[f"{SIM_SECTION}.initial_positions"] = q
    overrides = tuple(f"{k}={yaml_text(values[k])}" for k in sorted(values))
    return overrides, problem


def _start_positions(factors, values, base, base_value):
    """Initial joint positions [rad] of the start_offset factors, and a problem or ''."""
    model = base.controller.model              # with the simulator's ground truth
    key = f"{SIM_SECTION}.initial_positions"
    q = np.array(values.get(key, base_value(key)), dtype=float)
    if "start_offset_px" in factors:
        if base.controller["trajectory.type"] == "sinusoid":
            traj = [np.asarray(values.get(f"{CONTROLLER_SECTION}.trajectory.{name}",
                                          base_value(f"{CONTROLLER_SECTION}.trajectory.{name}")),
                               dtype=float) for name in ("offset", "a_cos", "a_sin", "omega")]
            x_start = SinusoidTrajectory(*traj[:3], float(traj[3]))(0.0)[0]
        else:
            x_start = base.controller.trajectory(0.0)[0]
        if "start_offset_angle_deg" in factors:
            angle = math.radians(factors["start_offset_angle_deg"])
            direction = np.array([math.cos(angle), math.sin(angle)])
        else:
            direction = np.array(ROBUSTNESS_DIRECTION)
        target = x_start + factors["start_offset_px"] * np.tile(direction, model.m)
        try:
            q = joints_seeing(model, target, q)
        except (ValueError, np.linalg.LinAlgError) as exc:
            return q.tolist(), f"start_offset_px: {exc}"
    if "start_offset_joint" in factors:
        offset = np.array(factors["start_offset_joint"], dtype=float).reshape(-1)
        if offset.size not in (1, model.n):
            return q.tolist(), (f"start_offset_joint: needs 1 or {model.n} values, "
                                f"got {offset.size}")
        q = q + offset
    return q.tolist(), ""


def joints_seeing(model, pixels, q_start, iterations=50):
    """Joint positions near ``q_start`` whose features project to ``pixels`` (Newton)."""
    q = np.array(q_start, dtype=float)
    for _ in range(iterations):
        x, z = model.project(q)
        err = pixels - x
        if np.max(np.abs(err)) < 1e-9:
            return q
        J = model.true_image_jacobian(q, x) / np.repeat(z, 2)[:, None]
        q = q + np.linalg.pinv(J) @ err
    raise ValueError(f"no joint positions near {list(q_start)} see the feature at {pixels}")
