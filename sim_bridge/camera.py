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

"""The simulated cameras: a general pinhole camera and the feature camera built on it.

ROS-free, numpy only.

Conventions
-----------
* Camera frame as in OpenCV: X_C to the right of the picture, Y_C down, Z_C
  along the optical axis.  ``rotation`` has the camera axes as rows, in world
  coordinates; ``position`` is the camera centre in the world.
* Raw image coordinates (what a real sensor gives): ``col = f beta_x X_C / Z_C + c_x``,
  ``row = f beta_y Y_C / Z_C + c_y``, continuous, with (0, 0) the top-left
  corner of the top-left pixel; the picture is ``width`` x ``height`` pixels.
* The controller's pixels: ``x = pixel_axes * ([col, row] - pixel_origin)``,
  per coordinate, with each axis +-1.  A standard camera uses origin (0, 0) and
  axes (1, 1).  The paper's camera uses origin (320, 240) and axes (-1, -1):
  pixels measured from the optical axis, u to the left and v up in the
  picture, so that ``x = f beta [r_y, r_z] / (r_x + d_C)`` exactly as in
  section 4 of the paper.  The controller never needs to know this map (any
  fixed affine change of pixel coordinates is absorbed by the unknown
  projection); the feature detector uses it to report pixels in this
  convention.
* Depth z = Z_C in metres.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from visual_adaptive_servo.models.urdf_chain import rpy_matrix

CAMERA_KEYS = ("position", "look_at", "up", "rpy", "focal_length", "pixel_scale",
               "principal_point", "image_size", "pixel_origin", "pixel_axes")


def picture_bounds(size, pixel_origin, pixel_axes):
    """[u_min, u_max, v_min, v_max] of a picture of ``size`` (width, height), in controller pixels.

    A controller pixel is ``pixel_axes * (raw - pixel_origin)``.  Also a guessed camera's
    picture, from what its driver tells (``controller_node.image_bounds``' default).
    """
    corners = (np.asarray(pixel_axes, float)
               * (np.array([[0.0, 0.0], np.asarray(size, float)])
                  - np.asarray(pixel_origin, float)))
    u, v = corners[:, 0], corners[:, 1]
    return np.array([u.min(), u.max(), v.min(), v.max()])


@dataclass(frozen=True)
class PinholeCamera:
    """A fixed pinhole camera (see the module docstring for every convention).

    Parameters
    ----------
    rotation : (3, 3)
        Rows X_C, Y_C, Z_C in world coordinates (orthonormal, right-handed).
    position : (3,)
        Camera centre in the world [m].
    fx, fy : float
        Focal length times pixel scale per axis, f beta_x and f beta_y [px].
    cx, cy : float
        Principal point in raw image coordinates [px].
    width, height : int
        Picture size [px].
    pixel_origin, pixel_axes : (2,)
        The map from raw image coordinates to the controller's pixels.
    """

    rotation: np.ndarray
    position: np.ndarray
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    pixel_origin: tuple = (0.0, 0.0)
    pixel_axes: tuple = (1.0, 1.0)

    def __post_init__(self):
        R = np.asarray(self.rotation, dtype=float)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-9) \
                or np.linalg.det(R) < 0.0:
            raise ValueError(f"camera rotation: must be a rotation matrix, got {R.tolist()}")
        object.__setattr__(self, "_P", self._projection())

    def _projection(self):
        R = np.asarray(self.rotation, dtype=float)
        c = np.asarray(self.position, dtype=float)
        K = np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])
        raw = K @ np.hstack([R, (-R @ c)[:, None]])
        axes, origin = np.asarray(self.pixel_axes, float), np.asarray(self.pixel_origin, float)
        P = raw.copy()
        P[:2] = axes[:, None] * (raw[:2] - origin[:, None] * raw[2])
        return P

    @property
    def projection_matrix(self):
        """P (3, 4): ``[x * z, z] = P [r, 1]`` in the controller's pixels, z in metres."""
        return self._P.copy()

    def project(self, points):
        """Controller pixels (2m,) and depths (m,) of world points (m, 3).

        A point on or behind the camera plane gets inf/NaN pixels and depth <= 0.
        """
        h = np.asarray(points, dtype=float).dot(self._P[:, :3].T) + self._P[:, 3]
        z = h[:, 2]
        if min(z.tolist()) > 0.0:
            uv = h[:, :2] / h[:, 2:]
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                uv = h[:, :2] / h[:, 2:]
        return uv.reshape(-1), z

    def to_raw(self, pixels):
        """Raw image coordinates (m, 2) [col, row] of controller pixels (2m,)."""
        uv = np.asarray(pixels, dtype=float).reshape(-1, 2)
        return uv / np.asarray(self.pixel_axes, float) + np.asarray(self.pixel_origin, float)

    @property
    def image_bounds(self):
        """[u_min, u_max, v_min, v_max] of the picture in the controller's pixels."""
        return picture_bounds((self.width, self.height), self.pixel_origin, self.pixel_axes)

    def to_pixels(self, raw):
        """Controller pixels (2m,) of raw image coordinates (m, 2)."""
        raw = np.asarray(raw, dtype=float).reshape(-1, 2)
        return (np.asarray(self.pixel_axes, float)
                * (raw - np.asarray(self.pixel_origin, float))).reshape(-1)

    # -- constructors ---------------------------------------------------------------
    @classmethod
    def look_at(cls, position, target, up, fx, fy, cx, cy, width, height,
                pixel_origin=(0.0, 0.0), pixel_axes=(1.0, 1.0)):
        """Camera at ``position`` looking at ``target``, ``up`` pointing up in the picture."""
        position = np.asarray(position, dtype=float)
        z_axis = np.asarray(target, dtype=float) - position
        if np.linalg.norm(z_axis) == 0.0:
            raise ValueError("look_at: must differ from the camera position")
        z_axis = z_axis / np.linalg.norm(z_axis)
        x_axis = np.cross(z_axis, np.asarray(up, dtype=float))   # right = forward x up
        if np.linalg.norm(x_axis) < 1e-9:
            raise ValueError("up: must not be parallel to the viewing direction")
        x_axis = x_axis / np.linalg.norm(x_axis)
        y_axis = np.cross(z_axis, x_axis)                        # down
        return cls(np.array([x_axis, y_axis, z_axis]), position, fx, fy, cx, cy, width, height,
                   tuple(pixel_origin), tuple(pixel_axes))

    @classmethod
    def from_rpy(cls, position, rpy, fx, fy, cx, cy, width, height,
                 pixel_origin=(0.0, 0.0), pixel_axes=(1.0, 1.0)):
        """Camera whose frame (X right, Y down, Z forward) has URDF roll-pitch-yaw ``rpy``."""
        return cls(rpy_matrix(rpy).T, np.asarray(position, dtype=float), fx, fy, cx, cy,
                   width, height, tuple(pixel_origin), tuple(pixel_axes))

    @classmethod
    def paper(cls, focal_length=0.15, scale=900.0, distance=5.0, width=640, height=480):
        """The paper's camera: X_C || Y_0, Y_C || Z_0, Z_C || X_0, centre at (-d_C, 0, 0).

        Pixels from the optical axis with u along Y_0 and v along Z_0, f beta = 135 px.
        """
        fb = focal_length * scale
        return cls.look_at((-distance, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), fb, fb,
                           width / 2.0, height / 2.0, width, height,
                           (width / 2.0, height / 2.0), (-1.0, -1.0))

    @classmethod
    def from_params(cls, values, prefix="camera.", section="sim_node"):
        """The camera of a parameter set (keys ``prefix + CAMERA_KEYS``); ValueError naming one."""
        def get(key):
            return values[prefix + key]

        def where(key):
            return f"{section}.{prefix}{key}"

        for key, size in (("position", 3), ("up", 3), ("pixel_scale", 2),
                          ("principal_point", 2), ("image_size", 2), ("pixel_origin", 2),
                          ("pixel_axes", 2)):
            if len(get(key)) != size:
                raise ValueError(f"{where(key)}: needs {size} values, got {len(get(key))}")
        if get("focal_length") <= 0.0:
            raise ValueError(f"{where('focal_length')}: must be > 0, got {get('focal_length')}")
        if min(get("pixel_scale")) <= 0.0:
            raise ValueError(f"{where('pixel_scale')}: must be > 0, got "
                             f"{list(get('pixel_scale'))}")
        width, height = (float(v) for v in get("image_size"))
        if width < 1 or height < 1 or width != int(width) or height != int(height):
            raise ValueError(f"{where('image_size')}: two whole numbers >= 1, got "
                             f"{list(get('image_size'))}")
        if any(abs(a) != 1.0 for a in get("pixel_axes")):
            raise ValueError(f"{where('pixel_axes')}: each must be 1 or -1, got "
                             f"{list(get('pixel_axes'))}")
        fx, fy = (get("focal_length") * s for s in get("pixel_scale"))
        cx, cy = get("principal_point")
        common = (fx, fy, cx, cy, int(width), int(height), tuple(get("pixel_origin")),
                  tuple(get("pixel_axes")))
        # the orientation says which of look_at (with up) and rpy is read; the other is not
        orientation = get("orientation")
        if orientation not in ("look_at", "rpy"):
            raise ValueError(f"{where('orientation')}: must be 'look_at' (read look_at and "
                             f"up) or 'rpy' (read rpy), got {orientation!r}")
        used = "look_at" if orientation == "look_at" else "rpy"
        if len(get(used)) != 3:
            raise ValueError(f"{where(used)}: needs 3 values with {prefix}orientation "
                             f"{orientation}, got {len(get(used))}")
        try:
            if orientation == "look_at":
                return cls.look_at(get("position"), get("look_at"), get("up"), *common)
            return cls.from_rpy(get("position"), get("rpy"), *common)
        except ValueError as exc:
            raise ValueError(f"{section}.{prefix}{exc}") from None


@dataclass(frozen=True)
class CameraFrame:
    """One camera frame: capture time, pixels (2m,, noisy), true depths (m,) and pixels.

    ``image`` (h, w, 3) uint8 is the rendered picture when the camera renders.
    """

    stamp: float
    pixels: np.ndarray
    depth: np.ndarray
    visible: bool
    true_pixels: np.ndarray = None
    image: np.ndarray = None


class FeatureCamera:
    """The camera as the controller sees it: frames at its own rate, noisy and late.

    A frame is captured at the first control instant at or after each nominal
    frame time k / ``rate`` (so capture times jitter by up to one control period
    when the rates do not divide), gets Gaussian pixel noise, and is published at
    the first control instant at or after its capture time plus ``latency``,
    stamped with its capture time.  Points behind the camera are marked not
    visible.  ``rate`` 0 means a frame at every control instant.
    """

    def __init__(self, camera, pixel_noise_std=0.0, rate=0.0, latency=0.0, seed=0):
        self.camera = camera
        self.noise = float(pixel_noise_std)
        self.period = 1.0 / rate if rate > 0.0 else 0.0
        self.latency = float(latency)
        self.rng = np.random.default_rng(seed)
        self.pending = deque()
        self.captured = 0
        self.published = 0

    def step(self, t, pixels, depth, render=None):
        """Capture a frame at ``t`` if one is due, return the frame published at ``t`` (or None).

        ``pixels`` (2m,) and ``depth`` (m,) are the exact projection at t; ``render``, if
        given, is called at a capture to produce the frame's picture.
        """
        if t >= self.captured * self.period - 1e-9:
            noisy = pixels
            if self.noise > 0.0:
                noisy = pixels + self.rng.normal(0.0, self.noise, pixels.shape)
            self.pending.append(CameraFrame(t, noisy, depth, min(depth.tolist()) > 0.0, pixels,
                                            None if render is None else render()))
            self.captured += 1
        if self.pending and self.pending[0].stamp + self.latency <= t + 1e-9:
            self.published += 1
            return self.pending.popleft()
        return None
