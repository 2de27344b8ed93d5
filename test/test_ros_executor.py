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

"""The package's executor (ros/executor.py) against rclpy's own, entity by entity.

Needs a sourced ROS 2 Jazzy (skipped otherwise).  Every test runs on both
executors: rclpy's ``SingleThreadedExecutor`` is the oracle of what must happen
(timers, subscriptions in creation order, services and clients, QoS event
handlers, guard conditions, tasks and ``async def`` callbacks, entities created
and destroyed while spinning, an external shutdown).  The closed loops of
test_nodes.py and test_hardware_node.py spin on the package's executor
(conftest.spin_until), so their equality with ``vas run`` covers it too.
"""

import os
import time

import pytest

rclpy = pytest.importorskip("rclpy", reason="needs a sourced ROS 2 Jazzy (rclpy)")

from rcl_interfaces.msg import Parameter as ParameterMsg  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup  # noqa: E402
from rclpy.event_handler import SubscriptionEventCallbacks  # noqa: E402
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy  # noqa: E402
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from std_msgs.msg import Int64  # noqa: E402

from visual_adaptive_servo.ros.executor import KeptWaitSetExecutor  # noqa: E402
from visual_adaptive_servo.ros.main import EXECUTORS  # noqa: E402

DOMAIN_ID = 150 + os.getpid() % 50
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture(params=["kept_wait_set", "rclpy"])
def setup(request):
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    executor = EXECUTORS[request.param](context=ctx)
    nodes = []

    def node(name, **kwargs):
        made = rclpy.create_node(name, context=ctx, **kwargs)
        executor.add_node(made)
        nodes.append(made)
        return made

    yield ctx, executor, node
    executor.shutdown()
    for made in nodes:
        made.destroy_node()
    rclpy.try_shutdown(context=ctx)


def spin(executor, until, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not until() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    return until()


def test_the_default_executor_is_the_kept_wait_set_one():
    assert EXECUTORS["kept_wait_set"] is KeptWaitSetExecutor
    assert EXECUTORS["rclpy"] is SingleThreadedExecutor


def test_messages_arrive_in_order_and_a_timer_fires(setup):
    _, executor, node = setup
    sender, receiver = node("sender"), node("receiver")
    pub = sender.create_publisher(Int64, "/numbers", RELIABLE)
    got, ticks = [], []
    receiver.create_subscription(Int64, "/numbers", lambda msg: got.append(msg.data), RELIABLE)
    receiver.create_timer(0.01, lambda: ticks.append(time.monotonic()))
    assert spin(executor, lambda: pub.get_subscription_count() == 1)
    for k in range(50):
        pub.publish(Int64(data=k))
    assert spin(executor, lambda: len(got) == 50 and len(ticks) >= 5)
    assert got == list(range(50))
    assert all(b > a for a, b in zip(ticks, ticks[1:]))


def test_ready_subscriptions_are_served_in_creation_order(setup):
    # controller_node relies on it: a waiting frame is taken before the joint state
    _, executor, node = setup
    sender, receiver = node("sender"), node("receiver")
    first = sender.create_publisher(Int64, "/first", RELIABLE)
    second = sender.create_publisher(Int64, "/second", RELIABLE)
    order = []
    receiver.create_subscription(Int64, "/first", lambda msg: order.append(("first", msg.data)),
                                 RELIABLE)
    receiver.create_subscription(Int64, "/second",
                                 lambda msg: order.append(("second", msg.data)), RELIABLE)
    assert spin(executor, lambda: first.get_subscription_count() == second.get_subscription_count()
                == 1)
    for k in range(20):
        second.publish(Int64(data=k))       # published first, created second
        first.publish(Int64(data=k))
        time.sleep(0.002)                   # both are waiting when the executor wakes
        assert spin(executor, lambda want=2 * (k + 1): len(order) == want)
        assert order[-2:] == [("first", k), ("second", k)]


def test_a_service_answers_a_client_on_the_same_executor(setup):
    _, executor, node = setup
    server = node("server", parameter_overrides=[Parameter("gain", value=1.0)])
    server.declare_parameter("gain", 1.0)
    client = node("client").create_client(SetParameters, "/server/set_parameters")
    assert spin(executor, client.service_is_ready)
    request = SetParameters.Request(parameters=[
        Parameter("gain", value=2.5).to_parameter_msg()])
    future = client.call_async(request)
    assert spin(executor, future.done)
    assert future.result().results[0].successful
    assert server.get_parameter("gain").value == 2.5
    assert isinstance(request.parameters[0], ParameterMsg)


def test_a_qos_event_handler_reports_an_incompatible_publisher(setup):
    _, executor, node = setup
    events = []
    node("receiver").create_subscription(
        Int64, "/qos", lambda msg: None, RELIABLE,
        event_callbacks=SubscriptionEventCallbacks(incompatible_qos=events.append))
    node("sender").create_publisher(
        Int64, "/qos", QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
    assert spin(executor, lambda: events)
    assert events[0].total_count >= 1


def test_guard_conditions_tasks_and_async_callbacks_run(setup):
    _, executor, node = setup
    receiver = node("receiver")
    calls = []
    guard = receiver.create_guard_condition(lambda: calls.append("guard"))
    guard.trigger()
    assert spin(executor, lambda: "guard" in calls)

    async def task():
        calls.append("task")
        return 7
    future = executor.create_task(task)
    assert spin(executor, future.done)
    assert future.result() == 7 and "task" in calls

    async def on_message(msg):
        calls.append(("async", msg.data))
    receiver.create_subscription(Int64, "/async", on_message, RELIABLE)
    pub = node("sender").create_publisher(Int64, "/async", RELIABLE)
    assert spin(executor, lambda: pub.get_subscription_count() == 1)
    pub.publish(Int64(data=3))
    assert spin(executor, lambda: ("async", 3) in calls)


def test_entities_created_and_destroyed_while_spinning(setup):
    _, executor, node = setup
    sender, receiver = node("sender"), node("receiver")
    pub = sender.create_publisher(Int64, "/late", RELIABLE)
    spin(executor, lambda: False, timeout=0.2)          # the wait set is built without it
    got = []
    sub = receiver.create_subscription(Int64, "/late", lambda msg: got.append(msg.data),
                                       RELIABLE)
    assert spin(executor, lambda: pub.get_subscription_count() == 1)
    pub.publish(Int64(data=1))
    assert spin(executor, lambda: got == [1])
    assert receiver.destroy_subscription(sub)
    assert spin(executor, lambda: pub.get_subscription_count() == 0)
    pub.publish(Int64(data=2))
    spin(executor, lambda: False, timeout=0.2)
    assert got == [1]
    timer_calls = []
    timer = receiver.create_timer(0.01, lambda: timer_calls.append(1))
    assert spin(executor, lambda: len(timer_calls) >= 2)
    receiver.destroy_timer(timer)
    spin(executor, lambda: False, timeout=0.05)
    count = len(timer_calls)
    spin(executor, lambda: False, timeout=0.1)
    assert len(timer_calls) == count


def test_an_external_shutdown_ends_the_spin(setup):
    # rclpy's executor may raise RCLError instead (its timeout timer cannot be created in a
    # shut down context: main.py's doc); the package's raises ExternalShutdownException
    ctx, executor, node = setup
    node("lonely")
    spin(executor, lambda: False, timeout=0.1)
    rclpy.shutdown(context=ctx)
    expected = (ExternalShutdownException if isinstance(executor, KeptWaitSetExecutor)
                else (ExternalShutdownException, _rclpy.RCLError))
    with pytest.raises(expected):
        for _ in range(3):
            executor.spin_once(timeout_sec=0.05)


def test_an_unknown_executor_is_refused_by_name():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_ID)
    from visual_adaptive_servo.ros.main import make_executor
    from visual_adaptive_servo.schema import ConfigError
    made = rclpy.create_node("named", context=ctx, parameter_overrides=[
        Parameter("executor", value="events")])
    try:
        with pytest.raises(ConfigError, match="executor: 'events' is not one of"):
            make_executor(made)
    finally:
        made.destroy_node()
        rclpy.try_shutdown(context=ctx)


def test_the_fast_nodes_publishers_keep_the_incompatible_qos_warning(setup):
    from visual_adaptive_servo.ros.executor import incompatible_qos_warning

    _, executor, node = setup
    sender = node("sender")
    warnings = []

    class Logger:

        def warning(self, text):
            warnings.append(text)

    sender.get_logger = Logger
    best_effort = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    pub = sender.create_publisher(Int64, "~/state", best_effort,
                                  event_callbacks=incompatible_qos_warning(sender, "~/state"))
    assert len(pub.event_handlers) == 1       # rclpy's default: two (QoS and type)
    node("receiver").create_subscription(Int64, "/sender/state", lambda msg: None, RELIABLE)
    assert spin(executor, lambda: warnings)
    assert warnings[0].startswith("New subscription discovered on topic '/sender/state', "
                                  "requesting incompatible QoS")
    assert warnings[0].endswith("Last incompatible policy: RELIABILITY")


def test_an_async_callback_awaiting_a_service_on_the_same_executor_completes(setup):
    # the task waits for a future only a later wake-up (the response) completes: the
    # executor must keep waiting on its entities while the task is pending
    _, executor, node = setup
    server = node("server")
    server.declare_parameter("gain", 1.0)
    caller = node("caller")
    # its own callback group: in the subscription's, rclpy would wait for the callback
    # to end before taking the response the callback awaits
    client = caller.create_client(SetParameters, "/server/set_parameters",
                                  callback_group=MutuallyExclusiveCallbackGroup())
    assert spin(executor, client.service_is_ready)
    results = []

    async def on_message(msg):
        request = SetParameters.Request(parameters=[
            Parameter("gain", value=float(msg.data)).to_parameter_msg()])
        response = await client.call_async(request)
        results.append(response.results[0].successful)

    caller.create_subscription(Int64, "/set", on_message, RELIABLE)
    pub = node("sender").create_publisher(Int64, "/set", RELIABLE)
    assert spin(executor, lambda: pub.get_subscription_count() == 1)
    pub.publish(Int64(data=4))
    assert spin(executor, lambda: results == [True], timeout=5.0)
    assert server.get_parameter("gain").value == 4.0
