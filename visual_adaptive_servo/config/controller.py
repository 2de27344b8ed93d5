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
parameter name and the rule it breaks, and nothing is partially applied.  The
feature detector's schema, :data:`DETECTOR_PARAMS`, is validated the same way
by :meth:`detection.DetectorConfig.from_params`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import yaml

from sim_bridge.camera import PinholeCamera

from .models import MODEL_NAMES, RobotCameraModel, make_model
from .models.urdf_arm import check_feature_points
from .models.urdf_chain import load_chain
from .resources import resolve_path
from .trajectory import TRAJECTORY_TYPES, SinusoidTrajectory, TabulatedTrajectory

SIM_SECTION = "sim_node"
CONTROLLER_SECTION = "controller_node"
DETECTOR_SECTION = "feature_detector"
TIMING_MODES = ("lockstep", "realtime")
STRUCTURE_NAMES = ("model", "urdf", "base_link", "tip_link", "feature_points", "unknown_lengths")
FALLBACKS = ("gravity_compensation", "zero_torque")
CAMERA_MODES = ("points", "rendered")


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
    ``structure`` those that define the model (read first).
    """

    name: str
    default: Any
    kind: str
    description: str
    low: float | None = None
    high: float | None = None
    runtime: bool = False
    structure: bool = False

    @property
    def computed(self):
        """The default depends on the structure or on other parameters."""
        return callable(self.default)

    def default_for(self, structure, values):
        return self.default(structure, values) if callable(self.default) else self.default


INF = math.inf
PAPER_URDF = "package://visual_adaptive_servo/urdf/paper_rrr.urdf"
MARKER_COLORS = (230.0, 30.0, 30.0, 30.0, 200.0, 30.0, 40.0, 90.0, 255.0)   # red, green, blue


def camera_specs(prefix, what):
    """The parameters of one pinhole camera (defaults: the paper's camera)."""
    return (
        ParamSpec(prefix + "position", [-5.0, 0.0, 0.0], "float_list",
                  f"{what}: centre in the URDF root frame [m]."),
        ParamSpec(prefix + "orientation", "look_at", "str",
                  f"{what}: 'look_at' (use look_at and up) or 'rpy' (use rpy)."),
        ParamSpec(prefix + "look_at", [0.0, 0.0, 0.0], "float_list",
                  f"{what}: a point on the optical axis [m]."),
        ParamSpec(prefix + "up", [0.0, 0.0, 1.0], "float_list",
                  f"{what}: the direction that points up in the picture."),
        ParamSpec(prefix + "rpy", [0.0, 0.0, 0.0], "float_list",
                  f"{what}: orientation of the camera frame (X right, Y down, Z along the "
                  f"optical axis) as URDF roll-pitch-yaw [rad]."),
        ParamSpec(prefix + "focal_length", 0.15, "float", f"{what}: focal length f [m].",
                  1e-9, None),
        ParamSpec(prefix + "pixel_scale", [900.0, 900.0], "float_list",
                  f"{what}: pixel scales beta_x, beta_y [px/m].", 0.0, None),
        ParamSpec(prefix + "principal_point", [320.0, 240.0], "float_list",
                  f"{what}: principal point in raw image coordinates [px]."),
        ParamSpec(prefix + "image_size", [640.0, 480.0], "float_list",
                  f"{what}: picture width and height [px].", 1.0, None),
        ParamSpec(prefix + "pixel_origin", [320.0, 240.0], "float_list",
                  f"{what}: raw image point that is the controller's pixel origin [px]."),
        ParamSpec(prefix + "pixel_axes", [-1.0, -1.0], "float_list",
                  f"{what}: +1/-1 per axis: controller pixel = axes * (raw - origin)."),
    )


def _structure_specs(default_urdf, default_base, default_tip, default_points, what):
    return (
        ParamSpec("urdf", default_urdf, "str",
                  f"URDF of the arm{what} (file path, package:// or pybullet_data://).",
                  structure=True),
        ParamSpec("base_link", default_base, "str", "Fixed base link of the chain.",
                  structure=True),
        ParamSpec("tip_link", default_tip, "str", "Link carrying the feature points.",
                  structure=True),
        ParamSpec("feature_points", default_points, "float_list",
                  "Offsets c_i of the m = 1..3 feature points in the tip link frame, 3 numbers "
                  "each [m].", structure=True),
    )


SIM_PARAMS = _structure_specs(PAPER_URDF, "base_link", "tip", [0.0, 0.0, 0.0], "") + (
    ParamSpec("physics_dt", 0.001, "float", "PyBullet physics step [s].", 1e-5, 0.01),
    ParamSpec("control_period", 0.005, "float",
              "Camera frame / control period [s]; a whole multiple of physics_dt.", 1e-4, 1.0),
    ParamSpec("duration", 0.0, "float", "Stop after this simulated time [s]; 0 = run forever.",
              0.0, None),
    ParamSpec("initial_positions", lambda s, v: [0.0] * s.n, "float_list",
              "Joint positions at start [rad or m]."),
    ParamSpec("initial_velocities", lambda s, v: [0.0] * s.n, "float_list",
              "Joint velocities at start [rad/s or m/s]."),
    ParamSpec("joint_names", lambda s, v: list(s.joint_names), "str_list",
              "Joint names in /joint_states and the command order (default: the URDF chain's)."),
    ParamSpec("camera_mode", "points", "str",
              "points: the camera reports the projected feature points (plus pixel_noise_std); "
              "rendered: it renders pictures (/camera/image_raw) and a feature detector finds "
              "the markers in them."),
    ParamSpec("pixel_noise_std", 0.0, "float", "Gaussian pixel noise std [px] (points mode).",
              0.0, 100.0),
    ParamSpec("camera_rate", 0.0, "float",
              "Camera frames per second; 0 = one frame per control_period [Hz].", 0.0, None),
    ParamSpec("camera_latency", 0.0, "float",
              "Time from a frame's capture to its publication, rounded up to the control period "
              "[s]; the frame is stamped with its capture time.", 0.0, 10.0),
    ParamSpec("seed", 0, "int", "Seed of the pixel noise generator.", 0, 2**31 - 1),
) + camera_specs("camera.", "Simulated camera") + (
    ParamSpec("markers.radius", 0.03, "float",
              "Radius of the coloured sphere drawn at each feature point [m].", 1e-4, 1.0),
    ParamSpec("markers.colors", lambda s, v: list(MARKER_COLORS[:3 * s.m]), "float_list",
              "RGB 0-255 of each feature point's marker, 3 numbers per point.", 0.0, 255.0),
    ParamSpec("faults.nan_pixels", [0.0, 0.0], "float_list",
              "Fault injection: frames captured in [start, start + length] carry NaN pixels "
              "[s, s]; length 0 = off.", 0.0, None),
    ParamSpec("faults.nan_joint_states", [0.0, 0.0], "float_list",
              "Fault injection: joint positions read NaN in [start, start + length] [s, s].",
              0.0, None),
    ParamSpec("faults.dropout", [0.0, 0.0], "float_list",
              "Fault injection: frames captured in [start, start + length] are lost [s, s].",
              0.0, None),
    ParamSpec("faults.occlusion", [0.0, 0.0], "float_list",
              "Fault injection: point 1 hidden in [start, start + length] [s, s] (rendered: an "
              "occluder in front of it; points: its frames are lost).", 0.0, None),
    ParamSpec("faults.drop_every", 0, "int",
              "Fault injection: every k-th frame is lost; 0 = none.", 0, None),
    ParamSpec("timing_mode", "lockstep", "str",
              "lockstep: wait for the command answering each state; realtime: wall-clock timer."),
    ParamSpec("command_timeout", 1.0, "float",
              "lockstep: wall time to wait for a command before applying zero torque (and, "
              "with frame_ack, for a frame's acknowledgement) [s].", 1e-3, 60.0),
    ParamSpec("frame_ack", False, "bool",
              "lockstep: after publishing a camera frame, wait until every subscriber has "
              "acknowledged it before the joint state follows (wait_for_all_acked). Costs up to "
              "a DDS heartbeat period per frame (about 100 ms with Cyclone DDS's defaults); "
              "without it the frame is published first and, on one host, arrives first."),
    ParamSpec("detector_timeout", 0.5, "float",
              "lockstep, rendered: wall time to wait for the feature detector to have processed "
              "a picture (/feature_detector/processed) before the joint state follows [s].",
              1e-3, 60.0),
    ParamSpec("start.wait_for_recorder", False, "bool",
              "Start only once every recorded topic (visual_adaptive_servo.recording.TOPICS) "
              "has a subscriber and /joint_states, /clock and the features have two (the "
              "controller's and a recorder's); ros2 launch sets it with record:=true."),
    ParamSpec("render.enabled", False, "bool", "Publish the camera view on ~/image."),
    ParamSpec("render.rate", 10.0, "float", "Rendering rate [Hz].", 0.1, 60.0),
    ParamSpec("render.width", 320, "int", "Rendered image width [px].", 16, 1920),
    ParamSpec("render.height", 240, "int", "Rendered image height [px].", 16, 1080),
)


def _nominal(model, values):
    """The model's estimate from ``initial_estimate.*`` (what a user knows before the run)."""
    camera = PinholeCamera.from_params(values, "initial_estimate.camera.", CONTROLLER_SECTION)
    return model.estimate(camera.projection_matrix, values["initial_estimate.length_scale"],
                          values["initial_estimate.inertia_scale"])


CONTROLLER_PARAMS = (
    ParamSpec("model", "paper_rrr", "str",
              f"Robot + camera model: one of {list(MODEL_NAMES)} (paper_rrr: the paper's arm, "
              f"derived by hand; urdf: any serial arm from urdf/base_link/tip_link).",
              structure=True),
) + _structure_specs("", "", "", [0.0, 0.0, 0.0], " (model urdf)") + (
    ParamSpec("unknown_lengths", ["all"], "str_list",
              "model urdf: names of the lengths adapted as unknown (joint.x/y/z, point1.x, ...), "
              "or [all]; the others are taken from the URDF.", structure=True),
    ParamSpec("joint_names",
              lambda m, v: list(getattr(m, "joint_names", [f"joint{i + 1}" for i in range(m.n)])),
              "str_list",
              "ROS node: joints taken from /joint_states, in the order of the torque command."),
    ParamSpec("timing_mode", "lockstep", "str",
              "ROS node: QoS of the measurement subscriptions; must match sim_node.timing_mode "
              "(lockstep: reliable; realtime: best-effort sensor data)."),
    ParamSpec("sample_time", 0.005, "float", "Nominal control period T [s].", 1e-5, 1.0),
    ParamSpec("K", lambda m, v: [0.001] * (2 * m.m), "float_list",
              "Diagonal of the feedback gain K of eq (22), (2m,).", 0.0, None, True),
    ParamSpec("joint_damping.inertia_rate", 0.0, "float",
              "Joint-space damping of s, D = rate x (estimated inertia matrix at the start), "
              "added to eq (22) [1/s]; 0 = the paper's law.  Keeps Theorem 1 (see README).",
              0.0, None),
    ParamSpec("joint_damping.diagonal", lambda m, v: [0.0] * m.n, "float_list",
              "A constant diagonal added to that damping [N m s/rad].", 0.0, None),
    ParamSpec("alpha", 10.0, "float", "Observer gain alpha of eq (10); alpha > gamma/3.",
              0.0, None),
    ParamSpec("gamma", 10.0, "float", "Reference gain gamma of eq (18); alpha > gamma/3.",
              0.0, None),
    ParamSpec("Gamma_d_normalized", 300.0, "float",
              "Default of Gamma_d: this divided by the square of each Y_d column's typical size, "
              "so every parameter adapts like one with an O(1) column.", 0.0, None),
    ParamSpec("Gamma_d", lambda m, v: list(v["Gamma_d_normalized"]
                                           / np.maximum(m.dynamic_column_rms(), 0.1) ** 2),
              "float_list",
              "Diagonal of the dynamic adaptation gain Gamma_d of eq (23) (default from "
              "Gamma_d_normalized).", 0.0, None, True),
    ParamSpec("Gamma_z_perp", lambda m, v: [600.0] * m.p_perp, "float_list",
              "Diagonal of Gamma_z_perp of eq (24).", 0.0, None, True),
    ParamSpec("Gamma_z", lambda m, v: [0.2] * m.p_z, "float_list",
              "Diagonal of Gamma_z of eq (25).", 0.0, None, True),
) + camera_specs("initial_estimate.camera.", "Guessed camera for the initial estimates") + (
    ParamSpec("initial_estimate.length_scale", 1.0, "float",
              "Initial estimates: the model's nominal lengths times this.", 1e-3, 1e3),
    ParamSpec("initial_estimate.inertia_scale", 1.0, "float",
              "Initial estimates: the nominal inertial parameters times this.", 0.0, 1e3),
    ParamSpec("a_z_perp_init", lambda m, v: list(_nominal(m, v)[0]), "float_list",
              "Initial estimate of a_z_perp (default: from initial_estimate.*)."),
    ParamSpec("a_z_init", lambda m, v: list(_nominal(m, v)[1]), "float_list",
              "Initial estimate of a_z (default: from initial_estimate.*)."),
    ParamSpec("a_d_init", lambda m, v: list(_nominal(m, v)[2]), "float_list",
              "Initial estimate of a_d (default: from initial_estimate.*)."),
    ParamSpec("trajectory.type", "sinusoid", "str",
              f"Desired image trajectory: one of {list(TRAJECTORY_TYPES)}."),
    ParamSpec("trajectory.file", "", "str",
              "trajectory.type table: CSV with columns t, u1, v1, ..., um, vm [s, px]."),
    ParamSpec("trajectory.offset", lambda m, v: [0.0] * (2 * m.m), "float_list",
              "x_d = offset + a_cos cos(w t) + a_sin sin(w t) [px]."),
    ParamSpec("trajectory.a_cos", lambda m, v: [0.0] * (2 * m.m), "float_list",
              "Cosine amplitudes of x_d [px]."),
    ParamSpec("trajectory.a_sin", lambda m, v: [0.0] * (2 * m.m), "float_list",
              "Sine amplitudes of x_d [px]."),
    ParamSpec("trajectory.omega", 0.0, "float", "Angular frequency w of x_d [rad/s].",
              0.0, None),
    ParamSpec("start_blend_time", 2.0, "float",
              "Blend the offset between the first measured feature and x_d(0) out over this "
              "time [s] (zero when the start is on the trajectory); 0 = no blend.", 0.0, 60.0),
    ParamSpec("start_tolerance", 0.01, "float",
              "A start (or camera recovery) within this of x_d counts as on the trajectory and "
              "is not blended [px].", 0.0, None),
    ParamSpec("projection.enabled", True, "bool",
              "Project the kinematic adaptation (Remark 6) onto the bounds below."),
    ParamSpec("projection.a_z_perp_min", lambda m, v: [-INF] * m.p_perp, "float_list",
              "Lower bounds of a_z_perp_hat."),
    ParamSpec("projection.a_z_perp_max", lambda m, v: [INF] * m.p_perp, "float_list",
              "Upper bounds of a_z_perp_hat."),
    ParamSpec("projection.a_z_min", lambda m, v: [-INF] * m.p_z, "float_list",
              "Lower bounds of a_z_hat."),
    ParamSpec("projection.a_z_max", lambda m, v: [INF] * m.p_z, "float_list",
              "Upper bounds of a_z_hat."),
    ParamSpec("projection.a_d_min", lambda m, v: [-INF] * m.p_d, "float_list",
              "Lower bounds of a_d_hat."),
    ParamSpec("projection.a_d_max", lambda m, v: [INF] * m.p_d, "float_list",
              "Upper bounds of a_d_hat."),
    ParamSpec("projection.min_depth", 0.1, "float",
              "Smallest allowed estimated depth z_hat_i [m].", 1e-6, None),
    ParamSpec("torque_limit", lambda m, v: [INF] * m.n, "float_list",
              "Per-joint |tau| limit [N m]; the command saturates there.", 0.0, None, True),
    ParamSpec("min_singular_value", 0.0, "float",
              "Damp the pseudo-inverse of J* when its smallest singular value drops below "
              "this [px m/rad]; 0 = never.", 0.0, None, True),
    ParamSpec("max_dt", 0.05, "float",
              "Longest interval integrated in one step [s]; longer gaps are clamped.",
              1e-5, 10.0),
    ParamSpec("image_bounds", [-320.0, 320.0, -240.0, 240.0], "float_list",
              "Valid feature region [u_min, u_max, v_min, v_max] [px]."),
    ParamSpec("latency_compensation", True, "bool",
              "Run at every joint sample on x_hat, the latest camera frame applied at its capture "
              "time and predicted to now from the joints (false: take a frame as current when it "
              "arrives and hold the command between frames)."),
    ParamSpec("max_frame_age", 0.5, "float",
              "Frames captured longer ago than this are refused; the joint buffer keeps this "
              "much [s].", 1e-3, 10.0),
    ParamSpec("frame_gain", 1.0, "float",
              "Weight of a frame against the prediction at its capture time: 1 resets the "
              "prediction to the frame, less filters pixel noise.", 1e-3, 1.0),
    ParamSpec("drift_gain", 0.0, "float",
              "Learn the prediction's drift from each frame's innovation with this gain "
              "(0: off).", 0.0, 1.0),
    ParamSpec("safety.hold_time", 0.05, "float",
              "Hold the last valid command this long after input goes bad [s].", 0.0, 10.0,
              True),
    ParamSpec("safety.camera_timeout", 0.1, "float",
              "No valid feature for this long = stale camera [s].", 1e-3, 60.0, True),
    ParamSpec("safety.recovery_blend_time", 1.0, "float",
              "When a stale camera comes back, blend the offset between the measured feature and "
              "x_d out over this time [s].", 0.0, 60.0, True),
    ParamSpec("safety.fallback", "gravity_compensation", "str",
              "After hold_time: gravity_compensation (estimated g(q), damped by "
              "fallback_damping and the joint_damping matrix) or zero_torque.", runtime=True),
    ParamSpec("safety.fallback_damping", 5.0, "float",
              "Joint damping D of the gravity-compensation fallback [N m s/rad].", 0.0, None,
              True),
    ParamSpec("divergence_torque", 1e5, "float",
              "|tau| above this (before saturation) is reported as divergence [N m].", 0.0, None),
)

DETECTOR_PARAMS = (
    ParamSpec("markers.colors", list(MARKER_COLORS[:3]), "float_list",
              "Marker colours as the camera sees them, RGB 0-255, three values per marker "
              "(1 to 3 markers), in feature order (default: the simulator's first marker).",
              0.0, 255.0, True),
    ParamSpec("markers.tolerance", 40.0, "float",
              "A pixel belongs to a marker when each of its R, G, B is within this of the "
              "marker's colour.", 0.0, 255.0, True),
    ParamSpec("blob_area", [10.0, 50000.0], "float_list",
              "[min, max] area of a marker blob [px]; blobs outside are not markers.",
              1.0, None, True),
    ParamSpec("pixel_origin", [320.0, 240.0], "float_list",
              "Image point (column, row) [px] that is pixel (0, 0) of the controller; "
              "continuous image coordinates, the top-left corner of the image is (0, 0). "
              "The default is the paper's camera (origin on the optical axis) for 640x480."),
    ParamSpec("pixel_axes", [-1.0, -1.0], "float_list",
              "+1 or -1 per axis: u = axes[0] (column - origin[0]), v = axes[1] (row - "
              "origin[1]); [1, 1] for a standard camera, [-1, -1] for the paper's (u to the "
              "left, v up)."),
    ParamSpec("overlay.enabled", True, "bool",
              "Publish ~/overlay: the image with x, x_d and x_o drawn (for image viewers)."),
    ParamSpec("timing_mode", "lockstep", "str",
              "QoS of the image subscription and the features publisher; must match the "
              "camera's and the controller's (lockstep: reliable; realtime: best-effort "
              "sensor data)."),
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


def resolve_params(specs, params, section, build_structure):
    """Check names and types of a flat parameter dict and fill defaults, structure first.

    ``build_structure(values)`` turns the structure parameters into the object the
    computed defaults need (a model, or the simulator's arm); a ValueError it raises
    becomes a ConfigError.  Returns ``(structure, values)``.
    """
    specs_by_name = {s.name: s for s in specs}
    unknown = sorted(set(params) - set(specs_by_name))
    if unknown:
        raise ConfigError(f"{section}: unknown parameter(s) {unknown}")
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


def _require_length(values, name, length, section):
    if len(values[name]) != length:
        raise ConfigError(f"{section}.{name}: needs {length} values, got {len(values[name])}")


def _require_finite(values, name, section):
    if not np.all(np.isfinite(values[name])):
        raise ConfigError(f"{section}.{name}: must be finite")


@dataclass(frozen=True, eq=False)
class _ValidatedParams:
    """A complete, validated parameter dict, read as attributes or items."""

    params: dict = field(repr=False)

    def __getattr__(self, name):
        try:
            return self.__dict__["params"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __getitem__(self, name):
        return self.params[name]


@dataclass(frozen=True)
class SimArm:
    """The simulator's arm as the configuration knows it: the URDF chain and its points."""

    chain: object               # models.urdf_chain.KinematicChain
    offsets: np.ndarray         # (m, 3) feature offsets in the tip frame [m]

    @property
    def n(self):
        return self.chain.n

    @property
    def m(self):
        return len(self.offsets)

    @property
    def joint_names(self):
        return self.chain.joint_names


def build_sim_arm(values, section=SIM_SECTION, search_dirs=()):
    """The simulator's arm (URDF chain and feature offsets) from the structure parameters."""
    path = resolve_path(values["urdf"], search_dirs, f"{section}.urdf")
    chain = load_chain(path, values["base_link"], values["tip_link"], section)
    points = np.asarray(values["feature_points"], dtype=float)
    if points.size == 0 or points.size % 3:
        raise ValueError(f"{section}.feature_points: 3 numbers per point, got {points.size}")
    check_feature_points(points.reshape(-1, 3), chain.n, section)
    return SimArm(chain, points.reshape(-1, 3))


@dataclass(frozen=True, eq=False)
class SimConfig(_ValidatedParams):
    """Validated parameters of the simulator (``sim_node``): the arm, its camera and timing."""

    arm: SimArm = None
    camera: PinholeCamera = None

    @classmethod
    def from_params(cls, params, section=SIM_SECTION, search_dirs=()):
        arm, v = resolve_params(SIM_PARAMS, params, section,
                                lambda values: build_sim_arm(values, section, search_dirs))
        for name in ("initial_positions", "initial_velocities", "joint_names"):
            _require_length(v, name, arm.n, section)
        for name in ("initial_positions", "initial_velocities"):
            _require_finite(v, name, section)
        _require_length(v, "markers.colors", 3 * arm.m, section)
        for name in ("faults.nan_pixels", "faults.nan_joint_states", "faults.dropout",
                     "faults.occlusion"):
            _require_length(v, name, 2, section)
        ratio = v["control_period"] / v["physics_dt"]
        if abs(ratio - round(ratio)) > 1e-9 * ratio:
            raise ConfigError(f"{section}.control_period: must be a whole multiple of "
                              f"physics_dt ({v['physics_dt']}), got {v['control_period']}")
        if v["timing_mode"] not in TIMING_MODES:
            raise ConfigError(f"{section}.timing_mode: must be one of {TIMING_MODES}, "
                              f"got {v['timing_mode']!r}")
        if v["camera_mode"] not in CAMERA_MODES:
            raise ConfigError(f"{section}.camera_mode: must be one of {CAMERA_MODES}, "
                              f"got {v['camera_mode']!r}")
        if v["camera_rate"] * v["control_period"] > 1.0 + 1e-9:
            raise ConfigError(f"{section}.camera_rate: at most one frame per control period "
                              f"({1.0 / v['control_period']:g} Hz), got {v['camera_rate']}")
        camera = _camera(v, "camera.", section)
        return cls(v, arm, camera)

    @property
    def substeps(self):
        return int(round(self.control_period / self.physics_dt))

    @property
    def image_bounds(self):
        """[u_min, u_max, v_min, v_max] of the simulated picture in the controller's pixels."""
        return self.camera.image_bounds


def _camera(values, prefix, section):
    if values[prefix + "orientation"] not in ("look_at", "rpy"):
        raise ConfigError(f"{section}.{prefix}orientation: must be 'look_at' or 'rpy', got "
                          f"{values[prefix + 'orientation']!r}")
    try:
        return PinholeCamera.from_params(values, prefix, section)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def _check_image_bounds(v, section):
    _require_length(v, "image_bounds", 4, section)
    u0, u1, v0, v1 = v["image_bounds"]
    if not (u0 < u1 and v0 < v1):
        raise ConfigError(f"{section}.image_bounds: needs u_min < u_max and v_min < v_max, "
                          f"got {v['image_bounds'].tolist()}")


def build_controller_model(values, section=CONTROLLER_SECTION, search_dirs=(), model=None):
    """The controller's model from the structure parameters (``model`` reused if unchanged)."""
    name = values["model"]
    if name not in MODEL_NAMES:
        raise ValueError(f"model: unknown model name {name!r}; known: {list(MODEL_NAMES)}")
    if model is not None and getattr(model, "structure", None) == _structure_key(values):
        return model
    built = make_model(name, values, section, search_dirs)
    built.structure = _structure_key(values)
    return built


def _structure_key(values):
    return tuple((k, tuple(v) if isinstance(v, (tuple, np.ndarray)) else v)
                 for k, v in sorted(values.items()) if k in STRUCTURE_NAMES)


@dataclass(frozen=True, eq=False)
class ControllerConfig(_ValidatedParams):
    """Validated parameters of the controller (``controller_node``), its model and x_d."""

    model: RobotCameraModel = None
    trajectory: object = None
    search_dirs: tuple = ()

    @property
    def model_name(self):
        return self.params["model"]

    @classmethod
    def from_params(cls, params, section=CONTROLLER_SECTION, search_dirs=(), model=None):
        """Validate a whole parameter set; ``model`` is reused when its structure is unchanged."""
        model, v = resolve_params(
            CONTROLLER_PARAMS, params, section,
            lambda values: build_controller_model(values, section, search_dirs, model))
        m2 = 2 * model.m
        lengths = {"K": m2, "Gamma_d": model.p_d, "joint_damping.diagonal": model.n,
                   "Gamma_z_perp": model.p_perp, "Gamma_z": model.p_z,
                   "a_z_perp_init": model.p_perp, "a_z_init": model.p_z,
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
        trajectory = _trajectory(v, model.m, section, search_dirs)
        return cls(v, model, trajectory, tuple(search_dirs))

    def with_changes(self, **changes):
        """A new, whole-validated configuration with some parameters changed (same model)."""
        params = dict(self.params)
        params.update(changes)
        return ControllerConfig.from_params(params, search_dirs=self.search_dirs,
                                            model=self.model)


def _trajectory(v, m, section, search_dirs):
    kind = v["trajectory.type"]
    if kind == "sinusoid":
        return SinusoidTrajectory(v["trajectory.offset"], v["trajectory.a_cos"],
                                  v["trajectory.a_sin"], v["trajectory.omega"])
    if kind == "table":
        try:
            path = resolve_path(v["trajectory.file"], search_dirs, f"{section}.trajectory.file")
            return TabulatedTrajectory.from_csv(path, m)
        except (FileNotFoundError, ValueError) as exc:
            text = str(exc)
            raise ConfigError(text if text.startswith(section) else
                              f"{section}.trajectory.file: {text}") from None
    raise ConfigError(f"{section}.trajectory.type: must be one of {list(TRAJECTORY_TYPES)}, "
                      f"got {kind!r}")


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
    """Read a ROS 2 parameter YAML into {section: flat params}.

    ``sim_node`` and ``controller_node`` are required; a ``feature_detector``
    section (the detector of ``camera_mode: rendered``) is read when present.
    """
    with open(path, encoding="utf-8") as handle:
        try:
            data = yaml.safe_load(handle)
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: must be a mapping with sim_node and controller_node")
    sections = {}
    for section in (SIM_SECTION, CONTROLLER_SECTION, DETECTOR_SECTION):
        body = data.get(section) or data.get("/" + section)
        if body is None and section == DETECTOR_SECTION:
            continue
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
        if section == DETECTOR_SECTION:
            result.setdefault(section, {})
        if not sep or not dot or section not in result:
            raise ConfigError(f"--set {item!r}: expected sim_node.NAME=VALUE, "
                              f"controller_node.NAME=VALUE or feature_detector.NAME=VALUE")
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
    detector: object = None     # detection.DetectorConfig when the camera renders


def detector_for(sim, params=None):
    """The feature detector matching the simulated camera: its marker colours and pixel map.

    ``params`` (a ``feature_detector`` section) may change anything, e.g. the tolerance.
    """
    from .detection import DetectorConfig

    base = {"markers.colors": [float(v) for v in sim["markers.colors"]],
            "pixel_origin": [float(v) for v in sim.camera.pixel_origin],
            "pixel_axes": [float(v) for v in sim.camera.pixel_axes]}
    base.update(params or {})
    return DetectorConfig.from_params(base)


def load_scenario(path, overrides=(), edit: Callable[[dict], None] | None = None):
    """Read, override and validate a parameter file; both sections or nothing.

    File names inside (URDFs, trajectory tables) may be relative to the file's
    folder.  The controller's model gets the simulator's camera and arm as its
    ground truth, and the start is checked: every feature point in front of the
    camera and inside both the picture and the controller's ``image_bounds``,
    the true and the estimated image Jacobian of full row rank (Assumption 2).
    """
    sections = apply_overrides(read_param_file(path), overrides)
    if edit is not None:
        edit(sections)
    search_dirs = (os.path.dirname(os.path.abspath(path)),)
    sim = SimConfig.from_params(sections[SIM_SECTION], search_dirs=search_dirs)
    ctrl = ControllerConfig.from_params(sections[CONTROLLER_SECTION], search_dirs=search_dirs)
    model = ctrl.model
    if (model.n, model.m) != (sim.arm.n, sim.arm.m):
        raise ConfigError(f"controller_node.model: describes {model.n} joints and {model.m} "
                          f"point(s); the simulated arm (sim_node.urdf, feature_points) has "
                          f"{sim.arm.n} and {sim.arm.m}")
    if tuple(ctrl.joint_names) != tuple(sim.joint_names):
        raise ConfigError(f"controller_node.joint_names: must equal sim_node.joint_names "
                          f"{list(sim.joint_names)}, got {list(ctrl.joint_names)}")
    try:
        model.set_ground_truth(sim.camera.projection_matrix, sim.arm.chain, sim.arm.offsets)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    check_start(sim, ctrl)
    detector = (detector_for(sim, sections.get(DETECTOR_SECTION))
                if sim.camera_mode == "rendered" else None)
    return Scenario(sim, ctrl, detector)


def check_start(sim, ctrl):
    """The start-up checks of :func:`load_scenario` (ConfigError naming what fails)."""
    q0 = np.asarray(sim.initial_positions, dtype=float)
    points = sim.arm.chain.points(q0, sim.arm.offsets)
    root = sim.arm.chain.root_to_base
    pixels, depth = sim.camera.project(points @ root[:3, :3].T + root[:3, 3])
    behind = [i + 1 for i, z in enumerate(depth.tolist()) if not z > 0.0]
    if behind:
        raise ConfigError(f"sim_node.initial_positions: feature point(s) {behind} behind the "
                          f"camera at the start (depths {np.round(depth, 3).tolist()} m); move "
                          f"sim_node.camera or the start pose")
    for section, bounds in ((SIM_SECTION + ".camera", sim.image_bounds),
                            (CONTROLLER_SECTION + ".image_bounds", ctrl.image_bounds)):
        u0, u1, v0, v1 = bounds
        outside = [i + 1 for i, (u, v) in enumerate(pixels.reshape(-1, 2).tolist())
                   if not (u0 <= u <= u1 and v0 <= v <= v1)]
        if outside:
            raise ConfigError(f"sim_node.initial_positions: feature point(s) {outside} outside "
                              f"the image at the start (pixels {np.round(pixels, 1).tolist()}, "
                              f"{section} {[float(b) for b in bounds]})")
    model = ctrl.model
    tensors = model.kinematic_tensors(q0, np.zeros(model.n))
    _, dH, _, W, _ = tensors
    for what, a_perp, a_z in (("true", model.a_z_perp, model.a_z),
                              ("estimated", ctrl.a_z_perp_init, ctrl.a_z_init)):
        J = model.image_jacobian(W, dH, pixels, np.asarray(a_perp), np.asarray(a_z))
        sv = np.linalg.svd(J, compute_uv=False)
        if sv[-1] <= 1e-9 * max(sv[0], 1e-300):
            hint = ("the initial estimates (controller_node.a_z_perp_init/a_z_init or "
                    "initial_estimate.*)" if what == "estimated" else
                    "the camera and the points (sim_node.camera, feature_points)")
            raise ConfigError(f"sim_node.initial_positions: the {what} image Jacobian J(q, x) "
                              f"at the start has rank {int(np.sum(sv > 1e-9 * sv[0]))} < "
                              f"{2 * model.m} (singular values {np.round(sv, 6).tolist()}): "
                              f"Assumption 2 of the paper fails here; change the start pose or "
                              f"{hint}")
