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

"""Real-time scheduling of a node: its executor and middleware threads on SCHED_FIFO.

What ros2_control's controller_manager does for its update thread, whatever the
kernel (SCHED_FIFO, priority 50; its userdoc, "Determinism"), here also for the
middleware's threads, which carry each message in and out of the process (Cyclone
DDS names them: ``recvUC``, ``tev``, ``dq.user``, ...).  A 1 kHz loop through ROS
on a machine where a recorder and ``ros2 topic hz`` share the cores otherwise
waits behind them (README, "1 kHz through ROS in real time").

Which threads: the main thread (the node's executor) and every thread that has a
name of its own (the middleware's).  Threads that kept the process's name are
left alone: they are pools of the numerical libraries, such as OpenBLAS's, whose
workers spin while they wait for work; on SCHED_FIFO a spinning worker keeps
every thread of its priority off its core (seen here: a controller whose threads
were all pinned to one core stopped answering, SIGTERM included).

Needs the right to real-time priorities (root, ``CAP_SYS_NICE`` or an
``rtprio`` limit: ``/etc/security/limits.conf``, or ``ulimit -r``); without it
nothing changes and the caller is told why.  No rclpy here: tested without ROS.
"""

from __future__ import annotations

import os

TASKS = "/proc/self/task"
#: what to do when the right is missing (part of every refusal's message)
HOW_TO_ALLOW = ("allow real-time priorities for this user (an rtprio limit in "
                "/etc/security/limits.conf, as ros2_control's controller_manager documents, or "
                "CAP_SYS_NICE), or set realtime_priority to 0")


def _name(tasks, tid):
    with open(os.path.join(tasks, str(tid), "comm")) as comm:
        return comm.read().strip()


def realtime_threads(tasks=TASKS):
    """The ids of the main thread and of the threads named otherwise than it, in order."""
    main = os.getpid()
    main_name = _name(tasks, main)
    chosen = []
    for tid in sorted(int(entry) for entry in os.listdir(tasks)):
        try:
            if tid == main or _name(tasks, tid) != main_name:
                chosen.append(tid)
        except FileNotFoundError:           # the thread ended meanwhile
            continue
    return chosen


def fifo_threads(priority, threads):
    """Put the ``threads`` (ids) on SCHED_FIFO at ``priority`` (1-99), all of them or none.

    Threads they start later inherit the policy.  Returns None when done, else
    why not (a sentence ending with what to do); when one thread is refused the
    ones already changed get their previous policy back.  ValueError for a
    priority outside 1-99.
    """
    if not (isinstance(priority, int) and not isinstance(priority, bool)
            and 1 <= priority <= 99):
        raise ValueError(f"realtime_priority: SCHED_FIFO priorities are 1-99, got {priority!r}")
    if not hasattr(os, "sched_setscheduler"):
        return "SCHED_FIFO is not available on this system"
    changed = []
    try:
        for tid in threads:
            try:
                before = (os.sched_getscheduler(tid), os.sched_getparam(tid))
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
            except ProcessLookupError:      # the thread ended meanwhile
                continue
            changed.append((tid, before))
    except OSError as exc:
        for tid, (policy, param) in reversed(changed):
            try:
                os.sched_setscheduler(tid, policy, param)
            except ProcessLookupError:
                pass
        return (f"SCHED_FIFO priority {priority} refused ({exc.strerror or exc}); "
                f"to use it, {HOW_TO_ALLOW}")
    return None
