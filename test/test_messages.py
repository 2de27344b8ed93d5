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

"""Arrays <-> ROS 2 messages: round trips, CDR serialisation, rclpy and rosbags agree.

Runs without ROS (the rosbags type store has the Jazzy definitions); the
rclpy cases run where a sourced ROS 2 makes the message packages importable.
The cross check: the same message built through :func:`messages.rclpy_messages`
and serialised by rclpy has exactly the bytes rosbags produces.
"""

import importlib.util

import numpy as np
import pytest

from sim_bridge.camera import PinholeCamera
from visual_adaptive_servo.recording import messages as m
from visual_adaptive_servo.models import make_model
from visual_adaptive_servo.recording.recorder import TOPICS

HAVE_RCLPY = importlib.util.find_spec("rclpy") is not None
NAMES = ["joint1", "joint2", "joint3"]


@pytest.fixture(scope="module")
def bags():
    return m.rosbags_messages()


@pytest.fixture(scope="module", params=["rosbags", "rclpy"])
def msgs(request, bags):
    if request.param == "rosbags":
        return bags
    if not HAVE_RCLPY:
        pytest.skip("rclpy not importable: source a ROS 2 Jazzy setup.bash for these cases")
    return m.rclpy_messages()


def _examples(msgs):
    """(short type name, message) of every type the nodes publish."""
    q = np.array([1.0807, 0.5756, -0.5])
    return [
        ("JointState", m.joint_state_to_msg(msgs, 1.25, NAMES, q, -q, [0.5, 100.0, -7.0])),
        ("PolygonStamped", m.features_to_msg(msgs, 2.005, [65.0, 65.5, -10.25, 3.0])),
        ("Float64MultiArray", m.float_array_to_msg(msgs, [1.0, 2.0], ["a", "b"])),
        ("Float64MultiArray", m.float_array_to_msg(msgs, [])),
        ("Clock", m.clock_to_msg(msgs, 3.5)),
        ("DiagnosticArray", m.diagnostics_to_msg(msgs, 4.0, "controller_node", "WARN",
                                                 "torque saturated", {"status": "ok"})),
        ("Image", m.image_to_msg(msgs, 0.1, np.arange(2 * 3 * 3, dtype=np.uint8)
                                 .reshape(2, 3, 3))),
        ("CameraInfo", m.camera_info_to_msg(msgs, 0.1, _camera())),
        ("JointState", m.effort_command_to_msg(msgs, m.time_to_stamp(msgs, 0.015), NAMES,
                                               [1.5, -2.0, 72.0])),
    ]


def _camera():
    """The paper's camera: f beta = 135 px, principal point (320, 240), 640 x 480."""
    return PinholeCamera.look_at([-5.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 135.0,
                                 135.0, 320.0, 240.0, 640, 480, (320.0, 240.0), (-1.0, -1.0))


def test_joint_state_round_trip_reorders_to_the_requested_names(msgs):
    q = np.array([0.1, 0.2, 0.3])
    qd = np.array([-1.0, -2.0, -3.0])
    msg = m.joint_state_to_msg(msgs, 12.345678901, NAMES, q, qd, [4.0, 5.0, 6.0])
    t, q2, qd2 = m.joint_state_from_msg(msg, ["joint3", "joint1", "joint2"])
    assert t == pytest.approx(12.345678901, abs=1e-9)
    np.testing.assert_array_equal(q2, q[[2, 0, 1]])
    np.testing.assert_array_equal(qd2, qd[[2, 0, 1]])
    np.testing.assert_array_equal(np.asarray(msg.effort), [4.0, 5.0, 6.0])


def test_joint_state_with_a_missing_joint_is_refused_with_its_name(msgs):
    msg = m.joint_state_to_msg(msgs, 0.0, NAMES, [0.0] * 3, [0.0] * 3, [0.0] * 3)
    with pytest.raises(ValueError, match=r"missing joint\(s\) \['elbow'\]"):
        m.joint_state_from_msg(msg, ["joint1", "elbow"])


def test_joint_state_with_too_few_velocities_is_refused(msgs):
    msg = m.joint_state_to_msg(msgs, 0.0, NAMES, [0.0] * 3, [0.0] * 3, [0.0] * 3)
    msg.velocity = msgs.floats([0.0, 0.0])
    with pytest.raises(ValueError, match="3 names but 3 positions and 2 velocities"):
        m.joint_state_from_msg(msg, NAMES)


def test_features_round_trip_one_point_per_feature(msgs):
    pixels = np.array([65.0, 65.5, -10.25, 3.0])
    msg = m.features_to_msg(msgs, 2.005, pixels)
    assert msg.header.frame_id == "camera"
    assert len(msg.polygon.points) == 2 and msg.polygon.points[1].z == 0.0
    t, back = m.features_from_msg(msg)
    assert t == pytest.approx(2.005, abs=1e-9)
    np.testing.assert_allclose(back, pixels)   # Point32 holds float32: these are exact


def test_camera_info_holds_the_pinhole_intrinsics(msgs):
    camera = _camera()
    msg = m.camera_info_to_msg(msgs, 2.005, camera)
    assert (msg.width, msg.height, msg.distortion_model) == (640, 480, "plumb_bob")
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == \
        (2, 5_000_000, "camera")
    K, P = np.reshape(msg.k, (3, 3)), np.reshape(msg.p, (3, 4))
    np.testing.assert_array_equal(K, [[135.0, 0.0, 320.0], [0.0, 135.0, 240.0], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(P, np.hstack([K, np.zeros((3, 1))]))
    np.testing.assert_array_equal(np.reshape(msg.r, (3, 3)), np.eye(3))
    np.testing.assert_array_equal(msg.d, np.zeros(5))
    # oracle: K projects a point in the camera frame to the raw pixel the camera computes
    point = np.array([0.3, 0.7, 0.2])
    raw = camera.to_raw(camera.project(point[None, :])[0])[0]
    h = K @ (camera.rotation @ (point - camera.position))
    np.testing.assert_allclose(h[:2] / h[2], raw, atol=1e-9)


def test_effort_command_carries_the_answered_stamp_exactly(msgs):
    stamp = msgs.Time(sec=1_700_000_000, nanosec=123_456_789)
    msg = m.effort_command_to_msg(msgs, stamp, ["b", "a"], [2.0, 1.0])
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert len(msg.position) == len(msg.velocity) == 0
    stamp_ns, tau = m.effort_command_from_msg(msg, ["a", "b"])
    assert stamp_ns == 1_700_000_000_123_456_789
    np.testing.assert_array_equal(tau, [1.0, 2.0])
    with pytest.raises(ValueError, match=r"missing joint\(s\) \['c'\]"):
        m.effort_command_from_msg(msg, ["a", "c"])


@pytest.mark.parametrize("t", [0.015, 0.005 * 3, 0.005 * 601, 29.995, 1234.567891])
def test_received_time_is_what_a_stamp_of_t_reads(msgs, t):
    assert m.received_time(t) == m.stamp_to_time(m.time_to_stamp(msgs, t))


def test_received_pixels_are_what_a_subscriber_reads_after_serialisation(bags):
    pixels = np.array([65.123456789, -10.987654321])
    typename = m.MESSAGE_TYPES["PolygonStamped"]
    raw = bags.typestore.serialize_cdr(m.features_to_msg(bags, 0.0, pixels), typename)
    carried = m.features_from_msg(bags.typestore.deserialize_cdr(raw, typename))[1]
    np.testing.assert_array_equal(m.received_pixels(pixels), carried)
    assert np.all(carried != pixels)


def test_labelled_float_array_round_trip(msgs):
    model = make_model("paper_rrr")
    labels = m.parameter_labels(model)
    assert len(labels) == model.p_perp + model.p_z + model.p_d
    assert labels[0].startswith("a_z_perp.") and labels[-1].startswith("a_d.")
    values = np.linspace(-1.0, 1.0, len(labels))
    back, back_labels = m.float_array_from_msg(m.float_array_to_msg(msgs, values, labels))
    np.testing.assert_array_equal(back, values)
    assert back_labels == labels


def test_float_array_refuses_a_label_count_mismatch(msgs):
    with pytest.raises(ValueError, match="2 labels for 3 values"):
        m.float_array_to_msg(msgs, [1.0, 2.0, 3.0], ["a", "b"])


@pytest.mark.parametrize("t, sec, nanosec", [(0.0, 0, 0), (1.5, 1, 500_000_000),
                                             (0.005 * 601, 3, 5_000_000),
                                             (2.9999999999, 3, 0)])
def test_stamps_round_to_the_nanosecond(msgs, t, sec, nanosec):
    stamp = m.time_to_stamp(msgs, t)
    assert (stamp.sec, stamp.nanosec) == (sec, nanosec)


def test_negative_stamp_is_refused(msgs):
    with pytest.raises(ValueError, match="negative time"):
        m.time_to_stamp(msgs, -0.001)


def test_diagnostics_level_and_values(msgs):
    msg = m.diagnostics_to_msg(msgs, 1.0, "sim_node", "ERROR", "stale", {"steps": 3})
    status = msg.status[0]
    assert status.level in (2, b"\x02")
    assert (status.name, status.message, status.hardware_id) == ("sim_node", "stale", "sim")
    assert [(kv.key, kv.value) for kv in status.values] == [("steps", "3")]


def test_image_is_rgb8_row_major(msgs):
    rgb = np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3)
    msg = m.image_to_msg(msgs, 0.1, rgb)
    assert (msg.height, msg.width, msg.step, msg.encoding) == (2, 3, 9, "rgb8")
    assert bytes(msg.data) == rgb.tobytes()


def test_every_recorded_topic_has_a_known_type():
    assert set(TOPICS.values()) <= set(m.MESSAGE_TYPES)


def test_cdr_serialisation_round_trips_through_the_rosbags_typestore(bags):
    store = bags.typestore
    for short, msg in _examples(bags):
        typename = m.MESSAGE_TYPES[short]
        raw = store.serialize_cdr(msg, typename)
        back = store.deserialize_cdr(raw, typename)
        assert bytes(store.serialize_cdr(back, typename)) == bytes(raw), short
    back = store.deserialize_cdr(store.serialize_cdr(_examples(bags)[0][1], m.MESSAGE_TYPES[
        "JointState"]), m.MESSAGE_TYPES["JointState"])
    t, q, _ = m.joint_state_from_msg(back, NAMES)
    assert t == pytest.approx(1.25)
    np.testing.assert_array_equal(q, [1.0807, 0.5756, -0.5])


def test_rclpy_serialises_to_the_same_bytes_as_rosbags(bags):
    if not HAVE_RCLPY:
        pytest.skip("rclpy not importable: source a ROS 2 Jazzy setup.bash for this case")
    from rclpy.serialization import deserialize_message, serialize_message

    ros = m.rclpy_messages()
    for (short, ros_msg), (_, bag_msg) in zip(_examples(ros), _examples(bags)):
        typename = m.MESSAGE_TYPES[short]
        raw = serialize_message(ros_msg)
        assert raw == bytes(bags.typestore.serialize_cdr(bag_msg, typename)), short
        assert deserialize_message(raw, type(ros_msg)) == ros_msg, short


def _image_msg(msgs, pixels, encoding, step=None, padding=0, is_bigendian=0):
    """An Image of ``pixels`` (h, w, c) as stored, rows padded with ``padding`` bytes of 0xAB."""
    h, w, c = pixels.shape
    step = w * c + padding if step is None else step
    rows = np.full((h, step), 0xAB, dtype=np.uint8)
    rows[:, :w * c] = pixels.reshape(h, w * c)
    return msgs.Image(header=m.header(msgs, 2.5, "cam"), height=h, width=w, encoding=encoding,
                      is_bigendian=is_bigendian, step=step, data=msgs.uint8s(rows))


@pytest.fixture()
def picture(rng):
    return rng.integers(0, 256, (5, 7, 3), dtype=np.uint8)


def test_image_round_trips_through_image_to_msg(msgs, picture):
    t, rgb = m.image_from_msg(m.image_to_msg(msgs, 1.25, picture))
    assert t == pytest.approx(1.25)
    np.testing.assert_array_equal(rgb, picture)
    assert rgb.dtype == np.uint8 and rgb.flags.c_contiguous and rgb.flags.writeable


@pytest.mark.parametrize("encoding, stored", [
    ("rgb8", lambda p: p), ("bgr8", lambda p: p[..., ::-1]),
    ("rgba8", lambda p: np.dstack([p, np.full(p.shape[:2], 9, np.uint8)])),
    ("bgra8", lambda p: np.dstack([p[..., ::-1], np.full(p.shape[:2], 9, np.uint8)]))])
@pytest.mark.parametrize("padding", [0, 5])
def test_colour_encodings_and_padded_rows_give_rgb(msgs, picture, encoding, stored, padding):
    msg = _image_msg(msgs, stored(picture), encoding, padding=padding)
    t, rgb = m.image_from_msg(msg)
    assert t == pytest.approx(2.5)
    np.testing.assert_array_equal(rgb, picture)


def test_is_bigendian_does_not_matter_for_8_bit_channels(msgs, picture):
    little = m.image_from_msg(_image_msg(msgs, picture, "rgb8", is_bigendian=0))[1]
    big = m.image_from_msg(_image_msg(msgs, picture, "rgb8", is_bigendian=1))[1]
    np.testing.assert_array_equal(little, big)


def test_image_never_shares_memory_with_the_message(bags, picture):
    msg = m.image_to_msg(bags, 0.0, picture)
    rgb = m.image_from_msg(msg)[1]
    assert not np.shares_memory(rgb, msg.data)
    rgb[:] = 0
    np.testing.assert_array_equal(np.asarray(msg.data).reshape(picture.shape), picture)


@pytest.mark.parametrize("change, match", [
    ({"height": 6}, r"image: 105 bytes of data, but height 6 x step 21 = 126"),
    ({"width": 8}, r"image: step 21 is less than width 8 x 3 bytes \(rgb8\)"),
    ({"step": 20}, r"image: step 20 is less than width 7 x 3 bytes"),
    ({"step": 22}, r"image: 105 bytes of data, but height 5 x step 22 = 110"),
    ({"encoding": "mono8"}, r"image: encoding 'mono8' is not supported; use one of "
                            r"\['bgr8', 'bgra8', 'rgb8', 'rgba8'\]"),
    ({"encoding": "16UC1"}, r"encoding '16UC1' is not supported"),
    ({"encoding": "yuv422"}, r"encoding 'yuv422' is not supported"),
    ({"encoding": ""}, r"encoding '' is not supported"),
])
def test_inconsistent_or_unsupported_images_are_refused(msgs, picture, change, match):
    msg = m.image_to_msg(msgs, 0.0, picture)
    for name, value in change.items():
        setattr(msg, name, value)
    with pytest.raises(ValueError, match=match):
        m.image_from_msg(msg)


def test_empty_image_converts_to_an_empty_array(bags):
    msg = bags.Image(header=m.header(bags, 0.0), height=0, width=4, encoding="rgb8",
                     is_bigendian=0, step=12, data=bags.uint8s([]))
    assert m.image_from_msg(msg)[1].shape == (0, 4, 3)


def test_features_for_an_image_carry_its_stamp_and_frame_exactly(msgs):
    stamp = msgs.Time(sec=1_700_000_000, nanosec=123_456_789)
    image_header = msgs.Header(stamp=stamp, frame_id="camera_optical")
    msg = m.features_for_image(msgs, image_header, [1.5, -2.25, 3.0, 4.0])
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_700_000_000, 123_456_789)
    assert msg.header.frame_id == "camera_optical"
    np.testing.assert_array_equal(m.features_from_msg(msg)[1], [1.5, -2.25, 3.0, 4.0])
    # why not through seconds: the float64 of this stamp is 21 ns off
    via_float = m.time_to_stamp(msgs, m.stamp_to_time(stamp))
    assert via_float.nanosec != 123_456_789
    assert msg.header.stamp is not stamp
