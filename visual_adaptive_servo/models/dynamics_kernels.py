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

"""Compiled (numba) dynamic regressors Y_d of Property 4, and their contractions.

References (and test oracles): :meth:`.paper_rrr.PaperRRRCamera.dynamic_regressor_numpy`
(the closed form) and, for a URDF chain, Pinocchio's joint torque regressor
through :meth:`.rigid_body.RigidBodyDynamics.regressor_pinocchio`.

A serial chain's joint torque regressor is the recursive Newton-Euler
algorithm written per parameter (Atkeson, An & Hollerbach 1986): with the
joints' spatial velocities v_i and accelerations a_i (gravity as a base
acceleration), every link contributes a 6 x 10 body regressor Yb_i(v_i, a_i)
(force f, moment n about the joint frame's origin, linear in Pinocchio's
m, m c, I_O parameters), and row i of Y is S_i^T X*_{i<-j} Yb_j over the links
j at and after joint i.  The control law needs Y_d only through

    Y_d a_d     (the torque, eq (22))    and    Y_d^T r     (eq (23)),

and both cost O(n), not the O(n^2) of the matrix: Y a is the RNEA torque of
the parameters a, and (Y^T r)_j = Yb_j^T w_j with w_j the "velocity" the
joint rates r give link j (w_j = X_{j<-j-1} w_{j-1} + S_j r_j), because
X*_{i<-j} is X_{j<-i}^T.  :func:`chain_contractions` evaluates both for the
two-call polarisation of :meth:`.rigid_body.RigidBodyDynamics._full_regressor`;
:func:`chain_regressor` forms the matrix (start-up, fallback torque, tests).

Spatial vectors are Pinocchio's: motion (linear, angular), force (force, moment).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .kernels import compiled

_INV_SQRT8 = 1.0 / math.sqrt(8.0)


@numba.njit(inline="always")
def _cross3(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


#: columns of a row of ``joints`` (:meth:`.rigid_body.RigidBodyDynamics.kernel_constants`):
#: the placement's rotation (row-major) and translation, the motion subspace, revolute
JOINT_R, JOINT_P, JOINT_S, JOINT_REVOLUTE, JOINT_WIDTH = 0, 9, 12, 18, 19


@numba.njit(cache=False, error_model="numpy")
def _poses(q, joints, R, p):
    """Each joint frame's pose in its parent's: R (n, 3, 3), p (n, 3).

    Joint i's frame sits at its placement (R_J, p_J) in its parent's, moved by
    the joint: rotated by q_i about the axis S_ang (revolute, R = R_J Rot) or
    shifted by q_i S_lin (prismatic, p = p_J + R_J S_lin q_i).
    """
    for i in range(q.shape[0]):
        J = joints[i]
        k0, k1, k2 = J[JOINT_S + 3], J[JOINT_S + 4], J[JOINT_S + 5]
        if J[JOINT_REVOLUTE] != 0.0:
            # Rot(k, q) = cos q I + sin q [k]x + (1 - cos q) k k^T for the unit axis k
            s, c = math.sin(q[i]), math.cos(q[i])
            d = 1.0 - c
            r00, r01, r02 = c + d * k0 * k0, d * k0 * k1 - s * k2, d * k0 * k2 + s * k1
            r10, r11, r12 = d * k1 * k0 + s * k2, c + d * k1 * k1, d * k1 * k2 - s * k0
            r20, r21, r22 = d * k2 * k0 - s * k1, d * k2 * k1 + s * k0, c + d * k2 * k2
            for r in range(3):
                a, b, e = J[3 * r], J[3 * r + 1], J[3 * r + 2]
                R[i, r, 0] = a * r00 + b * r10 + e * r20
                R[i, r, 1] = a * r01 + b * r11 + e * r21
                R[i, r, 2] = a * r02 + b * r12 + e * r22
                p[i, r] = J[JOINT_P + r]
        else:
            l0, l1, l2 = J[JOINT_S], J[JOINT_S + 1], J[JOINT_S + 2]
            for r in range(3):
                a, b, e = J[3 * r], J[3 * r + 1], J[3 * r + 2]
                R[i, r, 0], R[i, r, 1], R[i, r, 2] = a, b, e
                p[i, r] = J[JOINT_P + r] + q[i] * (a * l0 + b * l1 + e * l2)


@numba.njit(cache=False, error_model="numpy")
def _motion(joints, R, p, qd, qdd, g0, g1, g2, v, a):
    """Forward pass: each joint frame's spatial velocity v and acceleration a (n, 6).

    The base moves with linear acceleration (g0, g1, g2) (-gravity, or 0) and no
    velocity; v_i = X_i v_parent + S_i qd_i, a_i = X_i a_parent + S_i qdd_i +
    v_i x S_i qd_i, with X_i: ang' = R^T ang, lin' = R^T (lin + ang x p).
    """
    pw0, pw1, pw2 = 0.0, 0.0, 0.0            # parent's angular velocity
    pv0, pv1, pv2 = 0.0, 0.0, 0.0            # parent's linear velocity
    pal0, pal1, pal2 = 0.0, 0.0, 0.0         # parent's angular acceleration
    pa0, pa1, pa2 = g0, g1, g2               # parent's linear acceleration
    for i in range(qd.shape[0]):
        J = joints[i]
        sl0, sl1, sl2 = J[JOINT_S], J[JOINT_S + 1], J[JOINT_S + 2]
        sa0, sa1, sa2 = J[JOINT_S + 3], J[JOINT_S + 4], J[JOINT_S + 5]
        px, py, pz = p[i, 0], p[i, 1], p[i, 2]
        cx, cy, cz = _cross3(pw0, pw1, pw2, px, py, pz)
        lx, ly, lz = pv0 + cx, pv1 + cy, pv2 + cz
        dx, dy, dz = _cross3(pal0, pal1, pal2, px, py, pz)
        mx, my, mz = pa0 + dx, pa1 + dy, pa2 + dz
        Ri = R[i]
        rate, acc = qd[i], qdd[i]
        w0 = Ri[0, 0] * pw0 + Ri[1, 0] * pw1 + Ri[2, 0] * pw2 + sa0 * rate
        w1 = Ri[0, 1] * pw0 + Ri[1, 1] * pw1 + Ri[2, 1] * pw2 + sa1 * rate
        w2 = Ri[0, 2] * pw0 + Ri[1, 2] * pw1 + Ri[2, 2] * pw2 + sa2 * rate
        v0 = Ri[0, 0] * lx + Ri[1, 0] * ly + Ri[2, 0] * lz + sl0 * rate
        v1 = Ri[0, 1] * lx + Ri[1, 1] * ly + Ri[2, 1] * lz + sl1 * rate
        v2 = Ri[0, 2] * lx + Ri[1, 2] * ly + Ri[2, 2] * lz + sl2 * rate
        # v x (S qd) = (w x s_lin + v x s_ang, w x s_ang) qd
        c1x, c1y, c1z = _cross3(w0, w1, w2, sl0, sl1, sl2)
        c2x, c2y, c2z = _cross3(v0, v1, v2, sa0, sa1, sa2)
        c3x, c3y, c3z = _cross3(w0, w1, w2, sa0, sa1, sa2)
        al0 = (Ri[0, 0] * mx + Ri[1, 0] * my + Ri[2, 0] * mz) + sl0 * acc + (c1x + c2x) * rate
        al1 = (Ri[0, 1] * mx + Ri[1, 1] * my + Ri[2, 1] * mz) + sl1 * acc + (c1y + c2y) * rate
        al2 = (Ri[0, 2] * mx + Ri[1, 2] * my + Ri[2, 2] * mz) + sl2 * acc + (c1z + c2z) * rate
        aa0 = (Ri[0, 0] * pal0 + Ri[1, 0] * pal1 + Ri[2, 0] * pal2) + sa0 * acc + c3x * rate
        aa1 = (Ri[0, 1] * pal0 + Ri[1, 1] * pal1 + Ri[2, 1] * pal2) + sa1 * acc + c3y * rate
        aa2 = (Ri[0, 2] * pal0 + Ri[1, 2] * pal1 + Ri[2, 2] * pal2) + sa2 * acc + c3z * rate
        v[i, 0], v[i, 1], v[i, 2], v[i, 3], v[i, 4], v[i, 5] = v0, v1, v2, w0, w1, w2
        a[i, 0], a[i, 1], a[i, 2], a[i, 3], a[i, 4], a[i, 5] = al0, al1, al2, aa0, aa1, aa2
        pw0, pw1, pw2, pv0, pv1, pv2 = w0, w1, w2, v0, v1, v2
        pa0, pa1, pa2, pal0, pal1, pal2 = al0, al1, al2, aa0, aa1, aa2


@numba.njit(cache=False, error_model="numpy")
def _body_regressor(v, a, out):
    """Yb (6, 10): (force; moment about the origin) of one link, columns m, m c, I_O.

    With a_c = a_lin + w x v_lin: m -> (a_c; 0); m c_k -> (alpha x e_k + w x (w x e_k);
    e_k x a_c); an entry of I_O (basis matrix E) -> (0; E alpha + w x (E w)).
    """
    v0, v1, v2, w0, w1, w2 = v[0], v[1], v[2], v[3], v[4], v[5]
    l0, l1, l2, al0, al1, al2 = a[0], a[1], a[2], a[3], a[4], a[5]
    cx, cy, cz = _cross3(w0, w1, w2, v0, v1, v2)
    ac0, ac1, ac2 = l0 + cx, l1 + cy, l2 + cz
    for r in range(6):
        for col in range(10):
            out[r, col] = 0.0
    out[0, 0], out[1, 0], out[2, 0] = ac0, ac1, ac2
    for k in range(3):
        e0, e1, e2 = (1.0 if k == 0 else 0.0), (1.0 if k == 1 else 0.0), (1.0 if k == 2 else 0.0)
        f0, f1, f2 = _cross3(al0, al1, al2, e0, e1, e2)          # alpha x e
        g0, g1, g2 = _cross3(w0, w1, w2, e0, e1, e2)              # w x e
        h0, h1, h2 = _cross3(w0, w1, w2, g0, g1, g2)              # w x (w x e)
        n0, n1, n2 = _cross3(e0, e1, e2, ac0, ac1, ac2)           # e x a_c
        out[0, 1 + k], out[1, 1 + k], out[2, 1 + k] = f0 + h0, f1 + h1, f2 + h2
        out[3, 1 + k], out[4, 1 + k], out[5, 1 + k] = n0, n1, n2
    _inertia_column(out, 4, al0, 0.0, 0.0, w0, 0.0, 0.0, w0, w1, w2)    # Ixx
    _inertia_column(out, 5, al1, al0, 0.0, w1, w0, 0.0, w0, w1, w2)    # Ixy
    _inertia_column(out, 6, 0.0, al1, 0.0, 0.0, w1, 0.0, w0, w1, w2)   # Iyy
    _inertia_column(out, 7, al2, 0.0, al0, w2, 0.0, w0, w0, w1, w2)    # Ixz
    _inertia_column(out, 8, 0.0, al2, al1, 0.0, w2, w1, w0, w1, w2)    # Iyz
    _inertia_column(out, 9, 0.0, 0.0, al2, 0.0, 0.0, w2, w0, w1, w2)   # Izz


@numba.njit(inline="always")
def _inertia_column(out, col, ea0, ea1, ea2, ew0, ew1, ew2, w0, w1, w2):
    x0, x1, x2 = _cross3(w0, w1, w2, ew0, ew1, ew2)
    out[3, col], out[4, col], out[5, col] = ea0 + x0, ea1 + x1, ea2 + x2


@numba.njit(cache=False, error_model="numpy")
def _to_parent(R, p, F, out):
    """Forces (6, k) of a frame in its parent: f' = R f, n' = R n + p x (R f)."""
    for col in range(F.shape[1]):
        f0 = R[0, 0] * F[0, col] + R[0, 1] * F[1, col] + R[0, 2] * F[2, col]
        f1 = R[1, 0] * F[0, col] + R[1, 1] * F[1, col] + R[1, 2] * F[2, col]
        f2 = R[2, 0] * F[0, col] + R[2, 1] * F[1, col] + R[2, 2] * F[2, col]
        m0 = R[0, 0] * F[3, col] + R[0, 1] * F[4, col] + R[0, 2] * F[5, col]
        m1 = R[1, 0] * F[3, col] + R[1, 1] * F[4, col] + R[1, 2] * F[5, col]
        m2 = R[2, 0] * F[3, col] + R[2, 1] * F[4, col] + R[2, 2] * F[5, col]
        c0, c1, c2 = _cross3(p[0], p[1], p[2], f0, f1, f2)
        out[0, col], out[1, col], out[2, col] = f0, f1, f2
        out[3, col], out[4, col], out[5, col] = m0 + c0, m1 + c1, m2 + c2


@numba.njit(cache=False, error_model="numpy")
def _torque_regressor(joints, R, p, qd, qdd, a0, out, scale):
    """out += scale * Y(q, qd, qdd) (n, 10 n), Y a = M qdd + C qd + g (RNEA), poses R, p."""
    n = qd.shape[0]
    v = np.empty((n, 6))
    a = np.empty((n, 6))
    _motion(joints, R, p, qd, qdd, a0[0], a0[1], a0[2], v, a)
    F = np.empty((6, 10))
    G = np.empty((6, 10))
    for j in range(n):
        _body_regressor(v[j], a[j], F)
        for i in range(j, -1, -1):
            S = joints[i, JOINT_S:JOINT_S + 6]
            for col in range(10):
                acc = 0.0
                for r in range(6):
                    acc += S[r] * F[r, col]
                out[i, 10 * j + col] += scale * acc
            if i > 0:
                _to_parent(R[i], p[i], F, G)
                F[:, :] = G


@compiled(error_model="numpy")
def chain_regressor(q, qd, xi, xi_dot, joints, a0, columns):
    """Y_d (n, p_d) of Property 4: ``RigidBodyDynamics.regressor`` compiled.

    The same two-call polarisation, Y_d = 2 Y(q, (q_dot + xi)/sqrt 8, xi_dot)
    - Y(q, (q_dot - xi)/2, xi_dot), restricted to the base ``columns``.
    Constants (:meth:`.rigid_body.RigidBodyDynamics.kernel_constants`): ``joints``
    (n, 19) placements, motion subspaces, revolute flags; a0 (3,) = -gravity.
    """
    n = q.shape[0]
    R = np.empty((n, 3, 3))
    p = np.empty((n, 3))
    _poses(q, joints, R, p)
    full = np.zeros((n, 10 * n))
    _torque_regressor(joints, R, p, _INV_SQRT8 * (qd + xi), xi_dot, a0, full, 2.0)
    _torque_regressor(joints, R, p, 0.5 * (qd - xi), xi_dot, a0, full, -1.0)
    out = np.empty((n, columns.shape[0]))
    for i in range(n):
        for c in range(columns.shape[0]):
            out[i, c] = full[i, columns[c]]
    return out


@numba.njit(cache=False, error_model="numpy")
def _force_and_transpose(v, a, pi, w, scale, f, Ytw):
    """f += scale Yb(v, a) pi (6,) and Ytw += scale Yb(v, a)^T w (10,), Yb not formed.

    pi: m, m c, Ixx, Ixy, Iyy, Ixz, Iyz, Izz.  Yb pi = (m a_c + alpha x h + w x (w x h);
    h x a_c + I alpha + w x (I w)); Yb^T w for w = (wl, wa): a_c . wl,
    (wl x alpha)_k + w_k (w . wl) - wl_k |w|^2 + (a_c x wa)_k, wa^T E alpha + u^T E w
    with u = wa x w.
    """
    v0, v1, v2, w0, w1, w2 = v[0], v[1], v[2], v[3], v[4], v[5]
    l0, l1, l2, al0, al1, al2 = a[0], a[1], a[2], a[3], a[4], a[5]
    cx, cy, cz = _cross3(w0, w1, w2, v0, v1, v2)
    ac0, ac1, ac2 = l0 + cx, l1 + cy, l2 + cz
    m, h0, h1, h2 = pi[0], pi[1], pi[2], pi[3]
    Ixx, Ixy, Iyy, Ixz, Iyz, Izz = pi[4], pi[5], pi[6], pi[7], pi[8], pi[9]
    t0, t1, t2 = _cross3(al0, al1, al2, h0, h1, h2)
    g0, g1, g2 = _cross3(w0, w1, w2, h0, h1, h2)
    u0, u1, u2 = _cross3(w0, w1, w2, g0, g1, g2)
    f[0] += scale * (m * ac0 + t0 + u0)
    f[1] += scale * (m * ac1 + t1 + u1)
    f[2] += scale * (m * ac2 + t2 + u2)
    n0, n1, n2 = _cross3(h0, h1, h2, ac0, ac1, ac2)
    ia0 = Ixx * al0 + Ixy * al1 + Ixz * al2
    ia1 = Ixy * al0 + Iyy * al1 + Iyz * al2
    ia2 = Ixz * al0 + Iyz * al1 + Izz * al2
    iw0 = Ixx * w0 + Ixy * w1 + Ixz * w2
    iw1 = Ixy * w0 + Iyy * w1 + Iyz * w2
    iw2 = Ixz * w0 + Iyz * w1 + Izz * w2
    x0, x1, x2 = _cross3(w0, w1, w2, iw0, iw1, iw2)
    f[3] += scale * (n0 + ia0 + x0)
    f[4] += scale * (n1 + ia1 + x1)
    f[5] += scale * (n2 + ia2 + x2)
    wl0, wl1, wl2, wa0, wa1, wa2 = w[0], w[1], w[2], w[3], w[4], w[5]
    Ytw[0] += scale * (ac0 * wl0 + ac1 * wl1 + ac2 * wl2)
    b0, b1, b2 = _cross3(wl0, wl1, wl2, al0, al1, al2)
    d0, d1, d2 = _cross3(ac0, ac1, ac2, wa0, wa1, wa2)
    ww = w0 * wl0 + w1 * wl1 + w2 * wl2
    w2n = w0 * w0 + w1 * w1 + w2 * w2
    Ytw[1] += scale * (b0 + w0 * ww - wl0 * w2n + d0)
    Ytw[2] += scale * (b1 + w1 * ww - wl1 * w2n + d1)
    Ytw[3] += scale * (b2 + w2 * ww - wl2 * w2n + d2)
    z0, z1, z2 = _cross3(wa0, wa1, wa2, w0, w1, w2)
    Ytw[4] += scale * (wa0 * al0 + z0 * w0)
    Ytw[5] += scale * (wa0 * al1 + wa1 * al0 + z0 * w1 + z1 * w0)
    Ytw[6] += scale * (wa1 * al1 + z1 * w1)
    Ytw[7] += scale * (wa0 * al2 + wa2 * al0 + z0 * w2 + z2 * w0)
    Ytw[8] += scale * (wa1 * al2 + wa2 * al1 + z1 * w2 + z2 * w1)
    Ytw[9] += scale * (wa2 * al2 + z2 * w2)


@numba.njit(cache=False, error_model="numpy")
def chain_contractions(q, qd, xi, xi_dot, r, a_d, joints, a0, columns, tau, Ytr):
    """tau = Y_d a_d (n,) and Ytr = Y_d^T r (p_d,) in O(n), without forming Y_d.

    Y_d as in :func:`chain_regressor`; a_d fills the base ``columns`` of the
    10 n standard parameters (the others are zero).
    """
    n = q.shape[0]
    nf = 10 * n
    pi = np.zeros(nf)
    for c in range(columns.shape[0]):
        pi[columns[c]] = a_d[c]
    full_tr = np.zeros(nf)
    R = np.empty((n, 3, 3))
    p = np.empty((n, 3))
    _poses(q, joints, R, p)
    # w_j: the motion the joint rates r give link j (the transpose of the force recursion)
    wr = np.empty((n, 6))
    v = np.empty((n, 6))
    a = np.empty((n, 6))
    _motion(joints, R, p, r, np.zeros(n), 0.0, 0.0, 0.0, wr, a)
    f = np.zeros((n, 6))
    for pol in range(2):
        if pol == 0:
            vel, scale = _INV_SQRT8 * (qd + xi), 2.0
        else:
            vel, scale = 0.5 * (qd - xi), -1.0
        _motion(joints, R, p, vel, xi_dot, a0[0], a0[1], a0[2], v, a)
        for j in range(n):
            _force_and_transpose(v[j], a[j], pi[10 * j:10 * j + 10], wr[j], scale, f[j],
                                 full_tr[10 * j:10 * j + 10])
    # backward: F_i = f_i + X* F_{i+1}; tau_i = S_i^T F_i
    fp = np.empty((6, 1))
    for i in range(n - 1, -1, -1):
        acc = 0.0
        for k in range(6):
            acc += joints[i, JOINT_S + k] * f[i, k]
        tau[i] = acc
        if i > 0:
            _to_parent(R[i], p[i], f[i].reshape(6, 1), fp)
            for k in range(6):
                f[i - 1, k] += fp[k, 0]
    for c in range(columns.shape[0]):
        Ytr[c] = full_tr[columns[c]]


@numba.njit(cache=False, error_model="numpy")
def _paper_fill(q, qd, xi, xi_dot, Y):
    q2, q3 = q[1], q[2]
    w1, w2, w3 = qd[0], qd[1], qd[2]
    x1, x2, x3 = xi[0], xi[1], xi[2]
    e1, e2, e3 = xi_dot[0], xi_dot[1], xi_dot[2]
    s2, c2, s3, c3 = math.sin(q2), math.cos(q2), math.sin(q3), math.cos(q3)
    s23, c23 = math.sin(q2 + q3), math.cos(q2 + q3)
    w23 = w2 + w3
    h2 = s2 * c23 + c2 * s23
    h3 = c2 * s23
    p3 = c23 * s23 * w1 * x1
    Y[0, 0] = e1
    Y[0, 1] = c2 * c2 * e1 - c2 * s2 * (w2 * x1 + w1 * x2)
    Y[0, 2] = c23 * c23 * e1 - c23 * s23 * (w23 * x1 + w1 * (x2 + x3))
    Y[0, 3] = 0.0
    Y[0, 4] = 0.0
    Y[0, 5] = 2.0 * c2 * c23 * e1 - (h2 * w2 + h3 * w3) * x1 - (h2 * x2 + h3 * x3) * w1
    Y[0, 6] = 0.0
    Y[0, 7] = 0.0
    Y[1, 0] = 0.0
    Y[1, 1] = c2 * s2 * w1 * x1
    Y[1, 2] = p3
    Y[1, 3] = e2
    Y[1, 4] = e2 + e3
    Y[1, 5] = c3 * (2.0 * e2 + e3) - s3 * (w3 * x2 + w23 * x3) + h2 * w1 * x1
    Y[1, 6] = c2
    Y[1, 7] = c23
    Y[2, 0] = 0.0
    Y[2, 1] = 0.0
    Y[2, 2] = p3
    Y[2, 3] = 0.0
    Y[2, 4] = e2 + e3
    Y[2, 5] = c3 * e2 + s3 * w2 * x2 + h3 * w1 * x1
    Y[2, 6] = 0.0
    Y[2, 7] = c23


@compiled(error_model="numpy")
def paper_regressor(q, qd, xi, xi_dot):
    """Y_d (3, 8) of the paper's arm: ``PaperRRRCamera.dynamic_regressor_numpy`` compiled."""
    Y = np.empty((3, 8))
    _paper_fill(q, qd, xi, xi_dot, Y)
    return Y


@numba.njit(cache=False, error_model="numpy")
def paper_contractions(q, qd, xi, xi_dot, r, a_d, tau, Ytr):
    """tau = Y_d a_d (3,), Ytr = Y_d^T r (8,) of the paper's arm (from the matrix: 3 x 8)."""
    Y = np.empty((3, 8))
    _paper_fill(q, qd, xi, xi_dot, Y)
    for i in range(3):
        acc = 0.0
        for c in range(8):
            acc += Y[i, c] * a_d[c]
        tau[i] = acc
    for c in range(8):
        acc = 0.0
        for i in range(3):
            acc += r[i] * Y[i, c]
        Ytr[c] = acc
