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

"""Default gains that follow from the arm, the camera and the rates (docs/gain_design.md).

Every gain a configuration leaves out is derived here, once, at the first
valid joint sample q0, from what the controller knows then: the sample time T,
the camera it expects (rate and latency), the model's structure and the
initial estimates (J_hat*, Z_hat and M_hat at q0, the desired trajectory).
Nothing reads the true parameters.

* Bandwidths.  The image loop sees the camera through a delay of about
  tau = T + latency + 1/(2 rate); ``gamma = min(gamma_max, delay_bandwidth / tau)``
  keeps the phase the delay costs at the loop's bandwidth small, and the
  observer runs ``observer_ratio`` times faster (alpha > gamma/3 of Theorem 1).
* Joint damping.  D = c M_hat(q0) with ``c = damping_per_sample / T``: each mode
  of the arm is damped at the same rate, and c T is the per-sample step of the
  discretised velocity loop (period-2 oscillation past 1, divergence past 2).
* K.  The largest scalar with J*^T K J* <= ``K_fraction`` D at q0: the image-space
  feedback Theorem 1 needs, never more damping than a fraction of D.
* Adaptation gains of eqs (23)-(25), at rates proportional to gamma (eq (23)'s
  at most ``dynamic_rate_max``).  For a regressor Y driving an estimate
  error a~ through a gradient law, a~_dot ~ -Gamma G a~ with G the regressor's
  Gram matrix over typical motions.  Gamma = rate / (lambda_max(C) diag(G)),
  C the Gram matrix with unit diagonal, gives the best-excited direction the
  convergence rate ``rate`` [1/s] whatever the columns' units, the pixel origin
  and scale (the regressor of eq (25) carries pixel coordinates) and the number
  of parameters (lambda_max(C) is between 1 and p).  The typical motions are
  image velocities of the size of the desired trajectory's, mapped to joint
  velocities through J_hat*(q0)^+.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the gains a configuration may leave out to have them derived at the first joint sample
DESIGNED = ("K", "Gamma_d", "Gamma_z_perp", "Gamma_z")
#: the ``gain_design.*`` parameters, in the order of :class:`DesignSettings`' fields
DESIGN_NAMES = ("delay_bandwidth", "gamma_max", "observer_ratio", "damping_per_sample",
                "K_fraction", "kinematic_rate", "dynamic_rate", "excitation_floor",
                "dynamic_rate_max")
#: joint-velocity samples drawn for the Gram matrices (fixed seed: the design is repeatable)
DESIGN_SAMPLES = 64
DESIGN_SEED = 20150101
#: the poses of those samples: q0 plus this standard deviation per joint [rad], so the
#: Gram matrices see the neighbourhood the arm will move in, not one pose
DESIGN_POSE_SPREAD = 0.1


@dataclass(frozen=True)
class DesignSettings:
    """The inputs of the gain design (the ``gain_design.*`` and camera parameters)."""

    sample_time: float
    camera_rate: float          # Hz; 0: a frame at every joint sample
    camera_latency: float       # s
    delay_bandwidth: float      # gamma tau
    gamma_max: float            # 1/s
    observer_ratio: float       # alpha / gamma
    damping_per_sample: float   # c T
    K_fraction: float
    kinematic_rate: float       # eqs (24), (25): convergence rate / gamma
    dynamic_rate: float         # eq (23): convergence rate / gamma
    excitation_floor: float     # a column's energy counts as at least this x the strongest's
    dynamic_rate_max: float = float("inf")   # eq (23): at most this convergence rate [1/s]

    @classmethod
    def from_values(cls, values):
        """From the controller's parameters (a mapping: sample_time, camera_*, gain_design.*)."""
        return cls(values["sample_time"], values["camera_rate"], values["camera_latency"],
                   *(values[f"gain_design.{name}"] for name in DESIGN_NAMES))

    @property
    def loop_delay(self):
        """tau = T + latency + half a frame interval [s]."""
        frame = 0.5 / self.camera_rate if self.camera_rate > 0.0 else 0.0
        return self.sample_time + self.camera_latency + frame

    def bandwidths(self):
        """(alpha, gamma) of eqs (10) and (18)."""
        gamma = min(self.gamma_max, self.delay_bandwidth / self.loop_delay)
        return self.observer_ratio * gamma, gamma

    def inertia_rate(self):
        """c of D = c M_hat(q0) [1/s]."""
        return self.damping_per_sample / self.sample_time


def normalized_gain(G, rate, floor=1e-3):
    """Diagonal Gamma (p,) with lambda_max(Gamma^1/2 G Gamma^1/2) = ``rate``, Jacobi-shaped.

    ``G`` (p, p) is a regressor's Gram matrix.  A column that carries less than
    ``floor`` of the strongest's energy -- a parameter the typical motions hardly
    excite -- is treated as having that much: its gain is at most 1/floor times
    the strongest column's, not unbounded.
    """
    d = np.diag(G).copy()
    if not d.max() > 0.0:
        return np.full(d.shape, rate)
    d = np.maximum(d, floor * d.max())
    scale = 1.0 / np.sqrt(d)
    lam = np.linalg.eigvalsh(G * scale[:, None] * scale[None, :])[-1]
    return rate / (max(lam, 1.0) * d)


def typical_image_speed(trajectory, m2, gamma, horizon=20.0, samples=200):
    """Per-coordinate RMS of x_d_dot over [0, horizon] [px/s], at least gamma x 1 px."""
    speeds = np.array([trajectory(t)[1] for t in np.linspace(0.0, horizon, samples)])
    rms = np.sqrt(np.mean(speeds**2, axis=0)) if speeds.size else np.zeros(m2)
    return np.maximum(rms, gamma * 1.0)


@dataclass(frozen=True)
class DesignedGains:
    """The gains :func:`design_gains` derives (the start-up report lists them)."""

    alpha: float
    gamma: float
    K: np.ndarray
    Gamma_z_perp: np.ndarray
    Gamma_z: np.ndarray
    Gamma_d: np.ndarray | None


def design_gains(model, settings, state, q0, trajectory, D=None, alpha=None, gamma=None):
    """Every gain of eqs (10), (18), (22)-(25) from the design settings at q0.

    Parameters
    ----------
    model : RobotCameraModel
        Structure only (the true parameters are never read).
    settings : DesignSettings
    state : EstimatorState
        The initial estimates.
    q0 : (n,) the first joint sample [rad].
    trajectory : callable
        x_d(t) -> (x_d, x_d_dot, x_d_ddot); x_d(0) stands for where the features are.
    D : (n, n) or None
        The joint damping in effect (derived from ``settings`` when None).
    alpha, gamma : float or None
        Given bandwidths (derived when None); the adaptation rates follow gamma.

    Returns
    -------
    DesignedGains
    """
    n, m2 = model.n, 2 * model.m
    gamma = settings.bandwidths()[1] if gamma is None else gamma
    alpha = (settings.observer_ratio * gamma if alpha is None else alpha)
    if D is None:
        D = settings.inertia_rate() * positive_definite(model.estimated_mass_matrix(q0, state.a_d))
    zero = np.zeros(n)
    H, dH, _, W, _ = model.kinematic_tensors(q0, zero)
    x0 = trajectory(0.0)[0]
    H2, dH2 = H.repeat(2, axis=0), dH.repeat(2, axis=0)
    Z2 = H2.dot(state.a_z)
    # J_hat*(q0, x_d(0)) of eq (a1), as the law forms it (estimated_kinematics): the same
    # rounding as the per-sample J*, not model.image_jacobian's
    J_star = W.dot(state.a_z_perp) - x0[:, None] * dH2.dot(state.a_z)

    # K: the largest scalar with J*^T K J* <= K_fraction D
    D_inv = np.linalg.inv(D) if np.any(D) else None
    if D_inv is not None:
        lam = np.linalg.eigvalsh(J_star.dot(D_inv).dot(J_star.T))[-1]
        K = np.full(m2, settings.K_fraction / lam if lam > 0.0 else settings.K_fraction)
    else:
        K = np.full(m2, 1e-3)

    # typical motions: image velocities xi of the desired trajectory's size, through J*^+
    speed = typical_image_speed(trajectory, m2, gamma)
    rng = np.random.default_rng(DESIGN_SEED)
    xis = rng.standard_normal((DESIGN_SAMPLES, m2)) * speed
    J_pinv = np.linalg.pinv(J_star)
    G_perp = np.zeros((model.p_perp, model.p_perp))
    G_z = np.zeros((model.p_z, model.p_z))
    G_d = np.zeros((model.p_d, model.p_d))
    poses = q0 + DESIGN_POSE_SPREAD * rng.standard_normal((DESIGN_SAMPLES, n))
    for xi, q in zip(xis, poses):
        qd = J_pinv.dot(Z2 * xi)
        Hq, dHq, _, Wq, _ = model.kinematic_tensors(q, zero)
        Hq2, dHq2 = Hq.repeat(2, axis=0), dHq.repeat(2, axis=0)
        Y_perp = qd.dot(Wq)                                       # eq (24)'s regressor
        Y_z = x0[:, None] * qd.dot(dHq2) + xi[:, None] * Hq2     # eq (25)'s, Y_z_bar + Y_z
        G_perp += Y_perp.T.dot(Y_perp)
        G_z += Y_z.T.dot(Y_z)
        if D_inv is not None:
            Y_d = model.dynamic_regressor(q, qd, qd, gamma * qd)   # eq (23)'s
            G_d += Y_d.T.dot(D_inv).dot(Y_d)
    z_mean = float(np.mean(np.abs(Z2)))
    kin_rate = settings.kinematic_rate * gamma
    # a~ enters the observer's error through Z^-1 Y a~ / alpha: alpha z / G is a rate
    floor = settings.excitation_floor
    Gamma_z_perp = normalized_gain(G_perp / DESIGN_SAMPLES, kin_rate, floor) * alpha * z_mean
    Gamma_z = normalized_gain(G_z / DESIGN_SAMPLES, kin_rate, floor) * alpha * z_mean
    # eq (23)'s rate follows gamma up to a cap: pixel noise reaches Y_d through q_ddot_r
    # (gamma alpha times the noise), so a fast camera's gamma must not speed it up unbounded
    dyn_rate = min(settings.dynamic_rate * gamma, settings.dynamic_rate_max)
    Gamma_d = (normalized_gain(G_d / DESIGN_SAMPLES, dyn_rate, floor)
               if D_inv is not None else None)
    return DesignedGains(alpha, gamma, K, Gamma_z_perp, Gamma_z, Gamma_d)


def positive_definite(M, floor=1e-6):
    """M symmetrised with its eigenvalues floored at ``floor`` x the largest."""
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    top = max(w[-1], 0.0)
    if top <= 0.0:
        return np.zeros_like(M)
    return (V * np.maximum(w, floor * top)).dot(V.T)


def sampled_data_margin(M_hat, B, T):
    """Per-sample step of the velocity loop, overall and per joint.

    With tau = -B q_dot held over a sample T on an arm of inertia M, the velocity
    error is multiplied by I - T M^-1 B per sample: it alternates in sign once
    an eigenvalue of T M^-1 B passes 1 and grows once one passes 2.  Returns
    (rho, rho_joint): the largest eigenvalue of T M_hat^-1 B, and per joint
    T B_jj / M_hat_jj (which joint carries it).  NaN when M_hat is not positive
    definite (an initial estimate without inertia: nothing to check against).
    """
    if np.linalg.eigvalsh(0.5 * (M_hat + M_hat.T))[0] <= 0.0:
        return float("nan"), np.full(M_hat.shape[0], np.nan)
    w = np.linalg.eigvals(np.linalg.solve(M_hat, B))
    rho = float(T * max(w.real))
    diag = np.diag(M_hat)
    rho_joint = T * np.diag(B) / np.where(diag > 0.0, diag, np.inf)
    return rho, rho_joint
