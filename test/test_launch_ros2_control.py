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

"""launch_testing: the paper's arm through a real ros2_control stack.

``launch/ros2_control.launch.py`` with a 3 s scenario on a private ROS domain:
the controller_manager gets the generated robot description, the spawner
activates effort_controller and joint_state_broadcaster, the simulator releases
its brakes at the first command and reaches its duration with no command
timeout; every process exits with status 0.  Skipped without launch_testing,
without the package installed (colcon build), or without ros2_control
(controller_manager, joint_state_broadcaster, effort_controllers and
joint_state_topic_hardware_interface in the ament index; that skip is in the
test, so that the other test files of the session still run).
"""

import os
import tempfile
import unittest

import pytest

pytest.importorskip("launch_testing", reason="needs ROS 2 launch_testing")

import launch_testing.actions
import launch_testing.asserts
from ament_index_python.packages import (
    PackageNotFoundError,
    get_package_share_directory,
)
from launch.actions import ExecuteProcess, IncludeLaunchDescription, SetEnvironmentVariable
from launch.launch_description_sources import PythonLaunchDescriptionSource

from launch import LaunchDescription

from conftest import installed_share, short_params_file

ROS2_CONTROL = ("controller_manager", "joint_state_broadcaster", "effort_controllers",
                "joint_state_topic_hardware_interface")
SHARE = installed_share()


def _missing(names):
    missing = []
    for name in names:
        try:
            get_package_share_directory(name)
        except PackageNotFoundError:
            missing.append(name)
    return missing


# skipped in the tests, not here: a module-level skip in a launch_test module ends the
# whole pytest session (the launch_testing plugin), the other test files with it
MISSING = _missing(ROS2_CONTROL)
SKIP_REASON = f"ros2_control is not installed (no {', '.join(MISSING)} in the ament index)"


@pytest.mark.launch_test
def generate_test_description():
    if MISSING:
        # a process for the launch to wait on: a description without one ends before the
        # (skipped) tests run, and launch_testing fails them ("Launch stopped before the
        # active tests finished")
        return LaunchDescription([ExecuteProcess(cmd=["sleep", "60"]),
                                  launch_testing.actions.ReadyToTest()]), {"before": set()}
    before = _manager_files()
    return LaunchDescription([
        SetEnvironmentVariable("ROS_DOMAIN_ID", str(200 + os.getpid() % 30)),
        IncludeLaunchDescription(
            PythonLaunchDescriptionSource(os.path.join(SHARE, "launch",
                                                       "ros2_control.launch.py")),
            launch_arguments={"params_file": short_params_file(SHARE, 3.0)}.items()),
        launch_testing.actions.ReadyToTest(),
    ]), {"before": before}


def _manager_files():
    """The controller_manager parameter files ros2_control.launch.py wrote, now there."""
    return {name for name in os.listdir(tempfile.gettempdir())
            if name.startswith("vas_ros2_control_") and name.endswith(".yaml")}


class TestChain(unittest.TestCase):

    def test_the_arm_is_driven_through_the_controller_manager(self, proc_output, proc_info):
        if MISSING:
            self.skipTest(SKIP_REASON)
        proc_output.assertWaitFor("Received robot description from topic", timeout=60)
        proc_output.assertWaitFor("Loaded hardware 'SimulatedArm' from plugin "
                                  "'joint_state_topic_hardware_interface/JointStateTopicSystem'",
                                  timeout=30)
        proc_output.assertWaitFor("Configured and activated all the parsed controllers list : "
                                  "['effort_controller', 'joint_state_broadcaster']", timeout=60)
        proc_output.assertWaitFor("effort_controller is active: tracking starts", timeout=30)
        proc_output.assertWaitFor("brakes released", timeout=30)
        proc_output.assertWaitFor("duration 3.0 s reached after", timeout=120)
        proc_output.assertWaitFor("0 command timeouts, 0 refused commands", timeout=10)
        proc_info.assertWaitForShutdown(process="sim_node", timeout=30)


@launch_testing.post_shutdown_test()
class TestShutdown(unittest.TestCase):

    def test_every_process_exits_cleanly(self, proc_info):
        if MISSING:
            self.skipTest(SKIP_REASON)
        launch_testing.asserts.assertExitCodes(proc_info)

    def test_the_controller_manager_file_is_removed_at_shutdown(self, before):
        if MISSING:
            self.skipTest(SKIP_REASON)
        self.assertEqual(_manager_files() - before, set())
