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

"""A scenario through a real ros2_control stack (needs ros2_control installed).

    ros2 launch visual_adaptive_servo ros2_control.launch.py params_file:=/path/scenario.yaml

The chain: controller_node -> /effort_controller/commands -> effort_controller
(effort_controllers/JointGroupEffortController) -> controller_manager ->
JointStateTopicSystem -> sim_node, and back: sim_node -> JointStateTopicSystem ->
joint_state_broadcaster -> /joint_states -> controller_node.  The camera
(/camera/features) goes from sim_node to controller_node directly.

From the scenario file: the URDF of ``sim_node.urdf`` gets a ``<ros2_control>``
tag for ``sim_node.joint_names`` (effort commands; position, velocity, effort
states) and is latched on /robot_description (``robot_description`` node: the
controller_manager of Jazzy reads it from that topic; no robot_state_publisher
needed); the controller_manager runs ``controllers_file`` (default
config/ros2_control.yaml) at 1 / ``sim_node.control_period`` Hz on /clock
(use_sim_time), with the effort controller's joints in the scenario's order;
the spawner loads effort_controller and joint_state_broadcaster and activates
them in one switch (controller_node starts tracking at its first /joint_states:
its commands must reach the arm from then on).
sim_node runs in realtime as the hardware (``hardware.command_topic``
HARDWARE_COMMANDS, ``hardware.state_topic`` HARDWARE_STATES): its arm stays on its
brakes until the first command and whenever the commands stop for the file's
``command_timeout`` (a few periods would be too few: on a busy machine the
controller_manager misses 50 ms now and then, and braking the arm mid-motion under a
running controller makes it diverge on release).  The launch shuts down when
sim_node exits (after ``duration`` of simulated time, or ``duration:=``); the other
processes may stop alone and the rest says what it then does.  controller_node tracks while
effort_controller is active (``ros2_control.effort_controller``) and sim_node holds
the arm on its brakes while it is not (``hardware.effort_controller``); when
controller_node exits the effort controller is unspawned (deactivated and unloaded):
it would otherwise go on sending the stopped node's last command.  ``record:=true``
records the package's topics and the two hardware topics with ``ros2 bag record -s
mcap``, as servo.launch.py does.  ``publish_rate`` and ``diagnostics_rate`` set
controller_node's rates of its state topics and /diagnostics (empty: 100 Hz and
1 Hz; the commands go out at every sample).
"""

import os

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
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from visual_adaptive_servo.config.ros2_control import (
    controller_manager_parameters,
    robot_description,
)
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.recording.recorder import TOPICS
from visual_adaptive_servo.ros.launch_args import duration_argument, node_arguments, \
    node_parameters, rate_arguments, rates, recording_folder, removed_on_shutdown, \
    sim_duration, temporary_yaml, unless_failed

PACKAGE = "visual_adaptive_servo"
HARDWARE_COMMANDS = "/sim_node/joint_commands"
HARDWARE_STATES = "/sim_node/joint_states"
EFFORT_CONTROLLER = "effort_controller"
RECORDER_GRACE = 1.0     # s of wall time between the simulator's exit and the shutdown
UNSPAWN_DELAY = 0.2      # s of wall time between controller_node's exit and the unspawner


def _unspawn(event, context):
    """controller_node exited: deactivate and unload the effort controller, unless shutting down.

    After ``UNSPAWN_DELAY``: a Ctrl-C reaches every process of the group at once, and
    controller_node may exit before the launch has seen its own SIGINT (the timer is
    cancelled by the shutdown).
    """
    def unspawn(context):
        if context.is_shutdown:
            return None
        return [LogInfo(msg=f"controller_node exited ({event.returncode}): unspawning "
                            f"{EFFORT_CONTROLLER}"),
                Node(package="controller_manager", executable="unspawner", output="screen",
                     arguments=[EFFORT_CONTROLLER, "--controller-manager",
                                "/controller_manager"])]

    return [TimerAction(period=UNSPAWN_DELAY, actions=[OpaqueFunction(function=unspawn)])]


def _nodes(context):
    params_file = LaunchConfiguration("params_file").perform(context)
    controllers_file = LaunchConfiguration("controllers_file").perform(context)
    record = LaunchConfiguration("record").perform(context) == "true"
    hardware = {"timing_mode": "realtime", "hardware.command_topic": HARDWARE_COMMANDS,
                "hardware.state_topic": HARDWARE_STATES,
                "hardware.effort_controller": EFFORT_CONTROLLER}
    sim = load_scenario(params_file, [f"sim_node.{k}={v}" for k, v in hardware.items()]).sim
    with open(sim.arm.chain.urdf, encoding="utf-8") as handle:
        description = robot_description(handle.read(), sim.joint_names, HARDWARE_COMMANDS,
                                        HARDWARE_STATES)
    with open(controllers_file, encoding="utf-8") as handle:
        manager = controller_manager_parameters(yaml.safe_load(handle), sim.joint_names,
                                                sim.control_period)
    manager_file = temporary_yaml("vas_ros2_control_", manager)
    rate = manager["controller_manager"]["ros__parameters"]["update_rate"]

    controller_node = Node(package=PACKAGE, executable="controller_node", name="controller_node",
                           output="screen", parameters=[params_file, {
                               "timing_mode": "realtime", "use_sim_time": True,
                               "ros2_control.effort_controller": EFFORT_CONTROLLER,
                               **rates(context), **node_parameters(context)}])
    sim_node = Node(package=PACKAGE, executable="sim_node", name="sim_node", output="screen",
                    parameters=[params_file, dict(hardware, **{
                        "start.wait_for_recorder": record}, **sim_duration(context),
                        **node_parameters(context))])
    nodes = [
        Node(package=PACKAGE, executable="robot_description", name="robot_description",
             output="screen", parameters=[{"robot_description": description,
                                           **node_parameters(context)}]),
        Node(package="controller_manager", executable="ros2_control_node",
             name="controller_manager", output="screen",
             parameters=[manager_file, {"use_sim_time": True}]),
        # both in one switch: controller_node starts tracking at its first /joint_states, so
        # the broadcaster must not run before the effort controller passes its commands on
        Node(package="controller_manager", executable="spawner", output="screen",
             arguments=[EFFORT_CONTROLLER, "joint_state_broadcaster", "--activate-as-group",
                        "--controller-manager", "/controller_manager"]),
        sim_node,
        controller_node,
    ]
    shutdown = EmitEvent(event=Shutdown(reason="sim_node exited"))
    actions = [
        # the effort controller would go on sending the last command of a stopped controller
        RegisterEventHandler(OnProcessExit(target_action=controller_node, on_exit=_unspawn)),
        LogInfo(msg=f"{os.path.basename(params_file)} through ros2_control: controller_manager "
                    f"at {rate} Hz, joints {list(sim.joint_names)}"),
        RegisterEventHandler(OnProcessExit(target_action=sim_node, on_exit=unless_failed([
            TimerAction(period=RECORDER_GRACE, actions=[shutdown]) if record else shutdown]))),
    ]
    if record:
        bag_dir = recording_folder(context)
        cmd = ["ros2", "bag", "record", "-s", "mcap"] + (["-o", bag_dir] if bag_dir else [])
        cmd += ["--topics"] + sorted(TOPICS) + [HARDWARE_COMMANDS, HARDWARE_STATES]
        actions += [LogInfo(msg="recording: " + " ".join(cmd)),
                    ExecuteProcess(cmd=cmd, output="screen", name="bag_record")]
    # the controller_manager's parameter file, written above, goes when the launch ends,
    # also when a node cannot start (registered before the nodes are executed)
    return [removed_on_shutdown(manager_file)] + nodes + actions


def generate_launch_description():
    share = get_package_share_directory(PACKAGE)
    return LaunchDescription([
        DeclareLaunchArgument("params_file",
                              default_value=os.path.join(share, "config", "paper_3dof.yaml"),
                              description="Scenario YAML (sim_node and controller_node sections)"),
        DeclareLaunchArgument("controllers_file",
                              default_value=os.path.join(share, "config", "ros2_control.yaml"),
                              description="controller_manager parameters (controller types); "
                                          "update_rate and the effort controller's joints "
                                          "come from the scenario"),
        DeclareLaunchArgument("record", default_value="false", choices=["true", "false"],
                              description="Record the package and hardware topics (MCAP)"),
        DeclareLaunchArgument("bag_dir", default_value="",
                              description="Output folder of the recording (must not exist)"),
        duration_argument(),
        *rate_arguments(),
        *node_arguments(),
        OpaqueFunction(function=_nodes),
    ])
