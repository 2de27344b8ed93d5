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

"""The rate gate of controller_node's state topics, against hand-computed sequences.

Stamps are made as a subscriber reads them (integer nanoseconds to seconds), so
the float arithmetic is the node's.
"""

import math

import pytest

from visual_adaptive_servo.recording.cadence import RateGate
from visual_adaptive_servo.schema import ConfigError


def _stamp(ns):
    return ns // 10**9 + (ns % 10**9) * 1e-9


def _due_indices(rate, stamps):
    gate = RateGate(rate)
    return [k for k, t in enumerate(stamps) if gate.due(t)]


KHZ = [_stamp(k * 1_000_000) for k in range(31)]   # 1 kHz samples, 0 .. 30 ms


@pytest.mark.parametrize("rate, expected", [
    (100.0, [0, 10, 20, 30]),
    # grid 3.33, 6.67, 10, 13.3, ... ms: the first sample at or after each instant
    (300.0, [0, 4, 7, 10, 14, 17, 20, 24, 27, 30]),
    (1000.0, list(range(31))),
    (2500.0, list(range(31))),       # faster than the samples: every one
    (40, [0, 25]),                    # an integer rate is taken
], ids=["100Hz", "300Hz", "1kHz", "2.5kHz", "40Hz_int"])
def test_gate_lets_the_first_sample_after_each_grid_instant_through(rate, expected):
    assert _due_indices(rate, KHZ) == expected


def test_rate_is_kept_on_average_over_a_long_run():
    # 1 kHz for 20 s at 300 Hz: 6000 grid instants, each one sample, plus the first
    gate = RateGate(300.0)
    passed = sum(gate.due(_stamp(k * 1_000_000)) for k in range(20_000))
    assert passed == 6000


def test_a_gap_lets_the_next_sample_through_without_a_burst():
    stamps = [0.0, 0.001, 0.002, 0.035, 0.036, 0.040, 0.041, 0.050]
    # 35 ms: due (>= 10 ms), the grid goes on at 40 ms, then 50 ms
    assert _due_indices(100.0, stamps) == [0, 3, 5, 7]


def test_time_going_back_starts_a_new_grid():
    stamps = [0.0, 0.01, 0.02, 0.005, 0.006, 0.014, 0.015]
    assert _due_indices(100.0, stamps) == [0, 1, 2, 3, 6]


@pytest.mark.parametrize("rate", [0.0, -5.0, math.inf, math.nan, "100", True, None])
def test_rate_must_be_a_positive_finite_number(rate):
    with pytest.raises(ConfigError, match=r"controller_node\.publish_rate: must be a"):
        RateGate(rate, "controller_node.publish_rate")
