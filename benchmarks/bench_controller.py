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
of the bare :func:`control_law`, for the paper's RRR arm (n = 3, m = 1), and of
the model's ``kinematic_tensors`` alone -- with each backend of the tensors
(``compiled``: numba, ``numpy``: the reference), replays alternating.

How: the scenario (default config/paper_3dof.yaml) is simulated once in
closed loop and its measurements (t, q, q_dot, x, the frame's capture stamp)
are stored.  A fresh tracker
then replays them; because the controller is deterministic it goes through
exactly the states of the closed loop.  The first replay is a warm-up and is
not timed; every sample of the following replays is timed on its own with
``time.perf_counter_ns``.  ``control_law`` is timed on the (state, inputs)
pairs the tracker saw.  The garbage collector stays enabled: its pauses are
part of what a real control loop sees in p99.  With a camera slower than the
joint loop (``--set sim_node.camera_rate=30``) the samples are also timed by
kind: with a frame (applied at its capture time, the prediction re-run when it
is late) and between frames (prediction only).

Start-up of the compiled backend, each in a fresh process: the first run
compiles the kernels into an empty numba cache (``NUMBA_CACHE_DIR`` a new
temporary folder), the second loads them from it -- what every later start
costs.  The first kernel (the paper's) also pays numba's own initialisation.

Usage::

    python benchmarks/bench_controller.py [--config FILE] [--steps N] [--repeats R]
        [--backend both|compiled|numpy] [--set NODE.PARAM=VALUE ...] [--out FILE]
        [--no-startup]

Prints a markdown table and writes benchmarks/results/controller_step_<config>.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np
from benchlib import environment, write_result

from sim_bridge.simulator import Simulator
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.control.controller import AdaptiveVisualTracker
from visual_adaptive_servo.models.backend import kernels

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_CONFIG = os.path.join(HERE, os.pardir, "config", "paper_3dof.yaml")
RESULTS = os.path.join(HERE, "results", "controller_step_{name}.json")


def record_measurements(scenario, steps):
    """Closed-loop run of ``steps`` samples; returns the list of (t, q, qd, x, x_stamp)."""
    sim = Simulator(scenario.sim)
    ctl = AdaptiveVisualTracker(scenario.controller)
    samples = []
    try:
        for _ in range(steps):
            meas = sim.measure()
            sample = (meas.t, meas.q, meas.qd, meas.pixels, meas.feature_stamp)
            samples.append(sample)
            sim.apply(ctl.step(*sample).tau)
    finally:
        sim.close()
    return samples


def time_steps(scenario, samples, repeats, backends):
    """Per-sample ns of ``step`` over ``repeats`` timed replays after one warm-up replay.

    The replays of the ``backends`` alternate.  Returns, per backend, (all timings,
    timings of samples with a frame, of samples without one, the law's inputs).
    """
    clock = time.perf_counter_ns
    model = scenario.controller.model
    out = {b: ([], [], [], []) for b in backends}
    for rep in range(repeats + 1):
        for backend in backends:
            model.set_backend(backend)
            timings, with_frame, between, law_inputs = out[backend]
            ctl = AdaptiveVisualTracker(scenario.controller)
            for t, q, qd, x, stamp in samples:
                t0 = clock()
                res = ctl.step(t, q, qd, x, stamp)
                t1 = clock()
                if rep > 0:
                    timings.append(t1 - t0)
                    (with_frame if x is not None else between).append(t1 - t0)
                elif res.status == "ok" and x is not None:
                    x_law = ctl.predictor.x_hat if ctl.compensate else x
                    law_inputs.append((t, res.state, q, qd, x_law, ctl.desired(t),
                                       ctl.e_int.copy()))
    return {b: (np.array(t), np.array(f), np.array(w), law) for b, (t, f, w, law) in out.items()}


def time_law(ctl, law_inputs, repeats):
    """Per-call ns of the tracker's law (``_law``: the backend's) on recorded inputs.

    The tracker ``ctl`` has run the samples (its gains are fixed); the kinematic
    tensors are computed outside the timing, the projection is passed as
    ``step`` passes it (None when no bound is near).
    """
    clock = time.perf_counter_ns
    model, proj = ctl.model, ctl.projection
    inputs = []
    for t, state, q, qd, x, desired, e_int in law_inputs:
        tensors = model.kinematic_tensors(q, qd)
        near = proj if proj is not None and not proj.interior(state, tensors[0]) else None
        inputs.append((t, state, q, qd, x, *desired, tensors, near, e_int))
    timings = []
    for rep in range(repeats + 1):
        for args in inputs:
            t0 = clock()
            ctl._law(*args)
            t1 = clock()
            if rep > 0:
                timings.append(t1 - t0)
    return np.array(timings)


def time_tensors(model, samples, repeats):
    """Per-call ns of ``model.kinematic_tensors`` at the samples' (q, q_dot)."""
    clock = time.perf_counter_ns
    timings = []
    for rep in range(repeats + 1):
        for _, q, qd, _, _ in samples:
            t0 = clock()
            model.kinematic_tensors(q, qd)
            t1 = clock()
            if rep > 0:
                timings.append(t1 - t0)
    return np.array(timings)


STARTUP = """
import json, os, time
t0 = time.perf_counter()
import numba
t1 = time.perf_counter()
import numpy as np
from sim_bridge.plant import URDF_DIR
from visual_adaptive_servo.models import PaperRRRCamera
from visual_adaptive_servo.models.kinematic_regressor import KinematicRegressor
from visual_adaptive_servo.models.urdf_chain import load_chain
from visual_adaptive_servo.recording import csv_kernels
paper = PaperRRRCamera(backend="numpy")
chain = KinematicRegressor(load_chain(os.path.join(URDF_DIR, "paper_rrr.urdf"), "base_link",
                                      "tip"), [[0.0, 0.0, 0.0]], backend="numpy")
t2 = time.perf_counter()
paper.set_backend("compiled")
t3 = time.perf_counter()
chain.set_backend("compiled")
t4 = time.perf_counter()
csv_kernels.format_g10(np.ones(1), np.empty((1, csv_kernels.WIDTH), np.uint8),
                       np.empty(1, np.intp), np.empty(1, np.bool_))
t5 = time.perf_counter()
from visual_adaptive_servo.control.law_kernels import CompiledLaw
from visual_adaptive_servo.models import dynamics_kernels
from visual_adaptive_servo.models.rigid_body import RigidBodyDynamics
dynamics = RigidBodyDynamics(os.path.join(URDF_DIR, "paper_rrr.urdf"), "base_link", "tip")
constants = dynamics.kernel_constants()
t6 = time.perf_counter()
dynamics_kernels.chain_regressor(*np.zeros((4, 3)), *constants)
t7 = time.perf_counter()
law = CompiledLaw(paper)
t8 = time.perf_counter()
from visual_adaptive_servo.control.motion_scale_kernels import BufferedMotionScale
from visual_adaptive_servo.control.prediction_kernels import BufferedFramePredictor
from visual_adaptive_servo.control.sample_kernels import CompiledSample
from visual_adaptive_servo.control.trajectory import SinusoidTrajectory
CompiledSample(law, paper, SinusoidTrajectory(np.zeros(2), np.ones(2), np.ones(2), 1.0))
t9 = time.perf_counter()
BufferedFramePredictor(0.2, 1.0, 0.0, 2)
BufferedMotionScale(1.0, 1.0, 0.5, 2.0, 0.5, 0.2, 2)
t10 = time.perf_counter()
print(json.dumps({"import_numba_s": t1 - t0, "paper_kernel_s": t3 - t2,
                  "chain_kernel_s": t4 - t3, "csv_kernel_s": t5 - t4,
                  "regressor_kernel_s": t7 - t6, "law_kernel_s": t8 - t7,
                  "sample_kernel_s": t9 - t8, "predictor_scale_kernels_s": t10 - t9}))
"""


def time_startup():
    """First-run (empty cache) and cached start-up of the compiled kernels, fresh processes."""
    root = os.path.join(HERE, os.pardir)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [root] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    runs = {}
    with tempfile.TemporaryDirectory() as cache:
        env["NUMBA_CACHE_DIR"] = cache
        for name in ("first_run", "cached"):
            done = subprocess.run([sys.executable, "-c", STARTUP],
                                  env=env, capture_output=True, text=True, check=True)
            runs[name] = json.loads(done.stdout.strip().splitlines()[-1])
    return runs


def stats(ns):
    if ns.size == 0:
        return None
    us = ns / 1e3
    return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
            "mean_us": float(np.mean(us)), "min_us": float(np.min(us)), "samples": int(us.size)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=DEFAULT_CONFIG)
    parser.add_argument("--steps", type=int, default=4000, help="closed-loop samples (5 ms)")
    parser.add_argument("--repeats", type=int, default=3, help="timed replays per backend")
    parser.add_argument("--backend", choices=("both", "compiled", "numpy"), default="both",
                        help="kinematic tensors backend(s) to time (default both, alternating)")
    parser.add_argument("--set", action="append", default=[], metavar="NODE.PARAM=VALUE",
                        help="parameter override, as vas run --set (repeatable)")
    parser.add_argument("--out", help="JSON result file (default: results/"
                        "controller_step_<config name>.json)")
    parser.add_argument("--no-startup", action="store_true",
                        help="skip the start-up timing (two fresh processes, one compiling "
                             "every kernel into an empty cache: ~30 s)")
    args = parser.parse_args(argv)

    backends = (["compiled", "numpy"] if args.backend == "both" else [args.backend])
    if "compiled" in backends and kernels() is None:
        parser.error("--backend compiled needs numba")
    scenario = load_scenario(args.config, args.set)
    model = scenario.controller.model
    samples = record_measurements(scenario, args.steps)
    steps = time_steps(scenario, samples, args.repeats, backends)
    by_backend = {}
    for backend in backends:
        step_ns, frame_ns, between_ns, law_inputs = steps[backend]
        model.set_backend(backend)
        ctl = AdaptiveVisualTracker(scenario.controller)
        for sample in samples:
            ctl.step(*sample)
        law_ns = time_law(ctl, law_inputs, args.repeats)
        by_backend[backend] = {
            "step": stats(step_ns), "step_with_frame": stats(frame_ns),
            "step_between_frames": stats(between_ns), "control_law": stats(law_ns),
            "kinematic_tensors": stats(time_tensors(model, samples, args.repeats))}
    startup = time_startup() if "compiled" in backends and not args.no_startup else None
    result = {
        "config": os.path.relpath(os.path.abspath(args.config), os.path.join(HERE, os.pardir)),
        "overrides": args.set, "n": model.n, "m": model.m,
        "parameters": {"p_perp": model.p_perp, "p_z": model.p_z, "p_d": model.p_d},
        "steps": args.steps, "repeats": args.repeats, "backends": by_backend,
        "compiled_startup": startup, **environment(),
    }
    print(f"controller latency, n={model.n}, m={model.m} (p = {model.p_perp} + {model.p_z} + "
          f"{model.p_d}), {args.steps} samples x {args.repeats} replays per backend "
          f"(numpy {np.__version__}, Python {platform.python_version()}, load average "
          f"{result['load_average_1min']:.2f})\n")
    print("| call | backend | median [µs] | p99 [µs] | mean [µs] | min [µs] |")
    print("|---|---|---:|---:|---:|---:|")
    for name, key in (("AdaptiveVisualTracker.step", "step"),
                      ("step, sample with a camera frame", "step_with_frame"),
                      ("step, sample between frames (prediction only)", "step_between_frames"),
                      ("the law (control_law / its kernel)", "control_law"),
                      ("model.kinematic_tensors", "kinematic_tensors")):
        for backend in backends:
            s = by_backend[backend][key]
            if s is not None:
                print(f"| {name} | {backend} | {s['median_us']:.1f} | {s['p99_us']:.1f} | "
                      f"{s['mean_us']:.1f} | {s['min_us']:.1f} |")
    if startup:
        print("\ncompiled backend start-up, fresh processes [s]:\n")
        print("| | import numba | paper kernel (+ numba's initialisation) | chain kernel "
              "| csv kernels | chain Y_d kernel | control law kernel | whole sample kernel "
              "| predictor and motion scale kernels |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for name, run in startup.items():
            print(f"| {name.replace('_', ' ')} | {run['import_numba_s']:.2f} | "
                  f"{run['paper_kernel_s']:.2f} | {run['chain_kernel_s']:.2f} | "
                  f"{run['csv_kernel_s']:.2f} | {run['regressor_kernel_s']:.2f} | "
                  f"{run['law_kernel_s']:.2f} | {run['sample_kernel_s']:.2f} | "
                  f"{run['predictor_scale_kernels_s']:.2f} |")
    print("\ntargets (issue 18), compiled: the iiwa's step median <= 30 µs and p99 <= 80 µs, "
          "the paper's <= 10 µs; with a 30 Hz frame 33 ms late (--set sim_node.camera_rate=30 "
          "--set sim_node.camera_latency=0.033 at 1 ms joints), the step with the frame <= 60 µs")
    name = os.path.splitext(os.path.basename(args.config))[0]
    write_result(args.out or RESULTS.format(name=name + ("_" + "_".join(
        o.split(".")[-1].replace("=", "") for o in args.set) if args.set else "")), result)


if __name__ == "__main__":
    main()
