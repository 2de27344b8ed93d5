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

"""Desired image trajectories x_d(t) with their first and second derivatives.

* :class:`SinusoidTrajectory`: the paper's circle (and any per-coordinate sinusoid);
* :class:`TabulatedTrajectory`: a CSV of t, u_1, v_1, ..., u_m, v_m interpolated by a
  C2 cubic spline (for m > 1 an arbitrary image curve is not realisable: three points
  fix a pose; a taught trajectory, ``vas teach``, is);
* :class:`BlendedStart`: the safe start, the initial offset blended out.
"""

from __future__ import annotations

import bisect
import csv
from dataclasses import dataclass
from math import cos, sin

import numpy as np

TRAJECTORY_TYPES = ("sinusoid", "table")


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


#: the largest value of sigma_dot(tau) of :func:`quintic_blend`: 30 (1/2)^2 (1/2)^2
QUINTIC_PEAK_RATE = 1.875


def blend_duration(least, distance, speed):
    """How long a quintic blend over ``distance`` [px] takes to peak at ``speed`` [px/s].

    At least ``least`` [s]; ``speed`` <= 0 (no limit) gives ``least``.
    """
    if speed <= 0.0:
        return least
    return max(least, QUINTIC_PEAK_RATE * distance / speed)


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


class TabulatedTrajectory:
    """x_d(t) from samples (t_k, x_k), a C2 cubic spline through them.

    A table whose last row equals its first (to 1e-9 px) is periodic and repeats
    with period t_last - t_0 (periodic spline: C2 across the seam); any other table
    uses a clamped spline (zero velocity at both ends) and holds its last point
    after the end.  Times start at 0 and increase strictly.

    Parameters
    ----------
    t : (N,) times [s]
    x : (N, 2m) pixels
    """

    def __init__(self, t, x, source="trajectory"):
        from scipy.interpolate import CubicSpline

        t = np.asarray(t, dtype=float)
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or len(t) != len(x) or len(t) < 4:
            raise ValueError(f"{source}: needs at least 4 rows of t and 2m pixel columns")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(x))):
            raise ValueError(f"{source}: contains NaN or inf")
        if t[0] != 0.0 or np.any(np.diff(t) <= 0.0):
            raise ValueError(f"{source}: times must start at 0 and increase strictly")
        self.periodic = bool(np.max(np.abs(x[-1] - x[0])) <= 1e-9)
        if self.periodic:
            x = x.copy()
            x[-1] = x[0]
        self.spline = CubicSpline(t, x, bc_type="periodic" if self.periodic else "clamped")
        self.t_end = float(t[-1])
        self.source = source
        # per interval, the polynomial coefficients of x, x_dot, x_ddot in powers of (t - t_k):
        # one product evaluates all three (CubicSpline's three calls cost ~19 us at 2m = 6)
        c = self.spline.c                                           # (4, N-1, 2m)
        self._knots = self.spline.x[:-1].tolist()
        zero = np.zeros_like(c[0])
        coef = np.stack([c, np.stack([zero, 3 * c[0], 2 * c[1], c[2]]),
                         np.stack([zero, zero, 6 * c[0], 2 * c[1]])], axis=2)  # (4, N-1, 3, 2m)
        self._m2 = c.shape[2]
        self._coef = coef.transpose(1, 0, 2, 3).reshape(len(self._knots), 4, -1).copy()

    @classmethod
    def from_csv(cls, path, m):
        """Read ``t, u1, v1, ..., um, vm`` (header row optional) for m feature points."""
        rows = []
        width = 1 + 2 * m
        with open(path, newline="", encoding="utf-8") as handle:
            for k, row in enumerate(csv.reader(handle)):
                if not row or row[0].lstrip().startswith("#"):
                    continue
                try:
                    values = [float(v) for v in row]
                except ValueError:
                    if rows or k > 0:
                        raise ValueError(f"{path}: line {k + 1} is not numbers: {row}") from None
                    continue                                    # the header
                if len(values) != width:
                    raise ValueError(f"{path}: line {k + 1} has {len(values)} columns, needs "
                                     f"{width} (t, u1, v1, ...) for {m} point(s)")
                rows.append(values)
        table = np.array(rows, dtype=float).reshape(-1, width)
        return cls(table[:, 0], table[:, 1:], source=str(path))

    def __call__(self, t):
        """Return (x_d, x_d_dot, x_d_ddot) at time t, each (2m,)."""
        if self.periodic:
            t = t % self.t_end
        elif t >= self.t_end:
            x = self.spline(self.t_end)
            return x, np.zeros_like(x), np.zeros_like(x)
        t = max(t, 0.0)
        k = max(bisect.bisect_right(self._knots, t) - 1, 0)
        h = t - self._knots[k]
        x, xd, xdd = np.array([h * h * h, h * h, h, 1.0]).dot(self._coef[k]).reshape(3, self._m2)
        return x, xd, xdd


@dataclass(frozen=True)
class BlendedStart:
    """Start from where the feature is, at rest: the trajectory blended in.

    ``x_d(t) = sigma x_traj(t) + (1 - sigma) x_start`` with sigma the quintic of
    ``(t - t_start) / duration``: x_d starts at the measured point with zero
    velocity and acceleration (the arm is at rest at a start, and held by the
    fallback before a camera recovery), and equals the trajectory from
    ``t_start + duration`` on, C2 throughout.  Blending only the offset out
    (x_traj + (1 - sigma) (x_start - x_traj(t_start))) would ask for the
    trajectory's full velocity from the first sample: in the 200-run campaign of
    config/campaigns/start_and_estimates.yaml that doubled the median peak torque
    (62 -> 113 N m) and diverged 2 runs with wrong estimates.  A start on the
    trajectory is not blended (:meth:`from_measurement`), so the paper's run is
    unchanged; with ``duration`` 0 there is no blend.
    """

    trajectory: object
    x_start: np.ndarray
    t_start: float
    duration: float

    def __post_init__(self):
        object.__setattr__(self, "x_start", np.asarray(self.x_start, dtype=float))

    @classmethod
    def from_measurement(cls, trajectory, x, t, duration, tolerance, speed=0.0):
        """The blend from the measured ``x`` at ``t``, or ``trajectory`` itself when x is on it.

        "On it" means every coordinate within ``tolerance`` [px] of x_d(t): such an
        offset is far below any camera's resolution, and not blending it keeps a run
        that starts on the trajectory exactly that run (the paper's start,
        q(0) = (1.0807, 0.5756, -0.5), is 0.0036 px off x_d(0)).

        ``speed`` > 0 [px/s] lengthens the blend past ``duration`` where needed, so that
        the offset's part of the blend's velocity, sigma_dot |x - x_d(t)| with the offset
        at ``t``, peaks at no more than ``speed`` (:func:`blend_duration`).
        """
        offset = np.asarray(x, dtype=float) - trajectory(t)[0]
        if duration <= 0.0 or max(np.abs(offset).tolist()) <= tolerance:
            return trajectory
        return cls(trajectory, np.array(x, dtype=float), t,
                   blend_duration(duration, float(np.linalg.norm(offset)), speed))

    def __call__(self, t):
        x, xd, xdd = self.trajectory(t)
        if self.duration <= 0.0:
            return x, xd, xdd
        tau = (t - self.t_start) / self.duration
        if tau >= 1.0:
            return x, xd, xdd
        sigma, sd, sdd = quintic_blend(tau)
        sd, sdd = sd / self.duration, sdd / self.duration**2
        gap = x - self.x_start                      # trajectory minus the start point
        return (self.x_start + sigma * gap, sigma * xd + sd * gap,
                sigma * xdd + 2.0 * sd * xd + sdd * gap)
