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

"""Closed-loop throughput: simulated seconds per wall-clock second, headless.

What it measures: :func:`visual_adaptive_servo.runner.run_scenario` on the
reference scenario (config/paper_3dof.yaml, 30 s, 5 ms control period, 1 ms
physics) without the MCAP recording and without plots -- the PyBullet plant,
the camera model, the controller and the runner's bookkeeping.  Two figures:

* ``loop``: simulated time / wall time of the control loop alone (what
  ``summary.json`` reports as ``realtime_factor``);
* ``call``: simulated time / wall time of the whole ``run_scenario`` call,
  including PyBullet start-up and writing timeseries.csv and summary.json.

Each is the median of ``--repeats`` runs (default 5) after one warm-up run.
A per-part breakdown (physics sub-steps, measurement, controller, runner rest)
of one control period is printed from a separate instrumented loop.

Usage::

    python benchmarks/bench_closed_loop.py [--config FILE] [--duration S] [--repeats R]

Prints a markdown table and writes benchmarks/results/closed_loop_<config name>.json.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time

import numpy as np
from benchlib import environment, write_result

from sim_bridge.simulator import Simulator
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.control.controller import AdaptiveVisualTracker
from visual_adaptive_servo.runner import run_scenario

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_CONFIG = os.path.join(HERE, os.pardir, "config", "paper_3dof.yaml")
RESULTS = os.path.join(HERE, "results", "closed_loop_{name}.json")


def time_runs(scenario, duration, repeats):
    """(loop factors, call factors, last summary) over ``repeats`` runs after a warm-up."""
    loop, call, summary = [], [], None
    with tempfile.TemporaryDirectory() as out:
        for rep in range(repeats + 1):
            t0 = time.perf_counter()
            summary = run_scenario(scenario, out, duration=duration, progress=False,
                                   record=False, plots=False)
            wall = time.perf_counter() - t0
            if rep > 0:
                loop.append(summary["realtime_factor"])
                call.append(summary["sim_time_s"] / wall)
    return loop, call, summary


def breakdown(scenario, duration):
    """Median wall time [us] per control period of each part of the loop."""
    clock = time.perf_counter_ns
    sim = Simulator(scenario.sim)
    ctl = AdaptiveVisualTracker(scenario.controller)
    parts = {"measure": [], "controller step": [], "apply (physics sub-steps)": []}
    try:
        for _ in range(int(round(duration / scenario.sim.control_period))):
            t0 = clock()
            meas = sim.measure()
            t1 = clock()
            res = ctl.step(meas.t, meas.q, meas.qd, meas.pixels)
            t2 = clock()
            sim.apply(res.tau)
            t3 = clock()
            parts["measure"].append(t1 - t0)
            parts["controller step"].append(t2 - t1)
            parts["apply (physics sub-steps)"].append(t3 - t2)
    finally:
        sim.close()
    return {name: float(np.median(ns)) / 1e3 for name, ns in parts.items()}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=DEFAULT_CONFIG)
    parser.add_argument("--duration", type=float, default=30.0, help="simulated seconds")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs")
    parser.add_argument("--out", help="JSON result file (default: "
                        "results/closed_loop_<config name>.json)")
    args = parser.parse_args(argv)

    scenario = load_scenario(args.config)
    loop, call, summary = time_runs(scenario, args.duration, args.repeats)
    parts = breakdown(scenario, args.duration)
    period_us = scenario.sim.control_period * 1e6
    result = {
        "config": os.path.relpath(os.path.abspath(args.config), os.path.join(HERE, os.pardir)),
        "duration_s": args.duration, "repeats": args.repeats,
        "realtime_factor_loop": {"median": float(np.median(loop)), "min": float(np.min(loop)),
                                 "max": float(np.max(loop))},
        "realtime_factor_call": {"median": float(np.median(call)), "min": float(np.min(call)),
                                 "max": float(np.max(call))},
        "per_period_us": parts,
        "final_rms_error_px": summary["final_rms_error_px"], "diverged": summary["diverged"],
        **environment(),
    }
    print(f"closed loop, {args.duration:g} s simulated, median of {args.repeats} runs "
          f"(numpy {np.__version__}, Python {platform.python_version()})\n")
    print("| measure | simulated s / wall s (median) | min | max |")
    print("|---|---:|---:|---:|")
    for name, key in (("control loop", "realtime_factor_loop"),
                      ("whole run_scenario call", "realtime_factor_call")):
        r = result[key]
        print(f"| {name} | {r['median']:.1f} | {r['min']:.1f} | {r['max']:.1f} |")
    print(f"\nper control period ({period_us:.0f} µs simulated), median wall time:\n")
    print("| part | µs |")
    print("|---|---:|")
    for name, us in parts.items():
        print(f"| {name} | {us:.1f} |")
    print(f"| sum | {sum(parts.values()):.1f} |")
    name = os.path.splitext(os.path.basename(args.config))[0]
    write_result(args.out or RESULTS.format(name=name), result)


if __name__ == "__main__":
    main()
