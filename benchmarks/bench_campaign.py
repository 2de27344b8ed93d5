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

"""Campaign throughput: the same 8-run campaign with 1 and with 2 worker processes.

What it measures: :func:`visual_adaptive_servo.campaigns.campaign.run_campaign` on eight
runs of the reference scenario (config/paper_3dof.yaml, 2 s blend, the feature
started 0 to 35 px off the trajectory start, ``--duration`` simulated seconds
each, 30 by default), into a fresh folder each time.  Two figures per worker
count, each the median over ``--repeats`` alternating repetitions:

* ``runs phase``: runs per wall second from the first worker's start to the last
  row written (worker start-up included, report excluded);
* ``whole call``: runs per wall second of the whole call (spec resolution,
  worker start-up, runs, summary and plots).

The goal is a runs-phase ratio 2 workers / 1 worker >= 1.7 on 2 cores.  Other
processes on the machine take their share, so two load-independent figures are
recorded with it:

* ``cpu share``: CPU seconds the workers spent in runs / runs-phase wall seconds,
  the cores the campaign actually got (at most 1 with one worker, 2 with two);
* ``CPU s per run``: the same per run, which stays put when the runs of two
  workers do not slow each other down;
* ``busy``: the summed wall time of the runs inside the workers / (workers x
  runs-phase wall time), the fraction of the phase the workers spent in runs
  (the rest is worker start-up and the parent's bookkeeping).

And the machine's own ceiling, measured in the same repetitions: the same eight
runs in one bare process (``execute_run`` in a loop) against two bare processes
with four runs each, started together (``bare ratio``).  On a VM whose two
vCPUs slow each other down (here: CPU seconds per run rise 15-30 % when two
run at once) no engine can beat that ratio; ``engine / bare`` is what the
campaign engine itself keeps of it.

Usage::

    python benchmarks/bench_campaign.py [--duration S] [--repeats R]

Prints a markdown table and writes benchmarks/results/campaign.json.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

from benchlib import environment, write_result

from visual_adaptive_servo.campaigns.campaign import run_campaign
from visual_adaptive_servo.campaigns.engine import execute_run

HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = os.path.join(HERE, "results", "campaign.json")
SPEC = """\
base: paper_3dof.yaml
duration: {duration}
fixed:
  set.controller_node.start_blend_time: 2.0
grid:
  start_offset_px: [0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0]
"""


def timed_run(run):
    """:func:`execute_run` plus the CPU seconds the worker spent on it (``cpu_s``)."""
    start = time.process_time()
    figures = execute_run(run)
    return {**figures, "cpu_s": time.process_time() - start}


def time_campaign(spec, folder, workers):
    """One campaign into ``folder``: runs/s (runs phase, whole call), cpu share, busy."""
    cpu, in_runs = [], []

    def collect(result):
        cpu.append(result.figures["cpu_s"])
        in_runs.append(result.wall_time_s)

    start = time.perf_counter()
    summary = run_campaign(spec, folder, workers=workers, progress=False, run_fn=timed_run,
                           on_row=collect)
    whole = time.perf_counter() - start
    if summary["finished"] != summary["runs_in_spec"]:
        raise RuntimeError(f"{folder}: not every run finished: {summary['failed_runs']}")
    phase = summary["wall_time_s"]
    return {"runs": summary["rows"] / phase, "whole": summary["rows"] / whole,
            "cpu_share": sum(cpu) / phase, "busy": sum(in_runs) / (workers * phase),
            "cpu_per_run": sum(cpu) / len(cpu)}


BARE = """\
import sys
from visual_adaptive_servo.campaigns.engine import execute_run
from visual_adaptive_servo.campaigns.spec import load_spec
runs = load_spec(sys.argv[1]).runs()
for run in runs[int(sys.argv[2])::int(sys.argv[3])]:
    execute_run(run)
"""


def time_bare(spec, processes):
    """Runs per wall second of the spec's runs split over ``processes`` bare processes."""
    start = time.perf_counter()
    children = [subprocess.Popen([sys.executable, "-c", BARE, spec, str(i), str(processes)],
                                 stderr=subprocess.DEVNULL) for i in range(processes)]
    if any(child.wait() for child in children):
        raise RuntimeError("a bare process failed")
    return 8 / (time.perf_counter() - start)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=30.0,
                        help="simulated seconds per run")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    keys = ("runs", "whole", "cpu_share", "busy", "cpu_per_run", "bare")
    figures = {w: {k: [] for k in keys} for w in (1, 2)}
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        spec = os.path.join(tmp, "bench.yaml")
        with open(spec, "w", encoding="utf-8") as handle:
            handle.write(SPEC.format(duration=args.duration))
        for rep in range(args.repeats):
            for workers in (1, 2):
                got = time_campaign(spec, os.path.join(tmp, f"{workers}-{rep}"), workers)
                got["bare"] = time_bare(spec, workers)
                for key in keys:
                    figures[workers][key].append(got[key])
                print(f"repeat {rep + 1}, {workers} worker(s): {got['runs']:.3f} runs/s "
                      f"(runs phase), {got['whole']:.3f} runs/s (whole call), cpu share "
                      f"{got['cpu_share']:.2f}, busy {got['busy']:.2f}, CPU s per run "
                      f"{got['cpu_per_run']:.2f}; {workers} bare process(es) "
                      f"{got['bare']:.3f} runs/s; load {os.getloadavg()[0]:.1f}")
    median = {w: {k: statistics.median(v) for k, v in f.items()} for w, f in figures.items()}
    ratio = {k: median[2][k] / median[1][k] for k in ("runs", "whole", "bare")}
    per_repeat = [figures[2]["runs"][r] / figures[1]["runs"][r] for r in range(args.repeats)]
    bare_per_repeat = [figures[2]["bare"][r] / figures[1]["bare"][r]
                       for r in range(args.repeats)]
    print(f"\n8 runs of {args.duration:g} s simulated, median of {args.repeats}\n")
    print("| workers | runs/s, runs phase | runs/s, whole call | cpu share [cores] | busy "
          "| CPU s per run | bare processes, runs/s |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for workers in (1, 2):
        m = median[workers]
        print(f"| {workers} | {m['runs']:.3f} | {m['whole']:.3f} | {m['cpu_share']:.2f} "
              f"| {m['busy']:.2f} | {m['cpu_per_run']:.2f} | {m['bare']:.3f} |")
    print(f"| ratio 2/1 | {ratio['runs']:.2f} (goal >= 1.7) | {ratio['whole']:.2f} | | | "
          f"| {ratio['bare']:.2f} |")
    print(f"\nratio 2/1 per repeat, runs phase: {', '.join(f'{r:.2f}' for r in per_repeat)}; "
          f"bare processes: {', '.join(f'{r:.2f}' for r in bare_per_repeat)}; engine / bare "
          f"(medians): {ratio['runs'] / ratio['bare']:.2f}")
    write_result(RESULTS, {
        "benchmark": "campaign throughput, 8 runs, 1 vs 2 worker processes",
        "runs": 8, "duration_s": args.duration, "repeats": args.repeats,
        "per_repeat": {str(w): figures[w] for w in figures},
        "median": {str(w): median[w] for w in median},
        "ratio_2_over_1": ratio, "goal_ratio_runs_phase": 1.7,
        "ratio_2_over_1_per_repeat": per_repeat, "bare_ratio_per_repeat": bare_per_repeat,
        "engine_over_bare": ratio["runs"] / ratio["bare"],
        "load_average_1min_before": load_before,
        **environment(),
    })


if __name__ == "__main__":
    main()
