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

"""Desired image trajectories x_d(t) with their first and second derivatives."""

from __future__ import annotations

from dataclasses import dataclass
from math import cos, sin

import numpy as np


@dataclass(frozen=True)
class SinusoidTrajectory:
    """x_d(t) = offset + a_cos cos(w t) + a_sin sin(w t), per image coordinate.

    The paper's trajectory is offset = [45, 65], a_cos = [20, 0],
    a_sin = [0, 20], w = pi/3 rad/s.  All vectors have shape (2m,), pixels.
    """

    offset: np.ndarray
    a_cos: np.ndarray
    a_sin: np.ndarray
    omega: float

    def __post_init__(self):
        # rows a_cos, a_sin, offset: one product gives x_d and both derivatives (called
        # every sample)
        object.__setattr__(self, "_coefficients",
                           np.array([self.a_cos, self.a_sin, self.offset], dtype=float))

    def __call__(self, t):
        """Return (x_d, x_d_dot, x_d_ddot) at time t (a number), each (2m,)."""
        w = self.omega
        c, s = cos(w * t), sin(w * t)
        x, xd, xdd = np.array([[c, s, 1.0], [-w * s, w * c, 0.0],
                               [-w * w * c, -w * w * s, 0.0]]).dot(self._coefficients)
        return x, xd, xdd


def quintic_blend(tau):
    """sigma(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 on [0, 1] and its two derivatives.

    sigma goes 0 -> 1 with zero first and second derivatives at both ends, so a
    blend built from it is C^2 everywhere.
    """
    if tau <= 0.0:
        return 0.0, 0.0, 0.0
    if tau >= 1.0:
        return 1.0, 0.0, 0.0
    t2 = tau * tau
    t3 = t2 * tau
    sigma = t3 * (10.0 - 15.0 * tau + 6.0 * t2)
    sigma_d = 30.0 * t2 * (1.0 - tau) ** 2
    sigma_dd = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau)
    return sigma, sigma_d, sigma_dd


@dataclass(frozen=True)
class BlendedStart:
    """Blend from a held start point into a trajectory over ``duration`` seconds.

    x_d(t) = (1 - sigma) x_start + sigma x_traj(t) with sigma the quintic of
    (t - t_start) / duration, so x_d(t_start) = x_start with zero velocity and
    acceleration, and x_d equals the trajectory from t_start + duration on.
    """

    trajectory: SinusoidTrajectory
    x_start: np.ndarray
    t_start: float
    duration: float

    def __call__(self, t):
        x, xd, xdd = self.trajectory(t)
        if self.duration <= 0.0:
            return x, xd, xdd
        sigma, sd, sdd = quintic_blend((t - self.t_start) / self.duration)
        sd /= self.duration
        sdd /= self.duration**2
        diff = x - self.x_start
        return (self.x_start + sigma * diff,
                sd * diff + sigma * xd,
                sdd * diff + 2.0 * sd * xd + sigma * xdd)
