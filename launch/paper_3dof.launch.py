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

"""The paper's scenario under ROS 2: sim_node + controller_node, optionally recorded.

    ros2 launch visual_adaptive_servo paper_3dof.launch.py
    ros2 launch visual_adaptive_servo paper_3dof.launch.py timing_mode:=realtime render:=true
    ros2 launch visual_adaptive_servo paper_3dof.launch.py record:=true bag_dir:=/tmp/vas_bag

One parameter file configures both nodes (default: the installed
config/paper_3dof.yaml).  sim_node publishes /clock and runs on wall time
itself (its timers must run while sim time stands still, so no
use_sim_time); controller_node uses sim time.  When sim_node stops (after
``duration`` of simulated time) or either node exits, the launch shuts down.
``record:=true`` runs ``ros2 bag record -s mcap --use-sim-time`` on the
topics ``vas run`` records (visual_adaptive_servo.recording.TOPICS).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    ExecuteProcess,
    LogInfo,
    OpaqueFunction,
    RegisterEventHandler,
)
from launch.conditions import IfCondition
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from visual_adaptive_servo.recording import TOPICS

PACKAGE = "visual_adaptive_servo"


def _recorder(context):
    bag_dir = LaunchConfiguration("bag_dir").perform(context)
    cmd = ["ros2", "bag", "record", "-s", "mcap", "--use-sim-time"]
    if bag_dir:
        cmd += ["-o", bag_dir]
    cmd += ["--topics"] + sorted(TOPICS)
    return [LogInfo(msg="recording: " + " ".join(cmd)),
            ExecuteProcess(cmd=cmd, output="screen", name="bag_record")]


def generate_launch_description():
    default_params = os.path.join(get_package_share_directory(PACKAGE), "config",
                                  "paper_3dof.yaml")
    params_file = LaunchConfiguration("params_file")
    timing_mode = LaunchConfiguration("timing_mode")
    render = LaunchConfiguration("render")
    record = LaunchConfiguration("record")

    sim = Node(
        package=PACKAGE, executable="sim_node", name="sim_node", output="screen",
        parameters=[params_file, {"timing_mode": timing_mode, "render.enabled": render}])
    controller = Node(
        package=PACKAGE, executable="controller_node", name="controller_node", output="screen",
        parameters=[params_file, {"timing_mode": timing_mode, "use_sim_time": True}])
    shutdown_when_done = [
        RegisterEventHandler(OnProcessExit(
            target_action=node,
            on_exit=[EmitEvent(event=Shutdown(reason=f"{name} exited"))]))
        for node, name in ((sim, "sim_node"), (controller, "controller_node"))]

    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=default_params,
                              description="Parameter YAML with sim_node and controller_node"),
        DeclareLaunchArgument("timing_mode", default_value="lockstep",
                              choices=["lockstep", "realtime"],
                              description="lockstep: sim waits for each command; realtime: "
                                          "wall-clock timer (also selects the QoS)"),
        DeclareLaunchArgument("render", default_value="false", choices=["true", "false"],
                              description="Publish the camera view on /sim_node/image"),
        DeclareLaunchArgument("record", default_value="false", choices=["true", "false"],
                              description="Record the package topics with ros2 bag (MCAP)"),
        DeclareLaunchArgument("bag_dir", default_value="",
                              description="Output folder of the recording (must not exist); "
                                          "empty: rosbag2_<date> in the current folder"),
        sim,
        controller,
        *shutdown_when_done,
        OpaqueFunction(function=_recorder, condition=IfCondition(record)),
    ])
