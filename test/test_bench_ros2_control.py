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
"""benchmarks/bench_ros2_control.py on synthetic recordings: what it counts, at which period."""

import importlib.util
import os
from types import SimpleNamespace as NS

import numpy as np
import pytest

PATH = os.path.join(os.path.dirname(__file__), "..", "benchmarks", "bench_ros2_control.py")


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_ros2_control", PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def stamped(t_ns, **fields):
    return NS(header=NS(stamp=NS(sec=t_ns // 10**9, nanosec=t_ns % 10**9)), **fields)


def recording(period_ns, samples, missed=()):
    """A direct run at ``period_ns``, ``samples`` joint states.

    The joint state at k carries the command answering state k - 1, except in the
    ``missed`` periods, where the previous torque is applied again.
    """
    states, commands, tracking = [], [], []
    applied = np.zeros(2)
    for k in range(samples):
        t = k * period_ns
        states.append((t, stamped(t, effort=applied.tolist())))
        command = np.array([np.sin(0.01 * k), np.cos(0.013 * k)])
        commands.append((t, stamped(t, effort=command.tolist())))
        tracking.append((t, stamped(t, polygon=NS(points=[NS(x=0.3, y=0.4)]))))
        if k + 1 not in missed:
            applied = command
    return {"/joint_states": states, "/controller_node/effort_command": commands,
            "/controller_node/tracking_error": tracking}


def test_the_period_is_read_from_the_joint_states(bench):
    topics = recording(10**6, 3000, missed={1200, 2400})
    result = bench.analyse_topics(topics)
    assert result["period_s"] == pytest.approx(1e-3) == result["joint_state_period_s"]
    counts = result["periods"]
    assert counts["periods"] == 2999 and counts["held"] == 0       # (the first state has none)
    assert counts["commanded"] == 2999 and counts["new"] == 2997    # two periods held over
    assert result["delay_periods"]["max"] == 1.0                    # one each
    assert result["tracking_px"]["rms_last_5s"] == pytest.approx(0.5)
    # read with a 5 ms period a 1 kHz run shows no command at all, and says which it used
    wrong = bench.analyse_topics(topics, period=0.005)
    assert wrong["periods"]["commanded"] < 10
    assert wrong["period_s"] == 0.005 and wrong["joint_state_period_s"] == pytest.approx(1e-3)


def test_a_recording_without_a_period_is_refused(bench):
    topics = recording(10**6, 1)
    with pytest.raises(ValueError, match="fewer than two joint states"):
        bench.analyse_topics(topics)
