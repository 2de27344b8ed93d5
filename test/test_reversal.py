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


"""reversed_motion: frames moving against the model's image motion, said before a divergence."""

import os

import numpy as np
import pytest

from conftest import ROOT
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.control.reversal import MIN_FRAMES, ReversedMotion
from visual_adaptive_servo.runner import run_scenario

IIWA = os.path.join(ROOT, "config", "iiwa_3points.yaml")


def turn(deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s], [s, c]])


def feed(A, directions, noise, seconds=3.0, rate=30.0, seed=0):
    """Frames x = A p + noise of 3 points whose model path p moves along ``directions``."""
    rng = np.random.default_rng(seed)
    check = ReversedMotion(window=1.0, significance=5.0)
    verdicts = []
    for k in range(int(seconds * rate)):
        t = k / rate
        # each point on its own path: a sine along one direction, or a circle
        p = np.concatenate([3.0 * np.sin(2.0 * t + i) * d + 40.0 * i
                            for i, d in enumerate(directions)])
        x = (A.dot(p.reshape(-1, 2).T).T.ravel() + 100.0
             + noise * rng.standard_normal(p.size))
        verdict = check.frame(t, x, p)
        if verdict is not None:
            verdicts.append((t, verdict))
    return verdicts, check


LINE = [np.array([1.0, 0.3])] * 3                      # the start: every point along a line
SPREAD = [np.array([1.0, 0.0]), np.array([0.0, 1.0]), np.array([0.7, -0.7])]


@pytest.mark.parametrize("A", [0.3 * np.eye(2), 3.0 * turn(60.0), turn(-85.0),
                               np.diag([0.5, 2.0]), turn(40.0).dot(np.diag([0.7, 1.6]))])
@pytest.mark.parametrize("directions", [LINE, SPREAD])
@pytest.mark.parametrize("noise", [0.0, 1.0])
def test_a_guess_the_adaptation_can_mend_never_stops(A, directions, noise):
    # scales, stretches along the axes, turns of less than 90 degrees about the optical axis
    # and moderate mixes: the image moves the model's way (p^T A p > 0 for every p)
    verdicts, check = feed(A, directions, noise)
    assert verdicts == []
    assert check.fit[0] > 0.0


@pytest.mark.parametrize("A, directions", [
    (np.diag([-1.0, 1.0]), LINE),                      # one pixel axis the wrong way
    (np.diag([-1.0, 1.0]), [np.array([1.0, 0.0])] * 3),
    (2.0 * turn(135.0), SPREAD),                       # turned past 90 degrees
    (np.diag([1.0, -1.0]).dot(turn(20.0)), [np.array([0.2, 1.0])] * 3),
])
def test_frames_moving_against_the_model_stop_it_within_a_second_of_noisy_frames(A, directions):
    verdicts, _ = feed(A, directions, noise=1.0)
    assert verdicts, "no verdict"
    t, text = verdicts[0]
    assert t < 1.0
    assert "pixel_axes and pixel_origin" in text and "(reversed_motion)" in text


def test_no_verdict_before_enough_frames_or_without_motion():
    check = ReversedMotion(window=1.0, significance=5.0)
    p = np.zeros(6)
    for k in range(int(MIN_FRAMES) - 1):       # perfectly reversed, but too few frames
        p = p + 1.0
        assert check.frame(k / 30.0, -p, p) is None
    still = ReversedMotion(window=1.0, significance=5.0)
    rng = np.random.default_rng(1)
    for k in range(100):                        # the model's path does not move: noise only
        assert still.frame(k / 30.0, rng.standard_normal(6), np.zeros(6)) is None
    assert still.fit is None


def _iiwa(tmp_path, name, *overrides, duration=1.0):
    # the iiwa's guess with its u axis the wrong way (its picture kept in the image)
    scenario = load_scenario(IIWA, ["controller_node.initial_estimate.camera.pixel_axes=[-1, 1]",
                                    "controller_node.initial_estimate.camera.pixel_origin="
                                    "[640, 0]", *overrides])
    return run_scenario(scenario, str(tmp_path / name), duration, progress=False, record=False,
                        plots=False)


def test_a_divergence_from_a_mirrored_guess_points_at_the_guessed_camera(tmp_path):
    # the iiwa with a pixel axis of its guess turned diverges in 0.6 s, an estimate growing
    # first; the frames showed the reversed motion before that, and the reason says so
    summary = _iiwa(tmp_path, "mirrored")
    assert summary["diverged"]
    reason = summary["divergence_reason"]
    assert "grew first: a_z" in reason
    assert "the frames moved against the model's image motion from t=" in reason
    assert "pixel_axes, pixel_origin" in reason
    assert summary["reversed_motion_t"] < float(reason.split(" at t=")[1].split(";")[0])
    # the oracle: with the check off the same run diverges the same way, without the hint
    unchecked = _iiwa(tmp_path, "unchecked", "controller_node.reversed_motion=0")
    assert unchecked["divergence_reason"] == reason.split("; the frames moved")[0]
    assert np.isnan(unchecked["reversed_motion_t"])


def test_the_shipped_iiwa_sees_no_reversed_motion_with_a_clean_or_a_real_camera(tmp_path):
    for name, overrides in (("clean", ()), ("real", (
            "sim_node.camera_rate=30", "sim_node.camera_latency=0.033",
            "sim_node.pixel_noise_std=1.0", "controller_node.camera_rate=30",
            "controller_node.camera_latency=0.033"))):
        scenario = load_scenario(IIWA, list(overrides))
        summary = run_scenario(scenario, str(tmp_path / name), 2.0, progress=False,
                               record=False, plots=False)
        assert np.isnan(summary["reversed_motion_t"]) and not summary["diverged"], name
