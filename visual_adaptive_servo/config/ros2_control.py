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

"""The simulator behind a ros2_control stack: robot description and controller parameters.

``launch/ros2_control.launch.py`` runs the chain

    controller_node -> /effort_controller/commands -> JointGroupEffortController
    -> controller_manager -> JointStateTopicSystem -> sim_node (hardware.command_topic)
    sim_node (hardware.state_topic) -> JointStateTopicSystem -> joint_state_broadcaster
    -> /joint_states -> controller_node

with what this module builds from a scenario: the scenario's URDF with a
``<ros2_control>`` tag for its joints (:func:`robot_description`) and the
controller_manager's parameters (:func:`controller_manager_parameters`).
Plain strings and dicts: no ROS needed to build or to test them.
"""

from __future__ import annotations

import copy
import xml.etree.ElementTree as ET

TOPIC_SYSTEM_PLUGIN = "joint_state_topic_hardware_interface/JointStateTopicSystem"
MOVABLE_JOINT_TYPES = ("revolute", "continuous", "prismatic")
# JointStateTopicSystem skips a write when sum |effort state - effort command| is at most this
# threshold (default 1e-5).  The simulator reports the torque it applied as the effort state,
# so a command equal to the previous one would not be sent: every command must be.
SEND_EVERY_COMMAND = -1.0


def ros2_control_tag(joint_names, command_topic, state_topic, name="SimulatedArm"):
    """The ``<ros2_control>`` element (str) of a JointStateTopicSystem for ``joint_names``.

    Each joint: an ``effort`` command interface, ``position``, ``velocity`` and
    ``effort`` state interfaces.  The hardware sends the commands as
    sensor_msgs/JointState (``effort`` filled) on ``command_topic`` and reads the
    joint state from ``state_topic``; every command is sent
    (``trigger_joint_command_threshold`` = :data:`SEND_EVERY_COMMAND`).
    """
    if not joint_names:
        raise ValueError("ros2_control: no joints given")
    if command_topic == state_topic:
        raise ValueError(f"ros2_control: the command and state topics must differ, both are "
                         f"{command_topic!r}")
    root = ET.Element("ros2_control", name=name, type="system")
    hardware = ET.SubElement(root, "hardware")
    ET.SubElement(hardware, "plugin").text = TOPIC_SYSTEM_PLUGIN
    for key, value in (("joint_commands_topic", command_topic),
                       ("joint_states_topic", state_topic),
                       ("trigger_joint_command_threshold", repr(SEND_EVERY_COMMAND))):
        ET.SubElement(hardware, "param", name=key).text = value
    for joint in joint_names:
        element = ET.SubElement(root, "joint", name=joint)
        ET.SubElement(element, "command_interface", name="effort")
        for interface in ("position", "velocity", "effort"):
            ET.SubElement(element, "state_interface", name=interface)
    ET.indent(root, "  ")
    return ET.tostring(root, encoding="unicode")


def robot_description(urdf_text, joint_names, command_topic, state_topic, name="SimulatedArm"):
    """``urdf_text`` (str) with the :func:`ros2_control_tag` of ``joint_names`` added.

    Raises ValueError naming the joints that are not movable joints of the URDF
    (the controller_manager requires every joint of the tag in the URDF) or when
    the URDF has a ``<ros2_control>`` tag already.
    """
    robot = ET.fromstring(urdf_text)
    if robot.tag != "robot":
        raise ValueError(f"ros2_control: the URDF's root element is <{robot.tag}>, not <robot>")
    if robot.find("ros2_control") is not None:
        raise ValueError("ros2_control: the URDF has a <ros2_control> tag already")
    movable = [j.get("name") for j in robot.iter("joint") if j.get("type") in MOVABLE_JOINT_TYPES]
    missing = [joint for joint in joint_names if joint not in movable]
    if missing:
        raise ValueError(f"ros2_control: joint(s) {missing} are not movable joints of the URDF "
                         f"(movable: {movable})")
    robot.append(ET.fromstring(ros2_control_tag(joint_names, command_topic, state_topic, name)))
    return ET.tostring(robot, encoding="unicode")


def controller_manager_parameters(base, joint_names, control_period,
                                  manager="controller_manager", effort="effort_controller"):
    """The controller_manager's parameter file (dict) for a scenario.

    ``base`` is the file's content (``config/ros2_control.yaml``: the controller
    types and the manager's settings); the manager's ``update_rate`` becomes
    1 / ``control_period`` (a whole number of Hz) and the effort controller's
    ``joints`` the scenario's ``joint_names``, in that order (the order of
    ``controller_node``'s torques).  ``base`` itself is not changed.
    """
    rate = 1.0 / control_period
    if abs(rate - round(rate)) > 1e-6 * rate:
        raise ValueError(f"ros2_control: the controller_manager's update_rate is whole Hz; "
                         f"a control period of {control_period} s is {rate} Hz")
    params = copy.deepcopy(base)
    try:
        manager_params = params[manager]["ros__parameters"]
        manager_params[effort]["type"]
    except (KeyError, TypeError):
        raise ValueError(f"ros2_control: the parameter file has no {manager}.ros__parameters."
                         f"{effort}.type (the effort controller)") from None
    manager_params["update_rate"] = int(round(rate))
    params.setdefault(effort, {}).setdefault("ros__parameters", {})["joints"] = list(joint_names)
    return params
