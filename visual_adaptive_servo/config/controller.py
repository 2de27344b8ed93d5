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

"""The controller's section (``controller_node``): its parameter specs and validated configuration.

:class:`ControllerConfig` holds the model (built from the structure parameters),
the gains, the initial estimates (by default from a guessed camera and the
model's nominal lengths), the bounds of the projection, the safety settings and
the desired trajectory x_d.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sim_bridge.camera import PinholeCamera, picture_bounds

from ..control.controller import check_alpha_gamma
from ..control.gain_design import DESIGNED, DesignSettings
from ..control.trajectory import SinusoidTrajectory, TabulatedTrajectory, TRAJECTORY_TYPES
from ..models import BACKENDS, make_model, MODEL_NAMES, RobotCameraModel, STRUCTURE_PARAMS
from ..models.resources import resolve_path
from ..schema import (CONTROLLER_SECTION, ConfigError, failing_entries, INF, ParamSpec,
                      require_finite, require_length, resolve_params, TIMING_MODES,
                      ValidatedParams)
from .common import camera_specs, check_image_bounds, structure_specs

FALLBACKS = ("gravity_compensation", "zero_torque")


def _nominal(model, values):
    """The model's estimate from ``initial_estimate.*`` (what a user knows before the run)."""
    camera = PinholeCamera.from_params(values, "initial_estimate.camera.", CONTROLLER_SECTION)
    return model.estimate(camera.projection_matrix, values["initial_estimate.length_scale"],
                          values["initial_estimate.inertia_scale"])


def guessed_picture_bounds(values):
    """The guessed camera's picture [u_min, u_max, v_min, v_max] in the controller's pixels.

    The picture's size and pixel convention are known for a real camera (no calibration
    needed).  Entries of the wrong length are reported by the camera's own check; here
    they give the paper camera's picture.
    """
    size, origin, axes = (np.asarray(values[f"initial_estimate.camera.{k}"], dtype=float)
                          for k in ("image_size", "pixel_origin", "pixel_axes"))
    if not size.shape == origin.shape == axes.shape == (2,):
        return [-320.0, 320.0, -240.0, 240.0]
    return picture_bounds(size, origin, axes).tolist()


CONTROLLER_PARAMS = (
    ParamSpec("model", "paper_rrr", "str",
              f"Robot + camera model: one of {list(MODEL_NAMES)} (paper_rrr: the paper's arm, "
              f"derived by hand; urdf: any serial arm from urdf/base_link/tip_link).",
              structure=True),
) + structure_specs("", "", "", [0.0, 0.0, 0.0], " (model urdf)") + (
    ParamSpec("unknown_lengths", ["all"], "str_list",
              "model urdf: names of the lengths adapted as unknown (joint.x/y/z, point1.x, ...), "
              "or [all]; the others are taken from the URDF.", structure=True),
    ParamSpec("backend", "auto", "str",
              "Kinematic tensors: compiled (numba), numpy (the readable reference), or auto "
              "(compiled when numba imports).", structure=True),
    ParamSpec("joint_names",
              lambda m, v: list(getattr(m, "joint_names", [f"joint{i + 1}" for i in range(m.n)])),
              "str_list",
              "ROS node: joints taken from /joint_states, in the order of the torque command."),
    ParamSpec("timing_mode", "lockstep", "str",
              "ROS node: QoS of the measurement subscriptions; must match sim_node.timing_mode "
              "(lockstep: reliable; realtime: best-effort sensor data)."),
    ParamSpec("sample_time", 0.005, "float", "Nominal control period T [s].", 1e-5, 1.0),
    ParamSpec("camera_rate", 30.0, "float",
              "Frame rate of the camera as the controller should expect it [Hz] (0: a frame at "
              "every joint sample); sets the derived bandwidths (gain_design.*).", 0.0, None),
    ParamSpec("camera_latency", 0.05, "float",
              "Latency of the camera, capture to arrival, as the controller should expect it "
              "[s]; sets the derived bandwidths.", 0.0, 10.0),
    ParamSpec("camera_stamp_delay", 0.0, "float",
              "Time from a frame's capture to the time its stamp says [s]: the controller "
              "takes stamp - this as the capture time.  0 when the camera stamps its capture "
              "time (what sensor_msgs/Image's header.stamp should hold); a driver that stamps "
              "frames when it receives them: about camera_latency.", 0.0, 10.0),
    ParamSpec("gain_design.delay_bandwidth", 0.15, "float",
              "Derived gamma = this / tau, tau = sample_time + camera_latency + 1/(2 camera_rate) "
              "(the loop's bandwidth times its delay, rad).", 1e-3, 1.0),
    ParamSpec("gain_design.gamma_max", 20.0, "float", "Largest derived gamma [1/s].", 1e-3, None),
    ParamSpec("gain_design.observer_ratio", 2.0, "float",
              "Derived alpha = this x gamma (Theorem 1 needs > 1/3).", 0.34, 100.0),
    ParamSpec("gain_design.damping_per_sample", 0.2, "float",
              "Derived joint_damping.inertia_rate = this / sample_time: the per-sample step "
              "of the damped velocity loop (oscillates past 1, diverges past 2).", 0.0, 1.0),
    ParamSpec("gain_design.K_fraction", 0.05, "float",
              "Derived K: the largest scalar with J*^T K J* <= this x the joint damping at the "
              "first sample.", 1e-9, 1.0),
    ParamSpec("gain_design.kinematic_rate", 0.03, "float",
              "Derived Gamma_z_perp, Gamma_z: the kinematic estimates converge at this x gamma "
              "(regressor-normalised, docs/gain_design.md).", 0.0, 10.0),
    ParamSpec("gain_design.dynamic_rate", 0.3, "float",
              "Derived Gamma_d: the dynamic estimates converge at this x gamma.", 0.0, 10.0),
    ParamSpec("gain_design.dynamic_rate_max", 1.0, "float",
              "Derived Gamma_d: at most this convergence rate [1/s], whatever gamma "
              "(docs/gain_design.md).", 0.0, None),
    ParamSpec("gain_design.excitation_floor", 1e-3, "float",
              "Derived adaptation gains: a regressor column counts as carrying at least this "
              "fraction of the strongest column's energy (its gain at most 1/this times the "
              "strongest's).", 1e-9, 1.0),
    ParamSpec("gain_design.singular_fraction", 0.005, "float",
              "Derived min_singular_value: this fraction of the largest singular value of the "
              "estimated J(q0, x_d(0)), i.e. J* is damped past a condition number of 1 / this "
              "(docs/gain_design.md); 0: never damped.", 0.0, 1.0),
    ParamSpec("gain_design.follow_noise", True, "bool",
              "A derived gamma follows the pixel noise and the tracking error measured in the "
              "frames: lowered, down to gain_design.noise_min_factor x the delay's, where that "
              "lowers the tracking error they predict (docs/gain_design.md); false: the "
              "delay's gamma throughout.  No effect when gamma is given."),
    ParamSpec("gain_design.noise_window", 3.0, "float",
              "Window of those measurements, and the time constant with which gamma follows "
              "them [s].", 1e-3, None),
    ParamSpec("gain_design.noise_min_factor", 0.25, "float",
              "The measured noise never lowers gamma below this x the delay's gamma.",
              1e-3, 1.0),
    *(ParamSpec(f"gain_design.scale.{name}", 1.0, "float",
                f"The derived {name} times this (when {name} is left out).", 0.0, None)
      for name in DESIGNED),
    ParamSpec("K", None, "float_list",
              "Diagonal of the feedback gain K of eq (22), (2m,) or one number; left out: "
              "derived at the first joint sample (gain_design.K_fraction).", 0.0, None, True,
              optional=True, scalar=True),
    ParamSpec("joint_damping.inertia_rate",
              lambda m, v: v["gain_design.damping_per_sample"] / v["sample_time"], "float",
              "Joint-space damping of s, D = rate x (estimated inertia matrix at the start), "
              "added to eq (22) [1/s]; 0 = the paper's law.  Keeps Theorem 1 (see README).  "
              "Default: gain_design.damping_per_sample / sample_time.", 0.0, None),
    ParamSpec("joint_damping.diagonal", lambda m, v: [0.0] * m.n, "float_list",
              "A constant diagonal added to that damping [N m s/rad].", 0.0, None,
              scalar=True),
    ParamSpec("joint_damping.integral_rate", 10.0, "float",
              "k_i: eq (22) also gets -k_i D int s dt, the joint damping D acting on the "
              "integral of the joint velocity error (not in the paper; no effect without D): "
              "a wrong estimate of the dynamics no longer leaves a torque error the image loop "
              "must absorb.  Keeps Theorem 1 (docs/robust_adaptation.md) [1/s]; 0 = off.",
              0.0, None),
    ParamSpec("gamma", lambda m, v: DesignSettings.from_values(v).bandwidths()[1], "float",
              "Reference gain gamma of eq (18); alpha > gamma/3.  Default: "
              "min(gain_design.gamma_max, gain_design.delay_bandwidth / tau).", 0.0, None),
    ParamSpec("alpha", lambda m, v: v["gain_design.observer_ratio"] * v["gamma"], "float",
              "Observer gain alpha of eq (10); alpha > gamma/3.  Default: "
              "gain_design.observer_ratio x gamma.", 0.0, None),
    ParamSpec("reference.integral_rate", 0.25, "float",
              "Integral action in the reference velocity (not in the paper): x_r_dot = x_d_dot - "
              "gamma e - kappa int e, kappa = this x gamma^2; 0 = eq (18) "
              "(docs/robust_adaptation.md).", 0.0, 1.0),
    ParamSpec("robust.leakage_kinematic", 0.1, "float",
              "sigma-modification of eqs (24), (25) (not in the paper): a_hat_dot -= this x "
              "(a_hat - a_hat(0)) [1/s]; 0 = the paper's laws (docs/robust_adaptation.md).",
              0.0, None, True),
    ParamSpec("robust.leakage_dynamic", 0.1, "float",
              "The same for eq (23) [1/s].", 0.0, None, True),
    ParamSpec("Gamma_d_normalized", None, "float",
              "Gamma_d = this divided by the square of each Y_d column's typical size over "
              "random states (left out: Gamma_d derived at the first joint sample).", 0.0, None,
              optional=True),
    ParamSpec("Gamma_d", lambda m, v: (None if v["Gamma_d_normalized"] is None else
                                       list(v["Gamma_d_normalized"]
                                            / np.maximum(m.dynamic_column_rms(), 0.1) ** 2)),
              "float_list",
              "Diagonal of the dynamic adaptation gain Gamma_d of eq (23), or one number; left "
              "out: from Gamma_d_normalized, or derived at the first joint sample "
              "(gain_design.dynamic_rate).", 0.0, None, True, optional=True, scalar=True),
    ParamSpec("Gamma_z_perp", None, "float_list",
              "Diagonal of Gamma_z_perp of eq (24), or one number; left out: derived at the "
              "first joint sample (gain_design.kinematic_rate).", 0.0, None, True,
              optional=True, scalar=True),
    ParamSpec("Gamma_z", None, "float_list",
              "Diagonal of Gamma_z of eq (25), or one number; left out: derived at the first "
              "joint sample (gain_design.kinematic_rate).", 0.0, None, True, optional=True,
              scalar=True),
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
    ParamSpec("start_blend_speed", 1.0, "float",
              "The blend lasts long enough that its peak image speed is at most this x the "
              "RMS image speed of x_d (the typical motion the derived gains assume, "
              "docs/gain_design.md); start_blend_time and safety.recovery_blend_time are its "
              "least durations; 0 = those alone.", 0.0, None),
    ParamSpec("start_tolerance", 0.01, "float",
              "A start (or camera recovery) within this of x_d counts as on the trajectory and "
              "is not blended [px].", 0.0, None),
    ParamSpec("projection.enabled", True, "bool",
              "Project the kinematic adaptation (Remark 6) onto the bounds below."),
    ParamSpec("projection.a_z_perp_min", lambda m, v: [-INF] * m.p_perp, "float_list",
              "Lower bounds of a_z_perp_hat (or one number for all).",
              scalar=True),
    ParamSpec("projection.a_z_perp_max", lambda m, v: [INF] * m.p_perp, "float_list",
              "Upper bounds of a_z_perp_hat (or one number for all).",
              scalar=True),
    ParamSpec("projection.a_z_min", lambda m, v: [-INF] * m.p_z, "float_list",
              "Lower bounds of a_z_hat (or one number for all).",
              scalar=True),
    ParamSpec("projection.a_z_max", lambda m, v: [INF] * m.p_z, "float_list",
              "Upper bounds of a_z_hat (or one number for all).",
              scalar=True),
    ParamSpec("projection.a_d_min", lambda m, v: [-INF] * m.p_d, "float_list",
              "Lower bounds of a_d_hat (or one number for all).",
              scalar=True),
    ParamSpec("projection.a_d_max", lambda m, v: [INF] * m.p_d, "float_list",
              "Upper bounds of a_d_hat (or one number for all).",
              scalar=True),
    ParamSpec("projection.min_depth", 0.1, "float",
              "Smallest allowed estimated depth z_hat_i [m].", 1e-6, None),
    ParamSpec("torque_limit", lambda m, v: list(getattr(m, "effort_limits", [INF] * m.n)),
              "float_list",
              "Per-joint |tau| limit [N m], or one number; the command saturates there.  Left "
              "out: the URDF's <limit effort> of each joint (none where it gives none).", 0.0,
              None, True, scalar=True),
    ParamSpec("min_singular_value", 0.0, "float",
              "Damp the pseudo-inverse of J* when its smallest singular value drops below "
              "this [px m/rad]; 0 = never.  Left out: gain_design.singular_fraction x the "
              "largest singular value of the estimated J(q0, x_d(0)), at the first joint "
              "sample.", 0.0, None, True),
    ParamSpec("max_dt", 0.05, "float",
              "Longest interval integrated in one step [s]; longer gaps are clamped.",
              1e-5, 10.0),
    ParamSpec("image_bounds", lambda m, v: guessed_picture_bounds(v), "float_list",
              "Valid feature region [u_min, u_max, v_min, v_max] [px].  Default: the picture "
              "in the controller's pixels, from initial_estimate.camera's image_size, "
              "pixel_origin and pixel_axes (what a camera's driver tells)."),
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
    ParamSpec("motion_scale.enabled", True, "bool",
              "Learn the image-motion scale s from the camera frames and correct eqs (10), (18) "
              "by it (not in the paper; docs/robust_adaptation.md); false: the paper's law."),
    ParamSpec("motion_scale.window", 1.0, "float",
              "Time constant of the frames' weighting in the scale's regression [s].",
              0.01, 60.0),
    ParamSpec("motion_scale.rate", 3.0, "float",
              "How fast s follows the regression, and phi of the slow start decays, once it "
              "is trusted [1/s] (docs/robust_adaptation.md).", 1e-3, 100.0),
    ParamSpec("motion_scale.lower", 0.2, "float", "Lower bound of s.", 1e-3, 1.0),
    ParamSpec("motion_scale.upper", 5.0, "float", "Upper bound of s.", 1.0, 1e3),
    ParamSpec("motion_scale.initial", 1.0, "float",
              "s before the scale is first learnt (and after a reset), within [lower, upper] "
              "(docs/robust_adaptation.md).", 1e-3, 1e3),
    ParamSpec("motion_scale.start_factor", 1.5, "float",
              "The reference's slow start: eq (18) maps x_r_dot / (s phi), phi held at this "
              "until s is first learnt, then decaying to 1 at motion_scale.rate; 1: off "
              "(docs/robust_adaptation.md).", 1.0, 100.0),
    ParamSpec("motion_scale.min_motion", 1.0, "float",
              "RMS per image coordinate the predicted path must move within the window before "
              "s is learnt [px].", 0.0, None),
    ParamSpec("motion_scale.ratio_rate", 1.0, "float",
              "Learn, over the same window, how far a_z_perp is off relative to a_z from the "
              "frames' motion, and scale a_z_perp toward the fit at this rate [1/s] (not in "
              "the paper; docs/robust_adaptation.md); 0: off.", 0.0, 100.0),
    ParamSpec("motion_scale.ratio_condition", 0.02, "float",
              "Until the frames' noise is measured, the ratio is fitted only while the two "
              "parts of the model's image motion are this independent (smallest over largest "
              "eigenvalue of their 2 x 2 Gram matrix); then motion_scale.ratio_significance "
              "judges the fit instead.", 1e-6, 1.0),
    ParamSpec("motion_scale.ratio_band", 1.5, "float",
              "The ratio steps only while the fit's scale of the a_z part is within "
              "[1/band, band]: errors that are a ratio leave that part exact "
              "(docs/robust_adaptation.md).", 1.0, None),
    ParamSpec("motion_scale.ratio_evidence", 0.5, "float",
              "The ratio steps only while its two-part fit explains at least this share of "
              "what one scale leaves beyond the frames' measured noise: a guessed camera moved "
              "or turned is not a ratio (docs/robust_adaptation.md); 0: no test.", 0.0, 1.0),
    ParamSpec("motion_scale.ratio_significance", 3.0, "float",
              "Once the frames' noise is measured, the ratio steps only while its fit's "
              "k1 - k2 is this many of its standard deviations (from the noise) away from 0, "
              "in place of motion_scale.ratio_condition (docs/robust_adaptation.md); 0: no "
              "test, the condition throughout.", 0.0, 100.0),
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
    ParamSpec("reversed_motion", 5.0, "float",
              "Warn when the frames move against the model's image motion, their slope on the "
              "model's path below zero by this many standard errors (a guessed camera with a "
              "pixel axis the wrong way, on the far side of the arm or turned past 90 deg; "
              "also, for a second or two, a_z_perp far off relative to a_z, which the "
              "image-motion ratio mends); a divergence's reason says so (control/reversal.py). "
              "Needs motion_scale.enabled; 0: no check.", 0.0, None),
    ParamSpec("divergence_torque", 1e5, "float",
              "|tau| above this (before saturation) is reported as divergence [N m].", 0.0, None),
)


def build_controller_model(values, section=CONTROLLER_SECTION, search_dirs=(), model=None):
    """The controller's model from the structure parameters (``model`` reused if unchanged)."""
    name = values["model"]
    if name not in MODEL_NAMES:
        raise ValueError(f"model: unknown model name {name!r}; known: {list(MODEL_NAMES)}")
    if model is not None and getattr(model, "structure", None) == _structure_key(values):
        return model
    backend = values.get("backend", "auto")
    if backend not in ("auto",) + BACKENDS:
        raise ValueError(f"backend: must be one of {['auto', *BACKENDS]}, got {backend!r}")
    built = make_model(name, values, section, search_dirs,
                       backend=None if backend == "auto" else backend)
    built.structure = _structure_key(values)
    return built


def _structure_key(values):
    return tuple((k, tuple(v) if isinstance(v, (tuple, np.ndarray)) else v)
                 for k, v in sorted(values.items()) if k in STRUCTURE_PARAMS or k == "backend")


@dataclass(frozen=True, eq=False)
class ControllerConfig(ValidatedParams):
    """Validated parameters of the controller (``controller_node``), its model and x_d."""

    model: RobotCameraModel = None
    trajectory: object = None
    search_dirs: tuple = ()
    explicit: frozenset = frozenset()   # the parameters the configuration gave

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
        scalar = {spec.name for spec in CONTROLLER_PARAMS if spec.scalar}
        for name, length in lengths.items():
            require_length(v, name, length, section, name in scalar)
        require_length(v, "joint_names", model.n, section)
        chain = list(getattr(model, "joint_names", ()))
        if chain and list(v["joint_names"]) != chain:
            # the law's torques are in the chain's order, and a name the chain does not have
            # is not in /joint_states either: every sample refused, the arm at zero torque
            strangers = [name for name in v["joint_names"] if name not in chain]
            what = (f"{strangers} not among the URDF chain's joints" if strangers
                    else "not in the URDF chain's order")
            raise ConfigError(f"{section}.joint_names: {what} {chain}, got "
                              f"{list(v['joint_names'])} (left out: the chain's own)")
        if v["timing_mode"] not in TIMING_MODES:
            raise ConfigError(f"{section}.timing_mode: must be one of {TIMING_MODES}, "
                              f"got {v['timing_mode']!r}")
        for name in ("K", "Gamma_d", "Gamma_z_perp", "Gamma_z", "a_z_perp_init", "a_z_init",
                     "a_d_init", "trajectory.offset", "trajectory.a_cos", "trajectory.a_sin"):
            require_finite(v, name, section)
        for name in DESIGNED:
            if v[name] is not None and np.any(v[name] <= 0.0):
                raise ConfigError(f"{section}.{name}: every entry must be > 0 (a positive "
                                  f"definite gain; leave it out to have it derived), "
                                  f"{failing_entries(v[name], v[name] <= 0.0)}")
        for name in ("alpha", "gamma"):
            if v[name] <= 0.0:
                raise ConfigError(f"{section}.{name}: must be > 0, got {v[name]}")
        if np.any(v["torque_limit"] <= 0.0):
            raise ConfigError(f"{section}.torque_limit: every entry must be > 0, "
                              f"{failing_entries(v['torque_limit'], v['torque_limit'] <= 0.0)}")
        check_alpha_gamma(v["alpha"], v["gamma"], section)
        lower, upper = v["motion_scale.lower"], v["motion_scale.upper"]
        if not lower <= v["motion_scale.initial"] <= upper:
            raise ConfigError(f"{section}.motion_scale.initial: must be within "
                              f"[motion_scale.lower, motion_scale.upper] = [{lower}, {upper}], "
                              f"got {v['motion_scale.initial']}")
        check_image_bounds(v, section)
        if v["safety.fallback"] not in FALLBACKS:
            raise ConfigError(f"{section}.safety.fallback: must be one of {FALLBACKS}, "
                              f"got {v['safety.fallback']!r}")
        for name in ("a_z_perp", "a_z", "a_d"):
            lo, hi = v[f"projection.{name}_min"], v[f"projection.{name}_max"]
            init = v[f"{name}_init"]
            if np.any(lo > hi):
                raise ConfigError(f"{section}.projection.{name}_min: must be <= "
                                  f"projection.{name}_max element-wise")
            outside = (init < lo) | (init > hi)
            if v["projection.enabled"] and np.any(outside):
                raise ConfigError(f"{section}.{name}_init: must lie within "
                                  f"projection.{name}_min/_max, "
                                  f"{failing_entries(init, outside)}")
        trajectory = _trajectory(v, model.m, section, search_dirs)
        return cls(v, model, trajectory, tuple(search_dirs),
                   frozenset(name for name, value in params.items() if value is not None))

    def with_changes(self, **changes):
        """A new, whole-validated configuration with some parameters changed (same model)."""
        params = {name: value for name, value in self.params.items() if value is not None}
        params.update(changes)
        new = ControllerConfig.from_params(params, search_dirs=self.search_dirs,
                                           model=self.model)
        return replace(new, explicit=self.explicit | frozenset(changes))


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
