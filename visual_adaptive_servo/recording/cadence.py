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

"""Which samples' messages go out: a rate gate on the samples' own time stamps.

``controller_node`` runs at every joint state (1 kHz for the iiwa) but publishes
its state topics at ``publish_rate`` and ``/diagnostics`` at ``diagnostics_rate``;
:class:`RateGate` picks the samples.  It works on the samples' stamps (sim time in
simulation), not on a clock read at the callback, so the same run publishes the
same samples every time and a test can say which.
"""

from __future__ import annotations

import math

from ..schema import ConfigError

STAMP_RESOLUTION = 1e-9   # s: stamps are integer nanoseconds


def checked_rate(name, value):
    """``value`` as a float; ConfigError naming ``name`` unless it is a positive finite rate."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{name}: must be a number of Hz, got {value!r}")
    if not (math.isfinite(value) and value > 0.0):
        raise ConfigError(f"{name}: must be a positive finite rate [Hz], got {value!r}")
    return float(value)


class RateGate:
    """Lets samples through at ``rate`` Hz of their stamps, on a fixed grid.

    :meth:`due` is True for the first sample and then for the first sample at or
    after each grid instant ``t0 + k / rate`` (k = 1, 2, ...), ``t0`` the first
    sample's stamp.  With samples every T and ``rate`` < 1/T, on average ``rate``
    of them pass per second: at 1 kHz and 100 Hz every 10th, at 1 kHz and 300 Hz
    the 0th, 4th, 7th, 10th, 14th, ...; at ``rate`` >= 1/T every sample.  After a
    gap longer than a period the next sample passes and the grid moves on past
    the gap (no burst).  A stamp before the last one let through (time went back:
    a new simulation) starts a new grid there.
    """

    def __init__(self, rate, name="rate"):
        self.period = 1.0 / checked_rate(name, rate)
        self.t0 = None        # stamp of the grid's origin [s]
        self.last = None      # stamp of the last sample let through [s]
        self.next_k = 1       # index of the next grid instant

    def due(self, t):
        """Whether the sample stamped ``t`` [s] goes out (and if so, count it as sent)."""
        if self.t0 is None or t < self.last:
            self.t0, self.last, self.next_k = t, t, 1
            return True
        if t < self.t0 + self.next_k * self.period - STAMP_RESOLUTION:
            return False
        # the first grid instant after t: floor, with the stamps' resolution as margin
        self.next_k = math.floor((t - self.t0 + STAMP_RESOLUTION) / self.period) + 1
        self.last = t
        return True
