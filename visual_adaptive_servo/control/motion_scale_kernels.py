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

"""The image-motion scale's path and regression on arrays, compiled with numba.

:class:`.motion_scale.MotionScale` keeps its path in lists of Python floats
and stays the readable reference; :class:`BufferedMotionScale` is the same
scale with the path in preallocated arrays (a start and an end index, the same
trim rule) and a frame's regression in one kernel (:func:`_frame`), with the
same arithmetic in the same order (numpy's pairwise sum where the reference
calls np.sum); :class:`BufferedMotionRatio` does the same for
:class:`.motion_scale.MotionRatio`'s two paths and weighted sums.  The tracker runs
both with the compiled backend (test: test_compiled_law.py).  Importing this module
imports numba.
"""

from __future__ import annotations

import math

import numpy as np

from ..models.kernels import compiled
from .motion_scale import MotionRatio, MotionScale, RATIO_RECORD_INTERVAL
from .prediction import TIME_EPS
from .prediction_kernels import SampleRows


@compiled(inline="always")
def _numpy_sum(values):
    """np.sum of a short float64 array, bit for bit (numpy's pairwise sum below 128 entries)."""
    n = values.shape[0]
    if n < 8:
        total = 0.0
        for i in range(n):
            total += values[i]
        return total
    r = values[:8].copy()
    i = 8
    while i < n - n % 8:
        for j in range(8):
            r[j] += values[i + j]
        i += 8
    total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        total += values[i]
        i += 1
    return total


@compiled(error_model="numpy")
def _frame(times, path, speed, start, end, stamp, x, sums, has_sums, weight, t_frame, window,
           min_motion, lower, upper):
    """MotionScale.frame on the arrays: returns (status, weight, target).

    status 0: nothing done (no path at the stamp, or not after the last frame); 1: the
    frame is in the sums (updated in place) but the regression is not trusted yet; 2:
    ``target`` is the regression's new value.
    """
    i = start + np.searchsorted(times[start:end], stamp + TIME_EPS, side="right") - 1
    if i < start or (has_sums and stamp <= t_frame):
        return 0, weight, 0.0
    m2 = x.shape[0]
    h = stamp - times[i]
    decay = 0.0
    if has_sums:
        decay = math.exp(-(stamp - t_frame) / window)
    else:
        weight = 0.0
        for r in range(4):
            for j in range(m2):
                sums[r, j] = 0.0
    w = decay * weight + 1.0
    var_p = np.empty(m2)
    cov = np.empty(m2)
    for j in range(m2):
        p = path[i, j] + h * speed[i, j]
        sums[0, j] = decay * sums[0, j] + x[j]
        sums[1, j] = decay * sums[1, j] + p
        sums[2, j] = decay * sums[2, j] + x[j] * p
        sums[3, j] = decay * sums[3, j] + p * p
        sp = sums[1, j]
        var_p[j] = sums[3, j] / w - (sp / w) * (sp / w)
        cov[j] = sums[2, j] / w - sums[0, j] * sp / w ** 2
    total = _numpy_sum(var_p)
    if not total / m2 > max(min_motion ** 2, 1e-12):
        return 1, w, 0.0
    s = _numpy_sum(cov) / total
    if lower > s:               # min(max(s, lower), upper) as Python evaluates it
        s = lower
    if upper < s:
        s = upper
    return 2, w, s


@compiled(error_model="numpy")
def _record(times, path, speed, start, end, t, v):
    """MotionScale.record into row ``end``: P extended along the last speed, then v stored."""
    times[end] = t
    for j in range(v.shape[0]):
        if end > start:
            path[end, j] = path[end - 1, j] + (t - times[end - 1]) * speed[end - 1, j]
        else:
            path[end, j] = 0.0
        speed[end, j] = v[j]


class BufferedMotionScale(MotionScale, SampleRows):
    """:class:`.motion_scale.MotionScale` with its path on arrays and its regression compiled."""

    _ROWS = ("_times", "_path", "_speed")

    def __init__(self, window, rate, lower, upper, min_motion, horizon, m2, capacity=512,
                 initial=1.0, start_factor=1.0):
        self.m2 = int(m2)
        self._capacity = int(capacity)
        super().__init__(window, rate, lower, upper, min_motion, horizon, initial, start_factor)
        self._warm_up()

    def _warm_up(self):
        """Compile (or load) the kernels now, not at the first sample of a 1 kHz loop."""
        m2 = self.m2
        times, path, speed = np.array([0.0, 0.001]), np.zeros((2, m2)), np.ones((2, m2))
        _record(times, path, speed, 0, 1, 0.001, np.ones(m2))
        _frame(times, path, speed, 0, 2, 0.0015, np.ones(m2), np.zeros((4, m2)), False, 0.0,
               0.0, self.window, self.min_motion, self.lower, self.upper)

    def reset(self):
        # MotionScale.reset's lists are the arrays here; sums is None or the (4, 2m) array
        self._reset_fit()
        self._allocate(self._capacity)

    @classmethod
    def of(cls, scale, m2):
        """The buffered scale with the state of a list-based one."""
        new = cls(scale.window, scale.rate, scale.lower, scale.upper, scale.min_motion,
                  scale.horizon, m2, max(512, 2 * len(scale.times)), scale.initial,
                  scale.start_factor)
        new._load(scale.times, scale.path, scale.speed)
        new.value, new.target, new.weight, new.t_frame = (scale.value, scale.target,
                                                          scale.weight, scale.t_frame)
        new.factor, new.trusted = scale.factor, scale.trusted
        new.sums = None if scale.sums is None else np.array(scale.sums, dtype=float)
        return new

    def to_lists(self):
        """The list-based :class:`.motion_scale.MotionScale` with this state."""
        other = MotionScale(self.window, self.rate, self.lower, self.upper, self.min_motion,
                            self.horizon, self.initial, self.start_factor)
        a, b = self._start, self._end
        other.times = self._times[a:b].tolist()
        other.path = self._path[a:b].tolist()
        other.speed = self._speed[a:b].tolist()
        other.value, other.target, other.weight, other.t_frame = (self.value, self.target,
                                                                  self.weight, self.t_frame)
        other.factor, other.trusted = self.factor, self.trusted
        other.sums = None if self.sums is None else tuple(self.sums.tolist())
        return other

    def record(self, t, speed):
        end = self.next_row()
        _record(self._times, self._path, self._speed, self._start, end, t,
                np.ascontiguousarray(speed, dtype=float))
        self._keep_row(t)

    def path_at(self, stamp):
        a, b = self._start, self._end
        i = a + int(np.searchsorted(self._times[a:b], stamp + TIME_EPS, side="right")) - 1
        if i < a:
            return None
        return self._path[i] + (stamp - self._times[i]) * self._speed[i]

    @property
    def times(self):
        """The path's joint-sample times (a copy: read-only use)."""
        return self._times[self._start:self._end].tolist()

    def frame(self, stamp, x):
        has_sums = self.sums is not None
        sums = self.sums if has_sums else np.zeros((4, self.m2))
        status, weight, target = _frame(
            self._times, self._path, self._speed, self._start, self._end, stamp,
            np.ascontiguousarray(x, dtype=float), sums, has_sums, self.weight,
            0.0 if self.t_frame is None else self.t_frame, self.window, self.min_motion,
            self.lower, self.upper)
        if status == 0:
            return None
        self.weight, self.t_frame, self.sums = weight, stamp, sums
        if status == 1:
            return None
        self.target, self.trusted = target, True
        return target


@compiled(error_model="numpy")
def _ratio_moments(sums, decay, x, a, b):
    """MotionRatio._moments on a (10, 2m) array: the same arithmetic in the same order."""
    m2 = x.shape[0]
    for r in range(m2):
        sums[0, r] = decay * sums[0, r] + 1.0
        sums[1, r] = decay * sums[1, r] + x[r]
        sums[2, r] = decay * sums[2, r] + a[r]
        sums[3, r] = decay * sums[3, r] + b[r]
        sums[4, r] = decay * sums[4, r] + x[r] * a[r]
        sums[5, r] = decay * sums[5, r] + x[r] * b[r]
        sums[6, r] = decay * sums[6, r] + a[r] * a[r]
        sums[7, r] = decay * sums[7, r] + a[r] * b[r]
        sums[8, r] = decay * sums[8, r] + b[r] * b[r]
        sums[9, r] = decay * sums[9, r] + x[r] * x[r]
    c_aa = c_bb = c_ab = c_xa = c_xb = c_xx = 0.0
    for r in range(m2):
        wr = sums[0, r]
        ma, mb, mx = sums[2, r] / wr, sums[3, r] / wr, sums[1, r] / wr
        c_aa += sums[6, r] / wr - ma * ma
        c_bb += sums[8, r] / wr - mb * mb
        c_ab += sums[7, r] / wr - ma * mb
        c_xa += sums[4, r] / wr - mx * ma
        c_xb += sums[5, r] / wr - mx * mb
        c_xx += sums[9, r] / wr - mx * mx
    return c_aa, c_bb, c_ab, c_xa, c_xb, c_xx


@compiled(error_model="numpy")
def _ratio_record(times, path_a, path_b, speed_a, speed_b, start, end, t, jq, z_dot, z,
                  x_hat, unit):
    """MotionRatio.record into row ``end`` from the model's rate: the same arithmetic.

    A = jq / z times ``unit`` (1 / the steps' product), B = -x_hat z_dot / z; the paths are
    extended along the last speeds first.
    """
    times[end] = t
    h = t - times[end - 1] if end > start else 0.0
    for r in range(jq.shape[0]):
        if end > start:
            path_a[end, r] = path_a[end - 1, r] + h * speed_a[end - 1, r]
            path_b[end, r] = path_b[end - 1, r] + h * speed_b[end - 1, r]
        else:
            path_a[end, r] = 0.0
            path_b[end, r] = 0.0
        speed_a[end, r] = (jq[r] / z[r]) * unit
        speed_b[end, r] = -x_hat[r] * z_dot[r] / z[r]


@compiled(error_model="numpy")
def _ratio_paths_at(times, path_a, path_b, speed_a, speed_b, start, end, stamp, total, a, b):
    """MotionRatio._paths_at into ``a``, ``b``; False before the first sample."""
    i = start + np.searchsorted(times[start:end], stamp + TIME_EPS, side="right") - 1
    if i < start:
        return False
    h = stamp - times[i]
    for r in range(a.shape[0]):
        a[r] = total * (path_a[i, r] + h * speed_a[i, r])
        b[r] = path_b[i, r] + h * speed_b[i, r]
    return True


class BufferedMotionRatio(MotionRatio, SampleRows):
    """:class:`.motion_scale.MotionRatio` with its paths and sums on arrays, run compiled.

    The model's rate goes in as arrays (:meth:`record_rate`), the paths at a frame's capture
    time come out into two reused arrays (:meth:`_paths_at`), and a fitted frame's sums and
    moments, most of its cost, are folded in :func:`_ratio_moments`: no list is made at
    1 kHz.  The fit's decisions stay :meth:`.motion_scale.MotionRatio.frame`'s.  Equal to
    the reference at every sample (test_motion_scale.py, test_compiled_law.py).
    """

    _ROWS = ("_times", "_path_a", "_path_b", "_speed_a", "_speed_b")

    @classmethod
    def of(cls, ratio, m2, capacity=512):
        """This ratio's state (a list-based or a buffered one) on arrays."""
        if isinstance(ratio, BufferedMotionRatio):
            ratio = ratio.to_lists()
        new = cls.__new__(cls)
        state = dict(ratio.__dict__)
        times = state.pop("times", [])
        lists = [state.pop(name, []) for name in ("path_a", "path_b", "speed_a", "speed_b")]
        new.__dict__.update(state)
        if ratio.sums is not None:
            new.sums = np.array(ratio.sums, dtype=float)
        new.m2 = int(m2)
        new._allocate(max(int(capacity), 2 * len(times)))
        new._load(times, *lists)
        new._a, new._b = np.empty(new.m2), np.empty(new.m2)
        new._warm_up()
        return new

    def _warm_up(self):
        """Compile (or load) the kernels now, not at the first frame of a 1 kHz loop."""
        one = np.ones(self.m2)
        arrays = [np.zeros(2), *(np.zeros((2, self.m2)) for _ in range(4))]
        _ratio_record(*arrays, 0, 0, 0.0, one, one, one, one, 1.0)
        _ratio_paths_at(*arrays, 0, 1, 0.0, 1.0, np.empty(self.m2), np.empty(self.m2))
        _ratio_moments(np.zeros((10, self.m2)), 0.0, one, one, one)

    def reset(self):
        # MotionRatio.reset's lists are the arrays here
        super().reset()
        for name in ("times", "path_a", "path_b", "speed_a", "speed_b"):
            del self.__dict__[name]
        self._allocate(self._times.shape[0] if "_times" in self.__dict__ else 512)

    def to_lists(self):
        """The reference MotionRatio with this state."""
        ref = MotionRatio.__new__(MotionRatio)
        ref.__dict__.update(self.__dict__)
        for name in self._ROWS + ("m2", "_a", "_b", "_start", "_end"):
            del ref.__dict__[name]
        ref.__dict__.pop("_t_first", None)
        if self.sums is not None:
            ref.sums = self.sums.tolist()
        a, b = self._start, self._end
        ref.times = self._times[a:b].tolist()
        ref.path_a, ref.path_b = self._path_a[a:b].tolist(), self._path_b[a:b].tolist()
        ref.speed_a, ref.speed_b = self._speed_a[a:b].tolist(), self._speed_b[a:b].tolist()
        return ref

    def due(self, t):
        end = self._end
        return end == self._start or t - self._times[end - 1] >= RATIO_RECORD_INTERVAL - TIME_EPS

    def record(self, t, speed_a, speed_b):
        """MotionRatio.record from speeds A and B (lists or arrays): as the reference."""
        if not self.due(t):
            return
        speed_a, speed_b = np.asarray(speed_a, dtype=float), np.asarray(speed_b, dtype=float)
        ones = np.ones(self.m2)
        # A = (A / 1) * unit, B = -(-B) * 1 / 1: the reference's products, bit for bit
        self._record(t, speed_a, ones, ones, -speed_b)

    def record_rate(self, t, x_hat, jq, z_dot, z):
        """Extend the paths with A = jq / z and B = -x_hat z_dot / z (the model's rate)."""
        if self.due(t):
            self._record(t, jq, z_dot, z, x_hat)

    def _record(self, t, jq, z_dot, z, x_hat):
        end = self.next_row()
        _ratio_record(self._times, self._path_a, self._path_b, self._speed_a, self._speed_b,
                      self._start, end, t, jq, z_dot, z, x_hat, 1.0 / self.total)
        self._keep_row(t)

    def _paths_at(self, stamp):
        a, b = self._a, self._b
        if not _ratio_paths_at(self._times, self._path_a, self._path_b, self._speed_a,
                               self._speed_b, self._start, self._end, stamp, self.total, a, b):
            return None
        return a, b

    def _moments(self, decay, x, a, b):
        if self.sums is None:
            self.sums = np.zeros((10, self.m2))
        return _ratio_moments(self.sums, decay, np.ascontiguousarray(x, dtype=float), a, b)

    def rescale(self, step):
        self.total *= step
        sums = self.sums
        for k in (2, 4, 7):                 # a, xa, ab: step * v, as the reference
            sums[k] *= step
        sums[6] *= step * step              # aa: (step * step) * v
