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

"""The reference scenario in closed loop, and what ``vas run`` leaves behind."""

import json
import os

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from conftest import PAPER_CONFIG
from visual_adaptive_servo import cli
from visual_adaptive_servo.recording.recorder import TOPICS
from visual_adaptive_servo.runner import run_scenario

SUMMARY_KEYS = {"diverged", "final_rms_error_px", "max_error_px", "max_abs_torque",
                "final_depth_error", "sim_time_s", "wall_time_s", "realtime_factor"}


@pytest.fixture(scope="module")
def reference_run(tmp_path_factory, scenario):
    out = tmp_path_factory.mktemp("reference")
    return run_scenario(scenario, str(out), duration=30.0, progress=False, record=False,
                        plots=False), out


def test_reference_scenario_tracks_to_a_small_fraction_of_a_pixel(reference_run):
    summary, _ = reference_run
    assert not summary["diverged"]
    assert summary["sim_time_s"] == pytest.approx(30.0)
    assert summary["final_rms_error_px"] < 0.05
    assert summary["max_error_px"] < 2.0
    assert summary["rejected"] == 0


def test_reference_scenario_depth_estimate_stays_positive_and_near_truth(reference_run):
    summary, out = reference_run
    assert summary["min_estimated_depth"] > 0.5
    # the paper: the estimate approaches the actual depth but need not converge to it
    assert abs(summary["final_depth_error"]) < 2.0
    data = np.genfromtxt(os.path.join(out, "timeseries.csv"), delimiter=",", names=True)
    z, z_hat = data["z0"], data["z_hat0"]
    assert abs(z_hat[-1] - z[-1]) < abs(z_hat[0] - z[0])


def test_error_decreases_over_the_run(reference_run):
    _, out = reference_run
    data = np.genfromtxt(os.path.join(out, "timeseries.csv"), delimiter=",", names=True)
    err = np.hypot(data["x0"] - data["x_d0"], data["x1"] - data["x_d1"])
    t = data["t"]
    first, last = err[(t > 0.5) & (t < 5)], err[t >= 25]
    assert np.sqrt(np.mean(last**2)) < 0.25 * np.sqrt(np.mean(first**2))


def test_vas_run_writes_every_output_and_a_readable_mcap(tmp_path, capsys):
    out = tmp_path / "run"
    code = cli.main(["run", "--config", PAPER_CONFIG, "--out", str(out), "--duration", "1.0",
                     "--no-progress"])
    assert code == 0
    for name in ("summary.json", "timeseries.csv", "run.mcap", "tracking_error.png", "depth.png",
                 "torques.png", "parameters.png", "image_path.png"):
        assert (out / name).stat().st_size > 0, name
    summary = json.loads((out / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(summary)
    assert summary["sim_time_s"] == pytest.approx(1.0)
    with AnyReader([out / "run.mcap"]) as reader:
        found = {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}
        for topic in TOPICS:
            assert topic in found, topic
        assert found["/joint_states"] == ("sensor_msgs/msg/JointState", 200)
        conn = [c for c in reader.connections if c.topic == "/camera/features"]
        _, _, raw = next(reader.messages(connections=conn))
        msg = reader.deserialize(raw, conn[0].msgtype)
        assert len(msg.polygon.points) == 1
        assert msg.polygon.points[0].x == pytest.approx(65.0, abs=0.1)
    assert '"diverged": false' in capsys.readouterr().out


def test_vas_run_is_deterministic(tmp_path, scenario):
    a = run_scenario(scenario, str(tmp_path / "a"), duration=0.5, progress=False, record=False,
                     plots=False)
    b = run_scenario(scenario, str(tmp_path / "b"), duration=0.5, progress=False, record=False,
                     plots=False)
    assert (tmp_path / "a" / "timeseries.csv").read_text() == \
        (tmp_path / "b" / "timeseries.csv").read_text()
    assert a["final_rms_error_px"] == b["final_rms_error_px"]


def test_divergence_stops_early_and_still_writes_outputs(tmp_path):
    # the paper's gains with 1 px noise at 5 ms run away (DESIGN.md section 4)
    out = tmp_path / "div"
    code = cli.main(["run", "--config", PAPER_CONFIG, "--out", str(out), "--duration", "10",
                     "--pixel-noise", "1.0", "--no-progress", "--set",
                     "controller_node.torque_limit=[1e9, 1e9, 1e9]"])
    summary = json.loads((out / "summary.json").read_text())
    assert code == 1
    assert summary["diverged"] and "divergence_torque" in summary["divergence_reason"]
    assert summary["sim_time_s"] < 10.0
    with AnyReader([out / "run.mcap"]) as reader:
        assert sum(c.msgcount for c in reader.connections) > 0
    assert (out / "tracking_error.png").exists()


def test_exception_mid_run_still_writes_outputs(tmp_path, scenario):
    def explode(step, meas):
        if step == 50:
            raise RuntimeError("camera driver crashed")
        return meas

    summary = run_scenario(scenario, str(tmp_path), duration=1.0, progress=False, faults=explode)
    assert summary["error"] == "RuntimeError: camera driver crashed"
    assert summary["steps"] == 50
    with AnyReader([tmp_path / "run.mcap"]) as reader:
        assert {c.topic for c in reader.connections} >= set(TOPICS) - {"/diagnostics"}
    assert json.loads((tmp_path / "summary.json").read_text())["steps"] == 50


def test_ctrl_c_still_writes_outputs(tmp_path, scenario):
    def interrupt(step, meas):
        if step == 20:
            raise KeyboardInterrupt
        return meas

    summary = run_scenario(scenario, str(tmp_path), duration=1.0, progress=False,
                           faults=interrupt)
    assert summary["interrupted"] and summary["steps"] == 20
    assert (tmp_path / "timeseries.csv").exists() and (tmp_path / "run.mcap").exists()


@pytest.mark.parametrize("dropout, expected", [
    ("[0.0, 10.0]", "every sample was rejected"),
    ("[1.0, 10.0]", "no sample tracked after t=1.0"),
])
def test_a_run_that_does_not_track_says_so_and_fails(tmp_path, capsys, dropout, expected):
    # a camera that never delivers (or stops for good): every sample held, then the
    # fallback; such a run used to exit 0 with NaN figures and no word
    code = cli.main(["run", "--config", PAPER_CONFIG, "--out", str(tmp_path / "run"),
                     "--duration", "2.5", "--no-progress", "--no-bag",
                     "--set", f"sim_node.faults.dropout={dropout}"])
    err = capsys.readouterr().err
    assert code == 1
    assert f"NOT TRACKING: {expected}" in err and "(held, then the fallback torque)" in err
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert not summary["diverged"]


def test_a_short_camera_outage_is_not_a_run_that_did_not_track(tmp_path, capsys):
    code = cli.main(["run", "--config", PAPER_CONFIG, "--out", str(tmp_path / "run"),
                     "--duration", "2.5", "--no-progress", "--no-bag",
                     "--set", "sim_node.faults.dropout=[1.0, 0.5]"])
    assert code == 0 and "NOT TRACKING" not in capsys.readouterr().err


def test_a_detectors_reason_is_grouped_by_its_head():
    from visual_adaptive_servo.runner import reason_kind

    assert reason_kind("marker 1 missing: no pixel of its colour") == "marker 1 missing"
    assert reason_kind("tag 0 missing (ids found: none)") == "tag 0 missing (ids found: none)"
    assert reason_kind("tag 0 missing (ids found: 3): cut by the border") == \
        "tag 0 missing (ids found: 3)"
