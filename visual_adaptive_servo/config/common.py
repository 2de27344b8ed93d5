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

"""Parameter specs shared by the sections: a pinhole camera, an arm's structure.

The simulator's camera (``sim_node.camera.*``) and the controller's guessed camera
(``controller_node.initial_estimate.camera.*``) have the same parameters; so have
the simulated arm and the controller's URDF model (``urdf``, ``base_link``,
``tip_link``, ``feature_points``).
"""

from __future__ import annotations

from sim_bridge.camera import PinholeCamera

from ..schema import ConfigError, ParamSpec, require_length

PAPER_URDF = "package://visual_adaptive_servo/urdf/paper_rrr.urdf"
MARKER_COLORS = (230.0, 30.0, 30.0, 30.0, 200.0, 30.0, 40.0, 90.0, 255.0)   # red, green, blue


def camera_specs(prefix, what):
    """The parameters of one pinhole camera (defaults: the paper's camera)."""
    return (
        ParamSpec(prefix + "position", [-5.0, 0.0, 0.0], "float_list",
                  f"{what}: centre in the URDF root frame [m]."),
        ParamSpec(prefix + "orientation", "look_at", "str",
                  f"{what}: 'look_at' (read look_at and up; rpy is not read) or 'rpy' (read "
                  f"rpy; look_at and up are not read)."),
        ParamSpec(prefix + "look_at", [0.0, 0.0, 0.0], "float_list",
                  f"{what}: a point on the optical axis [m] (orientation look_at)."),
        ParamSpec(prefix + "up", [0.0, 0.0, 1.0], "float_list",
                  f"{what}: the direction that points up in the picture (orientation look_at)."),
        ParamSpec(prefix + "rpy", [0.0, 0.0, 0.0], "float_list",
                  f"{what}: orientation of the camera frame (X right, Y down, Z along the "
                  f"optical axis) as URDF roll-pitch-yaw [rad] (orientation rpy)."),
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


def structure_specs(default_urdf, default_base, default_tip, default_points, what):
    """The parameters that define an arm: its URDF, chain and feature points."""
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


def build_camera(values, prefix, section):
    """The :class:`PinholeCamera` of the ``prefix`` parameters (ConfigError naming them)."""
    try:
        return PinholeCamera.from_params(values, prefix, section)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def check_image_bounds(v, section):
    """``image_bounds`` is [u_min, u_max, v_min, v_max] with u_min < u_max, v_min < v_max."""
    require_length(v, "image_bounds", 4, section)
    u0, u1, v0, v1 = v["image_bounds"]
    if not (u0 < u1 and v0 < v1):
        raise ConfigError(f"{section}.image_bounds: needs u_min < u_max and v_min < v_max, "
                          f"got {v['image_bounds'].tolist()}")
