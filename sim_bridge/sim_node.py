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

"""``sim_node``: the PyBullet arm and fixed camera as a ROS 2 node.

Thin: it declares the parameters of :data:`config.SIM_PARAMS`, owns a
:class:`simulator.Simulator` and turns its measurements into messages.

Topics (DESIGN.md section 2)
----------------------------
out: ``/clock`` (rosgraph_msgs/Clock, the simulated time; this node itself runs on
     wall time and must NOT use_sim_time), ``/joint_states`` (q, q_dot, applied torque,
     stamped with sim time), ``/camera/features`` (PolygonStamped, frame ``camera``,
     stamp = capture time; nothing is published when no frame is due or the feature is
     behind the camera), ``~/true_depth`` (Float64MultiArray, ground truth for plots),
     ``/diagnostics``, and with ``render.enabled`` ``~/image`` (sensor_msgs/Image rgb8:
     the camera's view with x (red ring), x_d (green cross, from
     ``/controller_node/desired``) and x_o (blue ring, from ``/controller_node/observed``)).
in:  ``/effort_controller/commands`` (std_msgs/Float64MultiArray, one torque per joint in
     ``joint_names`` order: the ros2_control JointGroupEffortController convention).

Timing (``timing_mode``)
------------------------
Both modes start once a controller is connected (a publisher on the command
topic and a subscriber on /joint_states), so the arm does not fall meanwhile.

``lockstep`` (default): publish the state at t_k, wait for the next command,
hold it for one ``control_period``, publish the state at t_k+1, ...  The
simulation runs as fast as the controller answers, deterministically.  If no
command comes within ``command_timeout`` seconds of wall time, zero torque is
applied for that period (logged, counted in /diagnostics) and the loop goes on.
The command has no stamp, so a late command is applied to the next period.

``realtime``: a wall-clock timer at ``control_period`` applies the latest
command (zero torque once it is older than ``command_timeout``).

QoS: commands are reliable (depth 10) in both modes.  In lockstep everything
is reliable (depth 10); in realtime the measurements (/joint_states,
/camera/features, ~/image) are sensor data (best effort, depth 5) and the
rest is reliable.

``duration`` > 0: after that much simulated time the node stops stepping and
exits with status 0.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import rclpy
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.task import Future

from visual_adaptive_servo import messages as m
from visual_adaptive_servo.config import (
    SIM_PARAMS,
    SIM_SECTION,
    ConfigError,
    SimConfig,
    build_sim_arm,
)
from visual_adaptive_servo.overlay import COLOR_DESIRED, COLOR_MEASURED, COLOR_OBSERVED
from visual_adaptive_servo.ros_params import declare_schema

from . import render
from .simulator import Simulator

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
COMMAND_TOPIC = "/effort_controller/commands"
DIAGNOSTICS_PERIOD = 1.0   # s of sim time between two /diagnostics when nothing changes
START_POLL = 0.05          # s of wall time between two checks for a connected controller


class SimNode(Node):
    """Steps the simulator on commands (lockstep) or on a wall-clock timer (realtime)."""

    def __init__(self, **kwargs):
        super().__init__("sim_node", **kwargs)
        params = declare_schema(self, SIM_PARAMS, SIM_SECTION, build_sim_arm)
        self.config = config = SimConfig.from_params(params)
        self.sim = Simulator(config)
        self.msgs = msgs = m.rclpy_messages()
        self.lockstep = config.timing_mode == "lockstep"
        measurement_qos = RELIABLE if self.lockstep else qos_profile_sensor_data

        self.publishers_by_topic = {
            topic: self.create_publisher(getattr(msgs, kind), topic, qos)
            for topic, kind, qos in (("/clock", "Clock", RELIABLE),
                                     ("/joint_states", "JointState", measurement_qos),
                                     ("/camera/features", "PolygonStamped", measurement_qos),
                                     ("~/true_depth", "Float64MultiArray", RELIABLE))}
        self.diagnostics_pub = self.create_publisher(msgs.DiagnosticArray, "/diagnostics",
                                                     RELIABLE)
        self.create_subscription(msgs.Float64MultiArray, COMMAND_TOPIC, self._on_command,
                                 RELIABLE)
        self.render_every = 0
        if config.params["render.enabled"]:
            self.image_pub = self.create_publisher(msgs.Image, "~/image", measurement_qos)
            self.render_every = max(1, int(np.rint(1.0 / (config.params["render.rate"]
                                                          * config.control_period))))
            self.overlay = {"desired": None, "observed": None}
            for key in self.overlay:
                self.create_subscription(msgs.PolygonStamped, f"/controller_node/{key}",
                                         lambda msg, key=key: self._on_overlay(key, msg),
                                         RELIABLE)

        # wall-clock timers: the node must keep running while sim time stands still
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.start_timer = self.create_timer(START_POLL, self._on_start_poll, clock=steady)
        if self.lockstep:
            self.step_timer = self.create_timer(config.command_timeout, self._on_command_timeout,
                                                clock=steady, autostart=False)
        else:
            self.step_timer = self.create_timer(config.control_period, self._on_tick,
                                                clock=steady, autostart=False)

        self.finished = Future()
        self.started = False
        self.measurement = None
        self.command, self.command_wall = None, None
        self.counters = {"steps": 0, "command_timeouts": 0, "refused_commands": 0}
        self.problem = ""
        self.last_level, self.t_last_diagnostics = None, None
        self.wall_start = None
        self.get_logger().info(f"{config.timing_mode}: waiting for a controller on "
                               f"{COMMAND_TOPIC}")

    # -- start -------------------------------------------------------------------
    def _on_start_poll(self):
        if (self.count_publishers(COMMAND_TOPIC) == 0
                or self.publishers_by_topic["/joint_states"].get_subscription_count() == 0):
            return
        self.start_timer.cancel()
        self.started = True
        self.wall_start = time.monotonic()
        self.get_logger().info("controller connected: simulation starts")
        self._publish_measurement()
        if not self.lockstep:
            self.step_timer.reset()

    # -- commands and stepping ---------------------------------------------------
    def _on_command(self, msg):
        tau = m.float_array_from_msg(msg)[0]
        if self.lockstep:
            if self.started and not self.finished.done():
                self._advance(tau)
        else:
            self.command, self.command_wall = tau, time.monotonic()

    def _on_command_timeout(self):
        if not self.started or self.finished.done():
            return
        self.counters["command_timeouts"] += 1
        self.problem = (f"no command within {self.config.command_timeout} s at "
                        f"t={self.sim.t:.3f}: zero torque applied")
        self.get_logger().warning(self.problem, throttle_duration_sec=1.0)
        self._advance(np.zeros(self.sim.n))

    def _on_tick(self):
        if self.finished.done():
            return
        fresh = (self.command_wall is not None
                 and time.monotonic() - self.command_wall <= self.config.command_timeout)
        if not fresh and self.command_wall is not None:
            self.counters["command_timeouts"] += 1
            self.problem = (f"command older than {self.config.command_timeout} s at "
                            f"t={self.sim.t:.3f}: zero torque applied")
            self.get_logger().warning(self.problem, throttle_duration_sec=1.0)
        self._advance(self.command if fresh else np.zeros(self.sim.n))

    def _advance(self, tau):
        refused = self.sim.apply(tau)
        self.counters["steps"] += 1
        if refused is not None:
            self.counters["refused_commands"] += 1
            self.problem = f"{refused}; zero torque applied"
            self.get_logger().warning(self.problem, throttle_duration_sec=1.0)
        duration = self.config.duration
        if duration > 0.0 and self.sim.t >= duration - 1e-9:
            self._finish()
            return
        self._publish_measurement()
        if self.lockstep:
            self.step_timer.reset()

    def _finish(self):
        self.step_timer.cancel()
        wall = time.monotonic() - self.wall_start
        self.get_logger().info(
            f"duration {self.config.duration} s reached after {self.counters['steps']} steps "
            f"in {wall:.1f} s wall time; {self.counters['command_timeouts']} command "
            f"timeouts, {self.counters['refused_commands']} refused commands")
        self.finished.set_result(True)

    # -- outputs -----------------------------------------------------------------
    def _publish_measurement(self):
        meas = self.measurement = self.sim.measure()
        t = meas.t
        for topic, msg in m.sim_outputs(self.msgs, meas, self.config.joint_names):
            self.publishers_by_topic[topic].publish(msg)
        if meas.problems:
            self.problem = "; ".join(meas.problems)
        self._publish_diagnostics(t)
        if self.render_every and self.counters["steps"] % self.render_every == 0:
            self._publish_image(meas)

    def _publish_diagnostics(self, t):
        level = "WARN" if self.problem else "OK"
        if (level == self.last_level and self.t_last_diagnostics is not None
                and t - self.t_last_diagnostics < DIAGNOSTICS_PERIOD - 1e-9):
            return
        wall = time.monotonic() - self.wall_start
        values = dict(self.counters, timing_mode=self.config.timing_mode, sim_time=f"{t:.3f}",
                      realtime_factor=f"{t / wall:.3g}" if wall > 0 else "inf")
        self.diagnostics_pub.publish(m.diagnostics_to_msg(
            self.msgs, t, "sim_node", level, self.problem or "running", values, "sim"))
        self.last_level, self.t_last_diagnostics, self.problem = level, t, ""

    def _on_overlay(self, key, msg):
        self.overlay[key] = m.features_from_msg(msg)[1]

    def _publish_image(self, meas):
        cfg = self.config
        rgb = render.render_camera_view(
            self.sim.plant.client, self.sim.camera, cfg.params["render.width"],
            cfg.params["render.height"],
            [(self.overlay["desired"], COLOR_DESIRED, "cross"),
             (self.overlay["observed"], COLOR_OBSERVED, "ring"),
             (meas.pixels, COLOR_MEASURED, "ring")])
        self.image_pub.publish(m.image_to_msg(self.msgs, meas.t, rgb))

    def destroy_node(self):
        self.sim.close()
        return super().destroy_node()


def main(args=None):
    rclpy.init(args=args)
    try:
        node = SimNode()
    except (ConfigError, ValueError) as exc:
        rclpy.logging.get_logger("sim_node").fatal(f"invalid configuration: {exc}")
        rclpy.try_shutdown()
        return 2
    try:
        rclpy.spin_until_future_complete(node, node.finished)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
