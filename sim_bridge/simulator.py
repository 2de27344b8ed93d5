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

"""The simulated robot + camera as one object: what ``sim_node`` and ``vas run`` drive.

Each control period: :meth:`Simulator.measure` returns the joint state and the
camera frame published now, if any (camera rate, noise and latency applied,
stamped with its capture time), then :meth:`Simulator.apply` holds a torque
over the physics sub-steps.  Commands are validated here too:
a command of the wrong length or with NaN/inf is refused and zero torque is
applied instead, with the reason returned to the caller.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import isfinite

import numpy as np

from visual_adaptive_servo.models import GRAVITY

from .camera import FeatureCamera
from .plant import ArmPlant


@dataclass(frozen=True)
class Measurement:
    """The sensors at one control instant."""

    t: float
    q: np.ndarray
    qd: np.ndarray
    tau_applied: np.ndarray
    feature_stamp: float | None      # capture time of the frame published now
    pixels: np.ndarray | None        # (2m,) px, None when no frame is published now
    true_depth: np.ndarray           # (m,) depth at time t (ground truth, plots only)
    true_pixels: np.ndarray          # (2m,) noiseless pixels at time t
    problems: tuple = ()


class Simulator:
    """PyBullet arm + pinhole camera configured by a :class:`SimConfig`.

    The arm is ``sim_node.urdf`` (its chain ``base_link`` -> ``tip_link``), the
    feature points are ``feature_points`` in the tip frame, the camera is
    ``sim_node.camera.*``: nothing here depends on the controller's model.
    """

    def __init__(self, config):
        self.config = config
        arm = config.arm
        self.n = arm.n
        self.plant = ArmPlant(arm.chain.urdf, config.physics_dt, GRAVITY, arm.chain.tip_link,
                              arm.chain.joint_names, arm.offsets)
        self.camera = config.camera
        self.feature_camera = FeatureCamera(self.camera, config.pixel_noise_std,
                                            config.camera_rate, config.camera_latency, config.seed)
        self.plant.reset(config.initial_positions, config.initial_velocities)
        self.tau = np.zeros(self.n)
        self.step_index = 0
        # read once: SimConfig attribute access goes through __getattr__ (every period)
        self._period = config.control_period
        self._substeps = config.substeps

    @property
    def t(self):
        return self.step_index * self._period

    def measure(self):
        """Sensors now: the joint state, and the camera frame published now (if any)."""
        q, qd = self.plant.joint_state()
        t = self.t
        true_pixels, true_depth = self.camera.project(self.plant.feature_positions())
        frame = self.feature_camera.step(t, true_pixels, true_depth)
        problems = []
        pixels, stamp = None, None
        if frame is not None:
            if frame.visible:
                pixels, stamp = frame.pixels, frame.stamp
            else:
                problems.append(f"feature behind the camera at t={frame.stamp:.3f} "
                                f"(depth {frame.depth.tolist()})")
        return Measurement(t, q, qd, self.tau.copy(), stamp, pixels, true_depth,
                           true_pixels, tuple(problems))

    def apply(self, tau):
        """Hold ``tau`` for one control period; returns a reason if it was refused."""
        problem = None
        tau = np.asarray(tau, dtype=float).reshape(-1)
        if tau.shape != (self.n,):
            problem = f"command: expected {self.n} torques, got {tau.shape[0]}"
        elif not all(map(isfinite, tau.tolist())):
            problem = f"command: contains NaN or inf: {tau.tolist()}"
        self.tau = np.zeros(self.n) if problem else tau
        self.plant.advance(self.tau, self._substeps)
        self.step_index += 1
        return problem

    def close(self):
        self.plant.close()
