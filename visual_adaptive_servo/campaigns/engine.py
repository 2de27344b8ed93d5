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

"""Executing many runs at once: long-lived worker processes on this machine, or Ray tasks.

Both engines take resolved runs (:class:`~.spec.Run`) and call
``on_result(RunResult)`` in the calling process as each run ends, in the order
they end.  The run function (default :func:`execute_run`) is injectable.

* A run that raises is recorded ``failed`` with the exception text; it is not
  retried (the same inputs raise again).
* A run whose worker dies (killed, segfault, ``os._exit``) is started once more;
  a second death records it ``failed`` with both reasons
  (``worker died with exit code -9, twice``).  The engine counts the attempts
  itself, with Ray too (tasks are submitted with ``max_retries=0``), so
  ``attempts`` and the reason mean the same with both engines.

:class:`ProcessPool` keeps one pipe per worker, so the parent always knows which
run each worker holds and which run a dead worker took with it (a
``concurrent.futures`` pool declares itself broken instead).  Workers are forked
from a fork server (``multiprocessing`` ``forkserver``) that has imported numpy,
PyBullet and the controllers once: nothing of the parent's state (open files, a
PyBullet connection, threads) is inherited, and the ~0.3-0.5 s of imports is paid
once per campaign, not once per worker or per replacement of a dead one.
"""

from __future__ import annotations

import faulthandler
import logging
import math
import multiprocessing
import os
import signal
import socket
import time
from collections import deque
from dataclasses import dataclass
from multiprocessing.connection import wait

from ..models.resources import PACKAGE_PARENT

FIGURES = ("diverged", "final_rms_error_px", "final_rms_true_error_px", "max_error_px",
           "max_true_error_px", "max_abs_torque", "min_estimated_depth", "rejected", "fallback",
           "frames_dropped", "sim_time_s",
           # vas compare's figures over t >= 5 s (recording.summary.run_figures)
           "transient_rms_true_error_px", "transient_max_true_error_px", "torque_rms",
           "torque_rate_rms")
MAX_ATTEMPTS = 2
#: the key of a run's figures that says why it diverged (not a figure: the row's reason)
DIVERGENCE_REASON = "divergence_reason"
RAY_MISSING = ("--ray needs Ray, an optional extra: pip install 'visual_adaptive_servo[ray]' "
               "(or pip install ray)")


class CampaignError(RuntimeError):
    """The campaign cannot go on (the message says why and what to do)."""


class RunFailed(Exception):
    """The run ended with an error the runner caught (the message is the runner's)."""


@dataclass(frozen=True)
class RunResult:
    """How one run ended: ``status`` is ``finished`` or ``failed``.

    ``reason`` says why it failed, or why a finished run diverged (else it is empty).
    """

    run: object
    status: str
    figures: dict
    reason: str
    attempts: int
    wall_time_s: float


def execute_run(run, keep_dir=None, figures=FIGURES):
    """The default run function: the run, headless; returns its :data:`FIGURES`.

    ``keep_dir``: keep each run's timeseries.csv and summary.json in
    ``keep_dir/<run index>`` (``vas compare`` plots from them); by default nothing is
    written (a worker killed mid-run leaves no scratch folder behind).  ``figures``:
    the summary.json keys to return (``vas tune`` also reads the count of saturated
    samples).  A run that diverged also returns why (``DIVERGENCE_REASON``: what
    crossed its limit and what grew first), which runs.csv keeps in its ``reason``
    column.
    """
    from ..config.scenario import load_scenario
    from ..control.registry import controller_factory
    from ..runner import run_scenario

    scenario = load_scenario(run.base, run.overrides)
    factory = controller_factory(run.controller)
    out = None if keep_dir is None else os.path.join(keep_dir, f"{run.index:05d}")
    summary = run_scenario(scenario, out, duration=run.duration, progress=False,
                           record=False, plots=False, controller_factory=factory)
    if summary.get("error"):
        raise RunFailed(summary["error"])
    out = {key: summary.get(key, math.nan) for key in figures}
    if summary.get("diverged"):
        out[DIVERGENCE_REASON] = summary.get("divergence_reason", "")
    return out


def describe(exc):
    """The text recorded for a run that raised ``exc``."""
    if isinstance(exc, RunFailed):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"


def attempt(run_fn, run):
    """One attempt of ``run``: (``done``, figures, wall s) or (``error``, text, wall s)."""
    start = time.perf_counter()
    try:
        figures = run_fn(run)
    except Exception as exc:  # noqa: BLE001 -- the run's failure is recorded, not raised
        return "error", describe(exc), time.perf_counter() - start
    return "done", figures, time.perf_counter() - start


def death_reason(deaths):
    """``worker died with exit code -9, twice`` (or each death when they differ)."""
    if len(set(deaths)) == 1:
        return deaths[0] + ("" if len(deaths) == 1 else ", twice")
    return "; then ".join(deaths)


class _Attempts:
    """Shared bookkeeping of both engines: finish, fail, or retry after a death."""

    def __init__(self, on_result):
        self.on_result = on_result
        self.deaths = {}

    def count(self, run):
        return len(self.deaths.get(run.index, ())) + 1

    def ended(self, run, kind, payload, wall):
        if kind == "done":
            reason = payload.pop(DIVERGENCE_REASON, "") if isinstance(payload, dict) else ""
            self.on_result(RunResult(run, "finished", payload, reason, self.count(run), wall))
        else:
            self.on_result(RunResult(run, "failed", {}, payload, self.count(run), wall))

    def died(self, run, description):
        """Record a death; True when the run is to be started again."""
        deaths = self.deaths.setdefault(run.index, [])
        deaths.append(description)
        if len(deaths) < MAX_ATTEMPTS:
            return True
        self.on_result(RunResult(run, "failed", {}, death_reason(deaths), len(deaths),
                                 float("nan")))
        return False


def _worker_main(conn, run_fn, log_path, cwd):
    """A pool worker: run what the parent sends until it sends None or goes away."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)    # Ctrl-C is the parent's to handle
    os.chdir(cwd)       # the parent's, not the one it started this worker from
    if log_path is not None:
        # the terminal is the parent's progress bar: PyBullet's banner, a crash's
        # traceback (faulthandler) and log lines go to the log file instead
        log = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        os.dup2(log, 1)
        os.dup2(log, 2)
        os.close(log)
        faulthandler.enable()
    logging.basicConfig(level=logging.WARNING,
                        format=f"worker {os.getpid()} %(levelname)s %(name)s: %(message)s")
    # numpy, PyBullet and the controllers before the first run's clock starts (a no-op
    # when the fork server preloaded them)
    from .. import runner  # noqa: F401
    from ..control import baselines  # noqa: F401
    while True:
        try:
            run = conn.recv()
        except EOFError:
            return
        if run is None:
            return
        conn.send(("start", run.index, os.getpid()))
        conn.send((run.index,) + attempt(run_fn, run))


@dataclass(eq=False)
class _Worker:
    process: multiprocessing.Process
    conn: object
    run: object = None


class ProcessPool:
    """``workers`` long-lived processes on this machine, each pulling one run at a time.

    ``on_start(run, pid)``, if given, is called in the parent when a worker starts
    a run (tests use it to kill that worker).  The workers' stdout and stderr go to
    ``log_path`` when given.
    """

    def __init__(self, workers, run_fn=execute_run, on_start=None, log_path=None):
        if workers < 1:
            raise CampaignError(f"--workers: needs at least 1, got {workers}")
        self.size = workers
        self.run_fn = run_fn
        self.on_start = on_start
        self.log_path = None if log_path is None else os.path.abspath(log_path)
        self.context = multiprocessing.get_context("forkserver")
        # the fork server imports these once; each worker forked from it starts in
        # milliseconds instead of importing numpy, PyBullet and the controllers again
        self.context.set_forkserver_preload(["visual_adaptive_servo.runner",
                                             "visual_adaptive_servo.control.baselines"])
        self.workers = []

    def _spawn(self):
        parent, child = self.context.Pipe()
        cwd = os.getcwd()
        process = self.context.Process(target=_worker_main,
                                       args=(child, self.run_fn, self.log_path, cwd),
                                       daemon=True, name="vas-campaign-worker")
        # the fork server (started by the first start()) has '' -- the working
        # directory -- first on sys.path and (Python 3.11) imports its preload before
        # taking the parent's sys.path: from the folder that holds this package, ''
        # can only find this very package, never another checkout where vas was run
        os.chdir(PACKAGE_PARENT)
        try:
            process.start()
        finally:
            os.chdir(cwd)
        child.close()
        return _Worker(process, parent)

    def run(self, runs, on_result):
        """Execute ``runs``; ``on_result(RunResult)`` as each one ends."""
        queue = deque(runs)
        attempts = _Attempts(on_result)
        self.workers = [self._spawn() for _ in range(min(self.size, len(queue)))]
        while queue or any(w.run is not None for w in self.workers):
            for w in self.workers:
                if w.run is None and queue:
                    w.run = queue.popleft()
                    w.conn.send(w.run)
            waiting = {}
            for w in self.workers:
                if w.run is not None:
                    waiting[w.conn] = w
                    waiting[w.process.sentinel] = w
            for ready in wait(list(waiting)):
                w = waiting[ready]
                if w in self.workers:       # not replaced earlier in this round
                    self._service(w, queue, attempts)

    def _service(self, w, queue, attempts):
        """Read what worker ``w`` sent; if it died, retry or fail its run and replace it."""
        alive = True
        while w.conn.poll():
            try:
                message = w.conn.recv()
            except (EOFError, OSError):
                alive = False
                break
            if message[0] == "start":
                if self.on_start is not None:
                    self.on_start(w.run, message[2])
                continue
            run, w.run = w.run, None
            attempts.ended(run, *message[1:])
        if alive and w.process.is_alive():
            return
        w.process.join()
        w.conn.close()
        if w.run is not None:
            description = f"worker died with exit code {w.process.exitcode}"
            if attempts.died(w.run, description):
                queue.appendleft(w.run)
        index = self.workers.index(w)
        if queue:
            self.workers[index] = self._spawn()
        else:
            del self.workers[index]

    def close(self):
        """Stop every worker: idle ones are told to exit, busy ones are terminated."""
        for w in self.workers:
            if w.run is None and w.process.is_alive():
                try:
                    w.conn.send(None)
                except OSError:
                    pass
            else:
                w.process.terminate()
        for w in self.workers:
            w.process.join(timeout=10)
            if w.process.is_alive():
                w.process.kill()
                w.process.join()
            w.conn.close()
        self.workers = []


def _check_reachable(address, timeout=5.0):
    """Refuse a ``host:port`` nothing listens on (ray.init would wait there for minutes)."""
    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit():
        return      # another form of address: Ray judges it
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as exc:
        raise CampaignError(f"--ray {address}: no Ray cluster answers there ({exc})") from None


class RayCluster:
    """The same runs as Ray tasks: ``address`` ``auto`` starts Ray here, else joins it.

    ``auto`` joins the cluster RAY_ADDRESS names, else starts a new Ray instance on
    this machine (``ray.init(address="local")``); any other address is joined with
    ``ray.init(address=...)``: its nodes must have this package installed (and, with
    Ray's token authentication, the driver RAY_AUTH_MODE=token and the cluster's token).
    At most ``workers`` runs (default: the cluster's CPUs) are in flight, so Ctrl-C
    has little to cancel.
    """

    def __init__(self, address, workers=None, run_fn=execute_run):
        try:
            import ray
        except ImportError:
            raise CampaignError(RAY_MISSING) from None
        self.ray = ray
        if address != "auto":
            _check_reachable(address)
        options = {"include_dashboard": False, "log_to_driver": False}
        if address == "auto":
            # ray.init() with no address would also try the last `ray start` of this
            # machine (/tmp/ray/ray_current_cluster) and wait there if it is gone
            address_to_join = os.environ.get("RAY_ADDRESS") or "local"
        else:
            address_to_join = address
        try:
            ray.init(address=address_to_join, **options)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            hint = ("" if address == "auto" else " (a cluster with token authentication, the "
                    "default from Ray 2.59 on, also needs RAY_AUTH_MODE=token and its token "
                    "in this environment)")
            raise CampaignError(f"--ray {address}: cannot start or join Ray: {exc}{hint}") \
                from None
        self.size = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        self.run_fn = run_fn
        # retries are counted by _Attempts, so Ray's own (3 by default) are off
        self.task = ray.remote(max_retries=0)(attempt)
        self.pending = {}

    def run(self, runs, on_result):
        """Execute ``runs``; ``on_result(RunResult)`` as each one ends."""
        ray = self.ray
        queue = deque(runs)
        attempts = _Attempts(on_result)
        while queue or self.pending:
            while queue and len(self.pending) < self.size:
                run = queue.popleft()
                self.pending[self.task.remote(self.run_fn, run)] = run
            ready, _ = ray.wait(list(self.pending), num_returns=1)
            for ref in ready:
                run = self.pending.pop(ref)
                try:
                    kind, payload, wall = ray.get(ref)
                except ray.exceptions.RayTaskError as exc:
                    # raised outside the run function (e.g. this package missing on a node)
                    attempts.ended(run, "error", str(exc).strip().splitlines()[-1],
                                   float("nan"))
                    continue
                except ray.exceptions.RayError as exc:
                    # WorkerCrashedError (the worker process died) and its kin: a death
                    if attempts.died(run, f"worker died ({type(exc).__name__})"):
                        queue.appendleft(run)
                    continue
                attempts.ended(run, kind, payload, wall)

    def close(self):
        """Cancel what is in flight and disconnect (stopping Ray if it was started here)."""
        for ref in self.pending:
            self.ray.cancel(ref, force=True)
        self.pending = {}
        self.ray.shutdown()
