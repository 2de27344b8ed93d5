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

Thin: it declares the parameters of :data:`config.sim.SIM_PARAMS`, owns a
:class:`sim_bridge.simulator.Simulator` and turns its measurements into messages.

Topics (DESIGN.md section 2)
----------------------------
out: ``/clock`` (rosgraph_msgs/Clock, the simulated time; this node itself runs on
     wall time and must NOT use_sim_time), ``/joint_states`` (q, q_dot, applied torque,
     stamped with sim time), ``~/true_depth`` (Float64MultiArray, ground truth for plots),
     ``/diagnostics``; the camera at ``camera_rate``, each frame when ``camera_latency``
     has passed, stamped with its capture time:
     ``camera_mode: points``: ``/camera/features`` (PolygonStamped, frame ``camera``;
     nothing when the feature is behind the camera);
     ``camera_mode: rendered``: ``/camera/image_raw`` (sensor_msgs/Image rgb8, the
     rendered picture) and ``/camera/camera_info`` (sensor_msgs/CameraInfo of the
     simulated pinhole camera, for viewers), for the ``feature_detector`` node;
     with ``render.enabled`` ``~/image`` (sensor_msgs/Image rgb8: the camera's view with x
     (red ring), x_d (green cross, from ``/controller_node/desired``) and x_o (blue ring,
     from ``/controller_node/observed``), for humans).
in:  lockstep: ``/controller_node/effort_command`` (sensor_msgs/JointState, torques in
     ``effort``, stamped with the joint state they answer); realtime:
     ``/effort_controller/commands`` (std_msgs/Float64MultiArray, one torque per joint in
     ``joint_names`` order: the ros2_control JointGroupEffortController convention);
     rendered lockstep: ``/feature_detector/processed`` (std_msgs/Header: the detector
     has published the features of the picture with this stamp, if it found any).

As a ros2_control hardware (``hardware.command_topic`` set, realtime): the
commands come as ``joint_state_topic_hardware_interface/JointStateTopicSystem``
sends them, a sensor_msgs/JointState with the torques in ``effort``, joints by
name, on ``hardware.command_topic``, and the joint state goes out on
``hardware.state_topic`` (the system's ``joint_states_topic``;
``joint_state_broadcaster`` republishes it on /joint_states).  A command with
NaN is no command (the hardware's command interfaces hold NaN until a
controller writes them).  Without a command (before the first one, or none for
``command_timeout``) the arm is held still on its brakes
(:meth:`Simulator.hold`), time and /clock go on: the controller_manager runs
on /clock, so the controllers can be activated before the arm moves.  With
``hardware.effort_controller`` the arm is also held while that controller is not
active (``<hardware.controller_manager>/activity``): JointGroupEffortController
commands zero effort when it is deactivated, and the arm would fall.

Timing (``timing_mode``)
------------------------
The simulation starts once a controller is connected (it publishes the command
and subscribes /joint_states and the frame topic; in rendered mode a detector
too), with ``start.wait_for_recorder`` also once a recorder subscribes every
topic of :data:`visual_adaptive_servo.recording.recorder.TOPICS` (and /joint_states,
/clock and /camera/features have two subscribers; in rendered mode the pictures too,
unless ``start.recorder_takes_pictures`` is false), then after ``START_SETTLE``
more, so the other processes have matched each other too: the arm does not
fall meanwhile and the recording misses no period.  (A recorder with ``--use-sim-time``
subscribes nothing before /clock has moved, so it cannot be waited for.)

``lockstep`` (default), one period: measure; publish the camera frame due now
(if any) first, then /clock, /joint_states, ~/true_depth; then wait for the
stamped command whose stamp is this joint state's, hold it for one
``control_period``, and so on.  A command stamped otherwise is stale (counted,
logged, not applied).  The controller takes a waiting frame before a waiting
joint state, so it pairs each joint state with the frames sent before it, as
long as they arrive before it: on one host they do, both leave this process
in that order over the same transport (DDS does not order samples of two
writers in general).  With ``frame_ack`` the simulator also waits until every
subscriber has acknowledged the frame (``wait_for_all_acked``, at most
``command_timeout``; a timeout is logged as an error and counted), at the
price of up to one DDS heartbeat period per frame (about 100 ms with Cyclone
DDS's defaults, measured: 40 s of wall time for 400 periods instead of 1.5 s).
The run then equals ``vas run`` to the bit.  If no command comes within
``command_timeout`` seconds of wall time, zero torque is applied for that
period (logged, counted in /diagnostics) and the loop goes on.

Rendered: the picture goes to the detector, and the joint state follows when
the detector reports the picture processed (``/feature_detector/processed``
with its stamp, published after the features, or alone when it found none),
or after ``detector_timeout`` (counted, logged).  The features thus leave the
detector before the joint state leaves here, and on one host they reach the
controller first: deterministic up to the detector timeout.

``realtime``: a wall-clock timer at ``control_period`` applies the latest
/effort_controller/commands (zero torque once it is older than
``command_timeout``; taken from the subscription at the period's start, so that
a command that arrived while the node was busy is not left for the period
after; as a ros2_control hardware the latest command from
``hardware.command_topic``, the brakes without one), then publishes the frame
due now and the joint state first (rendered: the joint state, then the picture,
rendered after it of the same state, so the controller computes while it
renders), /clock and ~/true_depth after them and at
``publish_rate`` (a read-only node parameter, default 100 Hz of simulated time;
as a ros2_control hardware /clock at every period): the controller's period
starts with the joint state, and runs on its stamp, not on /clock (gazebo_ros
publishes /clock at 10 Hz by default).  The node asks for SCHED_FIFO
(``realtime_priority``, :func:`.main.realtime_scheduling`).  A late controller does
not stop this loop, it only makes it apply the previous command again, so
:class:`sim_bridge.command_age.CommandAge` counts the periods without a new
command (since the first command; those before it apart) and the age of the
command applied, in periods and in ms of wall time from its arrival (median,
p99, max); /diagnostics carries them (``periods_without_new_command``,
``command_age_periods_*``, ``command_age_ms_*``, ...) and the line at the end
states them.  A new command is a message received since the previous period;
as a ros2_control hardware, which resends the effort controller's latest
command at every cycle, a command whose torques differ from the previous one
(so a new command bit-identical to the one before, a torque held at its
limit, is not seen as new there).  A period whose work outlasts the control
period (rendering a 640x480 picture at every 5 ms period here) is counted
(``overrun_periods``) and stated at the end; a second of simulated time that takes
more than 1/0.9 s of wall time is warned of: the simulation runs slower than real
time.

The per-period messages (the frame, /clock, /joint_states, ~/true_depth, and the
commands in realtime) are serialized and read by :mod:`..recording.cdr`, the
bytes rclpy would make of :func:`..recording.messages.sim_outputs`, without
message objects.

QoS: commands are reliable (depth 10) in both modes.  In lockstep everything
is reliable (depth 10; with ``start.wait_for_recorder`` the published topics but
the pictures keep 2000, so a recorder that falls behind loses no period); in
realtime the measurements (/joint_states, the camera topics, ~/image) are sensor
data (best effort, depth 5) and the rest is reliable.

``duration`` > 0: after that much simulated time the node stops stepping and
exits with status 0.  SIGINT/SIGTERM stop it cleanly (:mod:`.main`).
"""

from __future__ import annotations

import sys
import time

import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.task import Future

from sim_bridge import render
from sim_bridge.command_age import CommandAge
from sim_bridge.simulator import Simulator

from ..config.sim import build_sim_arm, SIM_PARAMS, SimConfig
from ..recording import cdr, messages as m
from ..recording.cadence import RateGate
from ..recording.recorder import TOPICS
from ..schema import ConfigError, SIM_SECTION
from ..vision.overlay import COLOR_DESIRED, COLOR_MEASURED, COLOR_OBSERVED
from .executor import incompatible_qos_warning, RECORDED
from .main import run_node
from .params import declare_rate, declare_schema

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
COMMAND_TOPIC = "/effort_controller/commands"
STAMPED_COMMAND_TOPIC = "/controller_node/effort_command"
FEATURES_TOPIC = "/camera/features"
PROCESSED_TOPIC = "/feature_detector/processed"
DIAGNOSTICS_PERIOD = 1.0   # s of sim time between two /diagnostics when nothing changes
START_POLL = 0.05          # s of wall time between two checks for the subscribers
START_SETTLE = 0.25        # s of wall time everything must stay connected before the start
WAITING_LOG_PERIOD = 5.0   # s of wall time between two "waiting for ..." lines
PUBLISH_RATE = 100.0       # Hz of sim time: /clock and ~/true_depth in realtime
REALTIME_WARNING = 0.9     # realtime: warned of when a second's periods run slower than this
# the controller_manager's ~/activity: published on every change, reliable and transient local
ACTIVITY_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)


class SimNode(Node):
    """Steps the simulator on commands (lockstep) or on a wall-clock timer (realtime)."""

    def __init__(self, **kwargs):
        super().__init__("sim_node", **kwargs)
        params = declare_schema(self, SIM_PARAMS, SIM_SECTION, build_sim_arm)
        self.config = config = SimConfig.from_params(params)
        self.sim = Simulator(config)
        self.msgs = msgs = m.rclpy_messages()
        self.joint_state_cdr = cdr.JointStateEncoder(config.joint_names)
        publish_rate = declare_rate(
            self, SIM_SECTION, "publish_rate", PUBLISH_RATE,
            "Rate of /clock and ~/true_depth in realtime, in simulated time (lockstep and as "
            "a ros2_control hardware: every period)")
        self.lockstep = config.timing_mode == "lockstep"
        self.hardware_topic = config["hardware.command_topic"]
        self.state_topic = config["hardware.state_topic"]
        self.rendered = config.camera_mode == "rendered"
        # realtime, not as a hardware (the controller_manager runs a cycle per /clock)
        self.slow_gate = (None if self.lockstep or self.hardware_topic
                          else RateGate(publish_rate, f"{SIM_SECTION}.publish_rate"))
        # a lockstep recording keeps every period: a deep history lets the recorder fall
        # behind without losing one (the pictures keep 10: 2000 of them would be 2 GB)
        recorded = RECORDED if self.lockstep and config["start.wait_for_recorder"] \
            else RELIABLE
        picture_qos = RELIABLE if self.lockstep else qos_profile_sensor_data
        measurement_qos = recorded if self.lockstep else qos_profile_sensor_data

        camera_topics = ((("/camera/image_raw", "Image"), ("/camera/camera_info", "CameraInfo"))
                         if self.rendered else ((FEATURES_TOPIC, "PolygonStamped"),))
        camera_qos = picture_qos if self.rendered else measurement_qos
        self.publishers_by_topic = {
            topic: self.create_publisher(getattr(msgs, kind), topic, qos,
                                         event_callbacks=incompatible_qos_warning(self, topic))
            for topic, kind, qos in (
                *((topic, kind, camera_qos) for topic, kind in camera_topics),
                ("/clock", "Clock", recorded),
                (self.state_topic, "JointState", measurement_qos),
                ("~/true_depth", "Float64MultiArray", recorded))}
        # sim_outputs names the joint state /joint_states, wherever it is published
        self.publishers_by_topic["/joint_states"] = self.publishers_by_topic.pop(self.state_topic)
        self.diagnostics_pub = self.create_publisher(
            msgs.DiagnosticArray, "/diagnostics", recorded,
            event_callbacks=incompatible_qos_warning(self, "/diagnostics"))
        if self.lockstep:
            self.command_sub = self.create_subscription(
                msgs.JointState, STAMPED_COMMAND_TOPIC, self._on_stamped_command, RELIABLE)
        elif self.hardware_topic:
            self.command_sub = self.create_subscription(
                msgs.JointState, self.hardware_topic, self._on_hardware_command, RELIABLE)
        else:
            # serialized (cdr): the command is read without a message object, every period
            self.command_sub = self.create_subscription(
                msgs.Float64MultiArray, COMMAND_TOPIC, self._on_command, RELIABLE, raw=True)
        self.effort_controller = config["hardware.effort_controller"] if self.hardware_topic \
            else ""
        self.effort_state = None if self.effort_controller else "active"
        if self.effort_controller:
            try:
                from controller_manager_msgs.msg import ControllerManagerActivity
            except ImportError:
                raise ConfigError("sim_node.hardware.effort_controller: needs "
                                  "controller_manager_msgs (ros2_control) installed") from None
            self.create_subscription(ControllerManagerActivity,
                                     f"{config['hardware.controller_manager']}/activity",
                                     self._on_activity, ACTIVITY_QOS)
        self.processed_sub = None
        if self.rendered and self.lockstep:
            self.processed_sub = self.create_subscription(msgs.Header, PROCESSED_TOPIC,
                                                          self._on_detected, RELIABLE)
        self.render_every = 0
        if config.params["render.enabled"]:
            self.image_pub = self.create_publisher(msgs.Image, "~/image", picture_qos)
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
            self.detector_timer = self.create_timer(config["detector_timeout"],
                                                    self._on_detector_timeout, clock=steady,
                                                    autostart=False)
        else:
            # as a ros2_control hardware the timer also publishes /clock half way between steps
            ticks = 2 if self.hardware_topic else 1
            self.step_timer = self.create_timer(config.control_period / ticks, self._on_tick,
                                                clock=steady, autostart=False)
        self.pending_clock = None
        self.ack_timeout = Duration(seconds=config.command_timeout)

        self.finished = Future()
        self.started = False
        self.measurement = None
        self.step_ns = None             # stamp of the joint state waiting for its command
        self.awaiting_detection = None  # stamp of the picture waiting for its features
        self.command, self.command_wall = None, None
        self.command_age = None if self.lockstep else CommandAge()
        self.braking, self.brake_reason = False, ""
        self.counters = {"steps": 0, "command_timeouts": 0, "refused_commands": 0,
                         "stale_commands": 0, "frame_delivery_timeouts": 0,
                         "detector_timeouts": 0, "held_periods": 0}
        if not self.lockstep:
            # periods whose work (the step, the render, the publishing) outlasted the period
            self.counters["overrun_periods"] = 0
            self.longest_period = 0.0       # s of wall time
            # about 1 s: periods, overruns, the longest [s], the first one's start [s of wall]
            self.overrun_window = [0, 0, 0.0, 0.0]
        self.problem = ""
        self.last_level, self.t_last_diagnostics = None, None
        self.wall_start = None
        self.ready_since, self.wall_last_waiting = None, time.monotonic()
        self.get_logger().info(
            f"{config.timing_mode}, camera {config.camera_mode}: waiting for a controller"
            + (" and a recorder" if config["start.wait_for_recorder"] else ""))

    # -- start -------------------------------------------------------------------
    def _subscribers(self, topic):
        """Subscriptions to ``topic`` in the ROS graph, this node's own left out."""
        return sum(1 for info in self.get_subscriptions_info_by_topic(topic)
                   if (info.node_name, info.node_namespace) != (self.get_name(),
                                                                self.get_namespace()))

    def _missing(self):
        """What the start still waits for (empty when everything is connected).

        Subscribers of this node's own publishers are counted as matched
        (``get_subscription_count``), the others from the graph.
        """
        pubs = self.publishers_by_topic
        matched = {topic: pub.get_subscription_count() for topic, pub in pubs.items()}
        matched[pubs["~/true_depth"].topic_name] = matched.pop("~/true_depth")
        matched["/diagnostics"] = self.diagnostics_pub.get_subscription_count()
        need = {"/joint_states": 1, "/camera/features": 1}
        if self.config["start.wait_for_recorder"]:
            need = dict.fromkeys(TOPICS, 1)
            need.update({"/joint_states": 2, "/clock": 2, "/camera/features": 2})
        if self.rendered:
            need["/camera/image_raw"] = 1
            if (self.config["start.wait_for_recorder"]
                    and self.config["start.recorder_takes_pictures"]):
                # the detector's and the recorder's
                need.update({"/camera/image_raw": 2, "/camera/camera_info": 1})
        names = {"/joint_states": self.state_topic}
        missing = [f"{names.get(topic, topic)} ({count} of {need[topic]} subscribers)"
                   for topic in sorted(need)
                   for count in [matched[topic] if topic in matched else self._subscribers(topic)]
                   if count < need[topic]]
        command = (STAMPED_COMMAND_TOPIC if self.lockstep
                   else self.hardware_topic or COMMAND_TOPIC)
        if self.command_sub.get_publisher_count() == 0:
            missing.append(f"{command} (no publisher)")
        if self.rendered and self.count_publishers(FEATURES_TOPIC) == 0:
            missing.append(f"{FEATURES_TOPIC} (no publisher: a feature_detector)")
        if self.processed_sub is not None and self.processed_sub.get_publisher_count() == 0:
            missing.append(f"{PROCESSED_TOPIC} (no publisher: a feature_detector in lockstep)")
        return missing

    def _on_start_poll(self):
        missing = self._missing()
        now = time.monotonic()
        if missing:
            self.ready_since = None
            if now - self.wall_last_waiting >= WAITING_LOG_PERIOD:
                self.get_logger().info("waiting for: " + ", ".join(missing))
                self.wall_last_waiting = now
            return
        if self.ready_since is None:
            self.ready_since = now
        if now - self.ready_since < START_SETTLE:
            return
        self.start_timer.cancel()
        self.started = True
        self.wall_start = time.monotonic()
        self.get_logger().info("controller connected: simulation starts")
        self._publish_measurement()
        if not self.lockstep:
            self.step_timer.reset()

    # -- commands and stepping ---------------------------------------------------
    def _on_stamped_command(self, msg):
        if not self.started or self.finished.done():
            return
        refused = None
        try:
            stamp_ns, tau = m.effort_command_from_msg(msg, self.config.joint_names)
        except ValueError as exc:
            stamp_ns, tau, refused = m.stamp_to_ns(msg.header.stamp), None, str(exc)
        if stamp_ns != self.step_ns:
            self.counters["stale_commands"] += 1
            self.problem = (f"stale command stamped {stamp_ns * 1e-9:.3f} s at "
                            f"t={self.sim.t:.3f}: not applied")
            self.get_logger().warning(self.problem, throttle_duration_sec=1.0)
            return
        self._advance(tau, refused)

    def _on_command(self, data):
        try:
            command = cdr.float64_array_values(data)
        except ValueError as exc:
            self.counters["refused_commands"] += 1
            self.problem = f"{exc}: not applied"
            self.get_logger().warning(self.problem, throttle_duration_sec=1.0)
            return
        self.command, self.command_wall = command, time.monotonic()
        self.command_age.received(self.command_wall)

    def _on_hardware_command(self, msg):
        try:
            _, tau = m.effort_command_from_msg(msg, self.config.joint_names)
        except ValueError as exc:
            self.counters["refused_commands"] += 1
            self.problem = f"{exc}: not applied"
            self.get_logger().warning(self.problem, throttle_duration_sec=1.0)
            return
        if np.all(np.isfinite(tau)):
            # the hardware resends the controller's latest command at every cycle
            new = self.command is None or not np.array_equal(tau, self.command)
            self.command, self.command_wall = tau, time.monotonic()
            if new:
                self.command_age.received(self.command_wall)

    def _on_activity(self, msg):
        states = {c.name: c.state.label for c in msg.controllers}
        state = states.get(self.effort_controller, "not loaded")
        if state != self.effort_state:
            self.effort_state = state
            self.get_logger().info(f"{self.effort_controller} is {state}")

    def _on_command_timeout(self):
        if self.step_ns is None or self.finished.done():
            return
        self.counters["command_timeouts"] += 1
        self.problem = (f"no command within {self.config.command_timeout} s at "
                        f"t={self.sim.t:.3f}: zero torque applied")
        self.get_logger().warning(self.problem, throttle_duration_sec=1.0)
        self._advance(np.zeros(self.sim.n))

    def _on_tick(self):
        if self.finished.done():
            return
        if self.pending_clock is not None:
            # the controller_manager runs a cycle when /clock moves; the joint state its
            # hardware then reads left half a period ago, so it is there (published with
            # the state, /clock would often overtake it: the broadcaster would stamp the
            # previous state with the new time)
            self.publishers_by_topic["/clock"].publish(self.pending_clock)
            self.pending_clock = None
            return
        if not self.hardware_topic:
            self._take_commands()
        now = time.monotonic()
        fresh = (self.command_wall is not None
                 and now - self.command_wall <= self.config.command_timeout)
        if self.hardware_topic:
            self.command_age.period(now, fresh and self.effort_state == "active")
            self._hardware_tick(fresh)
        else:
            self.command_age.period(now, fresh)
            if not fresh and self.command_wall is not None:
                self.counters["command_timeouts"] += 1
                self.problem = (f"command older than {self.config.command_timeout} s at "
                                f"t={self.sim.t:.3f}: zero torque applied")
                self.get_logger().warning(self.problem, throttle_duration_sec=1.0)
            self._advance(self.command if fresh else np.zeros(self.sim.n))
        if not self.finished.done():        # (the last period waits for the recorder)
            self._count_overrun(now, time.monotonic() - now)

    def _take_commands(self):
        """Take the commands that arrived since the last callback, before the period uses one.

        After a period that outlasted the control period (a render) the timer is due at
        once, and an executor runs a due timer before the subscriptions of the same
        wake-up (rclpy's order): the command answering the state just published would be
        left for the period after, one period late, on top of the render's own wait.
        """
        sub = self.command_sub
        with sub.handle:
            while True:
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
                if taken is None:
                    return
                self._on_command(taken[0])

    def _count_overrun(self, start, seconds):
        """Count a period whose work outlasted the control period; warn when behind real time.

        ``start``: the period's start [s of wall time], ``seconds``: its work.  One long
        period now and then (a page fault, another process) only delays the next one; when
        a second of simulated time takes more than 1 / REALTIME_WARNING of wall time (a
        render at every period, or a long one at each frame) the simulation runs slower than
        real time: warned of, at most every 10 s, with how far and why.
        """
        period = self.config.control_period
        self.longest_period = max(self.longest_period, seconds)
        window = self.overrun_window
        if window[0] == 0:
            window[3] = start
        window[0] += 1
        if seconds > period:
            self.counters["overrun_periods"] += 1
            window[1] += 1
            window[2] = max(window[2], seconds)
        if window[0] * period < 1.0:
            return
        simulated, wall = window[0] * period, start + seconds - window[3]
        if simulated < REALTIME_WARNING * wall:
            self.get_logger().warning(
                f"realtime: {simulated:.3g} s of simulated time took {wall:.3g} s of wall time "
                f"({simulated / wall:.2f}x real time): {window[1]} of its {window[0]} periods "
                f"took longer than the control period ({period * 1e3:g} ms; longest "
                f"{window[2] * 1e3:.1f} ms)"
                + (", rendering the camera's picture most of it (a lower sim_node.camera_rate "
                   "renders fewer)" if self.rendered else ""),
                throttle_duration_sec=10.0)
        window[:] = [0, 0, 0.0, 0.0]

    def _hardware_tick(self, fresh):
        """Apply the hardware's latest command, or hold the arm on its brakes without one."""
        if fresh and self.effort_state == "active":
            if self.braking:
                self.braking = False
                self.get_logger().info(f"commands from {self.hardware_topic} at "
                                       f"t={self.sim.t:.3f}: brakes released")
            self._advance(self.command)
            return
        if not self.braking:
            self.braking = True
            if self.effort_state != "active":
                why = f"{self.effort_controller} is {self.effort_state or 'not reported yet'}"
            elif self.command_wall is None:
                why = f"no command yet from {self.hardware_topic}"
            else:
                why = f"no command from {self.hardware_topic} for {self.config.command_timeout} s"
            self.get_logger().warning(f"{why} at t={self.sim.t:.3f}: arm held on its brakes")
            self.brake_reason = why
        self.counters["held_periods"] += 1
        if self.command_wall is not None:
            self.problem = f"{self.brake_reason} at t={self.sim.t:.3f}: arm held on its brakes"
        self.sim.hold()
        self._advance_time()

    def _advance(self, tau, refused=None):
        """Hold ``tau`` for one period (zero torque if it is ``refused``: why), then measure."""
        if self.lockstep:
            self.step_timer.cancel()
            self.step_ns = None
        if refused is None:
            refused = self.sim.apply(tau)
        else:
            self.sim.apply(np.zeros(self.sim.n))
        self.counters["steps"] += 1
        if refused is not None:
            self.counters["refused_commands"] += 1
            self.problem = f"{refused}; zero torque applied"
            self.get_logger().warning(self.problem, throttle_duration_sec=1.0)
        self._advance_time()

    def _advance_time(self):
        """After a period: finish at ``duration``, else publish the new measurement."""
        duration = self.config.duration
        if duration > 0.0 and self.sim.t >= duration - 1e-9:
            self._finish()
            return
        self._publish_measurement()

    def _finish(self):
        self.step_timer.cancel()
        # what was published reaches its subscribers (a recorder) before the node exits
        for pub in (*self.publishers_by_topic.values(), self.diagnostics_pub):
            pub.wait_for_all_acked(self.ack_timeout)
        wall = time.monotonic() - self.wall_start
        c = self.counters
        self.get_logger().info(
            f"duration {self.config.duration} s reached after {c['steps']} steps "
            f"in {wall:.1f} s wall time; {c['command_timeouts']} command timeouts, "
            f"{c['refused_commands']} refused commands, {c['stale_commands']} stale commands, "
            f"{c['frame_delivery_timeouts']} frame delivery timeouts, "
            f"{c['detector_timeouts']} detector timeouts, "
            f"{c['held_periods']} periods held on the brakes"
            + ("" if self.lockstep else
               f", {c['overrun_periods']} periods longer than the control period (longest "
               f"{self.longest_period * 1e3:.1f} ms)")
            + ("" if self.command_age is None else "; " + self.command_age.summary()))
        self.finished.set_result(True)

    # -- outputs -----------------------------------------------------------------
    def _publish_measurement(self):
        if self.rendered and not self.lockstep:
            # realtime: the joint state first, then the picture (rendered after it, of the
            # same state): the controller computes its command while the picture renders,
            # and the frame reaches it a period later, stamped with its capture time
            meas = self.sim.measure(defer_picture=True)
            self._publish_state(meas)
            meas = self.measurement = self.sim.render_deferred(meas)
            for topic, msg in m.camera_outputs(self.msgs, meas, self.sim.camera):
                self.publishers_by_topic[topic].publish(msg)
            return
        meas = self.measurement = self.sim.measure()
        if self.rendered:
            for topic, msg in m.camera_outputs(self.msgs, meas, self.sim.camera):
                self.publishers_by_topic[topic].publish(msg)
            if self.lockstep and meas.image is not None:
                self.awaiting_detection = m.time_to_ns(meas.feature_stamp)
                self.detector_timer.reset()
                return
        self._publish_state(meas)

    def _on_detected(self, msg):
        if self.awaiting_detection is None or m.stamp_to_ns(msg.stamp) != self.awaiting_detection:
            return
        self.detector_timer.cancel()
        self.awaiting_detection = None
        self._publish_state(self.measurement)

    def _on_detector_timeout(self):
        self.detector_timer.cancel()
        if self.awaiting_detection is None or self.finished.done():
            return
        self.counters["detector_timeouts"] += 1
        self.problem = (f"the detector did not process the frame captured at "
                        f"{self.awaiting_detection * 1e-9:.3f} s within "
                        f"{self.config['detector_timeout']} s")
        self.get_logger().warning(self.problem, throttle_duration_sec=1.0)
        self.awaiting_detection = None
        self._publish_state(self.measurement)

    def _publish_state(self, meas):
        """The frame (points mode), delivered first in lockstep, then the joint state.

        As a ros2_control hardware /clock follows half a period later (:meth:`_on_tick`).
        """
        t = meas.t
        # serialized once here (recording.cdr: the bytes rclpy would make of m.sim_outputs)
        outputs = cdr.sim_outputs(self.joint_state_cdr, meas)
        if not self.lockstep:
            # the joint state right after the frame: the controller's period starts with it
            outputs.sort(key=lambda output: output[0] not in (FEATURES_TOPIC, "/joint_states"))
        if self.slow_gate is not None and not self.slow_gate.due(t):
            outputs = [output for output in outputs if output[0] in (FEATURES_TOPIC,
                                                                     "/joint_states")]
        for topic, msg in outputs:
            if topic == "/clock" and self.hardware_topic:
                self.pending_clock = msg        # half a period later (_on_tick)
                continue
            pub = self.publishers_by_topic[topic]
            pub.publish(msg)
            if topic == FEATURES_TOPIC and self.lockstep and self.config["frame_ack"]:
                self._wait_delivered(pub, meas.feature_stamp)
        if meas.problems:
            self.problem = "; ".join(meas.problems)
        self._publish_diagnostics(t)
        if self.render_every and self.counters["steps"] % self.render_every == 0:
            self._publish_image(meas)
        if self.lockstep:
            self.step_ns = m.time_to_ns(t)
            self.step_timer.reset()

    def _wait_delivered(self, pub, stamp):
        if pub.wait_for_all_acked(self.ack_timeout):
            return
        self.counters["frame_delivery_timeouts"] += 1
        self.problem = (f"frame captured at {stamp:.3f} s not acknowledged by every subscriber "
                        f"within {self.config.command_timeout} s: the joint state may overtake it")
        self.get_logger().error(self.problem, throttle_duration_sec=1.0)

    def _publish_diagnostics(self, t):
        level = "WARN" if self.problem else "OK"
        if (level == self.last_level and self.t_last_diagnostics is not None
                and t - self.t_last_diagnostics < DIAGNOSTICS_PERIOD - 1e-9):
            return
        wall = time.monotonic() - self.wall_start
        values = dict(self.counters, timing_mode=self.config.timing_mode, sim_time=f"{t:.3f}",
                      realtime_factor=f"{t / wall:.3g}" if wall > 0 else "inf")
        if self.command_age is not None:
            values.update(self.command_age.values())
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
    return run_node(SimNode, SIM_SECTION, args, (ConfigError, ValueError))


if __name__ == "__main__":
    sys.exit(main())
