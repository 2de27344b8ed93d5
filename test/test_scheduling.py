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

"""Real-time scheduling of a node's threads (ros/scheduling.py), without ROS.

Each case runs in a child process, so that this one keeps its scheduler: the
child starts a thread that names itself (as the middleware's do) and one that
does not (as a numerical library's pool), asks for SCHED_FIFO and prints what
the kernel then reports for each thread.  Where this user may not use real-time
priorities, the refusal and its message are what is checked.
"""

import json
import os
import subprocess
import sys
import textwrap

import pytest

from visual_adaptive_servo.ros import scheduling

pytestmark = pytest.mark.skipif(not hasattr(os, "sched_setscheduler"),
                                reason="SCHED_FIFO is Linux's")

CHILD = textwrap.dedent("""
    import json, os, sys, threading
    from visual_adaptive_servo.ros import scheduling

    ready, done = threading.Barrier(3), threading.Event()
    ids = {{}}

    def worker(name):
        tid = threading.get_native_id()
        if name:
            with open(f"/proc/self/task/{{tid}}/comm", "w") as comm:
                comm.write(name)
        ids[name or "unnamed"] = tid
        ready.wait()
        done.wait()

    threads = [threading.Thread(target=worker, args=(name,)) for name in ("recvUC", "")]
    for thread in threads:
        thread.start()
    ready.wait()
    ids["main"] = os.getpid()
    {action}
    policies = {{name: os.sched_getscheduler(tid) for name, tid in ids.items()}}
    done.set()
    print(json.dumps({{"ids": ids, "chosen": chosen, "why_not": why_not,
                      "policies": policies}}))
""")


def run_child(action):
    out = subprocess.run([sys.executable, "-c", CHILD.format(action=action)],
                         capture_output=True, text=True, timeout=60, check=True)
    return json.loads(out.stdout)


def test_the_main_thread_and_the_named_threads_go_on_fifo_the_pools_do_not():
    result = run_child("chosen = scheduling.realtime_threads(); "
                       "why_not = scheduling.fifo_threads(50, chosen)")
    ids = result["ids"]
    assert sorted(result["chosen"]) == sorted([ids["main"], ids["recvUC"]])
    policies = result["policies"]
    assert policies["unnamed"] == os.SCHED_OTHER
    if result["why_not"] is not None:
        assert "refused" in result["why_not"] and "rtprio" in result["why_not"]
        assert policies["main"] == policies["recvUC"] == os.SCHED_OTHER
    else:
        assert policies["main"] == policies["recvUC"] == os.SCHED_FIFO


def test_a_refused_thread_leaves_every_thread_as_it_was():
    """The second thread refused: the first one, already changed, gets its policy back."""
    result = run_child(textwrap.dedent("""
        real = os.sched_setscheduler
        calls = []
        def refuse_the_second(tid, policy, param):
            calls.append(tid)
            if len(calls) == 2:
                raise PermissionError(1, "Operation not permitted")
            return real(tid, policy, param)
        os.sched_setscheduler = refuse_the_second
        chosen = scheduling.realtime_threads()
        why_not = scheduling.fifo_threads(50, chosen)
        os.sched_setscheduler = real
    """))
    assert result["why_not"].startswith("SCHED_FIFO priority 50 refused (Operation not permitted)")
    assert result["why_not"].endswith("or set realtime_priority to 0")
    assert set(result["policies"].values()) == {os.SCHED_OTHER}


@pytest.mark.parametrize("priority", [0, 100, 50.0, True])
def test_a_priority_outside_1_to_99_is_refused_by_name(priority):
    with pytest.raises(ValueError, match="realtime_priority: SCHED_FIFO priorities are 1-99"):
        scheduling.fifo_threads(priority, [os.getpid()])
