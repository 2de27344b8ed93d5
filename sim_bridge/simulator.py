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
camera frame due now (noise and delay applied), then :meth:`Simulator.apply`
holds a torque over the physics sub-steps.  Commands are validated here too:
a command of the wrong length or with NaN/inf is refused and zero torque is
applied instead, with the reason returned to the caller.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import isfinite

import numpy as np

from .plant import ArmPlant, FeatureCamera, PinholeCamera, shipped_urdf


@dataclass(frozen=True)
class Measurement:
    """The sensors at one control instant."""

    t: float
    q: np.ndarray
    qd: np.ndarray
    tau_applied: np.ndarray
    feature_stamp: float | None      # capture time of the frame delivered now
    pixels: np.ndarray | None        # (2m,) px, None when no frame is due yet
    true_depth: np.ndarray           # (m,) depth at time t (ground truth, plots only)
    true_pixels: np.ndarray          # (2m,) noiseless pixels at time t
    problems: tuple = ()


def camera_for(model):
    """The fixed camera a model describes (only the paper's camera for now)."""
    return PinholeCamera.paper(model.focal_length, model.scale, model.camera_distance)


class Simulator:
    """PyBullet arm + pinhole camera configured by a :class:`SimConfig`."""

    def __init__(self, config):
        self.config = config
        self.model = config.model
        urdf = config.urdf or shipped_urdf(config.model_name)
        self.plant = ArmPlant(urdf, config.physics_dt, self.model.gravity)
        if self.plant.n != self.model.n:
            self.plant.close()
            raise ValueError(f"sim_node.urdf: {urdf} has {self.plant.n} joints, the model "
                             f"{config.model_name!r} has {self.model.n}")
        self.camera = camera_for(self.model)
        self.feature_camera = FeatureCamera(self.camera, config.pixel_noise_std,
                                            config.camera_delay_frames, config.seed)
        self.plant.reset(config.initial_positions, config.initial_velocities)
        self.tau = np.zeros(self.model.n)
        self.step_index = 0
        # read once: SimConfig attribute access goes through __getattr__ (every period)
        self._period = config.control_period
        self._substeps = config.substeps
        self._delay_frames = config.camera_delay_frames

    @property
    def t(self):
        return self.step_index * self._period

    def measure(self):
        """Sensors now; a frame is delivered once the camera delay has passed."""
        q, qd = self.plant.joint_state()
        t = self.t
        true_pixels, true_depth = self.camera.project(self.plant.tip_position()[None, :])
        frame = self.feature_camera.capture(t, true_pixels, true_depth)
        problems = []
        pixels, stamp = None, None
        if self.step_index >= self._delay_frames:
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
        if tau.shape != (self.model.n,):
            problem = f"command: expected {self.model.n} torques, got {tau.shape[0]}"
        elif not all(map(isfinite, tau.tolist())):
            problem = f"command: contains NaN or inf: {tau.tolist()}"
        self.tau = np.zeros(self.model.n) if problem else tau
        self.plant.advance(self.tau, self._substeps)
        self.step_index += 1
        return problem

    def close(self):
        self.plant.close()
