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

"""Latency of one controller sample on a realistic closed-loop trajectory.

What it measures: the wall time of one full :meth:`AdaptiveVisualTracker.step`
(input validation, Euler update, projection, the control law, saturation) and
of the bare :func:`control_law`, for the paper's RRR arm (n = 3, m = 1).

How: the reference scenario (config/paper_3dof.yaml) is simulated once in
closed loop and its measurements (t, q, q_dot, x) are stored.  A fresh tracker
then replays them; because the controller is deterministic it goes through
exactly the states of the closed loop.  The first replay is a warm-up and is
not timed; every sample of the following replays is timed on its own with
``time.perf_counter_ns``.  ``control_law`` is timed on the (state, inputs)
pairs the tracker saw.  The garbage collector stays enabled: its pauses are
part of what a real control loop sees in p99.

Usage::

    python benchmarks/bench_controller.py [--config FILE] [--steps N] [--repeats R]

Prints a markdown table and writes benchmarks/results/controller_step.json.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np
from benchlib import environment, write_result

from sim_bridge.simulator import Simulator
from visual_adaptive_servo.config import load_scenario
from visual_adaptive_servo.controller import AdaptiveVisualTracker, control_law

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_CONFIG = os.path.join(HERE, os.pardir, "config", "paper_3dof.yaml")
RESULTS = os.path.join(HERE, "results", "controller_step.json")


def record_measurements(scenario, steps):
    """Closed-loop run of ``steps`` samples; returns the list of (t, q, qd, x)."""
    sim = Simulator(scenario.sim)
    ctl = AdaptiveVisualTracker(scenario.controller)
    samples = []
    try:
        for _ in range(steps):
            meas = sim.measure()
            samples.append((meas.t, meas.q, meas.qd, meas.pixels))
            sim.apply(ctl.step(meas.t, meas.q, meas.qd, meas.pixels).tau)
    finally:
        sim.close()
    return samples


def time_steps(scenario, samples, repeats):
    """Per-sample ns of ``step`` over ``repeats`` timed replays after one warm-up replay."""
    clock = time.perf_counter_ns
    timings = []
    law_inputs = []
    for rep in range(repeats + 1):
        ctl = AdaptiveVisualTracker(scenario.controller)
        for t, q, qd, x in samples:
            t0 = clock()
            res = ctl.step(t, q, qd, x)
            t1 = clock()
            if rep > 0:
                timings.append(t1 - t0)
            elif res.status == "ok":
                law_inputs.append((res.state, q, qd, x, ctl.desired(t)))
    return np.array(timings), law_inputs


def time_law(ctl, law_inputs, repeats):
    """Per-call ns of ``control_law`` on recorded (state, inputs), after one warm-up pass."""
    clock = time.perf_counter_ns
    model, gains, proj = ctl.model, ctl.gains, ctl.projection
    msv = ctl.config.min_singular_value
    timings = []
    for rep in range(repeats + 1):
        for state, q, qd, x, (xd, xd_dot, xd_ddot) in law_inputs:
            t0 = clock()
            control_law(model, gains, state, q, qd, x, xd, xd_dot, xd_ddot, proj, msv)
            t1 = clock()
            if rep > 0:
                timings.append(t1 - t0)
    return np.array(timings)


def stats(ns):
    us = ns / 1e3
    return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
            "mean_us": float(np.mean(us)), "min_us": float(np.min(us)), "samples": int(us.size)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=DEFAULT_CONFIG)
    parser.add_argument("--steps", type=int, default=4000, help="closed-loop samples (5 ms)")
    parser.add_argument("--repeats", type=int, default=3, help="timed replays")
    parser.add_argument("--out", default=RESULTS, help="JSON result file")
    args = parser.parse_args(argv)

    scenario = load_scenario(args.config)
    samples = record_measurements(scenario, args.steps)
    step_ns, law_inputs = time_steps(scenario, samples, args.repeats)
    law_ns = time_law(AdaptiveVisualTracker(scenario.controller), law_inputs, args.repeats)
    model = scenario.controller.model
    result = {
        "config": os.path.relpath(os.path.abspath(args.config), os.path.join(HERE, os.pardir)),
        "n": model.n, "m": model.m, "steps": args.steps, "repeats": args.repeats,
        "step": stats(step_ns), "control_law": stats(law_ns),
        **environment(),
    }
    print(f"controller latency, n={model.n}, m={model.m}, {args.steps} samples x "
          f"{args.repeats} replays (numpy {np.__version__}, Python {platform.python_version()})\n")
    print("| call | median [µs] | p99 [µs] | mean [µs] | min [µs] |")
    print("|---|---:|---:|---:|---:|")
    for name, key in (("AdaptiveVisualTracker.step", "step"), ("control_law", "control_law")):
        s = result[key]
        print(f"| `{name}` | {s['median_us']:.1f} | {s['p99_us']:.1f} | {s['mean_us']:.1f} | "
              f"{s['min_us']:.1f} |")
    write_result(args.out, result)


if __name__ == "__main__":
    main()
