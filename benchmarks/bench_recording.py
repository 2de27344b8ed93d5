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

"""What the MCAP recording costs ``vas run``, as a share of the run's time.

What it measures: the reference run ``vas run --config config/paper_3dof.yaml
--out DIR`` (30 s simulated, plots on: the command of issue 11), each in a
fresh process as a user runs it, with and without ``--no-bag``, alternating,
``--repeats`` pairs.  The recording's cost is the median over the pairs of
(with - without) / without, of the wall time and of the child's CPU time
(user + system: other processes on a shared machine move it less).

Where the time goes: one run in this process (after a warm-up run) with each
part of the recorder timed (exclusive of the parts it calls), and, in a fresh
process, importing ``rosbags.typesys``, which only a recording run pays.

Usage::

    python benchmarks/bench_recording.py [--config FILE] [--duration S] [--repeats R]
                                         [--python OTHER_VENV/bin/python]

Prints markdown tables and writes benchmarks/results/recording.json.
"""

from __future__ import annotations

import argparse
import functools
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections import Counter

import numpy as np
from benchlib import environment, write_result

from visual_adaptive_servo.recording import messages, recorder as recording
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.runner import run_scenario

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_CONFIG = os.path.join(HERE, os.pardir, "config", "paper_3dof.yaml")
RESULTS = os.path.join(HERE, "results", "recording.json")

# (owner, attribute, label) of the recorder's parts, timed by ExclusiveTimers
PARTS = [
    (recording.McapRecorder, "__init__", "create: type store, file, schemas and channels"),
    (recording.McapRecorder, "_probe", "probe the CDR layouts (type store compiles serialisers)"),
    (recording.McapRecorder, "record", "record(): rest (/diagnostics when due)"),
    (recording.McapRecorder, "_store", "copy each period's numbers into the buffer"),
    (recording.McapRecorder, "flush", "flush: rest"),
    (recording.McapRecorder, "_chunk", "message records: heads, order, /diagnostics, index"),
    (messages.CdrLayout, "serialize", "CDR of every message from its layout"),
    (recording.McapFile, "write_chunk", "write chunks and message indexes"),
    (recording.McapRecorder, "close", "close"),
    (recording.McapFile, "close", "metadata, summary and footer"),
]

# what a recording run imports that a run without it does not (paid once per process)
IMPORT_TYPESYS = ("import time\n"
                  "import visual_adaptive_servo.runner\n"
                  "t0 = time.perf_counter()\n"
                  "import rosbags.typesys\n"
                  "print(time.perf_counter() - t0)\n")


def cli_run(python, config, out, duration, record):
    """(wall s, CPU s) of ``vas run`` in a fresh ``python`` process."""
    args = [python, "-m", "visual_adaptive_servo.cli", "run", "--config", config,
            "--out", out, "--duration", str(duration), "--no-progress"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    # run from the output folder: the current directory would shadow ``python``'s package
    subprocess.run(args + ([] if record else ["--no-bag"]), check=True,
                   cwd=os.path.dirname(out), stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def alternate(python, config, duration, repeats):
    """{"with"/"without": [(wall, cpu)]} of ``repeats`` pairs, without first in odd pairs."""
    runs = {"with": [], "without": []}
    with tempfile.TemporaryDirectory() as tmp:
        for rep in range(repeats):
            order = ("without", "with") if rep % 2 == 0 else ("with", "without")
            for name in order:
                out = os.path.join(tmp, f"{name}{rep}")
                runs[name].append(cli_run(python, config, out, duration, name == "with"))
                print(f"pair {rep + 1}: {name:7s} {runs[name][-1][0]:.2f} s wall, "
                      f"{runs[name][-1][1]:.2f} s CPU", file=sys.stderr)
    return runs


class ExclusiveTimers:
    """Wall time of each wrapped function minus the wrapped functions it calls."""

    def __init__(self, parts):
        self.total, self.calls, self._open, self._saved = Counter(), Counter(), [], []
        for owner, name, label in parts:
            self._saved.append((owner, name, getattr(owner, name)))
            setattr(owner, name, self._timed(getattr(owner, name), label))

    def _timed(self, inner, label):
        @functools.wraps(inner)
        def timed(*args, **kwargs):
            self._open.append(0.0)
            t0 = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                elapsed = time.perf_counter() - t0
                self.total[label] += elapsed - self._open.pop()
                self.calls[label] += 1
                if self._open:
                    self._open[-1] += elapsed
        return timed

    def restore(self):
        for owner, name, inner in self._saved:
            setattr(owner, name, inner)


def breakdown(scenario, duration):
    """({part: (ms, calls)}, headless run wall s) of one recorded run in this process."""
    with tempfile.TemporaryDirectory() as tmp:
        run_scenario(scenario, os.path.join(tmp, "warm"), duration=duration, progress=False,
                     plots=False)
        t0 = time.perf_counter()
        run_scenario(scenario, os.path.join(tmp, "bare"), duration=duration, progress=False,
                     record=False, plots=False)
        bare = time.perf_counter() - t0
        timers = ExclusiveTimers(PARTS)
        try:
            run_scenario(scenario, os.path.join(tmp, "timed"), duration=duration,
                         progress=False, plots=False)
        finally:
            timers.restore()
    imported = float(subprocess.run([sys.executable, "-c", IMPORT_TYPESYS], check=True,
                                    capture_output=True, text=True).stdout)
    parts = {"import rosbags.typesys (fresh process)": (imported * 1e3, 1)}
    parts.update({label: (timers.total[label] * 1e3, timers.calls[label])
                  for _, _, label in PARTS})
    return parts, bare


def stats(values):
    return {"median": float(np.median(values)), "min": float(np.min(values)),
            "max": float(np.max(values))}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=DEFAULT_CONFIG)
    parser.add_argument("--duration", type=float, default=30.0, help="simulated seconds")
    parser.add_argument("--repeats", type=int, default=5, help="pairs of runs")
    parser.add_argument("--out", default=RESULTS, help="JSON result file")
    parser.add_argument("--python", default=sys.executable,
                        help="interpreter whose vas the pairs run, e.g. of a virtual environment "
                        "with an older commit installed, for before/after figures")
    args = parser.parse_args(argv)

    load_before = os.getloadavg()[0]
    runs = alternate(args.python, os.path.abspath(args.config), args.duration, args.repeats)
    wall = {name: np.array([w for w, _ in r]) for name, r in runs.items()}
    cpu = {name: np.array([c for _, c in r]) for name, r in runs.items()}
    parts, bare = breakdown(load_scenario(args.config), args.duration)
    recorder_ms = sum(ms for ms, _ in parts.values())
    result = {
        "config": os.path.relpath(os.path.abspath(args.config), os.path.join(HERE, os.pardir)),
        "duration_s": args.duration, "repeats": args.repeats, "python_of_pairs": args.python,
        "cost_ratio_wall": stats((wall["with"] - wall["without"]) / wall["without"]),
        "cost_ratio_cpu": stats((cpu["with"] - cpu["without"]) / cpu["without"]),
        "wall_s": {name: stats(w) for name, w in wall.items()},
        "cpu_s": {name: stats(c) for name, c in cpu.items()},
        "recorder_parts_ms": {label: ms for label, (ms, _) in parts.items()},
        "recorder_total_ms": recorder_ms,
        "headless_run_without_recording_s": bare,
        "load_average_1min_before": load_before,
        **environment(),
    }
    print(f"vas run, {args.duration:g} s simulated, {args.repeats} pairs "
          f"(load average {load_before:.1f} before, {result['load_average_1min']:.1f} after)\n")
    print("| | without bag | with bag | recording cost (median of pairs) | min | max |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, key, ratio in (("wall", "wall_s", "cost_ratio_wall"),
                             ("CPU", "cpu_s", "cost_ratio_cpu")):
        r = result[ratio]
        print(f"| {name} | {result[key]['without']['median']:.2f} s | "
              f"{result[key]['with']['median']:.2f} s | {r['median']:+.1%} | {r['min']:+.1%} | "
              f"{r['max']:+.1%} |")
    print(f"\nwhere the recording's time goes (one run; the headless run without it took "
          f"{bare:.2f} s here):\n")
    print("| part | calls | ms |")
    print("|---|---:|---:|")
    for label, (ms, calls) in parts.items():
        print(f"| {label} | {calls} | {ms:.1f} |")
    print(f"| total | | {recorder_ms:.1f} |")
    write_result(args.out, result)


if __name__ == "__main__":
    main()
