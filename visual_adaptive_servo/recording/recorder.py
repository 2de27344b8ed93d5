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

"""Recording a run: a rosbag2 MCAP file with the nodes' topics, a CSV and summary.json.

The MCAP file holds the same topics and message types the ROS nodes publish
(DESIGN.md section 2), with the bytes the nodes' conversion functions and the
rosbags type store give, so ``ros2 bag info/play``, Foxglove and PlotJuggler
open it.

Where the time goes: a 30 s run is 6000 control periods of ten messages each.
Building each message object, serialising it with the type store and
rosbags' ``Writer.write`` doubled the run's wall time.  So the recorder
copies each period's numbers into a buffer and, a chunk at a time, turns
them into CDR bytes for all messages at once (:class:`messages.CdrLayout`,
probed from the messages ``sim_outputs``/``controller_outputs`` build) and
writes the chunk whole (:class:`McapFile`, the records rosbags' Writer
writes).

In rendered mode the pictures are recorded too (``/camera/image_raw``,
``/camera/camera_info``): 0.9 MB per 640x480 frame, so chunks holding
pictures are LZ4-compressed (the simulated scene's large even areas compress
about 190x at 0.2 ms per frame; lz4 comes with rosbags) and written when
:data:`PICTURE_CHUNK_BYTES` of pictures are pending.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import os
import struct
from pathlib import Path
from types import SimpleNamespace

import lz4.frame
import numpy as np
import yaml

from . import messages as m
from ..control.controller import health

log = logging.getLogger(__name__)

SIM_NS = "/sim_node"
CONTROLLER_NS = "/controller_node"

TOPICS = {
    "/clock": "Clock",
    "/joint_states": "JointState",
    "/camera/features": "PolygonStamped",
    "/effort_controller/commands": "Float64MultiArray",
    f"{SIM_NS}/true_depth": "Float64MultiArray",
    f"{CONTROLLER_NS}/desired": "PolygonStamped",
    f"{CONTROLLER_NS}/observed": "PolygonStamped",
    f"{CONTROLLER_NS}/tracking_error": "PolygonStamped",
    f"{CONTROLLER_NS}/estimated_depth": "Float64MultiArray",
    f"{CONTROLLER_NS}/parameters": "Float64MultiArray",
    f"{CONTROLLER_NS}/effort_command": "JointState",
    "/diagnostics": "DiagnosticArray",
}

# rendered mode: the frame's picture, published by sim_node before the joint state
CAMERA_TOPICS = {"/camera/image_raw": "Image", "/camera/camera_info": "CameraInfo"}
PICTURE_CHUNK_BYTES = 64 << 20    # uncompressed picture bytes per chunk, at most about

MAGIC = b"\x89MCAP0\r\n"
# Message record: opcode, record length, channel id, sequence, log time, publish time, data
MESSAGE_HEAD = struct.Struct("<BQHIQQ")
LOG_TIME_AT = 15  # byte offsets of the two times in MESSAGE_HEAD
PUBLISH_TIME_AT = 23


def _string(text):
    data = text.encode()
    return struct.pack("<I", len(data)) + data


def _record(opcode, body):
    return struct.pack("<BQ", opcode, len(body)) + body


class McapFile:
    """An MCAP file of the ros2 profile, with the records rosbags' Writer writes.

    Schemas (ros2msg definitions and RIHS01 hashes from the type store),
    channels (cdr, ``offered_qos_profiles`` metadata), a ``rosbag2`` metadata
    record with the bag's metadata.yaml, chunk and message indexes, statistics
    and summary offsets.  Messages come as whole chunks of ready message
    records (:meth:`write_chunk`).  The file is written next to ``path`` and
    moved there by :meth:`close`; a write cut short (Ctrl-C) is undone, so the
    file can still be finished.
    """

    def __init__(self, path):
        self.path = Path(path)
        # a plain open, not tempfile's: the file gets the permissions the umask gives
        self._tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.part")
        self._out = open(self._tmp, "wb")
        self._out.write(MAGIC + _record(0x01, _string("ros2") + _string("visual_adaptive_servo")))
        self._end = self._out.tell()  # end of the last whole record
        self.schemas = {}             # msgtype -> (schema id, schema record body)
        self.channels = []            # (channel id, topic, msgtype, RIHS01, record body)
        self.counts = {}              # channel id -> messages
        self.chunk_indexes = []
        self.start, self.end = None, None

    def add_channel(self, topic, msgtype, typestore):
        """Register ``topic`` (and its type's schema once); return the channel id."""
        if msgtype not in self.schemas:
            msgdef, _ = typestore.generate_msgdef(msgtype, ros_version=2)
            body = (struct.pack("<H", len(self.schemas) + 1) + _string(msgtype)
                    + _string("ros2msg") + _string(msgdef))
            self.schemas[msgtype] = (len(self.schemas) + 1, body)
            self._write(_record(0x03, body))
        channel_id = len(self.channels) + 1
        metadata = _string("offered_qos_profiles") + _string("[]")
        body = (struct.pack("<HH", channel_id, self.schemas[msgtype][0]) + _string(topic)
                + _string("cdr") + struct.pack("<I", len(metadata)) + metadata)
        self.channels.append((channel_id, topic, msgtype, typestore.hash_rihs01(msgtype), body))
        self.counts[channel_id] = 0
        self._write(_record(0x04, body))
        return channel_id

    def write_chunk(self, records, index, compress=False):
        """Write one chunk of message ``records`` and its message indexes.

        ``records``: the message records, as one bytes-like object or a list of
        them (written one after the other, so that a chunk of megabytes is not
        copied into one more buffer); ``index`` maps each channel id with
        messages in the chunk to (log times (P,) ns, offsets (P,) of its records
        in ``records``); ``compress``: store the records LZ4-compressed (the
        offsets stay those in the uncompressed records, as MCAP defines them).
        """
        pieces = records if isinstance(records, list) else [records]
        size = sum(memoryview(piece).nbytes for piece in pieces)
        start = min(int(times.min()) for times, _ in index.values())
        end = max(int(times.max()) for times, _ in index.values())
        if compress:
            compression, stored = "lz4", [lz4.frame.compress(b"".join(pieces))]
        else:
            compression, stored = "", pieces
        stored_size = sum(memoryview(piece).nbytes for piece in stored)
        body = (struct.pack("<QQQI", start, end, size, 0) + _string(compression)
                + struct.pack("<Q", stored_size))
        head = struct.pack("<BQ", 0x06, len(body) + stored_size) + body
        chunk_at, chunk_size = self._end, len(head) + stored_size
        indexes, offsets, at = [], [], chunk_at + chunk_size
        for channel_id, (times, where) in sorted(index.items()):
            entries = np.column_stack([times, where]).astype("<u8").tobytes()
            indexes.append(_record(0x07, struct.pack("<HI", channel_id, len(entries)) + entries))
            offsets.append(struct.pack("<HQ", channel_id, at))
            at += len(indexes[-1])
        self._write([head, *stored, b"".join(indexes)])
        offsets = b"".join(offsets)
        self.chunk_indexes.append(
            struct.pack("<QQQQI", start, end, chunk_at, chunk_size, len(offsets)) + offsets
            + struct.pack("<Q", at - chunk_at - chunk_size) + _string(compression)
            + struct.pack("<QQ", stored_size, size))
        for channel_id, (times, _) in index.items():
            self.counts[channel_id] += len(times)
        self.start = start if self.start is None else min(self.start, start)
        self.end = end if self.end is None else max(self.end, end)

    def close(self):
        """Write metadata, summary and footer and move the file to ``path``."""
        if self._out is None:
            return
        try:
            self._write_summary()
            self._out.close()
            os.replace(self._tmp, self.path)
        except BaseException:
            self.discard()
            raise
        self._out = None

    def discard(self):
        """Close and delete the unfinished file."""
        if self._out is not None:
            self._out.close()
            self._out = None
            self._tmp.unlink(missing_ok=True)

    def _write(self, data):
        """Append ``data`` (bytes-like, or a list of them) to the file, all of it or nothing."""
        pieces = data if isinstance(data, list) else [data]
        try:
            for piece in pieces:
                self._out.write(piece)
        except BaseException:
            # a write cut short (Ctrl-C) is undone: the file ends with whole records
            self._out.seek(self._end)
            self._out.truncate()
            raise
        self._end = self._out.tell()

    def _write_summary(self):
        pairs = _string("serialized_metadata") + _string(self._bag_metadata())
        metadata_at = self._end
        self._write(_record(0x0C, _string("rosbag2") + struct.pack("<I", len(pairs)) + pairs))
        metadata_length = self._end - metadata_at
        self._write(_record(0x0F, struct.pack("<I", 0)))
        groups = []

        def group(opcode, records):
            at = self._end
            self._write(b"".join(_record(opcode, body) for body in records))
            groups.append(struct.pack("<BQQ", opcode, at, self._end - at))

        summary_at = self._end
        group(0x03, [body for _, body in self.schemas.values()])
        group(0x04, [channel[-1] for channel in self.channels])
        if self.chunk_indexes:
            group(0x08, self.chunk_indexes)
        group(0x0D, [struct.pack("<QQ", metadata_at, metadata_length) + _string("rosbag2")])
        counts = b"".join(struct.pack("<HQ", cid, n) for cid, n in sorted(self.counts.items()))
        group(0x0B, [struct.pack("<QHIIIIQQI", sum(self.counts.values()), len(self.schemas),
                                 len(self.channels), 0, 1, len(self.chunk_indexes),
                                 self.start or 0, self.end or 0, len(counts)) + counts])
        offsets_at = self._end
        self._write(b"".join(_record(0x0E, body) for body in groups))
        self._write(_record(0x02, struct.pack("<QQI", summary_at, offsets_at, 0)) + MAGIC)

    def _bag_metadata(self):
        """The rosbag2 metadata.yaml (version 9) rosbags' Writer would write for this bag."""
        count = sum(self.counts.values())
        start = self.start or 0
        duration = (self.end or 0) - start
        return yaml.safe_dump({
            "version": 9, "storage_identifier": "mcap", "relative_file_paths": [self.path.name],
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start}, "message_count": count,
            "topics_with_message_count": [
                {"topic_metadata": {"name": topic, "type": msgtype, "serialization_format": "cdr",
                                    "offered_qos_profiles": [],
                                    "type_description_hash": digest},
                 "message_count": self.counts[cid]}
                for cid, topic, msgtype, digest, _ in self.channels],
            "compression_format": "", "compression_mode": "",
            "files": [{"path": self.path.name, "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": duration}, "message_count": count}],
            "custom_data": None, "ros_distro": "rosbags",
        }, default_flow_style=False).strip()


class McapRecorder:
    """Record what sim_node and controller_node publish each control period into ``path``.

    One :meth:`record` call per period copies the period's numbers into a
    buffer of ``steps_per_chunk`` rows.  A full buffer is written as one MCAP
    chunk before the next period is added (and by :meth:`flush` and
    :meth:`close`): the numbers of every topic
    (:func:`messages.sim_output_arrays`, :func:`messages.controller_output_arrays`)
    put into the CDR bytes of the message ``sim_outputs``/``controller_outputs``
    build for sentinel values (:class:`messages.CdrLayout`).  /diagnostics
    (1 Hz and on a status change) is built and serialised message by message,
    with a type store of the recorded types only
    (:func:`messages.rosbags_messages_minimal`).  With a ``camera`` (rendered
    mode) :meth:`record_picture` adds each frame's picture and CameraInfo
    before its period.  Use as a context manager; the file is complete after
    :meth:`close` also when a run fails.
    """

    def __init__(self, path, joint_names, model, steps_per_chunk=1000, camera=None):
        self.msgs = m.rosbags_messages_minimal()
        n, m2, m1 = len(joint_names), 2 * model.m, model.m
        # the fields of Measurement and StepResult that sim_outputs/controller_outputs read;
        # shapes as tuples: numpy 1.x reads an integer 1 as a scalar field (m = 1 depths)
        self._meas = np.empty(steps_per_chunk, dtype=[
            ("t", "f8"), ("q", "f8", (n,)), ("qd", "f8", (n,)), ("tau_applied", "f8", (n,)),
            ("feature_stamp", "f8"), ("pixels", "f8", (m2,)), ("true_depth", "f8", (m1,))])
        self._res = np.empty(steps_per_chunk, dtype=[
            ("t", "f8"), ("tau", "f8", (n,)), ("x_d", "f8", (m2,)), ("x_obs", "f8", (m2,)),
            ("error", "f8", (m2,)), ("z_hat", "f8", (m1,)), ("a_z_perp", "f8", (model.p_perp,)),
            ("a_z", "f8", (model.p_z,)), ("a_d", "f8", (model.p_d,))])
        self._count = 0
        self._diagnostics = {}  # row -> CDR of /diagnostics
        self._pictures = {}     # row -> [(topic, CDR)] of the frame published before it
        self._picture_bytes = 0
        self.camera = camera
        self.file = McapFile(path)
        topics = dict(TOPICS, **(CAMERA_TOPICS if camera is not None else {}))
        try:
            self.channels = {topic: self.file.add_channel(topic, m.MESSAGE_TYPES[short],
                                                          self.msgs.typestore)
                             for topic, short in topics.items()}
            self._layouts = self._probe(list(joint_names), model)
        except BaseException:
            self.file.discard()
            raise

    def record(self, meas, res, diagnostics_due):
        """Add one control period: the measurement ``meas``, the controller's ``res``."""
        if self._count == len(self._meas):
            self.flush()
        k = self._count
        self._store(k, meas, res)
        if diagnostics_due:
            level, message, values = health(res)
            msg = m.diagnostics_to_msg(self.msgs, meas.t, "controller_node", level, message,
                                       values, "controller")
            self._diagnostics[k] = bytes(self.msgs.typestore.serialize_cdr(
                msg, m.MESSAGE_TYPES["DiagnosticArray"]))
        self._count = k + 1

    def record_picture(self, meas):
        """Add the rendered frame of ``meas`` (its picture, before detection) to the next period.

        Call before :meth:`record` of the same period; nothing without a picture.
        """
        if meas.image is None:
            return
        if self.camera is None:
            raise ValueError("McapRecorder: record_picture needs the recorder made with camera=")
        if self._count == len(self._meas) or self._picture_bytes >= PICTURE_CHUNK_BYTES:
            self.flush()
        serialize = self.msgs.typestore.serialize_cdr
        pictures = [(topic, bytes(serialize(msg, m.MESSAGE_TYPES[CAMERA_TOPICS[topic]])))
                    for topic, msg in m.camera_outputs(self.msgs, meas, self.camera)]
        self._pictures[self._count] = pictures
        self._picture_bytes += sum(len(cdr) for _, cdr in pictures)

    def flush(self):
        """Write the recorded periods as one chunk (nothing if there are none)."""
        if self._count == 0:
            return
        records, index = self._chunk(*self._stacked(self._count))
        self.file.write_chunk(records, index, compress=bool(self._pictures))
        self._count, self._diagnostics, self._pictures, self._picture_bytes = 0, {}, {}, 0

    def close(self):
        """Write the recorded periods and finish the file.

        A failure to write the periods is logged, not raised: close runs while
        a run ends, possibly on another error, and the file must be finished
        either way (call :meth:`flush` first to see the error).
        """
        try:
            self.flush()
        except Exception:  # noqa: BLE001 -- the file is finished below either way
            log.exception("recording: the last %d periods could not be written", self._count)
        finally:
            self.file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _store(self, k, meas, res):
        frame = meas.pixels is not None
        self._meas[k] = (meas.t, meas.q, meas.qd, meas.tau_applied,
                         meas.feature_stamp if frame else np.nan,
                         meas.pixels if frame else np.nan, meas.true_depth)
        st = res.state
        self._res[k] = (res.t, res.tau, res.x_d, res.x_obs, res.error, res.z_hat,
                        st.a_z_perp, st.a_z, st.a_d)

    def _stacked(self, count):
        """The first ``count`` rows as a Measurement and a StepResult of (count, ...) arrays."""
        meas, res = self._meas[:count], self._res[:count]
        state = SimpleNamespace(a_z_perp=res["a_z_perp"], a_z=res["a_z"], a_d=res["a_d"])
        return (SimpleNamespace(**{name: meas[name] for name in meas.dtype.names}),
                SimpleNamespace(state=state, **{name: res[name] for name in res.dtype.names}))

    def _probe(self, joint_names, model):
        """Topic -> (message record head, CdrLayout) from messages built for sentinel values.

        The sentinels are random, so each number occurs once in its message.
        """
        rng = np.random.default_rng(0)
        n, m2 = len(joint_names), 2 * model.m

        def values(size):
            return rng.uniform(1.0, 2.0, size)

        meas = SimpleNamespace(t=1234.5678901, q=values(n), qd=values(n), tau_applied=values(n),
                               feature_stamp=1234.5012345, pixels=values(m2),
                               true_depth=values(model.m))
        res = SimpleNamespace(t=meas.t, tau=values(n), x_d=values(m2), x_obs=values(m2),
                              error=values(m2), z_hat=values(model.m),
                              state=SimpleNamespace(a_z_perp=values(model.p_perp),
                                                    a_z=values(model.p_z), a_d=values(model.p_d)))
        labels = m.parameter_labels(model)
        built = ([(t.replace("~", SIM_NS), msg) for t, msg in m.sim_outputs(
                     self.msgs, meas, joint_names)]
                 + [(t.replace("~", CONTROLLER_NS), msg) for t, msg in m.controller_outputs(
                     self.msgs, res, labels, joint_names)])
        self._store(0, meas, res)
        numbers = self._numbers(*self._stacked(1))
        if [topic for topic, _ in built] != [topic for topic, *_ in numbers]:
            raise RuntimeError("messages.sim_output_arrays/controller_output_arrays do not list "
                               "the topics of sim_outputs/controller_outputs")
        layouts = {}
        for (topic, msg), (_, _, stamp, blocks) in zip(built, numbers):
            raw = self.msgs.typestore.serialize_cdr(msg, m.MESSAGE_TYPES[TOPICS[topic]])
            layout = m.CdrLayout.probe(raw, None if stamp is None else stamp[0],
                                       [block[0] for block in blocks])
            head = np.frombuffer(MESSAGE_HEAD.pack(0x05, MESSAGE_HEAD.size - 9 + layout.size,
                                                   self.channels[topic], 0, 0, 0), np.uint8)
            layouts[topic] = (head, layout)
        return layouts

    @staticmethod
    def _numbers(meas, res):
        return ([(t.replace("~", SIM_NS), *rest) for t, *rest in m.sim_output_arrays(meas)]
                + [(t.replace("~", CONTROLLER_NS), *rest)
                   for t, *rest in m.controller_output_arrays(res)])

    def _chunk(self, meas, res):
        """(message records, message index) of the recorded periods, in the order published."""
        k = len(meas.t)
        log_time = m.stamps_ns(meas.t)
        times = log_time.astype("<u8").view(np.uint8).reshape(k, 8)
        numbers = self._numbers(meas, res)
        sizes = [MESSAGE_HEAD.size + self._layouts[topic][1].size for topic, *_ in numbers]
        frame = np.empty((k, sum(sizes)), dtype=np.uint8)
        present = np.ones((k, len(numbers)), dtype=bool)
        at = 0
        for j, (topic, published, stamp, blocks) in enumerate(numbers):
            head, layout = self._layouts[topic]
            rows = slice(None) if published is None else published
            end = at + head.size
            frame[:, at:end] = head
            frame[:, at + LOG_TIME_AT:at + LOG_TIME_AT + 8] = times
            frame[:, at + PUBLISH_TIME_AT:at + PUBLISH_TIME_AT + 8] = times
            frame[rows, end:end + layout.size] = layout.serialize(
                None if stamp is None else stamp[rows], [block[rows] for block in blocks])
            if published is not None:
                present[:, j] = published
            at = end + layout.size
        sizes = np.array(sizes)
        data = frame.reshape(-1) if present.all() else frame[np.repeat(present, sizes, axis=1)]

        def message(topic, s, cdr):
            return MESSAGE_HEAD.pack(0x05, MESSAGE_HEAD.size - 9 + len(cdr), self.channels[topic],
                                     0, log_time[s], log_time[s]) + cdr

        # the frame's picture comes before the period's messages, /diagnostics after them
        before = {s: [(topic, message(topic, s, cdr)) for topic, cdr in pictures]
                  for s, pictures in self._pictures.items()}
        after = {s: [("/diagnostics", message("/diagnostics", s, cdr))]
                 for s, cdr in self._diagnostics.items()}
        lengths = np.zeros((k, len(numbers) + 2), dtype=np.int64)
        lengths[:, 1:-1] = present * sizes
        for column, extra in ((0, before), (-1, after)):
            lengths[list(extra), column] = [sum(len(r) for _, r in records)
                                            for records in extra.values()]
        starts = (np.cumsum(lengths) - lengths.ravel()).reshape(lengths.shape)
        row_ends = np.cumsum(lengths[:, 1:-1].sum(axis=1))    # in ``data``
        parts, done, extra_at = [], 0, {}
        for s in sorted(set(before) | set(after)):
            row_start = row_ends[s] - lengths[s, 1:-1].sum()
            parts.append(data[done:row_start])
            for column, records in ((0, before.get(s, ())), (-1, after.get(s, ()))):
                if column == -1:
                    parts.append(data[row_start:row_ends[s]])
                at = starts[s, column]
                for topic, record in records:
                    parts.append(record)
                    extra_at.setdefault(topic, []).append((log_time[s], at))
                    at += len(record)
            done = row_ends[s]
        parts.append(data[done:])
        parts = [part for part in parts if len(part)]
        index = {}
        for j, (topic, *_) in enumerate(numbers):
            rows = present[:, j]
            if rows.any():
                index[self.channels[topic]] = (log_time[rows], starts[rows, j + 1])
        for topic, entries in extra_at.items():
            times, where = np.array(entries, dtype=np.int64).T
            index[self.channels[topic]] = (times, where)
        return b"".join(parts), index


#: rows of timeseries.csv formatted at a time (the compiled path's buffer: ~10 MB at 200 columns)
CSV_BLOCK_ROWS = 2000


def write_csv(path, columns, table, labels):
    """Write ``table`` (N, C) as ``"%.10g"`` numbers, then the strings ``labels`` (N,).

    ``columns`` (C + 1) names the columns.  The file is what ``csv.writer``
    writes for rows ``[f"{v:.10g}" for v in row] + [label]`` (the excel dialect:
    CR LF line ends, a label quoted only when it holds a comma, a quote or a
    line end).  With numba the numbers are formatted by
    :mod:`.csv_kernels` (equal to Python's, byte for byte), else by Python's ``%``
    one row at a time.
    """
    table = np.ascontiguousarray(table, dtype=float)
    if table.ndim != 2 or len(table) != len(labels):
        raise ValueError(f"write_csv: table (N, C) and N labels, got {table.shape} and "
                         f"{len(labels)}")
    unique = list(dict.fromkeys(labels))
    fields = [_csv_line(["", label])[1:-2] for label in unique]
    compiled_csv = _csv_kernels()
    with open(path, "wb") as handle:
        handle.write(_csv_line(columns).encode("utf-8"))
        if compiled_csv is None:
            template = "%.10g," * table.shape[1] + "%s\r\n"
            field = dict(zip(unique, fields))
            for start in range(0, len(table), CSV_BLOCK_ROWS):
                block = table[start:start + CSV_BLOCK_ROWS].tolist()
                handle.write("".join(template % (*row, field[label]) for row, label in zip(
                    block, labels[start:start + CSV_BLOCK_ROWS])).encode("utf-8"))
            return
        code = {label: k for k, label in enumerate(unique)}
        encoded = [f.encode("utf-8") for f in fields]
        label_text = np.frombuffer(b"".join(encoded), dtype=np.uint8)
        label_offsets = np.concatenate([[0], np.cumsum([len(f) for f in encoded])]).astype(np.intp)
        codes = np.array([code[label] for label in labels], dtype=np.intp)
        for start in range(0, len(table), CSV_BLOCK_ROWS):
            values = table[start:start + CSV_BLOCK_ROWS].reshape(-1)
            text = np.empty((len(values), compiled_csv.WIDTH), dtype=np.uint8)
            lengths = np.empty(len(values), dtype=np.intp)
            undecided = np.empty(len(values), dtype=np.bool_)
            compiled_csv.format_g10(values, text, lengths, undecided)
            for i in np.flatnonzero(undecided):
                number = ("%.10g" % values[i]).encode("ascii")
                text[i, :len(number)] = np.frombuffer(number, dtype=np.uint8)
                lengths[i] = len(number)
            handle.write(compiled_csv.join_rows(
                text, lengths, table.shape[1], codes[start:start + CSV_BLOCK_ROWS], label_text,
                label_offsets).tobytes())


def _csv_line(row):
    """One row as ``csv.writer`` writes it (the excel dialect), with its CR LF."""
    buffer = io.StringIO()
    csv.writer(buffer).writerow(row)
    return buffer.getvalue()


def _csv_kernels():
    """:mod:`.csv_kernels`, or None without numba."""
    from ..models.backend import kernels

    if kernels() is None:
        return None
    from . import csv_kernels

    return csv_kernels


def write_json(path, data):
    def default(obj):
        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.ndarray):
            return obj.tolist()
        raise TypeError(type(obj))

    with open(path, "w", encoding="utf-8") as handle:
        json.dump(data, handle, indent=2, default=default, allow_nan=True)
        handle.write("\n")
