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


"""The abstract robot + fixed-camera model: the regressors of Properties 1 and 4.

A model owns the structure of the kinematics, the camera and the dynamics, and
exposes everything the controller needs as *regressors* that are linear in the
unknown parameters:

=====================  ========================================================
``a_z``  (p_z,)        depth parameters:          z(q) = H(q) a_z
``a_z_perp`` (p_perp,) depth-rate-independent:    J_z_perp(q) q_dot = Y_z_perp a_z_perp
``a_d`` (p_d,)         dynamic parameters:        M xi_dot + C xi + g = Y_d a_d
=====================  ========================================================

The kinematic structure is given by three tensors whose layout makes every
contraction a single ``@``:

* ``H(q)``      (m, p_z):         depth regressor, ``z = H @ a_z``
* ``dH(q)``     (m, n, p_z):      its joint gradient, ``J_z = dH @ a_z`` (m, n)
* ``W(q)``      (2m, n, p_perp):  ``J_z_perp = W @ a_z_perp`` (2m, n)

plus their time derivatives along ``q_dot`` (needed by the total derivatives
in eq (19)).  From these, :class:`RobotCameraModel` derives the paper's
``Y_z``, ``Y_z_bar``, ``Y_z_perp`` and the estimated Jacobian of eq (a1).

The controller never sees the true parameters; they live on the model only so
that the simulator and the tests have ground truth (:meth:`set_ground_truth`,
from the simulator's camera and URDF).  :meth:`estimate` turns nominal
knowledge -- a guessed camera, nominal lengths and masses -- into initial
estimates, the way a user with a real arm and camera would start.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

GRAVITY = 9.81  # m/s^2


class RobotCameraModel(ABC):
    """Structure of an n-joint arm seen by a fixed pinhole camera (m feature points).

    Subclasses implement the abstract tensors; everything else is derived here
    once, so that a new robot only has to provide its kinematic and dynamic
    regressors.
    """

    #: joints, feature points, and the parameter counts (p_perp, p_z, p_d)
    n: int
    m: int
    p_perp: int
    p_z: int
    p_d: int
    #: ground truth (for the simulator and tests only; see :meth:`set_ground_truth`)
    a_z_perp: np.ndarray
    a_z: np.ndarray
    a_d: np.ndarray
    #: labels used by diagnostics and the parameter topic
    a_z_perp_labels: tuple[str, ...]
    a_z_labels: tuple[str, ...]
    a_d_labels: tuple[str, ...]

    # -- structure supplied by a concrete model --------------------------------
    @abstractmethod
    def kinematic_tensors(self, q, qd):
        """Return ``(H, dH, dH_rate, W, W_rate)`` at ``(q, q_dot)``.

        Shapes: H (m, p_z), dH and dH_rate (m, n, p_z), W and W_rate
        (2m, n, p_perp); ``*_rate`` is the time derivative along ``q_dot``.
        One call so that a model can share trigonometry between them.
        """

    @abstractmethod
    def dynamic_regressor(self, q, qd, xi, xi_dot):
        """Y_d(q, q_dot, xi, xi_dot) (n, p_d) of eq (7): M xi_dot + C xi + g = Y_d a_d."""

    @abstractmethod
    def feature_positions(self, q):
        """True feature points r_i in the robot base frame, (m, 3)."""

    @abstractmethod
    def project(self, q):
        """True image coordinates x (2m,) in pixels and depths z (m,) at q."""

    @abstractmethod
    def estimate(self, camera_matrix, length_scale=1.0, inertia_scale=1.0):
        """Parameters (a_z_perp, a_z, a_d) implied by nominal knowledge.

        ``camera_matrix`` (3, 4) is a (guessed) projection matrix in the base frame
        of the arm, in the controller's pixels with depth in metres (see
        ``sim_bridge.camera.PinholeCamera.projection_matrix``); the nominal lengths
        are multiplied by ``length_scale`` and the inertial parameters by
        ``inertia_scale``.  With the true camera and scales 1 this is the truth.
        """

    @abstractmethod
    def set_ground_truth(self, camera_matrix, chain=None, offsets=None):
        """Make the model the simulated arm seen by the simulated camera (tests, simulator).

        ``camera_matrix`` (3, 4) as in :meth:`estimate`, in the URDF root frame;
        ``chain`` the simulator's kinematic chain (its true lengths) and ``offsets``
        (m, 3) its true feature offsets, when they differ from the model's nominal ones.
        """

    @abstractmethod
    def mass_matrix(self, q):
        """True inertia matrix M(q) (n, n)."""

    @abstractmethod
    def coriolis_matrix(self, q, qd):
        """True Christoffel-form C(q, q_dot) (n, n), with M_dot - 2C skew-symmetric."""

    @abstractmethod
    def gravity_torque(self, q):
        """True gravity torque g(q) (n,)."""

    def dynamics_kernel(self):
        """``(kind, constants)`` of a compiled Y_d for the compiled control law, or None.

        None (this default): the control law runs in numpy (see control/law_kernels.py).
        """
        return None

    def estimated_mass_matrix(self, q, a_d):
        """M(q; a_d) (n, n) from the dynamic regressor: column j is Y_d(q, 0, 0, e_j) a_d - g."""
        zero = np.zeros(self.n)
        g = self.dynamic_regressor(q, zero, zero, zero).dot(a_d)
        return np.array([self.dynamic_regressor(q, zero, zero, e).dot(a_d) - g
                         for e in np.eye(self.n)]).T

    # -- scales ------------------------------------------------------------------
    def dynamic_column_rms(self, samples=200, seed=0):
        """Typical size of each column of Y_d, (p_d,): RMS of its norm over random states.

        States: q uniform in [-pi, pi], q_dot, xi, xi_dot standard normal (rad, rad/s,
        rad/s^2).  A parametrisation whose gravity columns carry g (Pinocchio's) has
        columns ~10x larger than one that folds g into the parameters (the paper's);
        the default adaptation gain divides by the square of this, so every
        parameter adapts at the rate the paper's gains give its O(1) columns.
        """
        cached = getattr(self, "_column_rms", None)
        if cached is not None:
            return cached
        rng = np.random.default_rng(seed)
        total = np.zeros(self.p_d)
        for _ in range(samples):
            q = rng.uniform(-np.pi, np.pi, self.n)
            qd, xi, xi_dot = rng.normal(size=(3, self.n))
            total += np.sum(self.dynamic_regressor(q, qd, xi, xi_dot) ** 2, axis=0)
        self._column_rms = np.sqrt(total / samples)
        return self._column_rms

    # -- Property 1, derived ----------------------------------------------------
    def depth(self, q, a_z):
        """z(q; a_z) = H(q) a_z, shape (m,)."""
        H = self.kinematic_tensors(q, np.zeros(self.n))[0]
        return H @ a_z

    def Y_z(self, H, psi):
        """Y_z(q, psi) (2m, p_z) with Z(q) psi = Y_z a_z, from ``H(q)``."""
        return (psi.reshape(self.m, 2)[:, :, None] * H[:, None, :]).reshape(2 * self.m, self.p_z)

    def Y_z_bar(self, H_rate, phi):
        """Y_z_bar(q, q_dot, phi) (2m, p_z) with Z_dot phi = Y_z_bar a_z, from ``H_dot``."""
        return self.Y_z(H_rate, phi)

    @staticmethod
    def Y_z_perp(W, qd):
        """Y_z_perp(q, q_dot) (2m, p_perp) with J_z_perp q_dot = Y_z_perp a_z_perp."""
        return np.asarray(qd).dot(W)  # = qd @ W; dot is the cheaper call on tiny arrays

    def image_jacobian(self, W, dH, u, a_z_perp, a_z):
        """J(q, u) = J_z_perp(q) - U J_z(q) of eq (a1), shape (2m, n).

        ``U = diag(u_i)`` stacks the 2-vectors ``u_i`` block-diagonally (2m, m),
        so row ``2i + k`` of ``U J_z`` is ``u_i[k] * J_z[i]``.
        """
        J_z = dH @ a_z  # (m, n)
        return W @ a_z_perp - u[:, None] * np.repeat(J_z, 2, axis=0)

    def true_image_jacobian(self, q, x):
        """True depth-independent image Jacobian J(q, x) (2m, n)."""
        _, dH, _, W, _ = self.kinematic_tensors(q, np.zeros(self.n))
        return self.image_jacobian(W, dH, x, self.a_z_perp, self.a_z)


def _lagrangian_regressor(M_basis, dM_basis, g_basis, qd, xi, xi_dot):
    """Y_d for dynamics written as M = sum_k a_k M_k(q), g = sum_k a_k g_k(q).

    C is built from the Christoffel symbols of the first kind, column by column:
    ``(C_k xi)_i = 1/2 sum_{j,l} (dM_k[i,j]/dq_l + dM_k[i,l]/dq_j - dM_k[j,l]/dq_i) qd_l xi_j``
    so that M_dot - 2C is skew-symmetric (Property 3).

    Shapes: M_basis (p, n, n), dM_basis (p, n, n, n) with the last index the
    joint differentiated, g_basis (p, n).  Returns (n, p).
    """
    M_dot = dM_basis @ qd                   # (p, n, n): dM_k[i,j]/dq_l qd_l
    term1 = M_dot @ xi                      # sum_{j,l} dM[i,j]/dq_l qd_l xi_j
    term2 = (dM_basis @ xi) @ qd            # sum_{j,l} dM[i,l]/dq_j xi_j qd_l
    term3 = (dM_basis.transpose(0, 3, 1, 2) @ qd) @ xi  # sum dM[j,l]/dq_i qd_l xi_j
    cols = M_basis @ xi_dot + 0.5 * (term1 + term2 - term3) + g_basis
    return cols.T
