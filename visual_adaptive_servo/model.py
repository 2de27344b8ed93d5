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

"""Robot + fixed-camera models: the regressors of Properties 1 and 4 of the paper.

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
that the simulator and the tests have ground truth.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from math import cos, sin

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
    #: ground truth (for the simulator and tests only)
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
    def mass_matrix(self, q):
        """True inertia matrix M(q) (n, n)."""

    @abstractmethod
    def coriolis_matrix(self, q, qd):
        """True Christoffel-form C(q, q_dot) (n, n), with M_dot - 2C skew-symmetric."""

    @abstractmethod
    def gravity_torque(self, q):
        """True gravity torque g(q) (n,)."""

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


@dataclass(frozen=True)
class CylinderLink:
    """A uniform solid cylinder along the link axis (SI units)."""

    length: float
    mass: float
    radius: float

    @property
    def axial_inertia(self):
        return 0.5 * self.mass * self.radius**2

    @property
    def transverse_inertia(self):
        """Inertia about a transverse axis through the centre of mass."""
        return self.mass * (3.0 * self.radius**2 + self.length**2) / 12.0


class PaperRRRCamera(RobotCameraModel):
    """The paper's RRR arm with the fixed camera of its simulation (one feature point).

    Kinematics (c23 = cos(q2 + q3), rho = l2 c2 + l3 c23)::

        r = [c1 rho, s1 rho, l1 + l2 s2 + l3 s23]

    Camera: X_C || Y_0, Y_C || Z_0, Z_C || X_0, origin at (-d_C, 0, 0), so
    ``x = f beta [r_y, r_z] / (r_x + d_C)`` and ``z = r_x + d_C``.

    Parameters, with l1 known:

    * ``a_z_perp = f beta [l2, l3]``   (J_z_perp q_dot = f beta d/dt [r_y, r_z])
    * ``a_z = [l2, l3, d_C]``          (z = [c1 c2, c1 c23, 1] a_z)
    * ``a_d = [P1, P2, P3, A, B, Cc, G1, G2]`` with
      M11 = P1 + P2 c2^2 + P3 c23^2 + 2 Cc c2 c23, M22 = A + B + 2 Cc c3,
      M23 = B + Cc c3, M33 = B, M12 = M13 = 0, and gravity
      g = [0, G1 c2 + G2 c23, G2 c23]  (G1 is the shoulder gravity term).
    """

    n = 3
    m = 1
    p_perp = 2
    p_z = 3
    p_d = 8
    a_z_perp_labels = ("f_beta_l2", "f_beta_l3")
    a_z_labels = ("l2", "l3", "d_C")
    a_d_labels = ("P1", "P2", "P3", "A", "B", "Cc", "G1", "G2")

    def __init__(self, l1=2.0, links=None, focal_length=0.15, scale=900.0,
                 camera_distance=5.0, gravity=GRAVITY):
        if links is None:
            links = (CylinderLink(2.0, 3.0, 0.10), CylinderLink(2.0, 2.0, 0.05),
                     CylinderLink(2.0, 1.0, 0.05))
        self.l1 = float(l1)
        self.links = tuple(links)
        self.focal_length = float(focal_length)
        self.scale = float(scale)
        self.camera_distance = float(camera_distance)
        self.gravity = float(gravity)
        link1, link2, link3 = self.links
        l2, l3 = link2.length, link3.length
        fb = self.focal_length * self.scale
        self.a_z_perp = np.array([fb * l2, fb * l3])
        self.a_z = np.array([l2, l3, self.camera_distance])
        self.a_d = self._dynamic_parameters()

    def _dynamic_parameters(self):
        link1, link2, link3 = self.links
        lc2, lc3 = link2.length / 2.0, link3.length / 2.0
        l2 = link2.length
        A = link2.transverse_inertia + link2.mass * lc2**2 + link3.mass * l2**2
        B = link3.transverse_inertia + link3.mass * lc3**2
        Cc = link3.mass * l2 * lc3
        P1 = link1.axial_inertia + link2.axial_inertia + link3.axial_inertia
        P2 = A - link2.axial_inertia
        P3 = B - link3.axial_inertia
        G1 = self.gravity * (link2.mass * lc2 + link3.mass * l2)
        G2 = self.gravity * link3.mass * lc3
        return np.array([P1, P2, P3, A, B, Cc, G1, G2])

    def kinematic_tensors(self, q, qd):
        # Python floats and one array for all five tensors: at n = 3 creating
        # small arrays costs more than the trigonometry (hot path, every sample)
        q1, q2, q3 = np.asarray(q, dtype=float).tolist()
        w1, w2, w3 = np.asarray(qd, dtype=float).tolist()
        s1, c1, s2, c2 = sin(q1), cos(q1), sin(q2), cos(q2)
        s23, c23 = sin(q2 + q3), cos(q2 + q3)
        w23 = w2 + w3
        c1c2, c1c23, c1s2, c1s23 = c1 * c2, c1 * c23, c1 * s2, c1 * s23
        s1c2, s1c23, s1s2, s1s23 = s1 * c2, s1 * c23, s1 * s2, s1 * s23
        buf = np.array([
            # H: depth z = [c1 c2, c1 c23, 1] . a_z                              (1, 3)
            c1c2, c1c23, 1.0,
            # dH = dH/dq                                                         (1, 3, 3)
            -s1c2, -s1c23, 0.0,
            -c1s2, -c1s23, 0.0,
            0.0, -c1s23, 0.0,
            # dH_rate: time derivative of dH entry by entry (chain rule along qd)
            -c1c2 * w1 + s1s2 * w2, -c1c23 * w1 + s1s23 * w23, 0.0,
            s1s2 * w1 - c1c2 * w2, s1s23 * w1 - c1c23 * w23, 0.0,
            0.0, s1s23 * w1 - c1c23 * w23, 0.0,
            # W, image-plane part: [r_y, r_z - l1] = [[s1 c2, s1 c23], [s2, s23]] @ [l2, l3]
            c1c2, c1c23, -s1s2, -s1s23, 0.0, -s1s23,                             # (2, 3, 2)
            0.0, 0.0, c2, c23, 0.0, c23,
            # W_rate
            -s1c2 * w1 - c1s2 * w2, -s1c23 * w1 - c1s23 * w23,
            -c1s2 * w1 - s1c2 * w2, -c1s23 * w1 - s1c23 * w23,
            0.0, -c1s23 * w1 - s1c23 * w23,
            0.0, 0.0, -s2 * w2, -s23 * w23, 0.0, -s23 * w23,
        ])
        return (buf[:3].reshape(1, 3), buf[3:12].reshape(1, 3, 3), buf[12:21].reshape(1, 3, 3),
                buf[21:33].reshape(2, 3, 2), buf[33:].reshape(2, 3, 2))

    def _dynamic_basis(self, q):
        _, q2, q3 = q
        s2, c2, s3, c3 = sin(q2), cos(q2), sin(q3), cos(q3)
        s23, c23 = sin(q2 + q3), cos(q2 + q3)
        M = np.zeros((8, 3, 3))
        dM = np.zeros((8, 3, 3, 3))
        M[0, 0, 0] = 1.0
        M[1, 0, 0] = c2 * c2
        dM[1, 0, 0, 1] = -2.0 * c2 * s2
        M[2, 0, 0] = c23 * c23
        dM[2, 0, 0, 1] = dM[2, 0, 0, 2] = -2.0 * c23 * s23
        M[3, 1, 1] = 1.0
        M[4, 1:, 1:] = 1.0
        M[5, 0, 0] = 2.0 * c2 * c23
        dM[5, 0, 0, 1] = -2.0 * (s2 * c23 + c2 * s23)
        dM[5, 0, 0, 2] = -2.0 * c2 * s23
        M[5, 1, 1] = 2.0 * c3
        M[5, 1, 2] = M[5, 2, 1] = c3
        dM[5, 1, 1, 2] = -2.0 * s3
        dM[5, 1, 2, 2] = dM[5, 2, 1, 2] = -s3
        g = np.zeros((8, 3))
        g[6, 1] = c2
        g[7, 1] = g[7, 2] = c23
        return M, dM, g

    def dynamic_regressor(self, q, qd, xi, xi_dot):
        """Y_d in closed form: the Christoffel sums of :func:`_lagrangian_regressor` by hand.

        Column by column, with w = q_dot, e = xi_dot, w23 = w2 + w3,
        h2 = s2 c23 + c2 s23 and h3 = c2 s23::

            P1: [e1, 0, 0]
            P2: [c2^2 e1 - c2 s2 (w2 xi1 + w1 xi2), c2 s2 w1 xi1, 0]
            P3: [c23^2 e1 - c23 s23 (w23 xi1 + w1 (xi2 + xi3)), c23 s23 w1 xi1, (same)]
            A:  [0, e2, 0]
            B:  [0, e2 + e3, e2 + e3]
            Cc: [2 c2 c23 e1 - (h2 w2 + h3 w3) xi1 - (h2 xi2 + h3 xi3) w1,
                 c3 (2 e2 + e3) - s3 (w3 xi2 + w23 xi3) + h2 w1 xi1,
                 c3 e2 + s3 w2 xi2 + h3 w1 xi1]
            G1: [0, c2, 0]
            G2: [0, c23, c23]

        :meth:`generic_dynamic_regressor` is the same quantity from the basis.
        """
        _, q2, q3 = np.asarray(q, dtype=float).tolist()
        w1, w2, w3 = np.asarray(qd, dtype=float).tolist()
        x1, x2, x3 = np.asarray(xi, dtype=float).tolist()
        e1, e2, e3 = np.asarray(xi_dot, dtype=float).tolist()
        s2, c2, s3, c3 = sin(q2), cos(q2), sin(q3), cos(q3)
        s23, c23 = sin(q2 + q3), cos(q2 + q3)
        w23 = w2 + w3
        h2 = s2 * c23 + c2 * s23
        h3 = c2 * s23
        p3 = c23 * s23 * w1 * x1
        return np.array([
            [e1, c2 * c2 * e1 - c2 * s2 * (w2 * x1 + w1 * x2),
             c23 * c23 * e1 - c23 * s23 * (w23 * x1 + w1 * (x2 + x3)), 0.0, 0.0,
             2.0 * c2 * c23 * e1 - (h2 * w2 + h3 * w3) * x1 - (h2 * x2 + h3 * x3) * w1,
             0.0, 0.0],
            [0.0, c2 * s2 * w1 * x1, p3, e2, e2 + e3,
             c3 * (2.0 * e2 + e3) - s3 * (w3 * x2 + w23 * x3) + h2 * w1 * x1, c2, c23],
            [0.0, 0.0, p3, 0.0, e2 + e3, c3 * e2 + s3 * w2 * x2 + h3 * w1 * x1, 0.0, c23],
        ])

    def generic_dynamic_regressor(self, q, qd, xi, xi_dot):
        """Y_d from the basis of M and g by :func:`_lagrangian_regressor` (any model's way)."""
        M, dM, g = self._dynamic_basis(q)
        return _lagrangian_regressor(M, dM, g, np.asarray(qd, float), np.asarray(xi, float),
                                     np.asarray(xi_dot, float))

    def feature_positions(self, q):
        q1, q2, q3 = q
        l2, l3 = self.links[1].length, self.links[2].length
        rho = l2 * cos(q2) + l3 * cos(q2 + q3)
        return np.array([[cos(q1) * rho, sin(q1) * rho,
                          self.l1 + l2 * sin(q2) + l3 * sin(q2 + q3)]])

    def project(self, q):
        r = self.feature_positions(q)[0]
        z = r[0] + self.camera_distance
        fb = self.focal_length * self.scale
        return np.array([fb * r[1] / z, fb * r[2] / z]), np.array([z])

    def mass_matrix(self, q):
        M, _, _ = self._dynamic_basis(q)
        return np.tensordot(self.a_d, M, axes=1)

    def coriolis_matrix(self, q, qd):
        _, dM, _ = self._dynamic_basis(q)
        D = np.tensordot(self.a_d, dM, axes=1)  # D[i,j,l] = dM_ij/dq_l
        return 0.5 * (np.einsum("ijl,l->ij", D, qd) + np.einsum("ilj,l->ij", D, qd)
                      - np.einsum("jli,l->ij", D, qd))

    def gravity_torque(self, q):
        _, _, g = self._dynamic_basis(q)
        return self.a_d @ g


MODELS = {"paper_rrr": PaperRRRCamera}


def make_model(name, **kwargs):
    """Build a registered model by name (``model`` parameter of the configuration)."""
    try:
        cls = MODELS[name]
    except KeyError:
        raise ValueError(f"model: unknown model name {name!r}; known: {sorted(MODELS)}") from None
    return cls(**kwargs)
