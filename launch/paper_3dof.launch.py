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

"""The paper's scenario under ROS 2: servo.launch.py with config/paper_3dof.yaml.

    ros2 launch visual_adaptive_servo paper_3dof.launch.py
    ros2 launch visual_adaptive_servo paper_3dof.launch.py timing_mode:=realtime render:=true
    ros2 launch visual_adaptive_servo paper_3dof.launch.py record:=true bag_dir:=/tmp/vas_bag
    ros2 launch visual_adaptive_servo paper_3dof.launch.py camera_mode:=rendered

Every argument of servo.launch.py (params_file, timing_mode, camera_mode,
render, record, bag_dir, publish_rate, diagnostics_rate) works here too, with
the same defaults.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource


def generate_launch_description():
    share = get_package_share_directory("visual_adaptive_servo")
    return LaunchDescription([IncludeLaunchDescription(
        PythonLaunchDescriptionSource(os.path.join(share, "launch", "servo.launch.py")))])
