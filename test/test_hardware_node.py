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

"""sim_node as a ros2_control hardware, and controller_node following the effort controller.

A probe node plays JointStateTopicSystem: it reads the simulator's state topic
and sends efforts as a sensor_msgs/JointState in its own joint order.  The
simulator holds the arm on its brakes until the first finite command, applies
commands by joint name, publishes /clock after the state, and with
``hardware.effort_controller`` brakes while the controller_manager's activity
says the controller is not active; controller_node sends commands only while
it is active.  Real rclpy; the activity cases need controller_manager_msgs
(ros2_control) and skip without it.
"""

import os

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="needs a sourced ROS 2 Jazzy (rclpy)")

from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402

from conftest import spin_until  # noqa: E402
from visual_adaptive_servo.config.controller import CONTROLLER_PARAMS  # noqa: E402
from visual_adaptive_servo.config.files import read_param_file  # noqa: E402
from visual_adaptive_servo.config.sim import SIM_PARAMS  # noqa: E402
from visual_adaptive_servo.recording import messages as m  # noqa: E402
from visual_adaptive_servo.ros.controller_node import ACTIVITY_QOS, ControllerNode  # noqa: E402
from visual_adaptive_servo.ros.params import to_ros  # noqa: E402
from visual_adaptive_servo.ros.sim_node import SimNode  # noqa: E402
from visual_adaptive_servo.schema import CONTROLLER_SECTION, SIM_SECTION  # noqa: E402

CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config",
                      "paper_3dof.yaml")
DOMAIN_ID = 50 + os.getpid() % 50
COMMANDS, STATES = "/hw/joint_commands", "/hw/joint_states"
HARDWARE = {"timing_mode": "realtime", "hardware.command_topic": COMMANDS,
            "hardware.state_topic": STATES}


@pytest.fixture()
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def _overrides(specs, params):
    by_name = {spec.name: spec for spec in specs}
    return [Parameter(name, value=to_ros(by_name[name], value)) for name, value in params.items()]


def _sim(context, **changes):
    params = dict(read_param_file(CONFIG)[SIM_SECTION], **HARDWARE, **changes)
    return SimNode(context=context, parameter_overrides=_overrides(SIM_PARAMS, params))


class Hardware:
    """Plays JointStateTopicSystem (and, for the controller, what it needs to start)."""

    def __init__(self, context):
        self.node = rclpy.create_node("hardware_probe", context=context)
        self.msgs = msgs = m.rclpy_messages()
        self.received = []          # ("state", t, msg) or ("clock", t, None), in arrival order
        self.node.create_subscription(msgs.JointState, STATES, self._on_state,
                                      qos_profile_sensor_data)
        self.node.create_subscription(msgs.Clock, "/clock", self._on_clock, 10)
        # the simulator starts once /camera/features has a subscriber (a controller)
        self.node.create_subscription(msgs.PolygonStamped, "/camera/features", lambda _: None,
                                      qos_profile_sensor_data)
        self.publisher = self.node.create_publisher(msgs.JointState, COMMANDS, 1)

    def _on_state(self, msg):
        self.received.append(("state", m.stamp_to_ns(msg.header.stamp), msg))

    def _on_clock(self, msg):
        self.received.append(("clock", m.stamp_to_ns(msg.clock), None))

    def states(self):
        return [msg for kind, _, msg in self.received if kind == "state"]

    def send(self, names, efforts):
        self.publisher.publish(self.msgs.JointState(
            name=list(names), position=[], velocity=[], effort=[float(e) for e in efforts]))


def test_the_arm_is_held_until_the_first_finite_command_then_driven_by_name(context):
    sim, hw = _sim(context), Hardware(context)
    nodes = [sim, hw.node]
    try:
        spin_until(context, nodes, lambda: len(hw.states()) >= 20, timeout=30.0)
        # NaN: the hardware's command interfaces before a controller has written them
        for _ in range(10):
            hw.send(["joint3", "joint1", "joint2"], [np.nan] * 3)
            spin_until(context, nodes, lambda: False, timeout=0.01)
        held = hw.states()
        assert len(held) >= 20
        q0 = np.array(held[0].position)
        for msg in held:
            np.testing.assert_array_equal(msg.position, q0)
            np.testing.assert_array_equal(msg.velocity, 0.0)
            np.testing.assert_array_equal(msg.effort, 0.0)
        assert sim.counters["held_periods"] >= len(held) - 1
        # a command in the hardware's own joint order, then the sim reports it applied
        tau = {"joint1": 1.5, "joint2": 60.0, "joint3": 12.25}
        order = ["joint3", "joint1", "joint2"]
        count = len(hw.states())

        def applied():
            hw.send(order, [tau[n] for n in order])
            return any(list(s.effort) == [tau[n] for n in s.name] for s in hw.states()[count:])

        spin_until(context, nodes, applied, timeout=10.0)
        driven = [s for s in hw.states()[count:] if any(s.effort)]
        assert driven, "no state reported the command applied"
        assert list(driven[-1].name) == ["joint1", "joint2", "joint3"]
        assert list(driven[-1].effort) == [1.5, 60.0, 12.25]
        assert not np.array_equal(hw.states()[-1].position, q0)   # released: it moves
    finally:
        hw.node.destroy_node()
        sim.destroy_node()


def test_clock_follows_each_joint_state_half_a_period_later(context):
    sim, hw = _sim(context), Hardware(context)
    try:
        spin_until(context, [sim, hw.node], lambda: len(hw.states()) >= 40, timeout=30.0)
        arrival = {(kind, t): i for i, (kind, t, _) in enumerate(hw.received)}
        pairs = [(arrival[("state", t)], arrival[("clock", t)]) for kind, t, _ in hw.received
                 if kind == "state" and ("clock", t) in arrival]
        assert len(pairs) >= 30
        assert all(state < clock for state, clock in pairs)
    finally:
        hw.node.destroy_node()
        sim.destroy_node()


def test_a_command_without_a_controlled_joint_is_refused_and_counted(context):
    sim, hw = _sim(context), Hardware(context)
    nodes = [sim, hw.node]
    try:
        spin_until(context, nodes, lambda: len(hw.states()) >= 5, timeout=30.0)

        def refused():
            hw.send(["joint1", "joint2"], [1.0, 2.0])
            return sim.counters["refused_commands"] > 0

        spin_until(context, nodes, refused, timeout=10.0)
        assert sim.counters["refused_commands"] > 0
        for msg in hw.states():
            np.testing.assert_array_equal(msg.effort, 0.0)     # still on the brakes
    finally:
        hw.node.destroy_node()
        sim.destroy_node()


def _activity(context, active):
    cm = pytest.importorskip("controller_manager_msgs.msg",
                             reason="needs controller_manager_msgs (ros2_control)")
    lifecycle = pytest.importorskip("lifecycle_msgs.msg", reason="needs lifecycle_msgs")
    node = rclpy.create_node("controller_manager", context=context)
    publisher = node.create_publisher(cm.ControllerManagerActivity,
                                      "/controller_manager/activity", ACTIVITY_QOS)

    def publish(state):
        label = {True: "active", False: "inactive"}[state]
        publisher.publish(cm.ControllerManagerActivity(controllers=[cm.NamedLifecycleState(
            name="effort_controller", state=lifecycle.State(label=label))]))

    publish(active)
    return node, publish


def test_the_arm_is_held_while_the_effort_controller_is_not_active(context):
    manager, publish = _activity(context, False)
    sim, hw = _sim(context, **{"hardware.effort_controller": "effort_controller"}), \
        Hardware(context)
    nodes = [sim, hw.node, manager]
    try:
        def sending(until):
            def step():
                hw.send(["joint1", "joint2", "joint3"], [1.0, 50.0, 10.0])
                return until()
            return step

        spin_until(context, nodes, sending(lambda: len(hw.states()) >= 30), timeout=30.0)
        for msg in hw.states():                 # commands come, but the controller is inactive
            np.testing.assert_array_equal(msg.effort, 0.0)
        publish(True)
        spin_until(context, nodes, sending(lambda: any(s.effort[1] == 50.0 for s in hw.states())),
                   timeout=10.0)
        assert hw.states()[-1].effort[1] == 50.0
        publish(False)
        count = len(hw.states())
        spin_until(context, nodes, sending(lambda: len(hw.states()) >= count + 20), timeout=10.0)
        assert sim.effort_state == "inactive"
        np.testing.assert_array_equal(hw.states()[-1].effort, 0.0)
        np.testing.assert_array_equal(hw.states()[-1].velocity, 0.0)
    finally:
        manager.destroy_node()
        hw.node.destroy_node()
        sim.destroy_node()


def test_controller_commands_only_while_the_effort_controller_is_active(context):
    manager, publish = _activity(context, False)
    sections = read_param_file(CONFIG)
    sim = SimNode(context=context, parameter_overrides=_overrides(
        SIM_PARAMS, dict(sections[SIM_SECTION], timing_mode="realtime")))
    ctl = ControllerNode(context=context, parameter_overrides=_overrides(
        CONTROLLER_PARAMS, dict(sections[CONTROLLER_SECTION], timing_mode="realtime")) + [
        Parameter("use_sim_time", value=True),
        Parameter("ros2_control.effort_controller", value="effort_controller")])
    probe = rclpy.create_node("probe", context=context)
    commands = []
    probe.create_subscription(m.rclpy_messages().Float64MultiArray,
                              "/effort_controller/commands", commands.append, 100)
    nodes = [sim, ctl, probe, manager]
    try:
        spin_until(context, nodes, lambda: sim.counters["steps"] >= 40, timeout=30.0)
        assert commands == [] and ctl.samples == 0
        publish(True)
        spin_until(context, nodes, lambda: len(commands) >= 40, timeout=30.0)
        assert ctl.samples >= 40
        publish(False)
        spin_until(context, nodes, lambda: not ctl.effort_active, timeout=10.0)
        spin_until(context, nodes, lambda: False, timeout=0.05)
        count = len(commands)
        steps = sim.counters["steps"]
        spin_until(context, nodes, lambda: sim.counters["steps"] >= steps + 40, timeout=30.0)
        assert len(commands) == count
    finally:
        probe.destroy_node()
        ctl.destroy_node()
        sim.destroy_node()
        manager.destroy_node()
