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

"""The robustness matrix: start offsets, noise, delay, wrong estimates, bad input.

Each :class:`Case` is a scenario change plus an optional fault injector, and the
bounds it must meet.  ``vas robustness`` runs them all and writes a markdown
table; ``test/test_robustness.py`` runs the same cases and asserts the bounds.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from .config import load_scenario
from .runner import run_scenario

PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAPER = "paper_3dof.yaml"
NOISY = "paper_3dof_noisy.yaml"


def joints_seeing(model, pixels, q_start, iterations=50):
    """Joint positions near ``q_start`` whose features project to ``pixels`` (Newton)."""
    q = np.array(q_start, dtype=float)
    for _ in range(iterations):
        x, z = model.project(q)
        err = pixels - x
        if np.max(np.abs(err)) < 1e-9:
            return q
        J = model.true_image_jacobian(q, x) / np.repeat(z, 2)[:, None]
        q = q + np.linalg.pinv(J) @ err
    raise ValueError(f"no joint positions near {list(q_start)} see the feature at {pixels}")


def nan_burst(start_s, length_s, period, what="pixels"):
    """Fault injector: NaN in the pixels (or joint positions) for a while."""
    first, last = int(round(start_s / period)), int(round((start_s + length_s) / period))

    def inject(step, meas):
        if first <= step < last:
            if what == "pixels" and meas.pixels is not None:
                return replace(meas, pixels=np.full_like(meas.pixels, np.nan))
            if what == "q":
                return replace(meas, q=np.full_like(meas.q, np.nan))
        return meas
    return inject


def dropped_frames(every, outage_start_s, outage_s, period):
    """Fault injector: drop every ``every``-th frame, plus one outage of ``outage_s``."""
    first = int(round(outage_start_s / period))
    last = first + int(round(outage_s / period))

    def inject(step, meas):
        if step % every == every - 1 or first <= step < last:
            return replace(meas, pixels=None, feature_stamp=None)
        return meas
    return inject


@dataclass(frozen=True)
class Case:
    """One row of the matrix: config file, overrides, start offset, faults, bounds."""

    name: str
    config: str
    overrides: tuple = ()
    start_offset_px: float = 0.0
    faults: Callable | None = field(default=None, compare=False)
    rms_bound_px: float = 0.1       # true RMS image error over the last 5 s
    max_bound_px: float | None = None

    def scenario(self):
        path = os.path.join(PACKAGE_ROOT, "config", self.config)
        scenario = load_scenario(path, self.overrides)
        if self.start_offset_px:
            sim, model = scenario.sim, scenario.controller.model
            x0 = model.project(np.array(sim.initial_positions))[0]
            direction = np.tile([0.6, -0.8], model.m)
            q0 = joints_seeing(model, x0 + self.start_offset_px * direction,
                               sim.initial_positions)
            scenario = load_scenario(path, self.overrides + (
                f"sim_node.initial_positions={q0.tolist()}",))
        return scenario


BLEND = "controller_node.start_blend_time=2.0"
T = 0.005
CASES = (
    Case("start 5 px off", PAPER, (BLEND,), 5.0, rms_bound_px=0.1),
    Case("start 20 px off", PAPER, (BLEND,), 20.0, rms_bound_px=0.15),
    Case("start 50 px off", PAPER, (BLEND,), 50.0, rms_bound_px=0.15),
    Case("noise 0.5 px (noisy preset)", NOISY, ("sim_node.pixel_noise_std=0.5",),
         rms_bound_px=0.3),
    Case("noise 1 px (noisy preset)", NOISY, ("sim_node.pixel_noise_std=1.0",),
         rms_bound_px=0.5),
    Case("noise 1 px + delay 2 (noisy preset)", NOISY,
         ("sim_node.pixel_noise_std=1.0", "sim_node.camera_latency=0.01"), rms_bound_px=0.6),
    Case("delay 1 frame", PAPER, ("sim_node.camera_latency=0.005",), rms_bound_px=0.2),
    Case("delay 2 frames", PAPER, ("sim_node.camera_latency=0.01",), rms_bound_px=0.35),
    Case("delay 3 frames", PAPER, ("sim_node.camera_latency=0.015",), rms_bound_px=0.5),
    Case("estimates x0.5", PAPER, (BLEND, "controller_node.a_z_perp_init=[135.0, 135.0]",
                                   "controller_node.a_z_init=[1.0, 1.0, 2.5]"),
         rms_bound_px=0.1),
    Case("estimates x2", PAPER, (BLEND, "controller_node.a_z_perp_init=[540.0, 540.0]",
                                 "controller_node.a_z_init=[4.0, 4.0, 10.0]"),
         rms_bound_px=0.1),
    Case("NaN pixels 0.1 s", PAPER, (), faults=nan_burst(3.0, 0.1, T), rms_bound_px=0.1),
    Case("NaN joint states 0.03 s", PAPER, (), faults=nan_burst(3.0, 0.03, T, "q"),
         rms_bound_px=0.1),
    Case("every 10th frame dropped + 0.3 s outage", PAPER, (),
         faults=dropped_frames(10, 3.0, 0.3, T), rms_bound_px=0.15),
)


def run_case(case, out_dir, duration=10.0):
    """Run one case headless; returns its summary plus the torque limit it ran with."""
    scenario = case.scenario()
    summary = run_scenario(scenario, out_dir, duration=duration, progress=False, record=False,
                           plots=False, faults=case.faults)
    summary["torque_limit"] = float(np.max(scenario.controller.torque_limit))
    return summary


def markdown_table(results):
    lines = ["| case | config | diverged | true RMS error, last 5 s [px] (bound) "
             "| max true error [px] | max abs(tau) [N m] | rejected samples | fallback |",
             "|---|---|---|---|---|---|---|---|"]
    for case, s in results:
        lines.append(f"| {case.name} | {case.config} | {'yes' if s['diverged'] else 'no'} "
                     f"| {s['final_rms_true_error_px']:.3f} ({case.rms_bound_px:g}) "
                     f"| {s['max_true_error_px']:.2f} | {s['max_abs_torque']:.0f} "
                     f"| {s['rejected']} | {s['fallback']} |")
    return "\n".join(lines)
