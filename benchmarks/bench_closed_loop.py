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
physics) and the iiwa's (config/iiwa_3points.yaml, 1 ms control period), or the
``--config`` files, without the MCAP recording and without plots -- the PyBullet plant,
the camera model, the controller and the runner's bookkeeping.  Two figures:

* ``loop``: simulated time / wall time of the control loop alone (what
  ``summary.json`` reports as ``realtime_factor``);
* ``call``: simulated time / wall time of the whole ``run_scenario`` call,
  including PyBullet start-up and writing timeseries.csv and summary.json.

Each is the median of ``--repeats`` runs (default 5) after one warm-up run,
per backend of the kinematic tensors (``compiled``, ``numpy``; the runs
alternate).  Against the bare PyBullet plant, measured back to back with each
closed-loop run: the same simulator driven by the torques that run applied,
``measure`` (joint and link state reads, the camera) and ``apply`` (the physics
sub-steps) only; the ratio is the closed loop's wall time per control period
over the plant's (median of the runs' ratios).  A per-part breakdown
(physics sub-steps, measurement, controller) of one control period is
printed from a separate instrumented loop.

Usage::

    python benchmarks/bench_closed_loop.py [--config FILE ...] [--duration S] [--repeats R]
        [--backend both|compiled|numpy]

Prints markdown tables, the ratios of every scenario last, and writes
benchmarks/results/closed_loop_<config name>.json per scenario.
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
from visual_adaptive_servo.models.backend import kernels
from visual_adaptive_servo.runner import run_scenario

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_CONFIGS = [os.path.join(HERE, os.pardir, "config", name)
                   for name in ("paper_3dof.yaml", "iiwa_3points.yaml")]
RESULTS = os.path.join(HERE, "results", "closed_loop_{name}.json")


def time_runs(scenario, duration, repeats, backends):
    """Per backend: loop factors, call factors, ratios to the bare plant, last summary.

    Every closed-loop run is followed by the bare plant driven by its torques.
    """
    model = scenario.controller.model
    out = {b: {"loop": [], "call": [], "ratio": [], "loop_us": [], "plant_us": []}
           for b in backends}
    summary = None
    with tempfile.TemporaryDirectory() as folder:
        for rep in range(repeats + 1):
            for backend in backends:
                model.set_backend(backend)
                t0 = time.perf_counter()
                summary = run_scenario(scenario, folder, duration=duration, progress=False,
                                       record=False, plots=False)
                wall = time.perf_counter() - t0
                plant_us = bare_plant(scenario, applied_torques(folder))
                loop_us = summary["wall_time_s"] / summary["steps"] * 1e6
                if rep > 0:
                    r = out[backend]
                    r["loop"].append(summary["realtime_factor"])
                    r["call"].append(summary["sim_time_s"] / wall)
                    r["loop_us"].append(loop_us)
                    r["plant_us"].append(plant_us)
                    r["ratio"].append(loop_us / plant_us)
    return out, summary


def applied_torques(folder):
    """The torques (steps, n) of the run whose timeseries.csv is in ``folder``."""
    path = os.path.join(folder, "timeseries.csv")
    with open(path, encoding="utf-8") as handle:
        header = handle.readline().strip().split(",")
    columns = [k for k, name in enumerate(header) if name.startswith("tau.")]
    return np.loadtxt(path, delimiter=",", skiprows=1, usecols=columns, ndmin=2)


def bare_plant(scenario, taus):
    """Wall time [us] per control period of the plant alone, driven by ``taus`` (steps, n)."""
    sim = Simulator(scenario.sim)
    try:
        t0 = time.perf_counter()
        for tau in taus:
            sim.measure()
            sim.apply(tau)
        wall = time.perf_counter() - t0
    finally:
        sim.close()
    return wall / len(taus) * 1e6


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
    parser.add_argument("--config", action="append",
                        help="scenario (repeatable; default config/paper_3dof.yaml and "
                        "config/iiwa_3points.yaml, each then written to its own result file)")
    parser.add_argument("--duration", type=float, default=30.0, help="simulated seconds")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per backend")
    parser.add_argument("--backend", choices=("both", "compiled", "numpy"), default="both",
                        help="kinematic tensors backend(s) (default both, alternating)")
    parser.add_argument("--out", help="JSON result file (default: "
                        "results/closed_loop_<config name>.json)")
    args = parser.parse_args(argv)

    backends = ["compiled", "numpy"] if args.backend == "both" else [args.backend]
    if "compiled" in backends and kernels() is None:
        parser.error("--backend compiled needs numba")
    configs = args.config or DEFAULT_CONFIGS
    if args.out and len(configs) > 1:
        parser.error("--out needs a single --config")
    ratios = {}
    for config in configs:
        ratios[config] = bench(config, args, backends)
    print("\nloop / bare plant, per control period (median of the runs; targets of issue 18, "
          "compiled: the iiwa at 1 kHz <= 4x, the paper <= 2.5x):\n")
    print("| scenario | control period | " + " | ".join(backends) + " |")
    print("|---|---:|" + "---:|" * len(backends))
    for config, (period_us, by_backend) in ratios.items():
        print(f"| {os.path.basename(config)} | {period_us:.0f} µs | " + " | ".join(
            f"{by_backend[b]['ratio_to_plant']['median']:.2f}x" for b in backends) + " |")


def bench(config, args, backends):
    """Time one scenario (both backends), print its tables, write its result file."""
    scenario = load_scenario(config)
    runs, summary = time_runs(scenario, args.duration, args.repeats, backends)
    period_us = scenario.sim.control_period * 1e6
    by_backend = {}
    for backend in backends:
        scenario.controller.model.set_backend(backend)
        r = runs[backend]
        by_backend[backend] = {
            **{f"realtime_factor_{key}": {"median": float(np.median(r[key])),
                                          "min": float(np.min(r[key])),
                                          "max": float(np.max(r[key]))}
               for key in ("loop", "call")},
            "loop_us_per_period": float(np.median(r["loop_us"])),
            "plant_us_per_period": float(np.median(r["plant_us"])),
            "ratio_to_plant": {"median": float(np.median(r["ratio"])),
                               "min": float(np.min(r["ratio"])),
                               "max": float(np.max(r["ratio"]))},
            "per_period_us": breakdown(scenario, args.duration)}
    result = {
        "config": os.path.relpath(os.path.abspath(config), os.path.join(HERE, os.pardir)),
        "duration_s": args.duration, "repeats": args.repeats,
        "control_period_us": period_us, "backends": by_backend,
        "final_rms_error_px": summary["final_rms_error_px"], "diverged": summary["diverged"],
        **environment(),
    }
    print(f"\n{os.path.basename(config)}: closed loop, {args.duration:g} s simulated, "
          f"{period_us:.0f} µs control period, "
          f"median of {args.repeats} runs per backend (numpy {np.__version__}, Python "
          f"{platform.python_version()}, load average {result['load_average_1min']:.2f})\n")
    print("| backend | control loop, sim s / wall s | whole call | loop µs / period | "
          "bare plant µs / period | loop / plant (min-max) |")
    print("|---|---:|---:|---:|---:|---:|")
    for backend, r in by_backend.items():
        ratio = r["ratio_to_plant"]
        print(f"| {backend} | {r['realtime_factor_loop']['median']:.1f} | "
              f"{r['realtime_factor_call']['median']:.1f} | {r['loop_us_per_period']:.1f} | "
              f"{r['plant_us_per_period']:.1f} | {ratio['median']:.2f} "
              f"({ratio['min']:.2f}-{ratio['max']:.2f}) |")
    print("\nper control period, median wall time [µs]:\n")
    print("| part | " + " | ".join(backends) + " |")
    print("|---|" + "---:|" * len(backends))
    for name in by_backend[backends[0]]["per_period_us"]:
        print(f"| {name} | " + " | ".join(f"{by_backend[b]['per_period_us'][name]:.1f}"
                                          for b in backends) + " |")
    name = os.path.splitext(os.path.basename(config))[0]
    write_result(args.out or RESULTS.format(name=name), result)
    return period_us, by_backend


if __name__ == "__main__":
    main()
