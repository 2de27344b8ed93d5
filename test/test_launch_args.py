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
from launch.actions import ExecuteProcess, LogInfo  # noqa: E402
from launch.events.process import ProcessExited  # noqa: E402

from visual_adaptive_servo.ros.launch_args import (  # noqa: E402
    recording_folder,
    sim_duration,
    unless_failed,
)


def _context(bag_dir="", duration=""):
    context = LaunchContext()
    context.launch_configurations.update(bag_dir=bag_dir, duration=duration)
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


def test_duration_is_the_files_unless_given_and_then_seconds_from_0():
    assert sim_duration(_context()) == {}
    assert sim_duration(_context(duration="2")) == {"duration": 2.0}
    assert sim_duration(_context(duration="0.5")) == {"duration": 0.5}
    assert sim_duration(_context(duration="0")) == {"duration": 0.0}   # for ever
    for text in ("-1", "nan", "inf", "2s"):
        with pytest.raises(RuntimeError, match=rf"duration:={text}: expected a number of "
                           r"simulated seconds, 0 or more \(0: for ever\)"):
            sim_duration(_context(duration=text))


def _exited(returncode):
    action = ExecuteProcess(cmd=["sim_node"], name="sim_node")
    return ProcessExited(action=action, name="sim_node-1", cmd=["sim_node"], cwd=None,
                         env=None, pid=4242, returncode=returncode)


def test_a_node_that_fails_makes_the_launch_fail_and_a_clean_exit_does_what_it_did():
    # ros2 launch exits 0 whatever its processes do; an exception in an event handler makes
    # LaunchService.run return 1 (after shutting everything down)
    then = [LogInfo(msg="shutting down")]
    handle = unless_failed(then)
    assert handle(_exited(0), LaunchContext()) is then
    with pytest.raises(RuntimeError, match=r"sim_node-1 exited with status 2 \(its log above "
                       r"says why\)"):
        handle(_exited(2), LaunchContext())
    # a node stopped by the shutdown (Ctrl-C, another node's end) is not a failure
    stopping = LaunchContext()
    stopping._set_is_shutdown(True)      # what LaunchService does when it shuts down
    assert handle(_exited(-2), stopping) is then
