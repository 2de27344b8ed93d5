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

"""``feature_detector``: coloured markers in a camera image -> the controller's pixels.

Thin: it declares the parameters of :data:`config.detector.DETECTOR_PARAMS`, turns the
image into an array (:func:`recording.messages.image_from_msg`) and calls
:func:`vision.detection.detect`; the pixel convention (``pixel_origin``,
``pixel_axes``) is documented in :mod:`vision.detection`.

Topics (DESIGN.md section 2)
----------------------------
in:  ``/camera/image_raw`` (sensor_msgs/Image: rgb8, bgr8, rgba8 or bgra8),
     ``/controller_node/desired``, ``/controller_node/observed`` (PolygonStamped x_d,
     x_o; drawn on the overlay, nothing else)
out: ``/camera/features`` (geometry_msgs/PolygonStamped, one Point32 (u, v, 0) per
     marker in feature order, with the image's stamp and frame_id), only for a
     frame in which every marker was found exactly once;
     ``~/overlay`` (sensor_msgs/Image rgb8, with ``overlay.enabled`` and only while
     someone subscribes: the input image with x as a red ring, x_d a green cross
     and x_o a blue ring, for rqt_image_view or Foxglove);
     ``/diagnostics`` (name ``feature_detector``): WARN with the reason when a
     frame gives no features, OK when it does; published when the level changes
     and otherwise at most once a second (wall time), with the counters
     ``frames``, ``frames_without_features`` and ``last_reason``;
     lockstep only: ``~/processed`` (std_msgs/Header, the image's stamp and
     frame_id) once per image, after the features (see below).

QoS: ``timing_mode: lockstep`` makes the image subscription and the features
(and overlay) publishers reliable (depth 10), ``realtime`` makes them sensor
data (best effort, depth 5), as for the other nodes' measurements; the
controller and the camera driver must use the same.  A lockstep run that is
recorded (``recorded: true``) keeps 2000 features messages, so a recorder that
falls behind loses none (ros/executor.py ``RECORDED``; the pictures keep 10).

Lockstep (the simulator's rendered mode): after each image, features or not,
the node publishes ``~/processed`` (std_msgs/Header with the image's stamp),
after the features.  The simulator waits for it before it publishes the joint
state, so the features leave this process before the simulator even hears
that they exist: on one host they reach the controller before the joint
state does, however the processes are scheduled.  (Waiting for the features
themselves would not do: one write goes to the simulator and to the controller
one after the other, and a preemption in between let the joint state overtake
the controller's copy in 1 of 400 frames here.)  A frame without features
costs the simulator no wait.

Runtime parameters: ``markers.colors`` (the number of markers cannot change),
``markers.tolerance`` and ``blob_area`` can be set while running, for tuning
against the live overlay; the new set is validated whole by
:func:`config.detector.detector_config` before it is applied.
"""

from __future__ import annotations

import sys
import time

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from ..config.detector import DETECTOR_PARAMS, detector_config
from ..recording import messages as m
from ..schema import ConfigError, DETECTOR_SECTION
from ..vision.detection import image_points
from ..vision.overlay import COLOR_DESIRED, COLOR_MEASURED, COLOR_OBSERVED, draw_points
from .executor import RECORDED
from .main import run_node
from .params import declare_schema, runtime_changes

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
DIAGNOSTICS_PERIOD = 1.0   # s of wall time between two /diagnostics when the level stays


class FeatureDetectorNode(Node):
    """Detects the markers in each image and publishes their pixels."""

    def __init__(self, **kwargs):
        super().__init__(DETECTOR_SECTION, **kwargs)
        self.specs = {spec.name: spec for spec in DETECTOR_PARAMS}
        self.params = declare_schema(self, DETECTOR_PARAMS, DETECTOR_SECTION)
        self.config = detector_config(self.params)
        self.detector = self.config.detector()
        self.msgs = msgs = m.rclpy_messages()

        self.lockstep = self.params["timing_mode"] == "lockstep"
        qos = RELIABLE if self.lockstep else qos_profile_sensor_data
        features_qos = RECORDED if self.lockstep and self.params["recorded"] else qos
        self.features_pub = self.create_publisher(msgs.PolygonStamped, "/camera/features",
                                                  features_qos)
        self.processed_pub = (self.create_publisher(msgs.Header, "~/processed", RELIABLE)
                              if self.lockstep else None)
        self.diagnostics_pub = self.create_publisher(msgs.DiagnosticArray, "/diagnostics",
                                                     RELIABLE)
        self.overlay_pub = None
        self.overlay = {"desired": None, "observed": None}
        if self.params["overlay.enabled"]:
            self.overlay_pub = self.create_publisher(msgs.Image, "~/overlay", qos)
            for key in self.overlay:
                self.create_subscription(msgs.PolygonStamped, f"/controller_node/{key}",
                                         lambda msg, key=key: self._on_overlay(key, msg),
                                         RELIABLE)
        self.create_subscription(msgs.Image, "/camera/image_raw", self._on_image, qos)
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self.counters = {"frames": 0, "frames_without_features": 0}
        self.last_reason = ""
        self.last_level, self.wall_last_diagnostics = None, None
        what = (f"tag {self.config.family} id {self.config.tag_id}, points "
                f"{list(self.config.points)}" if self.params["type"] == "apriltag" else
                f"{self.config.m} marker(s), colours {self.config.colors.tolist()}")
        self.get_logger().info(f"{what}, timing_mode {self.params['timing_mode']}")

    # -- one frame ---------------------------------------------------------------
    def _on_image(self, msg):
        self.counters["frames"] += 1
        try:
            _, rgb = m.image_from_msg(msg)
        except ValueError as exc:
            self._no_features(msg, str(exc))
        else:
            result = self.detector.detect(rgb)
            if result.pixels is None:
                self._no_features(msg, result.reason)
            else:
                self.features_pub.publish(m.features_for_image(self.msgs, msg.header,
                                                               result.pixels))
                self._publish_diagnostics(msg, "OK", f"{self.config.m} marker(s) found")
            if self.overlay_pub is not None and self.overlay_pub.get_subscription_count() > 0:
                self._publish_overlay(msg, rgb, result.pixels)
        if self.processed_pub is not None:
            self.processed_pub.publish(m.copy_header(self.msgs, msg.header))

    def _no_features(self, msg, reason):
        self.counters["frames_without_features"] += 1
        self.last_reason = reason
        self.get_logger().warning(f"no features: {reason}", throttle_duration_sec=1.0)
        self._publish_diagnostics(msg, "WARN", reason)

    def _publish_diagnostics(self, msg, level, message):
        now = time.monotonic()
        if (level == self.last_level and self.wall_last_diagnostics is not None
                and now - self.wall_last_diagnostics < DIAGNOSTICS_PERIOD):
            return
        values = dict(self.counters, last_reason=self.last_reason)
        self.diagnostics_pub.publish(m.diagnostics_to_msg(
            self.msgs, m.stamp_to_time(msg.header.stamp), DETECTOR_SECTION, level, message,
            values, "camera"))
        self.last_level, self.wall_last_diagnostics = level, now

    # -- overlay -----------------------------------------------------------------
    def _on_overlay(self, key, msg):
        self.overlay[key] = m.features_from_msg(msg)[1]

    def _publish_overlay(self, msg, rgb, pixels):
        for points, color, shape in ((self.overlay["desired"], COLOR_DESIRED, "cross"),
                                     (self.overlay["observed"], COLOR_OBSERVED, "ring"),
                                     (pixels, COLOR_MEASURED, "ring")):
            if points is not None:
                draw_points(rgb, image_points(points, self.config), color, shape)
        image = m.image_to_msg(self.msgs, 0.0, rgb)
        image.header = m.copy_header(self.msgs, msg.header)
        self.overlay_pub.publish(image)

    # -- parameters --------------------------------------------------------------
    def _on_set_parameters(self, parameters):
        changes, refused = runtime_changes(self.specs, parameters)
        if refused:
            return SetParametersResult(successful=False, reason=refused)
        if not changes:
            return SetParametersResult(successful=True)
        params = dict(self.params, **changes)
        try:
            config = detector_config(params)
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if config.m != self.config.m:
            return SetParametersResult(
                successful=False,
                reason=f"{DETECTOR_SECTION}.markers.colors: the number of markers cannot "
                       f"change while running ({self.config.m}, got {config.m})")
        self.params, self.config, self.detector = params, config, config.detector()
        self.get_logger().info(f"parameters changed: {sorted(changes)}")
        return SetParametersResult(successful=True)


def main(args=None):
    return run_node(FeatureDetectorNode, DETECTOR_SECTION, args)


if __name__ == "__main__":
    sys.exit(main())
