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

"""The closed loop through a rendered camera and the feature detector (camera_mode rendered).

Oracles: the true projection at each frame's capture (detection error), the
noiseless tracking error, and the loop's recovery after the marker is hidden.
"""

import numpy as np

from conftest import PAPER_CONFIG
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.runner import run_scenario

RENDERED = ["sim_node.camera_mode=rendered", "sim_node.camera_rate=30.0"]


def test_rendered_camera_and_detector_close_the_loop(tmp_path):
    scenario = load_scenario(PAPER_CONFIG, RENDERED)
    assert scenario.detector is not None and scenario.detector.m == 1
    summary = run_scenario(scenario, str(tmp_path), duration=3.0, progress=False, record=False,
                           plots=False)
    assert not summary["diverged"]
    assert summary["frames_without_features"] == 0
    assert summary["frames_published"] == 90
    assert summary["detection_rms_px"] < 0.3
    assert summary["final_rms_true_error_px"] < 0.5


def test_an_occluded_marker_is_missed_then_the_loop_recovers(tmp_path):
    """0.3 s behind an occluder: no features, prediction then fallback, then recovery."""
    scenario = load_scenario(PAPER_CONFIG, RENDERED + ["sim_node.faults.occlusion=[2.0, 0.3]",
                                                       "controller_node.start_blend_time=2.0"])
    summary = run_scenario(scenario, str(tmp_path), duration=8.0, progress=False, record=False,
                           plots=False)
    assert not summary["diverged"]
    assert 8 <= summary["frames_without_features"] <= 10          # 30 Hz x 0.3 s
    assert "marker 1 missing" in summary["frames_without_features_by_reason"]
    assert summary["fallback"] > 0                                  # the camera went stale
    data = np.genfromtxt(tmp_path / "timeseries.csv", delimiter=",", names=True)
    err = np.hypot(data["x_true0"] - data["x_d0"], data["x_true1"] - data["x_d1"])
    late = data["t"] >= 6.0
    assert np.max(err[late]) < 1.0 and summary["max_abs_torque"] < 500.0
