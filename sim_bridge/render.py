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

from dataclasses import dataclass

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


@dataclass(frozen=True)
class PictureSettings:
    """How camera-like the rendered pictures are (``sim_node.picture.*``).

    ``surroundings``: a textured floor and clutter behind the arm
    (:func:`.scene.add_surroundings`); ``shading``: directional light with diffuse
    and specular terms (:data:`.scene.CAMERA_LIGHT`) instead of flat colours;
    ``exposure`` [s] and ``exposure_samples``: motion blur, the mean of that many
    pictures spread over the exposure that ends at the capture; ``read_noise`` and
    ``shot_noise``: Gaussian sensor noise of standard deviation
    sqrt(read^2 + shot^2 I) on the intensity I in [0, 1]; ``gamma``: the picture is
    I^(1/gamma) (1: linear), applied after the noise, as in a camera.  Each step on the
    8-bit picture the renderer gives (so the picture's darkest levels are coarse).
    """

    surroundings: bool = False
    shading: bool = False
    exposure: float = 0.0
    exposure_samples: int = 1
    read_noise: float = 0.0
    shot_noise: float = 0.0
    gamma: float = 1.0

    @property
    def blurred(self):
        return self.exposure > 0.0 and self.exposure_samples > 1


class PictureMaker:
    """Camera-like pictures of a PyBullet scene (:class:`PictureSettings`).

    The surroundings do not move, so they are rendered once, in a PyBullet client of
    their own, with their depth; each picture renders only the client's bodies (arm,
    tag plate, occluders) and keeps a pixel of them where it is nearer than the
    surroundings' (the same frustum, so the two depth buffers compare directly).
    That costs about what the arm alone costs: with the floor and the boxes in the
    same client the TinyRenderer takes 4 to 5 times as long (their textured pixels
    cover most of the picture).
    """

    def __init__(self, client, camera, settings, seed=0):
        self.client, self.camera, self.settings = client, camera, settings
        self.rng = np.random.default_rng(seed)
        self.light = {}
        if settings.shading:
            from .scene import CAMERA_LIGHT

            self.light = CAMERA_LIGHT
        self.background = None
        if settings.surroundings:
            self.background = self._render_surroundings(seed)
        self.samples = []

    def _render_surroundings(self, seed):
        from .scene import add_surroundings

        other = pybullet.connect(pybullet.DIRECT)
        try:
            add_surroundings(other, self.camera, seed)
            return self._render(other)
        finally:
            pybullet.disconnect(other)

    def _render(self, client):
        """(rgb (h, w, 3) uint8, depth buffer (h, w) float32) of a client's bodies."""
        W, H = self.camera.width, self.camera.height
        view, projection = view_matrices(self.camera)
        _, _, rgba, depth, _ = pybullet.getCameraImage(
            W, H, viewMatrix=view, projectionMatrix=projection,
            renderer=pybullet.ER_TINY_RENDERER, flags=pybullet.ER_NO_SEGMENTATION_MASK,
            physicsClientId=client, **(self.light or FLAT_LIGHT))
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(H, W, 4)[:, :, :3]
        return rgb, np.asarray(depth, dtype=np.float32).reshape(H, W)

    def exposure_sample(self):
        """Render one picture of the exposure now (motion blur: :meth:`picture` averages)."""
        self.samples.append(self._composite())

    def _composite(self):
        import cv2

        rgb, depth = self._render(self.client)
        if self.background is None:
            return rgb
        bg_rgb, bg_depth = self.background
        picture = bg_rgb.copy()
        # cv2.copyTo: 1-2 ms against 5-20 ms for np.where over the 640 x 480 x 3 picture
        cv2.copyTo(rgb, (depth < bg_depth).view(np.uint8), picture)
        return picture

    def picture(self):
        """The picture captured now: (h, w, 3) uint8 RGB."""
        import cv2

        s = self.settings
        frames = self.samples + [self._composite()]
        self.samples = []
        if len(frames) == 1:
            picture = np.ascontiguousarray(frames[0])
        else:
            picture = np.rint(np.mean(np.stack(frames), axis=0)).astype(np.uint8)
        if s.read_noise > 0.0 or s.shot_noise > 0.0:
            # noise of each 8-bit level's intensity I: std sqrt(read^2 + shot^2 I), through a
            # look-up table, and the normal samples by cv2.randn (a third of numpy's time)
            levels = np.arange(256, dtype=np.float32) / np.float32(255.0)
            std = 255.0 * np.sqrt(s.read_noise ** 2 + s.shot_noise ** 2 * levels)
            noise = np.empty(picture.shape, np.float32)
            cv2.setRNGSeed(int(self.rng.integers(2**31)))
            # one channel: on an (h, w, 3) array cv2.randn would fill the first channel only
            cv2.randn(noise.reshape(noise.shape[0], -1), 0.0, 1.0)
            noisy = picture.astype(np.float32) + noise * cv2.LUT(picture, std.astype(np.float32))
            picture = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
        if s.gamma != 1.0:
            picture = cv2.LUT(picture, self._gamma_table)
        return picture

    @property
    def _gamma_table(self):
        levels = np.arange(256) / 255.0
        return np.rint(255.0 * levels ** (1.0 / self.settings.gamma)).astype(np.uint8)
