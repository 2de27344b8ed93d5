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

"""How fresh the commands a realtime loop applies are: periods without a new one, their age.

A wall-clock loop (``sim_node`` in realtime, alone or as a ros2_control hardware)
applies at each period the latest command it has.  When the controller is late,
that command is the previous period's again: the loop goes on and no timeout
fires, so :class:`CommandAge` counts it.  The caller says when a new command
arrives (:meth:`CommandAge.received`, at its wall time) and, at the start of
each period, whether the latest one is applied (:meth:`CommandAge.period`).
Ages go into fixed histograms (constant memory and cost per period however
long the run), so the percentiles are exact in periods and upper bounds to
``resolution`` in seconds.
"""

from __future__ import annotations

import math

import numpy as np

AGE_PERIODS_BINS = 10_000       # ages of 0 .. 9999 periods kept exactly, older ones as "more"
AGE_SECONDS_RESOLUTION = 1e-5   # s: width of a bin of the age in seconds
AGE_SECONDS_RANGE = 1.0         # s covered by the bins of the age in seconds


def _percentiles(counts, values, max_value):
    """median, p99 (the smallest value with that fraction at or below it) and max; inf beyond."""
    total = int(counts.sum())
    if total == 0:
        return {"median": math.nan, "p99": math.nan, "max": math.nan}
    cumulative = np.cumsum(counts)
    out = {}
    for name, fraction in (("median", 0.5), ("p99", 0.99)):
        index = int(np.searchsorted(cumulative, math.ceil(fraction * total)))
        out[name] = float(values[index]) if index < len(values) else math.inf
    out["max"] = float(max_value)
    return out


class CommandAge:
    """Counts the periods of a realtime loop that had no new command, and the applied one's age.

    Definitions (per period, in the order the loop calls them):

    * a period *with a new command* applies a command that arrived since the
      previous period started (:meth:`received` in between);
    * a period *without a new command* is any other period after the first
      command arrived: the previous command applied again, or none applied (zero
      torque after a timeout, the arm held on its brakes); periods before the
      first command are counted apart;
    * the *age* of the applied command: in periods, 0 when new, else one more
      than in the previous period; in seconds, the wall time from its arrival
      to the start of the period it is applied in (:meth:`period`'s ``wall``);
    * a command is *superseded* when a newer one arrived before the next period
      started (more than one arrived between two periods).

    ``resolution`` [s] is the bin width of the age in seconds: its median and p99
    are the upper edge of their bin (at most ``resolution`` above the true value);
    ages in periods are exact up to :data:`AGE_PERIODS_BINS`, beyond it (and
    beyond :data:`AGE_SECONDS_RANGE` in seconds) a percentile is ``inf``.  The
    maxima are exact.
    """

    def __init__(self, resolution=AGE_SECONDS_RESOLUTION):
        if not (math.isfinite(resolution) and resolution > 0.0):
            raise ValueError(f"CommandAge.resolution: must be a positive finite number of "
                             f"seconds, got {resolution!r}")
        self.resolution = resolution
        bins = int(math.ceil(AGE_SECONDS_RANGE / resolution))
        self.seconds_edges = resolution * np.arange(1, bins + 1)   # upper edge of each bin
        self.seconds_counts = np.zeros(bins + 1, dtype=np.int64)   # the last bin: beyond
        self.periods_counts = np.zeros(AGE_PERIODS_BINS + 1, dtype=np.int64)
        self.periods = 0                     # periods since the first command arrived
        self.periods_before_first = 0
        self.with_new = 0
        self.received_count = 0
        self.superseded = 0
        self.max_age_periods = 0
        self.max_age_seconds = 0.0
        self._arrival = None                 # wall time the latest command arrived
        self._unapplied = False              # it arrived since the previous period
        self._age = None                     # periods since the applied command was new

    def received(self, wall):
        """A new command arrived at wall time ``wall`` [s]."""
        if self._unapplied:
            self.superseded += 1
        self.received_count += 1
        self._arrival, self._unapplied = wall, True

    def period(self, wall, applied):
        """A period starts at wall time ``wall`` [s]; ``applied``: with the latest command.

        Returns the applied command's age in periods (None when none was applied).
        """
        if self._arrival is None:
            self.periods_before_first += 1
            return None
        self.periods += 1
        new, self._unapplied = self._unapplied, False
        if new:
            self._age = 0
            self.with_new += int(applied)
        elif self._age is not None:
            self._age += 1
        if not applied or self._age is None:
            return None
        age = self._age
        self.periods_counts[min(age, AGE_PERIODS_BINS)] += 1
        seconds = wall - self._arrival
        # bin k holds (k * resolution, (k + 1) * resolution]; 0 s goes in bin 0
        index = max(0, math.ceil(seconds / self.resolution) - 1)
        self.seconds_counts[min(index, len(self.seconds_counts) - 1)] += 1
        self.max_age_periods = max(self.max_age_periods, age)
        self.max_age_seconds = max(self.max_age_seconds, seconds)
        return age

    @property
    def without_new(self):
        """Periods since the first command arrived that got no new command."""
        return self.periods - self.with_new

    def age_periods(self):
        """{median, p99, max} of the applied commands' age in periods (NaN before any)."""
        return _percentiles(self.periods_counts, np.arange(AGE_PERIODS_BINS), self.max_age_periods)

    def age_seconds(self):
        """{median, p99, max} of the applied commands' age [s] (median, p99: bin upper edges)."""
        return _percentiles(self.seconds_counts, self.seconds_edges, self.max_age_seconds)

    def values(self):
        """The counts and ages as /diagnostics values (str: numbers formatted)."""
        periods, seconds = self.age_periods(), self.age_seconds()
        share = self.without_new / self.periods if self.periods else math.nan
        return {"commands_received": self.received_count,
                "commands_superseded": self.superseded,
                "periods_before_first_command": self.periods_before_first,
                "periods_without_new_command": self.without_new,
                "periods_without_new_command_share": f"{share:.6g}",
                **{f"command_age_periods_{k}": f"{v:g}" for k, v in periods.items()},
                **{f"command_age_ms_{k}": f"{v * 1e3:.6g}" for k, v in seconds.items()}}

    def summary(self):
        """One line for the end of a run."""
        periods, seconds = self.age_periods(), self.age_seconds()
        share = 100.0 * self.without_new / self.periods if self.periods else math.nan
        return (f"{self.without_new} of {self.periods} periods without a new command "
                f"({share:.3g} %), {self.periods_before_first} before the first; "
                f"{self.received_count} commands received, {self.superseded} superseded; "
                f"age of the applied command [periods] median {periods['median']:g} "
                f"p99 {periods['p99']:g} max {periods['max']:g}, [ms] median "
                f"{seconds['median'] * 1e3:.3g} p99 {seconds['p99'] * 1e3:.3g} "
                f"max {seconds['max'] * 1e3:.3g}")
