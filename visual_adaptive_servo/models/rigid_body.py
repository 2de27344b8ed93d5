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

"""Property 4 of the paper for any serial arm described by a URDF, through Pinocchio.

The rigid-body dynamics of an n-joint arm are linear in the inertial
parameters of its links::

    M(q) xi_dot + C(q, q_dot) xi + g(q) = Y_d(q, q_dot, xi, xi_dot) a_d       (Property 4)

with C in Christoffel form, so that M_dot - 2C is skew-symmetric (Property 3).
Pinocchio gives the joint-torque regressor of the recursive Newton-Euler
algorithm, Y(q, v, a) a_full = M(q) a + C(q, v) v + g(q), with 10 standard
parameters per link.  Its velocity part is the quadratic form
h(v) = C(q, v) v, and the Christoffel C(q, q_dot) xi is the symmetric bilinear
form of h, recovered by polarisation::

    Y_d = Y(q, 0, xi_dot) + 1/2 [Y(q, q_dot + xi, 0) - Y(q, q_dot, 0) - Y(q, xi, 0) + Y(q, 0, 0)]

(the gravity column terms Y(q, 0, 0) cancel inside the bracket and the first
term supplies them once).  :meth:`RigidBodyDynamics.regressor` evaluates the
same identity with two calls instead of five (see ``_full_regressor``).

Parameters per link, Pinocchio's ``Inertia.toDynamicParameters()`` order, in
the frame of the joint that moves the link (inertia about that frame's origin,
I = I_C + m S(c)^T S(c))::

    m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz

Not all 10 n of them act on the joint torques; :class:`RigidBodyDynamics`
reduces them to a set of base parameters (independent columns of the
regressor, found by QR with column pivoting over random samples).
"""

from __future__ import annotations

import os

import numpy as np
import pinocchio as pin
from scipy.linalg import qr, solve_triangular

#: labels of Pinocchio's 10 dynamic parameters of one link, in its order
LINK_PARAMETER_NAMES = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")

#: random samples stacked for the base-parameter reduction, and its seed
BASE_SAMPLES = 100
BASE_SEED = 20150101
#: |R_kk| / |R_00| below which a pivoted column counts as dependent
RANK_TOLERANCE = 1e-9
#: largest relative residual of Y_full = Y_full[:, B] E accepted over the samples
RECONSTRUCTION_TOLERANCE = 1e-10
#: |E| below which a standard parameter is not named in a base parameter's label
LABEL_COEFFICIENT = 1e-9
_INV_SQRT8 = 1.0 / np.sqrt(8.0)


class RigidBodyDynamics:
    """Dynamic regressor and true dynamics of the serial chain base_link -> tip_link of a URDF.

    Parameters
    ----------
    urdf_path : str
        URDF file (mesh files are not needed).
    base_link : str
        Link the chain starts from; it must be fixed to the URDF root (no
        movable joint between them).
    tip_link : str
        Link the chain ends at; a descendant of ``base_link``.
    gravity : float
        Gravity [m/s^2] along -z of the URDF root frame.
    reduce : bool
        If true, the regressor and the parameters are the base parameters
        (p_d <= 10 n); otherwise the 10 n standard parameters.

    Attributes
    ----------
    n : int
        Number of joints of the chain (revolute, continuous or prismatic).
    joint_names : tuple of str
        Joint names in chain order, base to tip; q is ordered the same way.
    link_names : tuple of str
        The link each joint moves (its inertia includes everything fixed to
        it and every other movable joint's subtree, locked at 0).
    p_d : int
        Number of dynamic parameters (base parameters if ``reduce``).
    parameter_labels : tuple of str
        One label per parameter, ``link.name`` (``link.name+...`` for a base
        parameter that is a combination of several standard ones).
    base_columns : ndarray of int, shape (p_d,)
        Columns B of the full regressor kept (all 10 n if not ``reduce``).
    base_map : ndarray, shape (p_d, 10 n)
        E with a_base = E a_full and Y_full = Y_full[:, B] E.

    Raises
    ------
    ValueError
        Naming ``urdf``, ``base_link`` or ``tip_link`` when the file does not
        load, a link does not exist, the tip is not a descendant of the base,
        the base moves relative to the root, or the chain has no movable joint.
    """

    def __init__(self, urdf_path, base_link, tip_link, gravity=9.81, reduce=True):
        full = _load_model(urdf_path)
        base_frame = _body_frame(full, base_link, "base_link", urdf_path)
        tip_frame = _body_frame(full, tip_link, "tip_link", urdf_path)
        base_joint = _parent_joint(full.frames[base_frame])
        if base_joint != 0:
            movers = [full.names[j] for j in full.supports[base_joint][1:]]
            raise ValueError(
                f"base_link: link {base_link!r} is moved relative to the URDF root "
                f"{_root_link(full)!r} by joint(s) {movers}; "
                f"the base must be fixed to the root")
        if not _is_descendant(full, tip_frame, base_frame):
            raise ValueError(
                f"tip_link: link {tip_link!r} is not a descendant of base_link {base_link!r} "
                f"in {urdf_path}, so there is no kinematic chain from base to tip")
        chain = list(full.supports[_parent_joint(full.frames[tip_frame])])[1:]
        if not chain:
            raise ValueError(f"tip_link: there is no revolute, continuous or prismatic joint "
                             f"between base_link {base_link!r} and tip_link {tip_link!r}")
        for j in chain:
            if full.joints[j].nv != 1:
                raise ValueError(
                    f"tip_link: joint {full.names[j]!r} on the chain from {base_link!r} to "
                    f"{tip_link!r} has {full.joints[j].nv} degrees of freedom; only revolute, "
                    f"continuous and prismatic joints are supported")
        locked = [j for j in range(1, full.njoints) if j not in chain]
        self.model = (pin.buildReducedModel(full, locked, pin.neutral(full)) if locked
                      else full)
        self.model.gravity = pin.Motion(np.array([0.0, 0.0, -float(gravity), 0.0, 0.0, 0.0]))
        self.data = self.model.createData()
        self.n = self.model.nv
        self.joint_names = tuple(self.model.names[1:])
        self.link_names = tuple(_child_link(full, j) for j in chain)
        self._q_zero = pin.neutral(self.model)
        # no continuous joint: Pinocchio's configuration is q itself
        self._q_is_configuration = self.model.nq == self.n
        self._a_full = np.concatenate([self.model.inertias[j].toDynamicParameters()
                                       for j in range(1, self.model.njoints)])
        full_labels = [f"{link}.{name}" for link in self.link_names
                       for name in LINK_PARAMETER_NAMES]
        if reduce:
            self.base_columns, self.base_map = self._base_parameters()
            # E keeps every entry (exact zeros come out as ~1e-17, and URDF round-off
            # such as cos(1.57079632679) = 5e-12 gives true entries of ~1e-12); only
            # the labels ignore coefficients that small
            self.parameter_labels = tuple(
                full_labels[b] + ("+..." if np.count_nonzero(np.abs(row) > LABEL_COEFFICIENT)
                                  > 1 else "")
                for b, row in zip(self.base_columns, self.base_map))
        else:
            self.base_columns = np.arange(self._a_full.size)
            self.base_map = np.eye(self._a_full.size)
            self.parameter_labels = tuple(full_labels)
        self.p_d = self.base_columns.size

    # -- configuration ------------------------------------------------------------
    def _configuration(self, q):
        """Pinocchio's configuration vector (nq,) for joint coordinates q (n,).

        A continuous joint is stored as (cos q, sin q); integrating the joint
        velocity q from the zero configuration maps every joint type exactly.
        """
        q = np.asarray(q, dtype=float)
        if self._q_is_configuration:
            return q
        return pin.integrate(self.model, self._q_zero, q)

    def _torque_regressor(self, q_pin, v, a):
        """Y(q, v, a) (n, 10 n): Y a_full = M(q) a + C(q, v) v + g(q) (RNEA)."""
        # returned by value (bindings' return_by_value), not a view of data
        return pin.computeJointTorqueRegressor(self.model, self.data, q_pin, v, a)

    def _full_regressor(self, q, qd, xi, xi_dot):
        """Y_d over the 10 n standard parameters (n, 10 n), by polarisation in two RNEA calls.

        With Y(q, v, a) = Y_M(q)[a] + Y_h(q; v) + Y_g(q), Y_h quadratic in v,
        the Christoffel term is the polar form
        C(q, u) w <- 1/4 [Y_h(u + w) - Y_h(u - w)], so::

            Y_d = 2 Y(q, (u + w) / sqrt(8), xi_dot) - Y(q, (u - w) / 2, xi_dot)

        (u = q_dot, w = xi): the quadratic parts give 2/8 Y_h(u + w) - 1/4 Y_h(u - w),
        the acceleration and gravity parts 2 - 1 = 1 time each.  It replaces the
        five-call form of the module docstring (same values to ~1e-15 of the
        torque scale; median 11 µs against 21 µs for the iiwa, benchmarks/bench_rigid_body.py).
        """
        q_pin = self._configuration(q)
        qd = np.asarray(qd, dtype=float)
        xi = np.asarray(xi, dtype=float)
        xi_dot = np.asarray(xi_dot, dtype=float)
        Y_d = self._torque_regressor(q_pin, _INV_SQRT8 * (qd + xi), xi_dot)
        # in place: each call returns a fresh array (return_by_value), not a view of data
        Y_d *= 2.0
        Y_d -= self._torque_regressor(q_pin, 0.5 * (qd - xi), xi_dot)
        return Y_d

    # -- Property 4 ---------------------------------------------------------------
    def regressor(self, q, qd, xi, xi_dot):
        """Y_d(q, q_dot, xi, xi_dot) (n, p_d) of Property 4.

        M(q) xi_dot + C(q, q_dot) xi + g(q) = Y_d a_d, with C in Christoffel
        form and a_d = :meth:`parameters`.

        Parameters
        ----------
        q, qd, xi, xi_dot : array_like, shape (n,)
            Joint positions, velocities, and the vectors multiplying C and M.

        Returns
        -------
        ndarray, shape (n, p_d)
        """
        # ndarray.take: the cheapest column selection at this size (~0.9 us against
        # ~3.5 us for Y[:, B] or np.take on 7 x 70, measured)
        return self._full_regressor(q, qd, xi, xi_dot).take(self.base_columns, 1)

    def kernel_constants(self):
        """The constant arrays of :func:`.dynamics_kernels.chain_regressor` for this chain.

        ``(joints, a0, columns)``: a row per joint (n, 19) with its placement in
        its parent's frame (rotation row-major, translation), its motion subspace
        (linear, angular: Pinocchio's joint velocity for a unit rate at the
        neutral configuration) and 1.0 for a revolute joint; -gravity (3,); the
        base columns.  ValueError when the chain is not one serial line of 1-dof
        joints.
        """
        model = self.model
        n = self.n
        if list(model.parents[1:]) != list(range(n)):
            raise ValueError(f"the joints' parents {list(model.parents[1:])} are not a serial "
                             "chain")
        R_J = np.empty((n, 3, 3))
        p_J = np.empty((n, 3))
        S = np.empty((n, 6))
        data = model.createData()
        q0 = pin.neutral(model)
        for i in range(n):
            placement = model.jointPlacements[i + 1]
            R_J[i], p_J[i] = placement.rotation, placement.translation
            rate = np.zeros(n)
            rate[i] = 1.0
            pin.forwardKinematics(model, data, q0, rate)
            S[i] = data.v[i + 1].vector
        angular = np.linalg.norm(S[:, 3:], axis=1)
        linear = np.linalg.norm(S[:, :3], axis=1)
        revolute = (angular > 0.5).astype(float)
        if not np.all(np.where(revolute > 0.0, linear < 1e-12, angular < 1e-12)):
            raise ValueError("a joint is neither a pure rotation nor a pure translation")
        a0 = -np.array(model.gravity.linear, dtype=float)
        joints = np.hstack([R_J.reshape(n, 9), p_J, S, revolute[:, None]])
        return (np.ascontiguousarray(joints), a0,
                np.ascontiguousarray(self.base_columns, dtype=np.intp))

    def parameters(self):
        """True dynamic parameters a_d (p_d,) from the URDF inertias (a_base = E a_full)."""
        return self.base_map @ self._a_full

    def full_parameters(self):
        """The 10 n standard parameters a_full (10 n,), link by link in chain order."""
        return self._a_full.copy()

    def _base_parameters(self):
        """Base columns B (p_d,) and map E (p_d, 10 n) with Y_full = Y_full[:, B] E.

        The regressor Y(q, v, a) and its polarised form are stacked over
        random samples; QR with column pivoting, W P = Q R, orders the columns
        so that the first r are independent, and the others follow from
        W[:, P[r:]] = W[:, P[:r]] R11^-1 R12.
        """
        rng = np.random.default_rng(BASE_SEED)
        blocks = []
        for _ in range(BASE_SAMPLES):
            q, v, a, w = rng.uniform(-np.pi, np.pi, self.n), *rng.standard_normal((3, self.n))
            blocks.append(self._torque_regressor(self._configuration(q), v, a))
            blocks.append(self._full_regressor(q, v, w, a))
        W = np.vstack(blocks)
        _, R, perm = qr(W, mode="economic", pivoting=True)
        diag = np.abs(np.diag(R))
        rank = int(np.count_nonzero(diag > RANK_TOLERANCE * diag[0]))
        E = np.zeros((rank, W.shape[1]))
        E[:, perm[:rank]] = np.eye(rank)
        E[:, perm[rank:]] = solve_triangular(R[:rank, :rank], R[:rank, rank:])
        order = np.argsort(perm[:rank])
        B, E = perm[:rank][order], E[order]
        residual = np.abs(W - W[:, B] @ E).max() / np.abs(W).max()
        if residual > RECONSTRUCTION_TOLERANCE:
            raise ValueError(f"reduce: the base parameters do not reproduce the full regressor "
                             f"(relative residual {residual:.1e} > "
                             f"{RECONSTRUCTION_TOLERANCE:.0e})")
        return B, E

    # -- true dynamics --------------------------------------------------------------
    def mass_matrix(self, q):
        """Inertia matrix M(q) (n, n), symmetric (CRBA's upper triangle mirrored)."""
        M = pin.crba(self.model, self.data, self._configuration(q))
        return np.triu(M) + np.triu(M, 1).T

    def coriolis_matrix(self, q, qd):
        """Christoffel-form C(q, q_dot) (n, n); M_dot - 2C is skew-symmetric."""
        return pin.computeCoriolisMatrix(self.model, self.data, self._configuration(q),
                                         np.asarray(qd, dtype=float))

    def gravity_torque(self, q):
        """Gravity torque g(q) (n,)."""
        return pin.computeGeneralizedGravity(self.model, self.data, self._configuration(q))


def _root_link(model):
    """Name of the URDF root link (the first link frame: frames are added root first)."""
    return next(f.name for f in model.frames if f.type == pin.BODY)


def _parent_joint(frame):
    """Index of the joint that moves ``frame`` (``parent`` before Pinocchio 3)."""
    return frame.parentJoint if hasattr(frame, "parentJoint") else frame.parent


def _parent_frame(frame):
    """Index of the frame ``frame`` hangs from (``previousFrame`` before Pinocchio 3)."""
    return frame.parentFrame if hasattr(frame, "parentFrame") else frame.previousFrame


def _load_model(urdf_path):
    if not os.path.isfile(urdf_path):
        raise ValueError(f"urdf: no such file {urdf_path!r}")
    try:
        return pin.buildModelFromUrdf(urdf_path)
    except (ValueError, RuntimeError) as exc:
        raise ValueError(f"urdf: {urdf_path!r} does not load as a URDF model ({exc})") from None


def _body_frame(model, link, parameter, urdf_path):
    """Index of the frame of ``link``; ValueError naming ``parameter`` if there is none."""
    if not model.existFrame(link, pin.BODY):
        links = [f.name for f in model.frames if f.type == pin.BODY]
        raise ValueError(f"{parameter}: no link named {link!r} in {urdf_path}; links: {links}")
    return model.getFrameId(link, pin.BODY)


def _is_descendant(model, frame, ancestor):
    """Whether link frame ``frame`` lies below ``ancestor`` in the URDF tree (or is it)."""
    while frame != ancestor:
        if frame == 0:
            return False
        frame = _parent_frame(model.frames[frame])
    return True


def _child_link(model, joint):
    """Name of the link that joint ``joint`` moves directly."""
    joint_frame = model.getFrameId(model.names[joint], pin.JOINT)
    return next(f.name for f in model.frames
                if f.type == pin.BODY and _parent_frame(f) == joint_frame)
