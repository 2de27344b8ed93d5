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

"""The image-motion scale: how much faster the features move than the estimated model says.

The initial kinematic estimates of an uncalibrated camera are off by a factor
of 2 or more in focal length and depth; the paper's adaptation (eqs (24), (25))
corrects them, but slowly, and meanwhile every image velocity the controller
maps to joint velocities is off by that factor: the reference velocity of
eq (18) is too fast or too slow by the ratio of the true to the estimated image
Jacobian, so is the loop gain, and a slow camera's loop has little margin for
that (docs/robust_adaptation.md).

:class:`MotionScale` estimates one positive scalar s from the camera frames:
the regression of each frame's pixels on the image path the estimated model
predicts from the joints alone,

    P(t) = integral of Z_hat^-1 J_hat(q, x_hat) q_dot dt   (the unscaled model rate),
    x_c - mean(x_c) = s (P(t_c) - mean(P(t_c)))            (per image coordinate),

over an exponentially weighted window of frames (``window`` seconds): pixel
noise is averaged over every frame in the window, and the per-coordinate means
absorb where the points are, so s does not depend on the pixel origin.  The
regression is only trusted once the predicted path moved ``min_motion`` px
(RMS per coordinate) within the window.  s follows the regression smoothly,
``d ln s / dt = rate (ln s_target - ln s)``, bounded to ``[lower, upper]``,
so its time derivative is known and eq (19) stays the exact derivative of
eq (18) (:func:`~.controller.control_law`, argument ``motion_scale``).

Until the first trusted regression nothing says how fast the image really
moves, and a guessed camera whose image motion is too slow makes the joints
run past what the observer follows.  ``start_factor`` phi >= 1 slows the
reference alone at the start: eq (18) maps x_r_dot / (s phi), phi held at
``start_factor`` until the first trusted regression and then decaying to 1,
``d ln phi / dt = -rate ln phi`` (the reference's rate is exact again); the
observer and the adaptation keep s (:attr:`MotionScale.reference`).
"""

from __future__ import annotations

import bisect
from math import exp, log, sqrt

import numpy as np

from .prediction import TIME_EPS, trim_buffers


class MotionScale:
    """The scale s of the estimated image motion, learnt from camera frames.

    Parameters
    ----------
    window : float
        Time constant of the frames' exponential weighting [s].
    rate : float
        How fast s follows the regression [1/s].
    lower, upper : float
        Bounds of s (and of the regression's value).
    min_motion : float
        RMS per image coordinate the predicted path must have moved within the
        window before the regression is trusted [px].
    horizon : float
        How far back a frame may be captured (the path buffer keeps this much) [s].
    initial : float
        s before the first trusted regression, and after a reset.  Above 1 the
        loop starts slower than designed: that helps when the guessed camera's
        image motion is too slow (the loop would run past its observer) and costs
        an observer lag when the guess is right (docs/robust_adaptation.md).
    start_factor : float
        phi >= 1 of the reference's slow start (module docstring): 1 is off.
    """

    def __init__(self, window, rate, lower, upper, min_motion, horizon, initial=1.0,
                 start_factor=1.0):
        if not start_factor >= 1.0:
            raise ValueError(f"start_factor must be at least 1, got {start_factor}")
        self.window = float(window)
        self.rate = float(rate)
        self.lower, self.upper = float(lower), float(upper)
        self.min_motion = float(min_motion)
        self.horizon = float(horizon)
        self.initial = float(initial)
        self.start_factor = float(start_factor)
        self.reset()

    def reset(self):
        self._reset_fit()
        # per joint sample (lists of Python floats: 2m = 2 to 6 values, for which each numpy
        # call costs more than its arithmetic; called at every joint sample and frame)
        self.times = []             # joint-sample times of the path
        self.path = []              # P at those times, (2m,) each
        self.speed = []             # the unscaled model rate there, (2m,) each

    def _reset_fit(self):
        """s, the regression's value and its sums back to the start (not the path)."""
        self.value = self.initial   # s
        self.target = self.initial  # the regression's value, once trusted
        self.weight = 0.0           # the frames' total weight w in the regression
        self.sums = None            # weighted sums (x, P, xP, PP) of the regression, 4 x (2m,)
        self.t_frame = None         # capture time of the last frame in the sums
        self.factor = self.start_factor  # phi of the reference's slow start
        self.trusted = False        # a regression has been trusted since the reset

    @property
    def derivative(self):
        """ds/dt at the current value."""
        return self.rate * self.value * (log(self.target) - log(self.value))

    @property
    def reference(self):
        """(s phi, d(s phi)/dt): the scale eq (18) maps the reference velocity with."""
        return self.scales()[2:]

    def scales(self):
        """(s, ds/dt, s phi, d(s phi)/dt), ds/dt computed once (every control sample)."""
        s, s_dot, phi = self.value, self.derivative, self.factor
        if phi == 1.0:
            return s, s_dot, s, s_dot
        phi_dot = -self.rate * phi * log(phi) if self.trusted else 0.0
        return s, s_dot, s * phi, s_dot * phi + s * phi_dot

    def advance(self, dt):
        """Move s toward the regression's value, phi toward 1 once trusted, over dt (exact)."""
        decay = None
        if self.target != self.value:
            decay = exp(-self.rate * dt)
            ln_s = log(self.target) + (log(self.value) - log(self.target)) * decay
            self.value = exp(ln_s)
        if self.trusted and self.factor != 1.0:
            if decay is None:
                decay = exp(-self.rate * dt)
            self.factor = exp(log(self.factor) * decay)

    def record(self, t, speed):
        """Extend the predicted path to joint time t; ``speed`` is the unscaled model rate at t."""
        speed = list(speed) if isinstance(speed, list) else np.asarray(speed, dtype=float).tolist()
        if self.times:
            h = t - self.times[-1]
            p = [a + h * b for a, b in zip(self.path[-1], self.speed[-1])]
        else:
            p = [0.0] * len(speed)
        self.times.append(t)
        self.path.append(p)
        self.speed.append(speed)
        if t - self.times[0] > 1.5 * self.horizon:
            trim_buffers(self.times, t, self.horizon, self.path, self.speed)

    def path_at(self, stamp):
        """P at ``stamp``, (2m,) (None before the first joint sample at or before it)."""
        p = self._path_at(stamp)
        return None if p is None else np.array(p)

    def _path_at(self, stamp):
        i = bisect.bisect_right(self.times, stamp + TIME_EPS) - 1
        if i < 0:
            return None
        h = stamp - self.times[i]
        return [a + h * b for a, b in zip(self.path[i], self.speed[i])]

    def frame(self, stamp, x):
        """Add the frame captured at ``stamp`` to the regression; the new target or None."""
        p = self._path_at(stamp)
        if p is None or (self.t_frame is not None and stamp <= self.t_frame):
            return None
        x = np.asarray(x, dtype=float).tolist()
        # the same arithmetic, element by element, as the numpy expressions in the comments
        if self.sums is None:
            self.weight, decay = 0.0, 0.0
            sx = sp = sxp = spp = [0.0] * len(x)
        else:
            decay = exp(-(stamp - self.t_frame) / self.window)
            sx, sp, sxp, spp = self.sums
        self.t_frame = stamp
        w = self.weight = decay * self.weight + 1.0
        sx = [decay * a + b for a, b in zip(sx, x)]                     # decay sx + x
        sp = [decay * a + b for a, b in zip(sp, p)]                     # decay sp + p
        sxp = [decay * a + b * c for a, b, c in zip(sxp, x, p)]         # decay sxp + x p
        spp = [decay * a + b * b for a, b in zip(spp, p)]               # decay spp + p**2
        self.sums = (sx, sp, sxp, spp)
        var_p = [b / w - (a / w) * (a / w) for a, b in zip(sp, spp)]  # spp/w - (sp/w)**2
        total = _numpy_sum(var_p)
        if not total / len(var_p) > max(self.min_motion ** 2, 1e-12):   # np.mean(var_p)
            return None
        cov = _numpy_sum([c / w - a * b / w**2 for a, b, c in zip(sx, sp, sxp)])
        s = cov / total
        self.target = min(max(s, self.lower), self.upper)
        self.trusted = True
        return self.target


def _numpy_sum(values):
    """np.sum of a list of floats, bit for bit: numpy adds fewer than 8 in order."""
    if len(values) >= 8:
        return float(np.sum(values))
    return sum(values)


#: :class:`MotionRatio` extends its paths at most this often [s] (a 200 Hz loop: every sample)
RATIO_RECORD_INTERVAL = 0.005
#: and fits frames captured at least this far apart [s] (a 30-60 Hz camera: every frame)
RATIO_FIT_INTERVAL = 0.01
#: the evidence test of MotionRatio judges a fit only when one scale leaves more than this
#: share of the frames' noise beyond it: below, no residual tells a ratio from another error
EVIDENCE_SIGNIFICANT = 0.5
#: with the significance test in charge, the normal matrix only has to be invertible
CONDITION_FLOOR = 1e-9


class MotionRatio:
    """How far the estimated camera's two parts disagree, learnt from the frames' motion.

    The model's image rate per coordinate is A + B: A = Z_hat^-1 J_hat_perp q_dot, the part
    of eq (a1) carried by a_z_perp, and B = -Z_hat^-1 x Z_hat_dot, the part carried by
    a_z.  An initial a_z_perp too large or too small *relative to* a_z (a scale common to
    both is the projection matrix's own, unobservable and harmless) makes A wrong by a
    factor while B stays right, an error no single scale of A + B (:class:`MotionScale`)
    removes.  This fits, over the same exponentially weighted window of frames,

        x_c - mean(x_c) = k1 (P_A(t_c) - mean) + k2 (P_B(t_c) - mean),

    P_A, P_B the paths of A and B (per image coordinate, pooled), and at every frame
    scales a_z_perp by rho^(rate dt), rho = k1 / k2 bounded to ``[lower, upper]`` and
    dt the time since the last frame (at most 1/rate): a_z_perp is moved toward the
    value whose A fits the frames.  The stored A paths are scaled with it, so the fit
    keeps measuring the remaining ratio.  No step until the paths moved ``min_motion``
    px (RMS per coordinate) within the window, while A and B are not independent
    enough to tell apart (the 2 x 2 normal matrix' eigenvalues further apart than
    1 / ``condition``), while k1 or k2 is below ``lower`` (frames that hardly move
    where the model says they should tell no ratio), and while k2 is outside
    ``[1/band, band]``: estimates off by c r (a_z_perp) and c (a_z) leave B exact, c
    cancelling in Z_hat_dot / Z_hat, so a B far off says the error is another one (a
    guessed camera moved or turned), which a step of a_z_perp does not correct.  With
    ``evidence`` > 0 and the frames' noise measured, no step either while the two-part fit
    explains less than that share of what one scale leaves beyond the noise
    (:meth:`_evident`).  With ``significance`` > 0 and the noise measured, the condition
    gives way to a test of the fit against that noise: a step only while k1 - k2 is that
    many of its standard deviations away from 0 (:meth:`_significant`), so parts of unequal
    size are fitted, and near the truth the noise no longer walks the ratio.

    The steps change an estimate between samples, outside eqs (23)-(25)
    (docs/robust_adaptation.md).  With a frame at every 1 ms sample the paths are
    extended every ``RATIO_RECORD_INTERVAL`` (the speed held in between) and frames
    captured at least ``RATIO_FIT_INTERVAL`` apart are fitted: a 1 s window still holds
    100 frames, and the ratio costs the 1 kHz step a few us instead of ~25.
    """

    def __init__(self, window, rate, lower, upper, min_motion, horizon, condition, band,
                 evidence=0.0, significance=0.0):
        self.window = float(window)
        self.rate = float(rate)
        self.lower, self.upper = float(lower), float(upper)
        self.min_motion = float(min_motion)
        self.horizon = float(horizon)
        self.condition = float(condition)
        self.band = float(band)
        self.evidence = float(evidence)
        self.significance = float(significance)
        self.reset()

    def reset(self):
        # per joint sample, lists of Python floats (as MotionScale's path: cheap at 1 kHz).
        # The A path and speeds are kept in the units of the estimate at the reset: times
        # ``self.total`` they are what the current a_z_perp gives, so a step rescales them
        # all at once
        self.times, self.path_a, self.path_b, self.speed_a, self.speed_b = [], [], [], [], []
        self.sums = None            # weighted sums, each (2m,) of: 1, x, a, b, xa, xb, aa,
        self.t_frame = None         # ab, bb, xx; capture time of the last frame in them
        self.weight2 = 0.0          # the sum of the squared frame weights (with sums[0])
        self.ratio = 1.0            # the last fitted rho (1: none yet)
        self.fit = None             # the last (k1, k2) fitted, stepped on or not
        self.total = 1.0            # the product of every step applied since the reset
        self.shown = float("nan")   # the share the last evidence test found (see _evident)
        self.spread = float("nan")  # the sd of k1 - k2 the last significance test found

    def due(self, t):
        """Whether :meth:`record` takes a joint sample at time t (RATIO_RECORD_INTERVAL)."""
        return not self.times or t - self.times[-1] >= RATIO_RECORD_INTERVAL - TIME_EPS

    def record(self, t, speed_a, speed_b):
        """Extend the two paths to joint time t with the model's A and B there, (2m,) each.

        A sample less than RATIO_RECORD_INTERVAL after the last one taken is skipped (see
        :meth:`due`): the last speeds hold over the interval.
        """
        if not self.due(t):
            return
        unit = 1.0 / self.total
        speed_a = [v * unit for v in speed_a]
        speed_b = list(speed_b)
        if self.times:
            h = t - self.times[-1]
            pa = [p + h * v for p, v in zip(self.path_a[-1], self.speed_a[-1])]
            pb = [p + h * v for p, v in zip(self.path_b[-1], self.speed_b[-1])]
        else:
            pa, pb = [0.0] * len(speed_a), [0.0] * len(speed_b)
        self.times.append(t)
        self.path_a.append(pa)
        self.path_b.append(pb)
        self.speed_a.append(speed_a)
        self.speed_b.append(speed_b)
        if t - self.times[0] > 1.5 * self.horizon:
            trim_buffers(self.times, t, self.horizon, self.path_a, self.path_b, self.speed_a,
                         self.speed_b)

    def _paths_at(self, stamp):
        """(P_A, P_B) at ``stamp`` with the current a_z_perp, lists; None before the first."""
        i = bisect.bisect_right(self.times, stamp + TIME_EPS) - 1
        if i < 0:
            return None
        h, unit = stamp - self.times[i], self.total
        pa = [unit * (p + h * v) for p, v in zip(self.path_a[i], self.speed_a[i])]
        pb = [p + h * v for p, v in zip(self.path_b[i], self.speed_b[i])]
        return pa, pb

    def frame(self, stamp, x, noise=None):
        """Add the frame captured at ``stamp``; the factor to scale a_z_perp by now (1: none).

        ``noise``: a callable giving the frames' pixel noise variance per coordinate [px^2]
        as measured, or None until it is (None: never measured); the evidence test
        (``evidence``) and the significance test (``significance``) run only once it is
        known, and it is asked only for the frames fitted, not for the 9 of 10 skipped at
        1 kHz.  Python floats throughout (2m <= 6 values a coordinate, a 2 x 2 system):
        numpy's per-call cost would be most of the work.
        """
        if self.t_frame is not None and stamp < self.t_frame + RATIO_FIT_INTERVAL - TIME_EPS:
            return 1.0                  # (before the paths: 9 of 10 frames at 1 kHz)
        paths = self._paths_at(stamp)
        if paths is None:
            return 1.0
        a, b = paths
        if self.sums is None:
            decay, dt = 0.0, 0.0
        else:
            decay = exp(-(stamp - self.t_frame) / self.window)
            dt = stamp - self.t_frame
        self.t_frame = stamp
        self.weight2 = decay * decay * self.weight2 + 1.0
        c_aa, c_bb, c_ab, c_xa, c_xb, c_xx = self._moments(decay, x, a, b)
        if not (c_aa + 2.0 * c_ab + c_bb) / len(a) > max(self.min_motion ** 2, 1e-12):
            return 1.0
        variance = (noise() if noise is not None
                    and (self.evidence > 0.0 or self.significance > 0.0) else None)
        tested = self.significance > 0.0 and variance is not None
        # the 2 x 2 normal matrix [[c_aa, c_ab], [c_ab, c_bb]]: its eigenvalues, its solution.
        # With the noise measured, the significance test says whether the fit is determined;
        # until then (or without it) the condition does
        mean, half = 0.5 * (c_aa + c_bb), sqrt(0.25 * (c_aa - c_bb) ** 2 + c_ab * c_ab)
        if not (mean - half > (CONDITION_FLOOR if tested else self.condition) * (mean + half)):
            return 1.0
        det = c_aa * c_bb - c_ab * c_ab
        k1 = (c_bb * c_xa - c_ab * c_xb) / det
        k2 = (c_aa * c_xb - c_ab * c_xa) / det
        self.fit = (k1, k2)
        if not (k1 >= self.lower and k2 >= self.lower):
            # the frames move far less than either part says: no ratio to tell
            return 1.0
        if not 1.0 / self.band <= k2 <= self.band:
            # a_z_perp and a_z off by factors c r and c leave B exact (c cancels in
            # Z_hat_dot / Z_hat): with B this far off the error is not a ratio
            return 1.0
        if tested and not self._significant(c_aa, c_bb, c_ab, det, k1, k2, variance):
            return 1.0
        if (self.evidence > 0.0 and variance is not None
                and not self._evident(c_aa, c_bb, c_ab, c_xa, c_xb, c_xx, k1, k2,
                                      len(a) * variance)):
            return 1.0
        self.ratio = min(max(k1 / k2, self.lower), self.upper)
        step = exp(min(self.rate * dt, 1.0) * log(self.ratio))
        if step != 1.0:
            self.rescale(step)
        return step

    def _significant(self, c_aa, c_bb, c_ab, det, k1, k2, variance):
        """Whether k1 - k2 (a ratio other than 1) stands out of the noise (``significance``).

        The fit's weighted least squares over n_eff = W1^2 / W2 frames (W1, W2 the sums of
        the frames' weights and of their squares) with the noise sigma^2 per coordinate has
        Cov(k1, k2) = sigma^2 / n_eff G^-1, G the pooled 2 x 2 normal matrix, so
        var(k1 - k2) = sigma^2 / n_eff (c_aa + 2 c_ab + c_bb) / det.  Parts that hardly move
        (or move together) make it large, whatever their scale.
        """
        w1 = self.sums[0][0]
        n_eff = w1 * w1 / self.weight2
        spread = variance / n_eff * (c_aa + 2.0 * c_ab + c_bb) / det
        self.spread = sqrt(spread)
        return (k1 - k2) ** 2 > self.significance ** 2 * spread

    def _evident(self, c_aa, c_bb, c_ab, c_xa, c_xb, c_xx, k1, k2, floor):
        """Whether the frames show a ratio (``evidence``, ``motion_scale.ratio_evidence``).

        left1 = the residual of x_c against one scale of P_A + P_B (what :class:`MotionScale`
        can do), left2 = the residual of the two-part fit; ``floor`` = the pixel noise's share
        of either (2m sigma^2, pooled).  An error that is a ratio leaves left2 at the floor,
        so (left1 - left2) / (left1 - floor) is near 1; a guess moved or turned leaves a
        residual that no ratio explains, and a fit of it is no correction.
        """
        left1 = c_xx - (c_xa + c_xb) ** 2 / (c_aa + 2.0 * c_ab + c_bb)
        left2 = c_xx - (k1 * c_xa + k2 * c_xb)
        excess = left1 - floor
        self.shown = (left1 - left2) / excess if excess > 0.0 else 0.0
        if not excess > EVIDENCE_SIGNIFICANT * floor:
            return True     # no more than the noise left: nothing tells a ratio from another
        return left1 - left2 >= self.evidence * excess

    def _moments(self, decay, x, a, b):
        """Fold the frame x and the paths a, b at its time into the weighted sums.

        Returns the centred (co)variances pooled over the coordinates: c_aa, c_bb, c_ab,
        c_xa, c_xb, c_xx.  (Compiled in :class:`.motion_scale_kernels.BufferedMotionRatio`.)
        """
        x = np.asarray(x, dtype=float).tolist()
        sums = self.sums if self.sums is not None else [[0.0] * len(x) for _ in range(10)]
        new = (None, x, a, b, [u * v for u, v in zip(x, a)], [u * v for u, v in zip(x, b)],
               [u * u for u in a], [u * v for u, v in zip(a, b)], [v * v for v in b],
               [u * u for u in x])
        sums[0] = [decay * w + 1.0 for w in sums[0]]
        for k in range(1, 10):
            sums[k] = [decay * old + value for old, value in zip(sums[k], new[k])]
        self.sums = sums
        w, sx, sa, sb, sxa, sxb, saa, sab, sbb, sxx = sums
        c_aa = c_bb = c_ab = c_xa = c_xb = c_xx = 0.0
        for r in range(len(x)):
            wr = w[r]
            ma, mb, mx = sa[r] / wr, sb[r] / wr, sx[r] / wr
            c_aa += saa[r] / wr - ma * ma
            c_bb += sbb[r] / wr - mb * mb
            c_ab += sab[r] / wr - ma * mb
            c_xa += sxa[r] / wr - mx * ma
            c_xb += sxb[r] / wr - mx * mb
            c_xx += sxx[r] / wr - mx * mx
        return c_aa, c_bb, c_ab, c_xa, c_xb, c_xx

    def rescale(self, step):
        """a_z_perp was scaled by ``step``: so are the A paths and the sums that carry them."""
        self.total *= step
        sums = self.sums
        for k in (2, 4, 7):                 # a, xa, ab
            sums[k] = [step * v for v in sums[k]]
        sums[6] = [step * step * v for v in sums[6]]      # aa
