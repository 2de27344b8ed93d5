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

"""Configuration: one ROS-style YAML file configures the simulator and the controller.

The file has a ``sim_node:`` and a ``controller_node:`` section, each with
``ros__parameters:``; nested mappings become dotted parameter names
(``projection: {min_depth: 0.5}`` is ``projection.min_depth``), exactly as
ROS 2 flattens them.  The same schema (:data:`SIM_PARAMS`,
:data:`CONTROLLER_PARAMS`) drives the ROS nodes' parameter declarations and
``vas run``, and :meth:`SimConfig.from_params` / :meth:`ControllerConfig.from_params`
validate a complete parameter set at once: an invalid value is refused with the
parameter name and the rule it breaks, and nothing is partially applied.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import yaml

from .model import RobotCameraModel, make_model

SIM_SECTION = "sim_node"
CONTROLLER_SECTION = "controller_node"
TIMING_MODES = ("lockstep", "realtime")
FALLBACKS = ("gravity_compensation", "zero_torque")


class ConfigError(ValueError):
    """A configuration value is missing, unknown or breaks a rule (message names it)."""


@dataclass(frozen=True)
class ParamSpec:
    """One declared parameter.

    ``default`` is a value or a callable of the model (for lengths that depend
    on n, m or the parameter counts).  ``kind`` is one of ``float``, ``int``,
    ``bool``, ``str``, ``float_list``, ``str_list``.  ``low``/``high`` are
    inclusive bounds applied to every element.  ``runtime`` marks parameters
    that may safely change while running.
    """

    name: str
    default: Any
    kind: str
    description: str
    low: float | None = None
    high: float | None = None
    runtime: bool = False

    def default_for(self, model):
        return self.default(model) if callable(self.default) else self.default


INF = math.inf

SIM_PARAMS = (
    ParamSpec("model", "paper_rrr", "str", "Robot + camera model name (see model.MODELS)."),
    ParamSpec("urdf", "", "str", "URDF of the arm; empty = the one shipped for the model."),
    ParamSpec("physics_dt", 0.001, "float", "PyBullet physics step [s].", 1e-5, 0.01),
    ParamSpec("control_period", 0.005, "float",
              "Camera frame / control period [s]; a whole multiple of physics_dt.", 1e-4, 1.0),
    ParamSpec("duration", 0.0, "float", "Stop after this simulated time [s]; 0 = run forever.",
              0.0, None),
    ParamSpec("initial_positions", lambda m: [0.0] * m.n, "float_list",
              "Joint positions at start [rad]."),
    ParamSpec("initial_velocities", lambda m: [0.0] * m.n, "float_list",
              "Joint velocities at start [rad/s]."),
    ParamSpec("joint_names", lambda m: [f"joint{i + 1}" for i in range(m.n)], "str_list",
              "Joint names in /joint_states and the command order."),
    ParamSpec("pixel_noise_std", 0.0, "float", "Gaussian pixel noise std [px].", 0.0, 100.0),
    ParamSpec("camera_delay_frames", 0, "int", "Camera latency in whole frames.", 0, 100),
    ParamSpec("seed", 0, "int", "Seed of the pixel noise generator.", 0, 2**31 - 1),
    ParamSpec("image_bounds", [-320.0, 320.0, -240.0, 240.0], "float_list",
              "Image extent [u_min, u_max, v_min, v_max] in px (origin on the optical axis)."),
    ParamSpec("timing_mode", "lockstep", "str",
              "lockstep: wait for the command answering each state; realtime: wall-clock timer."),
    ParamSpec("command_timeout", 1.0, "float",
              "lockstep: wall time to wait for a command before applying zero torque [s].",
              1e-3, 60.0),
    ParamSpec("render.enabled", False, "bool", "Publish the camera view on ~/image."),
    ParamSpec("render.rate", 10.0, "float", "Rendering rate [Hz].", 0.1, 60.0),
    ParamSpec("render.width", 320, "int", "Rendered image width [px].", 16, 1920),
    ParamSpec("render.height", 240, "int", "Rendered image height [px].", 16, 1080),
)

CONTROLLER_PARAMS = (
    ParamSpec("model", "paper_rrr", "str", "Robot + camera model name (see model.MODELS)."),
    ParamSpec("joint_names", lambda m: [f"joint{i + 1}" for i in range(m.n)], "str_list",
              "ROS node: joints taken from /joint_states, in the order of the torque command."),
    ParamSpec("timing_mode", "lockstep", "str",
              "ROS node: QoS of the measurement subscriptions; must match sim_node.timing_mode "
              "(lockstep: reliable; realtime: best-effort sensor data)."),
    ParamSpec("sample_time", 0.005, "float", "Nominal control period T [s].", 1e-5, 1.0),
    ParamSpec("K", lambda m: [0.001] * (2 * m.m), "float_list",
              "Diagonal of the feedback gain K of eq (22), (2m,).", 0.0, None, True),
    ParamSpec("alpha", 10.0, "float", "Observer gain alpha of eq (10); alpha > gamma/3.",
              0.0, None),
    ParamSpec("gamma", 10.0, "float", "Reference gain gamma of eq (18); alpha > gamma/3.",
              0.0, None),
    ParamSpec("Gamma_d", lambda m: [300.0] * m.p_d, "float_list",
              "Diagonal of the dynamic adaptation gain Gamma_d of eq (23).", 0.0, None, True),
    ParamSpec("Gamma_z_perp", lambda m: [600.0] * m.p_perp, "float_list",
              "Diagonal of Gamma_z_perp of eq (24).", 0.0, None, True),
    ParamSpec("Gamma_z", lambda m: [0.2] * m.p_z, "float_list",
              "Diagonal of Gamma_z of eq (25).", 0.0, None, True),
    ParamSpec("a_z_perp_init", lambda m: [1.0] * m.p_perp, "float_list",
              "Initial estimate of the depth-rate-independent parameters a_z_perp."),
    ParamSpec("a_z_init", lambda m: [1.0] * m.p_z, "float_list",
              "Initial estimate of the depth parameters a_z."),
    ParamSpec("a_d_init", lambda m: [0.0] * m.p_d, "float_list",
              "Initial estimate of the dynamic parameters a_d."),
    ParamSpec("trajectory.offset", lambda m: [0.0] * (2 * m.m), "float_list",
              "x_d = offset + a_cos cos(w t) + a_sin sin(w t) [px]."),
    ParamSpec("trajectory.a_cos", lambda m: [0.0] * (2 * m.m), "float_list",
              "Cosine amplitudes of x_d [px]."),
    ParamSpec("trajectory.a_sin", lambda m: [0.0] * (2 * m.m), "float_list",
              "Sine amplitudes of x_d [px]."),
    ParamSpec("trajectory.omega", 0.0, "float", "Angular frequency w of x_d [rad/s].",
              0.0, None),
    ParamSpec("start_blend_time", 2.0, "float",
              "Blend x_d in from the first measured feature over this time [s]; 0 = start "
              "directly on the trajectory (the paper).", 0.0, 60.0),
    ParamSpec("projection.enabled", True, "bool",
              "Project the kinematic adaptation (Remark 6) onto the bounds below."),
    ParamSpec("projection.a_z_perp_min", lambda m: [-INF] * m.p_perp, "float_list",
              "Lower bounds of a_z_perp_hat."),
    ParamSpec("projection.a_z_perp_max", lambda m: [INF] * m.p_perp, "float_list",
              "Upper bounds of a_z_perp_hat."),
    ParamSpec("projection.a_z_min", lambda m: [-INF] * m.p_z, "float_list",
              "Lower bounds of a_z_hat."),
    ParamSpec("projection.a_z_max", lambda m: [INF] * m.p_z, "float_list",
              "Upper bounds of a_z_hat."),
    ParamSpec("projection.a_d_min", lambda m: [-INF] * m.p_d, "float_list",
              "Lower bounds of a_d_hat."),
    ParamSpec("projection.a_d_max", lambda m: [INF] * m.p_d, "float_list",
              "Upper bounds of a_d_hat."),
    ParamSpec("projection.min_depth", 0.1, "float",
              "Smallest allowed estimated depth z_hat_i [m].", 1e-6, None),
    ParamSpec("torque_limit", lambda m: [INF] * m.n, "float_list",
              "Per-joint |tau| limit [N m]; the command saturates there.", 0.0, None, True),
    ParamSpec("min_singular_value", 0.0, "float",
              "Damp the pseudo-inverse of J* when its smallest singular value drops below "
              "this [px m/rad]; 0 = never.", 0.0, None, True),
    ParamSpec("max_dt", 0.05, "float",
              "Longest interval integrated in one step [s]; longer gaps are clamped.",
              1e-5, 10.0),
    ParamSpec("image_bounds", [-320.0, 320.0, -240.0, 240.0], "float_list",
              "Valid feature region [u_min, u_max, v_min, v_max] [px]."),
    ParamSpec("safety.hold_time", 0.05, "float",
              "Hold the last valid command this long after input goes bad [s].", 0.0, 10.0,
              True),
    ParamSpec("safety.camera_timeout", 0.1, "float",
              "No valid feature for this long = stale camera [s].", 1e-3, 60.0, True),
    ParamSpec("safety.recovery_blend_time", 1.0, "float",
              "When a stale camera comes back, blend x_d in again from the measured feature "
              "over this time [s].", 0.0, 60.0, True),
    ParamSpec("safety.fallback", "gravity_compensation", "str",
              "After hold_time: gravity_compensation (estimated g(q) - D q_dot) or zero_torque.",
              runtime=True),
    ParamSpec("safety.fallback_damping", 5.0, "float",
              "Joint damping D of the gravity-compensation fallback [N m s/rad].", 0.0, None,
              True),
    ParamSpec("divergence_torque", 1e5, "float",
              "|tau| above this (before saturation) is reported as divergence [N m].", 0.0, None),
)


def _to_value(spec, value, section):
    where = f"{section}.{spec.name}"
    kind = spec.kind
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


def resolve_params(specs, params, section):
    """Check names and types of a flat parameter dict, fill defaults; return (model, dict)."""
    specs_by_name = {s.name: s for s in specs}
    unknown = sorted(set(params) - set(specs_by_name))
    if unknown:
        raise ConfigError(f"{section}: unknown parameter(s) {unknown}")
    model_name = _to_value(specs_by_name["model"], params.get("model", "paper_rrr"), section)
    try:
        model = make_model(model_name)
    except ValueError as exc:
        raise ConfigError(f"{section}.{exc}") from None
    values = {}
    for spec in specs:
        raw = params.get(spec.name, spec.default_for(model))
        values[spec.name] = _to_value(spec, raw, section)
    return model, values


def _require_length(values, name, length, section):
    if len(values[name]) != length:
        raise ConfigError(f"{section}.{name}: needs {length} values, got {len(values[name])}")


def _require_finite(values, name, section):
    if not np.all(np.isfinite(values[name])):
        raise ConfigError(f"{section}.{name}: must be finite")


@dataclass(frozen=True, eq=False)
class _ValidatedParams:
    """A model plus a complete, validated parameter dict, read as attributes or items."""

    model: RobotCameraModel
    params: dict = field(repr=False)

    def __getattr__(self, name):
        try:
            return self.__dict__["params"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __getitem__(self, name):
        return self.params[name]

    @property
    def model_name(self):
        return self.params["model"]


class SimConfig(_ValidatedParams):
    """Validated parameters of the simulator (``sim_node``)."""

    @classmethod
    def from_params(cls, params, section=SIM_SECTION):
        model, v = resolve_params(SIM_PARAMS, params, section)
        for name in ("initial_positions", "initial_velocities", "joint_names"):
            _require_length(v, name, model.n, section)
        for name in ("initial_positions", "initial_velocities"):
            _require_finite(v, name, section)
        _check_image_bounds(v, section)
        ratio = v["control_period"] / v["physics_dt"]
        if abs(ratio - round(ratio)) > 1e-9 * ratio:
            raise ConfigError(f"{section}.control_period: must be a whole multiple of "
                              f"physics_dt ({v['physics_dt']}), got {v['control_period']}")
        if v["timing_mode"] not in TIMING_MODES:
            raise ConfigError(f"{section}.timing_mode: must be one of {TIMING_MODES}, "
                              f"got {v['timing_mode']!r}")
        return cls(model, v)

    @property
    def substeps(self):
        return int(round(self.control_period / self.physics_dt))


def _check_image_bounds(v, section):
    _require_length(v, "image_bounds", 4, section)
    u0, u1, v0, v1 = v["image_bounds"]
    if not (u0 < u1 and v0 < v1):
        raise ConfigError(f"{section}.image_bounds: needs u_min < u_max and v_min < v_max, "
                          f"got {list(v['image_bounds'])}")


class ControllerConfig(_ValidatedParams):
    """Validated parameters of the controller (``controller_node``)."""

    @classmethod
    def from_params(cls, params, section=CONTROLLER_SECTION):
        model, v = resolve_params(CONTROLLER_PARAMS, params, section)
        m2 = 2 * model.m
        lengths = {"K": m2, "Gamma_d": model.p_d, "Gamma_z_perp": model.p_perp,
                   "Gamma_z": model.p_z, "a_z_perp_init": model.p_perp, "a_z_init": model.p_z,
                   "a_d_init": model.p_d, "trajectory.offset": m2, "trajectory.a_cos": m2,
                   "trajectory.a_sin": m2, "projection.a_z_perp_min": model.p_perp,
                   "projection.a_z_perp_max": model.p_perp, "projection.a_z_min": model.p_z,
                   "projection.a_z_max": model.p_z, "projection.a_d_min": model.p_d,
                   "projection.a_d_max": model.p_d, "torque_limit": model.n}
        for name, length in lengths.items():
            _require_length(v, name, length, section)
        _require_length(v, "joint_names", model.n, section)
        if v["timing_mode"] not in TIMING_MODES:
            raise ConfigError(f"{section}.timing_mode: must be one of {TIMING_MODES}, "
                              f"got {v['timing_mode']!r}")
        for name in ("K", "Gamma_d", "Gamma_z_perp", "Gamma_z", "a_z_perp_init", "a_z_init",
                     "a_d_init", "trajectory.offset", "trajectory.a_cos", "trajectory.a_sin"):
            _require_finite(v, name, section)
        for name in ("K", "Gamma_d", "Gamma_z_perp", "Gamma_z"):
            if np.any(v[name] <= 0.0):
                raise ConfigError(f"{section}.{name}: every entry must be > 0 "
                                  f"(a positive definite gain), got {list(v[name])}")
        for name in ("alpha", "gamma"):
            if v[name] <= 0.0:
                raise ConfigError(f"{section}.{name}: must be > 0, got {v[name]}")
        if np.any(v["torque_limit"] <= 0.0):
            raise ConfigError(f"{section}.torque_limit: every entry must be > 0, "
                              f"got {list(v['torque_limit'])}")
        check_alpha_gamma(v["alpha"], v["gamma"], section)
        _check_image_bounds(v, section)
        if v["safety.fallback"] not in FALLBACKS:
            raise ConfigError(f"{section}.safety.fallback: must be one of {FALLBACKS}, "
                              f"got {v['safety.fallback']!r}")
        for name in ("a_z_perp", "a_z", "a_d"):
            lo, hi = v[f"projection.{name}_min"], v[f"projection.{name}_max"]
            init = v[f"{name}_init"]
            if np.any(lo > hi):
                raise ConfigError(f"{section}.projection.{name}_min: must be <= "
                                  f"projection.{name}_max element-wise")
            if v["projection.enabled"] and np.any((init < lo) | (init > hi)):
                raise ConfigError(f"{section}.{name}_init: must lie within "
                                  f"projection.{name}_min/_max, got {list(init)}")
        return cls(model, v)


def check_alpha_gamma(alpha, gamma, section=CONTROLLER_SECTION):
    """Theorem 1 needs alpha > gamma / 3; refuse anything else."""
    if not alpha > gamma / 3.0:
        raise ConfigError(f"{section}.alpha: Theorem 1 requires alpha > gamma/3, got "
                          f"alpha={alpha} and gamma={gamma} (gamma/3={gamma / 3.0:.6g})")


def flatten(mapping, prefix=""):
    """Flatten nested mappings to dotted names, as ROS 2 does with parameter files."""
    flat = {}
    for key, value in mapping.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def _coerce_numbers(value):
    """Read '1e9' as a number like ROS 2's parameter parser does (YAML 1.1 keeps it a string)."""
    if isinstance(value, list):
        return [_coerce_numbers(v) for v in value]
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def read_param_file(path):
    """Read a ROS 2 parameter YAML into {section: flat params}."""
    with open(path, encoding="utf-8") as handle:
        try:
            data = yaml.safe_load(handle)
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: must be a mapping with sim_node and controller_node")
    sections = {}
    for section in (SIM_SECTION, CONTROLLER_SECTION):
        body = data.get(section) or data.get("/" + section)
        if not isinstance(body, dict) or not isinstance(body.get("ros__parameters"), dict):
            raise ConfigError(f"{path}: needs a '{section}: ros__parameters:' mapping")
        sections[section] = {k: _coerce_numbers(v)
                             for k, v in flatten(body["ros__parameters"]).items()}
    return sections


def apply_overrides(sections, overrides):
    """Apply ``section.param=value`` strings (values parsed as YAML); returns a new dict."""
    result = {name: dict(body) for name, body in sections.items()}
    for item in overrides:
        key, sep, text = item.partition("=")
        section, dot, name = key.partition(".")
        if not sep or not dot or section not in result:
            raise ConfigError(f"--set {item!r}: expected sim_node.NAME=VALUE or "
                              f"controller_node.NAME=VALUE")
        try:
            result[section][name] = _coerce_numbers(yaml.safe_load(text))
        except yaml.YAMLError as exc:
            raise ConfigError(f"--set {item!r}: value is not valid YAML: {exc}") from None
    return result


@dataclass(frozen=True, eq=False)
class Scenario:
    """A validated simulator + controller configuration."""

    sim: SimConfig
    controller: ControllerConfig


def load_scenario(path, overrides=(), edit: Callable[[dict], None] | None = None):
    """Read, override and validate a parameter file; both sections or nothing."""
    sections = apply_overrides(read_param_file(path), overrides)
    if edit is not None:
        edit(sections)
    sim = SimConfig.from_params(sections[SIM_SECTION])
    ctrl = ControllerConfig.from_params(sections[CONTROLLER_SECTION])
    if sim.model.__class__ is not ctrl.model.__class__:
        raise ConfigError(f"controller_node.model: must match sim_node.model "
                          f"({sim.params['model']!r}), got {ctrl.params['model']!r}")
    return Scenario(sim, ctrl)
