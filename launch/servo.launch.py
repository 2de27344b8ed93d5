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

"""Any scenario file under ROS 2: sim_node + controller_node (+ feature_detector), recorded.

    ros2 launch visual_adaptive_servo servo.launch.py params_file:=/path/to/scenario.yaml
    ros2 launch visual_adaptive_servo servo.launch.py timing_mode:=realtime render:=true
    ros2 launch visual_adaptive_servo servo.launch.py camera_mode:=rendered
    ros2 launch visual_adaptive_servo servo.launch.py record:=true bag_dir:=/tmp/vas_bag

One parameter file configures every node (default: the installed
config/paper_3dof.yaml); file names inside it (URDFs, trajectory tables) are
``package://`` or absolute.  sim_node publishes /clock and runs on wall time
itself (its timers must run while sim time stands still, so no use_sim_time);
controller_node uses sim time.  ``camera_mode:=rendered`` (default: the file's
``sim_node.camera_mode``) makes the simulator publish pictures and starts the
feature_detector, configured by the file's ``feature_detector`` section.
When any node exits (sim_node after ``duration`` of simulated time: the file's, or
the ``duration:=`` argument's) the launch shuts down; a node that exits with an error
makes it exit with status 1 (launch_args.unless_failed).  ``record:=true`` runs
``ros2 bag record -s mcap`` on the topics ``vas run`` records
(visual_adaptive_servo.recording.recorder.TOPICS) and sets
``sim_node.start.wait_for_recorder``: the simulation starts once the recorder
subscribes, and the shutdown waits ``RECORDER_GRACE`` for it to take the last
messages.  Not ``--use-sim-time``: with it the recorder subscribes nothing
before /clock has moved, i.e. after the start; the bag's receive times are
wall time, the messages' header stamps simulated time.  With the rendered
camera the pictures are recorded too (recording.CAMERA_TOPICS), zstd-compressed
by the MCAP storage (``--storage-preset-profile zstd_fast``), as ``vas run``
records them (LZ4 there), unless ``record_pictures:=false``.

controller_node publishes its commands at every sample and its other topics at
``publish_rate`` and /diagnostics at ``diagnostics_rate`` (empty: the node's
defaults, 100 Hz and 1 Hz); with ``record:=true`` in lockstep it publishes
everything at every sample (``publish_every_sample``), so the bag holds every
period, as ``vas run``'s recording does; when the simulator is done the
controller is stopped first and waits until the recorder has everything it
published, and its exit stops the rest.
"""

import os
import signal

import yaml
from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    ExecuteProcess,
    LogInfo,
    OpaqueFunction,
    RegisterEventHandler,
    TimerAction,
)
from launch.event_handlers import OnProcessExit
from launch.events import matches_action, Shutdown
from launch.events.process import SignalProcess
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from visual_adaptive_servo.recording.recorder import CAMERA_TOPICS, TOPICS
from visual_adaptive_servo.ros.launch_args import duration_argument, node_arguments, \
    node_parameters, parameter_file, rate_arguments, rates, recorder_qos_overrides, \
    recording_folder, removed_on_shutdown, sim_duration, unless_failed

PACKAGE = "visual_adaptive_servo"
# s of wall time between a node's exit (recording in lockstep: the controller's) and the shutdown
RECORDER_GRACE = 1.0


def _file_camera_mode(params_file):
    """``sim_node.camera_mode`` of a parameter file (``points`` when it has none)."""
    with open(params_file, encoding="utf-8") as handle:
        data = yaml.safe_load(handle) or {}
    section = data.get("sim_node") or data.get("/sim_node") or {}
    return (section.get("ros__parameters") or {}).get("camera_mode", "points")


def _nodes(context):
    params_file = LaunchConfiguration("params_file").perform(context)
    timing_mode = LaunchConfiguration("timing_mode").perform(context)
    render = LaunchConfiguration("render").perform(context) == "true"
    record = LaunchConfiguration("record").perform(context) == "true"
    record_pictures = LaunchConfiguration("record_pictures").perform(context) == "true"
    camera_mode = (LaunchConfiguration("camera_mode").perform(context)
                   or _file_camera_mode(params_file))
    controller = {"timing_mode": timing_mode, "use_sim_time": True,
                  "publish_every_sample": record and timing_mode == "lockstep"}
    controller.update(rates(context))
    controller.update(node_parameters(context))
    # the launch's own parameters of each node: in files removed at shutdown (registered
    # before the processes start, so also when one cannot), not dicts, whose files
    # launch_ros leaves in the temporary folder
    cleanup = []
    sim_params = {"timing_mode": timing_mode, "camera_mode": camera_mode,
                  "render.enabled": render,
                  "start.wait_for_recorder": record,
                  "start.recorder_takes_pictures": record_pictures,
                  **sim_duration(context), **node_parameters(context)}

    nodes = [
        Node(package=PACKAGE, executable="sim_node", name="sim_node", output="screen",
             parameters=[params_file, parameter_file(sim_params, cleanup)]),
        Node(package=PACKAGE, executable="controller_node", name="controller_node",
             output="screen",
             parameters=[params_file, parameter_file(controller, cleanup)]),
    ]
    if camera_mode == "rendered":
        detector = {"timing_mode": timing_mode, "recorded": record,
                    **node_parameters(context)}
        nodes.append(Node(package=PACKAGE, executable="feature_detector",
                          name="feature_detector", output="screen",
                          parameters=[params_file, parameter_file(detector, cleanup)]))
    actions = [LogInfo(msg=f"{os.path.basename(params_file)}: {timing_mode}, camera "
                           f"{camera_mode}")]
    sim, controller = nodes[0], nodes[1]
    for node in nodes:
        shutdown = EmitEvent(event=Shutdown(reason=f"{node.node_executable} exited"))
        on_exit = [TimerAction(period=RECORDER_GRACE, actions=[shutdown])] if record else \
            [shutdown]
        if node is sim and record and timing_mode == "lockstep":
            # every period in the bag: the controller stops first and waits until the
            # recorder has all it published (ControllerNode.flush_on_exit); its exit then
            # stops the rest
            on_exit = [EmitEvent(event=SignalProcess(signal_number=signal.SIGINT,
                                                     process_matcher=matches_action(controller)))]
        actions.append(RegisterEventHandler(OnProcessExit(target_action=node,
                                                          on_exit=unless_failed(on_exit))))
    if record:
        bag_dir = recording_folder(context)
        cmd = ["ros2", "bag", "record", "-s", "mcap"]
        if bag_dir:
            cmd += ["-o", bag_dir]
        topics = sorted(TOPICS)
        if timing_mode == "lockstep":
            # every period: keep all until written (the publishers keep 2000, ros/executor.py);
            # the file, written now, is removed when the launch shuts down
            overrides = recorder_qos_overrides(topics)
            cmd += ["--qos-profile-overrides-path", overrides]
            # (registered before the processes start: also when one cannot)
            cleanup.append(removed_on_shutdown(overrides))
        if camera_mode == "rendered" and record_pictures:
            topics += sorted(CAMERA_TOPICS)
            cmd += ["--storage-preset-profile", "zstd_fast"]
        cmd += ["--topics"] + topics
        actions += [LogInfo(msg="recording: " + " ".join(cmd)),
                    ExecuteProcess(cmd=cmd, output="screen", name="bag_record")]
    return cleanup + nodes + actions


def generate_launch_description():
    default_params = os.path.join(get_package_share_directory(PACKAGE), "config",
                                  "paper_3dof.yaml")
    return LaunchDescription([
        DeclareLaunchArgument("params_file", default_value=default_params,
                              description="Parameter YAML with sim_node and controller_node "
                                          "(and feature_detector) sections"),
        DeclareLaunchArgument("timing_mode", default_value="lockstep",
                              choices=["lockstep", "realtime"],
                              description="lockstep: sim waits for each command; realtime: "
                                          "wall-clock timer (also selects the QoS)"),
        DeclareLaunchArgument("camera_mode", default_value="",
                              choices=["", "points", "rendered"],
                              description="points: the sim publishes /camera/features; "
                                          "rendered: pictures and the feature_detector; "
                                          "empty: the params_file's sim_node.camera_mode"),
        DeclareLaunchArgument("render", default_value="false", choices=["true", "false"],
                              description="Publish the camera view on /sim_node/image"),
        DeclareLaunchArgument("record", default_value="false", choices=["true", "false"],
                              description="Record the package topics with ros2 bag (MCAP); "
                                          "the simulation starts once the recorder listens"),
        DeclareLaunchArgument("record_pictures", default_value="true",
                              choices=["true", "false"],
                              description="With record:=true and the rendered camera: record "
                                          "/camera/image_raw and /camera/camera_info too"),
        duration_argument(),
        *rate_arguments("; every sample with record:=true in lockstep"),
        *node_arguments(),
        DeclareLaunchArgument("bag_dir", default_value="",
                              description="Output folder of the recording (must not exist); "
                                          "empty: rosbag2_<date> in the current folder"),
        OpaqueFunction(function=_nodes),
    ])
