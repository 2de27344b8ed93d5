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

"""The two ROS 2 nodes closing the loop through real rclpy topics.

Needs a sourced ROS 2 Jazzy (skipped otherwise).  Each test runs in its own
rclpy context on a private ROS domain, with the nodes in one executor (the
nodes' own, conftest.spin_until).  The oracle for the lockstep loop is the in-process
runner: both step the same simulator and controller in the same order and
``vas run`` reads pixels and times as the messages carry them (float32,
integer nanoseconds), so the tracking error through ROS must equal the one
``vas run`` records, sample by sample (with ``publish_every_sample``, as
servo.launch.py sets it for a lockstep recording).  Without it the state
topics must carry exactly the samples of the publish_rate grid (the first
sample at or after each instant k / rate, computed here from the 5 ms sample
grid).  The simulator's realtime counts of periods without a new command and
of the applied command's age are checked against what it really applied: a
test node commands it with torques that number the commands, and the joint
states it publishes carry the torque applied over each period.
"""

import logging
import math
import os
import re

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="needs a sourced ROS 2 Jazzy (rclpy)")

from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402

from conftest import bag_messages, spin_until  # noqa: E402
from visual_adaptive_servo.ros.sim_node import SimNode  # noqa: E402
from visual_adaptive_servo.recording import messages as m  # noqa: E402
from visual_adaptive_servo.config.controller import CONTROLLER_PARAMS  # noqa: E402
from visual_adaptive_servo.config.files import read_param_file  # noqa: E402
from visual_adaptive_servo.config.scenario import load_scenario  # noqa: E402
from visual_adaptive_servo.config.sim import SIM_PARAMS  # noqa: E402
from visual_adaptive_servo.schema import CONTROLLER_SECTION, SIM_SECTION, ConfigError  # noqa: E402
from visual_adaptive_servo.ros.controller_node import ControllerNode  # noqa: E402
from visual_adaptive_servo.ros.params import refuse_unknown_overrides, to_ros  # noqa: E402
from visual_adaptive_servo.runner import run_scenario  # noqa: E402

CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "config",
                      "paper_3dof.yaml")
DOMAIN_ID = 100 + os.getpid() % 100


@pytest.fixture()
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def _sections(**changes):
    """The parameter file's sections with ``section.name=value`` changes applied."""
    sections = read_param_file(CONFIG)
    for key, value in changes.items():
        section, name = key.split("__")
        sections[section][name.replace("_DOT_", ".")] = value
    return sections


def _overrides(specs, params):
    by_name = {spec.name: spec for spec in specs}
    return [Parameter(name, value=to_ros(by_name[name], value)) for name, value in params.items()]


def _make_nodes(context, sections, controller_extra=()):
    sim = SimNode(context=context, parameter_overrides=_overrides(SIM_PARAMS,
                                                                  sections[SIM_SECTION]))
    ctl = ControllerNode(context=context, parameter_overrides=_overrides(
        CONTROLLER_PARAMS, sections[CONTROLLER_SECTION]) + [Parameter("use_sim_time",
                                                                      value=True),
                                                            *controller_extra])
    return sim, ctl


class Probe:
    """A third node recording what the controller publishes."""

    def __init__(self, context):
        self.node = rclpy.create_node("probe", context=context)
        msgs = m.rclpy_messages()
        self.errors, self.commands, self.stamped, self.diagnostics = {}, [], [], []
        self.desired = []
        self.node.create_subscription(msgs.PolygonStamped, "/controller_node/tracking_error",
                                      self._on_error, 100)
        self.node.create_subscription(
            msgs.PolygonStamped, "/controller_node/desired",
            lambda msg: self.desired.append(m.stamp_to_ns(msg.header.stamp)), 100)
        self.node.create_subscription(msgs.Float64MultiArray, "/effort_controller/commands",
                                      lambda msg: self.commands.append(np.array(msg.data)), 100)
        self.node.create_subscription(msgs.JointState, "/controller_node/effort_command",
                                      self.stamped.append, 100)
        self.stamped_diagnostics = []     # (stamp ns, status)
        self.node.create_subscription(msgs.DiagnosticArray, "/diagnostics",
                                      self._on_diagnostics, 100)

    def _on_diagnostics(self, msg):
        self.diagnostics.extend(msg.status)
        self.stamped_diagnostics += [(m.stamp_to_ns(msg.header.stamp), s) for s in msg.status]

    def _on_error(self, msg):
        self.errors[m.stamp_to_ns(msg.header.stamp)] = m.features_from_msg(msg)[1]

    def last_values(self, name):
        status = [s for s in self.diagnostics if s.name == name][-1]
        return {kv.key: kv.value for kv in status.values}


def _reference_errors(tmp_path, changes, duration):
    """{stamp [ns]: x - x_d} that ``vas run`` records for the same parameters."""
    scenario = load_scenario(CONFIG, [f"{key.replace('__', '.').replace('_DOT_', '.')}={value}"
                                      for key, value in changes.items()])
    run_scenario(scenario, str(tmp_path), duration=duration, progress=False, plots=False)
    return {stamp: m.features_from_msg(msg)[1] for stamp, msg in
            bag_messages(tmp_path / "run.mcap", "/controller_node/tracking_error").items()}


@pytest.mark.parametrize("camera", [
    {},
    {"sim_node__camera_rate": 40.0, "sim_node__camera_latency": 0.03},
], ids=["paper", "40Hz_camera_30ms_late"])
def test_lockstep_loop_equals_the_in_process_runner(context, tmp_path, camera):
    duration = 2.0
    changes = dict(camera, sim_node__duration=duration)
    sim, ctl = _make_nodes(context, _sections(**changes),
                           [Parameter("publish_every_sample", value=True)])
    probe = Probe(context)
    try:
        spin_until(context, [sim, ctl, probe.node], lambda: sim.finished.done(), timeout=120.0)
        assert sim.finished.done(), "the lockstep loop did not reach its duration in 120 s"
        # let the last messages arrive
        spin_until(context, [probe.node], lambda: False, timeout=0.3)
        steps = round(duration / 0.005)
        assert sim.counters == {"steps": steps, "command_timeouts": 0, "refused_commands": 0,
                                "stale_commands": 0, "frame_delivery_timeouts": 0,
                                "detector_timeouts": 0, "held_periods": 0}
        assert ctl.samples == steps
        assert len(probe.commands) == len(probe.stamped) == steps
        assert [m.stamp_to_ns(c.header.stamp) for c in probe.stamped] == \
            [k * 5_000_000 for k in range(steps)]
        tau = np.array(probe.commands)
        assert np.all(np.isfinite(tau)) and np.max(np.abs(tau)) > 1.0
        np.testing.assert_array_equal([c.effort for c in probe.stamped], tau)

        reference = _reference_errors(tmp_path, changes, duration)
        # until the first frame arrives the samples are rejected: no tracking error
        waiting = round(camera.get("sim_node__camera_latency", 0.0) / 0.005)
        assert len(reference) == steps - waiting
        assert sorted(probe.errors) == sorted(reference)
        stamps = sorted(reference)
        np.testing.assert_allclose([probe.errors[s] for s in stamps],
                                   [reference[s] for s in stamps], rtol=0.0, atol=1e-6)
        ros_err = np.linalg.norm([probe.errors[s] for s in stamps], axis=1)
        assert np.max(ros_err) < 3.0
        assert np.max(ros_err[stamps.index(1_000_000_000):]) < 1.0
        levels = {s.name: s.level for s in probe.diagnostics}
        assert levels.get("controller_node") in (0, b"\x00")
        assert levels.get("sim_node") in (0, b"\x00")
        frames = probe.last_values("controller_node")
        if camera:
            assert int(frames["frames_late"]) == int(frames["frames_applied"]) > 30
            assert float(frames["frame_age_max"]) == pytest.approx(0.03, abs=1e-9)
        else:
            assert frames["frames_late"] == "0" and float(frames["frame_age_max"]) == 0.0
        assert frames["frames_dropped"] == "0"
    finally:
        probe.node.destroy_node()
        ctl.destroy_node()
        sim.destroy_node()


def test_runtime_gain_is_applied_and_invalid_changes_are_refused(context):
    ctl = ControllerNode(context=context, parameter_overrides=_overrides(
        CONTROLLER_PARAMS, read_param_file(CONFIG)[CONTROLLER_SECTION]))
    try:
        ok = ctl.set_parameters([Parameter("K", value=[0.002, 0.003])])[0]
        assert ok.successful, ok.reason
        np.testing.assert_array_equal(ctl.tracker.gains.K, [0.002, 0.003])

        bad = ctl.set_parameters([Parameter("K", value=[0.002, 0.0])])[0]
        assert not bad.successful
        assert "controller_node.K: every entry must be > 0" in bad.reason
        np.testing.assert_array_equal(ctl.tracker.gains.K, [0.002, 0.003])
        assert list(ctl.get_parameter("K").value) == [0.002, 0.003]

        fixed = ctl.set_parameters([Parameter("alpha", value=1.0)])[0]
        assert not fixed.successful and "read-only" in fixed.reason
        assert ctl.tracker.gains.alpha == 10.0

        limit = ctl.set_parameters([Parameter("torque_limit", value=[100.0, 100.0])])[0]
        assert not limit.successful and "torque_limit: needs 3 values" in limit.reason
    finally:
        ctl.destroy_node()


@pytest.mark.parametrize("overrides, match", [
    ({"alpha": 10.0, "gamma": 40.0}, r"alpha: Theorem 1 requires alpha > gamma/3"),
    ({"alpha": "ten"}, r"controller_node\.alpha: must be a number, got 'ten'"),
    ({"model": "scara"}, r"controller_node\.model"),
    ({"sample_time": -1.0}, r"controller_node\.sample_time: .*out of range"),
    ({"Gamma_z": [0.1, 0.2]}, r"controller_node\.Gamma_z: needs 3 values, got 2"),
])
def test_invalid_configuration_is_refused_at_start_up(context, overrides, match):
    core = logging.getLogger("visual_adaptive_servo")
    level, handlers = core.level, list(core.handlers)
    with pytest.raises(ConfigError, match=match):
        ControllerNode(context=context, parameter_overrides=[
            Parameter(name, value=value) for name, value in overrides.items()])
    # the node that failed leaves the core's logging as it found it
    assert core.level == level and core.handlers == handlers


def test_a_parameter_the_node_does_not_have_is_refused_naming_the_nearest(context):
    # rclpy ignores an override of a name never declared: a typo in a params file ran as if
    # absent, while vas run refuses the same file (run_node calls this once all is declared)
    ctl = ControllerNode(context=context, parameter_overrides=[
        Parameter("camera_latncy", value=0.03), Parameter("gamma", value=4.0)])
    try:
        with pytest.raises(ConfigError, match=r"controller_node: unknown parameter\(s\) "
                           r"\['camera_latncy'\] \(did you mean camera_latency for "
                           r"camera_latncy\?\)"):
            refuse_unknown_overrides(ctl, CONTROLLER_SECTION)
    finally:
        ctl.destroy_node()
    fine = ControllerNode(context=context, parameter_overrides=[Parameter("gamma", value=4.0)])
    try:
        refuse_unknown_overrides(fine, CONTROLLER_SECTION)     # every name given is declared
    finally:
        fine.destroy_node()


def test_the_core_s_lines_while_the_model_is_built_reach_the_node_s_log(context, capfd,
                                                                        monkeypatch):
    # a first start compiles the kernels for half a minute while the model and the tracker
    # are built (models/backend.py compile_notice): the node forwards the core's lines
    # from before that, not only once it is up
    from visual_adaptive_servo.ros import controller_node

    build = controller_node.build_controller_model
    module = logging.getLogger("visual_adaptive_servo.test_build")
    propagates, module.propagate = module.propagate, True   # as in the test below

    def logging_build(values):
        module.info("building the model now")
        return build(values)

    monkeypatch.setattr(controller_node, "build_controller_model", logging_build)
    try:
        ControllerNode(context=context).destroy_node()
    finally:
        module.propagate = propagates
    assert "building the model now" in capfd.readouterr().err


def test_a_scalar_gain_and_a_gain_left_out_are_accepted(context):
    # one number for a diagonal (dynamic typing), and the derived gains left unset
    ctl = ControllerNode(context=context, parameter_overrides=[
        Parameter("Gamma_z_perp", value=180.0), Parameter("K", value=[0.002, 0.003])])
    try:
        np.testing.assert_array_equal(ctl.tracker.config.Gamma_z_perp, [180.0, 180.0])
        np.testing.assert_array_equal(ctl.tracker.config.K, [0.002, 0.003])
        # Gamma_z not given: declared unset, derived at the first joint sample
        assert ctl.tracker.config.Gamma_z is None
        assert ctl.get_parameter("Gamma_z").type_ == Parameter.Type.NOT_SET
    finally:
        ctl.destroy_node()


def test_unconvertible_joint_state_is_a_rejected_sample_not_a_crash(context):
    ctl = ControllerNode(context=context)
    probe = Probe(context)
    msgs = m.rclpy_messages()
    pub_js = probe.node.create_publisher(msgs.JointState, "/joint_states", 10)
    pub_x = probe.node.create_publisher(msgs.PolygonStamped, "/camera/features", 10)
    try:
        spin_until(context, [ctl, probe.node],
                   lambda: pub_js.get_subscription_count() and pub_x.get_subscription_count(),
                   10.0)
        pub_js.publish(m.joint_state_to_msg(msgs, 0.5, ["a", "b", "c"], [0.0] * 3, [0.0] * 3,
                                            [0.0] * 3))
        pub_x.publish(m.features_to_msg(msgs, 0.5, [65.0, 65.0]))
        spin_until(context, [ctl, probe.node], lambda: probe.commands and probe.diagnostics, 10.0)
        assert ctl.samples == 1
        np.testing.assert_array_equal(probe.commands[0], [0.0, 0.0, 0.0])
        status = probe.diagnostics[0]
        assert status.level in (2, b"\x02") and "joint positions q: missing" in status.message
    finally:
        probe.node.destroy_node()
        ctl.destroy_node()


def test_realtime_mode_runs_on_the_wall_clock(context):
    sections = _sections(sim_node__duration=0.5, sim_node__timing_mode="realtime",
                         controller_node__timing_mode="realtime")
    sim, ctl = _make_nodes(context, sections)
    try:
        spin_until(context, [sim, ctl], lambda: sim.finished.done(), timeout=30.0)
        assert sim.finished.done()
        assert sim.counters["steps"] == 100
        assert ctl.samples > 50    # best effort: most samples arrive and are answered
        assert sim.sim.t == pytest.approx(0.5)
    finally:
        ctl.destroy_node()
        sim.destroy_node()


def _grid_stamps(rate, period_ns, steps):
    """Stamps [ns] of the samples (every ``period_ns``) a ``rate`` Hz grid lets through."""
    per_second = round(1e9 / period_ns)
    indices = sorted({math.ceil(j * per_second / rate - 1e-9)
                      for j in range(int(steps * rate / per_second) + 2)})
    return [k * period_ns for k in indices if k < steps]


@pytest.mark.parametrize("rate", [None, 30.0, 400])
def test_state_topics_go_out_at_publish_rate_and_commands_at_every_sample(context, rate):
    """Lockstep without recording: 100 samples at 200 Hz; the default 100 Hz is every 2nd."""
    extra = [] if rate is None else [Parameter("publish_rate", value=rate)]
    sim, ctl = _make_nodes(context, _sections(sim_node__duration=0.5), extra)
    probe = Probe(context)
    try:
        spin_until(context, [sim, ctl, probe.node], lambda: sim.finished.done(), timeout=60.0)
        assert sim.finished.done()
        spin_until(context, [probe.node], lambda: False, timeout=0.3)
        assert ctl.samples == len(probe.commands) == len(probe.stamped) == 100
        expected = _grid_stamps(100.0 if rate is None else rate, 5_000_000, 100)
        assert len(expected) == {None: 50, 30.0: 15, 400: 100}[rate]
        assert sorted(probe.desired) == expected
        assert sorted(probe.errors) == expected
    finally:
        probe.node.destroy_node()
        ctl.destroy_node()
        sim.destroy_node()


def test_diagnostics_at_their_rate_and_at_once_on_a_change_of_level(context):
    # a camera 30 ms late: the samples before the first frame are rejected (not OK), the
    # first one with a frame (at 30 ms, off the 10 Hz grid) is OK and must go out at once
    changes = {"sim_node__duration": 0.5, "sim_node__camera_rate": 40.0,
               "sim_node__camera_latency": 0.03}
    sim, ctl = _make_nodes(context, _sections(**changes),
                           [Parameter("diagnostics_rate", value=10)])
    probe = Probe(context)
    try:
        spin_until(context, [sim, ctl, probe.node], lambda: sim.finished.done(), timeout=60.0)
        assert sim.finished.done()
        spin_until(context, [probe.node], lambda: False, timeout=0.3)
        published = sorted((stamp, status.level) for stamp, status in probe.stamped_diagnostics
                           if status.name == "controller_node")
        stamps = [stamp for stamp, _ in published]
        assert len(set(stamps)) == len(stamps)
        grid = [k * 100_000_000 for k in range(5)]
        assert set(grid) <= set(stamps)
        first_frame = min(probe.errors)
        assert first_frame == 30_000_000
        assert first_frame in stamps
        levels = dict(published)
        assert levels[0] != levels[first_frame] and levels[first_frame] in (0, b"\x00")
        # anything off the grid is a change of level from the status published before it
        for (_, before), (stamp, level) in zip(published, published[1:]):
            assert stamp in grid or level != before, stamp
    finally:
        probe.node.destroy_node()
        ctl.destroy_node()
        sim.destroy_node()


@pytest.mark.parametrize("overrides, match", [
    ({"publish_rate": 0.0}, r"controller_node\.publish_rate: must be a positive finite rate"),
    ({"publish_rate": -100}, r"controller_node\.publish_rate: must be a positive finite rate"),
    ({"diagnostics_rate": math.inf},
     r"controller_node\.diagnostics_rate: must be a positive finite rate"),
    ({"publish_rate": "fast"}, r"controller_node\.publish_rate: must be a number of Hz"),
    ({"publish_every_sample": "yes"}, r"controller_node\.publish_every_sample: .*type"),
])
def test_invalid_rates_are_refused_at_start_up(context, overrides, match):
    with pytest.raises(ConfigError, match=match):
        ControllerNode(context=context, parameter_overrides=[
            Parameter(name, value=value) for name, value in overrides.items()])


def test_rates_are_read_only(context):
    ctl = ControllerNode(context=context, parameter_overrides=[Parameter("publish_rate",
                                                                         value=50)])
    try:
        assert ctl.get_parameter("publish_rate").value == 50
        assert ctl.state_gate.period == pytest.approx(0.02)
        result = ctl.set_parameters([Parameter("publish_rate", value=10.0)])[0]
        assert not result.successful and "read-only" in result.reason
    finally:
        ctl.destroy_node()


class CommandDriver:
    """A controller that answers every other joint state, with torques that number its commands.

    Command k is [k * 1e-3, 0, 0] N m.  ``hardware``: published as the ros2_control
    topic hardware does, a JointState on ``topic`` at every state, the latest command
    again when there is no new one.  Keeps every joint state it receives (stamp,
    applied torque).
    """

    def __init__(self, context, joint_names, topic, state_topic, hardware):
        self.node = rclpy.create_node("driver", context=context)
        msgs = self.msgs = m.rclpy_messages()
        self.names, self.hardware = list(joint_names), hardware
        reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.pub = self.node.create_publisher(msgs.JointState if hardware
                                              else msgs.Float64MultiArray, topic, reliable)
        # best effort like the simulator's states, deep enough to keep every one
        keep_all = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
        self.node.create_subscription(msgs.JointState, state_topic, self._on_state, keep_all)
        self.node.create_subscription(msgs.PolygonStamped, "/camera/features",
                                      lambda msg: None, keep_all)
        self.states, self.sent, self.tau = [], 0, None

    def _on_state(self, msg):
        self.states.append((m.stamp_to_ns(msg.header.stamp), tuple(msg.effort)))
        if len(self.states) % 2 == 0:
            self.sent += 1
            self.tau = [self.sent * 1e-3] + [0.0] * (len(self.names) - 1)
        elif not self.hardware or self.tau is None:
            return
        if self.hardware:
            self.pub.publish(m.effort_command_to_msg(self.msgs, msg.header.stamp, self.names,
                                                     self.tau))
        else:
            self.pub.publish(m.float_array_to_msg(self.msgs, self.tau))

    def applied(self, period_ns):
        """Per period (the states after the first), the number of the command applied or None."""
        numbers = {}
        for k in range(1, self.sent + 1):
            numbers[(k * 1e-3,) + (0.0,) * (len(self.names) - 1)] = k
        states = sorted(self.states)
        assert [stamp for stamp, _ in states] == [j * period_ns for j in range(len(states))], \
            "a joint state was lost: the oracle needs every period"
        return [numbers.get(effort) for _, effort in states[1:]]


def _oracle(applied):
    """before_first, with_new, ages [periods] of the applied commands, from what was applied."""
    before = next(i for i, k in enumerate(applied) if k is not None)
    first_seen, last, with_new, ages = {}, None, 0, []
    for i, k in enumerate(applied[before:]):
        if k is None:
            continue
        if k != last:
            first_seen[k] = i
            with_new += 1
            last = k
        ages.append(i - first_seen[k])
    return before, with_new, ages


@pytest.mark.parametrize("hardware", [False, True], ids=["direct", "ros2_control_hardware"])
def test_realtime_sim_counts_the_periods_without_a_new_command_it_really_had(context, hardware):
    changes = {"sim_node__duration": 0.0, "sim_node__timing_mode": "realtime"}
    topic, state_topic = "/effort_controller/commands", "/joint_states"
    if hardware:
        topic, state_topic = "/test_hardware/commands", "/test_hardware/states"
        changes.update({"sim_node__hardware_DOT_command_topic": topic,
                        "sim_node__hardware_DOT_state_topic": state_topic})
    sections = _sections(**changes)
    sim = SimNode(context=context, parameter_overrides=_overrides(SIM_PARAMS,
                                                                  sections[SIM_SECTION]))
    driver = CommandDriver(context, sim.config.joint_names, topic, state_topic, hardware)
    diagnostics = []
    msgs = m.rclpy_messages()
    driver.node.create_subscription(msgs.DiagnosticArray, "/diagnostics",
                                    lambda msg: diagnostics.extend(msg.status), 100)
    try:
        # 1.1 s of realtime at 200 Hz: the diagnostics at 1 s of sim time come too
        spin_until(context, [sim, driver.node], lambda: len(driver.states) > 220, timeout=30.0)
        # the simulator stops here; the driver takes the states still on their way
        spin_until(context, [driver.node], lambda: False, timeout=0.3)
        age = sim.command_age
        applied = driver.applied(5_000_000)
        assert age.periods + age.periods_before_first == len(applied)
        before, with_new, ages = _oracle(applied)
        assert (age.periods_before_first, age.with_new) == (before, with_new)
        assert age.without_new == len(applied) - before - with_new
        # the controller answers every other state: about half the periods have no new command
        assert 0.25 < age.without_new / age.periods < 0.75
        counts = np.bincount(ages)
        np.testing.assert_array_equal(age.periods_counts[:len(counts)], counts)
        assert age.periods_counts[len(counts):].sum() == 0
        assert age.age_periods() == {
            "median": float(np.percentile(ages, 50, method="inverted_cdf")),
            "p99": float(np.percentile(ages, 99, method="inverted_cdf")), "max": max(ages)}
        assert age.summary().startswith(f"{age.without_new} of {age.periods} periods without "
                                        f"a new command")
        # the diagnostics say what was true at their stamp
        status = [s for s in diagnostics if s.name == "sim_node"][-1]
        values = {kv.key: kv.value for kv in status.values}
        t_ns = round(float(values["sim_time"]) * 1e9)
        assert t_ns >= 1_000_000_000
        before_t, with_new_t, _ = _oracle(applied[:t_ns // 5_000_000])
        assert int(values["periods_before_first_command"]) == before_t
        assert int(values["periods_without_new_command"]) == \
            t_ns // 5_000_000 - before_t - with_new_t
    finally:
        driver.node.destroy_node()
        sim.destroy_node()


class _Sink:
    """Records what the handler forwards, per level (the node's logger in the test below)."""

    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(("info", text))

    def warning(self, text):
        self.lines.append(("warning", text))

    def error(self, text):
        self.lines.append(("error", text))


def test_the_core_s_log_lines_are_throttled_per_call_site_not_all_together(context, capfd):
    from visual_adaptive_servo.ros.controller_node import RosLogHandler
    core = logging.getLogger("visual_adaptive_servo.test_log_handler")
    core.setLevel(logging.INFO)
    now = [0.0]
    sink = _Sink()
    handler = RosLogHandler(sink, clock=lambda: now[0])
    core.addHandler(handler)
    try:
        for _ in range(3):                      # one call site, three times within 1 s
            core.info("report")
        core.info("blend")                      # another site 0 s later: not silenced
        core.warning("careful")
        now[0] = 1.0                            # a second later the first site speaks again
        core.info("report")
    finally:
        core.removeHandler(handler)
    assert sink.lines == [("info", "report"), ("info", "blend"), ("warning", "careful"),
                          ("info", "report")]
    # through a real node's logger: two sites within a second both reach the console
    node = rclpy.create_node("log_handler_test", context=context)
    handler = RosLogHandler(node.get_logger())
    core.addHandler(handler)
    try:
        core.info("first line of the core")
        core.info("second line of the core")
    finally:
        core.removeHandler(handler)
        node.destroy_node()
    err = capfd.readouterr().err
    assert "first line of the core" in err and "second line of the core" in err


def test_the_controller_node_logs_the_core_s_info_lines_and_restores_the_level(context, capfd):
    core = logging.getLogger("visual_adaptive_servo")
    before = core.level
    # under colcon test launch_testing's plugin makes new loggers not propagate (conftest's
    # logged_warnings); a node's own process propagates, as Python does by default
    module = logging.getLogger("visual_adaptive_servo.control.controller")
    propagates, module.propagate = module.propagate, True
    ctl = ControllerNode(context=context)
    try:
        # Python's default level (WARNING) would drop the core's INFO lines, among them
        # the start-up report and a long start blend's duration
        assert core.getEffectiveLevel() == logging.INFO
        q0 = load_scenario(CONFIG).sim.initial_positions
        ctl.tracker.start(q0)
    finally:
        ctl.destroy_node()
        module.propagate = propagates
    assert core.level == before
    err = capfd.readouterr().err
    assert err.count("start-up report:") == 1 and "departures from the paper" in err


@pytest.mark.parametrize("pictures", [True, False])
def test_a_recorded_rendered_start_waits_on_the_pictures_only_if_they_are_recorded(
        context, pictures):
    # servo.launch.py record_pictures:=false: a recorder without the picture topics; the
    # simulator waited for it on them until Ctrl-C
    sections = _sections(sim_node__camera_mode="rendered",
                         sim_node__start_DOT_wait_for_recorder=True,
                         sim_node__start_DOT_recorder_takes_pictures=pictures)
    sim = SimNode(context=context, parameter_overrides=_overrides(SIM_PARAMS,
                                                                  sections[SIM_SECTION]))
    try:
        missing = " ".join(sim._missing())
    finally:
        sim.destroy_node()
    # (the counts of subscribers, not the names, may include other tests' nodes still known
    # to discovery: the counts are matched loosely)
    assert bool(re.search(r"/camera/image_raw \(\d+ of 2 subscribers\)", missing)) == pictures
    assert bool(re.search(r"/camera/camera_info \(\d+ of 1 subscribers\)", missing)) == pictures
    assert pictures or re.search(r"/camera/image_raw \(\d+ of 1 subscribers\)", missing)


def test_integers_in_a_params_file_are_numbers_as_in_vas_run(context):
    # YAML's 2 and [0, 0, 1] reach rclpy as INTEGER and INTEGER_ARRAY; declared DOUBLE and
    # DOUBLE_ARRAY they were refused ("expecting type 'DOUBLE_ARRAY'") though vas run takes
    # them, as README's own template writes them
    sections = _sections()
    sim_params = {k: v for k, v in sections[SIM_SECTION].items()
                  if k not in ("duration", "camera.up")}
    sim = SimNode(context=context, parameter_overrides=_overrides(SIM_PARAMS, sim_params) + [
        Parameter("duration", value=2), Parameter("camera.up", value=[0, 0, 1])])
    try:
        assert sim.config["duration"] == 2.0 and isinstance(sim.config["duration"], float)
        assert list(sim.config["camera.up"]) == [0.0, 0.0, 1.0]
    finally:
        sim.destroy_node()
    ctl_params = {k: v for k, v in sections[CONTROLLER_SECTION].items() if k != "camera_rate"}
    ints = [Parameter("use_sim_time", value=True), Parameter("camera_rate", value=0)]
    ctl = ControllerNode(context=context,
                         parameter_overrides=_overrides(CONTROLLER_PARAMS, ctl_params) + ints)
    ctl.destroy_node()
    # what is not a number is still refused, naming the parameter
    with pytest.raises(ConfigError, match=r"sim_node.duration: must be a number, got 'two'"):
        SimNode(context=context, parameter_overrides=_overrides(SIM_PARAMS, sim_params) + [
            Parameter("duration", value="two"), Parameter("camera.up", value=[0, 0, 1])])
