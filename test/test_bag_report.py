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

"""``vas report``: a bag's figures against the run that recorded it.

The oracles are ``vas run``'s own outputs for the same run -- summary.json, and
timeseries.csv's noiseless pixels -- computed in-process from float64 arrays,
while the report reads only the messages (float32 pixels, nanosecond stamps).
Bags made here with rosbags' Writer cover what ``vas run`` never writes: a
rosbag2 folder in SQLite storage with its own receive times, gaps, warnings,
and topics missing.
"""

import json
import math
import os

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer

from conftest import PAPER_CONFIG, ROOT
from visual_adaptive_servo.cli import main
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.recording import messages as m
from visual_adaptive_servo.recording.bag_report import (
    BagError,
    bag_figures,
    read_bag,
    report_lines,
    write_report,
)
from visual_adaptive_servo.runner import run_scenario

PAPER_URDF = os.path.join(ROOT, "config", "paper_3dof_urdf.yaml")


@pytest.fixture(scope="module")
def noisy_run(tmp_path_factory):
    """The paper's scenario, 2 s, 0.3 px of noise: a frame at every sample, not late."""
    out = tmp_path_factory.mktemp("noisy")
    summary = run_scenario(load_scenario(PAPER_CONFIG, ["sim_node.pixel_noise_std=0.3"]),
                           str(out), duration=2.0, progress=False, plots=False)
    return out, summary


def test_a_recorded_run_reports_the_figures_of_its_summary(noisy_run):
    out, summary = noisy_run
    assert not summary["diverged"]
    figures = bag_figures(read_bag(out / "run.mcap"))
    # a frame at every sample and no latency: the frames' error at capture is summary.json's
    # measured error; x_d travels as float32 in the bag
    assert figures["final_rms_frame_error_px"] == pytest.approx(
        summary["final_rms_error_px"], abs=2e-4)
    assert figures["max_frame_error_px"] == pytest.approx(summary["max_error_px"], abs=2e-4)
    # and the law saw the frame itself
    assert figures["final_rms_tracking_error_px"] == pytest.approx(
        figures["final_rms_frame_error_px"], abs=1e-6)
    assert figures["max_abs_torque"] == summary["max_abs_torque"]
    assert figures["final_depth_error"] == summary["final_depth_error"]
    assert figures["min_estimated_depth"] == summary["min_estimated_depth"]
    assert figures["camera_frames"] == summary["frames_published"] == summary["steps"]
    assert figures["joint_states"] == summary["steps"]
    assert figures["joint_states_rate_hz"] == pytest.approx(200.0)
    assert figures["duration_s"] == pytest.approx(2.0 - 0.005)
    assert figures["commands_per_joint_state"] == 1.0
    assert figures["missing"] == []


def test_frames_are_judged_at_their_capture_time(tmp_path):
    """A 30 Hz camera 33 ms late, no noise: each frame's error is the true one at capture."""
    scenario = load_scenario(PAPER_URDF, [f"{node}.{name}={value}"
                                          for node in ("sim_node", "controller_node")
                                          for name, value in (("camera_rate", 30),
                                                              ("camera_latency", 0.033))])
    summary = run_scenario(scenario, str(tmp_path), duration=1.5, progress=False, plots=False)
    assert not summary["diverged"]
    data = np.genfromtxt(tmp_path / "timeseries.csv", delimiter=",", names=True)
    rec = read_bag(tmp_path / "run.mcap")
    figures = bag_figures(rec, window=1.0)
    frames = rec.signals["/camera/features"]
    assert figures["camera_frames"] == len(frames.t) == summary["frames_published"]
    assert figures["camera_frames_rate_hz"] == pytest.approx(30.0, rel=0.02)
    # the oracle: the noiseless pixels and x_d of the sample each frame was captured at,
    # for the frames captured once x_d is defined (the controller starts at the first)
    row = {round(t, 6): k for k, t in enumerate(data["t"])}
    t_capture = frames.t
    rows = [row[round(t, 6)] for t in t_capture]
    defined = np.isfinite(data["x_d0"][rows])
    assert 0 < np.count_nonzero(~defined) <= 2
    rows, t_capture = np.array(rows)[defined], t_capture[defined]
    err = np.hypot(data["x_true0"][rows] - data["x_d0"][rows],
                   data["x_true1"][rows] - data["x_d1"][rows])
    window = t_capture >= figures["duration_s"] - 1.0 + 1e-9
    assert figures["frame_errors"] == len(rows)
    assert figures["final_rms_frame_error_px"] == pytest.approx(
        np.sqrt(np.mean(err[window] ** 2)), abs=2e-4)
    assert figures["max_frame_error_px"] == pytest.approx(err.max(), abs=2e-4)
    # summary.json judges the frames so too, at their capture, over the last 5 s
    assert bag_figures(rec)["final_rms_frame_error_px"] == pytest.approx(
        summary["final_rms_error_px"], abs=2e-4)
    assert summary["max_error_px"] == pytest.approx(err.max(), abs=2e-4)
    # the frames' error is not the law's: that one is x_hat, the frame predicted to now
    assert figures["final_rms_tracking_error_px"] != pytest.approx(
        figures["final_rms_frame_error_px"], abs=1e-3)


def _rewrite(source, folder, storage, shift_ns=None, keep=None, drop=None):
    """The messages of ``source`` in a new rosbag2 ``folder``; receive times moved by topic.

    ``drop(topic, k)``: leave out the k-th message of the topic.
    """
    writer = Writer(folder, version=8, storage_plugin=storage)
    writer.open()
    typestore = m.rosbags_messages().typestore
    with AnyReader([source]) as reader:
        out = {}
        for conn in reader.connections:
            if keep is None or conn.topic in keep:
                out[conn.id] = writer.add_connection(conn.topic, conn.msgtype,
                                                     typestore=typestore)
        seen = {}
        for conn, time, raw in reader.messages():
            k = seen[conn.topic] = seen.get(conn.topic, -1) + 1
            if conn.id in out and not (drop and drop(conn.topic, k)):
                writer.write(out[conn.id], time + (shift_ns or {}).get(conn.topic, 0), raw)
    writer.close()
    return folder


def test_a_ros2_bag_folder_gives_the_figures_of_the_file(noisy_run, tmp_path):
    """SQLite storage, and the unstamped arrays received up to 0.4 ms after their partners."""
    out, _ = noisy_run
    original = bag_figures(read_bag(out / "run.mcap"))
    folder = _rewrite(out / "run.mcap", tmp_path / "bag", StoragePlugin.SQLITE3, {
        "/controller_node/estimated_depth": 300_000, "/controller_node/parameters": 400_000,
        "/sim_node/true_depth": -200_000})
    rec = read_bag(folder)
    # each array keeps its sample's stamp: the nearest partner, not the next sample's
    np.testing.assert_array_equal(rec.signals["/controller_node/estimated_depth"].t,
                                  rec.signals["/controller_node/observed"].t)
    figures = bag_figures(rec)
    assert {k: v for k, v in figures.items() if k != "bag"} == {
        k: v for k, v in original.items() if k != "bag"}


def _joint_state_bag(folder, stamps, diagnostics=()):
    """A bag of /joint_states at ``stamps`` [s] (and /diagnostics (t, level, message))."""
    msgs = m.rosbags_messages()
    writer = Writer(folder, version=8, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    joints = writer.add_connection("/joint_states", m.MESSAGE_TYPES["JointState"],
                                   typestore=msgs.typestore)
    diag = writer.add_connection("/diagnostics", m.MESSAGE_TYPES["DiagnosticArray"],
                                 typestore=msgs.typestore)
    for k, t in enumerate(stamps):
        msg = m.joint_state_to_msg(msgs, t, ["a", "b"], [0.1 * k, 0.0], [0.0, 0.0], [1.0, 2.0])
        writer.write(joints, int(t * 1e9), msgs.typestore.serialize_cdr(
            msg, m.MESSAGE_TYPES["JointState"]))
    for t, level, message in diagnostics:
        msg = m.diagnostics_to_msg(msgs, t, "controller_node", level, message)
        writer.write(diag, int(t * 1e9), msgs.typestore.serialize_cdr(
            msg, m.MESSAGE_TYPES["DiagnosticArray"]))
    writer.close()
    return folder


def test_gaps_warnings_and_missing_topics_are_reported(tmp_path):
    """A real arm's bag with a 40 ms hole in its joint states and a stale camera."""
    stamps = 1_700_000_000.0 + np.concatenate([np.arange(0, 0.5, 0.001),
                                               np.arange(0.54, 1.0, 0.001)])
    folder = _joint_state_bag(tmp_path / "arm", stamps, [
        (stamps[0], "OK", "ok"), (stamps[0] + 0.3, "WARN", "feature x: no camera frame for 0.1 s"),
        (stamps[0] + 0.35, "ERROR", "input bad or stale"), (stamps[0] + 0.6, "OK", "ok")])
    figures = bag_figures(read_bag(folder))
    assert figures["joint_states"] == len(stamps)
    assert figures["joint_states_largest_gap_s"] == pytest.approx(0.041, abs=1e-6)
    assert figures["joint_states_largest_gap_at_s"] == pytest.approx(0.54, abs=1e-6)
    assert figures["time_origin"] == "the first joint state"     # a wall clock's stamps
    status = figures["diagnostics"]["controller_node"]
    assert status["count"] == {"OK": 2, "WARN": 1, "ERROR": 1}
    # one problem from the WARN to the next OK, at its worst level
    [problem] = status["problems"]
    assert problem["start"] == pytest.approx(0.3, abs=1e-6)
    assert problem["end"] == pytest.approx(0.6, abs=1e-6)
    assert (problem["level"], problem["message"]) == ("ERROR", "input bad or stale")
    assert "/controller_node/tracking_error" in figures["missing"]
    assert "final_rms_frame_error_px" not in figures
    text = "\n".join(report_lines(figures))
    assert "largest gap 41.0 ms" in text
    assert "1 problem: ERROR t=0.300-0.600 s: input bad or stale" in text
    assert "not in the bag: /camera/features" in text
    written = write_report(read_bag(folder), tmp_path / "report")
    assert written["outputs"] == ["report.json", "timing.png", "diagnostics.png"]
    assert json.loads((tmp_path / "report" / "report.json").read_text())["joint_states"] \
        == len(stamps)


def test_the_command_writes_the_report_and_refuses_what_is_not_a_bag(noisy_run, tmp_path,
                                                                     capsys):
    out, _ = noisy_run
    assert main(["report", str(out / "run.mcap"), "--out", str(tmp_path / "r")]) == 0
    printed = capsys.readouterr().out
    assert "camera frames - x_d at their capture" in printed
    assert sorted(os.listdir(tmp_path / "r")) == sorted(
        ["report.json", "tracking_error.png", "depth.png", "torques.png", "parameters.png",
         "image_path.png", "timing.png", "diagnostics.png"])
    (tmp_path / "notes.txt").write_text("not a bag\n")
    assert main(["report", str(tmp_path / "notes.txt")]) == 2
    assert "notes.txt: not a readable rosbag2" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "nowhere")]) == 2
    assert "nowhere: no such bag" in capsys.readouterr().err
    assert not (tmp_path / "notes_report").exists()


def test_a_bag_without_the_package_topics_is_refused_by_name(tmp_path):
    msgs = m.rosbags_messages()
    writer = Writer(tmp_path / "other", version=8, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    conn = writer.add_connection("/chatter", m.MESSAGE_TYPES["Clock"], typestore=msgs.typestore)
    writer.write(conn, 1, msgs.typestore.serialize_cdr(m.clock_to_msg(msgs, 1.0),
                                                       m.MESSAGE_TYPES["Clock"]))
    writer.close()
    with pytest.raises(BagError, match=r"none of the package's topics.*\['/chatter'\]"):
        read_bag(tmp_path / "other")


def test_a_simulators_times_stay_its_own_when_the_recorder_missed_the_start(
        noisy_run, tmp_path):
    out, summary = noisy_run
    folder = _rewrite(out / "run.mcap", tmp_path / "late", StoragePlugin.MCAP,
                      drop=lambda topic, k: k < 10)
    figures = bag_figures(read_bag(folder))
    assert figures["time_origin"] == "simulated time"
    assert figures["start_s"] == pytest.approx(0.050)           # the 11th period, not 0
    assert figures["end_s"] == pytest.approx(2.0 - 0.005)
    assert figures["joint_states_first_at_s"] == pytest.approx(0.050)


def test_a_stall_shows_in_the_receive_times_and_missing_commands_are_counted(
        noisy_run, tmp_path):
    """A controller that stops answering for 20 periods while the simulator's stamps go on."""
    out, _ = noisy_run
    stall = range(100, 120)

    def drop(topic, k):
        return topic == "/controller_node/effort_command" and k in stall

    folder = _rewrite(out / "run.mcap", tmp_path / "stalled", StoragePlugin.MCAP,
                      drop=drop)
    figures = bag_figures(read_bag(folder))
    assert figures["joint_states_without_command"] == len(stall)
    assert figures["commands"] == 400 - len(stall)
    assert figures["commands_largest_gap_s"] == pytest.approx(0.005 * (len(stall) + 1))
    assert figures["commands_largest_gap_at_s"] == pytest.approx(0.005 * stall[-1] + 0.005)
    # the recorder's clock: a sim that stalls 0.5 s of wall time after its 200th period
    rec = read_bag(out / "run.mcap")
    late = rec.signals["/joint_states"].received >= rec.signals["/joint_states"].received[200]
    rec.signals["/joint_states"].received[late] += 500_000_000
    figures = bag_figures(rec)
    assert figures["joint_states_largest_gap_s"] == pytest.approx(0.005)   # stamps regular
    assert figures["joint_states_largest_received_gap_s"] == pytest.approx(0.505)
    assert figures["joint_states_largest_received_gap_at_s"] == pytest.approx(1.0)
    assert "as received, largest gap 505.0 ms (before t=1.000 s)" in "\n".join(
        report_lines(figures))


def test_unfinished_and_empty_bags_and_a_bad_window_are_refused_by_name(noisy_run, tmp_path):
    out, _ = noisy_run
    running = tmp_path / "running"
    running.mkdir()
    (running / "running_0.mcap").write_bytes((out / "run.mcap").read_bytes()[:5000])
    with pytest.raises(BagError, match=r"no metadata.yaml beside \['running_0.mcap'\]: the "
                       r"recording has not finished.*ros2 bag reindex"):
        read_bag(running)
    with pytest.raises(BagError, match=r"the file was not closed.*ros2 bag reindex"):
        read_bag(running / "running_0.mcap")
    (tmp_path / "empty").mkdir()
    with pytest.raises(BagError, match=r"not a rosbag2 \(no metadata.yaml, no .mcap or .db3"):
        read_bag(tmp_path / "empty")
    rec = read_bag(out / "run.mcap")
    for window in (0.0, -1.0, math.nan):
        with pytest.raises(BagError, match="window: expected a positive number of seconds"):
            bag_figures(rec, window)
    with pytest.raises(SystemExit):
        main(["report", str(out / "run.mcap"), "--window", "0"])
    # a window longer than the run is the whole run, and says so
    figures = bag_figures(rec, window=30.0)
    assert figures["window_s"] == pytest.approx(figures["duration_s"])
    assert "over the whole run (1.995 s)" in "\n".join(report_lines(figures))


def test_the_default_output_folder_is_the_bags_name_whole(noisy_run, tmp_path):
    out, _ = noisy_run
    for name in ("run.2026.12.07", "run.2026.12.08"):
        _rewrite(out / "run.mcap", tmp_path / name, StoragePlugin.MCAP)
        assert main(["report", str(tmp_path / name)]) == 0
        report = json.loads((tmp_path / f"{name}_report" / "report.json").read_text())
        assert report["bag"] == str(tmp_path / name)


def test_a_real_arms_subset_stamps_its_commands_by_the_joint_states(noisy_run, tmp_path):
    """Only /joint_states and /effort_controller/commands (no stamped copy of the commands)."""
    out, summary = noisy_run
    folder = _rewrite(out / "run.mcap", tmp_path / "subset", StoragePlugin.MCAP,
                      keep={"/joint_states", "/effort_controller/commands"})
    rec = read_bag(folder)
    np.testing.assert_array_equal(rec.signals["/effort_controller/commands"].t,
                                  rec.signals["/joint_states"].t)
    figures = bag_figures(rec)
    assert figures["commands"] == figures["joint_states"] == summary["steps"]
    assert figures["max_abs_torque"] == summary["max_abs_torque"]
    assert "joint_states_without_command" not in figures    # unstamped: not matched by stamp
    assert "/controller_node/effort_command" in figures["missing"]


def test_a_silent_topic_is_not_drawn_across():
    from visual_adaptive_servo.recording.plots import _broken

    t = np.concatenate([np.arange(0.0, 1.0, 0.01), np.arange(1.5, 2.0, 0.01)])
    values = np.ones((len(t), 2))
    t_drawn, drawn = _broken(t, values)
    gap = np.flatnonzero(np.isnan(drawn[:, 0]))
    assert len(gap) == 1 and 0.99 < t_drawn[gap[0]] < 1.5      # one break, inside the gap
    np.testing.assert_array_equal(t_drawn[~np.isnan(drawn[:, 0])], t)
    regular = values[:100]
    assert _broken(t[:100], regular)[1] is regular                # nothing to break


def test_a_backlog_keeps_its_stamps_and_lost_messages_are_named(noisy_run, tmp_path):
    """Arrays received 12 ms (2.4 periods) after their partners; then the last 50 lost."""
    out, _ = noisy_run
    original = read_bag(out / "run.mcap")
    late = _rewrite(out / "run.mcap", tmp_path / "late", StoragePlugin.MCAP, {
        "/controller_node/estimated_depth": 12_000_000})
    rec = read_bag(late)
    # as many as their partner's: one for one, whatever the receive times say
    np.testing.assert_array_equal(rec.signals["/controller_node/estimated_depth"].t,
                                  rec.signals["/controller_node/observed"].t)
    assert "lost_messages" not in bag_figures(rec)
    lost = _rewrite(out / "run.mcap", tmp_path / "lost", StoragePlugin.MCAP,
                    drop=lambda topic, k: topic == "/controller_node/estimated_depth" and k >= 350)
    figures = bag_figures(read_bag(lost))
    assert figures["lost_messages"] == {"/controller_node/estimated_depth": 50}
    assert ("/controller_node/estimated_depth: 50 message(s) fewer than "
            "/controller_node/observed" in "\n".join(report_lines(figures)))
    # the depth error at the last estimate's stamp (1.745 s), not the true depth's last
    z_hat = original.signals["/controller_node/estimated_depth"].values[349]
    z = original.signals["/sim_node/true_depth"].values[349]
    assert figures["final_depth_error"] == pytest.approx(float((z_hat - z)[0]), abs=1e-12)
