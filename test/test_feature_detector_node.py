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

"""The feature detector node through real rclpy topics.

Needs a sourced ROS 2 Jazzy (skipped otherwise).  Each test runs in its own
rclpy context on a private ROS domain, with the node and a probe node in one
executor (the nodes' own, conftest.spin_until).  Oracle: the exact centroids of
the supersampled discs of conftest.draw_discs, and the stamp of the image that
was published.
"""

import os

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="needs a sourced ROS 2 Jazzy (rclpy)")

from rclpy.parameter import Parameter  # noqa: E402

from conftest import draw_discs, spin_until  # noqa: E402
from visual_adaptive_servo.recording import messages as m  # noqa: E402
from visual_adaptive_servo.schema import ConfigError  # noqa: E402
from visual_adaptive_servo.ros.feature_detector_node import FeatureDetectorNode, main  # noqa: E402
from visual_adaptive_servo.vision.overlay import COLOR_DESIRED, COLOR_MEASURED  # noqa: E402

DOMAIN_ID = 50 + os.getpid() % 50
RED, GREEN = (230, 30, 30), (30, 200, 30)
H, W = 120, 160
STAMP = (1_700_000_000, 123_456_789)      # a wall-clock stamp: not exact as float seconds
# two markers, standard camera convention (u = column, v = row)
PARAMETERS = [Parameter("markers.colors", value=[float(c) for c in RED + GREEN]),
              Parameter("pixel_origin", value=[0.0, 0.0]),
              Parameter("pixel_axes", value=[1.0, 1.0])]


@pytest.fixture()
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    yield ctx
    rclpy.try_shutdown(context=ctx)


class Probe:
    """A camera publishing images and a listener recording what the detector publishes."""

    def __init__(self, context):
        self.node = rclpy.create_node("probe", context=context)
        self.msgs = msgs = m.rclpy_messages()
        self.features, self.statuses, self.overlays, self.processed = [], [], [], []
        self.camera = self.node.create_publisher(msgs.Image, "/camera/image_raw", 10)
        self.desired = self.node.create_publisher(msgs.PolygonStamped,
                                                  "/controller_node/desired", 10)
        self.node.create_subscription(msgs.PolygonStamped, "/camera/features",
                                      self.features.append, 10)
        self.node.create_subscription(msgs.Header, "/feature_detector/processed",
                                      self.processed.append, 10)
        self.node.create_subscription(
            msgs.DiagnosticArray, "/diagnostics",
            lambda msg: self.statuses.extend(s for s in msg.status
                                             if s.name == "feature_detector"), 10)

    def listen_to_overlay(self):
        self.node.create_subscription(self.msgs.Image, "/feature_detector/overlay",
                                      self.overlays.append, 10)

    def publish_image(self, rgb):
        msg = m.image_to_msg(self.msgs, 0.0, rgb, frame_id="camera_optical")
        msg.header.stamp = self.msgs.Time(sec=STAMP[0], nanosec=STAMP[1])
        self.camera.publish(msg)


def _connected(context, node, probe, overlay=False):
    def ready():
        return (probe.camera.get_subscription_count() > 0
                and node.features_pub.get_subscription_count() > 0
                and node.diagnostics_pub.get_subscription_count() > 0
                and (not overlay or node.overlay_pub.get_subscription_count() > 0))
    spin_until(context, [node, probe.node], ready, 10.0)
    assert ready(), "the probe and the detector did not discover each other in 10 s"


def test_features_of_an_image_carry_its_stamp_and_frame(context):
    node = FeatureDetectorNode(context=context, parameter_overrides=PARAMETERS)
    probe = Probe(context)
    try:
        _connected(context, node, probe)
        image, truth = draw_discs(H, W, [(40.3, 50.7, 6.0, RED), (110.6, 70.2, 6.0, GREEN)])
        probe.publish_image(image)
        spin_until(context, [node, probe.node], lambda: probe.features and probe.statuses, 10.0)
        assert len(probe.features) == 1
        spin_until(context, [node, probe.node], lambda: probe.processed, 10.0)
        assert [(p.stamp.sec, p.stamp.nanosec) for p in probe.processed] == [STAMP]
        msg = probe.features[0]
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == STAMP
        assert msg.header.frame_id == "camera_optical"
        assert [p.z for p in msg.polygon.points] == [0.0, 0.0]
        # Point32 holds float32: ~1e-5 px at these coordinates
        np.testing.assert_allclose(m.features_from_msg(msg)[1], truth.reshape(-1), atol=0.02)
        status = probe.statuses[-1]
        assert status.level in (0, b"\x00")
        values = {kv.key: kv.value for kv in status.values}
        assert (values["frames"], values["frames_without_features"]) == ("1", "0")
    finally:
        probe.node.destroy_node()
        node.destroy_node()


def test_frame_with_a_missing_marker_gives_no_features_and_a_warning(context):
    node = FeatureDetectorNode(context=context, parameter_overrides=PARAMETERS)
    probe = Probe(context)
    try:
        _connected(context, node, probe)
        image, _ = draw_discs(H, W, [(40.3, 50.7, 6.0, RED)])
        probe.publish_image(image)
        spin_until(context, [node, probe.node], lambda: probe.statuses, 10.0)
        spin_until(context, [node, probe.node], lambda: False, 0.3)   # nothing else may come
        assert probe.features == []
        # lockstep: the simulator hears at once that this frame has no features
        assert [(p.stamp.sec, p.stamp.nanosec, p.frame_id) for p in probe.processed] == \
            [STAMP + ("camera_optical",)]
        status = probe.statuses[-1]
        assert status.level in (1, b"\x01")
        assert status.message.startswith("marker 2 missing: no pixel within tolerance")
        values = {kv.key: kv.value for kv in status.values}
        assert values["frames_without_features"] == "1"
        assert values["last_reason"] == status.message
    finally:
        probe.node.destroy_node()
        node.destroy_node()


def test_unsupported_encoding_is_reported_not_fatal(context):
    node = FeatureDetectorNode(context=context, parameter_overrides=PARAMETERS)
    probe = Probe(context)
    try:
        _connected(context, node, probe)
        msg = m.image_to_msg(probe.msgs, 0.5, np.zeros((4, 4, 3), np.uint8))
        msg.encoding = "mono8"
        probe.camera.publish(msg)
        spin_until(context, [node, probe.node], lambda: probe.statuses, 10.0)
        assert probe.features == []
        assert probe.statuses[-1].level in (1, b"\x01")
        assert "encoding 'mono8' is not supported" in probe.statuses[-1].message
    finally:
        probe.node.destroy_node()
        node.destroy_node()


def test_overlay_shows_the_detected_and_the_desired_features(context):
    node = FeatureDetectorNode(context=context, parameter_overrides=PARAMETERS)
    probe = Probe(context)
    probe.listen_to_overlay()
    try:
        _connected(context, node, probe, overlay=True)
        spin_until(context, [node, probe.node],
                   lambda: probe.desired.get_subscription_count() > 0, 10.0)
        probe.desired.publish(m.features_to_msg(probe.msgs, 0.0, [80.5, 20.5, 30.5, 100.5]))
        spin_until(context, [node, probe.node], lambda: node.overlay["desired"] is not None, 10.0)
        image, truth = draw_discs(H, W, [(40.3, 50.7, 6.0, RED), (110.6, 70.2, 6.0, GREEN)])
        probe.publish_image(image)
        spin_until(context, [node, probe.node], lambda: probe.overlays, 10.0)
        overlay = probe.overlays[0]
        assert (overlay.header.stamp.sec, overlay.header.stamp.nanosec) == STAMP
        rgb = m.image_from_msg(overlay)[1]
        assert rgb.shape == (H, W, 3) and overlay.encoding == "rgb8"
        assert tuple(rgb[20, 80]) == COLOR_DESIRED and tuple(rgb[100, 30]) == COLOR_DESIRED
        col, row = (int(v) for v in truth[0])
        ring = rgb[row - 5:row + 6, col - 5:col + 6].reshape(-1, 3)
        assert any(tuple(p) == COLOR_MEASURED for p in ring)
    finally:
        probe.node.destroy_node()
        node.destroy_node()


def test_tuning_parameters_change_while_running_and_bad_sets_are_refused(context):
    node = FeatureDetectorNode(context=context, parameter_overrides=PARAMETERS)
    try:
        ok = node.set_parameters([Parameter("markers.tolerance", value=20.0)])[0]
        assert ok.successful, ok.reason
        assert node.config.tolerance == 20.0

        overlap = node.set_parameters([Parameter("markers.tolerance", value=150.0)])[0]
        assert not overlap.successful
        assert "feature_detector.markers.tolerance: markers 1 and 2 differ" in overlap.reason
        assert node.config.tolerance == 20.0

        fewer = node.set_parameters([Parameter("markers.colors", value=[1.0, 2.0, 3.0])])[0]
        assert not fewer.successful and "number of markers cannot change" in fewer.reason

        fixed = node.set_parameters([Parameter("pixel_axes", value=[-1.0, -1.0])])[0]
        assert not fixed.successful and "read-only" in fixed.reason
        np.testing.assert_array_equal(node.config.pixel_axes, [1.0, 1.0])
    finally:
        node.destroy_node()


@pytest.mark.parametrize("timing_mode, recorded, depth, reliable", [
    ("lockstep", True, 2000, True),     # every frame in the bag, as the simulator's topics
    ("lockstep", False, 10, True),
    ("realtime", True, 5, False),       # sensor data: a recorder takes what it can
])
def test_a_recorded_lockstep_run_keeps_the_features_for_a_recorder_that_falls_behind(
        context, timing_mode, recorded, depth, reliable):
    from rclpy.qos import ReliabilityPolicy
    from visual_adaptive_servo.ros.executor import RECORDED_DEPTH

    node = FeatureDetectorNode(context=context, parameter_overrides=[
        Parameter("timing_mode", value=timing_mode), Parameter("recorded", value=recorded)])
    try:
        qos = node.features_pub.qos_profile
        assert qos.depth == depth
        assert (qos.reliability == ReliabilityPolicy.RELIABLE) == reliable
        if recorded and timing_mode == "lockstep":
            assert depth == RECORDED_DEPTH
    finally:
        node.destroy_node()


@pytest.mark.parametrize("name, value, match", [
    ("markers.colors", [255.0, 0.0, 0.0, 0.0],
     r"feature_detector\.markers\.colors: needs 3 values per marker, got 4"),
    ("markers.tolerance", "forty",
     r"feature_detector\.markers\.tolerance: must be a number, got 'forty'"),
    ("markers.tolerance", 300.0, r"feature_detector\.markers\.tolerance: "),
    ("pixel_axes", [1.0, 2.0], r"feature_detector\.pixel_axes: every entry must be \+1 or -1"),
    ("timing_mode", "fast", r"feature_detector\.timing_mode: must be one of"),
])
def test_invalid_configuration_is_refused_at_start_up(context, name, value, match):
    with pytest.raises(ConfigError, match=match):
        FeatureDetectorNode(context=context, parameter_overrides=[Parameter(name, value=value)])


def test_main_exits_with_status_2_on_an_invalid_configuration():
    assert main(["--ros-args", "-p", "blob_area:=[50.0, 10.0]"]) == 2
