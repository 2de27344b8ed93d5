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

"""What a run leaves behind: messages, the MCAP recording, the summary figures, the plots.

* :mod:`.messages`: arrays to and from the ROS 2 Jazzy messages (rclpy's classes or
  the rosbags type store, the same functions for both);
* :mod:`.recorder`: :class:`~.recorder.McapRecorder` (rosbag2-compatible MCAP),
  the recorded topics, CSV and JSON outputs;
* :mod:`.summary`: the figures of summary.json and of ``vas compare`` (numpy only);
* :mod:`.cadence`: :class:`~.cadence.RateGate`, which samples' messages a node publishes;
* :mod:`.plots`: the PNGs of a run (matplotlib, imported only by runs that plot);
* :mod:`.bag_report`: ``vas report``, the figures and plots of a recorded bag.
"""
