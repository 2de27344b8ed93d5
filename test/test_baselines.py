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

"""The baselines of ``vas compare``: their laws against independent oracles, and short runs.

* the calibrated IBVS law produces the commanded image acceleration, checked by
  finite differences of the true projection along the commanded joint motion;
* the velocity baseline's image velocity is the backward difference of the pixels,
  low-pass filtered when asked (seen through the integrated estimate x_obs);
* closed loop: calibrated IBVS tracks the clean reference scenario to a small
  error, the velocity baseline runs it without diverging.
"""

import functools
import os

import numpy as np
import pytest

from visual_adaptive_servo.control.baselines import (
    CalibratedIBVS,
    VelocityAdaptiveTracker,
    ibvs_law,
)
from visual_adaptive_servo.runner import run_scenario

Q0 = np.array([1.0807, 0.5756, -0.5000])


def test_ibvs_law_commands_the_image_acceleration(scenario, rng):
    model = scenario.controller.model
    gains = (400.0, 40.0, 10.0)
    for _ in range(20):
        q = Q0 + rng.normal(0.0, 0.2, 3)
        qd = rng.normal(0.0, 0.5, 3)
        x, z = model.project(q)
        xd, xd_dot, xd_ddot = x + rng.normal(0, 2, 2), rng.normal(0, 10, 2), rng.normal(0, 10, 2)
        out = ibvs_law(model, q, qd, x, xd, xd_dot, xd_ddot, gains)
        qdd = out.qr_ddot
        h = 1e-4
        xs = [model.project(q + qd * s + 0.5 * qdd * s * s)[0] for s in (-h, 0.0, h)]
        x_dot = (xs[2] - xs[0]) / (2 * h)
        x_ddot = (xs[2] - 2 * xs[1] + xs[0]) / h**2
        commanded = xd_ddot - 40.0 * (x_dot - xd_dot) - 400.0 * (x - xd)
        np.testing.assert_allclose(out.rates.x_obs, x_dot, rtol=1e-5, atol=1e-4)
        np.testing.assert_allclose(x_ddot, commanded, rtol=1e-4, atol=1e-3)
        # the torque is the true computed torque M qdd + C qd + g
        tau = (model.mass_matrix(q) @ qdd + model.coriolis_matrix(q, qd) @ qd
               + model.gravity_torque(q))
        np.testing.assert_allclose(out.tau, tau, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("filter_time", [0.0, 0.02])
def test_velocity_is_the_filtered_backward_difference_of_the_pixels(scenario, filter_time):
    ctl = VelocityAdaptiveTracker(scenario.controller, filter_time=filter_time)
    x0, v, period = scenario.controller.model.project(Q0)[0], np.array([12.0, -7.0]), 0.005
    a = period / (filter_time + period)
    steps = [ctl.step(k * period, Q0, np.zeros(3), x0 + v * k * period) for k in range(6)]
    assert all(r.status == "ok" for r in steps)
    # x_obs integrates the velocity estimate: its increment over a period is T v_{k-1}
    for k in range(2, 6):
        v_prev = v * (1.0 - (1.0 - a) ** (k - 1))       # v_0 = 0, then first order
        np.testing.assert_allclose(steps[k].x_obs - steps[k - 1].x_obs, period * v_prev,
                                   rtol=1e-9, atol=1e-12)


def test_velocity_baseline_refuses_bad_settings(scenario):
    with pytest.raises(ValueError, match="filter_time"):
        VelocityAdaptiveTracker(scenario.controller, filter_time=-1.0)
    with pytest.raises(ValueError, match="prediction_gain"):
        VelocityAdaptiveTracker(scenario.controller, prediction_gain=-1.0)


def test_calibrated_ibvs_tracks_the_clean_reference_scenario(scenario, tmp_path):
    summary = run_scenario(scenario, str(tmp_path), duration=6.0, progress=False, record=False,
                           plots=False, controller_factory=CalibratedIBVS)
    assert not summary["diverged"]
    assert summary["final_rms_true_error_px"] < 0.01
    assert summary["max_true_error_px"] < 1.0


def test_velocity_baseline_runs_the_clean_reference_scenario(scenario, tmp_path):
    factory = functools.partial(VelocityAdaptiveTracker, filter_time=0.1, prediction_gain=1e-3)
    summary = run_scenario(scenario, str(tmp_path), duration=4.0, progress=False, record=False,
                           plots=False, controller_factory=factory)
    assert not summary["diverged"]
    assert summary["rejected"] == 0
    assert summary["final_rms_true_error_px"] < 0.2


def test_compare_figures_on_a_known_signal():
    from visual_adaptive_servo.recording.summary import run_figures

    period = 0.01
    t = np.arange(0.0, 10.0, period)
    x_d = np.zeros((len(t), 2))
    x_true = np.column_stack([np.where(t < 5.0, 100.0, 3.0), np.full(len(t), 4.0)])  # |e| = 5
    tau = np.column_stack([np.sin(t), np.zeros(len(t)), np.zeros(len(t))])
    fig = run_figures(t, x_true, x_d, tau, period, transient=5.0)
    assert fig["rms_error_px"] == pytest.approx(5.0)
    assert fig["max_error_px"] == pytest.approx(5.0)
    window = t >= 5.0 - 1e-9
    assert fig["torque_rms"] == pytest.approx(np.sqrt(np.mean(np.sin(t[window]) ** 2)))
    # the rate of sin is cos: RMS of cos over the same window, to the difference quotient
    assert fig["torque_rate_rms"] == pytest.approx(np.sqrt(np.mean(np.cos(t[window]) ** 2)),
                                                   rel=1e-2)


def test_vas_compare_is_registered():
    from visual_adaptive_servo.cli import build_parser

    args = build_parser().parse_args(["compare", "--out", "x", "--duration", "5",
                                      "--workers", "2"])
    assert args.command == "compare" and args.duration == 5.0 and args.workers == 2
    assert args.spec.endswith("config/campaigns/compare.yaml")


def test_controller_names_are_the_compared_controllers():
    from visual_adaptive_servo.control.registry import (
        CONTROLLER_NAMES,
        controller_factory,
        controllers,
    )

    assert CONTROLLER_NAMES == tuple(name for name, _, _ in controllers())

    def same(f, g):     # controllers() builds new partials on every call
        return (getattr(f, "func", f), getattr(f, "keywords", {})) == (
            getattr(g, "func", g), getattr(g, "keywords", {}))

    assert all(same(controller_factory(name), factory) for name, _, factory in controllers())
    with pytest.raises(ValueError, match=r"controller: must be one of \['observer'"):
        controller_factory("pid")


def test_vas_run_controller_runs_that_baseline(scenario, tmp_path):
    import json

    from visual_adaptive_servo.cli import main

    config = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                          "config", "paper_3dof.yaml")
    assert main(["run", "--config", config, "--duration", "0.5", "--controller", "velocity-lp",
                 "--out", str(tmp_path / "cli"), "--no-bag", "--no-progress"]) == 0
    with open(tmp_path / "cli" / "summary.json", encoding="utf-8") as handle:
        cli = json.load(handle)
    direct = run_scenario(scenario, str(tmp_path / "direct"), duration=0.5, progress=False,
                          record=False, plots=False,
                          controller_factory=functools.partial(
                              VelocityAdaptiveTracker, filter_time=0.1, prediction_gain=1e-3))
    assert cli["max_abs_torque"] == direct["max_abs_torque"]
    assert cli["final_rms_error_px"] == direct["final_rms_error_px"]
