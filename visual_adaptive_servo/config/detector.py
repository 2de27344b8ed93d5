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

"""The feature detector's section (``feature_detector``): its parameter specs and configuration.

:func:`detector_config` validates a flat parameter set into the
:class:`~visual_adaptive_servo.vision.detection.DetectorConfig` that
:func:`~visual_adaptive_servo.vision.detection.detect` runs with;
:func:`detector_for` is the detector that matches a simulated camera.
"""

from __future__ import annotations

from ..schema import ConfigError, DETECTOR_SECTION, ParamSpec, resolve_params, TIMING_MODES
from ..vision.detection import DetectorConfig
from .common import MARKER_COLORS


DETECTOR_TYPES = ("color", "apriltag")

DETECTOR_PARAMS = (
    ParamSpec("type", "color", "str",
              "color: one coloured blob per feature point (markers.*); apriltag: the corners "
              "or centre of one AprilTag (tag.*)."),
    ParamSpec("tag.family", "36h11", "str", "AprilTag family (16h5, 25h9, 36h10, 36h11)."),
    ParamSpec("tag.id", 0, "int", "The tag's id in its family.", 0, None),
    ParamSpec("tag.points", ["top_left", "top_right", "bottom_right"], "str_list",
              "The feature points in feature order (1 to 3): top_left, top_right, "
              "bottom_right, bottom_left (the black square's corners as printed), center."),
    ParamSpec("markers.colors", list(MARKER_COLORS[:3]), "float_list",
              "Marker colours as the camera sees them, RGB 0-255, three values per marker "
              "(1 to 3 markers), in feature order (default: the simulator's first marker).",
              0.0, 255.0, True),
    ParamSpec("markers.tolerance", 40.0, "float",
              "A pixel belongs to a marker when each of its R, G, B is within this of the "
              "marker's colour.", 0.0, 255.0, True),
    ParamSpec("blob_area", [10.0, 50000.0], "float_list",
              "[min, max] area of a marker blob [px]; blobs outside are not markers.",
              1.0, None, True),
    ParamSpec("pixel_origin", [320.0, 240.0], "float_list",
              "Image point (column, row) [px] that is pixel (0, 0) of the controller; "
              "continuous image coordinates, the top-left corner of the image is (0, 0). "
              "The default is the paper's camera (origin on the optical axis) for 640x480."),
    ParamSpec("pixel_axes", [-1.0, -1.0], "float_list",
              "+1 or -1 per axis: u = axes[0] (column - origin[0]), v = axes[1] (row - "
              "origin[1]); [1, 1] for a standard camera, [-1, -1] for the paper's (u to the "
              "left, v up)."),
    ParamSpec("overlay.enabled", True, "bool",
              "Publish ~/overlay: the image with x, x_d and x_o drawn (for image viewers)."),
    ParamSpec("timing_mode", "lockstep", "str",
              "QoS of the image subscription and the features publisher; must match the "
              "camera's and the controller's (lockstep: reliable; realtime: best-effort "
              "sensor data)."),
    ParamSpec("recorded", False, "bool",
              "Lockstep: a recorder keeps every message of this run (servo.launch.py "
              "record:=true); /camera/features then keeps 2000 messages for subscribers that "
              "fall behind, as the other recorded topics do (ros/executor.py RECORDED)."),
)


def detector_config(params):
    """The :class:`DetectorConfig` of ``feature_detector`` parameters (:data:`DETECTOR_PARAMS`).

    Checks the node's own parameters too (``timing_mode``), so that a bad
    parameter set is refused in one place.
    """
    # no structure parameter: every default is a plain value
    _, v = resolve_params(DETECTOR_PARAMS, params, DETECTOR_SECTION, lambda values: None)
    if v["timing_mode"] not in TIMING_MODES:
        raise ConfigError(f"{DETECTOR_SECTION}.timing_mode: must be one of {TIMING_MODES}, "
                          f"got {v['timing_mode']!r}")
    if v["type"] not in DETECTOR_TYPES:
        raise ConfigError(f"{DETECTOR_SECTION}.type: must be one of {DETECTOR_TYPES}, got "
                          f"{v['type']!r}")
    if v["type"] == "apriltag":
        from ..vision.apriltag import TagDetectorConfig

        return TagDetectorConfig(v["tag.family"], v["tag.id"], tuple(v["tag.points"]),
                                 v["pixel_origin"], v["pixel_axes"])
    return DetectorConfig(v["markers.colors"], v["markers.tolerance"], v["blob_area"],
                          v["pixel_origin"], v["pixel_axes"])


def detector_for(sim, params=None):
    """The feature detector matching the simulated camera: its marker colours and pixel map.

    ``params`` (a ``feature_detector`` section) may change anything, e.g. the tolerance.
    """
    base = {"markers.colors": [float(v) for v in sim["markers.colors"]],
            "pixel_origin": [float(v) for v in sim.camera.pixel_origin],
            "pixel_axes": [float(v) for v in sim.camera.pixel_axes]}
    if sim.tag is not None:
        base.update({"type": "apriltag", "tag.family": sim.tag.family, "tag.id": sim.tag.tag_id,
                     "tag.points": list(sim.tag.points)})
    base.update(params or {})
    return detector_config(base)
