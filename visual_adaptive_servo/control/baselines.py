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

"""Baselines the paper's controller is measured against (``vas compare``).

No public code of these methods exists; both are written here from their
papers' equations, on the same model object (the regressors of Properties 1
and 4), and both are sampled controllers of the same kind as
:class:`~.controller.AdaptiveVisualTracker` -- same input checks, hold and
fallback, torque limit, Euler integration and ``step(t, q, qd, x)`` ->
:class:`~.controller.StepResult` -- with only the law replaced.

:class:`VelocityAdaptiveTracker`
    Adaptive visual tracking with the depth-independent interaction matrix in
    the style of Liu, Wang, Wang & Lam (IEEE T-RO 2006) and Cheah, Liu &
    Slotine (ICRA 2007): the image velocity is *measured*, by differentiating
    the pixels numerically.  It is the paper's controller with the observer
    taken out, which isolates what the observer buys:

    * x_o := x (no observer state), and the measured velocity v replaces the
      observer rate: x_r_dot = x_d_dot - gamma (x - x_d), x_r_ddot =
      x_d_ddot - gamma (v - x_d_dot), J* = J_hat(q, (x + x_d)/2) with
      u_dot = (v + x_d_dot)/2 in its total derivative;
    * eqs (18)-(23) unchanged (same K, Gamma_d: Slotine-Li dynamic adaptation);
    * kinematic adaptation: eqs (24)/(25) with Delta x_o = 0, i.e.
      a_z_perp_dot = Gamma_z_perp Y_z_perp^T Delta x and a_z_dot =
      -Gamma_z (Y_z_bar(q, q_dot, u) + Y_z(q, x_r_dot))^T Delta x, plus,
      with ``prediction_gain`` k_e > 0, Liu et al.'s gradient on the image
      velocity prediction error e = Z_hat v - J_hat(q, x) q_dot
      = (Y_z(q, v) + Y_z_bar(q, q_dot, x)) Delta a_z - Y_z_perp Delta a_z_perp.

    The velocity v: backward difference of the pixels over the time since the
    last accepted sample, ``(x_k - x_{k-1}) / (t_k - t_{k-1})``, then, when
    ``filter_time`` tau_f > 0, the first-order low-pass tau_f v_dot + v = raw
    discretised by backward Euler, ``v_k = v_{k-1} + dt / (tau_f + dt) (raw -
    v_{k-1})``.  At a (re)start there is no previous pixel and v = 0.

:class:`CalibratedIBVS`
    Classical image-based visual servoing with computed torque and *everything
    known*: the true camera and arm parameters (the model's ``a_z_perp``,
    ``a_z``, ``a_d``).  The image velocity comes from the joint velocity through
    the exact interaction matrix, x_dot = Z^-1 J(q, x) q_dot, and the commanded
    image acceleration x_ddot* = x_d_ddot - k_v (x_dot - x_d_dot) - k_p (x - x_d)
    is resolved by Z x_ddot = J q_ddot + J_dot q_dot - Z_dot x_dot into
    q_ddot* = J^+ (Z x_ddot* + Z_dot x_dot - J_dot q_dot) - k_n (I - J^+ J) q_dot
    (the last term damps the self-motion of a redundant arm); the torque is the
    computed torque M q_ddot* + C q_dot + g = Y_d(q, q_dot, q_dot, q_ddot*) a_d.
    It is the upper reference: what perfect calibration allows at this
    sampling rate, noise and delay.
"""

from __future__ import annotations

import numpy as np

from .controller import (AdaptiveVisualTracker, EstimatorState, LawOutput, _damped_gram_inverse,
                         estimated_kinematics, joint_space_law)


def velocity_law(model, gains, state, q, qd, x, x_dot, xd, xd_dot, xd_ddot, projection=None,
                 min_singular_value=0.0, tensors=None, prediction_gain=0.0):
    """The velocity-based adaptive law at one instant (see the module docstring).

    Parameters are those of :func:`~.controller.control_law` plus ``x_dot``
    (2m,), the measured image velocity [px/s], and ``prediction_gain`` k_e >= 0
    of the prediction-error adaptation.  ``state.x_obs`` is not used; the
    returned ``rates.x_obs`` is ``x_dot``.
    """
    if tensors is None:
        tensors = model.kinematic_tensors(q, qd)
    H, dH, dH_rate, W, W_rate = tensors
    a_z_perp, a_z = state.a_z_perp, state.a_z
    H_rate = qd @ dH
    H2, dH2, _, Zh, Zh_rate, J_perp, J_z = estimated_kinematics(tensors, qd, state)

    dx = x - xd
    x_r_dot = xd_dot - gains.gamma * dx
    x_r_ddot = xd_ddot - gains.gamma * (x_dot - xd_dot)    # the measured image velocity
    u = 0.5 * (x + xd)
    u_dot = 0.5 * (x_dot + xd_dot)

    # eqs (24), (25) with x_o = x
    Y_perp = model.Y_z_perp(W, qd)
    Y_2star = model.Y_z_bar(H_rate, u) + model.Y_z(H, x_r_dot)
    a_perp_dot = gains.Gamma_z_perp * (Y_perp.T @ dx)
    a_z_dot = -gains.Gamma_z * (Y_2star.T @ dx)
    if prediction_gain > 0.0:
        # Liu et al. 2006: gradient of |e|^2 / 2 with e = Z_hat v - J_hat(q, x) q_dot (eq (a5))
        Y_e = model.Y_z(H, x_dot) + model.Y_z_bar(H_rate, x)
        e = Y_e @ a_z - Y_perp @ a_z_perp
        a_perp_dot = a_perp_dot + gains.Gamma_z_perp * (Y_perp.T @ (prediction_gain * e))
        a_z_dot = a_z_dot - gains.Gamma_z * (Y_e.T @ (prediction_gain * e))
    return joint_space_law(model, gains, state, q, qd, (H2, dH2, dH_rate, W, W_rate),
                           (J_perp, J_z), (Zh, Zh_rate), (u, u_dot, x_r_dot, x_r_ddot),
                           (x_dot, a_perp_dot, a_z_dot), projection, min_singular_value)


class VelocityAdaptiveTracker(AdaptiveVisualTracker):
    """Velocity-based adaptive tracker with numerically differentiated pixels.

    It takes each camera frame as current when it arrives (no latency compensation:
    it has no observer to predict with) and holds its command between frames.

    Parameters
    ----------
    config : ControllerConfig
        The same configuration (gains, initial estimates, bounds) as the paper's
        controller; ``alpha`` is not used (there is no observer).
    filter_time : float
        Time constant tau_f [s] of the first-order low-pass on the backward
        difference; 0 = the raw backward difference.
    prediction_gain : float
        Weight k_e of the image-velocity prediction error in the kinematic
        adaptation; 0 = Lyapunov terms only.
    """

    compensates_latency = False

    def __init__(self, config, filter_time=0.0, prediction_gain=0.0):
        if not filter_time >= 0.0:
            raise ValueError(f"filter_time: must be >= 0, got {filter_time}")
        if not prediction_gain >= 0.0:
            raise ValueError(f"prediction_gain: must be >= 0, got {prediction_gain}")
        self.filter_time = float(filter_time)
        self.prediction_gain = float(prediction_gain)
        super().__init__(config)

    def reset(self):
        super().reset()
        self._last_pixels = None    # (t, x, v) of the last accepted sample
        self._pending = None

    def velocity(self, t, x):
        """Image velocity estimate v (2m,) at the new sample (t, x); nothing committed."""
        if self._last_pixels is None or self.t_last is None or self.stale:
            return np.zeros_like(x)
        t_prev, x_prev, v_prev = self._last_pixels
        dt = t - t_prev
        raw = (x - x_prev) / dt
        if self.filter_time == 0.0:
            return raw
        return v_prev + (dt / (self.filter_time + dt)) * (raw - v_prev)

    def step(self, t, q, qd, x=None, x_stamp=None):
        result = super().step(t, q, qd, x, x_stamp)
        if result.status == "ok":
            self._last_pixels = self._pending
        return result

    def _law(self, t, state, q, qd, x, xd, xd_dot, xd_ddot, tensors, projection, e_int=None):
        v = self.velocity(t, x)
        self._pending = (t, x, v)
        return velocity_law(self.model, self.gains, state, q, qd, x, v, xd, xd_dot, xd_ddot,
                            projection, self.min_singular_value, tensors,
                            self.prediction_gain)


def ibvs_law(model, q, qd, x, xd, xd_dot, xd_ddot, gains, min_singular_value=0.0, tensors=None):
    """Calibrated IBVS with computed torque at one instant (see the module docstring).

    ``gains`` is ``(k_p, k_v, k_n)``: image position [1/s^2] and velocity [1/s]
    gains and the self-motion damping [1/s].  Only the model's true parameters
    are used.  Returns a :class:`~.controller.LawOutput` with zero adaptation
    rates, ``rates.x_obs`` = x_dot, ``qr_dot`` = q_dot, ``qr_ddot`` = q_ddot*
    and ``J_star`` = J(q, x).
    """
    k_p, k_v, k_n = gains
    if tensors is None:
        tensors = model.kinematic_tensors(q, qd)
    H, dH, dH_rate, W, W_rate = tensors
    a_z_perp, a_z = model.a_z_perp, model.a_z
    z = H @ a_z
    Z = np.repeat(z, 2)
    Z_rate = np.repeat((qd @ dH) @ a_z, 2)
    J_z = np.repeat(dH @ a_z, 2, axis=0)
    J = W @ a_z_perp - x[:, None] * J_z                  # eq (a1), exact
    x_dot = (J @ qd) / Z
    x_ddot_cmd = xd_ddot - k_v * (x_dot - xd_dot) - k_p * (x - xd)
    J_dot = (W_rate @ a_z_perp - x_dot[:, None] * J_z
             - x[:, None] * np.repeat(dH_rate @ a_z, 2, axis=0))
    G_inv, sigma_min, damped = _damped_gram_inverse(J @ J.T, min_singular_value)
    J_pinv = J.T @ G_inv
    qdd = (J_pinv @ (Z * x_ddot_cmd + Z_rate * x_dot - J_dot @ qd)
           - k_n * (qd - J_pinv @ (J @ qd)))
    tau = model.dynamic_regressor(q, qd, qd, qdd) @ model.a_d   # M qdd + C qd + g
    zero = EstimatorState(x_dot, np.zeros(model.p_perp), np.zeros(model.p_z),
                          np.zeros(model.p_d))
    return LawOutput(tau, zero, np.zeros(model.n), qd, qdd, J, z, sigma_min, damped, False)


class CalibratedIBVS(AdaptiveVisualTracker):
    """Calibrated image-based visual servoing with computed torque (the upper reference).

    Parameters
    ----------
    config : ControllerConfig
        Used for the trajectory, start blend, torque limit, singular-value damping
        and the safety settings; gains and initial estimates are not used.
    natural_frequency, damping_ratio : float
        Of the image error dynamics: k_p = w^2, k_v = 2 zeta w.
    null_space_damping : float
        k_n [1/s] on the self-motion of a redundant arm.
    """

    compensates_latency = False

    def __init__(self, config, natural_frequency=20.0, damping_ratio=1.0,
                 null_space_damping=10.0):
        w = float(natural_frequency)
        self.ibvs_gains = (w * w, 2.0 * float(damping_ratio) * w, float(null_space_damping))
        super().__init__(config)
        self.projection = None          # nothing is estimated

    def reset(self):
        super().reset()
        m = self.model
        self.state = EstimatorState(np.zeros(2 * m.m), m.a_z_perp.copy(), m.a_z.copy(),
                                    m.a_d.copy())

    def _law(self, t, state, q, qd, x, xd, xd_dot, xd_ddot, tensors, projection, e_int=None):
        return ibvs_law(self.model, q, qd, x, xd, xd_dot, xd_ddot, self.ibvs_gains,
                        self.min_singular_value, tensors)


class FrameHoldingTracker(AdaptiveVisualTracker):
    """The paper's controller without latency compensation (``vas compare``'s reference).

    Each camera frame is taken as current when it arrives and the command is held
    between frames: the controller as it ran once per frame, before the frame
    predictor (``latency_compensation: false``).
    """

    compensates_latency = False
