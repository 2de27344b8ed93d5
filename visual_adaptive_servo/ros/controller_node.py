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

"""``controller_node``: H. Wang's adaptive visual tracker as a ROS 2 node.

Thin: it declares the parameters of :data:`config.controller.CONTROLLER_PARAMS`, turns
messages into arrays and back (:mod:`recording.messages`) and calls
:class:`control.controller.AdaptiveVisualTracker`.

Topics (DESIGN.md section 2)
----------------------------
in:  ``/camera/features`` (geometry_msgs/PolygonStamped, pixels, origin on the optical
     axis, stamp = capture time), ``/joint_states`` (sensor_msgs/JointState, joints
     picked by ``joint_names``)
out: ``/effort_controller/commands`` (std_msgs/Float64MultiArray, one torque per joint in
     ``joint_names`` order: the ros2_control JointGroupEffortController convention) and
     ``~/effort_command`` (sensor_msgs/JointState: the same torques in ``effort``, ``name`` =
     ``joint_names``, stamped with the joint state it answers: the simulator in lockstep
     applies a command only to that state), both at every sample; at ``publish_rate``
     ``~/desired``, ``~/observed``, ``~/tracking_error`` (PolygonStamped: x_d, x_o, x - x_d),
     ``~/estimated_depth``, ``~/parameters`` (Float64MultiArray, labelled); ``/diagnostics``
     (with the frame ages and counts) at ``diagnostics_rate`` and at once on a change.

One sample per joint state: the tracker runs at every /joint_states message,
at its stamp, with the newest camera frame received since the last sample that
was captured at or before it (older ones are counted as superseded; a frame
stamped after the joint state waits for the next one).  Frames come at the
camera's rate, late by its latency: with ``latency_compensation`` the tracker
predicts between frames and applies late frames at their capture time.  The
features subscription is created before the joint-state one, so when both are
waiting the executor takes the frame first; the simulator in lockstep delivers
the frame before the joint state, so the pairing does not depend on timing.  A
joint state that cannot be converted is processed as a rejected sample.

The joint states and frames are read, and the two commands written, as serialized
CDR (raw subscriptions, ``publish`` of bytes; :mod:`..recording.cdr`, byte-equal to
the messages of :mod:`..recording.messages`): message objects cost more than the
sample at 1 kHz.  In ``timing_mode: realtime`` the node asks for SCHED_FIFO
(``realtime_priority``, :func:`.main.realtime_scheduling`).

QoS: the commands are published reliable (depth 10; 2000 for every topic with
``publish_every_sample`` in lockstep, so a recorder that falls behind loses no
period).  With
``timing_mode: lockstep`` every subscription is reliable (depth 10): the
simulator waits for each command, so nothing may be lost.  With
``timing_mode: realtime`` the measurements are sensor data (best effort,
depth 5; its joint-state subscription depth 1): a late sample is worth less than
the next one.  ``timing_mode`` must match the publisher's: a reliable
subscription does not match a best-effort publisher.

Behind ros2_control (README "On a real arm"): the effort controller (a
JointGroupEffortController) sends on whatever it last received, also after this
node has stopped, and ignores the commands while it is not active.  With
``ros2_control.effort_controller`` set to its name, the node follows it on
``<ros2_control.controller_manager>/activity`` (controller_manager_msgs,
transient local): while it is not active the node does not track (no samples,
no commands: nothing winds up), and when it is active again tracking starts
afresh from the measured state (a new tracker: the start blend, the initial
estimates), which is also how it starts.  Independently of ros2_control, if no
joint state arrives for ``JOINT_STATE_WATCHDOG`` seconds of wall time the node
says so (the hardware or the simulator stopped: with ``use_sim_time`` no sim-time
timer would fire any more).

Rates (the node's own read-only parameters, not in the scenario file: ``vas run``
records every sample): at every joint state the two commands go out first, the
one the consumer takes first (lockstep: ``~/effort_command``, which the simulator
waits for; realtime: ``/effort_controller/commands``), each built and published
before anything else of the sample is built.  The state topics follow for the
samples :class:`~visual_adaptive_servo.recording.cadence.RateGate` lets through at
``publish_rate`` (default 100 Hz) of the samples' stamps, i.e. of the node's
clock (sim time under use_sim_time: the simulator stamps the joint state with
the time it publishes on /clock), so the same samples go out in every run.
``/diagnostics`` goes out at ``diagnostics_rate`` (default 1 Hz) and at once
when the health level (OK/WARN/ERROR) changes, so a fault is never delayed.
With ``publish_every_sample`` (servo.launch.py sets it for ``record:=true`` in
lockstep) every sample's state topics go out and /diagnostics as ``vas run``
records them (at ``diagnostics_rate`` and on every change of the sample's
status), so the bag holds every period and equals ``vas run``'s.

How the callbacks run: one single-threaded executor (:mod:`.main`: the package's
:class:`~.executor.KeptWaitSetExecutor`, or rclpy's with ``executor:=rclpy``), one
(default, mutually exclusive) callback group, no timer for the rates.  rclpy's
executors are Python: a MultiThreadedExecutor hands each callback to a thread
pool under the GIL (no parallel Python, more overhead per callback, and with
/clock it starved timers in Jazzy, rclpy#1452), and a sim-time timer at
``publish_rate`` would wake the executor for a wait set of its own.  So the
state topics are published in the joint-state callback after the commands:
``Publisher.publish`` converts the message and hands it to the middleware
before it returns, so the commands are on their way before the first state
message is built, and the next joint state waits in its queue only for the
samples that publish (every 10th at 1 kHz).  In realtime the joint-state
subscription keeps only the newest state (depth 1): a sample that comes late
answers the newest state instead of working through a queue of older ones.

Runtime parameters (``runtime`` in the schema: gains K and Gamma_*, torque
limit, damping and safety settings) can be changed with ``ros2 param set``;
the complete new set is validated by ``ControllerConfig.from_params`` before
it is applied.  All other parameters are read-only.
"""

from __future__ import annotations

import logging
from dataclasses import replace
import sys
import time

import numpy as np

from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from ..config.controller import build_controller_model, CONTROLLER_PARAMS, ControllerConfig
from ..control.controller import AdaptiveVisualTracker, frame_values, health
from ..recording import cdr, messages as m
from ..recording.cadence import RateGate
from ..schema import CONTROLLER_SECTION, ConfigError
from .executor import incompatible_qos_warning, RECORDED
from .main import run_node
from .params import declare_node_parameter, declare_rate, declare_schema, runtime_changes

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
# realtime joint states: sensor data keeping only the newest, so a late sample answers the
# newest state and never works through a queue of old ones (which delayed every command by
# 4-6 periods at 1 kHz with depth 5)
LATEST_SENSOR_DATA = QoSProfile(depth=1, reliability=qos_profile_sensor_data.reliability,
                                durability=qos_profile_sensor_data.durability,
                                history=qos_profile_sensor_data.history)
PUBLISH_RATE = 100.0       # Hz of sim time: default rate of the state topics
DIAGNOSTICS_RATE = 1.0     # Hz of sim time: default rate of /diagnostics when nothing changes
MAX_PENDING_FRAMES = 100   # frames kept while waiting for a joint state (more: superseded)
JOINT_STATE_WATCHDOG = 1.0   # s of wall time without a joint state before the node says so
NO_VALUES = np.zeros(0)      # the stamped command's position and velocity
# the controller_manager's ~/activity: published on every change, reliable and transient local
ACTIVITY_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)


class RosLogHandler(logging.Handler):
    """Forward the core's Python logging to the node's logger, a call site at most once a second.

    rclpy keys ``throttle_duration_sec`` on the line that calls the node's logger, which
    here would be this handler for every record of a level: one message of the core would
    silence every other of its level for a second (the warning that the fallback damping is
    capped hid the first sample's rejection 1 ms later).  So the throttle is kept here, per
    call site of the core (the record's file and line), on the steady clock.
    """

    #: s between two records of one call site
    THROTTLE = 1.0

    def __init__(self, logger, clock=time.monotonic):
        super().__init__()
        self.logger = logger
        self.clock = clock
        self.last = {}          # (file, line) -> clock of the record last forwarded

    def emit(self, record):
        site, now = (record.pathname, record.lineno), self.clock()
        last = self.last.get(site)
        if last is not None and now - last < self.THROTTLE:
            return
        self.last[site] = now
        text = self.format(record)
        if record.levelno >= logging.ERROR:
            self.logger.error(text)
        elif record.levelno >= logging.WARNING:
            self.logger.warning(text)
        else:
            self.logger.info(text)


#: s of wall time the node waits at its exit for a lockstep recording's recorder to have
#: every message it published (the recorder may have fallen behind: ros/executor.py RECORDED)
FLUSH_TIMEOUT = 10.0


class ControllerNode(Node):
    """Subscribes the measurements, runs the tracker, publishes torques and its state."""

    def __init__(self, **kwargs):
        super().__init__("controller_node", **kwargs)
        # the core's log lines reach the node's log at the node's own level (Python's default
        # WARNING would drop its INFO lines: the start-up report, a long start blend, a camera
        # coming back, the kernels compiling on a first start, which is why this comes
        # first); the previous level comes back with destroy_node, or here if the node fails
        core = logging.getLogger("visual_adaptive_servo")
        self.core_level = core.level
        core.setLevel(int(self.get_logger().get_effective_level()) or logging.INFO)
        self.log_handler = RosLogHandler(self.get_logger())
        core.addHandler(self.log_handler)
        try:
            self._start()
        except BaseException:
            self._release_log()
            raise

    def _start(self):
        self.specs = {spec.name: spec for spec in CONTROLLER_PARAMS}
        built = {}   # the model is built once, while the parameters are declared

        def build(values):
            built["model"] = build_controller_model(values)
            return built["model"]

        given = set()
        params = declare_schema(self, CONTROLLER_PARAMS, CONTROLLER_SECTION, build, given)
        config = replace(ControllerConfig.from_params(params, model=built.get("model")),
                         explicit=frozenset(given))
        self.tracker = AdaptiveVisualTracker(config)
        self.joint_names = list(config.joint_names)
        self.labels = m.parameter_labels(config.model)
        self.msgs = m.rclpy_messages()

        self.every_sample = declare_node_parameter(
            self, CONTROLLER_SECTION, "publish_every_sample", False,
            "Publish the state topics at every sample and /diagnostics as vas run records "
            "them (servo.launch.py: record:=true in lockstep); false: at publish_rate and "
            "diagnostics_rate.")
        publish_rate = declare_rate(
            self, CONTROLLER_SECTION, "publish_rate", PUBLISH_RATE,
            "Rate of ~/desired, ~/observed, ~/tracking_error, ~/estimated_depth and "
            "~/parameters in the node's clock (the commands go out at every sample)")
        diagnostics_rate = declare_rate(
            self, CONTROLLER_SECTION, "diagnostics_rate", DIAGNOSTICS_RATE,
            "Rate of /diagnostics in the node's clock, plus one at every change of the "
            "health level")
        self.state_gate = None if self.every_sample else RateGate(
            publish_rate, f"{CONTROLLER_SECTION}.publish_rate")
        self.diagnostics_gate = RateGate(diagnostics_rate,
                                         f"{CONTROLLER_SECTION}.diagnostics_rate")

        lockstep = config.timing_mode == "lockstep"
        measurement_qos = RELIABLE if lockstep else qos_profile_sensor_data
        # every sample recorded in lockstep: a deep history lets the recorder fall behind
        # without losing a period (ros/executor.py, RECORDED)
        published = RECORDED if lockstep and self.every_sample else RELIABLE
        msgs = self.msgs
        self.publishers_by_topic = {
            topic: self.create_publisher(getattr(msgs, kind), topic, published,
                                         event_callbacks=incompatible_qos_warning(self, topic))
            for topic, kind in (("/effort_controller/commands", "Float64MultiArray"),
                                ("~/desired", "PolygonStamped"),
                                ("~/observed", "PolygonStamped"),
                                ("~/tracking_error", "PolygonStamped"),
                                ("~/estimated_depth", "Float64MultiArray"),
                                ("~/parameters", "Float64MultiArray"),
                                ("~/effort_command", "JointState"))}
        self.diagnostics_pub = self.create_publisher(
            msgs.DiagnosticArray, "/diagnostics", published,
            event_callbacks=incompatible_qos_warning(self, "/diagnostics"))
        self.command_pub = self.publishers_by_topic["/effort_controller/commands"]
        self.stamped_command_pub = self.publishers_by_topic["~/effort_command"]
        self.lockstep = lockstep
        # frames before joint states: the executor serves ready subscriptions in creation
        # order, so a frame that is waiting is always taken before the joint state
        # both serialized (raw): read by recording.cdr without message objects, and the two
        # commands go out serialized too
        self.create_subscription(msgs.PolygonStamped, "/camera/features", self._on_features,
                                 measurement_qos, raw=True)
        self.create_subscription(msgs.JointState, "/joint_states", self._on_joint_state,
                                 RELIABLE if lockstep else LATEST_SENSOR_DATA, raw=True)
        self.joint_states = cdr.JointStateDecoder(self.joint_names)
        self.command_cdr = cdr.JointStateEncoder(self.joint_names)
        self.effort_controller = self.declare_parameter("ros2_control.effort_controller",
                                                        "").value
        manager = self.declare_parameter("ros2_control.controller_manager",
                                         "/controller_manager").value
        self.effort_active = not self.effort_controller  # unknown until the first activity
        if self.effort_controller:
            try:
                from controller_manager_msgs.msg import ControllerManagerActivity
            except ImportError:
                raise ConfigError("controller_node.ros2_control.effort_controller: needs "
                                  "controller_manager_msgs (ros2_control) installed") from None
            self.create_subscription(ControllerManagerActivity, f"{manager}/activity",
                                     self._on_activity, ACTIVITY_QOS)
        self.wall_last_state = None
        self.create_timer(JOINT_STATE_WATCHDOG / 4, self._on_watchdog,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self.pending_frames = []       # (stamp ns, (capture time, pixels)) not yet passed on
        self.superseded = 0
        self.last_status = None        # status of the previous sample (publish_every_sample)
        self.health_key = None         # what the health level of the previous sample depends on
        self.last_level = None         # its level
        self.samples = 0
        self.get_logger().info(f"model {params['model']} (kinematic tensors: "
                               f"{getattr(config.model, 'backend', 'numpy')} backend), joints "
                               f"{self.joint_names}, timing_mode {config.timing_mode}")
        self.get_logger().info(
            "commands at every sample; state topics and /diagnostics "
            + ("at every sample and as vas run records them (publish_every_sample)"
               if self.every_sample else f"at {publish_rate:g} Hz and {diagnostics_rate:g} Hz "
                                         f"(and on a change of health level)"))
        if self.effort_controller:
            self.get_logger().info(f"tracking while {self.effort_controller} is active "
                                   f"({manager}/activity)")

    # -- inputs ------------------------------------------------------------------
    def _on_features(self, data):
        try:
            stamp_ns, pixels = cdr.polygon_stamped_pixels(data)
        except ValueError as exc:
            self.get_logger().error(str(exc), throttle_duration_sec=1.0)
            return
        self.pending_frames.append((stamp_ns, (cdr.stamp_time(stamp_ns), pixels)))
        if len(self.pending_frames) > MAX_PENDING_FRAMES:
            del self.pending_frames[0]
            self.superseded += 1

    def _take_frame(self, stamp_ns):
        """The newest pending frame captured at or before ``stamp_ns``; the rest stay."""
        due = [item for item in self.pending_frames if item[0] <= stamp_ns]
        if not due:
            return None
        self.pending_frames = [item for item in self.pending_frames if item[0] > stamp_ns]
        self.superseded += len(due) - 1
        return max(due, key=lambda item: item[0])[1]

    def _on_joint_state(self, data):
        if self.wall_last_state is None or time.monotonic() - self.wall_last_state > \
                JOINT_STATE_WATCHDOG:
            self.get_logger().info("joint states arriving")
        self.wall_last_state = time.monotonic()
        try:
            stamp_ns = cdr.header_stamp_ns(data, "joint state")
        except ValueError as exc:       # not even a stamp to answer
            self.get_logger().error(str(exc), throttle_duration_sec=1.0)
            return
        frame = self._take_frame(stamp_ns)
        if not self.effort_active:
            return       # the effort controller would not pass a command on
        t = cdr.stamp_time(stamp_ns)
        try:
            _, q, qd = self.joint_states.decode(data)
        except ValueError as exc:
            self.get_logger().error(str(exc), throttle_duration_sec=1.0)
            q = qd = None
        x_stamp, x = (None, None) if frame is None else frame
        result = self.tracker.step(t, q, qd, x, x_stamp)
        self.samples += 1
        self._publish(result, stamp_ns)

    def _on_activity(self, msg):
        states = {c.name: c.state.label for c in msg.controllers}
        active = states.get(self.effort_controller) == "active"
        if active == self.effort_active:
            return
        self.effort_active = active
        if active:
            # the arm did not get this node's commands meanwhile: a new start from where it is
            self.tracker = AdaptiveVisualTracker(self.tracker.config)
            self.get_logger().info(f"{self.effort_controller} is active: tracking starts from "
                                   f"the measured state")
        else:
            state = states.get(self.effort_controller, "not loaded")
            self.get_logger().warning(f"{self.effort_controller} is {state}: it passes no "
                                      f"command on, so tracking stops until it is active again")
        self.diagnostics_pub.publish(m.diagnostics_to_msg(
            self.msgs, self.get_clock().now().nanoseconds * 1e-9,
            "controller_node", "OK" if active else "WARN",
            f"{self.effort_controller} {'active' if active else 'not active: not tracking'}",
            {}, "controller"))

    def _on_watchdog(self):
        if self.wall_last_state is None:
            return
        silent = time.monotonic() - self.wall_last_state
        if silent > JOINT_STATE_WATCHDOG:
            self.get_logger().warning(f"no joint state for {silent:.1f} s of wall time: "
                                      f"not tracking (the hardware or the simulator stopped?)",
                                      throttle_duration_sec=5.0)

    # -- one sample's outputs ----------------------------------------------------
    def _publish(self, res, stamp_ns):
        msgs = self.msgs
        # the command its consumer takes first: the simulator in lockstep waits for the stamped
        # one, the effort controller (or the simulator in realtime) takes the other; both
        # serialized here (recording.cdr: the bytes of m.float_array_to_msg and
        # m.effort_command_to_msg)
        command = cdr.float64_array(res.tau)
        stamped = self.command_cdr.encode(stamp_ns, NO_VALUES, NO_VALUES, res.tau)
        if self.lockstep:
            self.stamped_command_pub.publish(stamped)
            self.command_pub.publish(command)
        else:
            self.command_pub.publish(command)
            self.stamped_command_pub.publish(stamped)
        if self.state_gate is None or self.state_gate.due(res.t):
            for topic, msg in m.controller_state_outputs(msgs, res, self.labels):
                self.publishers_by_topic[topic].publish(msg)
        self._publish_diagnostics(res)

    def _publish_diagnostics(self, res):
        due = self.diagnostics_gate.due(res.t)
        if self.every_sample:
            changed = res.status != self.last_status      # as vas run records them
            self.last_status = res.status
        else:
            changed = False
            # health() formats its values: only computed when its level may have changed
            key = (res.status, res.saturated, res.projection_active, res.damped)
            if key != self.health_key:
                self.health_key = key
                level = health(res)[0]
                changed, self.last_level = level != self.last_level, level
        if not (due or changed):
            return
        level, message, values = health(res)
        values.update(frame_values(self.tracker.frames, self.superseded,
                                   getattr(self.tracker, "frame_noise", float("nan"))))
        self.diagnostics_pub.publish(m.diagnostics_to_msg(
            self.msgs, res.t, "controller_node", level, message, values, "controller"))

    # -- parameters --------------------------------------------------------------
    def _on_set_parameters(self, parameters):
        changes, refused = runtime_changes(self.specs, parameters)
        if refused:
            return SetParametersResult(successful=False, reason=refused)
        if changes:
            try:
                self.tracker.update_gains(**changes)
            except ConfigError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
            self.get_logger().info(f"parameters changed: {sorted(changes)}")
        return SetParametersResult(successful=True)

    def flush_on_exit(self):
        """In a lockstep recording, wait until the recorder has every message published.

        Called by :func:`.main.run_node` when the node stops (servo.launch.py stops it
        once the simulator is done, and the recorder after it).
        """
        if not (self.lockstep and self.every_sample):
            return
        timeout = Duration(seconds=FLUSH_TIMEOUT)
        for pub in (*self.publishers_by_topic.values(), self.diagnostics_pub):
            if not pub.wait_for_all_acked(timeout):
                self.get_logger().warning(f"{pub.topic_name}: not every message reached its "
                                          f"subscribers within {FLUSH_TIMEOUT:g} s")

    def destroy_node(self):
        self._release_log()
        return super().destroy_node()

    def _release_log(self):
        """The core's logging as it was before this node."""
        core = logging.getLogger("visual_adaptive_servo")
        core.removeHandler(self.log_handler)
        core.setLevel(self.core_level)


def main(args=None):
    return run_node(ControllerNode, CONTROLLER_SECTION, args)


if __name__ == "__main__":
    sys.exit(main())
