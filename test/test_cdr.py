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

"""The 1 kHz messages serialized by hand (recording.cdr) against the Jazzy definitions.

Oracle: the ``rosbags`` type store's CDR serializer and deserializer (the Jazzy
message definitions) applied to the messages :mod:`recording.messages` builds,
and, where a sourced ROS 2 makes rclpy importable, rclpy's ``serialize_message``.
Names of every length (the alignment of what follows them), 0 to 9 joints and 0 to
4 points, stamps up to 2^31 s.
"""

import importlib.util

import numpy as np
import pytest

from conftest import PAPER_CONFIG
from sim_bridge.simulator import Simulator
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.recording import cdr, messages as m

HAVE_RCLPY = importlib.util.find_spec("rclpy") is not None


@pytest.fixture(scope="module")
def bags():
    return m.rosbags_messages()


def serialized(bags, short, msg):
    return bytes(bags.typestore.serialize_cdr(msg, m.MESSAGE_TYPES[short]))


def random_names(rng, n):
    return ["j" * int(rng.integers(0, 3)) + f"{k}_" + "x" * int(rng.integers(0, 7))
            for k in range(n)]


def random_time(rng):
    return float(rng.choice([0.0, rng.uniform(0, 100), rng.uniform(1e9, 2.1e9)]))


def test_joint_states_and_stamped_commands_are_the_bytes_rosbags_makes(bags, rng):
    for _ in range(200):
        n = int(rng.integers(0, 10))
        names = random_names(rng, n)
        q, qd, effort = rng.normal(size=(3, n))
        t = random_time(rng)
        encoder = cdr.JointStateEncoder(names)
        assert encoder.encode(m.time_to_ns(t), q, qd, effort) == serialized(
            bags, "JointState", m.joint_state_to_msg(bags, t, names, q, qd, effort))
        stamp = m.time_to_stamp(bags, t)
        assert encoder.encode(m.stamp_to_ns(stamp), [], [], effort) == serialized(
            bags, "JointState", m.effort_command_to_msg(bags, stamp, names, effort))


def test_features_floats_and_the_clock_are_the_bytes_rosbags_makes(bags, rng):
    for _ in range(200):
        pixels = rng.uniform(-1e3, 1e3, 2 * int(rng.integers(0, 5)))
        values = rng.normal(size=int(rng.integers(0, 9)))
        t = random_time(rng)
        assert cdr.polygon_stamped(m.time_to_ns(t), pixels) == serialized(
            bags, "PolygonStamped", m.features_to_msg(bags, t, pixels))
        assert cdr.float64_array(values) == serialized(
            bags, "Float64MultiArray", m.float_array_to_msg(bags, values))
        assert cdr.clock(t) == serialized(bags, "Clock", m.clock_to_msg(bags, t))


def test_reading_gives_what_the_message_functions_give(bags, rng):
    for _ in range(200):
        n = int(rng.integers(1, 10))
        names = random_names(rng, n)
        wanted = list(rng.permutation(names))
        q, qd, effort = rng.normal(size=(3, n))
        t = random_time(rng)
        raw = serialized(bags, "JointState", m.joint_state_to_msg(bags, t, names, q, qd, effort))
        msg = bags.typestore.deserialize_cdr(raw, m.MESSAGE_TYPES["JointState"])
        t_ref, q_ref, qd_ref = m.joint_state_from_msg(msg, wanted)
        stamp_ns, q_cdr, qd_cdr = cdr.JointStateDecoder(wanted).decode(raw)
        assert stamp_ns == m.stamp_to_ns(msg.header.stamp) == cdr.header_stamp_ns(raw)
        assert cdr.stamp_time(stamp_ns) == t_ref
        np.testing.assert_array_equal(q_cdr, q_ref)
        np.testing.assert_array_equal(qd_cdr, qd_ref)
        assert q_cdr.dtype == np.float64 and q_cdr.flags.c_contiguous and q_cdr.flags.writeable

        pixels = rng.uniform(-1e3, 1e3, 2 * int(rng.integers(0, 5)))
        raw = serialized(bags, "PolygonStamped", m.features_to_msg(bags, t, pixels))
        t_ref, pixels_ref = m.features_from_msg(
            bags.typestore.deserialize_cdr(raw, m.MESSAGE_TYPES["PolygonStamped"]))
        stamp_ns, pixels_cdr = cdr.polygon_stamped_pixels(raw)
        assert cdr.stamp_time(stamp_ns) == t_ref
        np.testing.assert_array_equal(pixels_cdr, pixels_ref)
        np.testing.assert_array_equal(pixels_cdr, m.received_pixels(pixels))

        values = rng.normal(size=int(rng.integers(0, 9)))
        labels = [f"v{k}" for k in range(len(values))] if rng.random() < 0.5 else None
        raw = serialized(bags, "Float64MultiArray", m.float_array_to_msg(bags, values, labels))
        np.testing.assert_array_equal(cdr.float64_array_values(raw), values)


def test_a_joint_state_decoder_follows_a_change_of_names(bags):
    decoder = cdr.JointStateDecoder(["b", "a"])
    first = serialized(bags, "JointState",
                       m.joint_state_to_msg(bags, 1.0, ["a", "b"], [1.0, 2.0], [3.0, 4.0], []))
    second = serialized(bags, "JointState",
                        m.joint_state_to_msg(bags, 2.0, ["b", "c", "a"], [5.0, 6.0, 7.0],
                                             [8.0, 9.0, 10.0], []))
    np.testing.assert_array_equal(decoder.decode(first)[1], [2.0, 1.0])
    np.testing.assert_array_equal(decoder.decode(second)[1], [5.0, 7.0])
    np.testing.assert_array_equal(decoder.decode(first)[2], [4.0, 3.0])


@pytest.mark.parametrize("names, position, velocity", [
    (["a", "c"], [1.0, 2.0], [3.0, 4.0]),
    (["a", "b"], [1.0, 2.0], [3.0]),
])
def test_a_bad_joint_state_is_refused_as_the_message_functions_refuse_it(
        bags, names, position, velocity):
    msg = bags.JointState(header=m.header(bags, 1.0), name=names,
                          position=bags.floats(position), velocity=bags.floats(velocity),
                          effort=bags.floats([]))
    with pytest.raises(ValueError) as reference:
        m.joint_state_from_msg(msg, ["a", "b"])
    with pytest.raises(ValueError) as refused:
        cdr.JointStateDecoder(["a", "b"]).decode(serialized(bags, "JointState", msg))
    assert str(refused.value) == str(reference.value)


def test_truncated_or_foreign_bytes_are_refused_naming_what_they_were_read_as(bags):
    raw = serialized(bags, "JointState",
                     m.joint_state_to_msg(bags, 1.0, ["a"], [1.0], [2.0], [3.0]))
    with pytest.raises(cdr.CdrError, match="joint state: .* bytes end inside a field"):
        cdr.JointStateDecoder(["a"]).decode(raw[:-30])
    with pytest.raises(cdr.CdrError, match="features: not little-endian CDR"):
        cdr.polygon_stamped_pixels(b"\x00\x00\x00\x00" + raw[4:])
    with pytest.raises(cdr.CdrError, match="float array: .* bytes end inside a field"):
        cdr.float64_array_values(raw[:6])


def test_the_simulators_outputs_are_the_serialized_messages_of_vas_run(bags):
    scenario = load_scenario(PAPER_CONFIG, ["sim_node.pixel_noise_std=0.5"])
    sim = Simulator(scenario.sim)
    names = scenario.sim.joint_names
    encoder = cdr.JointStateEncoder(names)
    try:
        for k in range(20):
            meas = sim.measure()
            reference = [(topic, serialized(bags, type(msg).__name__.split("__")[-1], msg))
                         for topic, msg in m.sim_outputs(bags, meas, names)]
            assert cdr.sim_outputs(encoder, meas) == reference
            sim.apply(np.full(sim.n, 0.1 * k))
    finally:
        sim.close()


def test_rclpy_serialises_the_same_bytes(rng):
    if not HAVE_RCLPY:
        pytest.skip("rclpy not importable: source a ROS 2 Jazzy setup.bash for this case")
    from rclpy.serialization import serialize_message

    ros = m.rclpy_messages()
    names = random_names(rng, 7)
    q, qd, effort = rng.normal(size=(3, 7))
    pixels = rng.uniform(0, 640, 6)
    assert cdr.JointStateEncoder(names).encode(m.time_to_ns(12.5), q, qd, effort) == \
        serialize_message(m.joint_state_to_msg(ros, 12.5, names, q, qd, effort))
    assert cdr.polygon_stamped(m.time_to_ns(12.5), pixels) == \
        serialize_message(m.features_to_msg(ros, 12.5, pixels))
    assert cdr.float64_array(effort) == serialize_message(m.float_array_to_msg(ros, effort))
    assert cdr.clock(12.5) == serialize_message(m.clock_to_msg(ros, 12.5))
