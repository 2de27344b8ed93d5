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

"""Rendering the fixed camera's view of the simulated arm, with features drawn on it.

ROS-free: ``sim_node`` publishes the result as a sensor_msgs/Image.  The
picture comes from ``pybullet.getCameraImage`` with the TinyRenderer (works
in DIRECT mode, no display needed), looking from the camera centre along its
optical axis Z_C with Y_C up; the frustum is the camera's image bounds, so a
pixel coordinate (u, v) of the feature camera (origin on the optical axis)
lands on the same spot of the picture as the point it measures.

The camera axes are right-handed with Z_C forward and Y_C up, so X_C points to
the LEFT of the picture: u grows leftwards and v upwards.  The picture is what
the camera sees, upright; :func:`image_coordinates` does the mapping.
"""

from __future__ import annotations

import numpy as np
import pybullet

NEAR = 0.05   # m, clipping planes of the rendered frustum
FAR = 100.0   # m

# marker colours (RGB) of the measured feature x, the desired x_d and the observer x_o
COLOR_MEASURED = (230, 30, 30)
COLOR_DESIRED = (30, 200, 30)
COLOR_OBSERVED = (40, 90, 255)


def view_matrices(camera, bounds, near=NEAR, far=FAR):
    """PyBullet (view, projection) matrices of ``camera`` over the image ``bounds``.

    Parameters
    ----------
    camera : plant.PinholeCamera
    bounds : (4,) [u_min, u_max, v_min, v_max] in px, origin on the optical axis
    """
    rotation = np.asarray(camera.rotation, dtype=float)
    eye = np.asarray(camera.origin, dtype=float)
    view = pybullet.computeViewMatrix(eye.tolist(), (eye + rotation[2]).tolist(),
                                      rotation[1].tolist())
    u0, u1, v0, v1 = (float(b) for b in bounds)
    fb = camera.focal_length * camera.scale
    # the view's right axis is Z_C x Y_C = -X_C, so u_max is the left edge
    projection = pybullet.computeProjectionMatrix(-u1 / fb * near, -u0 / fb * near,
                                                  v0 / fb * near, v1 / fb * near, near, far)
    return view, projection


def image_coordinates(pixels, bounds, width, height):
    """(columns, rows) in a width x height picture of feature pixels (2m,) [u, v, ...]."""
    uv = np.asarray(pixels, dtype=float).reshape(-1, 2)
    u0, u1, v0, v1 = (float(b) for b in bounds)
    cols = width * (u1 - uv[:, 0]) / (u1 - u0)
    rows = height * (v1 - uv[:, 1]) / (v1 - v0)
    return cols, rows


def draw_marker(rgb, col, row, color, radius=4, shape="ring"):
    """Draw a ``ring`` or ``cross`` centred at (col, row) into ``rgb`` (h, w, 3), in place."""
    h, w, _ = rgb.shape
    if not (np.isfinite(col) and np.isfinite(row)):
        return
    rr, cc = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    if shape == "ring":
        dist = np.hypot(rr, cc)
        mask = np.abs(dist - radius + 0.5) <= 0.8
    elif shape == "cross":
        mask = (rr == 0) | (cc == 0)
    else:
        raise ValueError(f"marker shape: {shape!r} is not ring or cross")
    rows = int(np.rint(row)) + rr[mask]
    cols = int(np.rint(col)) + cc[mask]
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    rgb[rows[inside], cols[inside]] = color


def render_camera_view(client, camera, bounds, width, height, markers=()):
    """The camera's view of the PyBullet scene, with markers drawn.

    Parameters
    ----------
    client : int
        PyBullet physics client id (DIRECT mode is fine).
    camera : plant.PinholeCamera
    bounds : (4,) image bounds [px]
    width, height : int
        Size of the picture [px].
    markers : iterable of (pixels (2m,), colour (3,), shape)
        Feature pixels to draw; non-finite ones are skipped.

    Returns
    -------
    (height, width, 3) uint8 RGB array.
    """
    view, projection = view_matrices(camera, bounds)
    _, _, rgba, _, _ = pybullet.getCameraImage(
        int(width), int(height), viewMatrix=view, projectionMatrix=projection,
        renderer=pybullet.ER_TINY_RENDERER, physicsClientId=client)
    rgb = np.asarray(rgba, dtype=np.uint8).reshape(int(height), int(width), 4)[:, :, :3].copy()
    for pixels, color, shape in markers:
        if pixels is None:
            continue
        cols, rows = image_coordinates(pixels, bounds, width, height)
        for col, row in zip(cols, rows):
            draw_marker(rgb, col, row, color, shape=shape)
    return rgb
