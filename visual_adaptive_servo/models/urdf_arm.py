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

"""Any serial arm described by a URDF, with one to three feature points: the paper's general case.

* Kinematics (Property 1): :class:`~.kinematic_regressor.KinematicRegressor` on the
  chain ``base_link`` -> ``tip_link``; the camera and the chosen lengths are unknown.
* Dynamics (Property 4): :class:`~.rigid_body.RigidBodyDynamics` (Pinocchio's joint
  torque regressor, reduced to base parameters).

Assumption 1 of the paper is checked at construction: m <= 3, n >= 2m, the
points distinct (m = 2) and not collinear (m = 3).  The rank of J(q, u)
(Assumption 2) depends on the pose and the camera and is checked where both
are known (the start-up check of :func:`~visual_adaptive_servo.config.load_scenario`
and every sample's singular-value guard).  The file's mass properties are
checked before Pinocchio reads them (:func:`~.urdf_checks.check_urdf`).
"""

from __future__ import annotations

import logging

import numpy as np

from .backend import compile_notice, resolve_backend
from .base import GRAVITY, RobotCameraModel
from .kinematic_regressor import KinematicRegressor
from .resources import resolve_path
from .urdf_chain import load_chain
from .urdf_checks import check_urdf

log = logging.getLogger(__name__)

#: smallest triangle area / longest side (m) that counts as non-collinear
COLLINEAR_TOLERANCE = 1e-3


def check_feature_points(offsets, n, section):
    """Assumption 1 on the feature offsets (m, 3) of an n-joint arm; ValueError naming it."""
    offsets = np.asarray(offsets, dtype=float)
    m = len(offsets)
    where = f"{section}.feature_points"
    if not 1 <= m <= 3:
        raise ValueError(f"{where}: 1, 2 or 3 points (3 numbers each) are supported, got {m} "
                         f"(Assumption 1 of the paper: m <= 3)")
    if n < 2 * m:
        raise ValueError(f"{where}: {m} points need at least {2 * m} joints (Assumption 1: "
                         f"n >= 2m); the chain has {n}")
    if m >= 2:
        sides = [np.linalg.norm(offsets[i] - offsets[j]) for i in range(m) for j in range(i)]
        if min(sides) < COLLINEAR_TOLERANCE:
            raise ValueError(f"{where}: two feature points coincide "
                             f"({offsets.tolist()}): each point must be distinct")
    if m == 3:
        area = 0.5 * np.linalg.norm(np.cross(offsets[1] - offsets[0], offsets[2] - offsets[0]))
        if area / max(sides) < COLLINEAR_TOLERANCE:
            raise ValueError(f"{where}: the three points are collinear ({offsets.tolist()}); "
                             f"Assumption 1 of the paper needs them non-collinear")


class UrdfArmCamera(RobotCameraModel):
    """An arm from its URDF seen by an unknown fixed camera.

    Parameters
    ----------
    urdf : str
        File name (``package://`` and ``pybullet_data://`` accepted, see
        :func:`~visual_adaptive_servo.models.resources.resolve_path`).
    base_link, tip_link : str
        The chain's ends; its revolute and prismatic joints are the controlled joints.
    feature_points : sequence of float
        Nominal offsets c_i of the m feature points in the tip frame, 3 numbers
        each [m].
    unknown_lengths : "all" or sequence of str
        Lengths adapted as unknown (see ``KinematicRegressor.length_names``).
    section : str
        Configuration section used in error messages.
    backend : {"compiled", "numpy"}, optional
        Implementation of :meth:`kinematic_tensors` (see :mod:`.backend`); default
        compiled when numba imports.
    """

    def __init__(self, urdf, base_link, tip_link, feature_points, unknown_lengths="all",
                 gravity=GRAVITY, section="controller_node", search_dirs=(), backend=None):
        from .rigid_body import RigidBodyDynamics

        backend = resolve_backend(backend, section)

        try:
            path = resolve_path(urdf, search_dirs, f"{section}.urdf")
        except FileNotFoundError as exc:
            raise ValueError(str(exc)) from None
        self.urdf = path
        self.chain = load_chain(path, base_link, tip_link, section)
        check_urdf(path, self.chain.joint_names, section, simulator=False)
        offsets = np.asarray(feature_points, dtype=float)
        if offsets.size == 0 or offsets.size % 3:
            raise ValueError(f"{section}.feature_points: 3 numbers per point, got "
                             f"{offsets.size} numbers")
        offsets = offsets.reshape(-1, 3)
        check_feature_points(offsets, self.chain.n, section)
        self.offsets = offsets
        self.gravity = float(gravity)
        try:
            self.kinematics = KinematicRegressor(self.chain, offsets, unknown_lengths, backend)
        except ValueError as exc:
            raise ValueError(f"{section}.{exc}") from None
        self.dynamics = RigidBodyDynamics(path, base_link, tip_link, gravity)
        if tuple(self.dynamics.joint_names) != self.chain.joint_names:
            raise ValueError(f"{section}.urdf: the dynamics library reads the joints "
                             f"{list(self.dynamics.joint_names)}, the chain "
                             f"{list(self.chain.joint_names)}")
        self.n, self.m = self.chain.n, len(offsets)
        self.p_perp, self.p_z = self.kinematics.p_perp, self.kinematics.p_z
        self.p_d = self.dynamics.p_d
        self.a_z_perp_labels = self.kinematics.perp_reduction.labels
        self.a_z_labels = self.kinematics.z_reduction.labels
        self.a_d_labels = tuple(self.dynamics.parameter_labels)
        self._truth = None
        self._compile_dynamics()

    @property
    def joint_names(self):
        return self.chain.joint_names

    @property
    def effort_limits(self):
        """The URDF's ``<limit effort>`` per joint; inf where it gives none."""
        return self.chain.effort_limits

    @property
    def position_limits(self):
        """The URDF's ``(lower, upper)`` per joint [rad or m]; infinite where it gives none."""
        return self.chain.position_limits

    @property
    def prismatic(self):
        """Per joint: True where it slides."""
        return tuple(j.prismatic for j in self.chain.joints)

    @property
    def backend(self):
        """``"compiled"`` or ``"numpy"``: what :meth:`kinematic_tensors` runs."""
        return self.kinematics.backend

    def set_backend(self, backend):
        """Run :meth:`kinematic_tensors` and :meth:`dynamic_regressor` on ``backend`` from now on.

        See :mod:`.backend`.
        """
        self.kinematics.set_backend(backend)
        self._compile_dynamics()

    def _compile_dynamics(self):
        """With the compiled backend: the compiled Y_d, checked once against Pinocchio's.

        A chain the kernel cannot describe, or a mismatch, keeps Pinocchio's (a warning).
        """
        self._dynamics_constants = None
        if self.backend != "compiled":
            return
        from . import dynamics_kernels

        try:
            constants = self.dynamics.kernel_constants()
        except ValueError as exc:
            log.warning("dynamic regressor: Pinocchio's (the compiled one cannot run: %s)", exc)
            return
        rng = np.random.default_rng(0)
        q = rng.uniform(-np.pi, np.pi, self.n)
        qd, xi, xi_dot = rng.standard_normal((3, self.n))
        with compile_notice("dynamic regressor"):
            compiled = dynamics_kernels.chain_regressor(q, qd, xi, xi_dot, *constants)
        reference = self.dynamics.regressor(q, qd, xi, xi_dot)
        error = np.max(np.abs(compiled - reference)) / max(np.max(np.abs(reference)), 1.0)
        if not error < 1e-10:
            log.warning("dynamic regressor: Pinocchio's (the compiled one differs by %.3g of "
                        "its scale at a random state)", error)
            return
        self._dynamics_constants = constants

    def dynamics_kernel(self):
        """``(1, constants)`` of the compiled Y_d (:mod:`.dynamics_kernels`), or None."""
        if self._dynamics_constants is None:
            return None
        return 1, self._dynamics_constants

    def kinematic_tensors(self, q, qd):
        return self.kinematics.tensors(q, qd)

    def dynamic_regressor(self, q, qd, xi, xi_dot):
        if self._dynamics_constants is None:
            return self.dynamics.regressor(q, qd, xi, xi_dot)
        from .dynamics_kernels import chain_regressor

        args = [np.ascontiguousarray(v, dtype=float) for v in (q, qd, xi, xi_dot)]
        if any(v.shape != (self.n,) for v in args):
            raise ValueError(f"dynamic regressor: q, q_dot, xi, xi_dot need shape ({self.n},), "
                             f"got {[v.shape for v in args]}")
        return chain_regressor(*args, *self._dynamics_constants)

    def dynamic_regressor_numpy(self, q, qd, xi, xi_dot):
        """:meth:`dynamic_regressor` of the numpy backend (Pinocchio's): the reference."""
        return self.dynamics.regressor(q, qd, xi, xi_dot)

    def estimate(self, camera_matrix, length_scale=1.0, inertia_scale=1.0):
        lengths = {L.name: L.value * length_scale for L in self.kinematics.lengths}
        a_z_perp, a_z = self.kinematics.parameters(self._in_base(camera_matrix), lengths)
        return a_z_perp, a_z, inertia_scale * self.dynamics.parameters()

    def set_ground_truth(self, camera_matrix, chain=None, offsets=None):
        chain = self.chain if chain is None else chain
        offsets = self.offsets if offsets is None else np.asarray(offsets, float).reshape(-1, 3)
        if chain.joint_names != self.chain.joint_names or offsets.shape != self.offsets.shape:
            raise ValueError(f"sim_node: the simulated arm (joints {list(chain.joint_names)}, "
                             f"{len(offsets)} points) is not the controller's model (joints "
                             f"{list(self.chain.joint_names)}, {self.m} points)")
        lengths = {}
        for joint in chain.joints:
            for j, axis in enumerate("xyz"):
                lengths[f"{joint.name}.{axis}"] = joint.origin_translation[j]
        tip_name = chain.tip_joints[-1] if chain.tip_joints else chain.tip_link
        for j, axis in enumerate("xyz"):
            lengths[f"{tip_name}.{axis}"] = chain.tip_translation[j]
        for i, c in enumerate(offsets):
            for j, axis in enumerate("xyz"):
                lengths[f"point{i + 1}.{axis}"] = c[j]
        names = set(self.kinematics.length_names)
        P_base = self._in_base(camera_matrix)
        a_z_perp, a_z = self.kinematics.parameters(
            P_base, {k: v for k, v in lengths.items() if k in names})
        self._truth = (P_base, chain, offsets)
        self.a_z_perp, self.a_z, self.a_d = a_z_perp, a_z, self.dynamics.parameters()

    def _in_base(self, camera_matrix):
        """A projection matrix of the URDF root frame, re-expressed in the chain's base frame."""
        return np.asarray(camera_matrix, dtype=float) @ self.chain.root_to_base

    def _require_truth(self):
        if self._truth is None:
            raise RuntimeError("UrdfArmCamera: no ground truth (set_ground_truth is called by "
                               "the simulator's configuration; a real arm has none)")
        return self._truth

    def feature_positions(self, q):
        _, chain, offsets = self._require_truth()
        return chain.points(q, offsets)

    def project(self, q):
        P, _, _ = self._require_truth()
        r = self.feature_positions(q)
        h = r @ P[:, :3].T + P[:, 3]
        return (h[:, :2] / h[:, 2:]).reshape(-1), h[:, 2]

    def mass_matrix(self, q):
        return self.dynamics.mass_matrix(q)

    def coriolis_matrix(self, q, qd):
        return self.dynamics.coriolis_matrix(q, qd)

    def gravity_torque(self, q):
        return self.dynamics.gravity_torque(q)
