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

"""The image position between camera frames, predicted from joint measurements only.

A real camera delivers frames at 30-60 Hz, 20-100 ms after capture, while the
joints are measured at 0.5-1 kHz.  The paper's own kinematic model predicts how
the features move: ``x_dot = Z^-1 J(q, x) q_dot`` (eq (4)), which with the
current estimates is the observer's model term of eq (10),

    x_hat_dot = Z_hat^-1 J_hat(q, x_hat) q_dot
              = (J_perp_hat q_dot - x_hat * Z_hat_dot) / Z_hat      (per image coordinate)

using J_hat(q, x) q_dot = J_perp_hat q_dot - X Z_hat_dot (eq (a1) with
J_z_hat q_dot = Z_hat_dot).  :class:`FramePredictor` keeps a short ring buffer of
the joint samples -- for each, the time and the three quantities that define
the prediction rate there (J_perp_hat q_dot, Z_hat_dot and Z_hat, computed with
the estimates the controller had then) -- and:

* between frames, advances x_hat by one forward-Euler step per joint sample,
  exactly as the controller advances its own state;
* when a frame captured at t_c arrives (late), sets x_hat(t_c) = x_c and re-runs
  the prediction from t_c to now over the buffer, the way a delayed-measurement
  filter re-runs its prediction (the stored predictions after t_c are replaced,
  so the next frame is blended against what was really predicted for it).

Two filters act on the innovation nu = x_c - x_hat^-(t_c), the frame minus
what was predicted for its capture time (see docs/latency.md for the measured
effect of each):

* ``gain`` < 1 blends the frame into the prediction instead of resetting it,
  x_hat(t_c) = x_hat^-(t_c) + gain nu: it averages pixel noise over frames but
  lets the prediction carry the estimates' error longer;
* ``drift_gain`` > 0 learns the prediction's drift, a rate b added to the model
  term (x_hat_dot = Z_hat^-1 J_hat q_dot + b) and updated at each frame by
  b += drift_gain nu / (t_c - t_c,previous): while the kinematic estimates are
  still wrong, the model term is biased, and over a 50 ms latency that bias is
  the largest error left; b removes its slowly varying part.
"""

from __future__ import annotations

import bisect

import numpy as np

#: two stamps closer than this are the same instant [s]
TIME_EPS = 1e-9


class FramePredictor:
    """Ring buffer of joint samples and the predicted image position x_hat.

    Parameters
    ----------
    horizon : float
        How far back a frame may be captured and still be applied [s]; older
        frames are refused (:meth:`check_stamp`).
    gain : float
        Weight of a frame against the prediction at its capture time (1: reset).
    """

    def __init__(self, horizon, gain=1.0, drift_gain=0.0):
        self.horizon = float(horizon)
        self.gain = float(gain)
        self.drift_gain = float(drift_gain)
        self.drift = 0.0            # b, (2m,) once a frame has been applied twice
        # lists, not deques: a late frame needs random access (bisect, slices); the front is
        # cut in batches (_trim), so appending stays O(1) amortised
        self.times = []             # joint-sample times, increasing
        self.rates = []             # (J_perp q_dot, Z_dot, Z) per sample, (3, 2m)
        self.history = []           # x_hat at each sample (None before the first frame)
        self.last_stamp = None      # capture time of the last applied frame

    def reset(self):
        self.times.clear()
        self.rates.clear()
        self.history.clear()
        self.last_stamp = None
        self.drift = 0.0

    @property
    def x_hat(self):
        """The prediction at the last sample (None before the first frame)."""
        return self.history[-1] if self.history else None

    def check_stamp(self, stamp, t):
        """None if a frame captured at ``stamp`` can be applied at joint time ``t``, else why."""
        if stamp > t + TIME_EPS:
            return f"stamped {stamp:.6f} s, in the future of the joint sample at {t:.6f} s"
        if self.last_stamp is not None and stamp <= self.last_stamp + TIME_EPS:
            return (f"stamped {stamp:.6f} s, not after the last applied frame "
                    f"({self.last_stamp:.6f} s)")
        oldest = self._oldest()
        if stamp < t - TIME_EPS and (oldest is None or stamp < oldest - TIME_EPS
                                     or t - stamp > self.horizon + TIME_EPS):
            oldest = "none" if oldest is None else f"{oldest:.6f} s"
            return (f"stamped {stamp:.6f} s, {t - stamp:.3f} s old: older than the joint "
                    f"buffer (horizon {self.horizon:g} s, oldest sample {oldest})")
        return None

    def _oldest(self):
        """The time of the oldest sample in the buffer (None when it is empty)."""
        return self.times[0] if self.times else None

    def _advance(self, x, dt, rate):
        jq, z_dot, z = rate
        return x + dt * ((jq - x * z_dot) / z + self.drift)

    def predict(self, t):
        """x_hat at ``t`` from the last sample's rate (None before the first frame)."""
        x = self.x_hat
        if x is None:
            return None
        return self._advance(x, t - self.times[-1], self.rates[-1])

    def prior(self, stamp, t):
        """x_hat predicted at ``stamp`` before the frame captured then is applied.

        None before the first frame.  ``stamp`` must have passed :meth:`check_stamp`
        for joint time ``t``; the innovation of that frame is the frame minus this.
        """
        if stamp >= t - TIME_EPS:
            return self.predict(stamp)
        return self._before(stamp)[1]

    def _before(self, stamp):
        """(i, x_hat at ``stamp`` from sample i): i the last buffered sample at or before it."""
        i = bisect.bisect_right(self.times, stamp + TIME_EPS) - 1
        x = self.history[i]
        return i, None if x is None else self._advance(x, stamp - self.times[i], self.rates[i])

    def correct(self, stamp, x_frame, t):
        """x_hat at ``t`` with the frame captured at ``stamp`` applied.

        ``stamp`` must have passed :meth:`check_stamp`.  The predictions stored for
        the samples after the stamp are replaced by the re-run ones; the result at
        ``t`` is returned and becomes the prediction once :meth:`commit` stores t.
        """
        x_frame = np.asarray(x_frame, dtype=float)
        if stamp >= t - TIME_EPS:
            if self.gain >= 1.0 and self.drift_gain == 0.0:
                return x_frame.copy()         # a frame of now resets: nothing to predict
            prior = self.predict(t)
            self._learn_drift(prior, x_frame, stamp)
            return self._blend(prior, x_frame)
        i, prior = self._before(stamp)
        self._learn_drift(prior, x_frame, stamp)
        x = self._blend(prior, x_frame)
        # the Euler steps x_{k+1} = x_k + dt_k (jq_k - x_k z_dot_k) / z_k + dt_k b are affine,
        # x_{k+1} = a_k x_k + c_k: with P_k the running product of the a_k, every step of
        # the re-run is x_k = P_k (x + sum_{j<k} c_j / P_{j+1}) -- a few array operations
        # instead of a Python loop over the buffer (~2 us a sample)
        times = self.times[i:] + [t]
        dt = np.diff(times)
        dt[0] = times[1] - stamp
        jq, z_dot, z = np.stack(self.rates[i:], axis=1)
        a = 1.0 - dt[:, None] * z_dot / z
        c = dt[:, None] * (jq / z + self.drift)
        P = np.cumprod(a, axis=0)
        steps = P * (x + np.cumsum(c / P, axis=0))                 # x at times[1:]
        self.history[i + 1:] = list(steps[:-1])
        return steps[-1]

    def _learn_drift(self, prior, x_frame, stamp):
        if self.drift_gain > 0.0 and prior is not None and self.last_stamp is not None:
            interval = stamp - self.last_stamp
            self.drift = self.drift + self.drift_gain * (x_frame - prior) / interval

    def _blend(self, prior, x_frame):
        if prior is None or self.gain >= 1.0:
            return x_frame.copy()
        return prior + self.gain * (x_frame - prior)

    def commit(self, t, x_hat, rate, applied_stamp=None):
        """Store the joint sample at ``t``: its prediction x_hat(t) and its prediction rate.

        ``rate`` is ``(J_perp_hat q_dot, Z_hat_dot, Z_hat)`` at t, (2m,) each, with
        the estimates used at t.  ``applied_stamp``: the frame applied at this sample.
        """
        self.times.append(t)
        # one (3, 2m) array: stacking a re-run is cheap; not copied when it is one (the
        # tracker's are new arrays, never written afterwards)
        self.rates.append(np.asarray(rate, dtype=float))
        self.history.append(x_hat)
        if applied_stamp is not None:
            self.last_stamp = applied_stamp
        if t - self.times[0] > 1.5 * self.horizon:
            self._trim(t)

    def _trim(self, t):
        trim_buffers(self.times, t, self.horizon, self.rates, self.history)


def trim_buffers(times, t, horizon, *columns):
    """Drop the joint samples older than ``horizon`` before ``t`` (keeping one at or before it).

    ``times`` is increasing; each of ``columns`` is a list with one entry per time.
    """
    first = first_kept(times, t, horizon)
    del times[:first]
    for column in columns:
        del column[:first]


def first_kept(times, t, horizon):
    """How many of the increasing ``times`` (a list or an array) :func:`trim_buffers` drops."""
    return max(bisect.bisect_left(times, t - horizon - TIME_EPS) - 1, 0)
