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

"""The PyBullet plant: a torque-controlled arm from any URDF, with feature points.

ROS-free.  PyBullet runs in DIRECT mode with an explicit time step; its default
velocity motors and link damping are switched off, so the simulated arm is the
rigid-body model M q_ddot + C q_dot + g = tau and nothing else.  The URDF is
checked before PyBullet reads it (:func:`~visual_adaptive_servo.models.urdf_checks.check_urdf`:
every moving link's mass and inertia, every mesh), so what PyBullet would
silently misread or refuse with a bare "Cannot load URDF file." is a
``ConfigError`` naming the link, the file and the rule.  A torque
command lasts one ``stepSimulation`` in PyBullet, so :meth:`ArmPlant.advance`
re-applies it before every physics sub-step (zero-order hold over the control
period).  The cameras are in :mod:`.camera`.
"""

from __future__ import annotations

import os

import numpy as np
import pybullet

from visual_adaptive_servo.models.urdf_checks import check_urdf, UrdfError
from visual_adaptive_servo.schema import ConfigError, SIM_SECTION

URDF_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "urdf")


class ArmPlant:
    """A fixed-base arm in its own PyBullet physics client (DIRECT mode).

    Parameters
    ----------
    urdf : str
        Path of the arm's URDF; its root link is fixed at the world origin.
    physics_dt : float
        Physics step [s].
    gravity : float
        Gravity along -z [m/s^2].
    tip_link : str
        Link that carries the feature points.
    joint_names : sequence of str, optional
        The controlled joints, in order (default: every revolute/prismatic joint of
        the file, in file order).  Any other movable joint (a gripper's fingers) is
        held at its zero position by a stiff position motor.
    feature_points : (m, 3), optional
        Offsets c_i of the feature points in the tip frame [m]; default the tip
        link's origin.
    section : str
        Configuration section named in a URDF error (``section.urdf: ...``).

    Raises
    ------
    ConfigError
        The URDF breaks a rule of :func:`~visual_adaptive_servo.models.urdf_checks.check_urdf`
        (checked before PyBullet reads it).
    """

    def __init__(self, urdf, physics_dt=0.001, gravity=9.81, tip_link="tip", joint_names=None,
                 feature_points=((0.0, 0.0, 0.0),), section=SIM_SECTION):
        try:
            check_urdf(os.path.abspath(urdf), joint_names, section, simulator=True)
        except UrdfError as exc:
            raise ConfigError(str(exc)) from None
        self.physics_dt = float(physics_dt)
        self.offsets = np.asarray(feature_points, dtype=float).reshape(-1, 3)
        self.client = pybullet.connect(pybullet.DIRECT)
        try:
            pb = self.client
            pybullet.setTimeStep(self.physics_dt, physicsClientId=pb)
            pybullet.setGravity(0.0, 0.0, -gravity, physicsClientId=pb)
            self.body = pybullet.loadURDF(urdf, useFixedBase=True,
                                          flags=pybullet.URDF_USE_INERTIA_FROM_FILE,
                                          physicsClientId=pb)
            movable, by_name, tips = [], {}, []
            for j in range(pybullet.getNumJoints(self.body, physicsClientId=pb)):
                info = pybullet.getJointInfo(self.body, j, physicsClientId=pb)
                if info[2] in (pybullet.JOINT_REVOLUTE, pybullet.JOINT_PRISMATIC):
                    movable.append(j)
                    by_name[info[1].decode()] = j
                if info[12].decode() == tip_link:
                    tips.append(j)
                pybullet.changeDynamics(self.body, j, linearDamping=0.0, angularDamping=0.0,
                                        jointDamping=0.0, physicsClientId=pb)
            if not tips:
                raise ValueError(f"{urdf}: no link named {tip_link!r} (or it is the root link)")
            self.tip = tips[0]
            if joint_names is None:
                joint_names = [name for name, j in sorted(by_name.items(), key=lambda e: e[1])]
            missing = [name for name in joint_names if name not in by_name]
            if missing:
                raise ValueError(f"{urdf}: no movable joint(s) {missing}; movable: "
                                 f"{sorted(by_name)}")
            self.joints = [by_name[name] for name in joint_names]
            self.joint_names = list(joint_names)
            self.held = [j for j in movable if j not in self.joints]
            # switch off the default velocity motors once, before torque control
            pybullet.setJointMotorControlArray(self.body, self.joints, pybullet.VELOCITY_CONTROL,
                                               forces=[0.0] * len(self.joints),
                                               physicsClientId=pb)
            if self.held:
                pybullet.setJointMotorControlArray(
                    self.body, self.held, pybullet.POSITION_CONTROL,
                    targetPositions=[0.0] * len(self.held), forces=[1e4] * len(self.held),
                    physicsClientId=pb)
        except Exception:
            pybullet.disconnect(self.client)
            raise
        self.n = len(self.joints)
        self.markers = []
        self.t = 0.0

    def reset(self, q, qd=None):
        qd = np.zeros(self.n) if qd is None else qd
        for j, qi, qdi in zip(self.joints, q, qd):
            pybullet.resetJointState(self.body, j, float(qi), float(qdi),
                                     physicsClientId=self.client)
        for j in self.held:
            pybullet.resetJointState(self.body, j, 0.0, 0.0, physicsClientId=self.client)
        self.t = 0.0

    def joint_state(self):
        """(q, q_dot) as float64 arrays (n,)."""
        states = pybullet.getJointStates(self.body, self.joints, physicsClientId=self.client)
        q, qd = np.array(list(zip(*states))[:2])
        return q, qd

    def tip_pose(self):
        """World rotation (3, 3) and origin (3,) of the tip link's frame."""
        state = pybullet.getLinkState(self.body, self.tip, computeForwardKinematics=True,
                                      physicsClientId=self.client)
        R = np.array(pybullet.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        return R, np.array(state[4])

    def tip_position(self):
        """World position of the tip link's origin (3,)."""
        state = pybullet.getLinkState(self.body, self.tip, computeForwardKinematics=True,
                                      physicsClientId=self.client)
        return np.array(state[4])

    def feature_positions(self):
        """World positions (m, 3) of the feature points."""
        R, p = self.tip_pose()
        return p + self.offsets.dot(R.T)

    def add_markers(self, radius, colors):
        """Coloured spheres at the feature points, for the rendered picture (no mass, no contact).

        ``colors`` (m, 3) RGB 0-255.  :meth:`place_markers` moves them to the points.
        """
        for rgb in np.asarray(colors, dtype=float).reshape(-1, 3):
            shape = pybullet.createVisualShape(pybullet.GEOM_SPHERE, radius=float(radius),
                                               rgbaColor=list(rgb / 255.0) + [1.0],
                                               physicsClientId=self.client)
            self.markers.append(pybullet.createMultiBody(
                baseMass=0.0, baseVisualShapeIndex=shape, baseCollisionShapeIndex=-1,
                physicsClientId=self.client))
        self.place_markers()

    def place_markers(self):
        for body, point in zip(self.markers, self.feature_positions()):
            pybullet.resetBasePositionAndOrientation(body, point.tolist(), (0.0, 0.0, 0.0, 1.0),
                                                     physicsClientId=self.client)

    def advance(self, tau, substeps):
        """Hold ``tau`` for ``substeps`` physics steps (zero-order hold)."""
        forces = np.asarray(tau, dtype=float).tolist()
        for _ in range(substeps):
            pybullet.setJointMotorControlArray(self.body, self.joints, pybullet.TORQUE_CONTROL,
                                               forces=forces, physicsClientId=self.client)
            pybullet.stepSimulation(physicsClientId=self.client)
        self.t += substeps * self.physics_dt

    def brake(self, substeps):
        """Stop the joints where they are and keep them there for ``substeps`` physics steps.

        What a real arm's brakes do when its drives get no command: no torque, no
        motion (the joints' velocities are zeroed at once).
        """
        q, _ = self.joint_state()
        for j, qi in zip(self.joints, q):
            pybullet.resetJointState(self.body, j, float(qi), 0.0, physicsClientId=self.client)
        self.t += substeps * self.physics_dt

    def _all_joints(self, values):
        """``values`` of the controlled joints spread over every movable joint (others 0)."""
        full = {j: float(v) for j, v in zip(self.joints, values)}
        order = sorted(self.joints + self.held)
        return order, [full.get(j, 0.0) for j in order]

    def mass_matrix(self, q):
        order, full = self._all_joints(q)
        M = np.array(pybullet.calculateMassMatrix(self.body, full, physicsClientId=self.client))
        index = [order.index(j) for j in self.joints]
        return M[np.ix_(index, index)]

    def inverse_dynamics(self, q, qd, qdd):
        order, q_full = self._all_joints(q)
        _, qd_full = self._all_joints(qd)
        _, qdd_full = self._all_joints(qdd)
        tau = np.array(pybullet.calculateInverseDynamics(self.body, q_full, qd_full, qdd_full,
                                                         physicsClientId=self.client))
        return tau[[order.index(j) for j in self.joints]]

    def close(self):
        if self.client is not None and pybullet.isConnected(self.client):
            pybullet.disconnect(self.client)
        self.client = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
