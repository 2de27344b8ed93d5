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

"""The simulated robot + camera as one object: what ``sim_node`` and ``vas run`` drive.

Each control period: :meth:`Simulator.measure` returns the joint state and the
camera frame published now, if any (camera rate, noise and latency applied,
stamped with its capture time, or ``camera_stamp_delay`` after it), then
:meth:`Simulator.apply` holds a torque over the physics sub-steps (or
:meth:`Simulator.hold` holds the arm still on its brakes when there is no
command).  Commands are validated here too: a command of the wrong length or
with NaN/inf is refused and zero torque is applied instead, with the reason
returned to the caller.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from math import isfinite

import numpy as np

import pybullet

from visual_adaptive_servo.models import GRAVITY

from . import render
from .camera import FeatureCamera
from .plant import ArmPlant
from .scene import TagBody


#: the picture of a frame captured by ``Simulator.measure(defer_picture=True)``, until
#: ``Simulator.render_deferred``
DEFERRED = object()


@dataclass(frozen=True)
class Measurement:
    """The sensors at one control instant."""

    t: float
    q: np.ndarray
    qd: np.ndarray
    tau_applied: np.ndarray
    feature_stamp: float | None      # stamp of the frame published now (capture + stamp delay)
    pixels: np.ndarray | None        # (2m,) px, None when no frame is published now
    true_depth: np.ndarray           # (m,) depth at time t (ground truth, plots only)
    true_pixels: np.ndarray          # (2m,) noiseless pixels at time t
    problems: tuple = ()
    image: np.ndarray | None = None  # rendered picture of the frame published now (rendered)
    frame_true_pixels: np.ndarray | None = None   # noiseless pixels at the frame's capture
    true_q: np.ndarray | None = None  # the plant's joint positions (q may carry a fault)


@dataclass(frozen=True)
class Faults:
    """Injected faults, each a window [start, length] in seconds of simulated time.

    ``nan_pixels``: frames captured in the window carry NaN pixels; ``nan_joint_states``:
    joint positions read NaN; ``dropout``: frames captured in the window are not
    published; ``occlusion``: like dropout in points mode, a real occluder in front of
    point 1 when rendered (the detector then misses it); ``drop_every``: every k-th
    frame is not published (0: none).  For robustness tests and campaigns: every case
    is then a plain parameter set, reproducible with ``vas run --set``.
    """

    windows: dict
    drop_every: int = 0
    rendered: bool = False

    NAMES = ("nan_pixels", "nan_joint_states", "dropout", "occlusion")

    @classmethod
    def from_config(cls, config):
        windows = {}
        for name in cls.NAMES:
            window = list(config[f"faults.{name}"])
            windows[name] = tuple(window) if window[1] > 0.0 else None
        return cls(windows, int(config["faults.drop_every"]), config.camera_mode == "rendered")

    def active(self, name, t):
        window = self.windows[name]
        return window is not None and window[0] - 1e-9 <= t < window[0] + window[1] - 1e-9

    def drops(self, stamp, published):
        """Whether the frame captured at ``stamp`` (the ``published``-th) is suppressed."""
        if self.active("dropout", stamp) or (not self.rendered
                                             and self.active("occlusion", stamp)):
            return True
        return self.drop_every > 0 and published % self.drop_every == 0


class Simulator:
    """PyBullet arm + pinhole camera configured by a :class:`SimConfig`.

    The arm is ``sim_node.urdf`` (its chain ``base_link`` -> ``tip_link``), the
    feature points are ``feature_points`` in the tip frame, the camera is
    ``sim_node.camera.*``: nothing here depends on the controller's model.
    """

    def __init__(self, config):
        self.config = config
        arm = config.arm
        self.n = arm.n
        self.plant = ArmPlant(arm.chain.urdf, config.physics_dt, GRAVITY, arm.chain.tip_link,
                              arm.chain.joint_names, arm.offsets)
        self.camera = config.camera
        # the markers are in the scene always (they show in any rendered view); in
        # rendered mode the camera's frames are pictures and the pixels come from a detector
        self.tag = None
        if config.tag is not None:
            self.tag = TagBody(self.plant.client, config.tag)
            self.tag.place(*self.plant.tip_pose())
        else:
            self.plant.add_markers(config["markers.radius"],
                                   np.reshape(config["markers.colors"], (-1, 3)))
        self.rendered = config.camera_mode == "rendered"
        self.faults = Faults.from_config(config)
        self._occluder = None
        if self.rendered and self.faults.windows["occlusion"] is not None:
            self._occluder = self._make_occluder(config)
        self.pictures = None
        if self.rendered:
            settings = render.PictureSettings(
                config["picture.surroundings"], config["picture.shading"],
                config["picture.exposure"], config["picture.exposure_samples"],
                config["picture.read_noise"], config["picture.shot_noise"],
                config["picture.gamma"], config["picture.whole_every"])
            self.pictures = render.PictureMaker(
                self.plant.client, self.camera, settings, config.seed,
                *((None, None) if self.tag is None else (self.tag.body, self._plate_outline)),
                window_bodies=(self.plant.body,))
            self._exposure_times = []
        self.stamp_delay = config.camera_stamp_delay
        self.feature_camera = FeatureCamera(self.camera, config.pixel_noise_std,
                                            config.camera_rate, config.camera_latency, config.seed)
        self.plant.reset(config.initial_positions, config.initial_velocities)
        self.tau = np.zeros(self.n)
        self.step_index = 0
        # read once: SimConfig attribute access goes through __getattr__ (every period)
        self._period = config.control_period
        self._substeps = config.substeps

    @property
    def t(self):
        return self.step_index * self._period

    def measure(self, defer_picture=False):
        """Sensors now: the joint state, and the camera frame published now (if any).

        The ``faults.*`` windows apply here (see :class:`Faults`).  ``defer_picture``
        (rendered): a frame captured now holds :data:`DEFERRED` instead of its picture
        until :meth:`render_deferred`, so that the joint state can be published before
        the render (a realtime loop: the controller computes while the picture renders).
        """
        q, qd = self.plant.joint_state()
        t = self.t
        true_pixels, true_depth = self.camera.project(self.plant.feature_positions())
        self._place_occluder(t)
        if self.rendered and self.pictures.settings.blurred:
            self._expose(t)
        render = None
        if self.rendered:
            render = (lambda: DEFERRED) if defer_picture else self._render
        frame = self.feature_camera.step(t, true_pixels, true_depth, render)
        problems = []
        pixels, stamp, image, frame_truth = None, None, None, None
        measured_q = q
        if self.faults.active("nan_joint_states", t):
            measured_q = np.full_like(q, np.nan)
        if frame is not None and self.faults.drops(frame.stamp, self.feature_camera.published):
            frame = None
        if frame is not None:
            # (camera_stamp_delay: the stamp a driver that stamps on reception writes)
            stamp, frame_truth = frame.stamp + self.stamp_delay, frame.true_pixels
            if self.rendered:
                image = frame.image
            elif frame.visible:
                pixels = frame.pixels
            else:
                stamp = None
                problems.append(f"feature behind the camera at t={frame.stamp:.3f} "
                                f"(depth {frame.depth.tolist()})")
            if pixels is not None and self.faults.active("nan_pixels", frame.stamp):
                pixels = np.full_like(pixels, np.nan)
        return Measurement(t, measured_q, qd, self.tau.copy(), stamp, pixels, true_depth,
                           true_pixels, tuple(problems), image, frame_truth, q)

    def _make_occluder(self, config):
        """The occluder of ``faults.occlusion``: a ball before point 1, a board across a tag."""
        if self.tag is not None:
            half = 0.6 * config.tag.plate_edge
            shape = pybullet.createVisualShape(
                pybullet.GEOM_BOX, halfExtents=[half, half, 0.005],
                rgbaColor=(0.35, 0.35, 0.38, 1.0), physicsClientId=self.plant.client)
        else:
            shape = pybullet.createVisualShape(
                pybullet.GEOM_SPHERE, radius=3.0 * config["markers.radius"],
                rgbaColor=(0.35, 0.35, 0.38, 1.0), physicsClientId=self.plant.client)
        return pybullet.createMultiBody(
            baseMass=0.0, baseVisualShapeIndex=shape, baseCollisionShapeIndex=-1,
            basePosition=(0.0, 0.0, -1e3), physicsClientId=self.plant.client)

    def _place_occluder(self, t):
        """In rendered mode, an occlusion window puts an opaque object between camera and marker.

        Balls: a ball in front of point 1 for the whole window.  A tag: a board, facing
        the camera, that crosses the line of sight to the tag's centre from one side of
        the picture to the other during the window (it covers the tag in its middle part
        and cuts it at both ends).
        """
        if self._occluder is None:
            return
        where = np.array([0.0, 0.0, -1e3])
        if self.faults.active("occlusion", t):
            eye = np.asarray(self.camera.position, dtype=float)
            if self.tag is None:
                point = self.plant.feature_positions()[0]
                where = point + 0.3 * (eye - point)
            else:
                R, p = self.plant.tip_pose()
                centre = p + R @ np.asarray(self.config.tag.position, dtype=float)
                start, length = self.faults.windows["occlusion"]
                # from -1.5 to +1.5 board widths across the view over the window
                side = (3.0 * (t - start) / length - 1.5) * 1.2 * self.config.tag.plate_edge
                where = centre + 0.3 * (eye - centre) \
                    + side * np.asarray(self.camera.rotation[0], dtype=float)
        quaternion = (0.0, 0.0, 0.0, 1.0)
        if self.tag is not None:
            from .scene import rotation_quaternion

            # the board's Z along the optical axis: it faces the camera
            quaternion = rotation_quaternion(np.asarray(self.camera.rotation, dtype=float).T)
        pybullet.resetBasePositionAndOrientation(self._occluder, where.tolist(), quaternion,
                                                 physicsClientId=self.plant.client)

    def _expose(self, t):
        """Motion blur: render the exposure's earlier samples at their instants."""
        settings = self.pictures.settings
        capture = self.feature_camera.captured * self.feature_camera.period
        if not self._exposure_times and t < capture - 1e-9:
            count = settings.exposure_samples
            # the capture renders the last sample; these are the ones before it
            times = [capture - settings.exposure * (count - 1 - j) / (count - 1)
                     for j in range(count - 1)]
            self._exposure_times = [u for u in times if u > t - self._period + 1e-9]
        while self._exposure_times and self._exposure_times[0] <= t + 1e-9:
            self._exposure_times.pop(0)
            if t < capture - 1e-9:
                self._show_markers()
                self.pictures.exposure_sample()
        if t >= capture - 1e-9:
            self._exposure_times = []

    def _show_markers(self):
        if self.tag is not None:
            self.tag.place(*self.plant.tip_pose())
        else:
            self.plant.place_markers()

    def _plate_outline(self):
        """Raw image points (4, 2) of the tag plate's corners now (None if one is behind)."""
        R, p = self.plant.tip_pose()
        pixels, depth = self.camera.project(p + self.config.tag.plate_corners() @ R.T)
        if min(depth.tolist()) <= render.NEAR:
            return None
        return self.camera.to_raw(pixels)

    def render_deferred(self, meas):
        """``meas`` of :meth:`measure` (``defer_picture``) with the picture captured now rendered.

        Call it before the next :meth:`apply` or :meth:`hold`: the plant is still where it
        was at the capture, so the picture is the one :meth:`measure` would have rendered.
        A frame that waits for its latency gets its picture in the camera's queue.
        """
        pending = self.feature_camera.pending
        for i, frame in enumerate(pending):
            if frame.image is DEFERRED:
                pending[i] = replace(frame, image=self._render())
        if meas.image is DEFERRED:
            meas = replace(meas, image=self._render())
        return meas

    def _render(self):
        """The camera's picture now, markers placed (render.PictureMaker: how it looks)."""
        self._show_markers()
        return self.pictures.picture()

    def apply(self, tau):
        """Hold ``tau`` for one control period; returns a reason if it was refused."""
        problem = None
        tau = np.asarray(tau, dtype=float).reshape(-1)
        if tau.shape != (self.n,):
            problem = f"command: expected {self.n} torques, got {tau.shape[0]}"
        elif not all(map(isfinite, tau.tolist())):
            problem = f"command: contains NaN or inf: {tau.tolist()}"
        self.tau = np.zeros(self.n) if problem else tau
        self.plant.advance(self.tau, self._substeps)
        self.step_index += 1
        return problem

    def hold(self):
        """Hold the arm still for one control period, on its brakes (no command to apply).

        The joints stop where they are and no torque is applied; time and the
        camera go on as with :meth:`apply`.
        """
        self.tau = np.zeros(self.n)
        self.plant.brake(self._substeps)
        self.step_index += 1

    def close(self):
        self.plant.close()
