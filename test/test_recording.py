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

"""The MCAP recording: the messages, bytes and ros2-profile records of the recorder it replaced.

Oracle: :class:`ReferenceRecorder` is the recorder as it was before steps were
recorded a chunk at a time -- each message built by ``messages.sim_outputs`` /
``controller_outputs`` / ``diagnostics_to_msg``, serialised by the rosbags type
store and written by rosbags' ``Writer``.  Both record the same steps (a closed
loop with dropped frames, NaN bursts and rejected samples, and random steps
with NaN, inf and missing frames); every message must have the same channel,
times and bytes, in the same order, and schemas, channels, statistics and the
rosbag2 metadata must agree.  :func:`read_mcap` parses a file by the MCAP
specification and checks its summary, chunk and message indexes against the
records, which rosbags' reader does not use (``ros2 bag play`` does).
"""

import math
import os
import shutil
import struct
import tempfile
from collections import Counter
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import lz4.frame
import numpy as np
import pytest
import yaml
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer

from conftest import PAPER_CONFIG
from sim_bridge.simulator import Measurement, Simulator
from visual_adaptive_servo.recording import messages as m
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.control.controller import (
    AdaptiveVisualTracker,
    EstimatorState,
    health,
    StepResult,
)
from visual_adaptive_servo.recording.recorder import (
    CAMERA_TOPICS,
    CONTROLLER_NS,
    McapRecorder,
    SIM_NS,
    TOPICS,
)
from visual_adaptive_servo.runner import FrameDetections, run_scenario

MAGIC = b"\x89MCAP0\r\n"


class ReferenceRecorder:
    """The recorder before batching: one message object and one Writer.write per message."""

    def __init__(self, path, joint_names, model, camera=None):
        self.path, self.names = Path(path), list(joint_names)
        self.labels = m.parameter_labels(model)
        self.msgs = m.rosbags_messages()
        self.camera = camera
        self.tmp = Path(tempfile.mkdtemp(dir=self.path.parent))
        self.writer = Writer(self.tmp / self.path.stem, version=9,
                             storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        topics = dict(TOPICS, **(CAMERA_TOPICS if camera is not None else {}))
        self.connections = {topic: self.writer.add_connection(
            topic, m.MESSAGE_TYPES[short], typestore=self.msgs.typestore)
            for topic, short in topics.items()}

    def record_picture(self, meas):
        for topic, msg in m.camera_outputs(self.msgs, meas, self.camera):
            self.write(topic, meas.t, msg)

    def write(self, topic, t, msg):
        conn = self.connections[topic]
        self.writer.write(conn, int(round(t * 1e9)),
                          self.msgs.typestore.serialize_cdr(msg, conn.msgtype))

    def record(self, meas, res, diagnostics_due):
        t = meas.t
        for topic, msg in m.sim_outputs(self.msgs, meas, self.names):
            self.write(topic.replace("~", SIM_NS), t, msg)
        for topic, msg in m.controller_outputs(self.msgs, res, self.labels, self.names):
            self.write(topic.replace("~", CONTROLLER_NS), t, msg)
        if diagnostics_due:
            level, message, values = health(res)
            self.write("/diagnostics", t, m.diagnostics_to_msg(
                self.msgs, t, "controller_node", level, message, values, "controller"))

    def close(self):
        self.writer.close()
        os.replace(self.tmp / self.path.stem / f"{self.path.stem}.mcap", self.path)
        shutil.rmtree(self.tmp)


def test_the_minimal_type_store_has_the_jazzy_definitions():
    minimal = m.rosbags_messages_minimal().typestore
    jazzy = m.rosbags_messages().typestore
    names = set(m.JAZZY_DEFINITIONS) | {"builtin_interfaces/msg/Time"}
    assert set(m.MESSAGE_TYPES.values()) <= names
    for name in sorted(names):
        assert minimal.fielddefs[name] == jazzy.fielddefs[name], name
        assert minimal.generate_msgdef(name, ros_version=2) == jazzy.generate_msgdef(
            name, ros_version=2), name
        assert minimal.hash_rihs01(name) == jazzy.hash_rihs01(name), name


def records(data, start, end):
    """(offset, opcode, body) of the records in ``data[start:end]``."""
    at = start
    while at < end:
        opcode, length = struct.unpack_from("<BQ", data, at)
        yield at, opcode, data[at + 9:at + 9 + length]
        at += 9 + length
    assert at == end


def strings(body, at, count):
    """``count`` length-prefixed strings from ``body[at:]``; (list, next offset)."""
    out = []
    for _ in range(count):
        (length,) = struct.unpack_from("<I", body, at)
        out.append(body[at + 4:at + 4 + length])
        at += 4 + length
    return out, at


def read_mcap(path):
    """The content of an MCAP file, after checking its summary and indexes against its records.

    Returns a namespace: ``profile``, ``schemas`` and ``channels`` (id -> record
    body without the id), ``messages`` [(channel id, sequence, log time, publish
    time, data)] in file order, ``metadata`` {name: {key: value}} and
    ``statistics`` (the record's body).
    """
    data = Path(path).read_bytes()
    assert data[:8] == MAGIC and data[-8:] == MAGIC
    assert data[-37] == 0x02, "footer"
    summary_at, offsets_at, _ = struct.unpack_from("<QQI", data, len(data) - 28)
    out = SimpleNamespace(schemas={}, channels={}, messages=[], metadata={}, statistics=None)
    chunks, message_indexes = {}, {}

    def content(opcode, body, chunk_at=None, offset=None):
        if opcode == 0x03:
            out.schemas[struct.unpack_from("<H", body)[0]] = body[2:]
        elif opcode == 0x04:
            out.channels[struct.unpack_from("<H", body)[0]] = body[2:]
        elif opcode == 0x05:
            channel, sequence, log_time, publish_time = struct.unpack_from("<HIQQ", body)
            out.messages.append((channel, sequence, log_time, publish_time, body[22:]))
            chunks[chunk_at]["messages"][offset] = (channel, log_time)

    assert summary_at > 0
    for at, opcode, body in records(data, 8, summary_at):
        if opcode == 0x01:
            out.profile = strings(body, 0, 1)[0][0]
        elif opcode == 0x06:
            start, end, size, _ = struct.unpack_from("<QQQI", body)
            (compression,), pos = strings(body, 28, 1)
            (length,) = struct.unpack_from("<Q", body, pos)
            assert length == len(body) - pos - 8
            stored = body[pos + 8:]
            chunk_records = {b"": lambda data: data, b"lz4": lz4.frame.decompress}[compression](
                stored)
            assert len(chunk_records) == size
            chunks[at] = {"start": start, "end": end, "length": 9 + len(body), "messages": {},
                          "compression": compression, "sizes": (length, size)}
            for inner_at, inner_op, inner_body in records(chunk_records, 0, size):
                content(inner_op, inner_body, at, inner_at)
        elif opcode == 0x07:
            channel, size = struct.unpack_from("<HI", body)
            entries = np.frombuffer(body, "<u8", size // 8, 6).reshape(-1, 2)
            message_indexes[at] = (channel, entries, 9 + len(body))
        elif opcode == 0x0C:
            (name,), pos = strings(body, 0, 1)
            (size,) = struct.unpack_from("<I", body, pos)
            pairs, _ = strings(body[pos + 4:pos + 4 + size], 0, 2 * (size > 0))
            out.metadata[name.decode()] = {pairs[0].decode(): pairs[1].decode()}
        else:
            content(opcode, body)
    summary = {}
    for at, opcode, body in records(data, summary_at, offsets_at):
        summary.setdefault(opcode, []).append((at, body))
    for _, opcode, body in records(data, offsets_at, len(data) - 37):
        assert opcode == 0x0E
        group, start, length = struct.unpack_from("<BQQ", body)
        assert [a for a, _ in summary[group]][0] == start
        assert sum(9 + len(b) for _, b in summary[group]) == length

    # every chunk indexed, every message indexed once, at its record
    chunk_indexes = [body for _, body in summary.get(0x08, [])]
    assert len(chunk_indexes) == len(chunks)
    used = set()
    for body in chunk_indexes:
        start, end, chunk_at, chunk_length, size = struct.unpack_from("<QQQQI", body)
        chunk = chunks[chunk_at]
        assert (start, end, chunk_length) == (chunk["start"], chunk["end"], chunk["length"])
        offsets = dict(struct.iter_unpack("<HQ", body[36:36 + size]))
        (index_length,) = struct.unpack_from("<Q", body, 36 + size)
        assert index_length == sum(message_indexes[at][2] for at in offsets.values())
        (compression,), pos = strings(body, 44 + size, 1)
        assert compression == chunk["compression"]
        assert struct.unpack_from("<QQ", body, pos) == chunk["sizes"]
        indexed = {}
        for channel, at in offsets.items():
            assert message_indexes[at][0] == channel
            for log_time, offset in message_indexes[at][1]:
                indexed[int(offset)] = (channel, int(log_time))
        assert indexed == chunk["messages"]
        assert (min(t for _, t in indexed.values()), max(t for _, t in indexed.values())) == (
            start, end)
        used |= set(offsets.values())
    assert used == set(message_indexes)

    (out.statistics,) = [body for _, body in summary[0x0B]]
    count, schemas, channels, _, _, chunk_count, start, end, size = struct.unpack_from(
        "<QHIIIIQQI", out.statistics)
    assert (count, schemas, channels, chunk_count) == (
        len(out.messages), len(out.schemas), len(out.channels), len(chunks))
    per_channel = dict(struct.iter_unpack("<HQ", out.statistics[46:46 + size]))
    for channel in out.channels:
        assert per_channel[channel] == sum(msg[0] == channel for msg in out.messages)
    if out.messages:
        times = [msg[2] for msg in out.messages]
        assert (start, end) == (min(times), max(times))
    assert {struct.unpack_from("<H", b)[0]: b[2:] for _, b in summary[0x03]} == out.schemas
    assert {struct.unpack_from("<H", b)[0]: b[2:] for _, b in summary[0x04]} == out.channels
    return out


def assert_same_recording(ours, reference):
    """Same ros2-profile content and the same messages, in the same order."""
    a, b = read_mcap(ours), read_mcap(reference)
    assert a.profile == b.profile == b"ros2"
    assert a.schemas == b.schemas
    assert a.channels == b.channels
    assert len(a.messages) == len(b.messages)
    for i, (mine, theirs) in enumerate(zip(a.messages, b.messages)):
        assert mine == theirs, f"message {i}"
    # the same statistics but for the number of chunks (rosbags closes one at 1 MiB)
    assert a.statistics[:22] + a.statistics[26:] == b.statistics[:22] + b.statistics[26:]
    assert set(a.metadata) == set(b.metadata) == {"rosbag2"}
    assert (yaml.safe_load(a.metadata["rosbag2"]["serialized_metadata"])
            == yaml.safe_load(b.metadata["rosbag2"]["serialized_metadata"]))


def record_both(tmp_path, steps, joint_names, model, steps_per_chunk, camera=None):
    """Record ``steps`` [(meas, res, diagnostics_due[, picture])] with both recorders.

    ``picture``: the measurement with the rendered frame (before detection), for
    recorders made with a ``camera``.  Returns the two paths.
    """
    ours, reference = tmp_path / "ours" / "run.mcap", tmp_path / "reference" / "run.mcap"
    ours.parent.mkdir()
    reference.parent.mkdir()
    with McapRecorder(ours, joint_names, model, steps_per_chunk, camera=camera) as recorder:
        ref = ReferenceRecorder(reference, joint_names, model, camera=camera)
        for meas, res, due, *picture in steps:
            if picture:
                recorder.record_picture(picture[0])
                ref.record_picture(picture[0])
            recorder.record(meas, res, due)
            ref.record(meas, res, due)
        ref.close()
    return ours, reference


def closed_loop_steps(scenario, count, blind=range(0)):
    """(meas, res, diagnostics due) of a closed loop with dropped frames and NaN bursts.

    ``blind``: the periods with no frame at all (a tag nobody detects).
    """
    sim = Simulator(scenario.sim)
    ctl = AdaptiveVisualTracker(scenario.controller)
    steps, last = [], None
    try:
        for k in range(count):
            meas = sim.measure()
            if 40 <= k < 45 or k % 7 == 3 or k in blind:
                meas = replace(meas, pixels=None, feature_stamp=None)
            elif 60 <= k < 70 and meas.pixels is not None:
                meas = replace(meas, pixels=np.full_like(meas.pixels, np.nan))
            elif 80 <= k < 82:
                meas = replace(meas, q=np.full_like(meas.q, np.nan))
            res = ctl.step(meas.t, meas.q, meas.qd, meas.pixels, meas.feature_stamp)
            steps.append((meas, res, k % 50 == 0 or res.status != last))
            last = res.status
            sim.apply(res.tau)
    finally:
        sim.close()
    return steps


SLOW_CAMERA = ["sim_node.camera_rate=40", "sim_node.camera_latency=0.012"]
RENDERED = ["sim_node.camera_mode=rendered", "sim_node.camera_rate=50",
            "sim_node.camera_latency=0.01"]


def rendered_steps(scenario, count):
    """(meas after detection, res, diagnostics due, meas with the picture) of a rendered loop."""
    sim = Simulator(scenario.sim)
    ctl = AdaptiveVisualTracker(scenario.controller)
    detections = FrameDetections(scenario.detector)
    steps = []
    try:
        for k in range(count):
            picture = sim.measure()
            meas = detections.detect(picture) if picture.image is not None else picture
            res = ctl.step(meas.t, meas.q, meas.qd, meas.pixels, meas.feature_stamp)
            steps.append((meas, res, k % 50 == 0, picture))
            sim.apply(res.tau)
    finally:
        sim.close()
    return steps


def test_rendered_recording_adds_the_pictures_before_their_period_compressed(tmp_path):
    scenario = load_scenario(PAPER_CONFIG, RENDERED)
    steps = rendered_steps(scenario, 60)
    frames = sum(picture.image is not None for *_, picture in steps)
    assert frames == 15 and all(meas.pixels is not None for meas, *_, picture in steps
                                if picture.image is not None)
    ours, reference = record_both(tmp_path, steps, scenario.sim.joint_names,
                                  scenario.controller.model, steps_per_chunk=25,
                                  camera=scenario.sim.camera)
    assert_same_recording(ours, reference)
    content = read_mcap(ours)
    # a channel's body after its id: schema id, topic, ...
    channels = {cid: strings(rest, 2, 1)[0][0].decode() for cid, rest in content.channels.items()}
    topics = [channels[msg[0]] for msg in content.messages]
    assert topics.count("/camera/image_raw") == topics.count("/camera/camera_info") == frames
    # each picture right before its period's messages, CameraInfo after it, then the features
    for i, topic in enumerate(topics):
        if topic == "/camera/image_raw":
            assert topics[i + 1:i + 4] == ["/camera/camera_info", "/camera/features", "/clock"]
    # the pictures make the file 100x smaller than their pixels (LZ4 chunks)
    assert os.path.getsize(ours) < frames * 640 * 480 * 3 / 50


@pytest.mark.parametrize("camera", [[], SLOW_CAMERA],
                         ids=["frame every period", "40 Hz camera, 12 ms latency"])
def test_closed_loop_recording_is_message_for_message_the_reference(tmp_path, camera):
    scenario = load_scenario(PAPER_CONFIG, camera)
    steps = closed_loop_steps(scenario, 300)
    assert {res.status for _, res, _ in steps} >= {"ok", "hold"}
    assert any(meas.pixels is None for meas, _, _ in steps)
    ours, reference = record_both(tmp_path, steps, scenario.sim.joint_names,
                                  scenario.controller.model, steps_per_chunk=64)
    assert_same_recording(ours, reference)


def test_a_chunk_without_any_frame_is_recorded_as_the_reference_does(tmp_path):
    # a tag never detected for a whole chunk: no /camera/features (and, the controller
    # holding, no ~/desired nor ~/tracking_error) in any of its periods; this raised
    # "cannot reshape array of size 0" and lost the rest of the recording
    scenario = load_scenario(PAPER_CONFIG)
    steps = closed_loop_steps(scenario, 250, blind=range(100, 200))
    assert not any(meas.pixels is not None for meas, _, _ in steps[100:200])
    ours, reference = record_both(tmp_path, steps, scenario.sim.joint_names,
                                  scenario.controller.model, steps_per_chunk=50)
    assert_same_recording(ours, reference)


def random_step(rng, k, n, model):
    """A Measurement and StepResult with random values, NaN, inf, -0.0 and missing frames."""
    m2 = 2 * model.m

    def values(size, bad=0.1):
        v = rng.normal(scale=rng.choice([1e-3, 1.0, 1e3]), size=size)
        if rng.random() < bad:
            v[rng.integers(size)] = rng.choice([np.nan, np.inf, -np.inf, -0.0, 1e300])
        return v

    def pixels(missing=0.0):
        if rng.random() < missing:
            return None
        return np.where(rng.random(m2) < 0.1, np.nan, rng.uniform(-1e4, 1e4, m2))

    t = k * 0.005 + rng.uniform(0, 1e-3)
    seen = pixels(missing=0.3)
    meas = Measurement(t, values(n), values(n), values(n), None if seen is None else t / 2,
                       seen, values(model.m), pixels(), ())
    state = EstimatorState(pixels(), values(model.p_perp), values(model.p_z), values(model.p_d))
    res = StepResult(t, values(n), pixels(), pixels(), pixels(), values(model.m), state,
                     rng.choice(["ok", "hold", "fallback"]), ("a reason",) * rng.integers(2),
                     bool(rng.random() < 0.5), sigma_min=float(rng.uniform()))
    return meas, res, bool(rng.random() < 0.2)


@pytest.mark.parametrize("n, m_points", [(3, 1), (6, 3)])
def test_random_steps_give_the_bytes_of_the_message_builders(tmp_path, rng, n, m_points):
    model = SimpleNamespace(m=m_points, p_perp=2 * m_points, p_z=3, p_d=1,
                            a_z_perp_labels=[f"p{i}" for i in range(2 * m_points)],
                            a_z_labels=["z0", "z1", "z2"], a_d_labels=["d"])
    steps = [random_step(rng, k, n, model) for k in range(250)]
    ours, reference = record_both(tmp_path, steps, [f"joint{i}" for i in range(n)], model,
                                  steps_per_chunk=40)
    assert_same_recording(ours, reference)
    # messages left out (no frame, NaN pixels, x_d or error not finite) were among the cases
    channels = list(TOPICS)
    counts = Counter(channels[msg[0] - 1] for msg in read_mcap(reference).messages)
    for topic in ("/camera/features", f"{CONTROLLER_NS}/desired",
                  f"{CONTROLLER_NS}/tracking_error"):
        assert 0 < counts[topic] < len(steps), topic
    assert counts["/joint_states"] == len(steps)


def test_a_point_too_large_for_float32_is_refused_as_by_the_type_store(tmp_path, scenario):
    meas, res, _ = closed_loop_steps(scenario, 1)[0]
    res = replace(res, x_obs=np.array([1e39, 0.0]))
    names, model = scenario.sim.joint_names, scenario.controller.model
    with pytest.raises(OverflowError, match="float too large to pack"):
        ReferenceRecorder(tmp_path / "ref.mcap", names, model).record(meas, res, False)
    recorder = McapRecorder(tmp_path / "ours.mcap", names, model)
    recorder.record(meas, res, False)
    with pytest.raises(OverflowError, match="float too large to pack"):
        recorder.flush()
    recorder.close()
    assert read_mcap(tmp_path / "ours.mcap").messages == []


class InterruptedWrite:
    """A file whose first large write stops halfway with KeyboardInterrupt (Ctrl-C)."""

    def __init__(self, out):
        self.out, self.armed = out, True

    def write(self, data):
        if self.armed and len(data) > 10_000:
            self.armed = False
            self.out.write(data[:len(data) // 2])
            raise KeyboardInterrupt
        return self.out.write(data)

    def __getattr__(self, name):
        return getattr(self.out, name)


def test_ctrl_c_while_a_chunk_is_written_leaves_a_valid_file_of_the_chunks_before(
        tmp_path, scenario):
    steps = closed_loop_steps(scenario, 250)
    path = tmp_path / "run.mcap"
    recorder = McapRecorder(path, scenario.sim.joint_names, scenario.controller.model,
                            steps_per_chunk=100)
    for meas, res, due in steps[:150]:
        recorder.record(meas, res, due)
    recorder.file._out = InterruptedWrite(recorder.file._out)
    with pytest.raises(KeyboardInterrupt):
        for meas, res, due in steps[150:]:
            recorder.record(meas, res, due)
    recorder.close()
    content = read_mcap(path)
    times = sorted({msg[2] for msg in content.messages})
    # the first chunk, and the interrupted one written again by close
    assert len(times) == 200 and times[-1] == int(round(steps[199][0].t * 1e9))
    with AnyReader([path]) as reader:
        assert sum(c.msgcount for c in reader.connections) == len(content.messages)


def test_the_file_gets_the_permissions_of_any_new_file(tmp_path, scenario):
    umask = os.umask(0o022)
    try:
        with McapRecorder(tmp_path / "run.mcap", scenario.sim.joint_names,
                          scenario.controller.model):
            pass
        (tmp_path / "plain").touch()
    finally:
        os.umask(umask)
    assert (tmp_path / "run.mcap").stat().st_mode == (tmp_path / "plain").stat().st_mode
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain", "run.mcap"]


def test_recorded_run_decodes_to_its_timeseries(tmp_path, scenario):
    summary = run_scenario(scenario, str(tmp_path), duration=2.0, progress=False, plots=False)
    steps = summary["steps"]
    data = np.genfromtxt(tmp_path / "timeseries.csv", delimiter=",", names=True)
    read_mcap(tmp_path / "run.mcap")
    with AnyReader([tmp_path / "run.mcap"]) as reader:
        by_topic = {}
        for conn, timestamp, raw in reader.messages():
            by_topic.setdefault(conn.topic, []).append(
                (timestamp, reader.deserialize(raw, conn.msgtype)))

    def cols(*names):
        return np.column_stack([data[name] for name in names])

    t = data["t"]
    for topic in set(TOPICS) - {"/diagnostics"}:
        times = np.array([ts for ts, _ in by_topic[topic]])
        np.testing.assert_array_equal(times, np.rint(t * 1e9).astype(np.int64), err_msg=topic)
    assert len(by_topic["/diagnostics"]) == math.ceil(steps / 200)

    def floats(topic, field):
        return np.array([np.asarray(getattr(msg, field), dtype=float)
                         for _, msg in by_topic[topic]])

    def points(topic):
        return np.array([[c for p in msg.polygon.points for c in (p.x, p.y)]
                         for _, msg in by_topic[topic]])

    def stamps(topic, get=lambda msg: msg.header.stamp):
        return np.array([get(msg).sec + get(msg).nanosec * 1e-9 for _, msg in by_topic[topic]])

    np.testing.assert_allclose(stamps("/clock", lambda msg: msg.clock), t, atol=1e-9)
    np.testing.assert_allclose(stamps("/joint_states"), t, atol=1e-9)
    np.testing.assert_allclose(floats("/joint_states", "position"), cols("q0", "q1", "q2"),
                               rtol=1e-9)
    np.testing.assert_allclose(floats("/joint_states", "velocity"), cols("qd0", "qd1", "qd2"),
                               rtol=1e-9, atol=1e-12)
    # the effort applied during a period is the command of the period before
    np.testing.assert_allclose(floats("/joint_states", "effort")[1:],
                               cols("tau0", "tau1", "tau2")[:-1], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(floats("/effort_controller/commands", "data"),
                               cols("tau0", "tau1", "tau2"), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(floats(f"{SIM_NS}/true_depth", "data"), cols("z0"), rtol=1e-9)
    np.testing.assert_allclose(floats(f"{CONTROLLER_NS}/estimated_depth", "data"),
                               cols("z_hat0"), rtol=1e-9)
    params = [n for n in data.dtype.names if n.split("_")[0] == "a"]
    np.testing.assert_allclose(floats(f"{CONTROLLER_NS}/parameters", "data"), cols(*params),
                               rtol=1e-9, atol=1e-12)
    # Point32 is float32: 65 px to 4e-6 px
    np.testing.assert_allclose(points("/camera/features"), cols("x0", "x1"), atol=1e-5)
    np.testing.assert_allclose(points(f"{CONTROLLER_NS}/desired"), cols("x_d0", "x_d1"),
                               atol=1e-5)
    np.testing.assert_allclose(points(f"{CONTROLLER_NS}/observed"), cols("x_obs0", "x_obs1"),
                               atol=1e-5)
    np.testing.assert_allclose(points(f"{CONTROLLER_NS}/tracking_error"),
                               cols("x0", "x1") - cols("x_d0", "x_d1"), atol=1e-5)
    np.testing.assert_allclose(stamps(f"{CONTROLLER_NS}/desired"), t, atol=1e-9)


def test_rendered_run_records_the_pictures_the_detector_saw(tmp_path):
    """Oracle: the detector, run again on the recorded pictures, gives the recorded features."""
    from visual_adaptive_servo.vision.detection import detect

    scenario = load_scenario(PAPER_CONFIG, RENDERED)
    summary = run_scenario(scenario, str(tmp_path), duration=0.3, progress=False, plots=False)
    assert not summary["diverged"] and summary["frames_published"] == 15
    by_topic = {}
    with AnyReader([tmp_path / "run.mcap"]) as reader:
        for conn, _, raw in reader.messages():
            by_topic.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    images, infos = by_topic["/camera/image_raw"], by_topic["/camera/camera_info"]
    features = by_topic["/camera/features"]
    assert len(images) == len(infos) == len(features) == 15
    camera = scenario.sim.camera
    for image, info, feature in zip(images, infos, features):
        assert (image.height, image.width, image.encoding) == (480, 640, "rgb8")
        assert image.header.stamp == info.header.stamp == feature.header.stamp
        np.testing.assert_allclose(info.k, [camera.fx, 0, camera.cx, 0, camera.fy, camera.cy,
                                            0, 0, 1])
        stamp, rgb = m.image_from_msg(image)
        assert stamp == m.stamp_to_time(feature.header.stamp)
        found = detect(rgb, scenario.detector)
        recorded = [c for p in feature.polygon.points for c in (p.x, p.y)]
        np.testing.assert_allclose(found.pixels, recorded, atol=1e-4)
