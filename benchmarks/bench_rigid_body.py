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

"""Latency of the URDF dynamic regressor Y_d (Property 4) for the KUKA iiwa (n = 7).

What it measures: the wall time of one :meth:`RigidBodyDynamics.regressor`
call with base parameters (``reduce=True``, the controller's case) and with
the 70 standard parameters (``reduce=False``); for scale, one Pinocchio
joint-torque regressor call, one RNEA, and the five-call polarisation written
plainly (the form ``regressor`` replaces with two calls).

How: random (q, q_dot, xi, xi_dot), uniform in [-pi, pi] and [-2, 2], fixed
seed; every call timed on its own with ``time.perf_counter_ns``, the calls
taking turns on each sample, after a warm-up pass over the first 10 % of the
samples, the garbage collector on.

Usage::

    python benchmarks/bench_rigid_body.py [--samples N]

Prints a markdown table and writes benchmarks/results/rigid_body.json.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import pinocchio as pin
import pybullet_data
from benchlib import environment, write_result

from visual_adaptive_servo.models.rigid_body import RigidBodyDynamics

HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = os.path.join(HERE, "results", "rigid_body.json")
IIWA = (os.path.join(pybullet_data.getDataPath(), "kuka_iiwa", "model.urdf"),
        "lbr_iiwa_link_0", "lbr_iiwa_link_7")


def time_calls(funs, samples):
    """Per-call ns (len(funs), len(samples)) of each ``fun(*sample)``, interleaved.

    The functions take turns on each sample, so that a change of load from other
    processes during the run falls on all of them alike; an untimed warm-up
    pass goes over the first 10 % of the samples.
    """
    clock = time.perf_counter_ns
    for sample in samples[:len(samples) // 10]:
        for fun in funs:
            fun(*sample)
    ns = np.empty((len(funs), len(samples)))
    for k, sample in enumerate(samples):
        for i, fun in enumerate(funs):
            t0 = clock()
            fun(*sample)
            ns[i, k] = clock() - t0
    return ns


def stats(ns):
    us = ns / 1e3
    return {"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99)),
            "mean_us": float(np.mean(us)), "min_us": float(np.min(us)), "samples": int(us.size)}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=20000, help="random motions timed")
    parser.add_argument("--out", default=RESULTS, help="JSON result file")
    args = parser.parse_args(argv)

    base = RigidBodyDynamics(*IIWA)
    full = RigidBodyDynamics(*IIWA, reduce=False)
    model, data = full.model, full.data
    rng = np.random.default_rng(7)
    samples = [(rng.uniform(-np.pi, np.pi, 7), *rng.uniform(-2.0, 2.0, (3, 7)))
               for _ in range(args.samples)]
    zero = np.zeros(7)

    def torque_regressor(q, qd, xi, xi_dot):
        return pin.computeJointTorqueRegressor(model, data, q, qd, xi_dot)

    def rnea(q, qd, xi, xi_dot):
        return pin.rnea(model, data, q, qd, xi_dot)

    def five_call_polarisation(q, qd, xi, xi_dot):
        def Y(v, a):
            return pin.computeJointTorqueRegressor(model, data, q, v, a)
        return Y(zero, xi_dot) + 0.5 * (Y(qd + xi, zero) - Y(qd, zero) - Y(xi, zero)
                                        + Y(zero, zero))

    calls = (("RigidBodyDynamics.regressor, base parameters", base.regressor),
             ("RigidBodyDynamics.regressor, 70 standard parameters", full.regressor),
             ("five-call polarisation (plain form, reference)", five_call_polarisation),
             ("one pin.computeJointTorqueRegressor", torque_regressor),
             ("one pin.rnea", rnea))
    result = {"robot": "kuka_iiwa/model.urdf (pybullet_data)", "n": 7,
              "p_d_base": base.p_d, "p_d_full": full.p_d, "pinocchio": pin.__version__,
              "calls": {name: stats(ns) for (name, _), ns
                        in zip(calls, time_calls([fun for _, fun in calls], samples))},
              **environment()}
    print(f"Y_d latency, KUKA iiwa (n = 7, p_d = {base.p_d} base / {full.p_d} standard), "
          f"{args.samples} random motions, Pinocchio {pin.__version__}, "
          f"load {result['load_average_1min']:.2f}\n")
    print("| call | median [µs] | p99 [µs] | mean [µs] | min [µs] |")
    print("|---|---:|---:|---:|---:|")
    for name, s in result["calls"].items():
        print(f"| {name} | {s['median_us']:.1f} | {s['p99_us']:.1f} | {s['mean_us']:.1f} | "
              f"{s['min_us']:.1f} |")
    write_result(args.out, result)


if __name__ == "__main__":
    main()
