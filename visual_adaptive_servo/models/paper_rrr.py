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


"""The paper's RRR arm and fixed camera (H. Wang, Automatica 2015, section 4), by hand.

The kinematic tensors and the dynamic regressor are derived in closed form for
this arm; :class:`~.urdf_arm.UrdfArmCamera` computes the same quantities for any
serial arm from its URDF, and the tests check the two against each other.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import cos, sin

import numpy as np

from .backend import compile_notice, kernels, resolve_backend
from .base import GRAVITY, RobotCameraModel, _lagrangian_regressor


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

    ``backend`` (``"compiled"`` or ``"numpy"``, default compiled when numba imports,
    see :mod:`.backend`) chooses what :meth:`kinematic_tensors` runs;
    :meth:`kinematic_tensors_numpy` is the reference.
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
                 camera_distance=5.0, gravity=GRAVITY, backend=None):
        self.set_backend(backend)
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

    def set_backend(self, backend):
        """Run :meth:`kinematic_tensors` on ``backend`` from now on (see :mod:`.backend`).

        Choosing compiled compiles the kernel (or loads it from numba's cache) here,
        rather than in the first control period.
        """
        backend = resolve_backend(backend)
        if backend == "compiled":
            with compile_notice("paper arm's kinematic and dynamic regressors"):
                from .dynamics_kernels import paper_regressor

                self._kernel = kernels().paper_tensors
                self._kernel(np.zeros(3), np.zeros(3))
                self._regressor_kernel = paper_regressor
                self._regressor_kernel(*np.zeros((4, 3)))
        self.backend = backend

    def dynamics_kernel(self):
        """``(0, ())`` with the compiled backend (the law's kernel has Y_d inline), else None."""
        return (0, ()) if self.backend == "compiled" else None

    def kinematic_tensors(self, q, qd):
        if self.backend == "numpy":
            return self.kinematic_tensors_numpy(q, qd)
        # contiguous float64 of length 3: the kernel does not check bounds
        q = np.ascontiguousarray(q, dtype=float)
        qd = np.ascontiguousarray(qd, dtype=float)
        if q.shape != (3,) or qd.shape != (3,):
            raise ValueError(f"kinematic tensors: q and q_dot need shape (3,), got {q.shape} "
                             f"and {qd.shape}")
        return self._kernel(q, qd)

    def kinematic_tensors_numpy(self, q, qd):
        """:meth:`kinematic_tensors` in numpy: the reference of the compiled kernel."""
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
        if self.backend == "numpy":
            return self.dynamic_regressor_numpy(q, qd, xi, xi_dot)
        args = [np.ascontiguousarray(v, dtype=float) for v in (q, qd, xi, xi_dot)]
        if any(v.shape != (3,) for v in args):
            raise ValueError(f"dynamic regressor: q, q_dot, xi, xi_dot need shape (3,), got "
                             f"{[v.shape for v in args]}")
        return self._regressor_kernel(*args)

    def dynamic_regressor_numpy(self, q, qd, xi, xi_dot):
        """Y_d in closed form: the Christoffel sums of :func:`_lagrangian_regressor` by hand.

        The reference of the compiled kernel (:func:`.dynamics_kernels.paper_regressor`).
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

    @property
    def camera_matrix(self):
        """The paper's camera as a projection matrix (3, 4) in the base frame."""
        fb = self.focal_length * self.scale
        return np.array([[0.0, fb, 0.0, 0.0], [0.0, 0.0, fb, 0.0],
                         [1.0, 0.0, 0.0, self.camera_distance]])

    @staticmethod
    def _paper_camera(camera_matrix, what):
        """(f beta, d_C) of a projection matrix with the paper's camera structure."""
        P = np.asarray(camera_matrix, dtype=float)
        fb = float(P[0, 1])
        expected = np.array([[0.0, fb, 0.0, 0.0], [0.0, 0.0, fb, 0.0], [1.0, 0.0, 0.0, P[2, 3]]])
        if P.shape != (3, 4) or fb <= 0.0 or not np.allclose(P, expected, rtol=0.0,
                                                             atol=1e-9 * max(1.0, fb)):
            raise ValueError(
                f"{what}: model paper_rrr assumes the paper's camera (Z_C along X_0, image axes "
                f"along Y_0 and Z_0, equal pixel scales, pixel origin on the optical axis); got "
                f"the projection matrix {np.round(P, 6).tolist()}. Use model: urdf for any "
                f"other camera")
        return fb, float(P[2, 3])

    def estimate(self, camera_matrix, length_scale=1.0, inertia_scale=1.0):
        fb, d_C = self._paper_camera(camera_matrix, "initial_estimate.camera")
        l2, l3 = (link.length * length_scale for link in self.links[1:])
        return (np.array([fb * l2, fb * l3]), np.array([l2, l3, d_C]),
                inertia_scale * self._dynamic_parameters())

    def set_ground_truth(self, camera_matrix, chain=None, offsets=None):
        fb, d_C = self._paper_camera(camera_matrix, "sim_node.camera")
        if offsets is not None and np.any(np.asarray(offsets, dtype=float) != 0.0):
            raise ValueError("sim_node.feature_points: model paper_rrr has its one feature point "
                             "at the tip (offset [0, 0, 0]); use model: urdf for others")
        if chain is not None:
            lengths = [chain.joints[1].origin_translation, chain.joints[2].origin_translation,
                       chain.tip_translation]
            expected = [(0.0, 0.0, self.l1), (self.links[1].length, 0.0, 0.0),
                        (self.links[2].length, 0.0, 0.0)]
            if chain.n != 3 or not np.allclose(lengths, expected, atol=1e-12):
                raise ValueError(f"sim_node.urdf: model paper_rrr is the paper's arm (l1 = "
                                 f"{self.l1}, l2 = {self.links[1].length}, l3 = "
                                 f"{self.links[2].length} m); {chain.urdf} differs. Use model: "
                                 f"urdf for another arm")
        self.focal_length = fb / self.scale
        self.camera_distance = d_C
        self.a_z_perp = np.array([fb * self.links[1].length, fb * self.links[2].length])
        self.a_z = np.array([self.links[1].length, self.links[2].length, d_C])

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
