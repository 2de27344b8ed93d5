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

"""Colour-marker feature detection: an RGB image in, the controller's pixels x out.

ROS-free (numpy and OpenCV); ``feature_detector_node`` wraps it.

Pixel convention
----------------
Image coordinates are continuous: (col_c, row_c) = (0, 0) is the top-left
CORNER of the top-left pixel, columns grow to the right and rows downwards, so
the pixel with array index ``[row, col]`` covers [col, col + 1) x [row, row + 1)
and has its centre at (col + 0.5, row + 0.5); a W x H image spans [0, W] x [0, H].
The controller's pixel x = (u, v) of an image point is::

    u = axes_u * (col_c - origin_u),    v = axes_v * (row_c - origin_v)

with ``pixel_origin`` = (origin_u, origin_v), an image point, and
``pixel_axes`` = (axes_u, axes_v), each +1 or -1 (the inverse is
col_c = origin_u + axes_u u, row_c = origin_v + axes_v v).

* A standard camera: origin (0, 0), axes (1, 1), so u = col_c, v = row_c
  (u to the right, v down).  OpenCV and sensor_msgs/CameraInfo put the centre
  of the top-left pixel at (0, 0); origin (0.5, 0.5) gives exactly their
  coordinates (an uncalibrated controller does not care about the half pixel).
* The paper's simulated camera (origin on the optical axis, u to the left and
  v up in the picture): origin (W/2, H/2), axes (-1, -1), so u = W/2 - col_c,
  v = H/2 - row_c.  ``sim_bridge.camera.PinholeCamera`` uses the same map with
  the same two parameters (``PinholeCamera.paper()``: (320, 240), (-1, -1)), so
  a detector configured like the simulated camera reports the simulator's pixels.

Detection, per marker in feature order
--------------------------------------
1. Colour: a pixel belongs to marker i when each of its R, G, B is within
   ``tolerance`` of the marker's colour c_i (max-norm, |p - c_i|_inf <= tolerance),
   ``cv2.inRange`` on exact integer bounds.
2. Blobs: 8-connected components (``cv2.connectedComponentsWithStats``); a blob
   whose pixel count lies outside ``blob_area`` [min, max] is not a marker.
3. Exactly one blob must remain and it must not touch the image border (a marker
   cut by the border has its centroid pulled inwards).  Otherwise the frame gives
   no pixels, and ``reason`` names the marker: missing (and how many blobs the
   area limits rejected), ambiguous (how many blobs), or cut by the border.
4. Sub-pixel centroid by linear unmixing: each pixel p within ``EDGE_MARGIN`` of
   the blob is read as a mix a c + (1 - a) b of the marker's colour c (median over
   the blob) and the local background b (median over a ring further out), with
   coverage a = clip((p - b).(c - b) / |c - b|^2, 0, 1); the centroid is the
   a-weighted mean of the pixel centres.  The weights are linear in the pixel
   values, so anti-aliased edges and a symmetric blur narrower than the margin
   leave the centroid in place, where the thresholded blob's own centroid moves with the marker's
   sub-pixel position.  Anti-aliased discs of radius 4 px (test_detection.py,
   benchmarks/bench_detection.py): the blob centroid is up to 0.23 px off, the
   unmixed one 0.004 px (0.012 px under a blur of sigma 1 px).  Without
   visible background around the blob, or with a background within
   ``MIN_CONTRAST`` of the marker colour, the blob centroid is used
   (``MarkerDetection.refined`` is False).

Images: (h, w, 3) RGB, uint8 (0-255) or float (0-1, rounded to 8 bits); any
strides.  Anything else (empty, another shape or dtype, NaN) is refused with a
reason, never an exception.  Time per 640 x 480 frame with 3 markers: 1.2 to
2.1 ms median on a shared 2-CPU VM, about half of it the three ``cv2.inRange``
passes over the frame; the same pipeline in numpy alone takes 20 to 60 times
as long (benchmarks/bench_detection.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..schema import ConfigError, DETECTOR_SECTION

MAX_MARKERS = 3
EDGE_MARGIN = 3        # px around a blob where partly covered pixels are weighted
BACKGROUND_GAP = 1     # px between that margin and the background ring
MIN_CONTRAST = 10.0    # 8-bit levels: below it the unmixing weights are mostly noise
# EDGE_MARGIN, measured at radius 4 px and tolerance 40 (largest error of 100 positions):
# 2 px lets a Gaussian blur of sigma 1 px move the centroid by 0.056 px (3 px: 0.013);
# 4 px collects more pixel noise (sigma 3 levels: 0.036 px against 0.032 px)
CROP_MARGIN = EDGE_MARGIN + BACKGROUND_GAP + 1    # px around a blob that the crop keeps
_EDGE_KERNEL = np.ones((2 * EDGE_MARGIN + 1,) * 2, np.uint8)
_GAP_KERNEL = np.ones((2 * (EDGE_MARGIN + BACKGROUND_GAP) + 1,) * 2, np.uint8)


def _vector(value, name, length=None):
    where = f"{DETECTOR_SECTION}.{name}"
    try:
        arr = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: must be a list of numbers, got {value!r}") from None
    if length is not None and arr.size != length:
        raise ConfigError(f"{where}: needs {length} values, got {arr.size}")
    if np.isnan(arr).any():
        raise ConfigError(f"{where}: must not contain NaN")
    return arr


def _frozen(arr):
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class DetectorConfig:
    """Validated settings of :func:`detect` (module docstring: the rules and conventions).

    Parameters
    ----------
    colors : (3m,) or (m, 3)
        Marker colours, RGB 0-255, in feature order, 1 <= m <= 3.  Stored as (m, 3).
    tolerance : float
        Per-channel colour tolerance, 0-255.  The colours of two markers must
        differ by more than 2 * tolerance in some channel, so that no pixel
        can belong to both.
    blob_area : (2,)
        [min, max] pixel count of a marker blob, 1 <= min <= max (max may be inf).
    pixel_origin : (2,)
        Image point (col_c, row_c) [px] of controller pixel (0, 0).
    pixel_axes : (2,)
        +1 or -1 for u and for v.

    Raises ConfigError naming ``feature_detector.<parameter>`` and the rule.
    """

    colors: np.ndarray
    tolerance: float
    blob_area: np.ndarray
    pixel_origin: np.ndarray
    pixel_axes: np.ndarray
    lower: np.ndarray = field(init=False, repr=False)   # (m, 3) uint8 inRange bounds
    upper: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        where = f"{DETECTOR_SECTION}."
        colors = _vector(self.colors, "markers.colors")
        if colors.size % 3:
            raise ConfigError(f"{where}markers.colors: needs 3 values per marker, "
                              f"got {colors.size}")
        if not 1 <= colors.size // 3 <= MAX_MARKERS:
            raise ConfigError(f"{where}markers.colors: needs 1 to {MAX_MARKERS} markers "
                              f"(3 to {3 * MAX_MARKERS} values), got {colors.size} values")
        if np.any((colors < 0.0) | (colors > 255.0)):
            raise ConfigError(f"{where}markers.colors: every entry must be in [0, 255], "
                              f"got {colors.tolist()}")
        colors = colors.reshape(-1, 3)

        tolerance = _vector(self.tolerance, "markers.tolerance", 1)[0]
        if not 0.0 <= tolerance <= 255.0:
            raise ConfigError(f"{where}markers.tolerance: must be in [0, 255], got {tolerance}")
        for i in range(len(colors)):
            for j in range(i + 1, len(colors)):
                gap = np.max(np.abs(colors[i] - colors[j]))
                if gap <= 2.0 * tolerance:
                    raise ConfigError(
                        f"{where}markers.tolerance: markers {i + 1} and {j + 1} differ by "
                        f"{gap:g} <= 2 * tolerance = {2.0 * tolerance:g} in every channel, so "
                        f"a pixel could belong to both")

        area = _vector(self.blob_area, "blob_area", 2)
        if not (1.0 <= area[0] <= area[1] and np.isfinite(area[0])):
            raise ConfigError(f"{where}blob_area: needs 1 <= min <= max (min finite), "
                              f"got {area.tolist()}")
        origin = _vector(self.pixel_origin, "pixel_origin", 2)
        if not np.all(np.isfinite(origin)):
            raise ConfigError(f"{where}pixel_origin: must be finite, got {origin.tolist()}")
        axes = _vector(self.pixel_axes, "pixel_axes", 2)
        if not np.all(np.abs(axes) == 1.0):
            raise ConfigError(f"{where}pixel_axes: every entry must be +1 or -1, "
                              f"got {axes.tolist()}")

        # integer bounds: c - tol <= p <= c + tol  <=>  ceil(c - tol) <= p <= floor(c + tol)
        lower = np.clip(np.ceil(colors - tolerance), 0, 255).astype(np.uint8)
        upper = np.clip(np.floor(colors + tolerance), 0, 255).astype(np.uint8)
        object.__setattr__(self, "tolerance", float(tolerance))
        for name, value in (("colors", colors), ("blob_area", area), ("pixel_origin", origin),
                            ("pixel_axes", axes), ("lower", lower), ("upper", upper)):
            object.__setattr__(self, name, _frozen(value))

    @property
    def m(self):
        """Number of markers (feature points)."""
        return len(self.colors)

    def detector(self):
        """A detector for a stream of pictures (``.detect(image)``, as the tag detector's)."""
        return ColorDetector(self)


@dataclass(frozen=True, eq=False)
class MarkerDetection:
    """What :func:`detect` found for one marker.

    ``blobs``: blobs of its colour within the area limits; ``rejected_by_area``:
    blobs of its colour outside them; ``area`` [px] and ``centroid`` (2,)
    (col_c, row_c) in image coordinates of the blob when exactly one was found
    (0 and NaN otherwise); ``refined``: the centroid is the unmixed one (step 4);
    ``problem``: why the marker is unusable, "" when it is.
    """

    blobs: int
    rejected_by_area: int
    area: int
    centroid: np.ndarray
    refined: bool
    problem: str


@dataclass(frozen=True, eq=False)
class DetectionResult:
    """``pixels`` (2m,) in the controller's convention, or None; ``reason`` "" or why not.

    ``markers`` has one :class:`MarkerDetection` per marker (empty when the image
    itself was refused).
    """

    pixels: np.ndarray | None
    reason: str
    markers: tuple = ()


class ColorDetector:
    """:func:`detect` with a fixed configuration (colour markers keep no state between frames)."""

    def __init__(self, config):
        self.config = config

    def detect(self, image):
        return detect(image, self.config)


def controller_pixels(points, config):
    """Controller pixels x (2m,) of image points (m, 2) (col_c, row_c): module docstring."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return ((points - config.pixel_origin) * config.pixel_axes).reshape(-1)


def image_points(pixels, config):
    """Image points (m, 2) (col_c, row_c) of controller pixels x (2m,); inverse of the above."""
    uv = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
    return config.pixel_origin + config.pixel_axes * uv   # axes are +-1: their own inverse


def as_rgb8(image):
    """(image as a C-contiguous (h, w, 3) uint8 array, "") or (None, why it is refused)."""
    if not isinstance(image, np.ndarray):
        return None, f"expected a numpy array, got {type(image).__name__}"
    if image.ndim != 3 or image.shape[2] != 3:
        return None, f"expected shape (h, w, 3), got {image.shape}"
    if image.shape[0] == 0 or image.shape[1] == 0:
        return None, f"empty ({image.shape[0]} x {image.shape[1]} pixels)"
    if image.dtype == np.uint8:
        return np.ascontiguousarray(image), ""
    if image.dtype.kind == "f":
        if not np.all(np.isfinite(image)):
            return None, "contains NaN or infinite values"
        low, high = float(image.min()), float(image.max())
        if low < 0.0 or high > 1.0:
            return None, (f"float values must lie in [0, 1], got [{low:g}, {high:g}] "
                          f"(pass uint8 for 0-255)")
        return np.rint(image * 255.0).astype(np.uint8), ""
    return None, f"dtype {image.dtype} is not supported (uint8 0-255, or float in [0, 1])"


def detect(image, config):
    """Find the markers of ``config`` in ``image``; never raises for a bad image.

    Parameters
    ----------
    image : (h, w, 3) array
        RGB, uint8 or float in [0, 1].
    config : DetectorConfig

    Returns
    -------
    DetectionResult
        ``pixels`` (2m,) float64 when every marker was found exactly once, else
        None and ``reason`` names each unusable marker (``"; "``-separated).
    """
    rgb, problem = as_rgb8(image)
    if rgb is None:
        return DetectionResult(None, f"image: {problem}")
    markers = tuple(_detect_marker(rgb, config, i) for i in range(config.m))
    problems = [f"marker {i + 1} {mk.problem}" for i, mk in enumerate(markers) if mk.problem]
    if problems:
        return DetectionResult(None, "; ".join(problems), markers)
    pixels = controller_pixels([mk.centroid for mk in markers], config)
    return DetectionResult(pixels, "", markers)


def _areas_text(areas):
    shown = ", ".join(str(int(a)) for a in sorted(areas, reverse=True)[:5])
    return f"areas {shown}{', ...' if len(areas) > 5 else ''}"


def _detect_marker(rgb, config, i):
    h, w, _ = rgb.shape
    mask = cv2.inRange(rgb, config.lower[i], config.upper[i])
    x, y, width, height = cv2.boundingRect(mask)
    if width == 0:
        color = ", ".join(f"{c:g}" for c in config.colors[i])
        return MarkerDetection(0, 0, 0, np.full(2, np.nan), False,
                               f"missing: no pixel within tolerance {config.tolerance:g} of "
                               f"RGB ({color})")
    # components only around the pixels of this colour (plus the unmixing margin): on a
    # whole, nearly empty 640x480 mask connectedComponentsWithStats takes ~2 ms, on a
    # marker-sized crop a few microseconds
    r0, c0 = max(y - CROP_MARGIN, 0), max(x - CROP_MARGIN, 0)
    r1, c1 = min(y + height + CROP_MARGIN, h), min(x + width + CROP_MARGIN, w)
    count, labels, stats, centroids = cv2.connectedComponentsWithStats(
        mask[r0:r1, c0:c1], connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    low, high = config.blob_area
    inside = (areas >= low) & (areas <= high)
    kept = np.flatnonzero(inside) + 1          # labels of the blobs within the area limits
    rejected = int(count - 1 - len(kept))
    limits = f"blob_area [{low:g}, {high:g}]"
    if len(kept) != 1:
        if len(kept) == 0:
            why = (f"missing: {rejected} blob{'s' if rejected > 1 else ''} rejected by "
                   f"{limits} ({_areas_text(areas[~inside])})")
        else:
            why = f"ambiguous: {len(kept)} blobs within {limits} ({_areas_text(areas[inside])})"
        return MarkerDetection(len(kept), rejected, 0, np.full(2, np.nan), False, why)
    label = int(kept[0])
    left, top, width, height, area = (int(s) for s in stats[label])
    left, top = left + c0, top + r0
    if left == 0 or top == 0 or left + width == w or top + height == h:
        return MarkerDetection(1, rejected, area, np.full(2, np.nan), False,
                               "touches the image border (its centroid would be biased)")
    centroid = _unmixed_centroid(rgb[r0:r1, c0:c1], labels, label, stats[label])
    if centroid is None:
        return MarkerDetection(1, rejected, area, centroids[label] + (c0 + 0.5, r0 + 0.5),
                               False, "")
    return MarkerDetection(1, rejected, area, centroid + (c0, r0), True, "")


def _unmixed_centroid(rgb, labels, label, stat):
    """(col_c, row_c) of the coverage-weighted blob (module docstring, step 4), or None.

    ``rgb`` and ``labels`` are the same crop, which extends ``CROP_MARGIN`` beyond the
    blob wherever the image does; the result is in the crop's coordinates.
    """
    h, w, _ = rgb.shape
    left, top, width, height = (int(s) for s in stat[:4])
    r0, r1 = max(top - CROP_MARGIN, 0), min(top + height + CROP_MARGIN, h)
    c0, c1 = max(left - CROP_MARGIN, 0), min(left + width + CROP_MARGIN, w)
    lab = labels[r0:r1, c0:c1]
    blob = (lab == label).astype(np.uint8)
    # other blobs of the same colour (specks rejected by area) get no weight
    near = cv2.dilate(blob, _EDGE_KERNEL).astype(bool) & ((lab == 0) | (lab == label))
    far = ~cv2.dilate(blob, _GAP_KERNEL).astype(bool)
    if not far.any():
        return None
    roi = rgb[r0:r1, c0:c1].astype(np.float64)
    marker = np.median(roi[blob.astype(bool)], axis=0)
    background = np.median(roi[far], axis=0)
    contrast = marker - background
    if np.max(np.abs(contrast)) < MIN_CONTRAST:
        return None
    coverage = np.clip((roi - background) @ (contrast / (contrast @ contrast)), 0.0, 1.0)
    coverage[~near] = 0.0
    total = coverage.sum()
    if not total > 0.0:
        return None
    col = coverage.sum(axis=0) @ (np.arange(c0, c1) + 0.5) / total
    row = coverage.sum(axis=1) @ (np.arange(r0, r1) + 0.5) / total
    return np.array([col, row])
