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

Thin: it declares the parameters of :data:`config.CONTROLLER_PARAMS`, turns
messages into arrays and back (:mod:`.messages`) and calls
:class:`controller.AdaptiveVisualTracker`.

Topics (DESIGN.md section 2)
----------------------------
in:  ``/joint_states`` (sensor_msgs/JointState, joints picked by ``joint_names``),
     ``/camera/features`` (geometry_msgs/PolygonStamped, pixels, origin on the optical axis)
out: ``/effort_controller/commands`` (std_msgs/Float64MultiArray, one torque per joint in
     ``joint_names`` order: the ros2_control JointGroupEffortController convention),
     ``~/desired``, ``~/observed``, ``~/tracking_error`` (PolygonStamped: x_d, x_o, x - x_d),
     ``~/estimated_depth``, ``~/parameters`` (Float64MultiArray, labelled), ``/diagnostics``.

Pairing: the newest unprocessed joint state is paired with the newest
unprocessed feature; a sample is processed when both have arrived, at the
joint state's stamp.  A joint state that finds no feature within one
``sample_time`` of wall time is processed without one (the tracker then holds
its last command and falls back safely, see ``safety.*``); a joint state that
cannot be converted is processed as a rejected sample.

QoS: the command is published reliable (depth 10).  With
``timing_mode: lockstep`` every subscription is reliable (depth 10): the
simulator waits for each command, so nothing may be lost.  With
``timing_mode: realtime`` the measurements are sensor data (best effort,
depth 5): a late sample is worth less than the next one.  ``timing_mode`` must
match the publisher's: a reliable subscription does not match a best-effort
publisher.

Runtime parameters (``runtime`` in the schema: gains K and Gamma_*, torque
limit, damping and safety settings) can be changed with ``ros2 param set``;
the complete new set is validated by ``ControllerConfig.from_params`` before
it is applied.  All other parameters are read-only.
"""

from __future__ import annotations

import logging
import sys
import time

import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from . import messages as m
from .config import (
    CONTROLLER_PARAMS,
    CONTROLLER_SECTION,
    ConfigError,
    ControllerConfig,
    build_controller_model,
)
from .controller import AdaptiveVisualTracker, health
from .ros_params import declare_schema, from_ros

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
DIAGNOSTICS_PERIOD = 1.0   # s of sim time between two /diagnostics when nothing changes


class RosLogHandler(logging.Handler):
    """Forward the core's Python logging to the node's logger (at most one line a second)."""

    def __init__(self, logger):
        super().__init__()
        self.logger = logger

    def emit(self, record):
        text = self.format(record)
        if record.levelno >= logging.ERROR:
            self.logger.error(text, throttle_duration_sec=1.0)
        elif record.levelno >= logging.WARNING:
            self.logger.warning(text, throttle_duration_sec=1.0)
        else:
            self.logger.info(text, throttle_duration_sec=1.0)


class ControllerNode(Node):
    """Subscribes the measurements, runs the tracker, publishes torques and its state."""

    def __init__(self, **kwargs):
        super().__init__("controller_node", **kwargs)
        self.specs = {spec.name: spec for spec in CONTROLLER_PARAMS}
        built = {}   # the model is built once, while the parameters are declared

        def build(values):
            built["model"] = build_controller_model(values)
            return built["model"]

        params = declare_schema(self, CONTROLLER_PARAMS, CONTROLLER_SECTION, build)
        config = ControllerConfig.from_params(params, model=built.get("model"))
        self.tracker = AdaptiveVisualTracker(config)
        self.joint_names = list(config.joint_names)
        self.labels = m.parameter_labels(config.model)
        self.msgs = m.rclpy_messages()

        measurement_qos = RELIABLE if config.timing_mode == "lockstep" else qos_profile_sensor_data
        msgs = self.msgs
        self.publishers_by_topic = {
            topic: self.create_publisher(getattr(msgs, kind), topic, RELIABLE)
            for topic, kind in (("/effort_controller/commands", "Float64MultiArray"),
                                ("~/desired", "PolygonStamped"),
                                ("~/observed", "PolygonStamped"),
                                ("~/tracking_error", "PolygonStamped"),
                                ("~/estimated_depth", "Float64MultiArray"),
                                ("~/parameters", "Float64MultiArray"))}
        self.diagnostics_pub = self.create_publisher(msgs.DiagnosticArray, "/diagnostics",
                                                     RELIABLE)
        self.create_subscription(msgs.JointState, "/joint_states", self._on_joint_state,
                                 measurement_qos)
        self.create_subscription(msgs.PolygonStamped, "/camera/features", self._on_features,
                                 measurement_qos)
        # wall clock: with use_sim_time a ROS-time timer would stop while the
        # simulator waits for our command
        self.create_timer(config.sample_time, self._on_pair_timeout,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self.pending_state = None      # newest unprocessed JointState
        self.pending_since = None      # wall time the oldest unprocessed one arrived
        self.pending_feature = None    # newest unprocessed PolygonStamped
        self.last_status = None
        self.t_last_diagnostics = None
        self.samples = 0
        self.log_handler = RosLogHandler(self.get_logger())
        logging.getLogger("visual_adaptive_servo").addHandler(self.log_handler)
        self.get_logger().info(f"model {params['model']}, joints {self.joint_names}, "
                               f"timing_mode {config.timing_mode}")

    # -- inputs ------------------------------------------------------------------
    def _on_joint_state(self, msg):
        if self.pending_state is None:
            self.pending_since = time.monotonic()
        self.pending_state = msg
        self._process_if_paired()

    def _on_features(self, msg):
        self.pending_feature = msg
        self._process_if_paired()

    def _process_if_paired(self):
        if self.pending_state is not None and self.pending_feature is not None:
            self._process(self.pending_state, self.pending_feature)

    def _on_pair_timeout(self):
        waited = (time.monotonic() - self.pending_since) if self.pending_state is not None else 0.0
        if waited >= self.tracker.config.sample_time:
            self._process(self.pending_state, None)

    # -- one sample --------------------------------------------------------------
    def _process(self, state_msg, feature_msg):
        self.pending_state, self.pending_feature, self.pending_since = None, None, None
        t = m.stamp_to_time(state_msg.header.stamp)
        try:
            t, q, qd = m.joint_state_from_msg(state_msg, self.joint_names)
        except ValueError as exc:
            self.get_logger().error(str(exc), throttle_duration_sec=1.0)
            q = qd = None
        x = m.features_from_msg(feature_msg)[1] if feature_msg is not None else None
        result = self.tracker.step(t, q, qd, x)
        self.samples += 1
        self._publish(result)

    def _publish(self, res):
        msgs, t = self.msgs, res.t
        for topic, msg in m.controller_outputs(msgs, res, self.labels):
            self.publishers_by_topic[topic].publish(msg)
        if (res.status != self.last_status or self.t_last_diagnostics is None
                or t - self.t_last_diagnostics >= DIAGNOSTICS_PERIOD - 1e-9):
            level, message, values = health(res)
            self.diagnostics_pub.publish(m.diagnostics_to_msg(
                msgs, t, "controller_node", level, message, values, "controller"))
            self.t_last_diagnostics = t
        self.last_status = res.status

    # -- parameters --------------------------------------------------------------
    def _on_set_parameters(self, parameters):
        changes = {}
        for param in parameters:
            spec = self.specs.get(param.name)
            if spec is None:          # rclpy's own parameters (use_sim_time, ...)
                continue
            if not spec.runtime:
                return SetParametersResult(
                    successful=False,
                    reason=f"{param.name} cannot change while running (restart the node)")
            changes[param.name] = from_ros(spec, param.value)
        if changes:
            try:
                self.tracker.update_gains(**changes)
            except ConfigError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
            self.get_logger().info(f"parameters changed: {sorted(changes)}")
        return SetParametersResult(successful=True)

    def destroy_node(self):
        logging.getLogger("visual_adaptive_servo").removeHandler(self.log_handler)
        return super().destroy_node()


def main(args=None):
    rclpy.init(args=args)
    try:
        node = ControllerNode()
    except ConfigError as exc:
        rclpy.logging.get_logger("controller_node").fatal(f"invalid configuration: {exc}")
        rclpy.try_shutdown()
        return 2
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
