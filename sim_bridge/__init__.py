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

"""sim_bridge: the PyBullet arm, pinhole camera and renderer (ROS-free).

Also :mod:`.command_age`: how fresh the commands a realtime loop applies are.

Its ROS 2 node is :mod:`visual_adaptive_servo.ros.sim_node`.
"""
