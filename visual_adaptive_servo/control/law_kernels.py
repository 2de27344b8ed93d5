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

"""The control law compiled with numba: :func:`.controller.control_law` in one kernel.

The numpy functions of :mod:`.controller` (``control_law``,
``estimated_kinematics``, ``joint_space_law``, ``_damped_gram_inverse``,
``Projection.kinematic_rates`` / ``dynamic_rate``) stay the readable reference
and the test oracle; :func:`law` follows them step by step, as loops over
the few elements they have (at n = 7, m = 3 the numpy law is ~80 calls on
arrays of 2 to 300 elements, and their fixed cost, not the arithmetic, is
its time).  The dynamic regressor enters only as Y_d a_d and Y_d^T r, which
:mod:`..models.dynamics_kernels` evaluates without forming Y_d (O(n) for a
URDF chain).  Importing this module imports numba.

:class:`CompiledLaw` packs a model's, the gains' and the projection's
constants once and calls the kernel; :meth:`.controller.AdaptiveVisualTracker._law`
uses it when the model runs the compiled backend.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..models.dynamics_kernels import chain_contractions, paper_contractions
from ..models.kernels import compiled

#: model kinds of :func:`law`: the paper's RRR arm (closed form), a URDF chain (RNEA)
PAPER, CHAIN = 0, 1


@numba.njit(cache=False, error_model="numpy")
def _smallest_eigenvalue(G):
    """The smallest eigenvalue of the symmetric G, as numpy.linalg.eigvalsh finds it.

    The same route as LAPACK's (dsyevd without vectors: dsytrd, then dsterf):
    Householder reduction to a tridiagonal matrix, then implicit QL with
    Wilkinson shifts (Numerical Recipes' tred2 / tqli); absolute accuracy eps |G|.
    (The Gram matrices here are far from overflow: sqrt replaces hypot.)
    """
    N = G.shape[0]
    a = G.copy()
    d = np.empty(N)
    e = np.zeros(N)
    for i in range(N - 1, 0, -1):
        lo = i - 1
        h = 0.0
        if lo > 0:
            scale = 0.0
            for k in range(lo + 1):
                scale += abs(a[i, k])
            if scale == 0.0:
                e[i] = a[i, lo]
            else:
                for k in range(lo + 1):
                    a[i, k] /= scale
                    h += a[i, k] * a[i, k]
                f = a[i, lo]
                g = -math.sqrt(h) if f >= 0.0 else math.sqrt(h)
                e[i] = scale * g
                h -= f * g
                a[i, lo] = f - g
                f = 0.0
                for j in range(lo + 1):
                    g = 0.0
                    for k in range(j + 1):
                        g += a[j, k] * a[i, k]
                    for k in range(j + 1, lo + 1):
                        g += a[k, j] * a[i, k]
                    e[j] = g / h
                    f += e[j] * a[i, j]
                hh = f / (h + h)
                for j in range(lo + 1):
                    f = a[i, j]
                    g = e[j] - hh * f
                    e[j] = g
                    for k in range(j + 1):
                        a[j, k] -= f * e[k] + g * a[i, k]
        else:
            e[i] = a[i, lo]
    for i in range(N):
        d[i] = a[i, i]
    for i in range(1, N):
        e[i - 1] = e[i]
    e[N - 1] = 0.0
    for lo in range(N):
        for _ in range(100):
            m = lo
            while m < N - 1:
                dd = abs(d[m]) + abs(d[m + 1])
                if abs(e[m]) <= 1.1102230246251565e-16 * dd:
                    break
                m += 1
            if m == lo:
                break
            g = (d[lo + 1] - d[lo]) / (2.0 * e[lo])
            r = math.sqrt(g * g + 1.0)
            g = d[m] - d[lo] + e[lo] / (g + (r if g >= 0.0 else -r))
            s, c, p = 1.0, 1.0, 0.0
            i = m - 1
            deflated = False
            while i >= lo:
                f = s * e[i]
                b = c * e[i]
                r = math.sqrt(f * f + g * g)    # hypot: 3x the time, no overflow here
                e[i + 1] = r
                if r == 0.0:
                    d[i + 1] -= p
                    e[m] = 0.0
                    deflated = True
                    break
                s = f / r
                c = g / r
                g = d[i + 1] - p
                r = (d[i] - g) * s + 2.0 * c * b
                p = s * r
                d[i + 1] = g + p
                g = c * r - b
                i -= 1
            if deflated:
                continue
            d[lo] -= p
            e[lo] = g
            e[m] = 0.0
    smallest = d[0]
    for i in range(1, N):
        smallest = min(smallest, d[i])
    return smallest


@numba.njit(cache=False, error_model="numpy")
def _inverse(G):
    """G^-1 by LU with partial pivoting (LAPACK's gesv on the identity, as numpy.linalg.inv).

    A zero pivot raises LinAlgError("Singular matrix"), as numpy does.
    """
    N = G.shape[0]
    A = G.copy()
    perm = np.arange(N)
    for k in range(N):
        piv, best = k, abs(A[k, k])
        for i in range(k + 1, N):
            if abs(A[i, k]) > best:
                piv, best = i, abs(A[i, k])
        if best == 0.0:
            raise np.linalg.LinAlgError("Singular matrix")
        if piv != k:
            for j in range(N):
                A[k, j], A[piv, j] = A[piv, j], A[k, j]
            perm[k], perm[piv] = perm[piv], perm[k]
        for i in range(k + 1, N):
            A[i, k] /= A[k, k]
            f = A[i, k]
            for j in range(k + 1, N):
                A[i, j] -= f * A[k, j]
    inv = np.empty((N, N))
    y = np.empty(N)
    for col in range(N):
        for i in range(N):                          # L y = P e_col
            acc = 1.0 if perm[i] == col else 0.0
            for j in range(i):
                acc -= A[i, j] * y[j]
            y[i] = acc
        for i in range(N - 1, -1, -1):              # U x = y
            acc = y[i]
            for j in range(i + 1, N):
                acc -= A[i, j] * inv[j, col]
            inv[i, col] = acc / A[i, i]
    return inv


# error_model="numpy": a division by zero gives inf/nan as numpy's does (the tracker then
# rejects the sample as not finite) instead of raising ZeroDivisionError.  fastmath
# "reassoc": sums over the parameters may be reordered (SIMD, several accumulators: a
# single accumulator waits ~4 cycles per add); no assumption about NaN or inf is made
@compiled(error_model="numpy", fastmath={"reassoc", "contract"})
def law(H, dH, dH_rate, W, W_rate, x_obs, a_perp, a_z, a_d, q, qd, x, xd, xd_dot, xd_ddot,
        e_int, scale, scale_dot, ref_scale, ref_scale_dot, gains, bounds, scalars, project,
        joints, columns, out):
    """The paper's law at one instant, as :func:`.controller.control_law` computes it.

    ``scale``, ``scale_dot``: the image-motion scale s and its rate (1, 0: off; see
    ``control_law``'s ``motion_scale``); ``ref_scale``, ``ref_scale_dot`` what eq (18)
    maps with (``control_law``'s ``reference_scale``; s, s_dot when it is None).  Few
    arguments otherwise, because numba's dispatcher checks each one at every call:
    ``gains`` is K (2m), Gamma_d (p_d), Gamma_z_perp (p_perp), Gamma_z (p_z), the
    leakage's a_z_perp(0), a_z(0), a_d(0) and D (n x n, row-major) end to end;
    ``bounds`` the projection's a_z_perp, a_z, a_d minima and maxima (in that
    order, min then max); ``scalars`` alpha, gamma, kappa (integral rate, 0: off),
    leakage kinematic and dynamic, min_singular_value, projection min_depth, 1.0
    if D is used, the model kind (PAPER, CHAIN) and -gravity (3).  ``project``:
    apply the projection.  ``joints``, ``columns``: the chain's constants
    (:meth:`.rigid_body.RigidBodyDynamics.kernel_constants`, empty for PAPER).

    Writes tau, x_obs_dot, a_perp_dot, a_z_dot, a_d_dot, s, qr_dot, qr_ddot,
    J_star (2m x n), z_hat, model_rate (3 x 2m) into ``out`` end to end (one array:
    returning each as its own array costs ~0.3 µs apiece); returns (sigma_min,
    damped, projection_active).
    """
    alpha, gamma, kappa = scalars[0], scalars[1], scalars[2]
    leak_k, leak_d, msv, min_depth = scalars[3], scalars[4], scalars[5], scalars[6]
    use_D = scalars[7] != 0.0
    kind = int(scalars[8])
    a0 = scalars[9:12]
    m2 = x.shape[0]
    m = H.shape[0]
    n = q.shape[0]
    pz = H.shape[1]
    pp = W.shape[2]
    pd = a_d.shape[0]
    K = gains[:m2]
    Gamma_d = gains[m2:m2 + pd]
    o = m2 + pd
    Gamma_zp = gains[o:o + pp]
    Gamma_z = gains[o + pp:o + pp + pz]
    o += pp + pz
    a_perp0 = gains[o:o + pp]
    a_z0 = gains[o + pp:o + pp + pz]
    a_d0 = gains[o + pp + pz:o + pp + pz + pd]
    D = gains[o + pp + pz + pd:o + pp + pz + pd + n * n].reshape(n, n)
    perp_lo, perp_hi = bounds[:pp], bounds[pp:2 * pp]
    z_lo, z_hi = bounds[2 * pp:2 * pp + pz], bounds[2 * pp + pz:2 * pp + 2 * pz]
    o = 2 * pp + 2 * pz
    d_lo, d_hi = bounds[o:o + pd], bounds[o + pd:o + 2 * pd]
    # the outputs, views of ``out`` (the layout of CompiledLaw.__init__)
    tau, o = out[:n], n
    x_obs_dot, o = out[o:o + m2], o + m2
    a_perp_dot, o = out[o:o + pp], o + pp
    a_z_dot, o = out[o:o + pz], o + pz
    a_d_dot, o = out[o:o + pd], o + pd
    s, o = out[o:o + n], o + n
    qr_dot, o = out[o:o + n], o + n
    qr_ddot, o = out[o:o + n], o + n
    J_star, o = out[o:o + m2 * n].reshape(m2, n), o + m2 * n
    Zh1, o = out[o:o + m], o + m
    rate = out[o:o + 3 * m2].reshape(3, m2)      # (J_perp q_dot, Z_hat_dot, Z_hat)
    # -- estimated_kinematics: per point, then per image coordinate (row r: point r // 2)
    H_rate = np.empty((m, pz))                       # q_dot . dH
    Zr1 = np.empty(m)
    J_z = np.empty((m, n))                           # dH . a_z
    for i in range(m):
        for p in range(pz):
            H_rate[i, p] = 0.0
        for k in range(n):
            for p in range(pz):
                H_rate[i, p] += qd[k] * dH[i, k, p]
        acc = 0.0
        acc_r = 0.0
        for p in range(pz):
            acc += H[i, p] * a_z[p]
            acc_r += H_rate[i, p] * a_z[p]
        Zh1[i] = acc
        Zr1[i] = acc_r
        for k in range(n):
            acc = 0.0
            for p in range(pz):
                acc += dH[i, k, p] * a_z[p]
            J_z[i, k] = acc
    J_perp = np.empty((m2, n))
    for r in range(m2):
        for k in range(n):
            acc = 0.0
            for p in range(pp):
                acc += W[r, k, p] * a_perp[p]
            J_perp[r, k] = acc
    # -- control_law: observer (10), references (18)/(19), rates (24), (25)
    x_r_dot = np.empty(m2)
    x_r_ddot = np.empty(m2)
    u = np.empty(m2)
    u_dot = np.empty(m2)
    dx = np.empty(m2)
    dx_obs = np.empty(m2)
    w_H = np.empty(m2)
    w_H_rate = np.empty(m2)
    for r in range(m2):
        zh, zr = Zh1[r // 2], Zr1[r // 2]
        e_obs = x_obs[r] - xd[r]
        dx_obs[r] = x_obs[r] - x[r]
        dx[r] = x[r] - xd[r]
        u[r] = 0.5 * (x_obs[r] + xd[r])
        x_mid = dx[r] + u[r]
        acc = 0.0
        for k in range(n):
            acc += J_perp[r, k] * qd[k]
        rate[0, r], rate[1, r], rate[2, r] = acc, zr, zh
        x_obs_model = scale * ((acc - zr * x_mid) / zh)
        x_obs_dot[r] = x_obs_model - alpha * dx_obs[r]
        x_r_dot[r] = xd_dot[r] - gamma * e_obs
        x_r_ddot[r] = xd_ddot[r] - gamma * (x_obs_dot[r] - xd_dot[r])
        if kappa > 0.0:
            x_r_dot[r] = x_r_dot[r] - kappa * e_int[r]
            x_r_ddot[r] = x_r_ddot[r] - kappa * e_obs
        w_H[r] = x_obs_model * dx_obs[r] - x_r_dot[r] * dx[r]
        w_H_rate[r] = x_mid * dx_obs[r] - u[r] * dx[r]
        u_dot[r] = 0.5 * (x_obs_dot[r] + xd_dot[r])
        if ref_scale != 1.0 or ref_scale_dot != 0.0:
            # the motion scale: eq (18) maps x_r_dot / r, eq (19) its exact derivative
            x_r_ddot[r] = (x_r_ddot[r] / ref_scale
                           - (ref_scale_dot / ref_scale ** 2) * x_r_dot[r])
            x_r_dot[r] = x_r_dot[r] / ref_scale
    for p in range(pp):
        a_perp_dot[p] = 0.0
    Y_perp = np.empty(pp)                            # row r of Y_z_perp = q_dot . W
    for r in range(m2):
        for p in range(pp):
            Y_perp[p] = 0.0
        for k in range(n):
            for p in range(pp):
                Y_perp[p] += qd[k] * W[r, k, p]
        c = dx[r] - dx_obs[r]
        for p in range(pp):
            a_perp_dot[p] += c * Y_perp[p]
    for p in range(pp):
        a_perp_dot[p] = Gamma_zp[p] * a_perp_dot[p]
    for p in range(pz):
        acc = 0.0
        acc_r = 0.0
        for r in range(m2):
            acc += w_H[r] * H[r // 2, p]
            acc_r += w_H_rate[r] * H_rate[r // 2, p]
        a_z_dot[p] = Gamma_z[p] * (acc + acc_r)
    if leak_k > 0.0:
        for p in range(pp):
            a_perp_dot[p] = a_perp_dot[p] - leak_k * (a_perp[p] - a_perp0[p])
        for p in range(pz):
            a_z_dot[p] = a_z_dot[p] - leak_k * (a_z[p] - a_z0[p])
    # -- joint_space_law: Projection.kinematic_rates (Remark 6)
    active = False
    if project:
        free = np.empty(pz)
        for p in range(pp):
            est, rt = a_perp[p], a_perp_dot[p]
            if (est <= perp_lo[p] and rt < 0.0) or (est >= perp_hi[p] and rt > 0.0):
                a_perp_dot[p] = 0.0
                active = True
        for p in range(pz):
            est, rt = a_z[p], a_z_dot[p]
            blocked = (est <= z_lo[p] and rt < 0.0) or (est >= z_hi[p] and rt > 0.0)
            free[p] = 0.0 if blocked else 1.0
            if blocked:
                a_z_dot[p] = 0.0
                active = True
        for i in range(m):
            depth, along = 0.0, 0.0
            for p in range(pz):
                depth += H[i, p] * a_z[p]
                along += H[i, p] * a_z_dot[p]
            if depth <= min_depth and along < 0.0:
                denom = 0.0
                for p in range(pz):
                    denom += H[i, p] * (Gamma_z[p] * H[i, p] * free[p])
                if denom > 0.0:
                    for p in range(pz):
                        a_z_dot[p] = a_z_dot[p] - Gamma_z[p] * H[i, p] * free[p] * along / denom
                    active = True
    # eq (18): J* = J_hat(q, u) and its total time derivative
    J_star_dot = np.empty((m2, n))
    J_z_dot = np.empty((m, n))
    for i in range(m):
        for k in range(n):
            acc = 0.0
            acc2 = 0.0
            for p in range(pz):
                acc += dH_rate[i, k, p] * a_z[p]
                acc2 += dH[i, k, p] * a_z_dot[p]
            J_z_dot[i, k] = acc + acc2
    Zh = rate[2]
    Zh_dot = np.empty(m2)
    for r in range(m2):
        i = r // 2
        for k in range(n):
            J_star[r, k] = J_perp[r, k] - u[r] * J_z[i, k]
            acc = 0.0
            acc2 = 0.0
            for p in range(pp):
                acc += W_rate[r, k, p] * a_perp[p]
                acc2 += W[r, k, p] * a_perp_dot[p]
            J_star_dot[r, k] = (acc + acc2) - u_dot[r] * J_z[i, k] - u[r] * J_z_dot[i, k]
        acc = 0.0
        for p in range(pz):
            acc += H[i, p] * a_z_dot[p]
        Zh_dot[r] = rate[1, r] + acc
    # _damped_gram_inverse
    G = np.empty((m2, m2))
    for r in range(m2):
        for c in range(m2):
            acc = 0.0
            for k in range(n):
                acc += J_star[r, k] * J_star[c, k]
            G[r, c] = acc
    ga, gb, gd = G[0, 0], G[0, 1], G[m2 - 1, m2 - 1]
    if m2 == 2:
        eig_min = 0.5 * (ga + gd) - math.sqrt(max(0.25 * (ga - gd) ** 2 + gb * gb, 0.0))
    else:
        eig_min = _smallest_eigenvalue(G)
    sigma_min = math.sqrt(max(eig_min, 0.0))
    damped = sigma_min < msv
    lam2 = msv * msv - sigma_min * sigma_min if damped else 0.0
    if m2 == 2:
        ga, gd = ga + lam2, gd + lam2
        det = ga * gd - gb * gb
        if det == 0.0:
            raise np.linalg.LinAlgError("Singular matrix")
        G_inv = np.empty((m2, m2))
        G_inv[0, 0], G_inv[0, 1] = gd / det, -gb / det
        G_inv[1, 0], G_inv[1, 1] = -gb / det, ga / det
    else:
        if damped:
            for r in range(m2):
                G[r, r] += lam2
        G_inv = _inverse(G)
    # q_dot_r (18), q_ddot_r (19)
    zx = np.empty(m2)
    for r in range(m2):
        zx[r] = Zh[r] * x_r_dot[r]
    y = np.empty(m2)
    for r in range(m2):
        acc = 0.0
        for c in range(m2):
            acc += G_inv[r, c] * zx[c]
        y[r] = acc
    v = np.empty(n)
    for k in range(n):
        acc = 0.0
        acc2 = 0.0
        for r in range(m2):
            acc += y[r] * J_star[r, k]
            acc2 += y[r] * J_star_dot[r, k]
        qr_dot[k] = acc
        v[k] = acc2
    b = np.empty(m2)
    for r in range(m2):
        acc = 0.0
        acc2 = 0.0
        for k in range(n):
            acc += J_star_dot[r, k] * qr_dot[k]
            acc2 += J_star[r, k] * v[k]
        b[r] = (Zh[r] * x_r_ddot[r] + Zh_dot[r] * x_r_dot[r] - acc) - acc2
    gb_ = np.empty(m2)
    for r in range(m2):
        acc = 0.0
        for c in range(m2):
            acc += G_inv[r, c] * b[c]
        gb_[r] = acc
    for k in range(n):
        acc = 0.0
        for r in range(m2):
            acc += gb_[r] * J_star[r, k]
        qr_ddot[k] = v[k] + acc
    # s (20), tau (22), a_d_dot (23)
    minus_s = np.empty(n)
    for k in range(n):
        s[k] = qd[k] - qr_dot[k]
        minus_s[k] = qr_dot[k] - qd[k]
    if kind == PAPER:
        paper_contractions(q, qd, qr_dot, qr_ddot, minus_s, a_d, tau, a_d_dot)
    else:
        chain_contractions(q, qd, qr_dot, qr_ddot, minus_s, a_d, joints, a0, columns, tau,
                           a_d_dot)
    ks = np.empty(m2)
    for r in range(m2):
        acc = 0.0
        for k in range(n):
            acc += J_star[r, k] * s[k]
        ks[r] = K[r] * acc
    for k in range(n):
        acc = 0.0
        for r in range(m2):
            acc += ks[r] * J_star[r, k]
        tau[k] = tau[k] - acc
    if use_D:
        for k in range(n):
            acc = 0.0
            for j in range(n):
                acc += D[k, j] * s[j]
            tau[k] = tau[k] - acc
    for p in range(pd):
        a_d_dot[p] = Gamma_d[p] * a_d_dot[p]
    if leak_d > 0.0:
        for p in range(pd):
            a_d_dot[p] = a_d_dot[p] - leak_d * (a_d[p] - a_d0[p])
    if project:
        for p in range(pd):
            est, rt = a_d[p], a_d_dot[p]
            if (est <= d_lo[p] and rt < 0.0) or (est >= d_hi[p] and rt > 0.0):
                a_d_dot[p] = 0.0
                active = True
    return sigma_min, damped, active


_NO_CHAIN = (np.zeros((0, 19)), np.zeros(0, dtype=np.intp))


def _vector(value, size):
    return np.broadcast_to(np.asarray(value, dtype=float), (size,))


class CompiledLaw:
    """:func:`law` for one model: its constants, and those of the gains and projection in use.

    ``model.dynamics_kernel()`` must not be None (the model runs the compiled
    backend and its Y_d has a kernel).  Making one compiles the kernel (or
    loads it from the cache).
    """

    def __init__(self, model):
        kind, constants = model.dynamics_kernel()
        self.kind = kind
        if kind == CHAIN:
            joints, self.gravity, columns = constants
            self.chain = (joints, columns)
        else:
            self.chain, self.gravity = _NO_CHAIN, np.zeros(3)
        self.n, self.m = model.n, model.m
        self.sizes = (model.p_perp, model.p_z, model.p_d)
        self._gains = None
        self._packed = None
        self._projection = None
        self._bounds = np.concatenate([np.full(size, side * np.inf) for size in self.sizes
                                       for side in (-1.0, 1.0)])
        self._zeros = np.zeros(2 * model.m)
        n, m2 = model.n, 2 * model.m
        sizes = (n, m2, model.p_perp, model.p_z, model.p_d, n, n, n, m2 * n, model.m, 3 * m2)
        ends = np.cumsum(sizes).tolist()
        self._size = ends[-1]
        self._slices = [slice(a, b) for a, b in zip([0] + ends[:7], ends[:8])]
        self._J_star = slice(ends[-4], ends[-3])
        #: where the rates x_obs_dot, a_perp_dot, a_z_dot, a_d_dot lie in ``out``, end to end
        self.rates = slice(ends[0], ends[4])
        #: where x_obs_dot, a_perp_dot, a_z_dot end within ``rates`` (EstimatorState.from_flat)
        self.state_ends = (m2, m2 + model.p_perp, m2 + model.p_perp + model.p_z)
        self._z_hat = slice(ends[-3], ends[-2])
        self._rate = slice(ends[-2], ends[-1])
        self._warm_up(model)

    def _warm_up(self, model):
        """Compile (or load) the kernel now, with placeholder inputs whose outputs are dropped."""
        n, m2 = self.n, 2 * self.m
        zero, pixels = np.zeros(n), np.zeros(m2)
        p_perp, p_z, p_d = self.sizes
        gains = np.ones(m2 + 3 * (p_perp + p_z + p_d) + n * n)
        scalars = np.concatenate([np.ones(8), [float(self.kind)], self.gravity])
        try:
            law(*model.kinematic_tensors(zero, zero), pixels, np.ones(p_perp), np.ones(p_z),
                np.ones(p_d), zero, zero, pixels, pixels, pixels, pixels, pixels, 1.0, 0.0, 1.0,
                0.0, gains, self._bounds, scalars, False, *self.chain, np.empty(self._size))
        except np.linalg.LinAlgError:
            pass                    # placeholder inputs: J* may well be singular

    def _pack(self, gains, kappa, msv, min_depth):
        n, m2 = self.n, 2 * self.m
        p_perp, p_z, p_d = self.sizes
        leak = gains.leakage
        if leak is None:
            rates, initial = (0.0, 0.0), [np.zeros(p_perp), np.zeros(p_z), np.zeros(p_d)]
        else:
            rates = (float(leak.kinematic), float(leak.dynamic))
            initial = [_vector(leak.a_z_perp0, p_perp), _vector(leak.a_z0, p_z),
                       _vector(leak.a_d0, p_d)]
        D = np.zeros(n * n) if gains.D is None else np.asarray(gains.D, dtype=float).reshape(-1)
        flat = np.concatenate([_vector(gains.K, m2), _vector(gains.Gamma_d, p_d),
                               _vector(gains.Gamma_z_perp, p_perp), _vector(gains.Gamma_z, p_z),
                               *initial, D])
        scalars = np.concatenate([[gains.alpha, gains.gamma, kappa, *rates, msv, min_depth,
                                   0.0 if gains.D is None else 1.0, float(self.kind)],
                                  self.gravity])
        return flat, scalars

    def __call__(self, gains, state, q, qd, x, xd, xd_dot, xd_ddot, projection,
                 min_singular_value, tensors, integral, motion_scale=None,
                 reference_scale=None):
        """The outputs of :func:`law` for the inputs of :func:`.controller.control_law`.

        (tau, x_obs_dot, a_perp_dot, a_z_dot, a_d_dot, s, qr_dot, qr_ddot, J_star, z_hat,
        model_rate, sigma_min, damped, projection_active): views of one new array.
        """
        out, sigma_min, damped, active = self.evaluate(
            gains, state, q, qd, x, xd, xd_dot, xd_ddot, projection, min_singular_value,
            tensors, integral, motion_scale, reference_scale)
        m2 = 2 * self.m
        return (*[out[s] for s in self._slices], out[self._J_star].reshape(m2, self.n),
                out[self._z_hat], out[self._rate].reshape(3, m2), sigma_min, damped, active)

    def evaluate(self, gains, state, q, qd, x, xd, xd_dot, xd_ddot, projection,
                 min_singular_value, tensors, integral, motion_scale=None,
                 reference_scale=None):
        """(out, sigma_min, damped, projection_active): :func:`law`'s one output array.

        ``out`` holds tau (n), x_obs_dot (2m), a_perp_dot, a_z_dot, a_d_dot, s, qr_dot,
        qr_ddot (n each), J_star (2m x n), z_hat (m), model_rate (3 x 2m) end to end: the
        four rates in the order of the state's fields (see ``rates``).
        """
        kappa, e_int = integral if integral is not None else (0.0, self._zeros)
        scale, scale_dot = motion_scale if motion_scale is not None else (1.0, 0.0)
        ref, ref_dot = reference_scale if reference_scale is not None else (scale, scale_dot)
        if projection is not None and projection is not self._projection:
            self._projection = projection
            self._bounds = np.concatenate([
                _vector(getattr(projection, f"{name}_{side}"), size)
                for name, size in zip(("a_z_perp", "a_z", "a_d"), self.sizes)
                for side in ("min", "max")])
            self._gains = None
        min_depth = self._projection.min_depth if self._projection is not None else 0.0
        key = (kappa, min_singular_value, min_depth)
        if self._gains is None or self._gains[0] is not gains or self._gains[1] != key:
            self._packed = self._pack(gains, kappa, min_singular_value, min_depth)
            self._gains = (gains, key)
        flat, scalars = self._packed
        out = np.empty(self._size)
        sigma_min, damped, active = law(
            *tensors, state.x_obs, state.a_z_perp, state.a_z, state.a_d, q, qd, x, xd, xd_dot,
            xd_ddot, e_int, float(scale), float(scale_dot), float(ref), float(ref_dot), flat,
            self._bounds, scalars, projection is not None, *self.chain, out)
        return out, sigma_min, damped, active
