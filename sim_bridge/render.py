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


def view_matrices(camera, near=NEAR, far=FAR, window=None):
    """PyBullet (view, projection) matrices of a :class:`~.camera.PinholeCamera`.

    ``window`` (c0, r0, c1, r1), whole raw pixels: the frustum of columns c0 to c1 and
    rows r0 to r1 of the camera's picture only; rendered at (c1 - c0) x (r1 - r0), pixel
    (i, j) of it is pixel (r0 + i, c0 + j) of the whole picture (:func:`tag_window`).
    """
    rotation = np.asarray(camera.rotation, dtype=float)
    eye = np.asarray(camera.position, dtype=float)
    view = pybullet.computeViewMatrix(eye.tolist(), (eye + rotation[2]).tolist(),
                                      (-rotation[1]).tolist())
    # frustum at the near plane: raw column c is X_C/Z_C = (c - cx)/fx, row r is
    # Y_C/Z_C = (r - cy)/fy with Y_C pointing down the picture
    c0, r0, c1, r1 = window or (0, 0, camera.width, camera.height)
    du, dv = RENDER_PIXEL_SHIFT
    projection = pybullet.computeProjectionMatrix(
        (c0 + du - camera.cx) / camera.fx * near, (c1 + du - camera.cx) / camera.fx * near,
        -(r1 + dv - camera.cy) / camera.fy * near, (camera.cy - r0 - dv) / camera.fy * near,
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


# the tag window (PictureSettings.whole_every): the bounding box of the tag plate's corners
# widened by this part of its size each side, MIN_WINDOW_MARGIN px at least (what the
# AprilTag quad search looks at around the tag: its 4 px threshold tiles and their
# neighbours, 12 px); wider than MAX_WINDOW_FRACTION of the picture, the whole picture
WINDOW_MARGIN = 0.15
MIN_WINDOW_MARGIN = 16
MAX_WINDOW_FRACTION = 0.5
# m added to each side of a link's (collision) bounding box before it is tested against the
# window: its visual mesh may reach a little beyond it
CULL_MARGIN = 0.05


def _bounding(windows):
    """The window (c0, r0, c1, r1) that holds every one of ``windows``."""
    c0, r0, c1, r1 = np.array(windows).T
    return int(c0.min()), int(r0.min()), int(c1.max()), int(r1.max())


def tag_window(points, width, height, margin=WINDOW_MARGIN, min_margin=MIN_WINDOW_MARGIN):
    """The window (c0, r0, c1, r1) of whole raw pixels around raw image points (k, 2).

    Their bounding box widened by ``margin`` x its larger side (at least ``min_margin``
    px) each side, clipped to the width x height picture; None when a point is not
    finite, the window is empty (the points are off the picture) or it covers more than
    ``MAX_WINDOW_FRACTION`` of the picture (then the whole picture costs about as much).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(points)):
        return None
    low, high = points.min(axis=0), points.max(axis=0)
    pad = max(margin * float(np.max(high - low)), float(min_margin))
    c0, r0 = (int(max(np.floor(v - pad), 0)) for v in low)
    c1 = int(min(np.ceil(high[0] + pad), width))
    r1 = int(min(np.ceil(high[1] + pad), height))
    if c1 <= c0 or r1 <= r0 or (c1 - c0) * (r1 - r0) > MAX_WINDOW_FRACTION * width * height:
        return None
    return c0, r0, c1, r1


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

    ``whole_every`` (with a tag): the whole picture is rendered at every
    ``whole_every``-th frame only (1: at every frame); at the frames between, only the
    tag window (:func:`tag_window` of the plate's corners), pasted before the noise into
    the last whole picture rendered without the plate.  Inside the window the picture
    is the whole rendering's; outside it the arm and any occluder are as at the last
    whole picture (the surroundings do not move), and no old copy of the tag is left.
    Only the box around the window and the last picture's window gets new noise (about
    a tenth of the picture here); the rest keeps the last picture's, as the scene there
    is the last whole picture's.
    """

    surroundings: bool = False
    shading: bool = False
    exposure: float = 0.0
    exposure_samples: int = 1
    read_noise: float = 0.0
    shot_noise: float = 0.0
    gamma: float = 1.0
    whole_every: int = 1

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

    ``tag_body`` and ``tag_outline``: the plate's body in ``client`` and a callable
    giving the raw image points (k, 2) of its corners now (None when it cannot: then
    the whole picture); without them every picture is rendered whole.  A window costs
    the TinyRenderer its pixels and every triangle of the visible bodies: the links of
    ``window_bodies`` whose bounding boxes (plus ``CULL_MARGIN``) project outside the
    window are left out of its rendering (``benchmarks/bench_render.py``: the parts).
    """

    def __init__(self, client, camera, settings, seed=0, tag_body=None, tag_outline=None,
                 window_bodies=()):
        self.client, self.camera, self.settings = client, camera, settings
        self.rng = np.random.default_rng(seed)
        self.light = {}
        if settings.shading:
            from .scene import CAMERA_LIGHT

            self.light = CAMERA_LIGHT
        self.background = None
        if settings.surroundings:
            self.background = self._render_surroundings(seed)
        windows = settings.whole_every > 1 and tag_outline is not None
        self.tag_body = tag_body if windows else None
        self.tag_outline = tag_outline if windows else None
        self.frames = 0           # pictures made
        self.windows = 0          # of them, made from a tag window
        self._base = None         # the last whole picture without the plate, before the noise
        # (body, link, rgba) of each link with one visual shape: hidden by alpha 0 (the
        # TinyRenderer skips such shapes), then given its colour back
        self._links = []
        for body in window_bodies if windows else ():
            shapes = pybullet.getVisualShapeData(body, physicsClientId=client)
            links = [shape[1] for shape in shapes]
            self._links += [(body, shape[1], shape[7]) for shape in shapes
                            if links.count(shape[1]) == 1]
        self._windowed = False    # whether the last _composite rendered a window
        self._last = None         # the last picture made, and its windows (None: whole)
        self._last_windows = [None]
        self.last_window = None   # (c0, r0, c1, r1) the last rendering's window, None: whole
        self._noise_std = None
        if settings.read_noise > 0.0 or settings.shot_noise > 0.0:
            levels = np.arange(256, dtype=np.float32) / np.float32(255.0)
            self._noise_std = (255.0 * np.sqrt(settings.read_noise ** 2
                                               + settings.shot_noise ** 2 * levels)
                               ).astype(np.float32)
        self.samples = []

    def _render_surroundings(self, seed):
        from .scene import add_surroundings

        other = pybullet.connect(pybullet.DIRECT)
        try:
            add_surroundings(other, self.camera, seed)
            return self._render(other)
        finally:
            pybullet.disconnect(other)

    def _render(self, client, window=None):
        """(rgb (h, w, 3) uint8, depth buffer (h, w) float32) of a client's bodies.

        ``window`` (c0, r0, c1, r1): that part of the picture only (:func:`view_matrices`).
        """
        import cv2

        c0, r0, c1, r1 = window or (0, 0, self.camera.width, self.camera.height)
        W, H = c1 - c0, r1 - r0
        view, projection = view_matrices(self.camera, window=window)
        _, _, rgba, depth, _ = pybullet.getCameraImage(
            W, H, viewMatrix=view, projectionMatrix=projection,
            renderer=pybullet.ER_TINY_RENDERER, flags=pybullet.ER_NO_SEGMENTATION_MASK,
            physicsClientId=client, **(self.light or FLAT_LIGHT))
        rgb = cv2.cvtColor(np.asarray(rgba, dtype=np.uint8).reshape(H, W, 4), cv2.COLOR_RGBA2RGB)
        return rgb, np.asarray(depth, dtype=np.float32).reshape(H, W)

    def exposure_sample(self):
        """Render one picture of the exposure now (motion blur: :meth:`picture` averages)."""
        self.samples.append((self._composite(), self.last_window))

    def _window(self):
        """The tag window to render now, None for the whole picture."""
        if (self.tag_outline is None or self._base is None
                or self.frames % self.settings.whole_every == 0):
            return None
        outline = self.tag_outline()
        if outline is None:
            return None
        return tag_window(outline, self.camera.width, self.camera.height)

    def _composite(self):
        """The scene now, before the noise: (h, w, 3) uint8 (the tag window when one is due)."""
        window = self._window()
        self._windowed, self.last_window = window is not None, window
        part = self._scene(window)
        if window is None:
            return part
        c0, r0, c1, r1 = window
        picture = self._base.copy()
        picture[r0:r1, c0:c1] = part
        return picture

    def _scene(self, window=None):
        """The client's bodies over the surroundings, by depth, in ``window`` (None: whole)."""
        import cv2

        hidden = self._outside(window) if window is not None else []
        try:
            for body, link, _ in hidden:
                pybullet.changeVisualShape(body, link, rgbaColor=(0, 0, 0, 0),
                                           physicsClientId=self.client)
            rgb, depth = self._render(self.client, window)
        finally:
            for body, link, rgba in hidden:
                pybullet.changeVisualShape(body, link, rgbaColor=rgba,
                                           physicsClientId=self.client)
        if self.background is None:
            return rgb
        bg_rgb, bg_depth = self.background
        if window is not None:
            c0, r0, c1, r1 = window
            bg_rgb, bg_depth = bg_rgb[r0:r1, c0:c1], bg_depth[r0:r1, c0:c1]
        picture = bg_rgb.copy()
        # cv2.copyTo: 1-2 ms against 5-20 ms for np.where over the 640 x 480 x 3 picture
        cv2.copyTo(rgb, (depth < bg_depth).view(np.uint8), picture)
        return picture

    def _outside(self, window):
        """The links whose bounding boxes cannot reach ``window`` (all corners in front)."""
        c0, r0, c1, r1 = window
        corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        outside = []
        for body, link, rgba in self._links:
            low, high = (np.asarray(v) for v in pybullet.getAABB(body, link,
                                                                 physicsClientId=self.client))
            box = np.where(corners, high + CULL_MARGIN, low - CULL_MARGIN)
            pixels, depth = self.camera.project(box)
            if min(depth.tolist()) <= NEAR:
                continue
            raw = self.camera.to_raw(pixels)
            (u0, v0), (u1, v1) = raw.min(axis=0), raw.max(axis=0)
            if u1 < c0 - 1 or u0 > c1 + 1 or v1 < r0 - 1 or v0 > r1 + 1:
                outside.append((body, link, rgba))
        return outside

    def _render_base(self):
        """The whole picture now without the tag plate (what a window is pasted into)."""
        pybullet.changeVisualShape(self.tag_body, -1, rgbaColor=(1, 1, 1, 0),
                                   physicsClientId=self.client)
        try:
            self._base = self._scene()
        finally:
            pybullet.changeVisualShape(self.tag_body, -1, rgbaColor=(1, 1, 1, 1),
                                       physicsClientId=self.client)

    def picture(self):
        """The picture captured now: (h, w, 3) uint8 RGB."""
        shots = self.samples + [(self._composite(), self.last_window)]
        self.samples = []
        windows = [window for _, window in shots]
        region = None
        if self._last is not None and None not in windows + self._last_windows:
            # only the windows' pixels changed since the last picture, and those of the last
            # picture's windows (where the plate was): the rest is the last picture's
            region = _bounding(windows + self._last_windows)
        if self.tag_outline is not None and not self._windowed:
            self._render_base()
            outline = self.tag_outline()
            # where the plate is in this whole picture: the next picture redoes it
            windows = [None] if outline is None else [
                tag_window(outline, self.camera.width, self.camera.height) or
                (0, 0, self.camera.width, self.camera.height)]
        self.frames += 1
        self.windows += self._windowed
        if region is None:
            picture = self._finish([shot for shot, _ in shots])
        else:
            c0, r0, c1, r1 = region
            picture = self._last.copy()
            picture[r0:r1, c0:c1] = self._finish([shot[r0:r1, c0:c1] for shot, _ in shots])
        self._last, self._last_windows = picture, windows
        return picture.copy()

    def _finish(self, shots):
        """The mean of the exposure's renderings with the noise and the gamma: uint8."""
        import cv2

        s = self.settings
        if len(shots) == 1:
            picture = np.ascontiguousarray(shots[0])
        else:
            picture = np.rint(np.mean(np.stack(shots), axis=0)).astype(np.uint8)
        if self._noise_std is not None:
            # noise of each 8-bit level's intensity I: std sqrt(read^2 + shot^2 I), through a
            # look-up table, and the normal samples by cv2.randn (a third of numpy's time)
            noise = np.empty(picture.shape, np.float32)
            cv2.setRNGSeed(int(self.rng.integers(2**31)))
            # one channel: on an (h, w, 3) array cv2.randn would fill the first channel only
            cv2.randn(noise.reshape(noise.shape[0], -1), 0.0, 1.0)
            # picture + noise x std(picture) in float32, rounded to nearest (ties to even) and
            # saturated to 0-255 by OpenCV: the numbers of np.clip(np.rint(...)) without its
            # temporary arrays (the sum of uint8 and float32 would be made in double, and
            # differ in 1 of 1500 values)
            noise = cv2.multiply(noise, cv2.LUT(picture, self._noise_std))
            picture = cv2.add(picture.astype(np.float32), noise, dtype=cv2.CV_8U)
        if s.gamma != 1.0:
            picture = cv2.LUT(picture, self._gamma_table)
        return picture

    @property
    def _gamma_table(self):
        levels = np.arange(256) / 255.0
        return np.rint(255.0 * levels ** (1.0 / self.settings.gamma)).astype(np.uint8)
