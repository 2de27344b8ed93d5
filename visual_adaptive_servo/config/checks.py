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

"""The start-up checks of a simulator and controller configuration (ConfigError naming what fails).

:func:`check_pair`: the controller's model describes the simulated arm (n, m,
joint names) and takes its camera and arm as ground truth; :func:`check_start`:
every feature point in front of the camera and inside both the picture and the
controller's ``image_bounds`` at the start, the true and the estimated image
Jacobian of full row rank (Assumption 2 of the paper).
"""

from __future__ import annotations

import numpy as np

from ..schema import CONTROLLER_SECTION, ConfigError, SIM_SECTION
from .controller import guessed_picture_bounds


def check_pair(sim, ctrl):
    """The controller's model fits the simulated arm; it gets the sim's camera and arm as truth."""
    model = ctrl.model
    if (model.n, model.m) != (sim.arm.n, sim.arm.m):
        raise ConfigError(f"controller_node.model: describes {model.n} joints and {model.m} "
                          f"point(s); the simulated arm (sim_node.urdf, feature_points) has "
                          f"{sim.arm.n} and {sim.arm.m}")
    if sim.tag is not None and "feature_points" in ctrl.params and ctrl["model"] == "urdf":
        if not np.allclose(ctrl["feature_points"], sim.arm.offsets.reshape(-1), rtol=0.0,
                           atol=1e-6):
            raise ConfigError(f"controller_node.feature_points: must be the tag's points "
                              f"(sim_node.feature_points, markers.tag.*) "
                              f"{sim.arm.offsets.reshape(-1).tolist()}, got "
                              f"{list(ctrl['feature_points'])}")
    if tuple(ctrl.joint_names) != tuple(sim.joint_names):
        raise ConfigError(f"controller_node.joint_names: must equal sim_node.joint_names "
                          f"{list(sim.joint_names)}, got {list(ctrl.joint_names)}")
    try:
        model.set_ground_truth(sim.camera.projection_matrix, sim.arm.chain, sim.arm.offsets)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def check_start(sim, ctrl):
    """The start pose: points visible and in bounds, J(q, x) of full rank (module docstring)."""
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
            hint = ""
            if section.endswith("image_bounds") and not np.allclose(bounds, sim.image_bounds):
                picture = [float(b) for b in sim.image_bounds]
                if np.allclose(bounds, guessed_picture_bounds(ctrl.params)):
                    # left out: the guessed camera's picture, in its own pixel convention
                    hint = (f"; image_bounds is initial_estimate.camera's picture (its "
                            f"image_size, pixel_origin, pixel_axes), and the camera's pixels "
                            f"lie in {picture}: give the guessed camera your camera's "
                            f"pixel_origin and pixel_axes (what its driver reports)")
                else:
                    hint = (f"; the simulated camera's picture is {picture} in the "
                            f"controller's pixels (its pixel_origin, pixel_axes): give "
                            f"controller_node.image_bounds your camera's picture in the same "
                            f"pixels, or leave it out to have it from initial_estimate.camera")
            raise ConfigError(f"sim_node.initial_positions: feature point(s) {outside} outside "
                              f"the image at the start (pixels {np.round(pixels, 1).tolist()}, "
                              f"{section} {[float(b) for b in bounds]}){hint}")
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
