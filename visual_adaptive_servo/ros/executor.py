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

"""A single-threaded rclpy executor that keeps its wait set: less than half rclpy's CPU.

Measured on the 2-core machine (benchmarks/bench_executor.py): a node shaped like
controller_node that only answers a 1 kHz joint state with two commands spends
0.95-0.98 ms of CPU per joint state under Jazzy's ``SingleThreadedExecutor``
(rclpy 7.1), i.e. the whole core, before any controller runs; 0.42-0.44 ms under
this one.  Per wake-up that executor gathers every entity of every node
in Python, enters each handle, allocates a new rcl wait set, wraps each ready
callback in a :class:`~rclpy.task.Task` coroutine and triggers its guard condition
twice per callback, which wakes it once more for nothing.

:class:`KeptWaitSetExecutor` does the same work with the same semantics, once:

* the entity lists and the rcl wait set are built when the set of entities changes
  (rclpy triggers the executor's guard condition at every ``create_*``,
  ``destroy_*``, ``add_node``, ``remove_node`` and ``create_task``), and the handles
  stay entered (in use) meanwhile, as rclpy enters them around each wait;
* per wake-up: clear and refill the kept wait set, wait, then call the ready
  callbacks directly, in rclpy's order of kinds (waitables, timers, subscriptions,
  guard conditions, clients, services; each kind in creation order; with several
  nodes rclpy goes node by node, this executor kind by kind), one message per ready
  subscription per wake-up, one callback after another in one thread (so every
  callback group is trivially respected);
* waitables (QoS event handlers, actions), guard-condition callbacks and tasks
  (``create_task``, futures' done callbacks) run as rclpy's Tasks, unchanged.

It uses rclpy's wait-set binding (``rclpy.impl.implementation_singleton``, what
``rclpy.executors`` itself uses; Jazzy's rclpy has no other single-threaded
executor).  Every kind of entity, and the shutdown paths, are tested against
rclpy's executor under real rclpy (test/test_ros_executor.py); the read-only node
parameter ``executor`` (``--ros-args -p executor:=rclpy``, or the launch files'
``executor:=rclpy``) selects rclpy's ``SingleThreadedExecutor`` instead.
"""

from __future__ import annotations

from contextlib import ExitStack
import inspect

from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import InvalidHandle
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.qos import QoSProfile, qos_policy_name_from_kind, ReliabilityPolicy
from rclpy.subscription import Subscription
from rclpy.task import Task


#: history of the reliable publishers a lockstep recording takes every period of: how many
#: messages a topic's recorder may fall behind (descheduled, stalled) before it loses the
#: oldest.  The history holds a message only until every reliable reader acknowledged it.
RECORDED_DEPTH = 2000
RECORDED = QoSProfile(depth=RECORDED_DEPTH, reliability=ReliabilityPolicy.RELIABLE)


def incompatible_qos_warning(node, topic):
    """PublisherEventCallbacks with one handler: rclpy's incompatible-QoS warning.

    rclpy gives every publisher two QoS event handlers (incompatible QoS and
    incompatible type), each a waitable the executor adds to its wait set and
    checks at every wake-up (2.4 us each under cProfile on the 2-core VM): 16 on
    controller_node's eight publishers.  The 1 kHz nodes keep the warning a user
    needs (a subscriber asking for reliable from a best-effort topic, the same text
    as rclpy's) and leave out the type one (the subscriber's side reports it too).
    """
    logger = node.get_logger()
    name = node.resolve_topic_name(topic)

    def warn(event):
        logger.warning(f"New subscription discovered on topic '{name}', requesting "
                       f"incompatible QoS. No messages will be sent to it. Last incompatible "
                       f"policy: {qos_policy_name_from_kind(event.last_policy_kind)}")
    return PublisherEventCallbacks(incompatible_qos=warn, use_default_callbacks=False)


class KeptWaitSetExecutor(Executor):
    """Runs callbacks in the thread that calls :meth:`spin_once`, from one kept wait set."""

    def __init__(self, *, context=None):
        super().__init__(context=context)
        self._kept = None           # (wait set, entities, entered handles) or None: rebuild

    # -- the kept wait set -------------------------------------------------------
    def _release(self):
        if self._kept is not None:
            kept, self._kept = self._kept, None
            kept[2].close()         # the handles may be destroyed again

    def _build(self):
        """Gather every node's entities, enter their handles, allocate the wait set."""
        self._release()
        nodes = self.get_nodes()
        subs, timers, clients, services, guards, waitables = [], [], [], [], [], []
        for node in nodes:
            subs.extend(node.subscriptions)
            timers.extend(node.timers)
            clients.extend(node.clients)
            services.extend(node.services)
            guards.extend(node.guards)
            waitables.extend(node.waitables)
        stack = ExitStack()
        try:
            def usable(entities, handle=lambda entity: entity.handle):
                kept = []
                for entity in entities:
                    try:
                        stack.enter_context(handle(entity))
                    except InvalidHandle:       # destroyed meanwhile
                        continue
                    kept.append(entity)
                return kept

            subs, timers, clients, services, guards = (
                usable(group) for group in (subs, timers, clients, services, guards))
            waitables = usable(waitables, lambda waitable: waitable)
            own = [gc for gc in (self._guard, self._sigint_gc) if gc is not None]
            stack.enter_context(self._context.handle)
            for gc in own:
                stack.enter_context(gc.handle)
            extra = [w.get_num_entities() for w in waitables]
            wait_set = _rclpy.WaitSet(
                len(subs) + sum(e.num_subscriptions for e in extra),
                len(guards) + len(own) + sum(e.num_guard_conditions for e in extra),
                len(timers) + sum(e.num_timers for e in extra),
                len(clients) + sum(e.num_clients for e in extra),
                len(services) + sum(e.num_services for e in extra),
                sum(e.num_events for e in extra), self._context.handle)
        except BaseException:
            stack.close()
            raise
        handles = ([s.handle for s in subs], [t.handle for t in timers],
                   [c.handle for c in clients], [s.handle for s in services],
                   [g.handle for g in guards + own])
        self._kept = (wait_set, (subs, timers, clients, services, guards, waitables, own,
                                 handles), stack)

    # -- spinning ----------------------------------------------------------------
    def spin_once(self, timeout_sec=None):
        """Wait up to ``timeout_sec`` (None: forever) for work and do all that is ready."""
        if self._is_shutdown:
            return
        if not self._context.ok():
            raise ExternalShutdownException()
        # tasks first, as rclpy yields them before it waits; one still pending (awaiting a
        # future) is resumed after each wake-up, once the entities that may complete it ran
        self._run_tasks()
        try:
            wait_set, entities = self._fill()
        except InvalidHandle:
            # an entity was destroyed since the last wake-up (its handle refuses new use);
            # the guard condition that says so has not been waited on yet
            self._release()
            wait_set, entities = self._fill()
        subs, timers, clients, services, guards, waitables, own, handles = entities
        sub_h, timer_h, client_h, service_h, guard_h = handles
        timeout_ns = -1 if timeout_sec is None or timeout_sec < 0 else int(timeout_sec * 1e9)
        wait_set.wait(timeout_ns)
        if self._is_shutdown:
            return
        if not self._context.ok():
            raise ExternalShutdownException()
        ready_guards = wait_set.get_ready_entities("guard_condition")
        # waitables are read before the wait set changes (their is_ready looks into it)
        ready_waitables = [w for w in waitables if w.is_ready(wait_set)]
        ready_timers = wait_set.get_ready_entities("timer") if timers else ()
        ready_subs = wait_set.get_ready_entities("subscription") if subs else ()
        ready_clients = wait_set.get_ready_entities("client") if clients else ()
        ready_services = wait_set.get_ready_entities("service") if services else ()

        for waitable in ready_waitables:
            self._waitable(waitable)
        for timer, handle in zip(timers, timer_h):
            if handle.pointer in ready_timers:
                self._later(self._timer(timer, handle))
        for sub, handle in zip(subs, sub_h):
            if handle.pointer in ready_subs:
                self._later(self._subscription(sub, handle))
        for gc in guards:
            if gc.handle.pointer in ready_guards and gc.callback is not None:
                self.create_task(gc.callback)
        for client, handle in zip(clients, client_h):
            if handle.pointer in ready_clients:
                self._client(client, handle)
        for service, handle in zip(services, service_h):
            if handle.pointer in ready_services:
                self._later(self._service(service, handle))
        if any(gc.handle.pointer in ready_guards for gc in own):
            # an entity, a node or a task was added or removed, or the executor woken
            self._release()
        self._run_tasks()

    def _fill(self):
        """The kept wait set (built if need be), cleared and filled with every entity."""
        if self._kept is None:
            self._build()
        wait_set, entities, _ = self._kept
        sub_h, timer_h, client_h, service_h, guard_h = entities[-1]
        wait_set.clear_entities()
        for h in sub_h:
            wait_set.add_subscription(h)
        for h in timer_h:
            wait_set.add_timer(h)
        for h in client_h:
            wait_set.add_client(h)
        for h in service_h:
            wait_set.add_service(h)
        for h in guard_h:
            wait_set.add_guard_condition(h)
        for waitable in entities[5]:
            waitable.add_to_wait_set(wait_set)
        return wait_set, entities

    def _later(self, result):
        """A coroutine callback (``async def``) runs on as a task, as in rclpy."""
        if result is not None and inspect.iscoroutine(result):
            self.create_task(result)

    def _run_tasks(self):
        """Run (or resume) once each task that can run (rclpy's rule), drop the done ones."""
        if not self._tasks:
            return
        with self._tasks_lock:
            tasks = list(self._tasks)
        for task, _, _ in tasks:
            if not task.executing() and not task.done():
                task()
                if task.exception() is not None:
                    raise task.exception()
        with self._tasks_lock:
            self._tasks = [entry for entry in self._tasks if not entry[0].done()]

    @staticmethod
    def _timer(timer, handle):
        # rclpy's workaround for rcl reporting a cancelled timer as ready
        if handle.is_timer_ready():
            handle.call_timer()
            return timer.callback()

    @staticmethod
    def _subscription(sub, handle):
        msg_info = handle.take_message(sub.msg_type, sub.raw)
        if msg_info is None:
            return
        if sub._callback_type is Subscription.CallbackType.MessageOnly:
            return sub.callback(msg_info[0])
        return sub.callback(*msg_info)

    def _client(self, client, handle):
        header, response = handle.take_response(client.srv_type.Response)
        if header is None:
            return
        try:
            future = client.get_pending_request(header.request_id.sequence_number)
        except KeyError:            # the request was cancelled
            return
        future._set_executor(self)
        future.set_result(response)

    @staticmethod
    def _service(service, handle):
        request, header = handle.service_take_request(service.srv_type.Request)
        if header is None:
            return
        response = service.callback(request, service.srv_type.Response())
        if inspect.iscoroutine(response):
            async def respond():
                service.send_response(await response, header)
            return respond()
        service.send_response(response, header)

    def _waitable(self, waitable):
        data = waitable.take_data()
        for future in waitable._futures:
            future._set_executor(self)
        task = Task(waitable.execute, (data,), executor=self)
        task()
        if not task.done():
            with self._tasks_lock:
                self._tasks.append((task, waitable, None))
        elif task.exception() is not None:
            raise task.exception()

    def shutdown(self, timeout_sec=None):
        self._release()
        return super().shutdown(timeout_sec)
