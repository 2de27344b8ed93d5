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

"""sim_node's count of periods without a new command and of the applied command's age.

Against a hand-computed timeline, and against numpy's nearest-rank percentiles
(``method="inverted_cdf"``) of the raw ages for random timelines.
"""

import math

import numpy as np
import pytest

from sim_bridge.command_age import AGE_PERIODS_BINS, CommandAge


def test_hand_computed_timeline():
    age = CommandAge(resolution=1e-4)
    assert age.period(0.000, applied=False) is None      # before any command
    age.received(0.00045)
    assert age.period(0.001, applied=True) == 0          # new, 0.55 ms old
    assert age.period(0.002, applied=True) == 1          # again, 1.55 ms
    age.received(0.00245)
    age.received(0.00275)                                # supersedes the one before
    assert age.period(0.003, applied=True) == 0          # new, 0.25 ms
    assert age.period(0.004, applied=False) is None      # none applied (a timeout)
    assert age.period(0.005, applied=True) == 2          # the same again, 2.25 ms
    age.received(0.00545)
    assert age.period(0.006, applied=False) is None      # arrived, not applied (brakes)
    assert age.period(0.007, applied=True) == 1          # 1.55 ms

    assert (age.periods, age.periods_before_first, age.with_new, age.without_new) == (7, 1, 2, 5)
    assert (age.received_count, age.superseded) == (4, 1)
    # ages [0, 1, 0, 2, 1]: sorted [0, 0, 1, 1, 2], median the 3rd, p99 the 5th
    assert age.age_periods() == {"median": 1.0, "p99": 2.0, "max": 2.0}
    # 0.55, 1.55, 0.25, 2.25, 1.55 ms in bins of 0.1 ms: upper edges 0.6, 1.6, 0.3, 2.3, 1.6
    seconds = age.age_seconds()
    assert seconds["median"] == pytest.approx(1.6e-3, abs=1e-12)
    assert seconds["p99"] == pytest.approx(2.3e-3, abs=1e-12)
    assert seconds["max"] == pytest.approx(2.25e-3, abs=1e-12)
    values = age.values()
    assert values["periods_without_new_command"] == 5
    assert values["commands_superseded"] == 1
    assert values["command_age_periods_p99"] == "2"
    assert values["command_age_ms_max"] == "2.25"
    assert age.summary().startswith("5 of 7 periods without a new command (71.4 %), 1 before "
                                    "the first; 4 commands received, 1 superseded")


@pytest.mark.parametrize("stale, p99", [(1, 0), (2, 1)])
def test_p99_is_the_nearest_rank(stale, p99):
    # 100 applied periods: each stale one repeats the command before it (age 1)
    age = CommandAge()
    t = 0.0
    for k in range(100):
        if k < 100 - stale:
            age.received(t + 1e-4)
        t += 1e-3
        age.period(t, applied=True)
    assert age.age_periods()["p99"] == p99


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_percentiles_equal_numpys_nearest_rank_of_the_raw_ages(seed):
    rng = np.random.default_rng(seed)
    age = CommandAge(resolution=1e-5)
    periods, seconds, arrival, current = [], [], None, None
    for k in range(2000):
        t = k * 1e-3
        if rng.random() < 0.6:                    # a command arrives in this period
            arrival = t - rng.uniform(0.0, 1e-3)
            age.received(arrival)
            current = 0
        elif current is not None:
            current += 1
        applied = rng.random() < 0.95
        got = age.period(t, applied)
        if current is not None and applied:
            periods.append(current)
            seconds.append(t - arrival)
            assert got == current
    expected = {q: np.percentile(periods, 100 * f, method="inverted_cdf")
                for q, f in (("median", 0.5), ("p99", 0.99))}
    out = age.age_periods()
    assert (out["median"], out["p99"], out["max"]) == (expected["median"], expected["p99"],
                                                       max(periods))
    out = age.age_seconds()
    for q, f in (("median", 0.5), ("p99", 0.99)):
        true = np.percentile(seconds, 100 * f, method="inverted_cdf")
        assert true <= out[q] + 1e-15 and out[q] < true + 1e-5 + 1e-15
    assert out["max"] == max(seconds)


def test_ages_beyond_the_histogram_are_infinite_percentiles_but_exact_maxima():
    # one command applied for N periods: ages 0 .. N - 1, the last 200 beyond the bins
    age, periods = CommandAge(), AGE_PERIODS_BINS + 200
    age.received(0.0)
    for k in range(periods):
        age.period(1e-3 * (k + 1), applied=True)
    out = age.age_periods()
    assert out["median"] == periods // 2 - 1 and out["p99"] == math.inf
    assert out["max"] == periods - 1
    assert age.age_seconds()["p99"] == math.inf          # 10 s > the 1 s of bins


def test_nothing_applied_yet_gives_nan():
    age = CommandAge()
    age.period(0.0, applied=False)
    assert all(math.isnan(v) for v in age.age_periods().values())
    assert age.values()["periods_before_first_command"] == 1


@pytest.mark.parametrize("resolution", [0.0, -1e-3, math.inf, math.nan])
def test_resolution_must_be_positive_and_finite(resolution):
    with pytest.raises(ValueError, match="CommandAge.resolution: must be a positive finite"):
        CommandAge(resolution)
