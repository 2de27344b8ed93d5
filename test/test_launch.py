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

"""launch_testing: the installed launch file runs the loop and ends cleanly.

``launch/paper_3dof.launch.py`` is started with a 2 s scenario on a private
ROS domain; the test waits for the simulator to report the duration reached,
the simulator must then exit by itself, and after shutdown every process must
have exited with status 0.  Skipped
without launch_testing or when the package is not installed (colcon build).
"""

import os
import unittest

import pytest

pytest.importorskip("launch_testing", reason="needs ROS 2 launch_testing")

import launch_testing.actions
import launch_testing.asserts
from launch.actions import IncludeLaunchDescription, SetEnvironmentVariable
from launch.launch_description_sources import PythonLaunchDescriptionSource

from launch import LaunchDescription

from conftest import installed_share, short_params_file

SHARE = installed_share()


@pytest.mark.launch_test
def generate_test_description():
    return LaunchDescription([
        SetEnvironmentVariable("ROS_DOMAIN_ID", str(150 + os.getpid() % 50)),
        IncludeLaunchDescription(
            PythonLaunchDescriptionSource(os.path.join(SHARE, "launch", "paper_3dof.launch.py")),
            launch_arguments={"params_file": short_params_file(SHARE, 2.0)}.items()),
        launch_testing.actions.ReadyToTest(),
    ])


class TestLoop(unittest.TestCase):

    def test_simulator_reaches_its_duration_and_exits(self, proc_output, proc_info):
        proc_output.assertWaitFor("controller connected: simulation starts", timeout=60)
        proc_output.assertWaitFor("duration 2.0 s reached after 400 steps", timeout=120)
        proc_output.assertWaitFor("0 command timeouts, 0 refused commands", timeout=10)
        proc_info.assertWaitForShutdown(process="sim_node", timeout=30)


@launch_testing.post_shutdown_test()
class TestShutdown(unittest.TestCase):

    def test_every_process_exits_cleanly(self, proc_info):
        launch_testing.asserts.assertExitCodes(proc_info)
