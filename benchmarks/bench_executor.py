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

"""CPU per joint state of a node shaped like controller_node, by executor (needs ROS 2).

    python benchmarks/bench_executor.py [--messages 5000] [--repeats 3] [--rate 1000]

A publisher process sends what sim_node sends an iiwa controller at 1 kHz
(/clock, /camera/features with 3 points, /joint_states with 7 joints, on a steady
wall timer); a subscriber process with controller_node's entities (8 publishers,
the two subscriptions, a 4 Hz watchdog timer, use_sim_time, the parameter services)
answers every joint state with the two commands and no controller: what is left
is the executor, the messages and the middleware.  Per executor of
``visual_adaptive_servo.ros.main.EXECUTORS`` (alternating, ``--repeats`` times):
the subscriber's CPU time (user + system) per joint state over ``--messages``
joint states after a warm-up, and the rate it answered at.  Writes
``results/executor.json``.
"""

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time

from benchlib import environment, write_result

HERE = os.path.dirname(os.path.abspath(__file__))
RESULT = os.path.join(HERE, "results", "executor.json")
WARMUP = 500


def publisher(rate):
    import rclpy
    from geometry_msgs.msg import Point32, PolygonStamped
    from rclpy.clock import Clock, ClockType
    from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock as ClockMsg
    from sensor_msgs.msg import JointState

    from visual_adaptive_servo.ros.executor import KeptWaitSetExecutor

    rclpy.init()
    node = rclpy.create_node("bench_sim")
    clock = node.create_publisher(ClockMsg, "/clock",
                                  QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    frames = node.create_publisher(PolygonStamped, "/camera/features", qos_profile_sensor_data)
    states = node.create_publisher(JointState, "/joint_states", qos_profile_sensor_data)
    count = [0]

    def tick():
        count[0] += 1
        ns = count[0] * round(1e9 / rate)
        msg = ClockMsg()
        msg.clock.sec, msg.clock.nanosec = divmod(ns, 1_000_000_000)
        clock.publish(msg)
        frame = PolygonStamped()
        frame.header.stamp = msg.clock
        frame.polygon.points = [Point32(x=1.0, y=2.0) for _ in range(3)]
        frames.publish(frame)
        state = JointState()
        state.header.stamp = msg.clock
        state.name = [f"joint_{i}" for i in range(7)]
        state.position, state.velocity, state.effort = [0.1] * 7, [0.0] * 7, [0.0] * 7
        states.publish(state)

    node.create_timer(1.0 / rate, tick, clock=Clock(clock_type=ClockType.STEADY_TIME))
    executor = KeptWaitSetExecutor()
    executor.add_node(node)
    while rclpy.ok():
        executor.spin_once(timeout_sec=0.1)


def subscriber(name, messages):
    import rclpy
    from geometry_msgs.msg import PolygonStamped
    from rclpy.clock import Clock, ClockType
    from rclpy.parameter import Parameter
    from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from visual_adaptive_servo.ros.main import EXECUTORS

    rclpy.init()
    node = rclpy.create_node("bench_controller",
                             parameter_overrides=[Parameter("use_sim_time", value=True)])
    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    pubs = [node.create_publisher(Float64MultiArray, f"/bench/out{i}", reliable)
            for i in range(8)]
    frames, answered = [], [0]

    def on_state(msg):
        answered[0] += 1
        command = Float64MultiArray()
        command.data = list(msg.position)
        pubs[0].publish(command)
        pubs[1].publish(command)
        frames.clear()

    node.create_subscription(PolygonStamped, "/camera/features", frames.append,
                             qos_profile_sensor_data)
    node.create_subscription(JointState, "/joint_states", on_state, qos_profile_sensor_data)
    node.create_timer(0.25, lambda: None, clock=Clock(clock_type=ClockType.STEADY_TIME))
    executor = EXECUTORS[name]()
    executor.add_node(node)
    while answered[0] < WARMUP:
        executor.spin_once(timeout_sec=0.1)
    r0, w0, a0 = resource.getrusage(resource.RUSAGE_SELF), time.monotonic(), answered[0]
    while answered[0] < a0 + messages:
        executor.spin_once(timeout_sec=0.1)
    r1, w1 = resource.getrusage(resource.RUSAGE_SELF), time.monotonic()
    cpu = r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime
    print(f"{cpu / messages * 1e6:.3f} {messages / (w1 - w0):.3f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--messages", type=int, default=5000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--rate", type=float, default=1000.0, help="joint states per second")
    parser.add_argument("--role", choices=["publisher", "subscriber"], help=argparse.SUPPRESS)
    parser.add_argument("--executor", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == "publisher":
        return publisher(args.rate)
    if args.role == "subscriber":
        return subscriber(args.executor, args.messages)

    from visual_adaptive_servo.ros.main import EXECUTORS

    domain = os.environ.get("ROS_DOMAIN_ID", str(60 + os.getpid() % 40))
    env = dict(os.environ, ROS_DOMAIN_ID=domain)
    me = [sys.executable, os.path.abspath(__file__)]
    load_before = os.getloadavg()
    source = subprocess.Popen(me + ["--role", "publisher", "--rate", str(args.rate)], env=env)
    runs = {name: [] for name in EXECUTORS}
    try:
        for _ in range(args.repeats):
            for name in EXECUTORS:
                out = subprocess.run(me + ["--role", "subscriber", "--executor", name,
                                           "--messages", str(args.messages)], env=env,
                                     check=True, capture_output=True, text=True, timeout=600)
                cpu_us, hz = map(float, out.stdout.split())
                runs[name].append({"cpu_us_per_joint_state": cpu_us, "rate_hz": hz})
    finally:
        source.terminate()
        source.wait()
    summary = {name: {"cpu_us_per_joint_state_median": statistics.median(
        r["cpu_us_per_joint_state"] for r in rs), "runs": rs} for name, rs in runs.items()}
    base = summary["rclpy"]["cpu_us_per_joint_state_median"]
    print(f"CPU per joint state at {args.rate:g} Hz, {args.messages} joint states x "
          f"{args.repeats} (load average {load_before[0]:.2f} before, "
          f"{os.getloadavg()[0]:.2f} after)\n")
    print("| executor | CPU per joint state, median [µs] | runs [µs] | answered at [Hz] | "
          "vs rclpy |")
    print("|---|---:|---|---|---:|")
    for name, s in summary.items():
        rs = s["runs"]
        print(f"| {name} | {s['cpu_us_per_joint_state_median']:.0f} | "
              + ", ".join(f"{r['cpu_us_per_joint_state']:.0f}" for r in rs) + " | "
              + ", ".join(f"{r['rate_hz']:.0f}" for r in rs)
              + f" | {s['cpu_us_per_joint_state_median'] / base:.2f}x |")
    write_result(RESULT, {"environment": environment(), "rate_hz": args.rate,
                          "messages": args.messages, "load_before": load_before[0],
                          "load_after": os.getloadavg()[0], "executors": summary})
    return 0


if __name__ == "__main__":
    sys.exit(main())
