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

"""The ``main`` of the package's nodes: spin until done or Ctrl-C, then stop cleanly.

The ros2/demos pattern (``rclpy.spin``; catch ``KeyboardInterrupt`` and
``ExternalShutdownException``; destroy the node; ``try_shutdown``) fails under a
terminal's Ctrl-C of ``ros2 launch``, seen here on Jazzy:

* rclpy's signal handler shuts the context down from its own thread while the
  main thread may be inside a callback: ``publish`` then raises ``RCLError:
  publisher's context is invalid`` (exit status 1), or the executor's next wait
  set raises ``failed to initialize wait set``;
* the terminal sends SIGINT to every process of the group and ``ros2 launch``
  forwards one more to each node: the second ``KeyboardInterrupt`` lands in the
  ``finally`` clause, inside ``destroy_node`` (traceback, exit status -2).

So rclpy installs no signal handler here (``SignalHandlerOptions.NO``); SIGINT
and SIGTERM only set a flag, and the executor spins with a short timeout and
looks at the flag between callbacks.  The sample in flight is finished, the
context stays valid until the node is destroyed, a second signal changes
nothing (after the first, signals are ignored up to the process's end), and
the node exits with status 0 within ``SPIN_TIMEOUT`` plus one callback.

The executor: :class:`~.executor.KeptWaitSetExecutor` (the node parameter
``executor``, read-only, default ``kept_wait_set``), which does rclpy's
single-threaded work at less than half its CPU per callback (0.45x,
benchmarks/bench_executor.py), or ``rclpy``: rclpy's own ``SingleThreadedExecutor``.

In ``timing_mode: realtime`` a node also asks for real-time scheduling
(:func:`realtime_scheduling`: the read-only parameter ``realtime_priority``).
"""

from __future__ import annotations

import gc
import signal
import threading

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from ..schema import ConfigError
from .executor import KeptWaitSetExecutor
from .params import refuse_unknown_overrides
from .scheduling import fifo_threads, realtime_threads

SPIN_TIMEOUT = 0.1    # s of wall time: the longest a stop request waits for the executor
EXECUTORS = {"kept_wait_set": KeptWaitSetExecutor, "rclpy": SingleThreadedExecutor}
DEFAULT_EXECUTOR = "kept_wait_set"
#: what the node parameter ``executor`` and the launch argument of that name say of it
EXECUTOR_DESCRIPTION = ("kept_wait_set: the package's executor (one kept wait set, callbacks "
                        "called directly: less than half of rclpy's CPU per callback); rclpy: "
                        "rclpy's SingleThreadedExecutor")

#: SCHED_FIFO priority of a node in realtime (ros2_control's controller_manager takes 50 too)
REALTIME_PRIORITY = 50
REALTIME_DESCRIPTION = ("timing_mode realtime only: the executor's and the middleware's threads "
                        "on SCHED_FIFO at this priority (1-99; a refusal is logged and changes "
                        "nothing), as ros2_control's controller_manager does; 0: the normal "
                        "scheduler")


def make_executor(node):
    """The executor the node's read-only parameter ``executor`` names (ConfigError otherwise)."""
    name = node.declare_parameter(
        "executor", DEFAULT_EXECUTOR,
        ParameterDescriptor(read_only=True, description=EXECUTOR_DESCRIPTION)).value
    if name not in EXECUTORS:
        raise ConfigError(f"executor: {name!r} is not one of {sorted(EXECUTORS)}")
    return EXECUTORS[name](context=node.context)


def realtime_scheduling(node):
    """For a node in ``timing_mode: realtime``: SCHED_FIFO and its start-up objects frozen.

    The read-only parameter ``realtime_priority`` (default
    :data:`REALTIME_PRIORITY`, 0: off) puts the executor's thread and the
    middleware's on SCHED_FIFO at that priority (:mod:`.scheduling`; a refusal is
    logged as a warning saying how to allow it, and the node runs on as before),
    and ``gc.freeze()`` moves every object made so far (the models, the compiled
    kernels, rclpy) out of the garbage collector's reach, so that its full
    collections, which would walk them all inside a control period, do not.
    Nodes in lockstep (their ``lockstep`` attribute true, or none) are left alone:
    they run flat out, and on SCHED_FIFO they would starve a recorder.
    """
    priority = node.declare_parameter(
        "realtime_priority", REALTIME_PRIORITY,
        ParameterDescriptor(read_only=True, description=REALTIME_DESCRIPTION)).value
    if not (isinstance(priority, int) and 0 <= priority <= 99):
        raise ConfigError(f"realtime_priority: 0 (off) or a SCHED_FIFO priority 1-99, "
                          f"got {priority!r}")
    if getattr(node, "lockstep", True) or priority == 0:
        return
    gc.freeze()
    threads = realtime_threads()
    why_not = fifo_threads(priority, threads)
    if why_not is None:
        node.get_logger().info(f"realtime: the executor's and the middleware's threads "
                               f"({len(threads)}) on SCHED_FIFO priority {priority}")
    else:
        node.get_logger().warning(f"realtime_priority: {why_not}; periods may be missed "
                                  f"when other processes share the cores")


def run_node(make_node, name, args=None, config_errors=(ConfigError,)):
    """Create a node with ``make_node()``, spin it, return the process exit status.

    Returns 2 when ``make_node`` raises one of ``config_errors`` (logged as a
    fatal invalid configuration), 0 when the node is done (its ``finished``
    future, if it has one, completes) or SIGINT/SIGTERM arrives.
    """
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set())
                for sig in (signal.SIGINT, signal.SIGTERM)}
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    executor, node = None, None
    try:
        try:
            node = make_node()
            executor = make_executor(node)
            realtime_scheduling(node)
            # every parameter is declared now: a name given that none of them has is a typo
            refuse_unknown_overrides(node, name)
        except (*config_errors, ConfigError) as exc:
            rclpy.logging.get_logger(name).fatal(f"invalid configuration: {exc}")
            return 2
        finished = getattr(node, "finished", None)
        executor.add_node(node)
        while not stop.is_set() and not (finished is not None and finished.done()):
            executor.spin_once(timeout_sec=SPIN_TIMEOUT)
        if stop.is_set():
            node.get_logger().info("interrupted: stopping")
        flush = getattr(node, "flush_on_exit", None)
        if flush is not None:
            flush()
        return 0
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            # After a stop signal, later ones are ignored up to the process's end: the
            # terminal's SIGINT and the one ``ros2 launch`` forwards come apart, and one that
            # lands after this point would otherwise find Python's own handler, or, once the
            # interpreter finalises (it resets handlers it set to SIG_DFL, not SIG_IGN), none:
            # exit status -2 and launch's "process has died" after a clean stop.
            signal.signal(sig, signal.SIG_IGN if stop.is_set() else handler)
