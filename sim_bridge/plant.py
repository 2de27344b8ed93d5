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

"""The PyBullet plant: a torque-controlled arm seen by a fixed pinhole camera.

ROS-free.  PyBullet runs in DIRECT mode with an explicit time step; its default
velocity motors and link damping are switched off, so the simulated arm is the
rigid-body model M q_ddot + C q_dot + g = tau and nothing else.  A torque
command lasts one ``stepSimulation`` in PyBullet, so :meth:`ArmPlant.advance`
re-applies it before every physics sub-step (zero-order hold over the control
period).
"""

from __future__ import annotations

import os
from collections import deque
from dataclasses import dataclass

import numpy as np
import pybullet

URDF_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "urdf")
SHIPPED_URDFS = {"paper_rrr": "paper_rrr.urdf"}


def shipped_urdf(model_name):
    """Path of the URDF shipped for a model name."""
    try:
        return os.path.join(URDF_DIR, SHIPPED_URDFS[model_name])
    except KeyError:
        raise ValueError(f"no URDF is shipped for model {model_name!r}") from None


class ArmPlant:
    """A fixed-base arm in its own PyBullet physics client (DIRECT mode).

    Parameters
    ----------
    urdf : str
        Path of the arm's URDF; its movable joints in order are the controlled joints.
    physics_dt : float
        Physics step [s].
    gravity : float
        Gravity along -z [m/s^2].
    tip_link : str
        Name of the link whose frame origin is the feature point.
    """

    def __init__(self, urdf, physics_dt=0.001, gravity=9.81, tip_link="tip"):
        self.physics_dt = float(physics_dt)
        self.client = pybullet.connect(pybullet.DIRECT)
        try:
            pb = self.client
            pybullet.setTimeStep(self.physics_dt, physicsClientId=pb)
            pybullet.setGravity(0.0, 0.0, -gravity, physicsClientId=pb)
            self.body = pybullet.loadURDF(urdf, useFixedBase=True,
                                          flags=pybullet.URDF_USE_INERTIA_FROM_FILE,
                                          physicsClientId=pb)
            self.joints, self.joint_names, tips = [], [], []
            for j in range(pybullet.getNumJoints(self.body, physicsClientId=pb)):
                info = pybullet.getJointInfo(self.body, j, physicsClientId=pb)
                if info[2] in (pybullet.JOINT_REVOLUTE, pybullet.JOINT_PRISMATIC):
                    self.joints.append(j)
                    self.joint_names.append(info[1].decode())
                if info[12].decode() == tip_link:
                    tips.append(j)
                pybullet.changeDynamics(self.body, j, linearDamping=0.0, angularDamping=0.0,
                                        jointDamping=0.0, physicsClientId=pb)
            if not tips:
                raise ValueError(f"{urdf}: no link named {tip_link!r}")
            self.tip = tips[0]
            # switch off the default velocity motors once, before torque control
            pybullet.setJointMotorControlArray(self.body, self.joints, pybullet.VELOCITY_CONTROL,
                                               forces=[0.0] * len(self.joints),
                                               physicsClientId=pb)
        except Exception:
            pybullet.disconnect(self.client)
            raise
        self.n = len(self.joints)
        self.t = 0.0

    def reset(self, q, qd=None):
        qd = np.zeros(self.n) if qd is None else qd
        for j, qi, qdi in zip(self.joints, q, qd):
            pybullet.resetJointState(self.body, j, float(qi), float(qdi),
                                     physicsClientId=self.client)
        self.t = 0.0

    def joint_state(self):
        """(q, q_dot) as float64 arrays (n,)."""
        states = pybullet.getJointStates(self.body, self.joints, physicsClientId=self.client)
        q, qd = np.array(list(zip(*states))[:2])
        return q, qd

    def tip_position(self):
        """World position of the feature point (3,)."""
        state = pybullet.getLinkState(self.body, self.tip, computeForwardKinematics=True,
                                      physicsClientId=self.client)
        return np.array(state[4])

    def advance(self, tau, substeps):
        """Hold ``tau`` for ``substeps`` physics steps (zero-order hold)."""
        forces = np.asarray(tau, dtype=float).tolist()
        for _ in range(substeps):
            pybullet.setJointMotorControlArray(self.body, self.joints, pybullet.TORQUE_CONTROL,
                                               forces=forces, physicsClientId=self.client)
            pybullet.stepSimulation(physicsClientId=self.client)
        self.t += substeps * self.physics_dt

    def mass_matrix(self, q):
        return np.array(pybullet.calculateMassMatrix(self.body, [float(v) for v in q],
                                                     physicsClientId=self.client))

    def inverse_dynamics(self, q, qd, qdd):
        return np.array(pybullet.calculateInverseDynamics(
            self.body, [float(v) for v in q], [float(v) for v in qd], [float(v) for v in qdd],
            physicsClientId=self.client))

    def close(self):
        if self.client is not None and pybullet.isConnected(self.client):
            pybullet.disconnect(self.client)
        self.client = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


@dataclass(frozen=True)
class PinholeCamera:
    """A fixed pinhole camera: pixels = f beta [X_C, Y_C] / Z_C, origin on the optical axis.

    ``rotation`` (3, 3) has the camera axes X_C, Y_C, Z_C as rows in the base
    frame; ``origin`` (3,) is the camera centre in the base frame.
    """

    focal_length: float
    scale: float
    rotation: np.ndarray
    origin: np.ndarray

    def __post_init__(self):
        # base frame -> [f beta X_C, f beta Y_C, Z_C] in one product (every control period)
        scaling = np.diag([self.focal_length * self.scale] * 2 + [1.0])
        object.__setattr__(self, "_to_image", (scaling @ np.asarray(self.rotation)).T)

    def project(self, points):
        """Pixels (2m,) and depths (m,) of base-frame points (m, 3)."""
        p = (np.asarray(points) - self.origin).dot(self._to_image)
        z = p[:, 2]
        if min(z.tolist()) > 0.0:
            uv = p[:, :2] / p[:, 2:]
        else:
            # a point on or behind the camera plane: inf/NaN pixels, marked not visible
            with np.errstate(divide="ignore", invalid="ignore"):
                uv = p[:, :2] / p[:, 2:]
        return uv.reshape(-1), z

    @classmethod
    def paper(cls, focal_length=0.15, scale=900.0, distance=5.0):
        """The paper's camera: X_C || Y_0, Y_C || Z_0, Z_C || X_0, centre at (-d_C, 0, 0)."""
        rotation = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
        return cls(focal_length, scale, rotation, np.array([-distance, 0.0, 0.0]))


@dataclass(frozen=True)
class CameraFrame:
    """One camera measurement: capture time, pixels (2m,) and true depths (m,)."""

    stamp: float
    pixels: np.ndarray
    depth: np.ndarray
    visible: bool


class FeatureCamera:
    """Produces the feature pixels seen by the controller: noise and frame delay.

    A frame captured at step k is delivered ``delay_frames`` frames later, with
    its own capture stamp.  Points behind the camera are marked not visible.
    """

    def __init__(self, camera, pixel_noise_std=0.0, delay_frames=0, seed=0):
        self.camera = camera
        self.noise = float(pixel_noise_std)
        self.rng = np.random.default_rng(seed)
        self.buffer = deque(maxlen=int(delay_frames) + 1)

    def capture(self, stamp, pixels, depth):
        """Capture a frame of the exact projection ``camera.project(points)`` now.

        Returns the frame due for delivery now (noise added, delay applied).
        """
        visible = min(depth.tolist()) > 0.0
        if self.noise > 0.0:
            pixels = pixels + self.rng.normal(0.0, self.noise, pixels.shape)
        self.buffer.append(CameraFrame(stamp, pixels, depth, visible))
        return self.buffer[0]
