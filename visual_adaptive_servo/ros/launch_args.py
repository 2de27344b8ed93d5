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

"""Launch arguments for controller_node shared by servo.launch.py and ros2_control.launch.py.

``publish_rate`` and ``diagnostics_rate``: empty leaves the node's own default;
``executor`` and ``realtime_priority``: how every node of ours runs (ros/main.py).
"""

import math
import os
import tempfile

import yaml
from launch.actions import DeclareLaunchArgument, RegisterEventHandler
from launch.event_handlers import OnShutdown
from launch.substitutions import LaunchConfiguration

from .main import (DEFAULT_EXECUTOR, EXECUTOR_DESCRIPTION, EXECUTORS, REALTIME_DESCRIPTION,
                   REALTIME_PRIORITY)

RATE_ARGUMENTS = ("publish_rate", "diagnostics_rate")


def rate_arguments(publish_note=""):
    """The two DeclareLaunchArgument; ``publish_note`` ends publish_rate's "(empty: 100...)"."""
    return [
        DeclareLaunchArgument("publish_rate", default_value="",
                              description="controller_node's rate [Hz] of its state topics "
                                          f"(empty: 100{publish_note})"),
        DeclareLaunchArgument("diagnostics_rate", default_value="",
                              description="controller_node's rate [Hz] of /diagnostics, plus "
                                          "one at each change of health level (empty: 1)"),
    ]


def node_arguments():
    """DeclareLaunchArgument ``executor`` (:data:`.main.EXECUTORS`) and ``realtime_priority``."""
    return [
        DeclareLaunchArgument(
            "executor", default_value=DEFAULT_EXECUTOR, choices=list(EXECUTORS),
            description="Executor of the package's nodes: " + EXECUTOR_DESCRIPTION),
        DeclareLaunchArgument(
            "realtime_priority", default_value=str(REALTIME_PRIORITY),
            description="The package's nodes, " + REALTIME_DESCRIPTION),
    ]


def node_parameters(context):
    """{"executor", "realtime_priority"}: the launch arguments, parameters of each node of ours.

    The priority YAML-parsed (``50`` is an integer), checked by the node.
    """
    return {"executor": LaunchConfiguration("executor").perform(context),
            "realtime_priority": yaml.safe_load(
                LaunchConfiguration("realtime_priority").perform(context))}


def rates(context):
    """controller_node's ``publish_rate`` and ``diagnostics_rate`` given as launch arguments.

    YAML-parsed (``100`` is a number), checked by the node.
    """
    given = {name: LaunchConfiguration(name).perform(context) for name in RATE_ARGUMENTS}
    return {name: yaml.safe_load(text) for name, text in given.items() if text}


def recorder_qos_overrides(topics, folder=None):
    """A ``--qos-profile-overrides-path`` file: ``topics`` recorded reliable, keeping all.

    For a lockstep recording, whose publishers are reliable with a deep history
    (ros/executor.py, ``RECORDED``): the recorder's own history then never drops
    what it has not written yet.  Written to a new file in ``folder`` (default: the
    temporary folder); returns its path.  Not for realtime: there the measurements
    are best effort, which a reliable request would not match.
    """
    overrides = {topic: {"history": "keep_all", "reliability": "reliable",
                         "durability": "volatile"} for topic in topics}
    return temporary_yaml("vas-recorder-qos-", overrides, folder)


def temporary_yaml(prefix, data, folder=None):
    """The path of a new ``<prefix>*.yaml`` holding ``data`` in ``folder`` (default: $TMPDIR).

    The files the launch files write for their processes (each removed at shutdown with
    :func:`removed_on_shutdown`).
    """
    handle, path = tempfile.mkstemp(prefix=prefix, suffix=".yaml", dir=folder)
    with open(handle, "w", encoding="utf-8") as stream:
        yaml.safe_dump(data, stream)
    return path


def parameter_file(values, cleanup):
    """A parameter file of ``values`` for the node it is given to; removed at shutdown.

    What launch_ros does with a dict of parameters (a ``/**`` YAML in the temporary
    folder), except that launch_ros leaves its files behind (ros2/launch_ros#5), one per
    node and launch; the action that removes this one is appended to ``cleanup``.
    """
    path = temporary_yaml("vas-launch-params-", {"/**": {"ros__parameters": values}})
    cleanup.append(removed_on_shutdown(path))
    return path


def removed_on_shutdown(path):
    """An action that deletes the file ``path`` the launch wrote when the launch shuts down."""
    return RegisterEventHandler(OnShutdown(
        on_shutdown=lambda event, context: _remove(path)))


def _remove(path):
    """Delete a file the launch wrote, if it is still there (no actions to run)."""
    try:
        os.remove(path)
    except FileNotFoundError:
        pass


def unless_failed(on_exit):
    """OnProcessExit's ``on_exit`` for a node of ours: ``on_exit`` after a clean exit.

    A node that exits with an error (an invalid parameter file: status 2) instead stops
    the launch with status 1: ``ros2 launch`` itself exits 0 whatever its processes do,
    but an exception raised while it handles an event is logged (``Caught exception in
    launch ...: sim_node exited with status 2``), shuts everything down and makes the
    launch service return 1.  Exits during a shutdown (Ctrl-C, another node's end) raise
    nothing.
    """
    def handle(event, context):
        if event.returncode != 0 and not context.is_shutdown:
            raise RuntimeError(f"{event.process_name} exited with status {event.returncode} "
                               f"(its log above says why)")
        return on_exit
    return handle


def duration_argument():
    """DeclareLaunchArgument ``duration``: sim_node's simulated seconds (:func:`sim_duration`)."""
    return DeclareLaunchArgument(
        "duration", default_value="",
        description="Simulated seconds until sim_node stops and the launch shuts down, 0 for "
                    "ever (empty: the params_file's sim_node.duration)")


def sim_duration(context):
    """``{"duration": seconds}`` for sim_node from the launch argument; {} when it is empty.

    Refused before any process starts unless it is a number of seconds, 0 or more (0:
    for ever, as sim_node.duration).
    """
    text = LaunchConfiguration("duration").perform(context)
    if not text:
        return {}
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0.0):
        raise RuntimeError(f"duration:={text}: expected a number of simulated seconds, 0 or "
                           f"more (0: for ever)")
    return {"duration": value}


def recording_folder(context):
    """The ``bag_dir`` launch argument ('' for ros2 bag's own name), refused if it exists.

    ``ros2 bag record -o`` refuses an existing folder and exits; the simulator, told to
    wait for the recorder, then waited for it until Ctrl-C.  A failed launch leaves its
    folder behind, so the next one with the same ``bag_dir`` hung that way.  Raised
    before any process starts.
    """
    bag_dir = LaunchConfiguration("bag_dir").perform(context)
    if bag_dir and os.path.exists(bag_dir):
        raise RuntimeError(f"bag_dir {bag_dir}: exists, and ros2 bag record refuses an existing "
                           f"folder (a run that failed leaves its own behind): remove it or "
                           f"choose another")
    return bag_dir
