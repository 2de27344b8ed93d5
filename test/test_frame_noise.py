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

"""The measured frame noise and the bandwidth it leaves (control/frame_noise.py)."""

from math import log

import numpy as np
import pytest

from visual_adaptive_servo.control.frame_noise import (FrameNoise, MIN_FRAMES, noise_bandwidth,
                                                       RAISE)

FRAME = 1.0 / 30


def _h2_by_frequency(observer_ratio, integral_rate):
    """||H||_2^2 for gamma = 1 by integrating |H(j w)|^2 / pi over w >= 0 (the oracle)."""
    w = np.concatenate([np.linspace(0.0, 50.0, 500001), np.geomspace(50.0, 1e6, 200001)[1:]])
    s = 1j * w
    a, k = observer_ratio, integral_rate
    H = a / (s + a) * ((s + k) / (s * s + s + k) if k > 0.0 else 1.0 / (s + 1.0))
    f = np.abs(H) ** 2
    return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(w)) / np.pi)


@pytest.mark.parametrize("observer_ratio, integral_rate",
                         [(2.0, 0.25), (2.0, 0.0), (1.0, 0.25), (0.5, 1.0), (6.0, 0.1)])
def test_the_noise_bandwidth_is_the_h2_norm_of_the_loop(observer_ratio, integral_rate):
    b = noise_bandwidth(observer_ratio, integral_rate)
    assert b == pytest.approx(_h2_by_frequency(observer_ratio, integral_rate), rel=1e-4)
    if integral_rate == 0.0:        # a / ((s + a)(s + 1)): a / (2 (a + 1)) in closed form
        assert b == pytest.approx(observer_ratio / (2.0 * (observer_ratio + 1.0)), rel=1e-12)


def _innovations(sigma, drift, frames, seed=0, m2=6):
    """Frames at 30 Hz: their innovations and noise.

    nu_k = n_k - n_{k-1} + d_k, a reset predictor's innovations with d a slow drift [px],
    and the frames' noise n_k itself.
    """
    rng = np.random.default_rng(seed)
    n = rng.normal(0.0, sigma, (frames + 1, m2))
    t = np.arange(frames) * FRAME
    phase = np.arange(m2)
    d = drift * np.sin(0.8 * t[:, None] + phase) + 0.5 * drift
    return t, n[1:] - n[:-1] + d, n[1:]


def _meter(window=2.0, min_factor=0.25, gamma=3.0):
    return FrameNoise(window, min_factor, gamma, 2.0 * gamma, 0.25)


@pytest.mark.parametrize("sigma, drift", [(0.6, 0.0), (0.6, 1.0), (0.2, 0.5), (1.0, 2.0)])
def test_the_noise_is_measured_whatever_the_drift_of_the_prediction(sigma, drift):
    meter = _meter()
    t, nu, n = _innovations(sigma, drift, 900)
    estimates = []
    for stamp, row, noise in zip(t, nu, n):
        meter.frame(stamp, row, noise)
        if stamp > 4.0:
            estimates.append(meter.sigma)
    # a 2 s window holds 60 frames x 6 coordinates: the estimate within 20 % at each frame,
    # its mean within 5 %
    assert np.all(np.abs(np.array(estimates) / sigma - 1.0) < 0.2)
    assert np.mean(estimates) == pytest.approx(sigma, rel=0.05)
    assert meter.interval == pytest.approx(FRAME, rel=1e-9)
    # the innovations' own spread counts the drift as noise: half their mean square does not
    # measure the noise when the prediction drifts
    if drift >= 1.0:
        assert np.sqrt(np.mean(nu[-60:] ** 2) / 2.0) > 1.3 * sigma


def test_a_frame_at_every_sample_is_measured_every_10_ms():
    # 1 kHz frames: a tenth measured, each innovation paired with the previous measured one
    # (nine frames between: no shared noise), the frames' interval from every frame
    meter = _meter()
    rng = np.random.default_rng(4)
    n = rng.normal(0.0, 0.5, (6001, 6))
    t = np.arange(6000) * 1e-3
    measured = 0
    for k, stamp in enumerate(t):
        if meter.due(stamp):
            meter.frame(stamp, n[k + 1] - n[k] + 0.1 * np.sin(stamp), n[k + 1])
            measured += 1
        else:
            meter.skip(stamp)
    assert measured == pytest.approx(600, abs=2)
    assert meter.interval == pytest.approx(1e-3, rel=1e-9)
    assert meter.sigma == pytest.approx(0.5, rel=0.15)


@pytest.mark.parametrize("error", [0.0, 0.3, 1.0])
def test_the_tracking_error_is_measured_beneath_the_noise(error):
    # the frames' error x_c - x_d: a slow tracking error (a new value every 0.5 s, RMS
    # ``error`` per coordinate) plus 0.6 px of noise at every frame
    meter = _meter(window=4.0)
    rng = np.random.default_rng(1)
    t, nu, n = _innovations(0.6, 0.2, 1800, seed=2)
    slow = rng.normal(0.0, error, (int(t[-1] / 0.5) + 1, 6))
    measured = []
    for stamp, row, noise in zip(t, nu, n):
        meter.frame(stamp, row, slow[int(stamp / 0.5)] + noise)
        if stamp > 8.0:
            measured.append(meter.tracking_error)
    # the noise alone would read 0.6 / sqrt(10) = 0.19 px per block: removed
    assert np.mean(measured) == pytest.approx(error, abs=0.06 + 0.15 * error)


def test_nothing_is_trusted_before_a_window_of_frames():
    meter = _meter()
    t, nu, n = _innovations(1.0, 0.0, 200)
    for stamp, row, noise in zip(t, nu, n):
        factor = meter.frame(stamp, row, noise)
        if stamp < 2.0 + 2 * FRAME:
            assert np.isnan(meter.sigma) and np.isnan(meter.tracking_error) and factor == 1.0
    assert meter.trusted and meter.frames >= MIN_FRAMES
    meter.reset()
    assert np.isnan(meter.sigma) and meter.factor == 1.0 and not meter.trusted


def test_gamma_settles_where_noise_and_model_error_balance():
    # a synthetic loop: at gamma = 3 f the frames show a slow tracking error of variance
    # N(f) + M(f), N the noise's share of the linear loop (sigma^2 T_f b gamma) and
    # M = M0 f^-4 the model's, plus 0.8 px of noise.  The factor must settle near the f
    # that minimises N + M, and stay at 1 when the model's share dominates at f = 1
    gamma, sigma, window = 3.0, 0.8, 2.0
    grid = np.geomspace(0.25, 1.0, 400)
    for M0, expect_one in ((0.002, False), (0.0002, False), (0.2, True)):
        meter = _meter(window=window, min_factor=0.25, gamma=gamma)
        rng = np.random.default_rng(5)
        t, nu, n = _innovations(sigma, 0.1, 4500, seed=6)
        slow, until, factors = None, -1.0, []
        for stamp, row, noise in zip(t, nu, n):
            if stamp >= until:          # a new slow error every half second, at the factor now
                f = meter.factor
                N = sigma ** 2 * FRAME * meter.bandwidth(f) * gamma * f
                slow, until = rng.normal(0.0, np.sqrt(N + M0 * f ** -4), 6), stamp + 0.5
            factors.append(meter.frame(stamp, row, slow + noise))
        total = [sigma ** 2 * FRAME * meter.bandwidth(f) * gamma * f + M0 * f ** -4
                 for f in grid]
        best = grid[int(np.argmin(total))]
        settled = np.median(factors[-900:])
        if expect_one:
            assert best == 1.0 and settled > 0.9
        else:
            assert 0.3 < best < 0.9
            assert settled == pytest.approx(best, rel=0.25)
        # it moves at 1 / window in ln down, RAISE / window up: no frame steps more than
        # that fraction of the gap
        steps = np.diff(np.log(factors))
        assert -steps.min() <= FRAME / window * log(4.0) + 1e-12
        assert steps.max() <= RAISE * FRAME / window * log(4.0) + 1e-12


def _iiwa_behind_a_noisy_camera(tmp_path, seed, follow):
    """The iiwa with its kinematics known, a 30 Hz camera 33 ms late with 0.8 px of noise."""
    import csv
    import os

    from visual_adaptive_servo.campaigns.spec import resolve_overrides
    from visual_adaptive_servo.config.scenario import load_scenario
    from visual_adaptive_servo.runner import run_scenario

    path = os.path.join(os.path.dirname(__file__), "..", "config", "iiwa_3points.yaml")
    exact, problem = resolve_overrides({"estimate_scale.a_z_perp": 1.0,
                                        "estimate_scale.a_z": 1.0}, load_scenario(path))
    assert not problem
    camera = ["sim_node.camera_rate=30.0", "sim_node.camera_latency=0.033",
              "controller_node.camera_rate=30.0", "controller_node.camera_latency=0.033",
              "sim_node.pixel_noise_std=0.8", f"sim_node.seed={seed}",
              f"controller_node.gain_design.follow_noise={str(follow).lower()}"]
    scenario = load_scenario(path, [*exact, *camera])
    out = tmp_path / f"{seed}_{follow}"
    summary = run_scenario(scenario, str(out), duration=20.0, progress=False, record=False,
                           plots=False)
    with open(out / "timeseries.csv") as f:
        gamma = [float(row["gamma"]) for row in csv.DictReader(f) if row["status"] == "ok"]
    return scenario, summary, gamma


@pytest.mark.parametrize("seed", [0, 1])
def test_behind_a_noisy_camera_gamma_comes_down_and_the_arm_tracks_closer(tmp_path, seed):
    scenario, on, gamma_on = _iiwa_behind_a_noisy_camera(tmp_path, seed, True)
    _, off, gamma_off = _iiwa_behind_a_noisy_camera(tmp_path, seed, False)
    delay = scenario.controller.gamma       # (timeseries.csv keeps 10 digits)
    assert not on["diverged"] and not off["diverged"]
    assert np.allclose(gamma_off, delay, rtol=1e-9, atol=0.0)
    # the noise measured in the frames is the simulator's
    assert on["frame_noise_px"] == pytest.approx(0.8, rel=0.1)
    assert np.isnan(off["frame_noise_px"])
    # gamma held while nothing is measured, then down, within its bounds
    assert gamma_on[0] == pytest.approx(delay, rel=1e-9) and max(gamma_on) <= delay * (1 + 1e-9)
    assert 0.25 * delay <= gamma_on[-1] < 0.7 * delay
    # and the noise the arm follows is less (the kinematics are exact: it is all noise)
    assert on["final_rms_true_error_px"] < 0.85 * off["final_rms_true_error_px"]
