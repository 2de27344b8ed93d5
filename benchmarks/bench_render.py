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

"""The rendered camera's cost: each part of one picture, and the closed loop's speed.

What it measures, on a rendered scenario (default config/iiwa_apriltag.yaml):

* per picture, the arm moved along a path of ``--frames`` poses around its start
  (0.05 rad per joint, the tag 5-20 px a frame), each part timed on its own with
  ``time.perf_counter`` and the median reported: the TinyRenderer's whole 640 x 480
  picture of the arm's client, the whole scene (that and the depth composite over
  the surroundings), the scene in the tag window (``render.tag_window``, the links
  outside it left out), the detector (window search, edge fit), and the whole
  ``PictureMaker.picture`` (noise and gamma included) with ``whole_every`` 1 (every
  picture whole) and the file's value (or ``--whole-every``);
* the closed loop: :func:`run_scenario` for ``--duration`` simulated seconds, without
  recording and plots, for ``whole_every`` 1 and the file's value: simulated seconds
  per wall second (the summary's ``realtime_factor``) and per CPU second of the
  process (less sensitive to the other jobs on a shared machine), with the load
  average before and after each run.

Usage::

    python benchmarks/bench_render.py [--config FILE] [--frames N] [--duration S]
        [--whole-every N]

Prints markdown tables and writes benchmarks/results/render_<config name>.json.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np
from benchlib import environment, write_result

from sim_bridge import render
from sim_bridge.simulator import Simulator
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.runner import run_scenario

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_CONFIG = os.path.join(HERE, os.pardir, "config", "iiwa_apriltag.yaml")


def _poses(q0, frames):
    """A smooth path of joint positions (frames, n) around q0: 0.05 rad per joint."""
    phase = np.linspace(0.0, 2.0 * np.pi, frames)[:, None]
    return q0 + 0.05 * np.sin(phase + np.arange(len(q0))[None, :])


def _median_ms(times):
    return float(1e3 * np.median(times)) if times else float("nan")


def picture_parts(config, frames, every):
    """Median milliseconds of each part of one picture along the path."""
    scenario = load_scenario(config, [f"sim_node.picture.whole_every={every}"])
    sim = Simulator(scenario.sim)
    parts = {k: [] for k in ("whole arm render", "whole scene (render, composite)",
                             "window scene (render without the links outside, composite)",
                             "detection (window search, edge fit)")}
    window_pixels = []
    try:
        maker, detector = sim.pictures, scenario.detector.detector()
        for q in _poses(np.asarray(scenario.sim.initial_positions, float), frames):
            sim.plant.reset(q)
            sim._show_markers()
            t0 = time.perf_counter()
            maker._render(maker.client)
            t1 = time.perf_counter()
            maker._scene()
            t2 = time.perf_counter()
            parts["whole arm render"].append(t1 - t0)
            parts["whole scene (render, composite)"].append(t2 - t1)
            window = render.tag_window(sim._plate_outline(), sim.camera.width,
                                       sim.camera.height)
            if window is not None:
                t0 = time.perf_counter()
                maker._scene(window)
                parts["window scene (render without the links outside, composite)"].append(
                    time.perf_counter() - t0)
                window_pixels.append((window[2] - window[0]) * (window[3] - window[1]))
            picture = maker.picture()
            t0 = time.perf_counter()
            detector.detect(picture)
            parts["detection (window search, edge fit)"].append(time.perf_counter() - t0)
    finally:
        sim.close()
    result = {name: _median_ms(times) for name, times in parts.items()}
    result["window pixels (median)"] = float(np.median(window_pixels)) if window_pixels \
        else float("nan")
    return result


def pictures(config, frames, every):
    """Median milliseconds of ``picture()`` along the path with ``whole_every`` = every."""
    scenario = load_scenario(config, [f"sim_node.picture.whole_every={every}"])
    sim = Simulator(scenario.sim)
    times = []
    try:
        for q in _poses(np.asarray(scenario.sim.initial_positions, float), frames):
            sim.plant.reset(q)
            sim._show_markers()
            t0 = time.perf_counter()
            sim.pictures.picture()
            times.append(time.perf_counter() - t0)
        windows = sim.pictures.windows
    finally:
        sim.close()
    return {"whole_every": every, "picture_ms": _median_ms(times), "windowed": windows,
            "frames": frames}


def closed_loop(config, duration, overrides):
    scenario = load_scenario(config, overrides)
    load_before = os.getloadavg()[0]
    cpu0 = time.process_time()
    with tempfile.TemporaryDirectory() as out:
        summary = run_scenario(scenario, out, duration=duration, progress=False, record=False,
                               plots=False)
    cpu = time.process_time() - cpu0
    simulated = summary["steps"] * scenario.sim.control_period
    return {"overrides": overrides, "simulated_s": simulated,
            "realtime_factor": summary["realtime_factor"],
            "sim_s_per_cpu_s": simulated / cpu, "diverged": summary["diverged"],
            "load_before": load_before, "load_after": os.getloadavg()[0]}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=DEFAULT_CONFIG)
    parser.add_argument("--frames", type=int, default=60, help="poses along the path")
    parser.add_argument("--duration", type=float, default=5.0,
                        help="simulated seconds of each closed-loop run (0: none)")
    parser.add_argument("--whole-every", type=int,
                        help="picture.whole_every of the fast case (default: the file's)")
    parser.add_argument("--out", help="JSON result file (default: "
                                      "benchmarks/results/render_<config name>.json)")
    args = parser.parse_args(argv)
    name = os.path.splitext(os.path.basename(args.config))[0]
    env = environment()
    print(f"{name}: {env['machine']}, load average {env['load_average_1min']:.2f}\n")

    every = args.whole_every or load_scenario(args.config).sim["picture.whole_every"]
    parts = picture_parts(args.config, args.frames, max(every, 2))
    whole, windowed = (pictures(args.config, args.frames, k) for k in (1, every))
    print("| part of one picture | median [ms] |")
    print("|---|---:|")
    for part, ms in parts.items():
        print(f"| {part} | {ms:.1f} |" if "pixels" not in part else f"| {part} | {ms:.0f} |")
    for case in (whole, windowed):
        print(f"| picture(), whole_every {case['whole_every']} ({case['windowed']} of "
              f"{case['frames']} from a window) | {case['picture_ms']:.1f} |")

    loops = []
    if args.duration > 0.0:
        cases = [["sim_node.picture.whole_every=1"]]
        if every != 1:
            cases.append([f"sim_node.picture.whole_every={every}"])
        loops = [closed_loop(args.config, args.duration, case) for case in cases]
        print(f"\n| closed loop, {args.duration:g} s, no recording | real time | "
              "sim s per CPU s | load before / after |")
        print("|---|---:|---:|---|")
        for loop in loops:
            print(f"| {' '.join(loop['overrides'])} | {loop['realtime_factor']:.2f}x | "
                  f"{loop['sim_s_per_cpu_s']:.2f} | {loop['load_before']:.2f} / "
                  f"{loop['load_after']:.2f} |")
    write_result(args.out or os.path.join(HERE, "results", f"render_{name}.json"),
                 {"config": name, "picture_parts_ms": parts, "pictures": [whole, windowed],
                  "closed_loop": loops, **env})


if __name__ == "__main__":
    main()
