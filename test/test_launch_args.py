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


"""The launch files' helpers (ros/launch_args.py), without launching anything."""

import pytest

pytest.importorskip("launch_ros", reason="needs ROS 2 launch (a sourced Jazzy)")

from launch import LaunchContext  # noqa: E402

from visual_adaptive_servo.ros.launch_args import recording_folder  # noqa: E402


def _context(bag_dir):
    context = LaunchContext()
    context.launch_configurations["bag_dir"] = bag_dir
    return context


def test_an_existing_bag_dir_is_refused_before_anything_starts(tmp_path):
    # ros2 bag record refuses an existing folder and the simulator then waited for the
    # recorder until Ctrl-C; a failed launch leaves its folder behind
    (tmp_path / "left").mkdir()
    with pytest.raises(RuntimeError, match=r"bag_dir .*left: exists, and ros2 bag record "
                       r"refuses an existing folder .*remove it or choose another"):
        recording_folder(_context(str(tmp_path / "left")))
    assert recording_folder(_context(str(tmp_path / "new"))) == str(tmp_path / "new")
    assert recording_folder(_context("")) == ""
