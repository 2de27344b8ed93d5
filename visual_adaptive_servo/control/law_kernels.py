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

import numpy as np

from ..models.dynamics_kernels import chain_contractions, paper_contractions
from ..models.kernels import compiled

#: model kinds of :func:`law`: the paper's RRR arm (closed form), a URDF chain (RNEA)
PAPER, CHAIN = 0, 1


# error_model="numpy": a division by zero gives inf/nan as numpy's does (the tracker then
# rejects the sample as not finite) instead of raising ZeroDivisionError
@compiled(error_model="numpy")
def law(H, dH, dH_rate, W, W_rate, x_obs, a_perp, a_z, a_d, q, qd, x, xd, xd_dot, xd_ddot,
        e_int, K, Gamma_d, Gamma_zp, Gamma_z, D, a_perp0, a_z0, a_d0,
        perp_lo, perp_hi, z_lo, z_hi, d_lo, d_hi, scalars, project,
        kind, R_J, p_J, S, revolute, a0, columns):
    """The paper's law at one instant, as :func:`.controller.control_law` computes it.

    ``scalars``: alpha, gamma, kappa (integral rate, 0: off), leakage kinematic,
    leakage dynamic, min_singular_value, projection min_depth, 1.0 if D is used.
    ``project``: apply the projection (the bounds ``*_lo``, ``*_hi``).  ``kind``
    and the chain constants choose the dynamic regressor (PAPER, CHAIN).

    Returns (tau, x_obs_dot, a_perp_dot, a_z_dot, a_d_dot, s, qr_dot, qr_ddot,
    J_star, z_hat, model_rate (3, 2m), sigma_min, damped, projection_active).
    """
    alpha, gamma, kappa = scalars[0], scalars[1], scalars[2]
    leak_k, leak_d, msv, min_depth = scalars[3], scalars[4], scalars[5], scalars[6]
    use_D = scalars[7] != 0.0
    m2 = x.shape[0]
    m = H.shape[0]
    n = q.shape[0]
    pz = H.shape[1]
    pp = W.shape[2]
    pd = a_d.shape[0]
    # -- estimated_kinematics: per point, then per image coordinate (row r: point r // 2)
    H_rate = np.empty((m, pz))                       # q_dot . dH
    Zh1 = np.empty(m)
    Zr1 = np.empty(m)
    J_z = np.empty((m, n))                           # dH . a_z
    for i in range(m):
        for p in range(pz):
            acc = 0.0
            for k in range(n):
                acc += qd[k] * dH[i, k, p]
            H_rate[i, p] = acc
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
    rate = np.empty((3, m2))                         # (J_perp q_dot, Z_hat_dot, Z_hat)
    x_obs_dot = np.empty(m2)
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
        x_obs_model = (acc - zr * x_mid) / zh
        x_obs_dot[r] = x_obs_model - alpha * dx_obs[r]
        x_r_dot[r] = xd_dot[r] - gamma * e_obs
        x_r_ddot[r] = xd_ddot[r] - gamma * (x_obs_dot[r] - xd_dot[r])
        if kappa > 0.0:
            x_r_dot[r] = x_r_dot[r] - kappa * e_int[r]
            x_r_ddot[r] = x_r_ddot[r] - kappa * e_obs
        w_H[r] = x_obs_model * dx_obs[r] - x_r_dot[r] * dx[r]
        w_H_rate[r] = x_mid * dx_obs[r] - u[r] * dx[r]
        u_dot[r] = 0.5 * (x_obs_dot[r] + xd_dot[r])
    a_perp_dot = np.empty(pp)
    for p in range(pp):
        acc = 0.0
        for r in range(m2):
            yzp = 0.0
            for k in range(n):
                yzp += qd[k] * W[r, k, p]            # Y_z_perp = q_dot . W
            acc += (dx[r] - dx_obs[r]) * yzp
        a_perp_dot[p] = Gamma_zp[p] * acc
    a_z_dot = np.empty(pz)
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
    J_star = np.empty((m2, n))
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
        eig_min = np.linalg.eigvalsh(G)[0]
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
        G_inv = np.empty((m2, m2))
        G_inv[:, :] = np.linalg.solve(G, np.eye(m2))     # gesv, as numpy.linalg.inv
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
    qr_dot = np.empty(n)
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
    qr_ddot = np.empty(n)
    for k in range(n):
        acc = 0.0
        for r in range(m2):
            acc += gb_[r] * J_star[r, k]
        qr_ddot[k] = v[k] + acc
    # s (20), tau (22), a_d_dot (23)
    s = np.empty(n)
    minus_s = np.empty(n)
    for k in range(n):
        s[k] = qd[k] - qr_dot[k]
        minus_s[k] = qr_dot[k] - qd[k]
    tau = np.empty(n)
    a_d_dot = np.empty(pd)
    if kind == 0:
        paper_contractions(q, qd, qr_dot, qr_ddot, minus_s, a_d, tau, a_d_dot)
    else:
        chain_contractions(q, qd, qr_dot, qr_ddot, minus_s, a_d, R_J, p_J, S, revolute, a0,
                           columns, tau, a_d_dot)
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
    return (tau, x_obs_dot, a_perp_dot, a_z_dot, a_d_dot, s, qr_dot, qr_ddot, J_star,
            Zh1, rate, sigma_min, damped, active)


_NO_CHAIN = (np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 6)), np.zeros(0), np.zeros(3),
             np.zeros(0, dtype=np.intp))


def _vector(value, size):
    return np.ascontiguousarray(np.broadcast_to(np.asarray(value, dtype=float), (size,)))


class CompiledLaw:
    """:func:`law` for one model: its constants, and those of the gains and projection in use.

    ``model.dynamics_kernel()`` must not be None (the model runs the compiled
    backend and its Y_d has a kernel).  The first evaluation compiles the
    kernel (or loads it from the cache); :meth:`warm_up` does it ahead.
    """

    def __init__(self, model):
        kind, constants = model.dynamics_kernel()
        self.kind = kind
        self.chain = tuple(constants) if kind == CHAIN else _NO_CHAIN
        self.n, self.m = model.n, model.m
        self._gains = None
        self._packed_gains = None
        self._projection = None
        self._bounds = tuple(np.full(size, np.inf) * sign
                             for size in (model.p_perp, model.p_z, model.p_d) for sign in (-1, 1))
        self._zeros = np.zeros(2 * model.m)
        self._warm_up(model)

    def _warm_up(self, model):
        """Compile (or load) the kernel now, with placeholder inputs whose outputs are dropped."""
        n, m2 = self.n, 2 * self.m
        zero, pixels = np.zeros(n), np.zeros(m2)
        sizes = (self._bounds[0].size, self._bounds[2].size, self._bounds[4].size)
        estimates = tuple(np.ones(size) for size in sizes)
        gains = (np.ones(m2), np.ones(sizes[2]), np.ones(sizes[0]), np.ones(sizes[1]),
                 np.zeros((n, n))) + tuple(np.zeros(size) for size in sizes)
        try:
            law(*model.kinematic_tensors(zero, zero), pixels, *estimates, zero, zero, pixels,
                pixels, pixels, pixels, pixels, *gains, *self._bounds, np.ones(8), False,
                self.kind, *self.chain)
        except np.linalg.LinAlgError:
            pass                    # placeholder inputs: J* may well be singular

    def _pack_gains(self, gains, kappa, msv, min_depth):
        n, m2 = self.n, 2 * self.m
        leak = gains.leakage
        D = (np.zeros((0, 0)) if gains.D is None
             else np.ascontiguousarray(gains.D, dtype=float).reshape(n, n))
        if leak is None:
            leak_rates, a0 = (0.0, 0.0), (np.zeros(0),) * 3
        else:
            leak_rates = (float(leak.kinematic), float(leak.dynamic))
            a0 = tuple(np.ascontiguousarray(v, dtype=float) for v in
                       (leak.a_z_perp0, leak.a_z0, leak.a_d0))
        p_perp, p_z, p_d = self._bounds[0].size, self._bounds[2].size, self._bounds[4].size
        arrays = (_vector(gains.K, m2), _vector(gains.Gamma_d, p_d),
                  _vector(gains.Gamma_z_perp, p_perp), _vector(gains.Gamma_z, p_z), D) + a0
        scalars = np.array([gains.alpha, gains.gamma, kappa, *leak_rates, msv, min_depth,
                            0.0 if gains.D is None else 1.0])
        return arrays, scalars

    def __call__(self, gains, state, q, qd, x, xd, xd_dot, xd_ddot, projection,
                 min_singular_value, tensors, integral):
        """The raw outputs of :func:`law` for the inputs of :func:`.controller.control_law`."""
        kappa, e_int = integral if integral is not None else (0.0, self._zeros)
        if projection is not None and projection is not self._projection:
            self._projection = projection
            sizes = (self._bounds[0].size, self._bounds[2].size, self._bounds[4].size)
            self._bounds = tuple(
                _vector(getattr(projection, f"{name}_{side}"), size)
                for name, size in zip(("a_z_perp", "a_z", "a_d"), sizes)
                for side in ("min", "max"))
            self._gains = None
        min_depth = self._projection.min_depth if self._projection is not None else 0.0
        key = (kappa, min_singular_value, min_depth)
        if self._gains is None or self._gains[0] is not gains or self._gains[1] != key:
            self._packed_gains = self._pack_gains(gains, kappa, min_singular_value, min_depth)
            self._gains = (gains, key)
        arrays, scalars = self._packed_gains
        return law(*tensors, state.x_obs, state.a_z_perp, state.a_z, state.a_d, q, qd, x, xd,
                   xd_dot, xd_ddot, e_int, *arrays, *self._bounds, scalars,
                   projection is not None, self.kind, *self.chain)
