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

"""Behind ros2_control, without ROS: the messages, the robot description, the parameters.

The joint states and commands are built as joint_state_broadcaster and
JointStateTopicSystem build them (rosbags' Jazzy message types): any joint
order, extra joints, only efforts in a command.  The robot description keeps
the URDF's chain (read back by the package's own URDF reader) and adds the
ros2_control tag the controller_manager parses.  The simulator's brakes hold
the arm against gravity where zero torque lets it fall (PyBullet's dynamics).
"""

import os
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from sim_bridge.simulator import Simulator
from visual_adaptive_servo.config.files import apply_overrides, read_param_file
from visual_adaptive_servo.config.ros2_control import (
    controller_manager_parameters,
    robot_description,
    ros2_control_tag,
    SEND_EVERY_COMMAND,
)
from visual_adaptive_servo.config.sim import SimConfig
from visual_adaptive_servo.models.resources import resolve_path
from visual_adaptive_servo.models.urdf_chain import load_chain
from visual_adaptive_servo.recording import messages as m
from visual_adaptive_servo.schema import ConfigError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAPER = os.path.join(ROOT, "config", "paper_3dof.yaml")
PAPER_URDF = os.path.join(ROOT, "sim_bridge", "urdf", "paper_rrr.urdf")
NAMES = ["joint1", "joint2", "joint3"]


@pytest.fixture(scope="module")
def bags():
    return m.rosbags_messages()


def _broadcaster_state(bags, names, position, velocity, effort, stamp=(12, 345)):
    return bags.JointState(header=bags.Header(stamp=bags.Time(sec=stamp[0], nanosec=stamp[1]),
                                              frame_id="base_link"),
                           name=list(names), position=bags.floats(position),
                           velocity=bags.floats(velocity), effort=bags.floats(effort))


def test_joint_state_from_the_broadcaster_is_taken_by_name_whatever_its_order(bags):
    # joint_state_broadcaster's order is its own, here with two finger joints among them
    names = ["finger_left", "joint3", "joint1", "finger_right", "joint2"]
    value = {"finger_left": 0.04, "joint3": -0.5, "joint1": 1.0807, "finger_right": 0.03,
             "joint2": 0.5756}
    position = [value[n] for n in names]
    velocity = [10 * value[n] for n in names]
    msg = _broadcaster_state(bags, names, position, velocity, [0.0] * len(names))
    t, q, qd = m.joint_state_from_msg(msg, NAMES)
    np.testing.assert_array_equal(q, [value[n] for n in NAMES])
    np.testing.assert_array_equal(qd, [10 * value[n] for n in NAMES])
    assert t == pytest.approx(12.000000345, abs=1e-12)


def test_joint_state_without_a_controlled_joint_names_it(bags):
    msg = _broadcaster_state(bags, ["joint1", "joint3"], [0.1, 0.2], [0.0, 0.0], [0.0, 0.0])
    with pytest.raises(ValueError, match=r"missing joint\(s\) \['joint2'\]; got \['joint1', "
                                         r"'joint3'\]"):
        m.joint_state_from_msg(msg, NAMES)


def test_effort_command_as_the_topic_hardware_sends_it_is_taken_by_name(bags):
    # JointStateTopicSystem: the joints of its <ros2_control> tag, efforts only
    msg = bags.JointState(header=bags.Header(stamp=bags.Time(sec=3, nanosec=0), frame_id=""),
                          name=["joint2", "joint3", "joint1"], position=bags.floats([]),
                          velocity=bags.floats([]), effort=bags.floats([20.0, -3.5, 1.25]))
    raw = bags.typestore.serialize_cdr(msg, "sensor_msgs/msg/JointState")
    back = bags.typestore.deserialize_cdr(raw, "sensor_msgs/msg/JointState")
    _, tau = m.effort_command_from_msg(back, NAMES)
    np.testing.assert_array_equal(tau, [1.25, 20.0, -3.5])


def test_ros2_control_tag_has_an_effort_command_and_three_states_per_joint():
    tag = ET.fromstring(ros2_control_tag(NAMES, "/sim_node/joint_commands",
                                         "/sim_node/joint_states"))
    assert (tag.tag, tag.get("type")) == ("ros2_control", "system")
    hardware = tag.find("hardware")
    assert hardware.findtext("plugin") == \
        "joint_state_topic_hardware_interface/JointStateTopicSystem"
    params = {p.get("name"): p.text for p in hardware.findall("param")}
    assert params["joint_commands_topic"] == "/sim_node/joint_commands"
    assert params["joint_states_topic"] == "/sim_node/joint_states"
    # the hardware skips a write when sum |effort state - command| <= threshold; the
    # difference is never negative, so every command is written
    assert float(params["trigger_joint_command_threshold"]) == SEND_EVERY_COMMAND < 0.0
    joints = tag.findall("joint")
    assert [j.get("name") for j in joints] == NAMES
    for joint in joints:
        assert [c.get("name") for c in joint.findall("command_interface")] == ["effort"]
        assert [s.get("name") for s in joint.findall("state_interface")] == \
            ["position", "velocity", "effort"]


def test_ros2_control_tag_refuses_one_topic_for_both_directions():
    with pytest.raises(ValueError, match="command and state topics must differ"):
        ros2_control_tag(NAMES, "/arm", "/arm")


def test_robot_description_keeps_the_urdf_chain_and_adds_one_tag(tmp_path):
    with open(PAPER_URDF, encoding="utf-8") as handle:
        original = handle.read()
    text = robot_description(original, NAMES, "/c", "/s")
    path = tmp_path / "described.urdf"
    path.write_text(text, encoding="utf-8")
    before = load_chain(PAPER_URDF, "base_link", "tip")
    after = load_chain(str(path), "base_link", "tip")
    assert after.joint_names == before.joint_names
    q = np.array([0.3, -0.7, 1.1])
    for a, b in zip(after.frames(q), before.frames(q)):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-15)
    assert len(ET.fromstring(text).findall("ros2_control")) == 1


def test_robot_description_refuses_joints_the_urdf_does_not_move():
    with open(PAPER_URDF, encoding="utf-8") as handle:
        original = handle.read()
    with pytest.raises(ValueError, match=r"joint\(s\) \['elbow'\] are not movable joints"):
        robot_description(original, ["joint1", "elbow"], "/c", "/s")
    with pytest.raises(ValueError, match="has a <ros2_control> tag already"):
        robot_description(robot_description(original, NAMES, "/c", "/s"), NAMES, "/c", "/s")


def test_robot_description_of_the_panda_takes_the_arm_and_leaves_the_fingers():
    path = resolve_path("pybullet_data://franka_panda/panda.urdf")
    arm = [f"panda_joint{i}" for i in range(1, 8)]
    with open(path, encoding="utf-8") as handle:
        tag = ET.fromstring(robot_description(handle.read(), arm, "/c", "/s")).find(
            "ros2_control")
    assert [j.get("name") for j in tag.findall("joint")] == arm


def test_controller_manager_parameters_take_the_scenarios_rate_and_joint_order():
    with open(os.path.join(ROOT, "config", "ros2_control.yaml"), encoding="utf-8") as handle:
        base = yaml.safe_load(handle)
    kept = yaml.safe_dump(base)
    params = controller_manager_parameters(base, ["joint3", "joint1", "joint2"], 0.001)
    assert params["controller_manager"]["ros__parameters"]["update_rate"] == 1000
    assert params["effort_controller"]["ros__parameters"]["joints"] == \
        ["joint3", "joint1", "joint2"]
    manager = params["controller_manager"]["ros__parameters"]
    assert manager["effort_controller"]["type"] == \
        "effort_controllers/JointGroupEffortController"
    assert manager["joint_state_broadcaster"]["type"] == \
        "joint_state_broadcaster/JointStateBroadcaster"
    assert yaml.safe_dump(base) == kept     # the caller's dict is not changed


def test_controller_manager_parameters_refuse_a_rate_that_is_not_whole_hz():
    base = {"controller_manager": {"ros__parameters": {
        "effort_controller": {"type": "effort_controllers/JointGroupEffortController"}}}}
    with pytest.raises(ValueError, match=r"whole Hz; a control period of 0.003 s"):
        controller_manager_parameters(base, NAMES, 0.003)
    with pytest.raises(ValueError, match=r"no controller_manager.ros__parameters."
                                         r"effort_controller.type"):
        controller_manager_parameters({"controller_manager": {}}, NAMES, 0.005)


def _sim_config(*overrides):
    sections = apply_overrides(read_param_file(PAPER), overrides)
    return SimConfig.from_params(sections["sim_node"], search_dirs=(os.path.dirname(PAPER),))


@pytest.mark.parametrize("overrides, match", [
    (["sim_node.hardware.command_topic=/c", "sim_node.hardware.state_topic=/s"],
     r"sim_node\.hardware\.command_topic: .* timing_mode must be 'realtime', got 'lockstep'"),
    (["sim_node.hardware.command_topic=/c", "sim_node.timing_mode=realtime"],
     r"sim_node\.hardware\.state_topic: .* neither /joint_states .* got '/joint_states'"),
    (["sim_node.hardware.command_topic=/c", "sim_node.hardware.state_topic=/c",
      "sim_node.timing_mode=realtime"],
     r"sim_node\.hardware\.state_topic: .* nor the command topic, got '/c'"),
])
def test_the_hardware_mode_refuses_lockstep_and_the_broadcasters_topic(overrides, match):
    with pytest.raises(ConfigError, match=match):
        _sim_config(*overrides)


def test_brakes_hold_the_arm_still_where_zero_torque_lets_it_fall():
    config = _sim_config()
    held, falling = Simulator(config), Simulator(config)
    try:
        q0 = held.measure().q
        for _ in range(100):                    # 0.5 s
            held.hold()
            falling.apply(np.zeros(3))
        still, fallen = held.measure(), falling.measure()
    finally:
        held.close()
        falling.close()
    assert still.t == pytest.approx(0.5) and fallen.t == pytest.approx(0.5)
    np.testing.assert_array_equal(still.q, q0)
    np.testing.assert_array_equal(still.qd, 0.0)
    np.testing.assert_array_equal(still.tau_applied, 0.0)
    # the oracle that gravity acts: the same arm without brakes has moved a lot
    assert np.max(np.abs(fallen.q - q0)) > 0.2
