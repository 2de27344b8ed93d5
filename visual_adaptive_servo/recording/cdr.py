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

"""The messages of the 1 kHz loop as serialized CDR, without message objects.

Every period the simulator publishes a frame, the clock, the joint state and the
true depths, and the controller takes the frame and the joint state and publishes
two commands.  Built as rclpy message objects, converted to C and serialized,
and taken back the same way, these cost more than the controller's whole
sample under ROS (measured on the 2-core VM: 60 µs to build the simulator's four
messages, a PolygonStamped's publish 65 µs against 45 µs for the same message
already serialized).  rclpy publishes ``bytes`` as they are (``publish_raw``) and
hands a subscription made with ``raw=True`` the serialized message, so the nodes
use these functions on their per-period topics instead.

The format: the 4-byte encapsulation header of little-endian plain CDR
(``00 01 00 00``), then the fields in order, each primitive aligned to its size
from the end of that header; a string is its length with the terminating NUL,
its bytes and the NUL; a sequence its length, then its elements.  The test
oracle is the Jazzy message definitions in the ``rosbags`` type store (its
serializer gives the same bytes, its deserializer the same values, whatever the
names, sizes and alignments) and, under ROS, rclpy's own ``serialize_message``.

Values are what :mod:`.messages` puts in and gets out: times as integer
nanoseconds (:func:`.messages.time_to_ns`), pixels as float32 (Point32).
"""

from __future__ import annotations

import struct

import numpy as np

from .messages import time_to_ns

ENCAPSULATION = b"\x00\x01\x00\x00"      # CDR, little endian
_STAMP = struct.Struct("<iI")
_U32 = struct.Struct("<I")
_F64 = np.dtype("<f8")
_F32 = np.dtype("<f4")
_NS = 1_000_000_000


class CdrError(ValueError):
    """Bytes that are not the serialized message they are read as."""


class _Writer:
    """Appends CDR fields, keeping the alignment (relative to the end of the header)."""

    __slots__ = ("parts", "size")

    def __init__(self):
        self.parts = [ENCAPSULATION]
        self.size = 0

    def _align(self, n):
        pad = -self.size % n
        if pad:
            self.parts.append(b"\x00" * pad)
            self.size += pad

    def stamp(self, ns):
        sec, nanosec = divmod(ns, _NS)
        self._align(4)
        self.parts.append(_STAMP.pack(sec, nanosec))
        self.size += 8

    def u32(self, value):
        self._align(4)
        self.parts.append(_U32.pack(value))
        self.size += 4

    def raw(self, data, align):
        """``data`` already encoded, its first field aligned to ``align``."""
        self._align(align)
        self.parts.append(data)
        self.size += len(data)

    def string(self, text):
        data = text.encode() + b"\x00"
        self.u32(len(data))
        self.parts.append(data)
        self.size += len(data)

    def f64_sequence(self, values):
        values = np.ascontiguousarray(values, dtype=_F64).reshape(-1)
        self.u32(values.size)
        if values.size:
            self.raw(values.tobytes(), 8)

    def encoded(self):
        return b"".join(self.parts)


def _string_sequence(texts):
    """A sequence of strings encoded from an offset aligned to 4 (where it must be put)."""
    writer = _Writer()
    writer.u32(len(texts))
    for text in texts:
        writer.string(text)
    return writer.encoded()[len(ENCAPSULATION):]


class _Reader:
    """Reads CDR fields from ``data`` (bytes of a whole message, header included)."""

    __slots__ = ("data", "pos", "what")

    def __init__(self, data, what):
        self.data, self.what = data, what
        if len(data) < 4 or data[1] != 1:
            raise CdrError(f"{what}: not little-endian CDR (header {bytes(data[:4])!r})")
        self.pos = 4

    def _take(self, size, align):
        start = self.pos + (-(self.pos - 4) % align)
        end = start + size
        if end > len(self.data):
            raise CdrError(f"{self.what}: {len(self.data)} bytes end inside a field "
                           f"(byte {start} of {end} needed)")
        self.pos = end
        return start

    def stamp_ns(self):
        sec, nanosec = _STAMP.unpack_from(self.data, self._take(8, 4))
        return sec * _NS + nanosec

    def u32(self):
        return _U32.unpack_from(self.data, self._take(4, 4))[0]

    def string(self):
        size = self.u32()
        start = self._take(size, 1)
        if size == 0 or self.data[start + size - 1] != 0:
            raise CdrError(f"{self.what}: a string without its terminating NUL")
        return bytes(self.data[start:start + size - 1]).decode()

    def skip_strings(self):
        """A sequence of strings: (its bytes, the count) without decoding them."""
        count = self.u32()
        begin = self.pos
        for _ in range(count):
            size = self.u32()
            self._take(size, 1)
        return bytes(self.data[begin:self.pos]), count

    def f64_sequence(self):
        count = self.u32()
        if count == 0:
            return np.zeros(0)
        start = self._take(8 * count, 8)
        return np.frombuffer(self.data, _F64, count, start).astype(float)

    def point32_sequence(self):
        count = self.u32()
        start = self._take(12 * count, 4)
        return np.frombuffer(self.data, _F32, 3 * count, start).reshape(count, 3)


def clock(t):
    """rosgraph_msgs/Clock of time ``t`` [s]."""
    writer = _Writer()
    writer.stamp(time_to_ns(t))
    return writer.encoded()


class JointStateEncoder:
    """sensor_msgs/JointState of fixed joint names, their sequence encoded once."""

    def __init__(self, names):
        self.names = list(names)
        self._names = _string_sequence(self.names)

    def encode(self, stamp_ns, position, velocity, effort):
        """The JointState stamped ``stamp_ns`` (frame_id empty); empty arrays for none."""
        writer = _Writer()
        writer.stamp(stamp_ns)
        writer.string("")
        writer.raw(self._names, 4)
        writer.f64_sequence(position)
        writer.f64_sequence(velocity)
        writer.f64_sequence(effort)
        return writer.encoded()


class JointStateDecoder:
    """(stamp ns, q, q_dot) of serialized JointStates, in the order of ``names``.

    The name sequence of the previous message is kept with its index, so a
    publisher that always sends the same names (every one does) costs one
    comparison of bytes.  ValueError (:class:`CdrError` for bytes that are not a
    JointState) with the message of :func:`.messages.joint_state_from_msg` when a
    joint is missing or the sizes do not match.
    """

    def __init__(self, names):
        self.names = list(names)
        self._names_bytes, self._order = None, None

    def _index(self, names, count):
        reader = _Reader(ENCAPSULATION + names, "joint state names")
        got = [reader.string() for _ in range(count)]
        index = {name: i for i, name in enumerate(got)}
        missing = [name for name in self.names if name not in index]
        if missing:
            raise ValueError(f"joint state: missing joint(s) {missing}; got {got}")
        return [index[name] for name in self.names]

    def decode(self, data):
        reader = _Reader(data, "joint state")
        stamp_ns = reader.stamp_ns()
        reader.string()                         # frame_id
        names, count = reader.skip_strings()
        if names != self._names_bytes:
            self._order = self._index(names, count)
            self._names_bytes = names
        position, velocity = reader.f64_sequence(), reader.f64_sequence()
        if len(position) != count or len(velocity) != count:
            raise ValueError(f"joint state: {count} names but {len(position)} positions "
                             f"and {len(velocity)} velocities")
        order = self._order
        return stamp_ns, position[order], velocity[order]


def polygon_stamped(stamp_ns, pixels, frame_id="camera"):
    """geometry_msgs/PolygonStamped of ``pixels`` (2m,): one Point32 (u, v, 0) per point."""
    uv = np.asarray(pixels, dtype=float).reshape(-1, 2)
    points = np.zeros((len(uv), 3), dtype=_F32)
    points[:, :2] = uv
    writer = _Writer()
    writer.stamp(stamp_ns)
    writer.string(frame_id)
    writer.u32(len(uv))
    if len(uv):
        writer.raw(points.tobytes(), 4)
    return writer.encoded()


def polygon_stamped_pixels(data):
    """(stamp ns, pixels (2m,) float64 of the float32 points) of a serialized PolygonStamped."""
    reader = _Reader(data, "features")
    stamp_ns = reader.stamp_ns()
    reader.string()
    points = reader.point32_sequence()
    return stamp_ns, points[:, :2].astype(float).reshape(-1)


def float64_array(values, label=""):
    """std_msgs/Float64MultiArray as :func:`.messages.float_array_to_msg` builds it.

    One dimension (``label``, size and stride the number of values), data_offset 0.
    """
    values = np.ascontiguousarray(values, dtype=_F64).reshape(-1)
    writer = _Writer()
    writer.u32(1)
    writer.string(label)
    writer.u32(values.size)
    writer.u32(values.size)
    writer.u32(0)
    writer.f64_sequence(values)
    return writer.encoded()


def float64_array_values(data):
    """The data (float64) of a serialized std_msgs/Float64MultiArray, whatever its layout."""
    reader = _Reader(data, "float array")
    for _ in range(reader.u32()):
        reader.string()
        reader.u32()
        reader.u32()
    reader.u32()                                # data_offset
    return reader.f64_sequence()


def stamp_time(stamp_ns):
    """Seconds of a stamp, as :func:`.messages.stamp_to_time` reads them (sec + nanosec 1e-9)."""
    sec, nanosec = divmod(stamp_ns, _NS)
    return sec + nanosec * 1e-9


def header_stamp_ns(data, what="message"):
    """The stamp [ns] of the header that starts a serialized message (JointState, ...)."""
    return _Reader(data, what).stamp_ns()


def sim_outputs(joint_state, meas):
    """:func:`.messages.sim_outputs` serialized: (topic, bytes), the same topics in the same order.

    ``joint_state`` is the :class:`JointStateEncoder` of the simulator's joints.
    """
    out = []
    if meas.pixels is not None:
        out.append(("/camera/features",
                    polygon_stamped(time_to_ns(meas.feature_stamp), meas.pixels)))
    out += [("/clock", clock(meas.t)),
            ("/joint_states", joint_state.encode(time_to_ns(meas.t), meas.q, meas.qd,
                                                 meas.tau_applied)),
            ("~/true_depth", float64_array(meas.true_depth))]
    return out
