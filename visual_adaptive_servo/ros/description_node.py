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

"""``robot_description``: the URDF latched on ``/robot_description``, for the controller_manager.

The controller_manager of ros2_control 4.x (Jazzy) reads the robot description
only from the ``robot_description`` topic (std_msgs/String, transient local),
usually published by robot_state_publisher.  The chain of
``launch/ros2_control.launch.py`` needs no TF, so this node does just the
latching part: it publishes its ``robot_description`` parameter once, reliable
and transient local (depth 1), and keeps it for late subscribers until stopped.
With robot_state_publisher installed, it can take this node's place
(``robot_state_publisher`` with the same ``robot_description`` parameter).
"""

from __future__ import annotations

import sys

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from .main import run_node

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class DescriptionNode(Node):
    """Publishes the ``robot_description`` parameter once, latched."""

    def __init__(self, **kwargs):
        super().__init__("robot_description", **kwargs)
        text = self.declare_parameter("robot_description", "").value
        if not text.strip():
            raise ValueError("robot_description: the parameter is empty (give the URDF text)")
        self.publisher = self.create_publisher(String, "/robot_description", LATCHED)
        self.publisher.publish(String(data=text))
        self.get_logger().info(f"robot_description latched ({len(text)} characters)")


def main(args=None):
    return run_node(DescriptionNode, "robot_description", args, (ValueError,))


if __name__ == "__main__":
    sys.exit(main())
