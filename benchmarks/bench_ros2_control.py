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

"""Tracking and command latency of realtime runs recorded with ``record:=true``.

    ros2 launch visual_adaptive_servo servo.launch.py timing_mode:=realtime record:=true \
        bag_dir:=/tmp/direct params_file:=...
    ros2 launch visual_adaptive_servo ros2_control.launch.py record:=true bag_dir:=/tmp/rc ...
    python benchmarks/bench_ros2_control.py /tmp/direct /tmp/rc [--period SECONDS]

(--period: the control period; by default the joint states' own, read from their stamps.)

Per bag (read with rosbags, no ROS needed):

* tracking: RMS and max over t >= 5 s (null for a shorter run) and over the last 5 s of
  max_i |x_i - x_d,i|
  (``/controller_node/tracking_error``), max |tau|;
* periods: the simulator's joint states (``/sim_node/joint_states`` through
  ros2_control, else ``/joint_states``) carry the torque applied over the period
  before their stamp; a period is *commanded* when that torque is one the
  controller published (``/controller_node/effort_command``, bit for bit), *new*
  when it differs from the previous period's, *held* when it is zero (no command);
* delay [periods]: start of the period a command was applied in minus the stamp of
  the joint state it answers (the effort_command's stamp), 0 = applied in the very
  next period, as in ``vas run``;
* latency [ms of wall time, at the recorder]: receipt of the joint state the controller
  answered (``/joint_states``) to receipt of the command the hardware sends
  (``/sim_node/joint_commands``; direct: ``/effort_controller/commands``).
"""

import argparse
import json
import os
import pathlib
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from benchlib import environment  # noqa: E402

TRANSIENT_S = 5.0


def _read(bag):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out = {}
    with AnyReader([pathlib.Path(bag)],
                   default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, log_ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            out.setdefault(conn.topic, []).append((log_ns, msg))
    return out


def _stamp_ns(msg):
    return int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)


def _percentiles(values, scale=1.0):
    if not values:
        return None
    v = np.asarray(values, dtype=float) * scale
    return {"n": int(v.size), "min": float(v.min()), "median": float(np.median(v)),
            "p99": float(np.percentile(v, 99)), "max": float(v.max())}


def state_period(states):
    """The simulator's control period [s]: the median interval between its joint states."""
    stamps = np.array([_stamp_ns(msg) for _, msg in states], dtype=np.int64)
    steps = np.diff(stamps)
    steps = steps[steps > 0]
    return float(np.median(steps)) * 1e-9 if steps.size else None


def analyse(bag, period=None):
    """The figures of one recorded run; ``period`` None: the joint states' own period."""
    return analyse_topics(_read(bag), period, bag)


def analyse_topics(topics, period=None, bag=None):
    """:func:`analyse` on the messages of a bag, ``{topic: [(log_ns, msg), ...]}``.

    A period that is not the joint states' own (a 1 kHz run read with a 5 ms period) would
    count no period as commanded: the one used is reported beside the joint states' own.
    """
    through_ros2_control = "/sim_node/joint_states" in topics
    sim_states = topics["/sim_node/joint_states" if through_ros2_control else "/joint_states"]
    own = state_period(sim_states)
    if period is None:
        if own is None:
            raise ValueError(f"{bag}: fewer than two joint states, no control period to read")
        period = own
    answered = {}           # torque bytes -> stamps of the joint states it answers (ascending)
    for _, msg in topics["/controller_node/effort_command"]:
        answered.setdefault(np.asarray(msg.effort, float).tobytes(), []).append(_stamp_ns(msg))

    def answering(key, before_ns):
        """The newest stamp at or before ``before_ns`` of a joint state ``key`` answers.

        A torque at its limit answers many.
        """
        stamps = [s for s in answered.get(key, ()) if s <= before_ns]
        return stamps[-1] if stamps else None

    period_ns = int(round(period * 1e9))
    delays, counts, previous = [], {"periods": 0, "commanded": 0, "new": 0, "held": 0,
                                    "other": 0}, None
    for _, msg in sim_states:
        tau = np.asarray(msg.effort, float)
        start = _stamp_ns(msg) - period_ns
        if start < 0:
            continue                    # the first state: no period before it
        counts["periods"] += 1
        key = tau.tobytes()
        stamp = answering(key, start)
        if stamp is not None:
            counts["commanded"] += 1
            counts["new"] += int(previous != key)
            delays.append((start - stamp) / period_ns)
        elif not np.any(tau):
            counts["held"] += 1
        else:
            counts["other"] += 1
        previous = key

    # wall latency at the recorder: the answered joint state's receipt -> the command's receipt
    state_log = {}
    for log_ns, msg in topics.get("/joint_states", []):
        state_log.setdefault(_stamp_ns(msg), log_ns)
    command_topic = "/sim_node/joint_commands" if through_ros2_control else \
        "/effort_controller/commands"
    latency, seen = [], set()
    for log_ns, msg in topics.get(command_topic, []):
        key = np.asarray(msg.effort if through_ros2_control else msg.data, float).tobytes()
        stamps = answered.get(key, ())
        # the first receipt of a torque that answers one joint state only (not one at its limit)
        if key not in seen and len(stamps) == 1 and stamps[0] in state_log:
            latency.append((log_ns - state_log[stamps[0]]) * 1e-6)
        seen.add(key)

    t, err = [], []
    for _, msg in topics["/controller_node/tracking_error"]:
        t.append(_stamp_ns(msg) * 1e-9)
        err.append(max(np.hypot(p.x, p.y) for p in msg.polygon.points))
    t, err = np.asarray(t), np.asarray(err)
    t = t - t[0]
    late, last = t >= TRANSIENT_S, t >= t[-1] - 5.0
    taus = [np.abs(np.asarray(m.effort, float)).max()
            for _, m in topics["/controller_node/effort_command"]]
    return {
        "bag": bag, "through_ros2_control": through_ros2_control,
        "period_s": period, "joint_state_period_s": own,
        # a run shorter than the transient has nothing after it: null, not a crash
        "tracking_px": {"rms_after_5s": (float(np.sqrt(np.mean(err[late] ** 2)))
                                         if late.any() else None),
                        "max_after_5s": float(err[late].max()) if late.any() else None,
                        "rms_last_5s": float(np.sqrt(np.mean(err[last] ** 2))),
                        "max": float(err.max()), "samples": int(err.size),
                        "duration_s": float(t[-1])},
        "max_abs_torque": float(max(taus)),
        "periods": counts,
        "delay_periods": _percentiles(delays),
        "latency_ms": _percentiles(latency),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("bags", nargs="+", help="rosbag2 folders (MCAP)")
    parser.add_argument("--period", type=float, default=None,
                        help="control period [s] (default: the joint states' own, read from "
                             "their stamps)")
    args = parser.parse_args()
    result = {"environment": environment(),
              "runs": [analyse(bag, args.period) for bag in args.bags]}
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
