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

"""The frames' pixel noise and the loop's own error, measured; the bandwidth they ask for.

Behind a camera at 30 Hz the image loop passes the pixel noise to the arm: a frame's
noise n_k (standard deviation sigma per image coordinate, held for the frame interval
T_f) reaches the tracking error through the observer (eq 10, bandwidth alpha) and the
reference (eq 18, gamma, with the integral of ``reference.integral_rate``), a linear
filter H(s).  The tracking error it leaves has the variance

    N(gamma) = sigma^2 T_f ||H||_2^2 = sigma^2 T_f b gamma,

b the loop's noise-equivalent bandwidth per unit gamma (:func:`noise_bandwidth`).  What
the model gets wrong (estimates still off, the dynamics) leaves an error that a slower
loop removes more slowly: with the integral, a slow disturbance of the image velocity
leaves e ~ omega d / kappa, kappa = integral_rate gamma^2, so its variance goes as
M(gamma) ~ gamma^-p, p = 4 (p = 2 without the integral).  The gamma that minimises
N + M, from N and M measured at the gamma in effect gamma_c, is

    gamma* = gamma_c (p M(gamma_c) / N(gamma_c))^(1 / (p + 1)),

never above the delay's gamma (``gain_design.delay_bandwidth``), never below
``min_factor`` times it.

Both are measured in the frames, not told.  The noise: at every applied frame the
innovation nu_k = x_c - x_hat^-(t_c), the frame against the predictor's prediction at its
capture time (:mod:`.prediction`).  After a reset at frame k-1 the prediction carries
that frame's noise, so nu_k = n_k - n_{k-1} + d_k, d_k what the model mispredicted over
the interval: a drift that changes slowly with the motion.  Then E[nu_k^2] =
2 sigma^2 + E[d^2] and E[nu_k nu_{k-2}] = E[d_k d_{k-2}], about E[d^2]: the noise is half
their difference, whatever the model's drift.  The error: the frames' error
x_c - x_d(t_c) averaged over blocks of 1/gamma seconds (the loop's time constant, so the
tracking error is kept and the noise averaged down to sigma^2 / n); the mean square of
the block means less sigma^2 / n is the tracking error's variance N + M, and M is what is
left of it beyond N.  Every statistic is an exponentially weighted mean over ``window``
seconds, pooled over the image coordinates, and gamma follows gamma* in log scale at
1 / window downward and RAISE / window upward.
"""

from __future__ import annotations

from math import exp, log

import numpy as np

#: frames before the noise is trusted (beside a whole window of them)
MIN_FRAMES = 10
#: frames closer than this to the last one measured are only counted: with a frame at every
#: 1 ms sample the statistics still take 100 a second, at a tenth of the cost [s]
MEASURE_INTERVAL = 0.01
#: gamma goes back up this many times faster than it comes down: an error that grows (a
#: disturbance, an estimate moving) is met within a fraction of the window
RAISE = 4.0


def noise_bandwidth(observer_ratio, integral_rate):
    """b = ||H||_2^2 / gamma of the image loop's noise filter, for gamma = 1 [rad/s / (rad/s)].

    H(s) = alpha / (s + alpha) x (gamma s + kappa) / (s^2 + gamma s + kappa): the observer
    (eq 10) following the frames at alpha = ``observer_ratio`` gamma, then the image
    error following the observer through eq (18) with kappa = ``integral_rate`` gamma^2.
    ||H||_2^2 = C P C^T with A P + P A^T + B B^T = 0 (its controllability Gramian).
    """
    a, k = float(observer_ratio), float(integral_rate)
    if k > 0.0:
        A = np.array([[-a, 0.0, 0.0], [0.0, 0.0, 1.0], [1.0, -k, -1.0]])
        B = np.array([a, 0.0, 0.0])
        C = np.array([0.0, k, 1.0])
    else:                               # (s + 1)^-1: kappa's state is not there
        A = np.array([[-a, 0.0], [1.0, -1.0]])
        B = np.array([a, 0.0])
        C = np.array([0.0, 1.0])
    n = len(B)
    eye = np.eye(n)
    P = np.linalg.solve(np.kron(eye, A) + np.kron(A, eye), -np.outer(B, B).ravel())
    return float(C.dot(P.reshape(n, n)).dot(C))


class FrameNoise:
    """The frames' noise and the tracking error's share beyond it; gamma's factor they ask for.

    Parameters
    ----------
    window : float
        Exponential window of the statistics, and the time constant with which the
        factor follows its target [s].
    min_factor : float
        The factor never goes below this.
    gamma, alpha : float
        The delay's gamma, the one the factor multiplies, and alpha, which stays [1/s].
    integral_rate : float
        ``reference.integral_rate`` (kappa / gamma^2).
    """

    def __init__(self, window, min_factor, gamma, alpha, integral_rate):
        self.window = float(window)
        self.min_factor = float(min_factor)
        self.gamma = float(gamma)
        self.alpha = float(alpha)
        self.integral_rate = float(integral_rate)
        self.power = 4.0 if self.integral_rate > 0.0 else 2.0
        self.block = 1.0 / self.gamma
        self._bandwidths = {}
        self.reset()

    def reset(self):
        self.factor = 1.0           # gamma in effect / the delay's
        self.frames = 0             # innovations taken (beside those only kept as lags)
        self.index = 0              # frames seen, measured or not
        self.first = None           # capture time of the first innovation taken
        self.last = None            # of the last frame seen
        self.measured = None        # of the last frame measured
        self.lags = []              # (index, nu) of the last two frames measured
        self.sums = [0.0, 0.0, 0.0]         # weight, nu^2, nu_k nu_j (j <= k - 2)
        self.intervals = [0.0, 0.0]         # weight, interval between frames
        self.blocks = [0.0, 0.0]    # weight, mean square of the block means less sigma^2 / n
        self.block_start = None     # capture time of the block's first frame
        self.block_sum = None       # the block's sum of x_c - x_d per coordinate
        self.block_n = 0
        self.block_count = 0

    def bandwidth(self, factor):
        """b of :func:`noise_bandwidth` at gamma x ``factor``, alpha as it is."""
        key = round(100.0 * log(factor))    # cached per 1 % of the factor
        b = self._bandwidths.get(key)
        if b is None:
            ratio = self.alpha / (self.gamma * exp(key / 100.0))
            b = self._bandwidths[key] = noise_bandwidth(ratio, self.integral_rate)
        return b

    @property
    def trusted(self):
        """Whether a whole window of frames (and MIN_FRAMES) has been measured."""
        return (self.frames >= MIN_FRAMES and self.first is not None
                and self.last - self.first >= self.window)

    @property
    def sigma(self):
        """The measured pixel noise per image coordinate [px] (NaN before it is trusted)."""
        if not self.trusted:
            return float("nan")
        w, s0, s2 = self.sums
        return (max(s0 - s2, 0.0) / (2.0 * w)) ** 0.5

    @property
    def interval(self):
        """The frames' mean interval [s] (NaN before it is trusted)."""
        w, total = self.intervals
        return total / w if self.trusted else float("nan")

    @property
    def tracking_error(self):
        """RMS tracking error per coordinate the frames show, noise removed [px] (NaN: not yet)."""
        w, v = self.blocks
        if not self.trusted or self.block_count < 2:
            return float("nan")
        return (max(v, 0.0) / w) ** 0.5

    def noise_error(self):
        """sqrt N: the error the noise leaves at the gamma in effect [px per coordinate]."""
        sigma, factor = self.sigma, self.factor
        return (sigma * sigma * self.interval * self.bandwidth(factor) * self.gamma
                * factor) ** 0.5

    def target(self):
        """The factor that minimises N + M (module docstring), within [min_factor, 1]."""
        sigma, error = self.sigma, self.tracking_error
        if not (sigma > 0.0 and error == error):    # no noise measured, or not yet
            return 1.0
        noise = self.noise_error() ** 2
        model = max(error * error - noise, 0.0)
        p = self.power
        factor = self.factor * (p * model / noise) ** (1.0 / (p + 1.0))
        return max(self.min_factor, min(1.0, factor))

    def due(self, stamp):
        """Whether the frame captured at ``stamp`` is to be measured (MEASURE_INTERVAL)."""
        return self.measured is None or stamp - self.measured >= MEASURE_INTERVAL - 1e-9

    def skip(self, stamp):
        """Count a frame that is not measured (its capture time: the frames' interval)."""
        self._seen(stamp)

    def _seen(self, stamp):
        if self.last is not None:
            dt = stamp - self.last
            w = exp(-dt / self.window)
            self.intervals[0] = w * self.intervals[0] + 1.0
            self.intervals[1] = w * self.intervals[1] + dt
        self.last = stamp
        self.index += 1

    def frame(self, stamp, innovation, error):
        """Measure the frame captured at ``stamp``: its innovation and x_c - x_d, (2m,) each.

        Returns the factor, which follows the target in log scale at 1 / window down, at
        RAISE / window up.
        """
        self._seen(stamp)
        nu = np.asarray(innovation, dtype=float)
        m = nu.shape[0]
        index, lags = self.index, self.lags
        # the innovation's partner: the latest measured at least two frames back (then they
        # share no frame's noise): the one before if a frame was skipped between, else the
        # one before that
        partner = None
        if lags and lags[-1][0] <= index - 2:
            partner = lags[-1][1]
        elif len(lags) == 2:
            partner = lags[0][1]
        dt = None if self.measured is None else stamp - self.measured
        if partner is not None:
            w = exp(-dt / self.window)
            s = self.sums
            s[0] = w * s[0] + 1.0
            s[1] = w * s[1] + nu.dot(nu) / m
            s[2] = w * s[2] + nu.dot(partner) / m
            if self.first is None:
                self.first = stamp
            self.frames += 1
        self.measured = stamp
        self.lags = [lags[-1], (index, nu)] if lags else [(index, nu)]
        self._block(stamp, np.asarray(error, dtype=float))
        if partner is not None:
            target = self.target()
            if target != self.factor:
                step = min(1.0, dt / self.window * (RAISE if target > self.factor else 1.0))
                self.factor = exp(log(self.factor) + step * (log(target) - log(self.factor)))
        return self.factor

    def _block(self, stamp, error):
        """Add x_c - x_d to the block; close it after 1/gamma, once the noise is measured."""
        if self.block_start is None:
            self.block_start, self.block_sum, self.block_n = stamp, error.copy(), 1
            return
        self.block_sum += error
        self.block_n += 1
        length = stamp - self.block_start
        if length < self.block:
            return
        sigma, n = self.sigma, self.block_n
        if sigma == sigma:
            mean = self.block_sum / n
            square = mean.dot(mean) / mean.shape[0] - sigma * sigma / n
            w = exp(-length / self.window)
            self.blocks[0] = w * self.blocks[0] + 1.0
            self.blocks[1] = w * self.blocks[1] + square
            self.block_count += 1
        self.block_start, self.block_sum, self.block_n = None, None, 0
