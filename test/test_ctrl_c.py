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

"""Ctrl-C of ``ros2 launch``: every node exits with status 0 within 1 s, no traceback.

As a terminal does it: ``ros2 launch`` runs in a session of its own and SIGINT
goes to its whole process group, mid-run, so each node gets one SIGINT from
the "terminal" and one more from launch; and a storm of SIGINTs after that,
every 20 ms to each node until it is gone, changes nothing.  The oracle is the process table (a
node is gone when its /proc entry is gone or a zombie) and launch's own report
of each exit ("process has finished cleanly").  Needs ``ros2`` and the
installed package (colcon build); skipped otherwise.
"""

import os
import re
import signal
import subprocess
import time

import pytest

pytest.importorskip("launch_testing", reason="needs ROS 2 (ros2 launch)")


from conftest import installed_share, PACKAGE

installed_share(ros2_command=True)


def _alive(pid):
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as handle:
            return handle.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):   # reaped before or while reading
        return False


def _wait_for(path, text, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if text in path.read_text(errors="replace"):
            return True
        time.sleep(0.05)
    return False


def _interrupt(tmp_path, timing_mode, camera_mode, storm):
    """Launch, SIGINT the group mid-run; with ``storm`` SIGINT each node every 20 ms after.

    Returns the launch's log, each node's pid and name, and the seconds each took to go.
    """
    log = tmp_path / "launch.log"
    env = dict(os.environ, ROS_DOMAIN_ID=str(200 + os.getpid() % 30))
    with open(log, "w", encoding="utf-8") as out:
        launch = subprocess.Popen(
            ["ros2", "launch", PACKAGE, "servo.launch.py", f"timing_mode:={timing_mode}",
             f"camera_mode:={camera_mode}"],
            stdout=out, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    try:
        assert _wait_for(log, "simulation starts", 60.0), log.read_text()
        time.sleep(1.0)   # mid-run
        nodes = {int(pid): name for name, pid in re.findall(
            r"\[INFO\] \[(\S+)-\d+\]: process started with pid \[(\d+)\]", log.read_text())}
        expected = {"sim_node", "controller_node"} | (
            {"feature_detector"} if camera_mode == "rendered" else set())
        assert set(nodes.values()) == expected, log.read_text()
        sigint = time.monotonic()
        os.killpg(launch.pid, signal.SIGINT)
        stopped = {}
        while len(stopped) < len(nodes) and time.monotonic() - sigint < 10.0:
            for pid, name in nodes.items():
                if name not in stopped and not _alive(pid):
                    stopped[name] = time.monotonic() - sigint
                elif name not in stopped and storm:
                    try:
                        os.kill(pid, signal.SIGINT)
                    except ProcessLookupError:
                        pass
            time.sleep(0.02 if storm else 0.005)
        assert launch.wait(timeout=15.0) == 0
    finally:
        if launch.poll() is None:
            os.killpg(launch.pid, signal.SIGKILL)
            launch.wait()
    text = log.read_text()
    assert "Traceback" not in text, text
    for pid, name in nodes.items():
        assert f"process has finished cleanly [pid {pid}]" in text, (name, text)
    assert set(stopped) == expected
    return stopped


@pytest.mark.parametrize("timing_mode, camera_mode", [
    ("lockstep", "points"), ("realtime", "points"), ("lockstep", "rendered"),
    ("realtime", "rendered")])
def test_sigint_to_the_launch_stops_every_node_cleanly_within_a_second(
        tmp_path, timing_mode, camera_mode):
    stopped = _interrupt(tmp_path, timing_mode, camera_mode, storm=False)
    assert max(stopped.values()) < 1.0, stopped


@pytest.mark.parametrize("timing_mode, camera_mode", [("realtime", "rendered")])
def test_sigints_after_the_first_change_nothing_up_to_the_nodes_exit(
        tmp_path, timing_mode, camera_mode):
    # The terminal's SIGINT and launch's forwarded one come apart; a late one used to land
    # after run_node's end, under Python's handler or, in the interpreter's finalisation,
    # under none (exit -2, "process has died": 1 run in 10 of the test above, every run here)
    stopped = _interrupt(tmp_path, timing_mode, camera_mode, storm=True)
    assert max(stopped.values()) < 2.0, stopped
