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

"""What the runner's and the recorder's bookkeeping cost per control period.

What it measures, on the measurements and controller results of one closed-loop
run (default config/iiwa_3points.yaml at 1 kHz, 5 s simulated), replayed
without the plant and the controller, each call timed on its own with
``perf_counter_ns``:

* ``Series.add``: the period's numbers into the run's arrays (as the runner calls it);
* ``McapRecorder.record``: the period into the recorder's buffer, /diagnostics
  when due (once a second), and every 1000 periods the MCAP chunk
  (``flush``: CDR bytes of all messages, records, indexes, the write);
* after the loop: ``write_outputs`` (timeseries.csv and summary.json, no plots),
  reported per period of the run, since it grows with every period.

The medians and p99 of the per-period calls and the totals divided by the
run's periods (what each adds to one period on average).  For before/after
figures run this file with another tree first on ``PYTHONPATH`` (it calls only
functions that tree has, by name).

Usage::

    python benchmarks/bench_bookkeeping.py [--config FILE] [--duration S] [--repeats R]

Prints a markdown table and writes benchmarks/results/bookkeeping_<config name>.json.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np
from benchlib import environment, write_result

import visual_adaptive_servo
from sim_bridge.simulator import Simulator
from visual_adaptive_servo import runner
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.control.controller import AdaptiveVisualTracker
from visual_adaptive_servo.recording.recorder import McapRecorder

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_CONFIG = os.path.join(HERE, os.pardir, "config", "iiwa_3points.yaml")
RESULTS = os.path.join(HERE, "results", "bookkeeping_{name}.json")


def closed_loop(scenario, steps):
    """[(measurement, controller result)] of ``steps`` closed-loop periods."""
    sim = Simulator(scenario.sim)
    ctl = AdaptiveVisualTracker(scenario.controller)
    periods = []
    try:
        for _ in range(steps):
            meas = sim.measure()
            res = ctl.step(meas.t, meas.q, meas.qd, meas.pixels, meas.feature_stamp)
            periods.append((meas, res))
            sim.apply(res.tau)
    finally:
        sim.close()
    return periods


def replay(scenario, periods):
    """ns of each Series.add and McapRecorder.record call, and of write_outputs."""
    clock = time.perf_counter_ns
    model = scenario.controller.model
    series = runner.Series(len(periods), model)
    add_ns, record_ns = [], []
    with tempfile.TemporaryDirectory() as tmp:
        recorder = McapRecorder(os.path.join(tmp, "run.mcap"), scenario.sim.joint_names, model)
        try:
            for k, (meas, res) in enumerate(periods):
                x = meas.pixels if meas.pixels is not None else np.nan
                t0 = clock()
                series.add(t=meas.t, x=x, x_true=meas.true_pixels, x_d=res.x_d,
                           x_obs=res.x_obs, z=meas.true_depth, z_hat=res.z_hat, q=meas.true_q,
                           qd=meas.qd, tau=res.tau, a_z_perp=res.state.a_z_perp,
                           a_z=res.state.a_z, a_d=res.state.a_d)
                series.status.append(res.status)
                t1 = clock()
                recorder.record(meas, res, k % 1000 == 0)
                t2 = clock()
                add_ns.append(t1 - t0)
                record_ns.append(t2 - t1)
            t0 = clock()
            recorder.flush()
            record_ns[-1] += clock() - t0
        finally:
            recorder.close()
        summary = {"outputs": []}
        t0 = clock()
        runner.write_outputs(tmp, series.view(), series.status, model, summary, False, False)
        outputs_ns = clock() - t0
    return np.array(add_ns), np.array(record_ns), outputs_ns


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=DEFAULT_CONFIG)
    parser.add_argument("--duration", type=float, default=5.0, help="simulated seconds")
    parser.add_argument("--repeats", type=int, default=3, help="timed replays")
    parser.add_argument("--out", help="JSON result file")
    args = parser.parse_args(argv)

    scenario = load_scenario(args.config)
    periods = closed_loop(scenario, int(round(args.duration / scenario.sim.control_period)))
    replay(scenario, periods[:500])   # warm-up: imports, compiled kernels
    runs = [replay(scenario, periods) for _ in range(args.repeats)]
    steps = len(periods)

    def figures(ns):
        us = ns / 1e3
        return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
                "mean_us": float(np.mean(us))}

    add = [figures(a) for a, _, _ in runs]
    record = [figures(r) for _, r, _ in runs]
    outputs = [o / 1e3 / steps for _, _, o in runs]
    median = {key: {k: float(np.median([f[k] for f in fs])) for k in fs[0]}
              for key, fs in (("Series.add", add), ("McapRecorder.record", record))}
    result = {
        "config": os.path.relpath(os.path.abspath(args.config), os.path.join(HERE, os.pardir)),
        "tree": os.path.dirname(os.path.dirname(os.path.abspath(visual_adaptive_servo.__file__))),
        "duration_s": args.duration, "repeats": args.repeats, "periods": steps,
        "control_period_s": scenario.sim.control_period, **median,
        "write_outputs_us_per_period": float(np.median(outputs)),
        "total_us_per_period": float(median["Series.add"]["mean_us"]
                                     + median["McapRecorder.record"]["mean_us"]
                                     + np.median(outputs)),
        **environment(),
    }
    print(f"bookkeeping of {result['config']} ({scenario.sim.control_period * 1e3:g} ms "
          f"periods, {steps} periods), tree {result['tree']}, median of {args.repeats} "
          f"replays, load average {result['load_average_1min']:.2f}\n")
    print("| part | median [µs] | p99 [µs] | mean = per period [µs] |")
    print("|---|---:|---:|---:|")
    for key in ("Series.add", "McapRecorder.record"):
        f = result[key]
        print(f"| {key} | {f['median_us']:.2f} | {f['p99_us']:.2f} | {f['mean_us']:.2f} |")
    print(f"| write_outputs (timeseries.csv, summary.json), after the loop | | | "
          f"{result['write_outputs_us_per_period']:.2f} |")
    print(f"| total | | | {result['total_us_per_period']:.2f} |")
    name = os.path.splitext(os.path.basename(args.config))[0]
    write_result(args.out or RESULTS.format(name=name), result)


if __name__ == "__main__":
    main()
