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

"""The tracker's common sample in one compiled call (numba).

:meth:`.controller.AdaptiveVisualTracker._sample`, for a sample that does not
restart the observer, is a chain of small steps: the forward-Euler step of the
state, the integral of x_o - x_d, the kinematic tensors, the projection's
interior test and clamp (Remark 6), x_d(t) from the trajectory (and the start
blend), the law of eqs (10)-(25), the finiteness checks, the saturation, and the
quantities the frame predictor and the image-motion scale store.  In Python
each is a few numpy calls on arrays of 2 to 150 elements, whose fixed cost,
not the arithmetic, is the sample's time (about 100 calls of 0.1-0.7 µs at
n = 7).  :func:`sample` does all of them in one kernel, on one preallocated
array per sample, with the same arithmetic in the same order as the numpy
code, which stays the readable reference and the test oracle (the tracker on
the numpy backend, compared at every sample in test_compiled_law.py).

What stays in Python: the restart of the observer (a rare sample), the
messages that name a refused input (:func:`inputs_valid` checks a sample's
measurements in one call first), the frame predictor's and the motion scale's
buffers, and the :class:`~.controller.StepResult`.  Importing this module imports numba.

Calling a numba kernel costs about 60 ns per array argument, so the constant
arrays (the chain's kinematic constants, the dynamic regressor's, the gains,
bounds, the trajectory's table) are packed end to end in one float array
``cf`` and one integer array ``ci``, whose first entries say where each one
lies (:func:`_pack_pieces`); the kernel takes its views.
"""

from __future__ import annotations

import math

import numpy as np

from ..models.kernels import chain_tensors, compiled, paper_tensors
from .law_kernels import CHAIN, law, PAPER
from .trajectory import BlendedStart, quintic_blend, SinusoidTrajectory, TabulatedTrajectory

#: trajectory kinds of :func:`sample`
SINUSOID, TABLE = 0, 1

# the packed pieces, in the order of the header (see _pack_pieces)
_FLOAT = ("A", "B", "C", "axes", "revolute", "dirs", "moves", "known", "gains", "bounds",
          "law_scalars", "joints", "torque_limit", "trajectory", "knots", "x_end",
          "trajectory_scalars", "joint_integral")
_INT = ("frame", "prismatic", "z_index", "perp_index", "columns", "sizes")
(_A, _B, _C, _AXES, _REVOLUTE, _DIRS, _MOVES, _KNOWN, _GAINS, _BOUNDS, _LAW_SCALARS, _JOINTS,
 _TORQUE_LIMIT, _TRAJECTORY_COEF, _KNOTS, _X_END, _TRAJECTORY_SCALARS,
 _JOINT_INTEGRAL) = range(len(_FLOAT))
(_FRAME, _PRISMATIC, _Z_INDEX, _PERP_INDEX, _COLUMNS, _SIZES) = range(
    len(_FLOAT), len(_FLOAT) + len(_INT))
#: entries of the "sizes" piece
(_NS, _LAW_SIZE, _P_PERP, _P_Z, _P_D, _KIND, _HAS_W0, _TRAJECTORY, _PERIODIC, _PROJECT,
 _INTEGRAL, _O_TAU, _O_XD, _O_EINT, _O_ERR, _O_SPEED, _O_RATE, _O_JOINT_INT) = range(18)


@compiled(inline="always")
def _view1(a, ci, k):
    o = ci[4 * k]
    return a[o:o + ci[4 * k + 1]]


@compiled(inline="always")
def _view2(a, ci, k):
    o, d0, d1 = ci[4 * k], ci[4 * k + 1], ci[4 * k + 2]
    return a[o:o + d0 * d1].reshape(d0, d1)


@compiled(inline="always")
def _view3(a, ci, k):
    o, d0, d1, d2 = ci[4 * k], ci[4 * k + 1], ci[4 * k + 2], ci[4 * k + 3]
    return a[o:o + d0 * d1 * d2].reshape(d0, d1, d2)


#: :func:`.trajectory.quintic_blend` compiled (the same function)
_quintic = compiled(inline="always")(quintic_blend)


@compiled(inline="always")
def _block(block, m2, pp, pz, pd):
    """(start in the state, size, start of its minima in the bounds) of estimate block 0-2.

    The blocks are a_z_perp, a_z, a_d; a block's maxima follow its minima in the bounds.
    """
    offset = 0 if block == 0 else pp if block == 1 else pp + pz
    return m2 + offset, (pp if block == 0 else pz if block == 1 else pd), 2 * offset


@compiled(inline="always")
def _desired(cf, ci, sizes, blend, t, xd, xd_dot, xd_ddot):
    """x_d(t) and its two derivatives: the trajectory's ``__call__``, then BlendedStart's."""
    m2 = xd.shape[0]
    scalars = _view1(cf, ci, _TRAJECTORY_SCALARS)
    if sizes[_TRAJECTORY] == SINUSOID:
        # SinusoidTrajectory: (c, s, 1) and its derivatives against rows a_cos, a_sin, offset
        coef = _view2(cf, ci, _TRAJECTORY_COEF)
        w = scalars[0]
        c, s = math.cos(w * t), math.sin(w * t)
        m10, m11 = -w * s, w * c
        m20, m21 = -w * w * c, -w * w * s
        for r in range(m2):
            a_c, a_s, off = coef[0, r], coef[1, r], coef[2, r]
            xd[r] = c * a_c + s * a_s + 1.0 * off
            xd_dot[r] = m10 * a_c + m11 * a_s + 0.0 * off
            xd_ddot[r] = m20 * a_c + m21 * a_s + 0.0 * off
    else:
        # TabulatedTrajectory: the interval's polynomial coefficients of x, x_dot, x_ddot
        t_end = scalars[1]
        tt = t
        if sizes[_PERIODIC] != 0:
            tt = tt % t_end
        if sizes[_PERIODIC] == 0 and tt >= t_end:
            x_end = _view1(cf, ci, _X_END)
            for r in range(m2):
                xd[r], xd_dot[r], xd_ddot[r] = x_end[r], 0.0, 0.0
        else:
            coef = _view3(cf, ci, _TRAJECTORY_COEF)
            knots = _view1(cf, ci, _KNOTS)
            tt = max(tt, 0.0)
            k = max(np.searchsorted(knots, tt, side="right") - 1, 0)
            h = tt - knots[k]
            p0, p1, p2 = h * h * h, h * h, h
            for j in range(3 * m2):
                v = p0 * coef[k, 0, j] + p1 * coef[k, 1, j] + p2 * coef[k, 2, j] \
                    + 1.0 * coef[k, 3, j]
                if j < m2:
                    xd[j] = v
                elif j < 2 * m2:
                    xd_dot[j - m2] = v
                else:
                    xd_ddot[j - 2 * m2] = v
    # BlendedStart: blend = (1.0 when on, t_start, duration, x_start (2m))
    if blend[0] != 0.0 and blend[2] > 0.0:
        duration = blend[2]
        tau = (t - blend[1]) / duration
        if tau < 1.0:
            sigma, sd, sdd = _quintic(tau)
            sd, sdd = sd / duration, sdd / duration ** 2
            for r in range(m2):
                x0 = blend[3 + r]
                gap = xd[r] - x0
                v, a = xd_dot[r], xd_ddot[r]
                xd[r] = x0 + sigma * gap
                xd_dot[r] = sigma * v + sd * gap
                xd_ddot[r] = sigma * a + 2.0 * sd * v + sdd * gap


#: the last five arguments of :func:`sample` when the sample is stored nowhere
NO_STORE = (np.zeros(0), np.zeros((0, 0)), np.zeros((0, 0)), np.zeros(0, dtype=np.bool_), -1)


@compiled(signature="boolean(float64[::1], float64[::1], float64[::1], float64[::1])")
def inputs_valid(q, qd, x, limits):
    """Whether a sample's measurements pass the tracker's input checks, in one call.

    True when q and q_dot hold ``limits[0]`` finite values and x ``limits[1]``
    finite pixels, each point inside the image (``limits[2:6]``: u_min, u_max,
    v_min, v_max); x may be empty (no frame: ``limits[1]`` 0).  The reference
    checks are :func:`.controller.validate_vector` and the tracker's
    ``_check_feature``, which name what is wrong: a False sends the sample to
    them.  The signature takes C-contiguous writable float64 vectors only; any
    other input (a list, a view, a message's read-only buffer) is refused with
    TypeError, which also sends it there (they copy it), instead of compiling
    another specialisation inside the control loop.
    """
    n, m2 = limits[0], limits[1]
    if q.shape[0] != n or qd.shape[0] != n or x.shape[0] != m2:
        return False
    for i in range(q.shape[0]):
        if not (math.isfinite(q[i]) and math.isfinite(qd[i])):
            return False
    for i in range(0, x.shape[0], 2):
        u, v = x[i], x[i + 1]
        if not (math.isfinite(u) and math.isfinite(v) and limits[2] <= u <= limits[3]
                and limits[4] <= v <= limits[5]):
            return False
    return True


@compiled(error_model="numpy")
def sample(cf, ci, blend, prev, res, q, qd, x, t, dt, s, s_dot, s_ref, s_ref_dot, times, rates,
           history, has, at):
    """One sample of :meth:`.controller.AdaptiveVisualTracker._sample`, not a restart.

    ``prev`` is the last accepted sample's array (its state, rates, integral and
    x_d are read), ``res`` this sample's (written; the layout of
    :class:`CompiledSample`); ``x`` the pixels the law sees, ``t`` the sample
    time, ``dt`` the Euler step (already clamped to max_dt), ``s``, ``s_dot`` the
    image-motion scale (1, 0: off), ``s_ref``, ``s_ref_dot`` what eq (18) maps with
    (:attr:`.motion_scale.MotionScale.reference`), ``blend`` the start blend in effect.  Returns
    (finite, sigma_min, damped, projection_active, saturated); with finite False
    ``res`` is to be dropped (the tracker keeps its state).  A singular J* raises
    LinAlgError, as the numpy law does.

    ``at`` >= 0: an accepted sample is also stored in row ``at`` of the frame
    predictor's buffer (``times``, ``rates`` flat, ``history``, ``has`` of
    :class:`.prediction_kernels.BufferedFramePredictor`): what its ``commit_flat``
    writes of (t, x, the rate below), here without a call of its own.
    """
    sizes = _view1(ci, ci, _SIZES)
    n = q.shape[0]
    m2 = x.shape[0]
    m = m2 // 2
    ns, size = sizes[_NS], sizes[_LAW_SIZE]
    pp, pz, pd = sizes[_P_PERP], sizes[_P_Z], sizes[_P_D]
    # the layout of CompiledSample (the law's output follows the state)
    o_out = ns
    o_tau, o_xd, o_eint = sizes[_O_TAU], sizes[_O_XD], sizes[_O_EINT]
    o_err, o_speed, o_rate = sizes[_O_ERR], sizes[_O_SPEED], sizes[_O_RATE]
    o_jint = sizes[_O_JOINT_INT]
    state = res[:ns]
    # EstimatorState.advanced: x + dt x_dot, the rates at the last sample (law output rates)
    for i in range(ns):
        state[i] = prev[i] + dt * prev[o_out + n + i]
    # the reference's integral of x_o - x_d (with the last sample's x_o and x_d)
    e_int = res[o_eint:o_eint + m2]
    for r in range(m2):
        if sizes[_INTEGRAL] != 0:
            e_int[r] = prev[o_eint + r] + dt * (prev[r] - prev[o_xd + r])
        else:
            e_int[r] = prev[o_eint + r]
    # the joint integral of s (joint_damping.integral_rate), with the s the last sample left
    joint_int = res[o_jint:o_jint + n]
    for k in range(n):
        joint_int[k] = prev[o_jint + k] + dt * prev[o_jint + n + k]
    # the model's kinematic tensors
    if sizes[_KIND] == PAPER:
        H, dH, dH_rate, W, W_rate = paper_tensors(q, qd)
    else:
        H, dH, dH_rate, W, W_rate = chain_tensors(
            q, qd, _view3(cf, ci, _A), _view3(cf, ci, _B), _view3(cf, ci, _C),
            _view2(cf, ci, _AXES), _view1(cf, ci, _REVOLUTE), _view1(ci, ci, _FRAME),
            _view2(cf, ci, _DIRS), _view2(cf, ci, _MOVES), _view2(cf, ci, _KNOWN),
            _view2(ci, ci, _PRISMATIC), _view2(ci, ci, _Z_INDEX), _view2(ci, ci, _PERP_INDEX),
            sizes[_HAS_W0] != 0)
    # Projection.interior, and Projection.clamp when the state is not inside
    bounds = _view1(cf, ci, _BOUNDS)
    law_scalars = _view1(cf, ci, _LAW_SCALARS)
    project = False
    if sizes[_PROJECT] != 0:
        min_depth = law_scalars[6]
        inside = True
        # the estimates a_z_perp, a_z, a_d follow x_obs in the state; bounds per block
        for block in range(3):
            first, count, lo_at = _block(block, m2, pp, pz, pd)
            for p in range(count):
                lo, hi = bounds[lo_at + p], bounds[lo_at + count + p]
                if math.isfinite(lo) or math.isfinite(hi):
                    if not (lo < state[first + p] < hi):
                        inside = False
        if inside:
            nearest = np.inf
            for i in range(m):
                acc = 0.0
                for p in range(pz):
                    acc += H[i, p] * state[m2 + pp + p]
                nearest = min(nearest, acc)
            inside = nearest > min_depth
        if not inside:
            project = True
            for block in range(3):
                first, count, lo_at = _block(block, m2, pp, pz, pd)
                for p in range(count):
                    # np.clip: NaN stays NaN
                    v = state[first + p]
                    if v < bounds[lo_at + p]:
                        v = bounds[lo_at + p]
                    if v > bounds[lo_at + count + p]:
                        v = bounds[lo_at + count + p]
                    state[first + p] = v
            a_z = state[m2 + pp:m2 + pp + pz]
            for i in range(m):
                along = 0.0
                hh = 0.0
                for p in range(pz):
                    along += H[i, p] * a_z[p]
                    hh += H[i, p] * H[i, p]
                deficit = min_depth - along
                if deficit > 0.0:
                    for p in range(pz):
                        a_z[p] = a_z[p] + H[i, p] * deficit / hh
    # x_d(t)
    xd = res[o_xd:o_xd + m2]
    xd_dot = res[o_xd + m2:o_xd + 2 * m2]
    xd_ddot = res[o_xd + 2 * m2:o_xd + 3 * m2]
    _desired(cf, ci, sizes, blend, t, xd, xd_dot, xd_ddot)
    # the law (its outputs written into res[o_out:o_tau])
    out = res[o_out:o_tau]
    sigma_min, damped, active = law(
        H, dH, dH_rate, W, W_rate, state[:m2], state[m2:m2 + pp], state[m2 + pp:m2 + pp + pz],
        state[m2 + pp + pz:ns], q, qd, x, xd, xd_dot, xd_ddot, e_int, s, s_dot,
        s_ref, s_ref_dot, _view1(cf, ci, _GAINS), bounds, law_scalars, project,
        _view2(cf, ci, _JOINTS), _view1(ci, ci, _COLUMNS), out)
    # the command before saturation: the law's torque, with - k_i D int s dt of
    # joint_damping.integral_rate (D, n x n row-major, ends the law's gains)
    tau_law = res[o_jint + 2 * n:o_jint + 3 * n]
    k_i = _view1(cf, ci, _JOINT_INTEGRAL)[0]
    if k_i != 0.0:
        gains = _view1(cf, ci, _GAINS)
        o_d = gains.shape[0] - n * n
        for k in range(n):
            acc = 0.0
            for j in range(n):
                acc += gains[o_d + k * n + j] * joint_int[j]
            tau_law[k] = out[k] - k_i * acc
    else:
        for k in range(n):
            tau_law[k] = out[k]
    # finiteness: the torque entry by entry when its sum is not (as _all_finite), the rates and
    # the state by their sums (as EstimatorState.is_finite)
    total = 0.0
    for k in range(n):
        total += tau_law[k]
    finite = math.isfinite(total)
    if not finite:
        finite = True
        for k in range(n):
            finite = finite and math.isfinite(tau_law[k])
    total = 0.0
    for i in range(ns):
        total += out[n + i]
    finite = finite and math.isfinite(total)
    total = 0.0
    for i in range(ns):
        total += state[i]
    finite = finite and math.isfinite(total)
    if not finite:
        return False, sigma_min, damped, active, False
    # saturation at the torque limit
    limit = _view1(cf, ci, _TORQUE_LIMIT)
    saturated = False
    for k in range(n):
        if not (-limit[k] <= tau_law[k] <= limit[k]):
            saturated = True
    for k in range(n):
        v = tau_law[k]
        if saturated:
            v = min(max(v, -limit[k]), limit[k])
        res[o_tau + k] = v
    # the s the next sample integrates: none after a saturated command (no wind-up)
    o_s = n + ns
    for k in range(n):
        res[o_jint + n + k] = 0.0 if saturated else out[o_s + k]
    # what the step reports, the motion scale's path and the frame predictor store
    rate = out[size - 3 * m2:size]                   # J_perp q_dot, Z_hat_dot, Z_hat
    for r in range(m2):
        res[o_err + r] = x[r] - xd[r]
        jq, z_dot, z = rate[r], rate[m2 + r], rate[2 * m2 + r]
        res[o_speed + r] = (jq - x[r] * z_dot) / z
        if s != 1.0:
            jq, z_dot = s * jq, s * z_dot
        res[o_rate + r], res[o_rate + m2 + r], res[o_rate + 2 * m2 + r] = jq, z_dot, z
    if at >= 0:
        times[at] = t
        for r in range(3 * m2):
            rates[at, r] = res[o_rate + r]
        for r in range(m2):
            history[at, r] = x[r]
        has[at] = True
    return True, sigma_min, damped, active, saturated


def _pack_pieces(floats, ints):
    """(cf, ci): the pieces ``floats`` (_FLOAT) and ``ints`` (_INT) packed end to end.

    ``floats`` go into one float array, ``ints`` into one integer array after a
    header of 4 integers per piece: where it starts (in cf or ci) and its shape (up
    to 3 dimensions, padded with 1).
    """
    header = []
    parts, offset = [], 0
    for piece in floats:
        arr = np.ascontiguousarray(piece, dtype=float)
        header.append([offset, *(list(arr.shape) + [1, 1, 1])[:3]])
        parts.append(arr.reshape(-1))
        offset += arr.size
    cf = np.concatenate(parts) if parts else np.zeros(0)
    ints_header_size = 4 * (len(floats) + len(ints))
    iparts, offset = [], ints_header_size
    for piece in ints:
        arr = np.ascontiguousarray(piece, dtype=np.intp)
        header.append([offset, *(list(arr.shape) + [1, 1, 1])[:3]])
        iparts.append(arr.reshape(-1))
        offset += arr.size
    ci = np.concatenate([np.array(header, dtype=np.intp).reshape(-1)] + iparts)
    return np.ascontiguousarray(cf), np.ascontiguousarray(ci, dtype=np.intp)


def supports(tracker):
    """Whether ``tracker``'s trajectory is one :func:`sample` evaluates."""
    return isinstance(tracker.trajectory, (SinusoidTrajectory, TabulatedTrajectory))


class CompiledSample:
    """:func:`sample` for one tracker: its constants packed, and the layout of a sample's array.

    The array of a sample (``size`` floats) holds, end to end: the state (x_obs,
    a_z_perp, a_z, a_d: ``ns``), the law's output (:class:`.law_kernels.CompiledLaw`:
    tau, the four rates, s, qr_dot, qr_ddot, J*, z_hat, the model rate), the
    saturated torque (n), x_d, x_d_dot, x_d_ddot, the integral e_int, the error
    x - x_d, the motion scale's speed (2m each), the rate the frame predictor
    stores (3 x 2m, scaled by s), the joint integral int s dt and the s the next
    sample integrates (n each), and the command before saturation (n: the law's
    torque with the joint integral's term).
    """

    #: the kernel (:func:`sample`)
    kernel = staticmethod(sample)
    #: its last arguments for a sample stored nowhere
    no_store = NO_STORE

    def __init__(self, law_kernel, model, trajectory):
        self.law = law_kernel
        n, m2 = model.n, 2 * model.m
        p_perp, p_z, p_d = model.p_perp, model.p_z, model.p_d
        self.n, self.m2 = n, m2
        self.ns = ns = m2 + p_perp + p_z + p_d
        self.state_ends = law_kernel.state_ends
        o_out = ns
        o_tau = o_out + law_kernel._size
        o_xd = o_tau + n
        o_eint = o_xd + 3 * m2
        o_err = o_eint + m2
        o_speed = o_err + m2
        o_rate = o_speed + m2
        o_jint = o_rate + 3 * m2
        self.size = o_jint + 3 * n
        self._offsets = [o_tau, o_xd, o_eint, o_err, o_speed, o_rate, o_jint]
        self.state = slice(0, ns)
        self.x_obs = slice(0, m2)
        self.out = slice(o_out, o_tau)
        self.rates = slice(o_out + n, o_out + n + ns)
        self.tau_unsaturated = slice(o_jint + 2 * n, o_jint + 3 * n)    # with the integral
        self.z_hat = slice(o_out + law_kernel._z_hat.start, o_out + law_kernel._z_hat.stop)
        self.model_rate = slice(o_out + law_kernel._rate.start, o_out + law_kernel._rate.stop)
        self.tau = slice(o_tau, o_tau + n)
        self.xd = slice(o_xd, o_xd + m2)
        self.e_int = slice(o_eint, o_eint + m2)
        self.error = slice(o_err, o_err + m2)
        self.speed = slice(o_speed, o_speed + m2)
        self.commit_rate = slice(o_rate, o_rate + 3 * m2)
        self.joint_int = slice(o_jint, o_jint + n)
        self.s_int = slice(o_jint + n, o_jint + 2 * n)
        self._trajectory = trajectory
        if isinstance(trajectory, SinusoidTrajectory):
            self._trajectory_pieces = (SINUSOID, 0, trajectory._coefficients,
                                       np.zeros(0), np.zeros(m2), [trajectory.omega, 0.0])
        elif isinstance(trajectory, TabulatedTrajectory):
            x_end = np.asarray(trajectory.spline(trajectory.t_end), dtype=float)
            self._trajectory_pieces = (TABLE, int(trajectory.periodic), trajectory._coef,
                                       np.asarray(trajectory._knots, dtype=float), x_end,
                                       [0.0, trajectory.t_end])
        else:
            raise TypeError(f"no compiled sample for a trajectory of type "
                            f"{type(trajectory).__name__}")
        kind, constants = model.dynamics_kernel()
        self._kind = kind
        if kind == CHAIN:
            reg = model.kinematics
            (self._A, self._B, self._C, self._axes, self._revolute, self._frame, self._dirs,
             self._moves, self._known, self._prismatic, self._z_index, self._perp_index,
             self._has_w0) = reg._kernel_constants
        else:
            empty3 = np.zeros((0, 3, 3))
            self._A = self._B = self._C = empty3
            self._axes, self._revolute, self._dirs = np.zeros((0, 3)), np.zeros(0), \
                np.zeros((0, 3))
            self._moves, self._known = np.zeros((0, 0)), np.zeros((0, 0))
            self._frame = np.zeros(0, dtype=np.intp)
            self._prismatic = np.zeros((0, 2), dtype=np.intp)
            self._z_index = np.zeros((0, 0), dtype=np.intp)
            self._perp_index = np.zeros((0, 0), dtype=np.intp)
            self._has_w0 = False
        self.key = None
        self.cf = self.ci = None
        self.blend = np.zeros(3 + m2)
        self.desired = trajectory
        self._warm()

    def prepare(self, gains, config, projection, min_singular_value):
        """Pack the constants of these gains, configuration and projection (when they changed).

        ``config``: the tracker's controller configuration (integral rate, torque
        limit); ``min_singular_value`` the damping floor of J* in effect.
        """
        key = self.key
        if (key is not None and key[0] is gains and key[1] is config
                and key[2] == min_singular_value):
            return
        kappa = config["reference.integral_rate"] * gains.gamma ** 2
        torque_limit = config["torque_limit"]
        law = self.law
        if projection is not None:
            bounds = np.concatenate([
                np.broadcast_to(np.asarray(getattr(projection, f"{name}_{side}"), dtype=float),
                                (size,))
                for name, size in zip(("a_z_perp", "a_z", "a_d"), law.sizes)
                for side in ("min", "max")])
            min_depth = projection.min_depth
        else:
            bounds, min_depth = law._bounds, 0.0
        flat, scalars = law._pack(gains, kappa, min_singular_value, min_depth)
        k_i = config["joint_damping.integral_rate"] if gains.D is not None else 0.0
        self.cf, self.ci = self._pack(flat, scalars, bounds, torque_limit,
                                      projection is not None, kappa > 0.0, k_i)
        self.key = (gains, config, min_singular_value)

    def _pack(self, flat, scalars, bounds, torque_limit, project, integral, k_i):
        law = self.law
        joints, columns = law.chain
        kind, periodic, coef, knots, x_end, traj_scalars = self._trajectory_pieces
        sizes = [self.ns, law._size, *law.sizes, self._kind, int(bool(self._has_w0)), kind,
                 periodic, int(project), int(integral), *self._offsets]
        floats = [self._A, self._B, self._C, self._axes, self._revolute, self._dirs,
                  self._moves, self._known, flat, bounds, scalars, joints,
                  np.broadcast_to(np.asarray(torque_limit, dtype=float), (self.n,)), coef,
                  knots, x_end, traj_scalars, np.array([float(k_i)])]
        ints = [self._frame, self._prismatic, self._z_index, self._perp_index, columns, sizes]
        return _pack_pieces(floats, ints)

    def set_desired(self, desired):
        """The start blend of ``desired`` (the trajectory itself, or a BlendedStart of it)."""
        self.desired = desired
        blend = np.zeros(3 + self.m2)
        if isinstance(desired, BlendedStart):
            if desired.trajectory is not self._trajectory:
                raise TypeError("the blend is of another trajectory")
            blend[0], blend[1], blend[2] = 1.0, desired.t_start, desired.duration
            blend[3:] = desired.x_start
        elif desired is not self._trajectory:
            raise TypeError("x_d is not the tracker's trajectory")
        self.blend = blend

    def record(self, state_flat, rates_flat, e_int, xd, joint_int, s_int):
        """A sample's array holding what the next :func:`sample` reads (after a Python sample)."""
        res = np.zeros(self.size)
        res[self.state] = state_flat
        res[self.rates] = rates_flat
        res[self.e_int] = e_int
        res[self.xd] = xd
        res[self.joint_int] = joint_int
        res[self.s_int] = s_int
        return res

    def _warm(self):
        """Compile (or load) the kernel now, with placeholder inputs whose outputs are dropped."""
        n, m2 = self.n, self.m2
        p_perp, p_z, p_d = self.law.sizes
        flat = np.ones(m2 + 3 * (p_perp + p_z + p_d) + n * n)
        scalars = np.concatenate([np.ones(8), [float(self._kind)], self.law.gravity])
        cf, ci = self._pack(flat, scalars, self.law._bounds, np.ones(n), True, True, 1.0)
        prev = np.zeros(self.size)
        prev[self.state] = 1.0
        try:
            sample(cf, ci, self.blend, prev, np.empty(self.size), np.zeros(n), np.zeros(n),
                   np.zeros(m2), 1.0, 0.001, 1.0, 0.0, 1.0, 0.0, *NO_STORE)
        except np.linalg.LinAlgError:
            pass                    # placeholder inputs: J* may well be singular
