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
picture comes from ``pybullet.getCameraImage`` (the TinyRenderer by default:
works in DIRECT mode, no display needed), from the camera centre along its
optical axis Z_C with -Y_C up, over the camera's own frustum: rendered at the
camera's resolution, pixel (row, col) of the picture covers the raw image
coordinates [col, col + 1) x [row, row + 1) of :mod:`.camera`, so a point
projected by :class:`~.camera.PinholeCamera` lands exactly where it is drawn.
Rendered at another size, coordinates scale with it.
"""

from __future__ import annotations

import numpy as np
import pybullet

from visual_adaptive_servo.vision.overlay import draw_points

NEAR = 0.05   # m, clipping planes of the rendered frustum
FAR = 100.0   # m
# PyBullet's TinyRenderer draws a point half a pixel right of and above where the frustum
# puts it (measured: +0.50 columns, -0.50 rows, test_render.py); the frustum is shifted by
# this much so that a rendered point lands on its projection
RENDER_PIXEL_SHIFT = (0.5, -0.5)
# flat lighting: marker spheres render as discs of exactly their colour (shading would
# move a colour-thresholded centroid by up to a pixel)
FLAT_LIGHT = {"lightAmbientCoeff": 1.0, "lightDiffuseCoeff": 0.0, "lightSpecularCoeff": 0.0}


def view_matrices(camera, near=NEAR, far=FAR):
    """PyBullet (view, projection) matrices of a :class:`~.camera.PinholeCamera`."""
    rotation = np.asarray(camera.rotation, dtype=float)
    eye = np.asarray(camera.position, dtype=float)
    view = pybullet.computeViewMatrix(eye.tolist(), (eye + rotation[2]).tolist(),
                                      (-rotation[1]).tolist())
    # frustum at the near plane: raw column c is X_C/Z_C = (c - cx)/fx, row r is
    # Y_C/Z_C = (r - cy)/fy with Y_C pointing down the picture
    W, H = camera.width, camera.height
    du, dv = RENDER_PIXEL_SHIFT
    projection = pybullet.computeProjectionMatrix(
        (du - camera.cx) / camera.fx * near, (W + du - camera.cx) / camera.fx * near,
        -(H + dv - camera.cy) / camera.fy * near, (camera.cy - dv) / camera.fy * near,
        near, far)
    return view, projection


def image_coordinates(pixels, camera, width=None, height=None):
    """(columns, rows), continuous, in a width x height picture of controller pixels (2m,)."""
    raw = camera.to_raw(pixels)
    sx = (width or camera.width) / camera.width
    sy = (height or camera.height) / camera.height
    return raw[:, 0] * sx, raw[:, 1] * sy


def render_image(client, camera, width=None, height=None, renderer=None, flat=False):
    """The camera's view as an (height, width, 3) uint8 RGB array (default: its own size).

    ``flat``: ambient light only, every surface in its own colour (for the detector).
    """
    import cv2

    width, height = int(width or camera.width), int(height or camera.height)
    view, projection = view_matrices(camera)
    _, _, rgba, _, _ = pybullet.getCameraImage(
        width, height, viewMatrix=view, projectionMatrix=projection,
        renderer=pybullet.ER_TINY_RENDERER if renderer is None else renderer,
        flags=pybullet.ER_NO_SEGMENTATION_MASK, physicsClientId=client,
        **(FLAT_LIGHT if flat else {}))
    rgba = np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)
    # dropping alpha with OpenCV: 0.2 ms against 1.5 ms for a strided numpy copy (640 x 480)
    return cv2.cvtColor(rgba, cv2.COLOR_RGBA2RGB)


def render_camera_view(client, camera, width, height, markers=()):
    """The camera's view of the PyBullet scene, with markers drawn.

    Parameters
    ----------
    client : int
        PyBullet physics client id (DIRECT mode is fine).
    camera : camera.PinholeCamera
    width, height : int
        Size of the picture [px].
    markers : iterable of (pixels (2m,), colour (3,), shape)
        Feature pixels (controller convention) to draw; non-finite ones are skipped.

    Returns
    -------
    (height, width, 3) uint8 RGB array.
    """
    rgb = render_image(client, camera, width, height)
    for pixels, color, shape in markers:
        if pixels is not None:
            cols, rows = image_coordinates(pixels, camera, width, height)
            draw_points(rgb, np.column_stack([cols, rows]), color, shape)
    return rgb
