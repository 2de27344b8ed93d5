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

"""The ROS 2 nodes: thin wrappers that declare parameters, convert messages and call the core.

* :mod:`.controller_node`: the controller (``ros2 run visual_adaptive_servo controller_node``);
* :mod:`.sim_node`: the PyBullet simulator of :mod:`sim_bridge` (``sim_node``);
* :mod:`.feature_detector_node`: the feature detector (``feature_detector``);
* :mod:`.description_node`: the URDF latched on /robot_description for ros2_control's
  controller_manager (``robot_description``);
* :mod:`.params`: a parameter schema declared on a node; :mod:`.main`: spinning and a
  clean stop on Ctrl-C.

The only modules of the package that import rclpy.
"""
