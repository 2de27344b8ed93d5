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

"""H. Wang's observer-based adaptive visual tracking controller (Automatica 2015).

Two layers:

* :func:`control_law` is the paper's section 3 as one pure function of the
  controller state and the measurements: observer (10), reference velocity and
  acceleration (18)/(19), sliding vector (20), torque (22) and the adaptation
  rates (23)-(25).  It has no memory, so tests can integrate it with any ODE
  scheme and compare against the Lyapunov functions of the proof.
* :class:`AdaptiveVisualTracker` is the sampled controller a robot runs:
  ``step(t, q, qd, x)`` integrates the state over the elapsed time, evaluates
  the law, projects the adaptation (Remark 6), saturates the torque, rejects bad
  samples without touching its state, and falls back safely when input is
  missing or stale.  It never measures image-space velocity.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, field, replace
from math import isfinite, log as ln, sqrt

import numpy as np

from ..models.backend import compile_notice
from ..schema import CONTROLLER_SECTION, ConfigError
from .frame_noise import FrameNoise
from .gain_design import (DESIGNED, design_gains, DesignSettings, positive_definite,
                          sampled_data_margin, typical_image_speed)
from .motion_scale import MotionRatio, MotionScale
from .prediction import FramePredictor
from .reversal import ReversedMotion
from .trajectory import BlendedStart

log = logging.getLogger(__name__)
#: a number in a problem's text (masked when telling two problems apart)
_NUMBER = re.compile(r"\d+(\.\d*)?(e[-+]?\d+)?")
#: a sample's problem before the first frame: logged at INFO (a camera's start), and a
#: warning once it has lasted safety.camera_timeout
WAITING_FOR_CAMERA = "feature x: waiting for the first camera frame"
INF = float("inf")
#: how often the joint positions are checked against the URDF's limits [s of sample time]
LIMIT_CHECK_PERIOD = 0.01
#: the frames' ages (joint sample time - capture time) are checked against camera_latency
#: once, over this many applied frames (:meth:`AdaptiveVisualTracker._check_frame_ages`)
AGE_CHECK_FRAMES = 30
#: the measured noise moves gamma in steps of at least this (in ln gamma)
BANDWIDTH_STEP = 0.01
_NO_PIXELS = np.empty(0)    # x of a sample without a frame, for sample_kernels.inputs_valid


def check_alpha_gamma(alpha, gamma, section=CONTROLLER_SECTION):
    """Theorem 1 needs alpha > gamma / 3; refuse anything else."""
    if not alpha > gamma / 3.0:
        raise ConfigError(f"{section}.alpha: Theorem 1 requires alpha > gamma/3, got "
                          f"alpha={alpha} and gamma={gamma} (gamma/3={gamma / 3.0:.6g})")


@dataclass(frozen=True)
class Leakage:
    """sigma-modification of eqs (23)-(25) toward the initial estimates (not in the paper).

    a_hat_dot = (paper's rate) - sigma (a_hat - a_hat(0)): an estimate the errors no
    longer drive decays back to the initial guess at the rate sigma [1/s], so pixel
    noise cannot make it drift without bound (docs/robust_adaptation.md).
    """

    kinematic: float
    dynamic: float
    a_z_perp0: np.ndarray
    a_z0: np.ndarray
    a_d0: np.ndarray


@dataclass(frozen=True)
class Gains:
    """Gains of eqs (10), (18), (22)-(25); matrices are diagonal, stored as vectors.

    ``D`` (n, n), optional, is a constant symmetric positive definite joint-space
    damping on the sliding vector, tau = -J*^T K J* s - D s + Y_d a_d (see
    :func:`joint_space_law`); None is the paper's law.
    """

    K: np.ndarray
    alpha: float
    gamma: float
    Gamma_d: np.ndarray
    Gamma_z_perp: np.ndarray
    Gamma_z: np.ndarray
    D: np.ndarray | None = None
    leakage: Leakage | None = None

    def __post_init__(self):
        check_alpha_gamma(self.alpha, self.gamma)


@dataclass(frozen=True)
class EstimatorState:
    """What the controller remembers: x_o (2m,), a_z_perp_hat, a_z_hat, a_d_hat."""

    x_obs: np.ndarray
    a_z_perp: np.ndarray
    a_z: np.ndarray
    a_d: np.ndarray

    @classmethod
    def from_flat(cls, flat, ends):
        """The state whose fields are views of the one array ``flat`` (no copy).

        ``flat`` holds x_obs, a_z_perp, a_z, a_d end to end; ``ends`` is where the
        first three end, (2m, 2m + p_perp, 2m + p_perp + p_z).  States and rates
        held this way step and check in one numpy call each (:meth:`advanced`,
        :meth:`is_finite`) instead of one per field; the compiled law writes its
        rates that way (:meth:`AdaptiveVisualTracker._law`).
        """
        i, j, k = ends
        return _frozen(cls, {"x_obs": flat[:i], "a_z_perp": flat[i:j], "a_z": flat[j:k],
                             "a_d": flat[k:], "_flat": (flat, ends)})

    def advanced(self, rates, dt):
        """Forward-Euler step of every state by ``dt`` with ``rates`` (an EstimatorState)."""
        theirs = rates.__dict__.get("_flat")
        if theirs is not None:
            # the same elementwise x + dt x_dot, on the four fields at once (a state that is
            # not flat, after a restart or a clamp, is made flat once)
            mine = self.__dict__.get("_flat")
            flat = (mine[0] if mine is not None else
                    np.concatenate([self.x_obs, self.a_z_perp, self.a_z, self.a_d]))
            return EstimatorState.from_flat(flat + dt * theirs[0], theirs[1])
        return EstimatorState(self.x_obs + dt * rates.x_obs, self.a_z_perp + dt * rates.a_z_perp,
                              self.a_z + dt * rates.a_z, self.a_d + dt * rates.a_d)

    def is_finite(self):
        # one sum: NaN and inf propagate through it, so it is finite exactly when every
        # entry is (short of an overflow past 1.8e308, which counts as not finite); 2-3x
        # cheaper than math.isfinite per entry for the iiwa's 149, far cheaper than np.isfinite
        flat = self.__dict__.get("_flat")
        if flat is not None:
            return isfinite(flat[0].sum())
        return isfinite(sum(self.x_obs.tolist() + self.a_z_perp.tolist()
                            + self.a_z.tolist() + self.a_d.tolist()))


class _LazyFlatState(EstimatorState):
    """An :class:`EstimatorState` of one flat array whose four fields are made when first read.

    What the compiled sample commits (:meth:`AdaptiveVisualTracker._sample_compiled`):
    a 1 kHz node publishes the estimates at a lower rate, so most samples' fields
    are never read.  Equal to :meth:`EstimatorState.from_flat` of the same array.
    """

    def __getattr__(self, name):          # only for names not in the instance's dict
        if name not in ("x_obs", "a_z_perp", "a_z", "a_d"):
            raise AttributeError(name)
        flat, (i, j, k) = self.__dict__["_flat"]
        views = {"x_obs": flat[:i], "a_z_perp": flat[i:j], "a_z": flat[j:k], "a_d": flat[k:]}
        self.__dict__.update(views)
        return views[name]


@dataclass(frozen=True)
class LawOutput:
    """Everything :func:`control_law` computes at one instant."""

    tau: np.ndarray          # (n,) eq (22)
    rates: EstimatorState    # x_o_dot (10), a_d_dot (23), a_z_perp_dot (24), a_z_dot (25)
    s: np.ndarray            # (n,) eq (20)
    qr_dot: np.ndarray       # (n,) eq (18)
    qr_ddot: np.ndarray      # (n,) eq (19)
    J_star: np.ndarray       # (2m, n)
    z_hat: np.ndarray        # (m,)
    sigma_min: float         # smallest singular value of J_star
    damped: bool             # the pseudo-inverse was damped
    projection_active: bool  # a projection changed an adaptation rate
    # (J_perp_hat q_dot, Z_hat_dot, Z_hat) per image coordinate: the rate of the frame
    # prediction (prediction.py), which the observer's model term shares
    model_rate: tuple | None = None


@dataclass(frozen=True)
class Projection:
    """Bounds of Remark 6: boxes on the estimates and a minimum estimated depth.

    The projection removes, from the unconstrained adaptation rate, the parts
    that would leave the set {lo <= a <= hi, z_hat_i(q) >= min_depth}; inside
    the set the rate is unchanged.  :meth:`clamp` returns a state that is back
    in the set after a finite Euler step.
    """

    a_z_perp_min: np.ndarray
    a_z_perp_max: np.ndarray
    a_z_min: np.ndarray
    a_z_max: np.ndarray
    a_d_min: np.ndarray
    a_d_max: np.ndarray
    min_depth: float

    def __post_init__(self):
        # the finite bounds only, as Python floats, with the index of their estimate in
        # interior()'s flat list: the per-sample test is several times cheaper on lists than
        # on arrays of a few elements, and an unbounded estimate needs no test at all
        lo, hi = (np.concatenate([getattr(self, name + side)
                                  for name in ("a_z_perp", "a_z", "a_d")]).astype(float)
                  for side in ("_min", "_max"))
        bounded = np.flatnonzero(np.isfinite(lo) | np.isfinite(hi))
        object.__setattr__(self, "_bounded", (bounded.tolist(), lo[bounded].tolist(),
                                              hi[bounded].tolist()))

    @staticmethod
    def _box(a, rate, lo, hi):
        blocked = ((a <= lo) & (rate < 0.0)) | ((a >= hi) & (rate > 0.0))
        return np.where(blocked, 0.0, rate), bool(blocked.any())

    def dynamic_rate(self, a_d, a_d_dot):
        """Project the dynamic adaptation rate of eq (23) onto the a_d box."""
        return self._box(a_d, a_d_dot, self.a_d_min, self.a_d_max)

    def kinematic_rates(self, state, a_perp_dot, a_z_dot, H, Gamma_z):
        """Project the rates of eqs (24) and (25); returns (a_perp_dot, a_z_dot, active)."""
        rate_z = a_z_dot
        a_perp_dot, act1 = self._box(state.a_z_perp, a_perp_dot, self.a_z_perp_min,
                                     self.a_z_perp_max)
        a_z_dot, act3 = self._box(state.a_z, rate_z, self.a_z_min, self.a_z_max)
        # depth half-spaces h_i . a_z >= min_depth: remove the Gamma-weighted normal
        # component of the rate that points out of an active half-space
        act4 = False
        free = ~(((state.a_z <= self.a_z_min) & (rate_z < 0.0))
                 | ((state.a_z >= self.a_z_max) & (rate_z > 0.0)))
        for h in H:
            if h @ state.a_z <= self.min_depth and h @ a_z_dot < 0.0:
                g = Gamma_z * h * free
                denom = h @ g
                if denom > 0.0:
                    a_z_dot = a_z_dot - g * (h @ a_z_dot) / denom
                    act4 = True
        return a_perp_dot, a_z_dot, act1 or act3 or act4

    def interior(self, state, H):
        """Every estimate strictly inside its bounds and every z_hat_i above min_depth.

        Then :meth:`clamp` changes nothing and no adaptation rate can be projected.
        """
        index, lo, hi = self._bounded
        if index:
            estimates = state.a_z_perp.tolist() + state.a_z.tolist() + state.a_d.tolist()
            if not all(low < estimates[i] < high for i, low, high in zip(index, lo, hi)):
                return False
        return min(H.dot(state.a_z).tolist()) > self.min_depth

    def clamp(self, state, H):
        """Return ``state`` with its estimates put back into the set after a finite step."""
        a_z = np.clip(state.a_z, self.a_z_min, self.a_z_max)
        for h in H:
            deficit = self.min_depth - h @ a_z
            if deficit > 0.0:
                # the depth-offset-like parameters move least in the weighted sense
                a_z = a_z + h * deficit / (h @ h)
        return replace(state, a_z_perp=np.clip(state.a_z_perp, self.a_z_perp_min,
                                               self.a_z_perp_max),
                       a_z=a_z, a_d=np.clip(state.a_d, self.a_d_min, self.a_d_max))


def control_law(model, gains, state, q, qd, x, xd, xd_dot, xd_ddot, projection=None,
                min_singular_value=0.0, tensors=None, integral=None, motion_scale=None,
                reference_scale=None):
    """Evaluate the paper's controller at one instant.

    Parameters
    ----------
    model : RobotCameraModel
        Structure only; its true parameters are never read here.
    gains : Gains
    state : EstimatorState
    q, qd : (n,) joint positions [rad] and velocities [rad/s]
    x : (2m,) measured feature pixels
    xd, xd_dot, xd_ddot : (2m,) desired pixels and their derivatives
    projection : Projection or None
        Applied to the adaptation rates before they enter the total derivatives
        of eq (19), so q_ddot_r stays the exact derivative of q_dot_r.
    min_singular_value : float
        Below this smallest singular value of J*, use a damped pseudo-inverse.
    tensors : tuple, optional
        ``model.kinematic_tensors(q, qd)`` if the caller has computed it already.
    integral : (kappa, e_int) or None
        The reference's integral action (docs/robust_adaptation.md, not in the
        paper): x_r_dot = x_d_dot - gamma (x_o - x_d) - kappa e_int with
        e_int_dot = x_o - x_d; None is the paper's eq (18).
    motion_scale : (s, s_dot) or None
        The image-motion scale of :mod:`.motion_scale` (docs/robust_adaptation.md, not in
        the paper) and its rate: the observer's model term of eq (10) is s times the
        paper's, and eq (18) maps x_r_dot / s (eq (19) its exact derivative); None is
        the paper's law.
    reference_scale : (r, r_dot) or None
        What eq (18) maps x_r_dot with instead of s (eq (19) its exact derivative):
        s phi of the motion scale's slow start (:attr:`.motion_scale.MotionScale.reference`);
        None: ``motion_scale``.

    Returns
    -------
    LawOutput

    Notes
    -----
    All arrays here have a few elements, so each numpy call costs far more
    than its arithmetic; the code is arranged to need few of them:
    ``a.dot(b)`` instead of ``a @ b`` (3x cheaper on tiny arrays), the
    estimated Jacobian kept as its two parts ``J_z_perp`` and ``U J_z`` of
    eq (a1), and the regressors Y_z of eq (25) contracted without being formed.
    """
    if tensors is None:
        tensors = model.kinematic_tensors(q, qd)
    _, _, dH_rate, W, W_rate = tensors
    H2, dH2, H2_rate, Zh, Zh_rate, J_perp, J_z = estimated_kinematics(tensors, qd, state)

    x_obs = state.x_obs
    e_obs = x_obs - xd                                # x_o - x_d
    dx_obs = x_obs - x                                # Delta x_o
    dx = x - xd                                       # Delta x
    u = 0.5 * (x_obs + xd)                            # where J* is evaluated, eq (18)
    x_mid = dx + u                                    # x + (x_o - x_d)/2
    # eq (10): the observer, x_o_dot = x_obs_model - alpha Delta x_o with
    # x_obs_model = Z^-1 (J_hat(q, x) q_dot - 1/2 Z_dot (x_o - x_d)), where
    # J_hat(q, x) q_dot = J_perp q_dot - X hat{Z_dot} since J_z_hat q_dot = hat{Z_dot}
    jq = J_perp.dot(qd)
    x_obs_model = (jq - Zh_rate * x_mid) / Zh
    if motion_scale is not None:
        scale, scale_dot = motion_scale
        x_obs_model = scale * x_obs_model
    x_obs_dot = x_obs_model - gains.alpha * dx_obs
    x_r_dot = xd_dot - gains.gamma * e_obs
    x_r_ddot = xd_ddot - gains.gamma * (x_obs_dot - xd_dot)
    if integral is not None:
        kappa, e_int = integral
        x_r_dot = x_r_dot - kappa * e_int
        x_r_ddot = x_r_ddot - kappa * e_obs

    # eq (24)
    a_perp_dot = gains.Gamma_z_perp * (dx - dx_obs).dot(qd.dot(W))  # Y_z_perp = qd . W
    # eq (25): -Gamma_z (Y_z**^T Delta x - Y_z*^T Delta x_o) with
    #   Y_z*  = Y_z(q, Z^-1 J q_dot - 1/2 Z^-1 Z_dot e_obs) + Y_z_bar(q, q_dot, x + e_obs/2)
    #         = Y_z(q, x_obs_model) + Y_z_bar(q, q_dot, x_mid)
    #   Y_z** = Y_z_bar(q, q_dot, (x_o + x_d)/2) + Y_z(q, x_r_dot)
    #         = Y_z_bar(q, q_dot, u) + Y_z(q, x_r_dot)
    # Y_z(H, psi)^T v = H^T (psi_i . v_i)_i, i.e. (psi * v) against H with its rows
    # repeated per coordinate, so neither regressor is formed.
    w_H = x_obs_model * dx_obs - x_r_dot * dx
    w_H_rate = x_mid * dx_obs - u * dx
    a_z_dot = gains.Gamma_z * (w_H.dot(H2) + w_H_rate.dot(H2_rate))
    leak = gains.leakage
    if leak is not None and leak.kinematic > 0.0:
        a_perp_dot = a_perp_dot - leak.kinematic * (state.a_z_perp - leak.a_z_perp0)
        a_z_dot = a_z_dot - leak.kinematic * (state.a_z - leak.a_z0)

    u_dot = 0.5 * (x_obs_dot + xd_dot)
    if reference_scale is None:
        reference_scale = motion_scale
    if reference_scale is not None:
        # the joints move 1/r as fast for the same reference: d/dt (x_r_dot / r)
        r, r_dot = reference_scale
        x_r_ddot = x_r_ddot / r - (r_dot / r**2) * x_r_dot
        x_r_dot = x_r_dot / r
    return joint_space_law(model, gains, state, q, qd, (H2, dH2, dH_rate, W, W_rate),
                           (J_perp, J_z), (Zh, Zh_rate), (u, u_dot, x_r_dot, x_r_ddot),
                           (x_obs_dot, a_perp_dot, a_z_dot), projection, min_singular_value,
                           (jq, Zh_rate, Zh))


def estimated_kinematics(tensors, qd, state):
    """Per-coordinate depth quantities and the two parts of J_hat from the model tensors.

    The depth tensors get each point's rows repeated for its two image
    coordinates, so depths, their rates and J_z come out per coordinate.
    Returns ``(H2, dH2, H2_rate, Zh, Zh_rate, J_perp, J_z)``: (2m, p_z),
    (2m, n, p_z), (2m, p_z), hat{Z} (2m,), its model rate hat{Z_dot} (2m,), and
    J_perp, J_z (2m, n) of eq (a1), J_hat(q, u) = J_perp - U J_z.
    """
    H, dH, _, W, _ = tensors
    H2, dH2 = H.repeat(2, axis=0), dH.repeat(2, axis=0)
    H2_rate = qd.dot(dH2)                             # d/dt H along q_dot
    return (H2, dH2, H2_rate, H2.dot(state.a_z), H2_rate.dot(state.a_z),
            W.dot(state.a_z_perp), dH2.dot(state.a_z))


def joint_space_law(model, gains, state, q, qd, tensors, jacobian, depth, references,
                    image_rates, projection, min_singular_value, model_rate=None):
    """Eqs (18)-(23) from the image-space references: the second half of :func:`control_law`.

    Shared with the velocity-based baseline, which feeds it measured instead of
    observed image quantities.

    Parameters
    ----------
    tensors : tuple
        ``(H2, dH2, dH_rate, W, W_rate)``: ``model.kinematic_tensors(q, qd)`` with the
        rows of H and dH repeated per image coordinate, (2m, p_z) and (2m, n, p_z).
    jacobian : (J_perp, J_z)
        The two parts of J_hat of eq (a1), (2m, n) each (rows of J_z per coordinate).
    depth : (Zh, Zh_rate)
        Estimated depths and their model rate per image coordinate, (2m,) each.
    references : (u, u_dot, x_r_dot, x_r_ddot)
        Where J* is evaluated and its rate, and the image reference velocity and
        acceleration, (2m,) each.
    image_rates : (x_obs_dot, a_perp_dot, a_z_dot)
        Observer rate (passed through) and the unprojected rates of eqs (24), (25).
    model_rate : tuple, optional
        Passed through to :attr:`LawOutput.model_rate`.

    Returns
    -------
    LawOutput
    """
    H2, dH2, dH_rate, W, W_rate = tensors
    J_perp, J_z = jacobian
    Zh, Zh_rate = depth
    u, u_dot, x_r_dot, x_r_ddot = references
    x_obs_dot, a_perp_dot, a_z_dot = image_rates
    a_z_perp, a_z = state.a_z_perp, state.a_z
    projection_active = False
    if projection is not None:
        a_perp_dot, a_z_dot, projection_active = projection.kinematic_rates(
            state, a_perp_dot, a_z_dot, H2[::2], gains.Gamma_z)

    # eq (18): J* = J_hat(q, u) and its TOTAL time derivative, through q_dot (the
    # *_rate tensors), the adaptation rates and u_dot
    u_col = u[:, None]
    J_star = J_perp - u_col * J_z
    J_z_dot = dH_rate.repeat(2, axis=0).dot(a_z) + dH2.dot(a_z_dot)
    J_star_dot = (W_rate.dot(a_z_perp) + W.dot(a_perp_dot)
                  - u_dot[:, None] * J_z - u_col * J_z_dot)
    Zh_dot_total = Zh_rate + H2.dot(a_z_dot)

    G_inv, sigma_min, damped = _damped_gram_inverse(J_star.dot(J_star.T), min_singular_value)
    y = G_inv.dot(Zh * x_r_dot)
    qr_dot = y.dot(J_star)                            # eq (18): J*^T (J* J*^T)^-1 Zh x_r_dot
    # eq (19), with J*^{+T} qr_dot = (J* J*^T)^{-1} Zh x_r_dot = y
    v = y.dot(J_star_dot)                             # J*_dot^T y
    b = Zh * x_r_ddot + Zh_dot_total * x_r_dot - J_star_dot.dot(qr_dot)
    qr_ddot = v + G_inv.dot(b - J_star.dot(v)).dot(J_star)

    s = qd - qr_dot                                   # eq (20)
    Y_d = model.dynamic_regressor(q, qd, qr_dot, qr_ddot)
    tau = Y_d.dot(state.a_d) - (gains.K * J_star.dot(s)).dot(J_star)  # eq (22)
    if gains.D is not None:
        # joint-space damping of s: V1_dot = -s^T (J*^T K J* + D) s <= -s^T J*^T K J* s, so
        # Theorem 1's argument is unchanged; it lets a light joint (a wrist) get the damping
        # the image-space K cannot give it without destabilising the heavy ones
        tau = tau - gains.D.dot(s)
    a_d_dot = gains.Gamma_d * (qr_dot - qd).dot(Y_d)  # eq (23): -Gamma_d Y_d^T s
    if gains.leakage is not None and gains.leakage.dynamic > 0.0:
        a_d_dot = a_d_dot - gains.leakage.dynamic * (state.a_d - gains.leakage.a_d0)
    if projection is not None:
        a_d_dot, active_d = projection.dynamic_rate(state.a_d, a_d_dot)
        projection_active = projection_active or active_d
    rates = EstimatorState(x_obs_dot, a_perp_dot, a_z_dot, a_d_dot)
    return LawOutput(tau, rates, s, qr_dot, qr_ddot, J_star, Zh[::2], sigma_min, damped,
                     projection_active, model_rate)


def _law_output(raw):
    """LawOutput of :func:`.law_kernels.law`'s outputs (the compiled :func:`control_law`)."""
    (tau, x_obs_dot, a_perp_dot, a_z_dot, a_d_dot, s, qr_dot, qr_ddot, J_star, z_hat, rate,
     sigma_min, damped, active) = raw
    return LawOutput(tau, EstimatorState(x_obs_dot, a_perp_dot, a_z_dot, a_d_dot), s, qr_dot,
                     qr_ddot, J_star, z_hat, sigma_min, damped, active, rate)


def _flat_law_output(kernel, out, sigma_min, damped, active):
    """LawOutput of :meth:`.law_kernels.CompiledLaw.evaluate`: views of its one array ``out``.

    The rates are one flat state (:meth:`EstimatorState.from_flat`), so the next
    sample's Euler step and this one's finiteness check are one numpy call each.
    """
    return _frozen(_FlatLawOutput, {
        "tau": out[kernel._slices[0]],
        "rates": EstimatorState.from_flat(out[kernel.rates], kernel.state_ends),
        "z_hat": out[kernel._z_hat], "sigma_min": sigma_min, "damped": damped,
        "projection_active": active, "model_rate": out[kernel._rate].reshape(3, 2 * kernel.m),
        "_source": (kernel, out)})


class _FlatLawOutput(LawOutput):
    """A :class:`LawOutput` whose s, qr_dot, qr_ddot and J_star are made when first read.

    :meth:`AdaptiveVisualTracker._sample` reads none of them; each is a view of
    the kernel's output array (``_source``), as the other fields are.
    """

    def __getattr__(self, name):          # only for names not in the instance's dict
        if name not in ("s", "qr_dot", "qr_ddot", "J_star"):
            raise AttributeError(name)
        kernel, out = self.__dict__["_source"]
        if name == "J_star":
            value = out[kernel._J_star].reshape(2 * kernel.m, kernel.n)
        else:
            value = out[kernel._slices[("s", "qr_dot", "qr_ddot").index(name) + 5]]
        object.__setattr__(self, name, value)
        return value


def _frozen(cls, values):
    """The frozen dataclass ``cls`` with the field ``values`` (a dict of every field).

    The generated __init__ of a frozen dataclass sets each field with
    object.__setattr__ (~0.13 µs a field: 2 µs for a StepResult); the hot path
    sets the instance's dict at once instead.  Equal to ``cls(**values)``.
    """
    obj = object.__new__(cls)
    object.__setattr__(obj, "__dict__", values)
    return obj


def _damped_gram_inverse(G, min_singular_value):
    """((J* J*^T) + lam^2 I)^-1, sigma_min(J*) and whether lam > 0, from G = J* J*^T.

    lam^2 = min_singular_value^2 - sigma_min^2 when sigma_min is below
    ``min_singular_value`` (damped least squares, Nakamura: the damping grows
    as sigma_min -> 0), else 0.  A 2x2 G (m = 1) is done in closed form.
    """
    m2 = G.shape[0]
    if m2 == 2:
        (a, b), (_, d) = G.tolist()
        eig_min = 0.5 * (a + d) - sqrt(max(0.25 * (a - d) ** 2 + b * b, 0.0))
    else:
        eig_min = np.linalg.eigvalsh(G)[0]
    sigma_min = sqrt(max(eig_min, 0.0))
    damped = sigma_min < min_singular_value
    lam2 = min_singular_value**2 - sigma_min**2 if damped else 0.0
    if m2 != 2:
        return np.linalg.inv(G + lam2 * np.eye(m2) if damped else G), sigma_min, damped
    a, d = a + lam2, d + lam2
    det = a * d - b * b
    if det == 0.0:
        raise np.linalg.LinAlgError("Singular matrix")
    return np.array([[d / det, -b / det], [-b / det, a / det]]), sigma_min, damped


@dataclass(frozen=True)
class StepResult:
    """One sample of the sampled controller (what the node publishes)."""

    t: float
    tau: np.ndarray             # command sent (after saturation / fallback)
    x_d: np.ndarray
    x_obs: np.ndarray
    error: np.ndarray           # x - x_d (NaN when x was rejected)
    z_hat: np.ndarray
    state: EstimatorState
    status: str                 # "ok", "hold", "fallback"
    problems: tuple = ()        # human-readable reasons a sample was rejected
    saturated: bool = False
    projection_active: bool = False
    damped: bool = False
    sigma_min: float = float("nan")
    tau_unsaturated: np.ndarray | None = None
    flags: dict = field(default_factory=dict)
    motion_scale: float = 1.0   # s of motion_scale.* (1: off, or not learnt yet)
    gamma: float = float("nan")  # gamma of eq (18) in effect (gain_design.follow_noise)


@dataclass(frozen=True)
class StartReport:
    """What :meth:`AdaptiveVisualTracker.start_report` found at the start pose."""

    n: int
    m: int
    p_perp: int
    p_z: int
    p_d: int
    gains: dict                 # the gains in effect
    derived: tuple              # the names of those derived at the start (gain_design.py)
    sigma_min: float            # of the estimated J(q0, x_d(0)) [px m/rad]
    sigma_max: float
    z_hat: np.ndarray           # estimated depths at q0 [m]
    margin: float               # largest eigenvalue of T M_hat^-1 B
    margin_joint: np.ndarray    # T B_jj / M_hat_jj per joint
    joint_names: tuple
    departures: tuple = ()      # the options on that depart from the paper, as "name value"
    torque_limit: tuple = ()    # |tau| limit per joint in effect [N m] (inf: none)
    torque_limit_source: str = "given"  # "given", "urdf" (<limit effort>) or "none"
    prismatic: tuple = ()       # per joint: True where it slides (its limit is in N)
    blend_speed: float = 0.0    # fastest image motion of a blend [px/s] (0: no limit)
    blend_ratio: float = 0.0    # start_blend_speed
    blend_least: float = 0.0    # start_blend_time [s]

    def lines(self):
        """The report as text lines."""
        def describe(value):
            arr = np.atleast_1d(np.asarray(value, dtype=float))
            if arr.size == 1 or np.all(arr == arr[0]):
                return f"{arr[0]:.4g}" + (f" (x{arr.size})" if arr.size > 1 else "")
            return f"{arr.min():.3g}..{arr.max():.3g} ({arr.size} entries)"
        out = [f"n = {self.n} joints, m = {self.m} points; parameters: a_z_perp {self.p_perp}, "
               f"a_z {self.p_z}, a_d {self.p_d}"]
        for name, value in self.gains.items():
            source = "derived" if name in self.derived else "given"
            out.append(f"{name} = {describe(value)} ({source})")
        out.append(f"estimated J(q0, x_d(0)): sigma_min {self.sigma_min:.4g}, sigma_max "
                   f"{self.sigma_max:.4g} px m/rad")
        out.append("estimated depths: " + ", ".join(f"{z:.3f}" for z in self.z_hat.tolist())
                   + " m")
        if np.isfinite(self.margin):
            per_joint = zip(self.joint_names, self.margin_joint.tolist())
            out.append(f"sampled-data step (T M_hat^-1 B): {self.margin:.3g}; per joint "
                       + ", ".join(f"{name} {rho:.3g}" for name, rho in per_joint))
        else:
            out.append("sampled-data step (T M_hat^-1 B): not checked, the initial estimate's "
                       "inertia M_hat is not positive definite (initial_estimate.a_d gives the "
                       "arm no mass)")
        if self.torque_limit:
            limits = np.asarray(self.torque_limit, dtype=float)
            if not np.any(np.isfinite(limits)):
                out.append("torque limit: none (no torque_limit, and the URDF gives no <limit "
                           "effort>): the command is never saturated")
            else:
                source = {"urdf": "the URDF's <limit effort>, as torque_limit is not given",
                          "given": "torque_limit"}.get(self.torque_limit_source,
                                                       self.torque_limit_source)
                units = self.prismatic or (False,) * len(self.joint_names)
                out.append("torque limit: " + ", ".join(
                    f"{name} {lim:g} {'N' if slides else 'N m'}" for name, lim, slides
                    in zip(self.joint_names, limits.tolist(), units)) + f" ({source})")
        if self.blend_speed > 0.0:
            out.append(f"start blend: x_d moves at most {self.blend_speed:.3g} px/s while it is "
                       f"blended in (start_blend_speed {self.blend_ratio:g} x its RMS image "
                       f"speed, each coordinate's at least gamma x 1 px): a start d px off "
                       f"takes max({self.blend_least:g} s, "
                       f"1.875 d / {self.blend_speed:.3g} px/s)")
        out.append("departures from the paper (docs/robust_adaptation.md): "
                   + (", ".join(self.departures) if self.departures else "none"))
        return out


#: the numeric options that depart from the paper when > 0 (docs/robust_adaptation.md)
DEPARTURES = ("joint_damping.inertia_rate", "joint_damping.integral_rate",
              "reference.integral_rate",
              "robust.leakage_kinematic", "robust.leakage_dynamic")


def joint_labels(model):
    """(names, prismatic) per joint of ``model``: "joint1".. and revolute where it says none."""
    names = getattr(model, "joint_names", None) or tuple(f"joint{i + 1}" for i in range(model.n))
    return tuple(names), tuple(getattr(model, "prismatic", None) or (False,) * model.n)


class InputError(ValueError):
    """A measurement was refused; the message names the input and the problem."""


def validate_vector(name, value, size):
    """Return ``value`` as a finite float64 vector of ``size`` or raise InputError."""
    if value is None:
        raise InputError(f"{name}: missing")
    arr = np.asarray(value, dtype=float)
    if arr.shape != (size,):
        raise InputError(f"{name}: expected {size} values, got shape {arr.shape}")
    if not (arr.flags.c_contiguous and arr.flags.writeable):
        # a strided or read-only array (a view, a message's buffer) would make the compiled
        # kernels compile another specialisation, for seconds, in the control loop
        arr = np.array(arr)
    if not _all_finite(arr.tolist()):
        raise InputError(f"{name}: contains NaN or inf: {arr.tolist()}")
    return arr


def _all_finite(values):
    """Every float of the list ``values`` finite.

    One sum first (NaN and inf propagate through it; 3x cheaper than isfinite per
    entry), entry by entry only when that sum is not finite: finite entries whose
    sum overflows still pass.
    """
    return isfinite(sum(values)) or all(map(isfinite, values))


class AdaptiveVisualTracker:
    """The sampled controller: ``step(t, q, qd, x, x_stamp)`` -> :class:`StepResult`.

    It runs at every joint sample; a camera frame (pixels x captured at x_stamp)
    may come with it or not.  With ``latency_compensation`` (the default) the law
    sees x_hat, the latest frame re-predicted to the sample time from the joint
    measurements (:mod:`.prediction`); without it, a frame is taken as current
    when it arrives and samples without a frame hold the last command (the
    behaviour of a controller that runs once per camera frame).

    Integration: the state (x_o and the estimates) is advanced by forward Euler
    over the time since the last accepted sample, using the rates computed there;
    the interval is clamped to ``max_dt`` so a long gap cannot make one huge step.

    Start: x_o(0) = x(0); the offset x(0) - x_d(0) is blended out over
    ``start_blend_time`` (:class:`~.trajectory.BlendedStart`), so the start is
    smooth from anywhere and unchanged when it is on the trajectory; longer when
    the offset is large, so that the blend never asks for image motion faster
    than ``start_blend_speed`` x the RMS image speed of x_d, the motion the
    derived gains assume (:mod:`.gain_design`).

    Bad input (missing, NaN/inf, wrong size, outside the image, time going
    backwards) rejects the sample: nothing is committed; the last valid command
    is held for ``safety.hold_time``, then the fallback applies
    (``gravity_compensation``: tau = g_hat(q) - D q_dot with the current
    estimate a_d_hat, or ``zero_torque``; with an invalid joint state, zero
    torque).  When the camera has been stale for ``safety.camera_timeout`` and
    comes back, the observer restarts at the measured x and x_d is blended in
    again from there (the offset blended out over ``safety.recovery_blend_time``),
    so recovery has no jump.
    """

    #: the baselines have no model-based predictor and take frames as current
    compensates_latency = True

    def __init__(self, config):
        self.config = config
        self.model = config.model
        self.trajectory = config.trajectory
        self.designed = {}          # gains derived at the first joint sample (gain_design.py)
        self._derived_floor = 0.0   # min_singular_value derived there (when the file has none)
        self.gains = None           # complete once every gain is known (see reset)
        self.damping = None         # D of the joint-space damping, fixed at the first sample
        self.fallback_bound = None  # the fallback's damping per joint, stable with D
        self._fallback_inputs = None    # (M_hat, D, T) it was bounded with
        self._fallback_for = None       # the safety.fallback_damping it was bounded for
        self.report = None          # the start-up report (start_report), at the first sample
        self.compensate = bool(config["latency_compensation"]) and self.compensates_latency
        self._law_backend = self._law_kernel = None     # _compiled_law
        self._fast = None           # the compiled sample (sample_kernels.py), with the law
        self._fast_layout = None    # the CompiledSample that wrote _fast_prev
        self._bounds_of = self._bounds = None   # _image_bounds: its configuration, its values
        self._inputs_valid = None   # sample_kernels.inputs_valid with the compiled backend
        self.predictor = FramePredictor(config["max_frame_age"], config["frame_gain"],
                                        config["drift_gain"])
        # the fastest image motion a blend may ask for [px/s]: start_blend_speed x the RMS
        # speed of x_d that the derived adaptation gains are normalised for (0: no limit)
        ratio = config["start_blend_speed"]
        self.blend_speed = (ratio * float(np.linalg.norm(typical_image_speed(
            self.trajectory, 2 * self.model.m, config["gamma"]))) if ratio > 0.0 else 0.0)
        # the URDF's joint position limits, (n, 2), None when it gives none: the law does not
        # keep the arm inside them, so a joint past one is reported (_check_position_limits)
        limits = np.asarray(getattr(self.model, "position_limits", ()), dtype=float)
        self.position_limits = (limits if limits.size and np.isfinite(limits).any() else None)
        self.scale = (MotionScale(config["motion_scale.window"], config["motion_scale.rate"],
                                  config["motion_scale.lower"], config["motion_scale.upper"],
                                  config["motion_scale.min_motion"], config["max_frame_age"],
                                  config["motion_scale.initial"],
                                  config["motion_scale.start_factor"])
                      if config["motion_scale.enabled"] and self.compensate else None)
        # how far a_z_perp is off relative to a_z, from the frames (motion_scale.ratio_rate)
        self.ratio = (MotionRatio(config["motion_scale.window"], config["motion_scale.ratio_rate"],
                                  config["motion_scale.lower"], config["motion_scale.upper"],
                                  config["motion_scale.min_motion"], config["max_frame_age"],
                                  config["motion_scale.ratio_condition"],
                                  config["motion_scale.ratio_band"],
                                  config["motion_scale.ratio_evidence"],
                                  config["motion_scale.ratio_significance"])
                      if self.scale is not None and config["motion_scale.ratio_rate"] > 0.0
                      else None)
        # the frames' motion against the model's (a mirrored guess, or a ratio far off): said
        self.reversal = (ReversedMotion(config["motion_scale.window"],
                                        config["reversed_motion"])
                         if self.scale is not None and config["reversed_motion"] > 0.0
                         else None)
        # the pixel noise and tracking error measured in the frames, and the factor of the
        # derived gamma they ask for (gain_design.follow_noise): only when gamma is derived
        self.noise = (FrameNoise(config["gain_design.noise_window"],
                                 config["gain_design.noise_min_factor"], config["gamma"],
                                 config["alpha"], config["reference.integral_rate"])
                      if self.compensate and config["gain_design.follow_noise"]
                      and "gamma" not in config.explicit else None)
        self.projection = (Projection(config["projection.a_z_perp_min"],
                                      config["projection.a_z_perp_max"],
                                      config["projection.a_z_min"], config["projection.a_z_max"],
                                      config["projection.a_d_min"], config["projection.a_d_max"],
                                      config["projection.min_depth"])
                           if config["projection.enabled"] else None)
        self.reset()
        self._compiled_law()        # compile (or load) the kernel now, not at the first sample

    def reset(self):
        """Forget everything: the next valid sample starts the controller."""
        c = self.config
        m2, p_perp, p_z = 2 * self.model.m, self.model.p_perp, self.model.p_z
        self.state = EstimatorState.from_flat(
            np.concatenate([np.zeros(m2), np.ravel(c.a_z_perp_init), np.ravel(c.a_z_init),
                            np.ravel(c.a_d_init)]).astype(float),
            (m2, m2 + p_perp, m2 + p_perp + p_z))
        # the last accepted sample's array when the compiled sample wrote it, else None (then
        # rates, e_int and x_d of that sample are read from it: see the properties below)
        self._fast_prev = None
        self.rates = None
        self.e_int = np.zeros(2 * self.model.m)   # integral of x_o - x_d (reference.integral)
        # the joint integral: int s dt (joint_damping.integral_rate) and the s it integrates
        # next (the last sample's, 0 when that sample saturated: no wind-up)
        self.joint_int = np.zeros(self.model.n)
        self._s_int = np.zeros(self.model.n)
        self._xd_last = None
        self._fast_sample = None    # (array, layout) of this sample's compiled sample, if any
        self.desired = None
        self.t_last = None          # time of the last accepted sample
        self.t_last_feature = None  # time of the last valid feature
        self.last_tau = np.zeros(self.model.n)
        self.t_last_tau = None
        self.stale = False
        # (t, text) of the reversed-motion check's first verdict, None before any
        self.reversed_motion = None
        if getattr(self, "reversal", None) is not None:
            self.reversal.reset()
        self._rejecting = ()        # kinds of problem of the current rejection streak
        self._waiting_since = None  # its start, while it waits for the first frame unwarned
        self.damping = self.fallback_bound = None
        # complete before the first sample when the configuration gives every gain (D comes
        # at the first sample); otherwise once the missing ones are derived there
        self.designed = {}
        if self.ratio is not None:
            self.ratio.reset()          # (before the gains: their leakage target follows it)
        self.bandwidth_factor = 1.0     # of the derived gamma in effect (follow_noise)
        self._noise_pending = None      # (stamp, innovation, frame) measured at the next sample
        if self.noise is not None:
            self.noise.reset()
        self.gains = (self._gains(np.zeros((self.model.n, self.model.n)))
                      if all(c[name] is not None for name in DESIGNED) else None)
        self._model_rate = None
        self.predictor.reset()
        if self.scale is not None:
            self.scale.reset()
        self.frames = {"received": 0, "applied": 0, "late": 0, "rejected": 0, "age_sum": 0.0,
                       "age_max": 0.0, "last_age": float("nan")}
        self.outside_limits = set()    # joints past a URDF position limit at the last check
        self.limit_excursions = 0      # times a joint went past one
        self._limit_next = -INF        # sample time of the next check

    def update_gains(self, **changes):
        """Replace gains (K, Gamma_*) or safety settings atomically; validated first."""
        new_config = self.config.with_changes(**changes)
        self.config = new_config
        if self.gains is not None:
            self.gains = self._gains(self.damping if self.damping is not None
                                     else np.zeros((self.model.n, self.model.n)))

    def desired_at(self, t):
        if self.desired is None:
            return self.trajectory(t)
        return self.desired(t)

    # -- the sample -------------------------------------------------------------
    def _image_bounds(self):
        """(u_min, u_max, v_min, v_max) as floats, and the limits of ``inputs_valid``.

        Computed once per configuration: ((bounds), (limits with a frame, without)).
        """
        config = self.config
        if self._bounds_of is not config:
            bounds = config["image_bounds"].tolist()
            n, m2 = self.model.n, 2 * self.model.m
            self._bounds_of = config
            self._bounds = bounds, (np.array([n, m2, *bounds]), np.array([n, 0.0, *bounds]))
        return self._bounds

    def _check_feature(self, x):
        x = validate_vector("feature x", x, 2 * self.model.m)
        u0, u1, v0, v1 = self._image_bounds()[0]
        pixels = x.tolist()
        us, vs = pixels[0::2], pixels[1::2]
        if u0 <= min(us) and max(us) <= u1 and v0 <= min(vs) and max(vs) <= v1:
            return x                # (x is finite here) every point inside: no list to make
        outside = [i + 1 for i, (u, v) in enumerate(zip(us, vs))    # counted from 1
                   if not (u0 <= u <= u1 and v0 <= v <= v1)]
        if outside:
            raise InputError(f"feature x: point(s) {outside} outside the "
                             f"image bounds {self.config.image_bounds.tolist()}: {pixels}")
        return x

    def step(self, t, q, qd, x=None, x_stamp=None):
        """Process one joint sample and the camera frame that came with it, if any.

        Parameters
        ----------
        t : float
            Time of the joint sample [s].
        q, qd : (n,)
            Joint positions and velocities at t.
        x : (2m,) or None
            Pixels of the camera frame that arrived with this sample (None: none did).
        x_stamp : float, optional
            The frame's stamp: its capture time plus ``camera_stamp_delay`` (default t:
            captured now).

        Never raises on bad measurements (see the class docstring).
        """
        checked = self._inputs_checked(t, q, qd, x)
        if not checked:
            n = self.model.n
            try:
                t = float(t)
                if not isfinite(t):
                    raise InputError("time: not finite")
                if self.t_last is not None and t <= self.t_last:
                    raise InputError(f"time: {t} is not after the last sample {self.t_last}")
            except (InputError, TypeError, ValueError) as exc:
                return self._reject(self.t_last or 0.0, None, None, [str(exc)])
            try:
                q = validate_vector("joint positions q", q, n)
                qd = validate_vector("joint velocities qd", qd, n)
            except InputError as exc:
                return self._reject(t, None, None, [str(exc)])
            if self.damping is None:
                try:
                    self._design(q)
                except (ConfigError, np.linalg.LinAlgError) as exc:
                    return self._reject(t, q, qd, [f"start: {exc}"])
        if self.position_limits is not None and t + 1e-9 >= self._limit_next:
            self._limit_next = t + LIMIT_CHECK_PERIOD
            self._check_position_limits(t, q)
        problems, frame, stamp = [], None, t
        if x is None and not self.compensate:
            problems.append("feature x: missing")
        elif x is not None:
            self.frames["received"] += 1
            try:
                frame = x if checked else self._check_feature(x)
                stamp = t if x_stamp is None else (float(x_stamp)
                                                   - self.config["camera_stamp_delay"])
                if not isfinite(stamp):
                    raise InputError("frame: stamp not finite")
                if self.compensate:
                    why = self.predictor.check_stamp(stamp, t)
                    if why is not None:
                        raise InputError(f"frame: {why}")
            except (InputError, TypeError, ValueError) as exc:
                self.frames["rejected"] += 1
                problems.append(str(exc))
                frame = None
        if self.compensate:
            return self._step_predicted(t, q, qd, frame, stamp, problems)
        if frame is None:
            self._check_stale(t)
            return self._reject(t, q, qd, problems)
        self._count_frame(t, stamp)
        return self._sample(t, q, qd, frame, None, True)

    def _inputs_checked(self, t, q, qd, x):
        """Whether t, q, q_dot and x pass every input check of :meth:`step`, in one compiled call.

        Only once the compiled sample runs (the start, with its design, is done) and
        for inputs exactly as the checks would pass them on: t a float after the last
        sample, the vectors C-contiguous writable float64 (:func:`.sample_kernels.inputs_valid`).
        False is no verdict: :meth:`step` then checks them one by one, and names what
        is wrong.
        """
        if self._fast_prev is None or self._inputs_valid is None:
            return False
        if type(t) is not float or not self.t_last < t < INF:
            return False
        with_frame, without = self._image_bounds()[1]
        try:
            if x is None:
                return self._inputs_valid(q, qd, _NO_PIXELS, without)
            return self._inputs_valid(q, qd, x, with_frame)
        except TypeError:           # not C-contiguous writable float64 vectors
            return False

    def _check_position_limits(self, t, q):
        """Warn once per excursion when a joint is past its URDF position limit.

        Nothing in eqs (18)-(22) keeps the arm inside its joint limits: a trajectory the
        arm can only follow past one drives the joint there, where a real arm stops at
        its end stop and the law winds up against it.  Checked every
        ``LIMIT_CHECK_PERIOD`` of sample time (not at every sample: a 1 kHz loop's cost).
        """
        lower, upper = self.position_limits[:, 0], self.position_limits[:, 1]
        for i, value in enumerate(np.asarray(q, dtype=float).tolist()):
            side = ("lower" if value < lower[i] else "upper" if value > upper[i] else None)
            if side is None:
                self.outside_limits.discard(i)
            elif i not in self.outside_limits:
                self.outside_limits.add(i)
                self.limit_excursions += 1
                names, slides = joint_labels(self.model)     # (only for the warning)
                unit = "m" if slides[i] else "rad"
                log.warning("joint %s at %.4g %s is past its URDF %s limit %.4g %s (t=%.3f): "
                            "the controller does not keep the arm inside its joint limits; "
                            "keep the trajectory within the arm's reach", names[i], value, unit,
                            side, lower[i] if side == "lower" else upper[i], unit, t)

    def _check_stale(self, t):
        """Mark the camera stale when no frame was applied for ``safety.camera_timeout``."""
        if (self.t_last_feature is None
                or t - self.t_last_feature >= self.config["safety.camera_timeout"]):
            if not self.stale and self.t_last_feature is not None:
                log.warning("camera stale: no valid frame for %.3f s", t - self.t_last_feature)
            self.stale = self.t_last_feature is not None
        return self.stale

    def _count_frame(self, t, stamp):
        age = t - stamp
        frames = self.frames
        frames["applied"] += 1
        frames["late"] += age > 1e-9
        frames["age_sum"] += age
        if age > frames["age_max"]:
            frames["age_max"] = age
        frames["last_age"] = age
        if frames["applied"] == AGE_CHECK_FRAMES and self.compensate:
            self._check_frame_ages(frames["age_sum"] / AGE_CHECK_FRAMES)

    def _check_frame_ages(self, mean):
        """Warn when the frames' mean age says camera_latency or their stamps are wrong.

        A frame is applied at a joint sample, its age measured from the capture time its
        stamp gives (less ``camera_stamp_delay``).  Far below ``camera_latency`` (under a
        quarter of it): most likely a driver that stamps frames when it receives them, so
        each frame is applied as if just captured and the arm runs that far behind the
        trajectory (docs/latency.md).  Far above it (twice it and 10 ms more): the derived
        gains assume a faster camera than this one, or the stamps are on another clock.
        """
        told = self.config["camera_latency"]
        ms, told_ms = 1e3 * mean, 1e3 * told
        if told >= 0.01 and mean < 0.25 * told:
            log.warning("the camera's frames are applied %.1f ms after their stamps (the mean "
                        "of the first %d), while camera_latency says %.0f ms: if the camera's "
                        "driver stamps frames when it receives them, set camera_stamp_delay to "
                        "the time from capture to its stamp (a frame taken for fresher than it "
                        "is leaves the arm that far behind the trajectory); if the camera is "
                        "that fast, set camera_latency (the derived gains assume it)",
                        ms, AGE_CHECK_FRAMES, told_ms)
        elif mean > 2.0 * told + 0.01:
            log.warning("the camera's frames are applied %.1f ms after their stamps (the mean "
                        "of the first %d), while camera_latency says %.0f ms: the derived gains "
                        "assume the faster camera; set camera_latency to what the camera "
                        "delivers, or check that the frames' stamps and the joint states' are "
                        "on the same clock", ms, AGE_CHECK_FRAMES, told_ms)

    def _step_predicted(self, t, q, qd, frame, stamp, problems):
        """Latency compensation: the law sees x_hat, the frame re-predicted to now.

        What replaces the measured x in eqs (10) and (18)-(25): x_hat(t) of
        :class:`~.prediction.FramePredictor`, which equals the frame at its capture
        time and follows x_hat_dot = Z_hat^-1 J_hat(q, x_hat) q_dot from the joint
        samples since (docs/latency.md).
        """
        if self._noise_pending is not None:
            # the last frame's measurement, one sample late: the sample with a frame (its
            # re-prediction) is the costly one
            self._follow_noise(*self._noise_pending)
            self._noise_pending = None
        if frame is not None:
            if self.scale is not None:
                self.scale.frame(stamp, frame)
                if (self.reversal is not None and self.reversed_motion is None
                        and self.reversal.due(stamp)):
                    self._check_reversal(t, stamp, frame)
            if self.ratio is not None and self.t_last is not None:
                # (the ratio's own paths and sums take the step as it is returned)
                step = self.ratio.frame(stamp, frame, self._noise_variance)
                if step != 1.0:
                    self._scale_a_perp(step)
            noise = self.noise
            prior = (self.predictor.prior(stamp, t) if noise is not None and noise.due(stamp)
                     else None)
            x_hat = self.predictor.correct(stamp, frame, t)
            if prior is not None:
                # (copied: a caller may reuse its pixel array before the next sample)
                self._noise_pending = (stamp, frame - prior, frame.copy())
            elif noise is not None:
                noise.skip(stamp)
        else:
            x_hat = self.predictor.predict(t)
        applied = stamp if frame is not None else None
        if x_hat is None:
            problems = problems or [WAITING_FOR_CAMERA]
        elif frame is None and self._check_stale(t):
            problems = problems or [f"feature x: no camera frame for "
                                    f"{t - self.t_last_feature:.3f} s (camera stale)"]
        else:
            if frame is not None:
                self._count_frame(t, stamp)
            result = self._sample(t, q, qd, x_hat, None, frame is not None, store=True)
            if result.status == "ok" and self._fast_sample is not None:
                # the compiled sample computed the scale's speed and stored the scaled rate
                # in the predictor's buffer
                res, fast = self._fast_sample
                if self.scale is not None:
                    self.scale.record(t, res[fast.speed])
                if self.ratio is not None and self.ratio.due(t):
                    m2 = 2 * self.model.m
                    self._record_ratio(t, x_hat, res[fast.model_rate].reshape(3, m2))
                self.predictor.stored(t, applied)
            else:
                rate = (self._model_rate
                        if result.status == "ok" and self._model_rate is not None
                        else self._prediction_rate(self.model.kinematic_tensors(q, qd), qd,
                                                   self.state))
                self._commit_prediction(t, x_hat, rate, applied)
            if problems and result.status == "ok":
                result = replace(result, problems=tuple(problems))
            return result
        # not run: keep the joint buffer continuous for the frames still to come
        self._commit_prediction(t, x_hat, self._prediction_rate(
            self.model.kinematic_tensors(q, qd), qd, self.state), applied)
        return self._reject(t, q, qd, problems)

    def _check_reversal(self, t, stamp, frame):
        """Feed the reversed-motion check a frame; its first verdict is logged and kept."""
        path = self.scale.path_at(stamp)
        if path is None:
            return
        verdict = self.reversal.frame(stamp, frame, path)
        if verdict is not None:
            self.reversed_motion = (t, verdict)
            log.warning("t=%.3f: %s", t, verdict)

    def _follow_noise(self, stamp, innovation, frame):
        """Measure a frame's innovation and error x_c - x_d(t_c); move gamma with them.

        The gains change in steps of at least BANDWIDTH_STEP (a new Gains: the compiled law
        packs it again at the next sample, so not at every 1 ms frame).
        """
        factor = self.noise.frame(stamp, innovation, frame - self.desired_at(stamp)[0])
        if abs(ln(factor / self.bandwidth_factor)) < BANDWIDTH_STEP:
            return
        self.bandwidth_factor = factor
        if self.gains is not None:
            self.gains = replace(self.gains, gamma=self._gamma())

    def _noise_variance(self):
        """sigma^2 of the frames' noise as measured (gain_design.follow_noise) [px^2], or None."""
        sigma = self.frame_noise
        return sigma * sigma if sigma == sigma else None

    @property
    def frame_noise(self):
        """The pixel noise measured in the frames [px per coordinate] (NaN: not measured)."""
        return self.noise.sigma if self.noise is not None else float("nan")

    def _gamma(self):
        """gamma in effect: a derived one times the noise's factor (alpha stays as designed).

        A gamma given (also one given later through :meth:`update_gains`) never moves.
        """
        c = self.config
        return c.gamma if "gamma" in c.explicit else c.gamma * self.bandwidth_factor

    def _record_ratio(self, t, x_hat, rate):
        """Extend the ratio's paths: A = J_perp_hat q_dot / Z_hat, B = -x_hat Z_hat_dot / Z_hat."""
        record_rate = getattr(self.ratio, "record_rate", None)
        if record_rate is not None:
            # (compiled: the rate's rows as they are, no list made)
            record_rate(t, *(np.ascontiguousarray(v, dtype=float) for v in (x_hat, *rate)))
            return
        jq, z_dot, z = (np.asarray(v).tolist() for v in rate)
        self.ratio.record(t, [a / c for a, c in zip(jq, z)],
                          [-u * b / c for u, b, c in zip(x_hat.tolist(), z_dot, z)])

    def _scale_a_perp(self, step):
        """a_z_perp *= step between samples (motion_scale.ratio_rate), in either backend.

        The kinematic leakage's target for a_z_perp takes the same step.
        """
        if self._fast_prev is not None:
            # the compiled sample reads the last sample's state from its array: a copy, so
            # the state the last step returned stays what it was
            layout = self._fast_layout
            self._fast_prev = self._fast_prev.copy()
            flat = self._fast_prev[layout.state]
            flat[layout.state_ends[0]:layout.state_ends[1]] *= step
            self.state = _frozen(_LazyFlatState, {"_flat": (flat, layout.state_ends)})
        else:
            self.state = replace(self.state, a_z_perp=self.state.a_z_perp * step)
        leak = None if self.gains is None else self.gains.leakage
        if leak is not None:
            # the leakage pulls toward the guess the steps corrected, not the first one (a
            # new Gains: the compiled law packs it again at the next sample)
            self.gains = replace(self.gains,
                                 leakage=replace(leak, a_z_perp0=leak.a_z_perp0 * step))

    def _commit_prediction(self, t, x_hat, rate, stamp):
        """Store the sample in the predictor (its rate scaled by s) and the scale's path."""
        if self.ratio is not None and x_hat is not None and self.ratio.due(t):
            self._record_ratio(t, x_hat, rate)
        if self.scale is not None:
            jq, z_dot, z = rate
            if x_hat is not None:
                # (jq - x_hat z_dot) / z on Python floats (the scale keeps lists; 2m <= 6)
                self.scale.record(t, [(a - x * b) / c for a, x, b, c in zip(
                    jq.tolist(), x_hat.tolist(), z_dot.tolist(), z.tolist())])
            s = self.scale.value
            if s != 1.0:
                rate = (s * jq, s * z_dot, z)
        self.predictor.commit(t, x_hat, rate, stamp)

    @staticmethod
    def _prediction_rate(tensors, qd, state):
        """(J_perp_hat q_dot, Z_hat_dot, Z_hat) per image coordinate with ``state``'s estimates."""
        _, _, _, Zh, Zh_rate, J_perp, _ = estimated_kinematics(tensors, qd, state)
        return J_perp.dot(qd), Zh_rate, Zh

    def _sample(self, t, q, qd, x, tensors, with_frame, store=False):
        """Integrate the state to t, evaluate the law with pixels ``x``, saturate and commit.

        ``tensors``: the model's kinematic tensors at (q, q_dot), or None (computed here
        when needed).  A sample that does not restart the observer runs compiled in one
        call when the compiled backend is on (:meth:`_sample_compiled`); this code is
        its reference.  ``store``: the compiled sample, if accepted, also writes its row
        of the frame predictor's buffer (the caller ends the commit).
        """
        restarting = self.t_last is None or self.stale
        self._fast_sample = None
        if not restarting:
            fast = self._compiled_sample()
            if fast is not None and self._fast_prev is not None:
                return self._sample_compiled(fast, t, q, qd, x, with_frame, store)
        if tensors is None:
            tensors = self.model.kinematic_tensors(q, qd)
        e_int, joint_int = self.e_int, self.joint_int
        if restarting:
            state = replace(self.state, x_obs=x.copy())
            e_int = np.zeros_like(e_int)
            joint_int = np.zeros_like(joint_int)
            blend = (self.config.start_blend_time if self.t_last is None
                     else self.config["safety.recovery_blend_time"])
            desired = BlendedStart.from_measurement(self.trajectory, x, t, blend,
                                                    self.config["start_tolerance"],
                                                    self.blend_speed)
        else:
            desired = self.desired
            dt = min(t - self.t_last, self.config["max_dt"])
            state = self.state.advanced(self.rates, dt)
            if self.scale is not None:
                self.scale.advance(dt)
            if self._integral:
                e_int = e_int + dt * (self.state.x_obs - self._xd_last)
            joint_int = joint_int + dt * self._s_int
        projection = self.projection
        if projection is not None:
            if projection.interior(state, tensors[0]):
                # nothing to clamp and nothing the law's projection could block
                projection = None
            else:
                state = projection.clamp(state, tensors[0])

        xd, xd_dot, xd_ddot = desired(t)
        try:
            out = self._law(t, state, q, qd, x, xd, xd_dot, xd_ddot, tensors, projection, e_int)
        except np.linalg.LinAlgError:
            return self._reject(t, q, qd, ["J* is singular (set min_singular_value > 0 to damp "
                                           "its pseudo-inverse; state kept)"])
        tau_law = out.tau
        if self._joint_integral > 0.0:
            # joint_damping.integral_rate: eq (22) - k_i D int s dt (docs/robust_adaptation.md)
            tau_law = tau_law - self._joint_integral * self.gains.D.dot(joint_int)
        torques = tau_law.tolist()
        if not (_all_finite(torques) and out.rates.is_finite() and state.is_finite()):
            return self._reject(t, q, qd, ["controller update is not finite (state kept)"])

        limit = self.config["torque_limit"]
        saturated = not all(-lim <= v <= lim for v, lim in zip(torques, limit.tolist()))
        tau = np.clip(tau_law, -limit, limit) if saturated else tau_law
        self._model_rate = out.model_rate
        # commit
        if restarting and self.stale:
            log.info("camera back at t=%.3f: observer restarted, x_d blended in again", t)
        if restarting and isinstance(desired, BlendedStart) and desired.duration > blend:
            log.info("x_d blended in over %.2f s, not %g s: the feature is %.1f px off x_d, and "
                     "a blend moves at most start_blend_speed x the RMS image speed of x_d "
                     "(%.3g px/s)", desired.duration, blend,
                     float(np.linalg.norm(desired.x_start - self.trajectory(t)[0])),
                     self.blend_speed)
        self.desired = desired
        self.state, self.rates, self.t_last = state, out.rates, t
        self.e_int, self._xd_last = e_int, xd
        self.joint_int = joint_int
        self._s_int = np.zeros_like(joint_int) if saturated else np.array(out.s, dtype=float)
        self._accepted(t, with_frame, tau)
        fast = self._compiled_sample()
        if fast is not None:
            # what the next sample, compiled, reads of this one
            self._fast_prev, self._fast_layout = fast.record(
                _flat_of(state), _flat_of(out.rates), e_int, xd, joint_int, self._s_int), fast
        else:
            self._fast_prev = None
        return _frozen(StepResult, {
            "t": t, "tau": tau, "x_d": xd, "x_obs": state.x_obs, "error": x - xd,
            "z_hat": out.z_hat, "state": state, "status": "ok", "problems": (),
            "saturated": saturated, "projection_active": out.projection_active,
            "damped": out.damped, "sigma_min": out.sigma_min, "tau_unsaturated": tau_law,
            "flags": {}, "motion_scale": self._scale_value, "gamma": self.gains.gamma})

    def _accepted(self, t, with_frame, tau):
        """Commit what every accepted sample does besides the state.

        The frame's time, the camera's and the rejections' flags, and the command the
        safety fallback holds.
        """
        if with_frame:
            self.t_last_feature = t
        self.stale = False
        if self._rejecting:
            log.info("input valid again at t=%.4f", t)
            self._rejecting = ()
        self.last_tau, self.t_last_tau = tau, t

    def _sample_compiled(self, fast, t, q, qd, x, with_frame, store=False):
        """:meth:`_sample` of a sample that does not restart, in one compiled call.

        The same steps in the same order (:mod:`.sample_kernels`): the Euler step of
        the state, the motion scale's advance, the integral, the projection's test
        and clamp, x_d(t), the law, the checks, the saturation; nothing is kept when
        the sample is refused.  ``store``: an accepted sample also goes in the frame
        predictor's buffer, written by the kernel (:meth:`.BufferedFramePredictor.store`).
        """
        config = self.config
        key = fast.key
        if key is None or key[0] is not self.gains or key[1] is not config:
            fast.prepare(self.gains, config, self.projection, self.min_singular_value)
        if self.desired is not fast.desired:
            fast.set_desired(self.desired)
        dt = min(t - self.t_last, config["max_dt"])
        scale = self.scale
        if scale is not None:
            scale.advance(dt)
            s, s_dot, s_ref, s_ref_dot = scale.scales()
        else:
            s, s_dot = s_ref, s_ref_dot = 1.0, 0.0
        # q, q_dot and x are contiguous, writable float64 (validate_vector, the predictor)
        res = np.empty(fast.size)
        try:
            finite, sigma_min, damped, active, saturated = fast.kernel(
                fast.cf, fast.ci, fast.blend, self._fast_prev, res, q, qd, x, t, dt, s, s_dot,
                s_ref, s_ref_dot,
                *(self.predictor.store() if store else fast.no_store))
        except np.linalg.LinAlgError:
            return self._reject(t, q, qd, ["J* is singular (set min_singular_value > 0 to damp "
                                           "its pseudo-inverse; state kept)"])
        if not finite:
            return self._reject(t, q, qd, ["controller update is not finite (state kept)"])
        # commit
        state = _frozen(_LazyFlatState, {"_flat": (res[fast.state], fast.state_ends)})
        self._model_rate = None         # the predictor's rate is in res (_step_predicted)
        self._fast_prev, self._fast_layout, self._fast_sample = res, fast, (res, fast)
        self.state, self._rates, self._e_int, self._xd, self.t_last = state, None, None, None, t
        self._joint_int = self._sint = None
        unsaturated = res[fast.tau_unsaturated]
        tau = res[fast.tau] if saturated else unsaturated     # as _sample: the same array
        self._accepted(t, with_frame, tau)
        return _frozen(StepResult, {
            "t": t, "tau": tau, "x_d": res[fast.xd], "x_obs": res[fast.x_obs],
            "error": res[fast.error], "z_hat": res[fast.z_hat], "state": state, "status": "ok",
            "problems": (), "saturated": saturated, "projection_active": active,
            "damped": damped, "sigma_min": sigma_min, "tau_unsaturated": unsaturated,
            "flags": {}, "motion_scale": s, "gamma": self.gains.gamma})

    # the rates, the integral and x_d of the last accepted sample: a compiled sample keeps
    # them in its array only (the attributes None), read from there when asked for
    def _last(self, attribute, part):
        """``attribute``, from the last compiled sample's array (its slice ``part``) if None.

        Without a compiled sample the value stays None.
        """
        value = self.__dict__[attribute]
        if value is None and self._fast_prev is not None:
            value = self._fast_prev[getattr(self._fast_layout, part)]
            if part == "rates":
                value = EstimatorState.from_flat(value, self._fast_layout.state_ends)
            self.__dict__[attribute] = value
        return value

    #: the adaptation rates of the last accepted sample (an EstimatorState), or None
    rates = property(lambda self: self._last("_rates", "rates"),
                     lambda self, value: setattr(self, "_rates", value))
    #: the reference's integral of x_o - x_d (zero when reference.integral_rate is 0)
    e_int = property(lambda self: self._last("_e_int", "e_int"),
                     lambda self, value: setattr(self, "_e_int", value))
    _xd_last = property(lambda self: self._last("_xd", "xd"),
                        lambda self, value: setattr(self, "_xd", value))
    #: int s dt of joint_damping.integral_rate, and the s it integrates at the next sample
    joint_int = property(lambda self: self._last("_joint_int", "joint_int"),
                         lambda self, value: setattr(self, "_joint_int", value))
    _s_int = property(lambda self: self._last("_sint", "s_int"),
                      lambda self, value: setattr(self, "_sint", value))

    def _compiled_sample(self):
        """The :class:`~.sample_kernels.CompiledSample` of this tracker, or None.

        None unless the compiled law runs, the trajectory is one the kernel evaluates,
        and neither :meth:`_law` nor :meth:`_sample` is overridden (the baselines).
        """
        if type(self)._law is not _TRACKER_LAW or type(self)._sample is not _TRACKER_SAMPLE:
            return None
        self._compiled_law()
        return self._fast

    def _design(self, q):
        """Fix the joint damping and derive the gains left out, at the first valid joint sample.

        D = c M_hat(q0) + diag(d) from ``joint_damping.*``: M_hat is the inertia matrix
        of the initial dynamic estimate at the start pose (from the model's own
        regressor), made positive definite (eigenvalues floored at 1e-6 of the
        largest): with D = c M_hat, D T M^-1 is about c T for every mode of the arm,
        so one rate c suits a heavy shoulder and a light wrist alike.  K and the
        adaptation gains the configuration leaves out follow from the arm
        (:func:`~.gain_design.design_gains`); the sampled-data margin of the
        velocity loop is checked (:meth:`start_report`).
        """
        config = self.config
        c = config["joint_damping.inertia_rate"]
        D = np.diag(np.asarray(config["joint_damping.diagonal"], dtype=float))
        M_hat = self.model.estimated_mass_matrix(q, self.state.a_d)
        if c > 0.0:
            w = np.linalg.eigvalsh(0.5 * (M_hat + M_hat.T))
            if w[0] <= 1e-6 * max(w[-1], 0.0):
                log.warning("joint_damping: the initial dynamic estimate's inertia matrix is not "
                            "positive definite at the start (eigenvalues %s); %s", w,
                            "floored" if w[-1] > 0.0 else "the inertia-shaped damping is off")
            D = D + c * positive_definite(M_hat)
        missing = [name for name in DESIGNED if config[name] is None]
        designed = {}
        if missing:
            derived = design_gains(self.model, DesignSettings.from_values(config), self.state, q,
                                   self.trajectory, D, config.alpha, config.gamma)
            if "Gamma_d" in missing and derived.Gamma_d is None:
                raise ConfigError(f"{CONTROLLER_SECTION}.Gamma_d: cannot be derived without a "
                                  "joint damping (joint_damping.* is zero): give Gamma_d or "
                                  "Gamma_d_normalized")
            designed = {name: getattr(derived, name) * config[f"gain_design.scale.{name}"]
                        for name in missing}
        gains = self._gains(D, designed)
        report = self.start_report(q, M_hat, gains)       # raises before anything is kept
        self.damping, self.designed, self.gains, self.report = D, designed, gains, report
        self._derived_floor = report.gains["min_singular_value"]
        self._fallback_inputs = (M_hat, D, config["sample_time"])
        self._fallback_for = config["safety.fallback_damping"]
        self.fallback_bound = fallback_bound(*self._fallback_inputs,
                                             config["safety.fallback_damping"])
        capped = self.fallback_bound < config["safety.fallback_damping"]
        if np.any(capped):
            # the default is capped quietly where the arm is light; a value given is warned of
            given = "safety.fallback_damping" in getattr(config, "explicit", frozenset())
            used = ", ".join(f"{name} {b:.3g}" for name, b, c in zip(
                report.joint_names, self.fallback_bound.tolist(), capped.tolist()) if c)
            log.log(logging.WARNING if given else logging.INFO,
                    "safety.fallback_damping %g N m s/rad is more than the sampled-data "
                    "bound of the light joints; the fallback uses %s there (the largest "
                    "step of T M_hat^-1 (D + diag d) <= %g)",
                    config["safety.fallback_damping"], used, FALLBACK_STEP)
        fast = self._compiled_sample()
        if fast is not None:
            # packed now, not in a later sample
            fast.prepare(gains, config, self.projection, self.min_singular_value)

    def start(self, q):
        """Fix the damping and the gains at joint positions ``q`` now (else at the first sample).

        Raises ConfigError when the configuration cannot run from q: a feature point
        lies behind the guessed camera, the sampled-data margin is gone, or a gain
        cannot be derived.
        """
        q = validate_vector("joint positions q", q, self.model.n)
        self._design(q)
        return self.report

    def start_report(self, q, M_hat, gains):
        """What the controller starts with at q: the start-up report (also logged).

        Refuses (ConfigError) an estimate under which a point lies behind the camera
        or closer than ``projection.min_depth``, and a velocity loop whose sampled-data
        step T M_hat^-1 B reaches 2 (B = D + J*^T K J* + gamma M_hat, the velocity
        feedback of eqs (19), (22)); warns past 1.
        """
        config, model, g = self.config, self.model, gains
        H, dH, _, W, _ = model.kinematic_tensors(q, np.zeros(model.n))
        z_hat = H.dot(self.state.a_z)
        nearest = config["projection.min_depth"]
        behind = [i for i, z in enumerate(z_hat.tolist()) if not z > nearest]
        if behind:
            # points counted from 1, as point1, point2 of unknown_lengths and the start checks
            raise ConfigError(
                f"{CONTROLLER_SECTION}.initial_estimate: under the guessed camera feature "
                f"point(s) {[i + 1 for i in behind]} lie at estimated depth(s) "
                f"{[round(z, 4) for z in z_hat[behind].tolist()]} m, behind it or nearer than "
                f"projection.min_depth ({config['projection.min_depth']} m) at the start pose: "
                "check initial_estimate.camera (position, look_at or rpy) against the arm")
        x0 = self.trajectory(0.0)[0]
        J_hat = model.image_jacobian(W, dH, x0, self.state.a_z_perp, self.state.a_z)
        sigma = np.linalg.svd(J_hat, compute_uv=False)
        B = (g.D if g.D is not None else np.zeros((model.n, model.n))) \
            + (g.K * J_hat.T).dot(J_hat) + g.gamma * M_hat
        rho, rho_joint = sampled_data_margin(positive_definite(M_hat), B, config["sample_time"])
        joint = int(np.argmax(np.nan_to_num(rho_joint, nan=-1.0)))
        names, prismatic = joint_labels(model)
        margin = (f"sampled-data step T M_hat^-1 (D + J*^T K J* + gamma M_hat) = {rho:.3g} "
                  f"(largest on joint {names[joint]}: {rho_joint[joint]:.3g}; oscillates past 1, "
                  "diverges past 2)")
        if rho >= 2.0:
            raise ConfigError(f"{CONTROLLER_SECTION}.joint_damping.inertia_rate / gamma / "
                              f"sample_time: {margin}: lower joint_damping.inertia_rate "
                              f"(now {config['joint_damping.inertia_rate']:g} 1/s) or gamma, "
                              "or shorten sample_time")
        if rho > 1.0:
            log.warning("start: %s: the velocity loop will ring; lower "
                        "joint_damping.inertia_rate or gamma", margin)
        explicit = getattr(config, "explicit", frozenset())
        # the damping floor of J*'s pseudo-inverse: the file's, or a fixed fraction of the
        # estimated J's largest singular value here (a condition number, whatever the units)
        floor = (config["min_singular_value"] if "min_singular_value" in explicit
                 else config["gain_design.singular_fraction"] * float(sigma[0]))
        if sigma[-1] < floor:
            log.warning("start: sigma_min of the estimated J(q, x) is %.3g px m/rad, below "
                        "min_singular_value %.3g: the pseudo-inverse is damped from the start",
                        sigma[-1], floor)
        gains = {"alpha": g.alpha, "gamma": g.gamma, "K": g.K,
                 "joint_damping.inertia_rate": config["joint_damping.inertia_rate"],
                 "Gamma_d": g.Gamma_d, "Gamma_z_perp": g.Gamma_z_perp, "Gamma_z": g.Gamma_z,
                 "min_singular_value": floor}
        derived = tuple(name for name in gains if name not in explicit
                        and not (name == "Gamma_d" and "Gamma_d_normalized" in explicit))
        departures = [f"{name} {config[name]:g}" for name in DEPARTURES if config[name] > 0.0
                      and (g.D is not None or name != "joint_damping.integral_rate")]
        if self.scale is not None:
            departures.append(f"motion_scale (window {self.scale.window:g} s, rate "
                              f"{self.scale.rate:g} /s, bounds [{self.scale.lower:g}, "
                              f"{self.scale.upper:g}], initial {self.scale.initial:g}, "
                              f"start_factor {self.scale.start_factor:g}"
                              + (f", ratio_rate {self.ratio.rate:g} /s, ratio_band "
                                 f"{self.ratio.band:g}, ratio_evidence {self.ratio.evidence:g}, "
                                 f"ratio_significance {self.ratio.significance:g}"
                                 if self.ratio is not None else "")
                              + ")")
        if self.noise is not None:
            departures.append(f"gain_design.follow_noise (gamma follows the pixel noise and "
                              f"the tracking error measured in the frames: window "
                              f"{self.noise.window:g} s, at least "
                              f"{self.noise.min_factor:g} x the delay's)")
        limit = tuple(config["torque_limit"].tolist())
        limit_source = ("given" if "torque_limit" in explicit
                        else "urdf" if any(np.isfinite(limit)) else "none")
        report = StartReport(model.n, model.m, model.p_perp, model.p_z, model.p_d,
                             gains, derived,
                             float(sigma[-1]), float(sigma[0]), z_hat, rho, rho_joint, names,
                             tuple(departures), limit, limit_source, prismatic,
                             self.blend_speed, config["start_blend_speed"],
                             config.start_blend_time)
        # one record: a node forwards the core's logging throttled per call site
        log.info("start-up report:\n  %s", "\n  ".join(report.lines()))
        return report

    def _gains(self, D, designed=None):
        """Gains from the configuration, with the derived ones where it has none."""
        designed = self.designed if designed is None else designed
        value = {name: (self.config[name] if self.config[name] is not None
                        else designed[name]) for name in DESIGNED}
        c = self.config
        rates = (c["robust.leakage_kinematic"], c["robust.leakage_dynamic"])
        # the leakage's target for a_z_perp: the guess times the ratio's steps so far
        corrected = 1.0 if self.ratio is None else self.ratio.total
        leakage = (Leakage(*rates, corrected * np.array(c.a_z_perp_init), np.array(c.a_z_init),
                           np.array(c.a_d_init)) if any(r > 0.0 for r in rates) else None)
        return Gains(value["K"], c.alpha, self._gamma(), value["Gamma_d"], value["Gamma_z_perp"],
                     value["Gamma_z"], D if np.any(D) else None, leakage)

    @property
    def _scale_value(self):
        """s of the image-motion scale in effect (1 when it is off)."""
        return 1.0 if self.scale is None else self.scale.value

    @property
    def _integral(self):
        return self.config["reference.integral_rate"] > 0.0

    @property
    def _joint_integral(self):
        """k_i of joint_damping.integral_rate in effect: 0 without a joint damping D."""
        return self.config["joint_damping.integral_rate"] if self.gains.D is not None else 0.0

    def _law(self, t, state, q, qd, x, xd, xd_dot, xd_ddot, tensors, projection, e_int=None):
        """The control law evaluated by :meth:`step` at time ``t`` (baselines override this).

        ``state`` is the integrated, clamped state; ``tensors`` the model's kinematic
        tensors at (q, q_dot); ``projection`` None when no bound is near.
        """
        kappa = self.config["reference.integral_rate"] * self.gains.gamma ** 2
        integral = (kappa, e_int) if kappa > 0.0 else None
        scale = self.scale
        motion_scale = reference_scale = None
        if scale is not None:
            s, s_dot, s_ref, s_ref_dot = scale.scales()
            motion_scale, reference_scale = (s, s_dot), (s_ref, s_ref_dot)
        compiled = self._compiled_law()
        if compiled is not None:
            return _flat_law_output(compiled, *compiled.evaluate(
                self.gains, state, q, qd, x, xd, xd_dot, xd_ddot, projection,
                self.min_singular_value, tensors, integral, motion_scale, reference_scale))
        return control_law(self.model, self.gains, state, q, qd, x, xd, xd_dot, xd_ddot,
                           projection, self.min_singular_value, tensors, integral,
                           motion_scale, reference_scale)

    @property
    def min_singular_value(self):
        """The damping floor of J*'s pseudo-inverse in effect [px m/rad].

        The configuration's when it gives one (also when changed while running), else
        ``gain_design.singular_fraction`` x sigma_max of the estimated J(q0, x_d(0)),
        fixed at the start (0 before it).
        """
        if "min_singular_value" in self.config.explicit:
            return self.config["min_singular_value"]
        return self._derived_floor

    def _compiled_law(self):
        """:class:`~.law_kernels.CompiledLaw` when the model runs the compiled backend, else None.

        Then :meth:`_law` evaluates the compiled kernel instead of :func:`control_law`
        (the same law, tested equal to 1e-12), a sample that does not restart runs
        whole in one compiled call (:mod:`.sample_kernels`), and the frame predictor
        and the image-motion scale keep their buffers in arrays with their steps
        compiled (:class:`~.prediction_kernels.BufferedFramePredictor`,
        :class:`~.motion_scale_kernels.BufferedMotionScale`, and the image-motion ratio's
        paths in :class:`~.motion_scale_kernels.BufferedMotionRatio`); followed when the
        model's backend changes.
        """
        backend = getattr(self.model, "backend", "numpy")
        if backend != self._law_backend:
            self._law_backend, self._law_kernel, self._fast = backend, None, None
            self._inputs_valid = None
            # the reference predictor and scale, on lists
            if hasattr(self.predictor, "to_lists"):
                self.predictor = self.predictor.to_lists()
            if hasattr(self.scale, "to_lists"):
                self.scale = self.scale.to_lists()
            if hasattr(self.ratio, "to_lists"):
                self.ratio = self.ratio.to_lists()
            kernel = getattr(self.model, "dynamics_kernel", None)
            if backend == "compiled" and kernel is not None and kernel() is not None:
                with compile_notice("control law"):
                    self._compile_sample()
        return self._law_kernel

    def _compile_sample(self):
        """The compiled law, its sample and the buffered predictor, scale and ratio."""
        from .law_kernels import CompiledLaw
        from .motion_scale_kernels import BufferedMotionRatio, BufferedMotionScale
        from .prediction_kernels import BufferedFramePredictor
        from .sample_kernels import CompiledSample, inputs_valid, supports

        self._law_kernel = CompiledLaw(self.model)
        self._inputs_valid = inputs_valid
        m2 = 2 * self.model.m
        self.predictor = BufferedFramePredictor.of(self.predictor, m2)
        if self.scale is not None:
            self.scale = BufferedMotionScale.of(self.scale, m2)
        if self.ratio is not None:
            self.ratio = BufferedMotionRatio.of(self.ratio, m2)
        self._fast = (CompiledSample(self._law_kernel, self.model, self.trajectory)
                      if supports(self) else None)

    def _reject(self, t, q, qd, problems):
        # log when the problem changes, not at every sample of a long outage: its text with
        # the numbers masked (a stale camera's age grows every sample), so a second problem
        # of the same input ('waiting for the first camera frame', then 'expected 4 values')
        # is logged too
        kinds = tuple(_NUMBER.sub("#", p) for p in problems)
        if kinds != self._rejecting:
            for p in problems:
                log.log(logging.INFO if p == WAITING_FOR_CAMERA else logging.WARNING,
                        "sample at t=%.4f rejected: %s", t, p)
            self._rejecting = kinds
            self._waiting_since = t if problems == [WAITING_FOR_CAMERA] else None
        elif (self._waiting_since is not None
              and t - self._waiting_since >= self.config["safety.camera_timeout"]):
            log.warning("no camera frame yet, %.3f s after the first sample (t=%.4f; "
                        "safety.camera_timeout %g s): the controller holds the safety fallback "
                        "until one comes", t - self._waiting_since, t,
                        self.config["safety.camera_timeout"])
            self._waiting_since = None
        safety = self.config
        xd = (self.desired_at(t)[0] if self.t_last is not None
              else np.full(2 * self.model.m, np.nan))
        if self.t_last_tau is not None and t - self.t_last_tau <= safety["safety.hold_time"]:
            tau, status = self.last_tau, "hold"
        else:
            tau, status = self.fallback_torque(q, qd), "fallback"
        z_hat = (self.model.depth(q, self.state.a_z) if q is not None
                 else np.full(self.model.m, np.nan))
        return StepResult(t, tau, xd, self.state.x_obs, np.full(2 * self.model.m, np.nan), z_hat,
                          self.state, status, tuple(problems), motion_scale=self._scale_value)

    def fallback_torque(self, q, qd):
        """Safe torque when no valid control can be computed.

        tau = g_hat(q) - (D + d I) q_dot: the estimated gravity, the joint-space damping D
        of ``joint_damping.*`` (shaped by the arm's inertia, so it is stable on a light
        wrist too) and ``safety.fallback_damping`` d.
        """
        n = self.model.n
        if q is None or qd is None or self.config["safety.fallback"] == "zero_torque":
            return np.zeros(n)
        zero = np.zeros(n)
        g_hat = self.model.dynamic_regressor(q, zero, zero, zero) @ self.state.a_d
        d = self.config["safety.fallback_damping"]
        if self.fallback_bound is not None:
            if self._fallback_for != d:         # changed while running: bound it again
                self.fallback_bound = fallback_bound(*self._fallback_inputs, d)
                self._fallback_for = d
            d = self.fallback_bound
        tau = g_hat - d * qd
        if self.damping is not None and np.any(self.damping):
            tau = tau - self.damping.dot(qd)
        return np.clip(tau, -self.config.torque_limit, self.config.torque_limit)


#: the largest sampled-data step T (D + d) / M_hat of a joint under the fallback's damping
FALLBACK_STEP = 0.5


def fallback_bound(M_hat, D, sample_time, requested=np.inf):
    """The fallback's damping d per joint: ``requested`` where the sampled step allows it.

    Pure damping on a sampled joint flips sign every sample and grows once T d / M
    passes 2; a fixed d in N m s/rad is far past that on a light wrist (0.5 kg hand,
    M about 1e-3 kg m^2: 5 N m s/rad at 1 ms is a step of 5).  Per joint, with the
    diagonal of the initial estimate's inertia, d_j is at most what keeps T (D_jj + d_j) /
    M_hat_jj <= FALLBACK_STEP (margin for the estimate's error); never negative.  A chain
    whose joints move one another (parallel axes: a planar arm) has modes far lighter than
    any diagonal entry, and those per-joint values together can still step past 2
    (measured: lambda_max(T M_hat^-1 (D + diag(d))) = 4.8 on a planar 3R arm, which the
    fallback threw to its velocity limits before the first frame); then all of them are
    scaled by the one factor that brings the largest step of the whole matrix to
    FALLBACK_STEP.  No bound (inf) on a joint whose estimated inertia is not positive: the
    estimate says nothing there (the paper's arm starts with a_d = 0).
    """
    M_diag = np.diag(M_hat)
    bound = np.maximum(FALLBACK_STEP * M_diag / sample_time - np.diag(D), 0.0)
    d = np.minimum(requested, np.where(M_diag > 0.0, bound, np.inf))
    if not np.all(np.isfinite(d)):
        return d
    try:
        L = np.linalg.cholesky(0.5 * (M_hat + M_hat.T))
    except np.linalg.LinAlgError:
        return d                # not positive definite: the diagonal is all there is

    def largest_step(scale):
        X = 0.5 * (D + D.T) + np.diag(scale * d)
        Y = np.linalg.solve(L, np.linalg.solve(L, X).T)     # L^-1 X L^-T, symmetric
        return sample_time * np.linalg.eigvalsh(0.5 * (Y + Y.T))[-1]

    if largest_step(1.0) <= FALLBACK_STEP:
        return d
    if largest_step(0.0) >= FALLBACK_STEP:
        return np.zeros_like(d)
    low, high = 0.0, 1.0        # the step grows with the scale: bisect for it
    for _ in range(40):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if largest_step(mid) <= FALLBACK_STEP else (low, mid)
    return low * d


_TRACKER_LAW = AdaptiveVisualTracker._law
_TRACKER_SAMPLE = AdaptiveVisualTracker._sample


def _flat_of(state):
    """The four fields of an EstimatorState end to end (its own array when it is flat)."""
    flat = state.__dict__.get("_flat")
    if flat is not None:
        return flat[0]
    return np.concatenate([state.x_obs, state.a_z_perp, state.a_z, state.a_d])


def health(result):
    """(level, message, values) of a :class:`StepResult` for /diagnostics."""
    values = {"status": result.status, "saturated": result.saturated,
              "projection_active": result.projection_active, "damped_pinv": result.damped,
              "sigma_min_J_star": f"{result.sigma_min:.6g}", "gamma": f"{result.gamma:.6g}"}
    reasons = "; ".join(result.problems)
    if result.status == "fallback":
        return "ERROR", "input bad or stale, fallback torque: " + reasons, values
    if result.status == "hold":
        return "WARN", "sample rejected, holding last command: " + reasons, values
    notes = [name for name, on in (("torque saturated", result.saturated),
                                   ("projection active", result.projection_active),
                                   ("J* near singular, damped", result.damped)) if on]
    if notes:
        return "WARN", ", ".join(notes), values
    return "OK", "tracking", values


def frame_values(frames, superseded=0, noise=float("nan")):
    """/diagnostics values of the camera frames: ages [s], counts and noise.

    ``frames`` is :attr:`AdaptiveVisualTracker.frames`; ``superseded`` counts the
    frames a node received but never passed on, because a newer one came before
    the next joint sample.  Dropped = refused by the tracker + superseded.
    ``noise``: :attr:`AdaptiveVisualTracker.frame_noise`.
    """
    applied = frames["applied"]
    mean = frames["age_sum"] / applied if applied else float("nan")
    return {"frames_applied": applied, "frames_late": frames["late"],
            "frames_dropped": frames["rejected"] + superseded,
            "frames_superseded": superseded,
            "frame_age_last": f"{frames['last_age']:.6g}",
            "frame_age_mean": f"{mean:.6g}",
            "frame_age_max": f"{frames['age_max'] if applied else float('nan'):.6g}",
            # per image coordinate, from the innovations (gain_design.follow_noise; NaN: not
            # measured)
            "frame_noise_px": f"{noise:.6g}"}
