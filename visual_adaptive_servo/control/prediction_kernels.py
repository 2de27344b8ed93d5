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

"""The frame predictor on preallocated arrays, its steps compiled with numba.

The numpy code of :class:`.prediction.FramePredictor` stays the reference.
:class:`BufferedFramePredictor` is the same predictor with its buffer in
preallocated arrays and its steps compiled: the prediction between frames
(:func:`_predict`) and a late frame's whole correction (:func:`_correct_late`),
whose re-run (:func:`_rerun`) evaluates the reference's closed form,
x_k = P_k (x + sum_{j<k} c_j / P_{j+1}) with a_k = 1 - dt_k Z_dot_k / Z_k,
c_k = dt_k (J_perp q_dot_k / Z_k + b) and P the running product of the a_k, in
the same order (so the same numbers), as one loop instead of ~10 numpy calls and
a stack of the buffer's rate arrays.  The tracker runs it with the compiled
backend.  Importing this module imports numba.
"""

from __future__ import annotations

import numpy as np

from ..models.kernels import compiled
from .prediction import first_kept, FramePredictor, TIME_EPS


@compiled(error_model="numpy")
def _rerun(times, stamp, rates, x, drift):
    """x_hat at ``times[1:]`` from x at ``stamp`` (between times[0] and times[1]).

    ``times`` (k + 1,) the buffer's joint-sample times from the last one at or
    before the stamp, then now; ``rates`` (k, 3, 2m) their (J_perp q_dot, Z_dot,
    Z); ``x`` (2m,) the frame's x_hat at the stamp; ``drift`` b (2m,).  Returns
    (k, 2m).
    """
    k, m2 = rates.shape[0], x.shape[0]
    steps = np.empty((k, m2))
    for j in range(m2):
        P = 1.0
        S = 0.0
        for s in range(k):
            dt = times[s + 1] - (stamp if s == 0 else times[s])
            a = 1.0 - dt * rates[s, 1, j] / rates[s, 2, j]
            c = dt * (rates[s, 0, j] / rates[s, 2, j] + drift[j])
            P = P * a
            S = S + c / P
            steps[s, j] = P * (x[j] + S)
    return steps


@compiled(error_model="numpy")
def _predict(x, rate, dt, drift, out):
    """FramePredictor._advance: out = x + dt ((jq - x z_dot) / z + b)."""
    for j in range(x.shape[0]):
        out[j] = x[j] + dt * ((rate[0, j] - x[j] * rate[1, j]) / rate[2, j] + drift[j])


@compiled(error_model="numpy")
def _correct_late(times, rates, history, has, i, end, stamp, x_frame, t, gain, drift_gain,
                  drift, interval, out):
    """FramePredictor.correct of a frame captured at ``stamp`` before the last sample.

    ``i`` is the buffer's last sample at or before the stamp, ``end`` one past the
    last; ``interval`` the time since the last applied frame (NaN: none, so no drift
    is learnt).  The prediction at the stamp from sample i, the drift learnt from the
    innovation (``drift`` updated in place), the blend, then the re-run of
    :func:`_rerun` from the stamp over samples i .. end-1 and to t: the predictions of
    samples i+1 .. end-1 are replaced in ``history`` (and marked in ``has``), x at t
    written into ``out``.
    """
    m2 = x_frame.shape[0]
    x = np.empty(m2)
    learn = drift_gain > 0.0 and has[i] and interval == interval
    for j in range(m2):
        if has[i]:
            prior = history[i, j] + (stamp - times[i]) * (
                (rates[i, 0, j] - history[i, j] * rates[i, 1, j]) / rates[i, 2, j] + drift[j])
            if learn:
                drift[j] = drift[j] + drift_gain * (x_frame[j] - prior) / interval
            x[j] = x_frame[j] if gain >= 1.0 else prior + gain * (x_frame[j] - prior)
        else:
            x[j] = x_frame[j]
    k = end - i
    times_rerun = np.empty(k + 1)
    times_rerun[:k] = times[i:end]
    times_rerun[k] = t
    steps = _rerun(times_rerun, stamp, rates[i:end], x, drift)
    history[i + 1:end] = steps[:k - 1]
    has[i + 1:end] = True
    out[:] = steps[k - 1]


class SampleRows:
    """Samples in rows ``_start`` to ``_end`` of preallocated arrays, trimmed as the lists are.

    The bookkeeping :class:`BufferedFramePredictor` and the image-motion scale's and ratio's
    buffers (:mod:`.motion_scale_kernels`) share.  A subclass names its arrays in ``_ROWS``
    (``_times`` first) and has ``horizon`` and ``m2``; ``_allocate(capacity)`` makes the
    arrays empty, by default ``_times`` (capacity,) and the others (capacity, m2).  A sample
    is written in the row :meth:`next_row` gives and kept by :meth:`_keep_row`, which drops
    the samples older than ``horizon`` once the oldest is 1.5 ``horizon`` old:
    :func:`.prediction.trim_buffers`' rule for the list-based references, so both keep the
    same samples.  :meth:`_load` fills them from a list-based buffer at once.
    """

    _ROWS = ("_times",)

    def _allocate(self, capacity):
        """Empty arrays of ``capacity`` rows: ``_times`` (capacity,), the others (capacity, m2)."""
        self._times = np.empty(capacity)
        for name in self._ROWS[1:]:
            setattr(self, name, np.empty((capacity, self.m2)))
        self._start = self._end = 0

    def next_row(self):
        """The row the next sample goes in (the arrays compacted or grown first if full)."""
        if self._end == self._times.shape[0]:
            self._make_room()
        return self._end

    def _make_room(self):
        """Move the live samples to the front of the arrays, or double them when full."""
        a, b = self._start, self._end
        live = b - a
        arrays = [getattr(self, name) for name in self._ROWS]
        if live > arrays[0].shape[0] // 2:
            self._allocate(2 * arrays[0].shape[0])
        for name, array in zip(self._ROWS, arrays):
            getattr(self, name)[:live] = array[a:b]
        self._start, self._end = 0, live

    def _keep_row(self, t):
        """Keep the sample at time t written in :meth:`next_row`'s row; trim the oldest."""
        start = self._start
        end = self._end = self._end + 1
        if end - start == 1:
            self._t_first = t            # times[_start] as a float: read at every sample
        if t - self._t_first > 1.5 * self.horizon:
            start = self._start = start + first_kept(self._times[start:end], t, self.horizon)
            self._t_first = float(self._times[start])

    def _load(self, times, *columns):
        """Fill rows 0 to n at once from a list-based buffer's times and columns; keep them."""
        n = len(times)
        self._times[:n] = times
        if n:
            for name, values in zip(self._ROWS[1:], columns):
                getattr(self, name)[:n] = values
        self._start, self._end = 0, n
        self._t_first = float(self._times[0]) if n else 0.0


class BufferedFramePredictor(FramePredictor, SampleRows):
    """:class:`.prediction.FramePredictor` on preallocated arrays, its steps compiled.

    The same predictor (the list-based class stays the reference; equal at every
    sample in test_compiled_law.py): the buffer's times, rates and predictions live
    in arrays with a start and an end index instead of lists, so a late frame's
    re-run reads and replaces them in place (:func:`_correct_late`) instead of
    stacking the buffer's arrays and making one per sample again, and the
    prediction between frames is one kernel call (:func:`_predict`).  The tracker
    runs it with the compiled backend.
    """

    _ROWS = ("_times", "_rates", "_history", "_has")

    def __init__(self, horizon, gain, drift_gain, m2, capacity=512):
        # FramePredictor.__init__ is not called: the arrays below are its buffer
        self.horizon = float(horizon)
        self.gain = float(gain)
        self.drift_gain = float(drift_gain)
        self.drift = 0.0
        self.last_stamp = None
        self.m2 = int(m2)
        self._zeros = np.zeros(self.m2)     # b before any drift is learnt
        self._allocate(int(capacity))
        self._warm_up()

    def _warm_up(self):
        """Compile (or load) the kernels now, not at the first frame of a 1 kHz loop."""
        m2, ones = self.m2, np.ones(self.m2)
        rates = np.ones((2, 3, m2))
        _predict(ones, rates[0], 0.001, self._zeros, np.empty(m2))
        _correct_late(np.array([0.0, 0.001]), rates, np.ones((2, m2)), np.ones(2, np.bool_), 0,
                      2, 0.0005, ones, 0.002, 1.0, 0.0, np.zeros(m2), 1.0, np.empty(m2))

    def _allocate(self, capacity):
        self._times = np.empty(capacity)
        self._rates = np.empty((capacity, 3, self.m2))
        self._rates_flat = self._rates.reshape(capacity, 3 * self.m2)     # a view
        self._history = np.empty((capacity, self.m2))
        self._has = np.zeros(capacity, dtype=np.bool_)
        self._start = self._end = 0

    @classmethod
    def of(cls, predictor, m2):
        """The buffered predictor with the state of a list-based one (the same samples)."""
        new = cls(predictor.horizon, predictor.gain, predictor.drift_gain, m2,
                  max(512, 2 * len(predictor.times)))
        for t, rate, x in zip(predictor.times, predictor.rates, predictor.history):
            new.commit(t, x, rate)
        new.last_stamp, new.drift = predictor.last_stamp, predictor.drift
        return new

    def to_lists(self):
        """The list-based :class:`.prediction.FramePredictor` with this state."""
        other = FramePredictor(self.horizon, self.gain, self.drift_gain)
        a, b = self._start, self._end
        other.times = self._times[a:b].tolist()
        other.rates = [rate.copy() for rate in self._rates[a:b]]
        other.history = [x.copy() if has else None
                         for x, has in zip(self._history[a:b], self._has[a:b])]
        other.last_stamp, other.drift = self.last_stamp, self.drift
        return other

    def reset(self):
        self._start = self._end = 0
        self.last_stamp = None
        self.drift = 0.0

    @property
    def times(self):
        """The buffer's joint-sample times (a copy: read-only use)."""
        return self._times[self._start:self._end].tolist()

    @property
    def x_hat(self):
        end = self._end
        if end == self._start or not self._has[end - 1]:
            return None
        return self._history[end - 1].copy()

    def _oldest(self):
        return None if self._end == self._start else float(self._times[self._start])

    def _drift_array(self):
        drift = self.drift
        if np.ndim(drift) == 0:
            return np.full(self.m2, float(drift))
        return np.array(drift, dtype=float)

    def predict(self, t):
        end = self._end
        if end == self._start or not self._has[end - 1]:
            return None
        out = np.empty(self.m2)
        drift = self.drift
        _predict(self._history[end - 1], self._rates[end - 1], t - self._times[end - 1],
                 self._zeros if isinstance(drift, float) else drift, out)
        return out

    def _index_at(self, stamp):
        """The buffer's row of the last sample at or before ``stamp``."""
        a, b = self._start, self._end
        return a + int(np.searchsorted(self._times[a:b], stamp + TIME_EPS, side="right")) - 1

    def prior(self, stamp, t):
        if stamp >= t - TIME_EPS:
            return self.predict(stamp)
        i = self._index_at(stamp)
        if not self._has[i]:
            return None
        out = np.empty(self.m2)
        drift = self.drift
        _predict(self._history[i], self._rates[i], stamp - self._times[i],
                 self._zeros if isinstance(drift, float) else drift, out)
        return out

    def correct(self, stamp, x_frame, t):
        x_frame = np.asarray(x_frame, dtype=float)
        if stamp >= t - TIME_EPS:
            if self.gain >= 1.0 and self.drift_gain == 0.0:
                # a frame of now resets: nothing to predict; not copied (the list-based
                # predictor keeps x_hat, this one copies it into its buffer)
                return x_frame
            return super().correct(stamp, x_frame, t)
        b = self._end
        i = self._index_at(stamp)
        drift = self._drift_array()
        interval = (stamp - self.last_stamp if self.last_stamp is not None else float("nan"))
        out = np.empty(self.m2)
        _correct_late(self._times, self._rates, self._history, self._has, i, b, stamp,
                      np.ascontiguousarray(x_frame), t, self.gain, self.drift_gain, drift,
                      interval, out)
        if self.drift_gain > 0.0 and self._has[i] and self.last_stamp is not None:
            self.drift = drift
        return out

    def commit(self, t, x_hat, rate, applied_stamp=None):
        self.commit_flat(t, x_hat, np.ravel(rate), applied_stamp)

    def commit_flat(self, t, x_hat, rate, applied_stamp=None):
        """:meth:`commit` with ``rate`` flat: J_perp q_dot, Z_dot, Z end to end (3 x 2m)."""
        end = self.next_row()
        self._times[end] = t
        self._rates_flat[end] = rate
        if x_hat is None:
            self._has[end] = False
        else:
            self._history[end] = x_hat
            self._has[end] = True
        self.stored(t, applied_stamp)

    def store(self):
        """(times, rates flat, history, has, row): where the compiled sample stores a sample.

        :func:`.sample_kernels.sample` writes the row as :meth:`commit_flat` does; then
        :meth:`stored` ends the commit.
        """
        row = self.next_row()           # first: it may compact or grow the arrays
        return self._times, self._rates_flat, self._history, self._has, row

    def stored(self, t, applied_stamp=None):
        """End the commit of the sample at ``t`` written in :meth:`next_row`: keep it, trim."""
        self._keep_row(t)
        if applied_stamp is not None:
            self.last_stamp = applied_stamp
