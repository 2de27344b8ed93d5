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

"""Arrays <-> ROS 2 messages, for rclpy and for the ``rosbags`` type store alike.

The conversion functions take a *message set* that supplies the message
classes and the two places where rclpy and rosbags differ (how a float
sequence and a ``byte`` are represented).  The nodes pass :func:`rclpy_messages`;
the MCAP recorder and the tests pass :func:`rosbags_messages` (the Jazzy
definitions), so what ``vas run`` records is built by the same code the nodes
publish with.

Topic content (see DESIGN.md section 2):

* ``/camera/features``: PolygonStamped, one Point32 per feature (x=u px, y=v px, z=0)
* ``/camera/image_raw``: Image, read in rgb8, bgr8, rgba8 or bgra8 (:func:`image_from_msg`)
* ``/camera/camera_info``: CameraInfo of the simulated pinhole camera (:func:`camera_info_to_msg`)
* ``/joint_states``: JointState with position, velocity and the applied effort
* ``/controller_node/effort_command``: JointState with the torques in ``effort``, stamped
  with the joint state it answers (:func:`effort_command_to_msg`)
* Float64MultiArray: one dimension whose label lists the entries, comma-separated

What a message carries is not exactly what was put in: times travel as integer
nanoseconds and pixels as float32 (geometry_msgs/Point32).  :func:`received_time`
and :func:`received_pixels` give what a subscriber reads; ``vas run`` feeds its
controller through them, so the in-process loop computes what the nodes compute,
bit for bit.
"""

from __future__ import annotations

import array
import importlib
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

MESSAGE_TYPES = {
    "Time": "builtin_interfaces/msg/Time",
    "Header": "std_msgs/msg/Header",
    "JointState": "sensor_msgs/msg/JointState",
    "Image": "sensor_msgs/msg/Image",
    "RegionOfInterest": "sensor_msgs/msg/RegionOfInterest",
    "CameraInfo": "sensor_msgs/msg/CameraInfo",
    "Point32": "geometry_msgs/msg/Point32",
    "Polygon": "geometry_msgs/msg/Polygon",
    "PolygonStamped": "geometry_msgs/msg/PolygonStamped",
    "MultiArrayDimension": "std_msgs/msg/MultiArrayDimension",
    "MultiArrayLayout": "std_msgs/msg/MultiArrayLayout",
    "Float64MultiArray": "std_msgs/msg/Float64MultiArray",
    "Clock": "rosgraph_msgs/msg/Clock",
    "KeyValue": "diagnostic_msgs/msg/KeyValue",
    "DiagnosticStatus": "diagnostic_msgs/msg/DiagnosticStatus",
    "DiagnosticArray": "diagnostic_msgs/msg/DiagnosticArray",
}

DIAGNOSTIC_LEVELS = {"OK": 0, "WARN": 1, "ERROR": 2, "STALE": 3}
# sensor_msgs/Image encodings read by image_from_msg: (bytes per pixel, channels to R, G, B)
IMAGE_ENCODINGS = {"rgb8": (3, (0, 1, 2)), "bgr8": (3, (2, 1, 0)),
                   "rgba8": (4, (0, 1, 2)), "bgra8": (4, (2, 1, 0))}


@dataclass(frozen=True)
class MessageSet:
    """Message classes by short name plus the representation adapters."""

    classes: dict
    floats: Callable[[Any], Any]     # float64 vector -> sequence field value
    uint8s: Callable[[Any], Any]     # uint8 vector -> sequence field value
    byte: Callable[[int], Any]       # int -> 'byte' field value
    typestore: Any = None            # the rosbags type store (serialisation), if any

    def __getattr__(self, name):
        try:
            return self.__dict__["classes"][name]
        except KeyError:
            raise AttributeError(name) from None


def rosbags_messages():
    """The ROS 2 Jazzy definitions of the rosbags type store (no ROS needed)."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    classes = {short: store.types[full] for short, full in MESSAGE_TYPES.items()}
    return MessageSet(classes, lambda v: np.asarray(v, dtype=np.float64).copy(),
                      lambda v: np.asarray(v, dtype=np.uint8).reshape(-1).copy(), int, store)


# The ROS 2 Jazzy definitions of MESSAGE_TYPES (builtin_interfaces/Time is in every rosbags
# store).  Importing rosbags' whole Jazzy store (built on Iron, Humble, ... Dashing) costs
# ``vas run`` about 0.065 s of CPU, a store of just these 0.01 s; test_recording checks
# them against the Jazzy store.
JAZZY_DEFINITIONS = {
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    "sensor_msgs/msg/JointState": ("std_msgs/Header header\nstring[] name\nfloat64[] position\n"
                                   "float64[] velocity\nfloat64[] effort"),
    "sensor_msgs/msg/Image": ("std_msgs/Header header\nuint32 height\nuint32 width\n"
                              "string encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data"),
    "geometry_msgs/msg/Point32": "float32 x\nfloat32 y\nfloat32 z",
    "geometry_msgs/msg/Polygon": "geometry_msgs/Point32[] points",
    "geometry_msgs/msg/PolygonStamped": "std_msgs/Header header\ngeometry_msgs/Polygon polygon",
    "std_msgs/msg/MultiArrayDimension": "string label\nuint32 size\nuint32 stride",
    "std_msgs/msg/MultiArrayLayout": "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset",
    "std_msgs/msg/Float64MultiArray": "std_msgs/MultiArrayLayout layout\nfloat64[] data",
    "rosgraph_msgs/msg/Clock": "builtin_interfaces/Time clock",
    "diagnostic_msgs/msg/KeyValue": "string key\nstring value",
    "diagnostic_msgs/msg/DiagnosticStatus": ("byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n"
                                             "byte level\nstring name\nstring message\n"
                                             "string hardware_id\n"
                                             "diagnostic_msgs/KeyValue[] values"),
    "diagnostic_msgs/msg/DiagnosticArray": ("std_msgs/Header header\n"
                                            "diagnostic_msgs/DiagnosticStatus[] status"),
    "sensor_msgs/msg/RegionOfInterest": ("uint32 x_offset\nuint32 y_offset\nuint32 height\n"
                                         "uint32 width\nbool do_rectify"),
    "sensor_msgs/msg/CameraInfo": ("std_msgs/Header header\nuint32 height\nuint32 width\n"
                                   "string distortion_model\nfloat64[] d\nfloat64[9] k\n"
                                   "float64[9] r\nfloat64[12] p\nuint32 binning_x\n"
                                   "uint32 binning_y\nsensor_msgs/RegionOfInterest roi"),
}


def rosbags_messages_minimal():
    """:func:`rosbags_messages` from a type store holding only :data:`JAZZY_DEFINITIONS`."""
    from rosbags.typesys import get_typestore, get_types_from_msg, Stores

    store = get_typestore(Stores.EMPTY)
    types = {}
    for name, text in JAZZY_DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    classes = {short: store.types[full] for short, full in MESSAGE_TYPES.items()}
    return MessageSet(classes, lambda v: np.asarray(v, dtype=np.float64).copy(),
                      lambda v: np.asarray(v, dtype=np.uint8).reshape(-1).copy(), int, store)


def rclpy_messages():
    """The installed ROS 2 Python message classes (needs a sourced ROS 2)."""
    classes = {}
    for short, full in MESSAGE_TYPES.items():
        package, _, name = full.split("/")
        classes[short] = getattr(importlib.import_module(f"{package}.msg"), name)
    # uint8[] as array.array('B') and float64[] as array.array('d'): the generated setter
    # stores them as they are (0.06 ms for a 640x480 rgb8 image; bytes are converted, 1.15
    # ms, and a list is checked element by element in Python: a 7-joint JointState is built
    # in 4.9 us instead of 6.9)
    return MessageSet(classes, lambda v: array.array("d", np.asarray(v, dtype=np.float64)
                                                     .reshape(-1).tobytes()),
                      lambda v: array.array("B", np.asarray(v, dtype=np.uint8).tobytes()),
                      lambda i: bytes([i]))


def time_to_ns(t):
    """Seconds (float) -> integer nanoseconds, rounded (how a stamp holds a time)."""
    ns = int(round(t * 1e9))
    if ns < 0:
        raise ValueError(f"stamp: negative time {t}")
    return ns


def time_to_stamp(msgs, t):
    """Seconds (float) -> builtin_interfaces/Time, rounded to the nanosecond."""
    sec, nanosec = divmod(time_to_ns(t), 1_000_000_000)
    return msgs.Time(sec=sec, nanosec=nanosec)


def stamp_to_ns(stamp):
    """builtin_interfaces/Time -> integer nanoseconds (exact: compare stamps with this)."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def stamp_to_time(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def received_time(t):
    """The time a subscriber reads from a stamp of ``t``: seconds -> nanoseconds -> seconds.

    The two can differ in the last bit (5 ms x 3 is 0.015000000000000001 s, its
    stamp reads 0.015 s), and the controller integrates over differences of them.
    """
    sec, nanosec = divmod(time_to_ns(t), 1_000_000_000)
    return sec + nanosec * 1e-9


def received_pixels(pixels):
    """The pixels (2m,) a subscriber reads from :func:`features_to_msg`: float32, as float64."""
    return np.asarray(pixels, dtype=np.float32).astype(np.float64)


def header(msgs, t, frame_id=""):
    return msgs.Header(stamp=time_to_stamp(msgs, t), frame_id=frame_id)


def copy_header(msgs, original):
    """A new Header with the stamp (field by field, exact) and frame_id of ``original``."""
    return msgs.Header(stamp=msgs.Time(sec=original.stamp.sec, nanosec=original.stamp.nanosec),
                       frame_id=original.frame_id)


def joint_state_to_msg(msgs, t, names, q, qd, effort):
    """JointState stamped t with position q, velocity qd and effort (all (n,))."""
    return msgs.JointState(header=header(msgs, t), name=list(names), position=msgs.floats(q),
                           velocity=msgs.floats(qd), effort=msgs.floats(effort))


def joint_state_from_msg(msg, names):
    """(t, q, qd) from a JointState, reordered to ``names``.

    Raises ValueError naming the problem when a joint is missing or the sizes
    do not match; values are not checked for NaN here (the controller does).
    """
    index = {name: i for i, name in enumerate(msg.name)}
    missing = [name for name in names if name not in index]
    if missing:
        raise ValueError(f"joint state: missing joint(s) {missing}; got {list(msg.name)}")
    position, velocity = np.asarray(msg.position, float), np.asarray(msg.velocity, float)
    if len(position) != len(msg.name) or len(velocity) != len(msg.name):
        raise ValueError(f"joint state: {len(msg.name)} names but {len(position)} positions "
                         f"and {len(velocity)} velocities")
    order = [index[name] for name in names]
    return stamp_to_time(msg.header.stamp), position[order], velocity[order]


def effort_command_to_msg(msgs, stamp, names, tau):
    """The stamped command: JointState with ``tau`` (n,) in ``effort``, ``stamp`` a Time.

    ``stamp`` is that of the joint state the command answers, copied field by
    field, so the simulator can match the two exactly; position and velocity
    stay empty.
    """
    return msgs.JointState(header=msgs.Header(stamp=msgs.Time(sec=stamp.sec,
                                                              nanosec=stamp.nanosec),
                                              frame_id=""),
                           name=list(names), position=msgs.floats([]), velocity=msgs.floats([]),
                           effort=msgs.floats(tau))


def effort_command_from_msg(msg, names):
    """(stamp in ns, tau (n,) in ``names`` order) of a stamped command.

    Raises ValueError naming the problem when a joint is missing or the number
    of efforts does not match the names.
    """
    index = {name: i for i, name in enumerate(msg.name)}
    missing = [name for name in names if name not in index]
    if missing:
        raise ValueError(f"effort command: missing joint(s) {missing}; got {list(msg.name)}")
    effort = np.asarray(msg.effort, float)
    if len(effort) != len(msg.name):
        raise ValueError(f"effort command: {len(msg.name)} names but {len(effort)} efforts")
    return stamp_to_ns(msg.header.stamp), effort[[index[name] for name in names]]


def _polygon(msgs, pixels):
    uv = np.asarray(pixels, dtype=float).reshape(-1, 2)
    return msgs.Polygon(points=[msgs.Point32(x=float(u), y=float(v), z=0.0) for u, v in uv])


def features_to_msg(msgs, t, pixels, frame_id="camera"):
    """PolygonStamped with one Point32 (u, v, 0) per feature; ``pixels`` is (2m,)."""
    return msgs.PolygonStamped(header=header(msgs, t, frame_id), polygon=_polygon(msgs, pixels))


def features_for_image(msgs, image_header, pixels):
    """PolygonStamped of ``pixels`` (2m,) with the stamp and frame_id of ``image_header``.

    The stamp is copied field by field, not through seconds: a float64 of a
    wall-clock stamp (~1.7e9 s) resolves only ~0.2 us, and tools that match
    stamps exactly (message_filters, tf) must find the image's own.
    """
    return msgs.PolygonStamped(header=copy_header(msgs, image_header),
                               polygon=_polygon(msgs, pixels))


def features_from_msg(msg):
    """(t, pixels (2m,)) from a PolygonStamped."""
    pixels = np.array([[p.x, p.y] for p in msg.polygon.points], dtype=float).reshape(-1)
    return stamp_to_time(msg.header.stamp), pixels


def float_array_to_msg(msgs, values, labels=None):
    """Float64MultiArray of a vector; ``labels`` (one per entry) go in the dimension label."""
    values = np.asarray(values, dtype=float).reshape(-1)
    label = ",".join(labels) if labels is not None else ""
    if labels is not None and len(labels) != len(values):
        raise ValueError(f"float array: {len(labels)} labels for {len(values)} values")
    dim = msgs.MultiArrayDimension(label=label, size=len(values), stride=len(values))
    return msgs.Float64MultiArray(layout=msgs.MultiArrayLayout(dim=[dim], data_offset=0),
                                  data=msgs.floats(values))


def float_array_from_msg(msg):
    """(values, labels or None) of a Float64MultiArray written by :func:`float_array_to_msg`."""
    values = np.asarray(msg.data, dtype=float)
    labels = None
    if msg.layout.dim and msg.layout.dim[0].label:
        labels = msg.layout.dim[0].label.split(",")
    return values, labels


def parameter_labels(model):
    """Labels of the ``~/parameters`` array: a_z_perp.*, a_z.*, a_d.* of the model."""
    return ([f"a_z_perp.{s}" for s in model.a_z_perp_labels]
            + [f"a_z.{s}" for s in model.a_z_labels] + [f"a_d.{s}" for s in model.a_d_labels])


def clock_to_msg(msgs, t):
    return msgs.Clock(clock=time_to_stamp(msgs, t))


def diagnostics_to_msg(msgs, t, name, level, message, values=None, hardware_id="sim"):
    """DiagnosticArray with one status; ``level`` is OK/WARN/ERROR/STALE."""
    pairs = [msgs.KeyValue(key=str(k), value=str(v)) for k, v in (values or {}).items()]
    status = msgs.DiagnosticStatus(level=msgs.byte(DIAGNOSTIC_LEVELS[level]), name=name,
                                   message=message, hardware_id=hardware_id, values=pairs)
    return msgs.DiagnosticArray(header=header(msgs, t), status=[status])


def image_to_msg(msgs, t, rgb, frame_id="camera"):
    """sensor_msgs/Image (rgb8) of an (h, w, 3) uint8 array."""
    h, w, _ = rgb.shape
    return msgs.Image(header=header(msgs, t, frame_id), height=h, width=w, encoding="rgb8",
                      is_bigendian=0, step=3 * w, data=msgs.uint8s(rgb))


def camera_info_to_msg(msgs, t, camera, frame_id="camera"):
    """sensor_msgs/CameraInfo of a :class:`sim_bridge.camera.PinholeCamera`, stamped t.

    K and P from its intrinsics (fx, fy, cx, cy in raw image coordinates, the
    ROS convention), R = I, plumb_bob with zero distortion, no binning, no ROI.
    For image viewers: the controller never reads it (it does not know the camera).
    """
    fx, fy, cx, cy = (float(v) for v in (camera.fx, camera.fy, camera.cx, camera.cy))
    return msgs.CameraInfo(
        header=header(msgs, t, frame_id), height=int(camera.height), width=int(camera.width),
        distortion_model="plumb_bob", d=msgs.floats([0.0] * 5),
        k=msgs.floats([fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]),
        r=msgs.floats([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
        p=msgs.floats([fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]),
        binning_x=0, binning_y=0,
        roi=msgs.RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))


def _uint8_buffer(data):
    """A flat uint8 view of an Image's ``data``: ndarray (rosbags), array.array (rclpy), bytes."""
    if isinstance(data, (list, tuple)):
        return np.asarray(data, dtype=np.uint8)
    return np.frombuffer(data, dtype=np.uint8)


def image_from_msg(msg):
    """(t, rgb) of a sensor_msgs/Image: rgb is a new (h, w, 3) uint8 RGB array.

    Reads ``rgb8``, ``bgr8``, ``rgba8`` and ``bgra8`` (alpha dropped); rows may be
    padded (``step`` > width x bytes per pixel).  ``is_bigendian`` is ignored: it
    does not matter for 8-bit channels.  ``mono8`` and every other encoding are
    refused, because the detector finds markers by colour and a grey image has
    none (a Bayer or YUV camera needs image_proc's debayer/colour conversion
    first).  The result never shares memory with the message.

    Raises ValueError naming the encoding, or the sizes that do not agree
    (the data must hold exactly height x step bytes, as sensor_msgs/Image says).
    """
    if msg.encoding not in IMAGE_ENCODINGS:
        raise ValueError(f"image: encoding {msg.encoding!r} is not supported; use one of "
                         f"{sorted(IMAGE_ENCODINGS)} (markers are found by colour)")
    size, channels = IMAGE_ENCODINGS[msg.encoding]
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    if step < width * size:
        raise ValueError(f"image: step {step} is less than width {width} x {size} bytes "
                         f"({msg.encoding})")
    data = _uint8_buffer(msg.data)
    if data.size != height * step:
        raise ValueError(f"image: {data.size} bytes of data, but height {height} x step {step} "
                         f"= {height * step}")
    pixels = data.reshape(height, step)[:, :width * size].reshape(height, width, size)
    if channels == (0, 1, 2) and size == 3:
        rgb = pixels.copy()
    else:
        rgb = pixels[:, :, list(channels)]     # fancy indexing: a new, contiguous array
    return stamp_to_time(msg.header.stamp), rgb


def sim_outputs(msgs, meas, joint_names):
    """(topic, message) pairs ``sim_node`` publishes for one measurement.

    ``meas`` is a :class:`sim_bridge.simulator.Measurement`; ``~`` in a topic
    is the node's namespace.  ``vas run`` records exactly these.

    The camera frame (if one is published now) comes first: ``sim_node`` in
    lockstep makes sure it has been delivered before it sends the joint state.
    A frame with NaN pixels (``faults.nan_pixels``) is published as it is, for
    the controller to refuse.  In rendered mode the frame is a picture, see
    :func:`camera_outputs`.
    """
    t = meas.t
    out = []
    if meas.pixels is not None:
        out.append(("/camera/features", features_to_msg(msgs, meas.feature_stamp, meas.pixels)))
    out += [("/clock", clock_to_msg(msgs, t)),
            ("/joint_states", joint_state_to_msg(msgs, t, joint_names, meas.q, meas.qd,
                                                 meas.tau_applied)),
            ("~/true_depth", float_array_to_msg(msgs, meas.true_depth))]
    return out


def camera_outputs(msgs, meas, camera):
    """(topic, message) pairs of the rendered frame published now (none without a picture).

    ``/camera/image_raw`` (rgb8) and ``/camera/camera_info``, both stamped with
    the capture time.
    """
    if meas.image is None:
        return []
    return [("/camera/image_raw", image_to_msg(msgs, meas.feature_stamp, meas.image)),
            ("/camera/camera_info", camera_info_to_msg(msgs, meas.feature_stamp, camera))]


def controller_outputs(msgs, res, labels, names, stamp=None):
    """(topic, message) pairs ``controller_node`` publishes for one :class:`StepResult`.

    The commands always; x_d and x - x_d only when defined (a rejected sample has
    no tracking error).  ``~/effort_command`` (the command stamped with ``stamp``,
    the Time of the joint state it answers; default: ``res.t``) comes last.  The
    order of :func:`controller_output_arrays` and of the recording; the node
    itself publishes both commands first, then :func:`controller_state_outputs`.
    ``/diagnostics`` is left to the caller's cadence.
    """
    return [("/effort_controller/commands", float_array_to_msg(msgs, res.tau)),
            *controller_state_outputs(msgs, res, labels),
            ("~/effort_command", effort_command_to_msg(
                msgs, time_to_stamp(msgs, res.t) if stamp is None else stamp, names, res.tau))]


def controller_state_outputs(msgs, res, labels):
    """The controller's state messages of a StepResult: x_d, x_o, x - x_d, z_hat, estimates.

    x_d and x - x_d only when defined (a rejected sample has no tracking error).
    """
    t = res.t
    out = []
    if np.all(np.isfinite(res.x_d)):
        out.append(("~/desired", features_to_msg(msgs, t, res.x_d)))
    out.append(("~/observed", features_to_msg(msgs, t, res.x_obs)))
    if np.all(np.isfinite(res.error)):
        out.append(("~/tracking_error", features_to_msg(msgs, t, res.error)))
    out.append(("~/estimated_depth", float_array_to_msg(msgs, res.z_hat)))
    st = res.state
    out.append(("~/parameters", float_array_to_msg(
        msgs, np.concatenate([st.a_z_perp, st.a_z, st.a_d]), labels)))
    return out


# Recording many samples at once (``vas run``): the same bytes as the builders above
# and the type store's serialize_cdr, from arrays, without a message object per sample.

def sim_output_arrays(meas):
    """The numbers of :func:`sim_outputs` for K measurements at once.

    ``meas`` has the attributes of a Measurement stacked over K samples:
    ``t`` and ``feature_stamp`` (K,) (NaN where no frame), ``q``, ``qd``,
    ``tau_applied`` (K, n), ``pixels`` (K, 2m) (NaN rows where no frame) and
    ``true_depth`` (K, m).  Returns ``(topic, present, stamp, blocks)`` per
    topic in sim_outputs' order: ``present`` (K,) bool or None (every sample),
    ``stamp`` (K,) seconds or None (no header), ``blocks`` the (K, w) float64
    number arrays in the order the message serialises them.  A
    :class:`CdrLayout` probed from the message sim_outputs builds turns them
    into that message's bytes.
    """
    t = meas.t
    has_frame = np.isfinite(meas.feature_stamp)   # a frame's pixels may be NaN (a fault)
    return [("/camera/features", has_frame, meas.feature_stamp, [_points(meas.pixels)]),
            ("/clock", None, t, []),
            ("/joint_states", None, t, [meas.q, meas.qd, meas.tau_applied]),
            ("~/true_depth", None, None, [meas.true_depth])]


def controller_output_arrays(res):
    """The numbers of :func:`controller_outputs` for K StepResults at once.

    ``res`` has the attributes of a StepResult stacked over K samples (``t``
    (K,), ``tau`` (K, n), ``x_d``, ``x_obs``, ``error`` (K, 2m), ``z_hat``
    (K, m), ``state.a_z_perp`` ... (K, p)); returns what
    :func:`sim_output_arrays` returns, in controller_outputs' order.
    """
    t = res.t
    st = res.state
    return [("/effort_controller/commands", None, None, [res.tau]),
            ("~/desired", np.isfinite(res.x_d).all(axis=1), t, [_points(res.x_d)]),
            ("~/observed", None, t, [_points(res.x_obs)]),
            ("~/tracking_error", np.isfinite(res.error).all(axis=1), t, [_points(res.error)]),
            ("~/estimated_depth", None, None, [res.z_hat]),
            ("~/parameters", None, None,
             [np.concatenate([st.a_z_perp, st.a_z, st.a_d], axis=1)]),
            ("~/effort_command", None, t, [res.tau])]


def _points(pixels):
    """(K, 2m) pixels -> (K, 3m) Point32 coordinates (u, v, 0) as :func:`features_to_msg`."""
    uv = np.asarray(pixels, dtype=float).reshape(len(pixels), -1, 2)
    return np.concatenate([uv, np.zeros(uv.shape[:2] + (1,))], axis=2).reshape(len(uv), -1)


def stamps_ns(times):
    """Seconds (K,) -> int64 nanoseconds (K,), rounded as :func:`time_to_stamp` rounds."""
    times = np.asarray(times, dtype=float)
    if not np.all(times >= 0.0):  # also refuses NaN
        raise ValueError(f"stamp: negative or undefined time {times[~(times >= 0.0)][0]}")
    # np.rint rounds half to even, as round() does in time_to_stamp
    return np.rint(times * 1e9).astype(np.int64)


class CdrLayout:
    """The CDR bytes of one fixed-size message and where its varying numbers sit.

    Built by :meth:`probe` from the serialised bytes of a message whose stamp and
    numbers are known, so the layout follows the message builders and the type
    store rather than restating the CDR rules.  :meth:`serialize` then writes
    the bytes of K messages of the same shape: the template with the stamp
    (builtin_interfaces/Time: int32 sec, uint32 nanosec) and each number block
    (float64, or float32 where the field is, as Point32's) overwritten.
    """

    def __init__(self, template, stamp_at, blocks):
        self.template = np.frombuffer(template, dtype=np.uint8)
        self.stamp_at = stamp_at     # byte offset of the stamp, or None
        self.blocks = blocks         # (byte offset, '<f8' or '<f4', width) per block

    @classmethod
    def probe(cls, raw, stamp, blocks):
        """Find ``stamp`` (seconds or None) and each 1-D block of float64 in ``raw``.

        Each must occur exactly once (the caller picks distinctive values);
        a block is looked for as float64, then as float32.
        """
        raw = bytes(raw)
        stamp_at = None
        if stamp is not None:
            ns = int(stamps_ns([stamp])[0])
            stamp_at = _find_once(raw, np.array([(ns // 10**9, ns % 10**9)], dtype="<i4,<u4")
                                  .tobytes(), "the stamp")
            if stamp_at is None:
                raise ValueError("CDR layout: the stamp is not in the message")
        found = []
        for i, block in enumerate(blocks):
            block = np.asarray(block, dtype=float)
            if block.size == 0:
                found.append((0, "<f8", 0))
                continue
            for dtype in ("<f8", "<f4"):
                at = _find_once(raw, block.astype(dtype).tobytes(), f"block {i}")
                if at is not None:
                    found.append((at, dtype, block.size))
                    break
            else:
                raise ValueError(f"CDR layout: block {i} is not in the message")
        return cls(raw, stamp_at, found)

    @property
    def size(self):
        return self.template.size

    def serialize(self, stamps, blocks):
        """(K, size) uint8: the CDR of K messages with these stamps (K,) and (K, w) blocks.

        Raises OverflowError where a finite value does not fit a float32 field,
        as the type store's serializer does.
        """
        k = len(blocks[0]) if blocks else len(stamps)
        out = np.empty((k, self.size), dtype=np.uint8)
        out[:] = self.template
        if self.stamp_at is not None:
            ns = stamps_ns(stamps)
            stamp = np.empty(k, dtype="<i4,<u4")
            stamp["f0"], stamp["f1"] = ns // 10**9, ns % 10**9
            out[:, self.stamp_at:self.stamp_at + 8] = stamp.view(np.uint8).reshape(k, 8)
        for (at, dtype, width), values in zip(self.blocks, blocks):
            values = np.asarray(values, dtype=float)
            if values.shape != (k, width):
                raise ValueError(f"CDR layout: expected {width} values per message, "
                                 f"got shape {values.shape[1:]}")
            with np.errstate(over="ignore"):
                wire = values.astype(dtype)
            if dtype == "<f4" and np.any(np.isinf(wire) & np.isfinite(values)):
                raise OverflowError("float too large to pack with f format")
            # (reshape to (k, bytes), not (k, -1): no message at all is (0, bytes) too)
            out[:, at:at + wire.itemsize * width] = wire.view(np.uint8).reshape(
                k, wire.itemsize * width)
        return out


def _find_once(raw, pattern, what):
    """Offset of ``pattern`` in ``raw``, None if absent; ValueError if it occurs twice."""
    at = raw.find(pattern)
    if at >= 0 and raw.find(pattern, at + 1) >= 0:
        raise ValueError(f"CDR layout: {what} occurs more than once in the message")
    return at if at >= 0 else None
