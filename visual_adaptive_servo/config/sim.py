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

"""The simulator's section (``sim_node``): its parameter specs and validated configuration."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..models.resources import resolve_path
from ..models.tag import DEFAULT_POINTS, FAMILIES, TagPlate
from ..models.urdf_arm import check_feature_points
from ..models.urdf_chain import load_chain
from ..models.urdf_checks import check_urdf
from ..schema import (ConfigError, ParamSpec, require_finite, require_length, resolve_params,
                      SIM_SECTION, TIMING_MODES, ValidatedParams)
from .common import build_camera, camera_specs, MARKER_COLORS, PAPER_URDF, structure_specs

CAMERA_MODES = ("points", "rendered")
MARKER_TYPES = ("balls", "apriltag")


SIM_PARAMS = structure_specs(PAPER_URDF, "base_link", "tip", [0.0, 0.0, 0.0], "") + (
    ParamSpec("physics_dt", 0.001, "float", "PyBullet physics step [s].", 1e-5, 0.01),
    ParamSpec("control_period", 0.005, "float",
              "Camera frame / control period [s]; a whole multiple of physics_dt.", 1e-4, 1.0),
    ParamSpec("duration", 0.0, "float", "Stop after this simulated time [s]; 0 = run forever.",
              0.0, None),
    ParamSpec("initial_positions", lambda s, v: [0.0] * s.n, "float_list",
              "Joint positions at start [rad or m]."),
    ParamSpec("initial_velocities", lambda s, v: [0.0] * s.n, "float_list",
              "Joint velocities at start [rad/s or m/s]."),
    ParamSpec("joint_names", lambda s, v: list(s.joint_names), "str_list",
              "Joint names in /joint_states and the command order (default: the URDF chain's)."),
    ParamSpec("camera_mode", "points", "str",
              "points: the camera reports the projected feature points (plus pixel_noise_std); "
              "rendered: it renders pictures (/camera/image_raw) and a feature detector finds "
              "the markers in them."),
    ParamSpec("pixel_noise_std", 0.0, "float", "Gaussian pixel noise std [px] (points mode).",
              0.0, 100.0),
    ParamSpec("camera_rate", 0.0, "float",
              "Camera frames per second; 0 = one frame per control_period [Hz].", 0.0, None),
    ParamSpec("camera_latency", 0.0, "float",
              "Time from a frame's capture to its publication, rounded up to the control period "
              "[s]; the frame is stamped with its capture time.", 0.0, 10.0),
    ParamSpec("camera_stamp_delay", 0.0, "float",
              "Time from a frame's capture to the time its stamp says [s]: a camera driver "
              "that stamps frames when it receives them (at most camera_latency); 0 = the "
              "capture time, as sensor_msgs/Image's header.stamp should hold.", 0.0, 10.0),
    ParamSpec("seed", 0, "int", "Seed of the pixel noise generator.", 0, 2**31 - 1),
) + camera_specs("camera.", "Simulated camera") + (
    ParamSpec("markers.radius", 0.03, "float",
              "Radius of the coloured sphere drawn at each feature point [m].", 1e-4, 1.0),
    ParamSpec("markers.colors", lambda s, v: list(MARKER_COLORS[:3 * s.m]), "float_list",
              "RGB 0-255 of each feature point's marker, 3 numbers per point.", 0.0, 255.0),
    ParamSpec("markers.type", "balls", "str",
              "balls: a coloured sphere at each feature point; apriltag: a printed AprilTag "
              "on a plate on the tip link (markers.tag.*), whose corners or centre are the "
              "feature points (feature_points must be the tag's points)."),
    ParamSpec("markers.tag.family", "36h11", "str",
              f"AprilTag family, one of {list(FAMILIES)}."),
    ParamSpec("markers.tag.id", 0, "int", "The tag's id in its family.", 0, None),
    ParamSpec("markers.tag.edge", 0.1, "float",
              "Side of the tag's black square (the AprilTag tag size) [m].", 1e-3, 10.0),
    ParamSpec("markers.tag.margin", 1.0, "float",
              "White border of the plate around the black square [cells].", 1.0, 10.0),
    ParamSpec("markers.tag.position", [0.0, 0.0, 0.0], "float_list",
              "Centre of the tag in the tip link frame [m]."),
    ParamSpec("markers.tag.rpy", [0.0, 0.0, 0.0], "float_list",
              "Orientation of the tag frame (X right and Y up in the printed tag, Z out of "
              "its face) in the tip link frame, URDF roll-pitch-yaw [rad]."),
    ParamSpec("markers.tag.points", lambda s, v: list(DEFAULT_POINTS[s.m]), "str_list",
              "The feature points in feature order: top_left, top_right, bottom_right, "
              "bottom_left (corners of the black square as printed), center (default: the "
              "centre for m = 1, a diagonal for m = 2, three corners for m = 3)."),
    ParamSpec("picture.surroundings", False, "bool",
              "Rendered pictures: a textured floor and boxes behind the arm."),
    ParamSpec("picture.shading", False, "bool",
              "Rendered pictures: directional light with diffuse and specular shading "
              "(false: flat colours, as the colour-ball detector expects)."),
    ParamSpec("picture.exposure", 0.0, "float",
              "Rendered pictures: exposure time ending at the capture, for motion blur [s]; "
              "0 = none.", 0.0, 1.0),
    ParamSpec("picture.exposure_samples", 3, "int",
              "Rendered pictures: pictures averaged over the exposure (each a rendering).",
              1, 16),
    ParamSpec("picture.read_noise", 0.0, "float",
              "Rendered pictures: Gaussian read noise, std as a fraction of full scale.",
              0.0, 0.5),
    ParamSpec("picture.shot_noise", 0.0, "float",
              "Rendered pictures: shot noise, std sqrt(I) x this on the intensity I in [0, 1].",
              0.0, 0.5),
    ParamSpec("picture.gamma", 1.0, "float",
              "Rendered pictures: gamma, the picture is I^(1/gamma) after the noise; 1 = linear.",
              0.2, 5.0),
    ParamSpec("picture.whole_every", 1, "int",
              "Rendered pictures of a tag: the whole picture is rendered at every "
              "whole_every-th frame; at the frames between only a window around the tag, "
              "pasted into the last whole picture (the window is exact, the arm outside it "
              "is up to whole_every - 1 frames old); 1 = every picture whole.", 1, 1000),
    ParamSpec("faults.nan_pixels", [0.0, 0.0], "float_list",
              "Fault injection: frames captured in [start, start + length] carry NaN pixels "
              "[s, s]; length 0 = off.", 0.0, None),
    ParamSpec("faults.nan_joint_states", [0.0, 0.0], "float_list",
              "Fault injection: joint positions read NaN in [start, start + length] [s, s].",
              0.0, None),
    ParamSpec("faults.dropout", [0.0, 0.0], "float_list",
              "Fault injection: frames captured in [start, start + length] are lost [s, s].",
              0.0, None),
    ParamSpec("faults.occlusion", [0.0, 0.0], "float_list",
              "Fault injection: point 1 hidden in [start, start + length] [s, s] (rendered: an "
              "occluder in front of it; points: its frames are lost).", 0.0, None),
    ParamSpec("faults.drop_every", 0, "int",
              "Fault injection: every k-th frame is lost; 0 = none.", 0, None),
    ParamSpec("timing_mode", "lockstep", "str",
              "lockstep: wait for the command answering each state; realtime: wall-clock timer."),
    ParamSpec("command_timeout", 1.0, "float",
              "lockstep: wall time to wait for a command before applying zero torque (and, "
              "with frame_ack, for a frame's acknowledgement); realtime: a command older than "
              "this is not applied (zero torque; the brakes with hardware.command_topic) [s].",
              1e-3, 60.0),
    ParamSpec("frame_ack", False, "bool",
              "lockstep: after publishing a camera frame, wait until every subscriber has "
              "acknowledged it before the joint state follows (wait_for_all_acked). Costs up to "
              "a DDS heartbeat period per frame (about 100 ms with Cyclone DDS's defaults); "
              "without it the frame is published first and, on one host, arrives first."),
    ParamSpec("detector_timeout", 0.5, "float",
              "lockstep, rendered: wall time to wait for the feature detector to have processed "
              "a picture (/feature_detector/processed) before the joint state follows [s].",
              1e-3, 60.0),
    ParamSpec("hardware.command_topic", "", "str",
              "realtime: empty = the commands come as std_msgs/Float64MultiArray on "
              "/effort_controller/commands (joint_names order); a topic name = the simulator "
              "is a ros2_control hardware behind JointStateTopicSystem: the commands come as "
              "sensor_msgs/JointState (efforts in 'effort', joints by name) on this topic, and "
              "without a command (before the first, or none for command_timeout) the arm is "
              "held still on its brakes instead of getting zero torque."),
    ParamSpec("hardware.state_topic", "/joint_states", "str",
              "Topic of the simulator's sensor_msgs/JointState; with hardware.command_topic it "
              "is JointStateTopicSystem's joint_states_topic and must not be /joint_states "
              "(joint_state_broadcaster publishes there)."),
    ParamSpec("hardware.effort_controller", "", "str",
              "With hardware.command_topic: the controller that drives this hardware's effort "
              "interfaces; while hardware.controller_manager/activity does not report it "
              "active, the arm is held on its brakes (as a real driver stops when no controller "
              "claims its interfaces; JointGroupEffortController commands zero effort when "
              "deactivated, and the arm would fall). Empty: not watched (needs "
              "controller_manager_msgs)."),
    ParamSpec("hardware.controller_manager", "/controller_manager", "str",
              "The controller_manager whose ~/activity hardware.effort_controller is read from."),
    ParamSpec("start.wait_for_recorder", False, "bool",
              "Start only once every recorded topic (visual_adaptive_servo.recording.recorder."
              "TOPICS) has a subscriber and /joint_states, /clock and the features have two "
              "(the controller's and a recorder's); ros2 launch sets it with record:=true."),
    ParamSpec("start.recorder_takes_pictures", True, "bool",
              "With start.wait_for_recorder and camera_mode rendered: wait for the recorder on "
              "/camera/image_raw and /camera/camera_info too (servo.launch.py "
              "record_pictures:=false sets it false)."),
    ParamSpec("render.enabled", False, "bool", "Publish the camera view on ~/image."),
    ParamSpec("render.rate", 10.0, "float", "Rendering rate [Hz].", 0.1, 60.0),
    ParamSpec("render.width", 320, "int", "Rendered image width [px].", 16, 1920),
    ParamSpec("render.height", 240, "int", "Rendered image height [px].", 16, 1080),
)


@dataclass(frozen=True)
class SimArm:
    """The simulator's arm as the configuration knows it: the URDF chain and its points."""

    chain: object               # models.urdf_chain.KinematicChain
    offsets: np.ndarray         # (m, 3) feature offsets in the tip frame [m]

    @property
    def n(self):
        return self.chain.n

    @property
    def m(self):
        return len(self.offsets)

    @property
    def joint_names(self):
        return self.chain.joint_names


def build_sim_arm(values, section=SIM_SECTION, search_dirs=()):
    """The simulator's arm (URDF chain and feature offsets) from the structure parameters."""
    path = resolve_path(values["urdf"], search_dirs, f"{section}.urdf")
    chain = load_chain(path, values["base_link"], values["tip_link"], section)
    check_urdf(path, chain.joint_names, section, simulator=True)
    points = np.asarray(values["feature_points"], dtype=float)
    if points.size == 0 or points.size % 3:
        raise ValueError(f"{section}.feature_points: 3 numbers per point, got {points.size}")
    check_feature_points(points.reshape(-1, 3), chain.n, section)
    return SimArm(chain, points.reshape(-1, 3))


def tag_plate(v, arm, section=SIM_SECTION):
    """The :class:`TagPlate` of ``markers.tag.*`` (None for balls); its points must be the arm's.

    ``feature_points`` are checked against the tag's points here, so that the model and
    the picture cannot disagree: the error gives the values to write.
    """
    if v["markers.type"] not in MARKER_TYPES:
        raise ConfigError(f"{section}.markers.type: must be one of {MARKER_TYPES}, got "
                          f"{v['markers.type']!r}")
    if v["markers.type"] != "apriltag":
        return None
    for name in ("markers.tag.position", "markers.tag.rpy"):
        require_length(v, name, 3, section)
    if len(v["markers.tag.points"]) != arm.m:
        raise ConfigError(f"{section}.markers.tag.points: needs one name per feature point "
                          f"({arm.m}), got {list(v['markers.tag.points'])}")
    try:
        plate = TagPlate(v["markers.tag.family"], v["markers.tag.id"], v["markers.tag.edge"],
                         tuple(v["markers.tag.position"]), tuple(v["markers.tag.rpy"]),
                         tuple(v["markers.tag.points"]), v["markers.tag.margin"])
    except ValueError as exc:
        raise ConfigError(f"{section}.markers.{exc}") from None
    expected = plate.feature_points()
    if not np.allclose(arm.offsets, expected, rtol=0.0, atol=1e-6):
        values = ", ".join(f"{c:.6g}" for c in expected.reshape(-1))
        raise ConfigError(f"{section}.feature_points: must be the tag's points "
                          f"{list(plate.points)} (markers.tag.*) in the tip frame, "
                          f"[{values}]; got {arm.offsets.reshape(-1).tolist()}")
    return plate


@dataclass(frozen=True, eq=False)
class SimConfig(ValidatedParams):
    """Validated parameters of the simulator (``sim_node``): the arm, its camera and timing."""

    arm: SimArm = None
    camera: object = None       # sim_bridge.camera.PinholeCamera
    tag: object = None          # models.tag.TagPlate with markers.type apriltag

    @classmethod
    def from_params(cls, params, section=SIM_SECTION, search_dirs=()):
        arm, v = resolve_params(SIM_PARAMS, params, section,
                                lambda values: build_sim_arm(values, section, search_dirs))
        for name in ("initial_positions", "initial_velocities", "joint_names"):
            require_length(v, name, arm.n, section)
        for name in ("initial_positions", "initial_velocities"):
            require_finite(v, name, section)
        require_length(v, "markers.colors", 3 * arm.m, section)
        for name in ("faults.nan_pixels", "faults.nan_joint_states", "faults.dropout",
                     "faults.occlusion"):
            require_length(v, name, 2, section)
        ratio = v["control_period"] / v["physics_dt"]
        if abs(ratio - round(ratio)) > 1e-9 * ratio:
            raise ConfigError(f"{section}.control_period: must be a whole multiple of "
                              f"physics_dt ({v['physics_dt']}), got {v['control_period']}")
        if v["timing_mode"] not in TIMING_MODES:
            raise ConfigError(f"{section}.timing_mode: must be one of {TIMING_MODES}, "
                              f"got {v['timing_mode']!r}")
        if v["camera_mode"] not in CAMERA_MODES:
            raise ConfigError(f"{section}.camera_mode: must be one of {CAMERA_MODES}, "
                              f"got {v['camera_mode']!r}")
        if v["camera_rate"] * v["control_period"] > 1.0 + 1e-9:
            raise ConfigError(f"{section}.camera_rate: at most one frame per control period "
                              f"({1.0 / v['control_period']:g} Hz), got {v['camera_rate']}")
        if v["camera_stamp_delay"] > v["camera_latency"]:
            raise ConfigError(f"{section}.camera_stamp_delay: at most camera_latency "
                              f"({v['camera_latency']} s; a frame cannot be stamped after it is "
                              f"published), got {v['camera_stamp_delay']}")
        if v["hardware.command_topic"]:
            if v["timing_mode"] != "realtime":
                raise ConfigError(f"{section}.hardware.command_topic: a ros2_control hardware "
                                  f"runs on the controller_manager's clock, so timing_mode must "
                                  f"be 'realtime', got {v['timing_mode']!r}")
            if v["hardware.state_topic"] in ("/joint_states", v["hardware.command_topic"]):
                raise ConfigError(f"{section}.hardware.state_topic: with hardware.command_topic "
                                  f"it must be neither /joint_states (joint_state_broadcaster "
                                  f"publishes there) nor the command topic, got "
                                  f"{v['hardware.state_topic']!r}")
        camera = build_camera(v, "camera.", section)
        return cls(v, arm, camera, tag_plate(v, arm, section))

    @property
    def substeps(self):
        return int(round(self.control_period / self.physics_dt))

    @property
    def image_bounds(self):
        """[u_min, u_max, v_min, v_max] of the simulated picture in the controller's pixels."""
        return self.camera.image_bounds
