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

"""Shared fixtures: the reference scenario, a continuous-time closed loop, marker pictures.

``simulate_continuous`` integrates the paper's closed loop -- true rigid-body
dynamics of the model, true projection, and :func:`control_law` -- with RK4,
so the proof's Lyapunov functions and the derivative in eq (19) can be checked
against the continuous-time theory, independently of sampling.

``draw_discs`` renders anti-aliased colour markers whose exact centroids are
known, for the feature detector's tests.

Under ``colcon test`` (ROS sourced) launch_testing's pytest plugin imports every
test module while it looks for launch tests (``pytest_pycollect_makemodule``), and
a module-level skip there (``pytest.importorskip`` of an optional extra) escapes as
a skip of the whole test folder: "collected 0 items / 1 skipped" and exit status 0.
:func:`pytest_pycollect_makemodule` below turns it back into the skip of that one
module.
"""

import atexit
import contextlib
import logging
import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.control.controller import EstimatorState, Gains, control_law

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAPER_CONFIG = os.path.join(ROOT, "config", "paper_3dof.yaml")
PACKAGE = "visual_adaptive_servo"


@pytest.hookimpl(hookwrapper=True)
def pytest_pycollect_makemodule(module_path, parent):
    """A module-level skip raised inside another plugin's hook skips that module only."""
    outcome = yield
    if outcome.excinfo is not None and issubclass(outcome.excinfo[0], pytest.skip.Exception):
        outcome.force_result(pytest.Module.from_parent(parent, path=module_path))


@pytest.fixture
def rng():
    return np.random.default_rng(20150101)


@pytest.fixture(scope="session")
def scenario():
    return load_scenario(PAPER_CONFIG)


def paper_gains(config):
    return Gains(config.K, config.alpha, config.gamma, config.Gamma_d, config.Gamma_z_perp,
                 config.Gamma_z)


def pack(q, qd, st):
    return np.concatenate([q, qd, st.x_obs, st.a_z_perp, st.a_z, st.a_d])


def unpack(y, model):
    n, m2 = model.n, 2 * model.m
    sizes = [n, n, m2, model.p_perp, model.p_z, model.p_d]
    parts = np.split(y, np.cumsum(sizes)[:-1])
    return parts[0], parts[1], EstimatorState(*parts[2:])


def closed_loop_rates(model, gains, trajectory, t, y):
    """Time derivative of the packed closed-loop state and the law's output."""
    q, qd, st = unpack(y, model)
    x, _ = model.project(q)
    xd, xd_dot, xd_ddot = trajectory(t)
    out = control_law(model, gains, st, q, qd, x, xd, xd_dot, xd_ddot)
    M = model.mass_matrix(q)
    qdd = np.linalg.solve(M, out.tau - model.coriolis_matrix(q, qd) @ qd
                          - model.gravity_torque(q))
    r = out.rates
    dy = np.concatenate([qd, qdd, r.x_obs, r.a_z_perp, r.a_z, r.a_d])
    return dy, out, x, (xd, xd_dot, xd_ddot)


def simulate_continuous(model, gains, trajectory, q0, qd0, state0, dt, steps, observe):
    """RK4 of the closed loop; ``observe(t, y, out, x, desired)`` at every step."""
    y = pack(q0, qd0, state0)
    t = 0.0
    for _ in range(steps + 1):
        k1, out, x, desired = closed_loop_rates(model, gains, trajectory, t, y)
        observe(t, y, out, x, desired)
        k2 = closed_loop_rates(model, gains, trajectory, t + dt / 2, y + dt / 2 * k1)[0]
        k3 = closed_loop_rates(model, gains, trajectory, t + dt / 2, y + dt / 2 * k2)[0]
        k4 = closed_loop_rates(model, gains, trajectory, t + dt, y + dt * k3)[0]
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += dt


def draw_discs(height, width, discs, background=(40, 40, 40), supersample=16):
    """An (height, width, 3) uint8 picture of anti-aliased discs, and their true centroids.

    ``discs``: (col, row, radius, (r, g, b)) per disc, centre and radius in
    continuous image coordinates (the top-left corner of the picture is (0, 0),
    see :mod:`visual_adaptive_servo.vision.detection`).  Each pixel is sampled on a
    ``supersample`` x ``supersample`` grid; its colour is the covered fraction's
    mix of disc and what lies below, rounded to 8 bits.  The true centroid of a
    disc is the mean of its covered sample points inside the picture (m, 2):
    exactly the centroid of what the picture shows, up to the 8-bit rounding.
    """
    picture = np.empty((height, width, 3))
    picture[:] = background
    offsets = (np.arange(supersample) + 0.5) / supersample
    centroids = []
    for col, row, radius, color in discs:
        r0, r1 = max(int(np.floor(row - radius)), 0), min(int(np.ceil(row + radius)) + 1, height)
        c0, c1 = max(int(np.floor(col - radius)), 0), min(int(np.ceil(col + radius)) + 1, width)
        ys = (np.arange(r0, r1)[:, None] + offsets).reshape(-1)
        xs = (np.arange(c0, c1)[:, None] + offsets).reshape(-1)
        inside = (xs[None, :] - col) ** 2 + (ys[:, None] - row) ** 2 <= radius ** 2
        coverage = inside.reshape(r1 - r0, supersample, c1 - c0, supersample).mean(axis=(1, 3))
        coverage = coverage[:, :, None]
        picture[r0:r1, c0:c1] = (coverage * np.asarray(color, dtype=float)
                                 + (1.0 - coverage) * picture[r0:r1, c0:c1])
        rows, cols = np.nonzero(inside)
        centroids.append([xs[cols].mean(), ys[rows].mean()])
    return np.rint(picture).astype(np.uint8), np.array(centroids)


def installed_share(ros2_command=False):
    """The package's share folder in the ament index; the calling module skipped without it.

    For the modules that launch the installed package (``colcon build`` it first); with
    ``ros2_command`` also skipped when the ``ros2`` command is not on the PATH.  Call it at
    module level, after ``pytest.importorskip`` of what the module needs from ROS.
    """
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

    try:
        share = get_package_share_directory(PACKAGE)
    except PackageNotFoundError:
        pytest.skip(f"{PACKAGE} is not installed in an ament index (colcon build it first)",
                    allow_module_level=True)
    if ros2_command and shutil.which("ros2") is None:
        pytest.skip("the ros2 command is not on the PATH", allow_module_level=True)
    return share


def short_params_file(share, duration, folder=None):
    """The installed config/paper_3dof.yaml with ``sim_node.duration`` set; its path.

    For the launch tests: written as ``paper_<duration>s.yaml`` into ``folder``, or without
    one into a temporary file removed when the test process exits.
    """
    import yaml

    with open(os.path.join(share, "config", "paper_3dof.yaml"), encoding="utf-8") as handle:
        params = yaml.safe_load(handle)
    params["sim_node"]["ros__parameters"]["duration"] = duration
    if folder is None:
        handle, path = tempfile.mkstemp(suffix=".yaml")
        atexit.register(os.remove, path)
    else:
        handle = path = os.path.join(folder, f"paper_{duration:g}s.yaml")
    with open(handle, "w", encoding="utf-8") as stream:
        yaml.safe_dump(params, stream)
    return path


@contextlib.contextmanager
def logged_warnings(name="visual_adaptive_servo.control.controller", level=logging.WARNING):
    """The records of ``level`` and above logger ``name`` emits inside the block (a list).

    A handler on the module's logger, not caplog: with ROS sourced, launch_testing's
    pytest plugin makes every new logger a LaunchLogger that does not propagate to the
    root, so caplog sees nothing under ``colcon test``.
    """
    records = []
    handler = logging.Handler(level)
    handler.emit = records.append
    logger = logging.getLogger(name)
    was = logger.level
    logger.addHandler(handler)
    if level < logger.getEffectiveLevel():
        logger.setLevel(level)
    try:
        yield records
    finally:
        logger.removeHandler(handler)
        logger.setLevel(was)


def bag_messages(path, topic):
    """{header stamp [ns]: message} of ``topic`` in a rosbag2 (folder or .mcap file)."""
    from rosbags.highlevel import AnyReader

    from visual_adaptive_servo.recording.messages import stamp_to_ns

    found = {}
    with AnyReader([Path(path)]) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        for connection, _, raw in reader.messages(connections=connections):
            msg = reader.deserialize(raw, connection.msgtype)
            found[stamp_to_ns(msg.header.stamp)] = msg
    return found


def bag_counts(path):
    """{topic: message count} of a rosbag2 (folder or .mcap file)."""
    from rosbags.highlevel import AnyReader

    counts = {}
    with AnyReader([Path(path)]) as reader:
        for connection in reader.connections:
            counts[connection.topic] = counts.get(connection.topic, 0) + connection.msgcount
    return counts


def spin_until(context, nodes, until, timeout):
    """Spin ``nodes`` in one executor of ``context`` until ``until()`` or ``timeout`` [s].

    For the rclpy tests (they import rclpy first, skipping without ROS); the nodes'
    own executor (ros/executor.py), as ``ros2 run`` spins them.
    """
    from visual_adaptive_servo.ros.executor import KeptWaitSetExecutor

    executor = KeptWaitSetExecutor(context=context)
    for node in nodes:
        executor.add_node(node)
    deadline = time.monotonic() + timeout
    while not until() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    executor.shutdown()
