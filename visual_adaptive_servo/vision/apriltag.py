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

"""AprilTag feature detection: an RGB image in, the chosen tag points in the controller's pixels.

ROS-free (numpy and OpenCV); ``feature_detector_node`` wraps it with
``detector.type: apriltag``.  The points and their order are those of
:mod:`visual_adaptive_servo.models.tag` (the simulator's plate uses the same
definition); the pixel convention is that of :mod:`.detection`.

Detection of one frame
----------------------
1. OpenCV's ArUco detector, decoding each candidate quad against the one code of
   ``tag_id`` (a fifth of the time of the family's 587 codes; another id's quad is
   rejected all the same, and only a miss of the whole picture decodes against the
   family, to name the ids it holds).  Near the tag's last position (a window of
   ``SEARCH_MARGIN``) first ArUco's contour quads, then, when they miss it (some tags
   over ~150 px), the AprilTag 2 quad detection (``CORNER_REFINE_APRILTAG``; quads
   found on the image smoothed by sigma ``QUAD_SIGMA``: on a noisy picture the
   unsmoothed search costs 5-10 times as long and finds nothing more), which also
   searches the whole picture when the tag is not found near its last position.
2. The tag with ``tag_id`` must be found exactly once, with every corner at least
   ``BORDER_MARGIN`` px inside the picture; otherwise no pixels, and ``reason``
   says why (missing, with the ids that were found; ambiguous; cut by the border).
3. Sub-pixel corners by fitting the square's four edges: across each edge,
   between 10 % and 90 % of its length, the edge is located on profiles of the
   grey image (bilinear samples every ``PROFILE_STEP`` px, +-0.45 cell) as the
   point where the profile's area equals that of an ideal dark-to-bright step;
   a total-least-squares line through those points per edge, the corners where
   adjacent lines meet; repeated from the new corners until they move less than
   0.01 px.  The area is linear in the pixel values and a straight edge stays
   straight under any homography, so pixel noise averages out along the edge and
   a symmetric blur leaves the edge in place.  Measured on synthetic warps
   (test/test_apriltag.py): OpenCV's AprilTag corners alone are 0.14 px RMS off
   and biased by 0.07 px, ``cv2.cornerSubPix`` after them 0.25-0.44 px (its
   window sees the data bits next to the corner), the edge fit 0.06 px.
4. The centre is where the refined square's diagonals cross (a homography keeps
   the crossing of the diagonals: it is the projection of the tag's centre).

OpenCV's ArUco (contour) corners count pixel centres from (0, 0), the AprilTag 2
ones are in this package's continuous convention (top-left corner of the image at
(0, 0), measured here: 0.43 px between the two): the contour corners are shifted by
half a pixel, and the fit works in the latter.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..models.tag import CELLS, check_points, CORNER_NAMES, FAMILIES
from ..schema import ConfigError, DETECTOR_SECTION
from .detection import as_rgb8, controller_pixels, DetectionResult

QUAD_SIGMA = 0.8        # px, smoothing before the quad search (AprilTag's quad_sigma)
# window around the last tag: its bounding box + this x its size (0.25: the quad search takes
# 0.56 of its time with 0.5, the same corners; the tag moves a few px a frame at 30 Hz)
SEARCH_MARGIN = 0.25
MIN_SEARCH_MARGIN = 16  # px, at least
BORDER_MARGIN = 3.0     # px between a corner and the picture's border
PROFILE_STEP = 0.1      # px between the samples across an edge
MAX_REFINEMENTS = 5
REMAP_COLUMNS = 1024
CROP_MARGIN = 12.0      # px around the corners that the edge fit reads
MIN_EDGE_CONTRAST = 20.0   # 8-bit levels between the dark border and the white margin


def _dictionary(family):
    return cv2.aruco.getPredefinedDictionary(
        getattr(cv2.aruco, f"DICT_APRILTAG_{family}"))


@dataclass(frozen=True, eq=False)
class TagDetectorConfig:
    """Validated settings of :class:`TagDetector`.

    Parameters
    ----------
    family : str
        AprilTag family, one of :data:`~visual_adaptive_servo.models.tag.FAMILIES`.
    tag_id : int
        The tag's id in its family.
    points : sequence of str
        The feature points, names of :data:`~visual_adaptive_servo.models.tag.TAG_POINTS`.
    pixel_origin, pixel_axes : (2,)
        The controller's pixel convention (:mod:`.detection`).

    Raises ConfigError naming ``feature_detector.<parameter>`` and the rule.
    """

    family: str
    tag_id: int
    points: tuple
    pixel_origin: np.ndarray
    pixel_axes: np.ndarray

    def __post_init__(self):
        where = f"{DETECTOR_SECTION}."
        if self.family not in FAMILIES:
            raise ConfigError(f"{where}tag.family: must be one of {list(FAMILIES)}, got "
                              f"{self.family!r}")
        size = len(_dictionary(self.family).bytesList)
        if not 0 <= int(self.tag_id) < size:
            raise ConfigError(f"{where}tag.id: family {self.family} has ids 0 to {size - 1}, "
                              f"got {self.tag_id}")
        try:
            points = check_points(self.points, f"{where}tag.points")
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        origin = np.array(self.pixel_origin, dtype=float).reshape(-1)
        axes = np.array(self.pixel_axes, dtype=float).reshape(-1)
        if origin.size != 2 or not np.all(np.isfinite(origin)):
            raise ConfigError(f"{where}pixel_origin: needs 2 finite values, got "
                              f"{origin.tolist()}")
        if axes.size != 2 or not np.all(np.abs(axes) == 1.0):
            raise ConfigError(f"{where}pixel_axes: 2 values, each +1 or -1, got "
                              f"{axes.tolist()}")
        origin.setflags(write=False)
        axes.setflags(write=False)
        object.__setattr__(self, "tag_id", int(self.tag_id))
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "pixel_origin", origin)
        object.__setattr__(self, "pixel_axes", axes)

    @property
    def m(self):
        """Number of feature points."""
        return len(self.points)

    def detector(self):
        """A :class:`TagDetector` for a stream of pictures."""
        return TagDetector(self)


class TagDetector:
    """Finds one tag in a stream of pictures (module docstring); remembers where it was."""

    def __init__(self, config):
        self.config = config
        quads = cv2.aruco.DetectorParameters()
        quads.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_APRILTAG
        quads.aprilTagQuadSigma = QUAD_SIGMA
        quick = cv2.aruco.DetectorParameters()
        quick.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
        family = _dictionary(config.family)
        # every candidate quad is decoded against the dictionary: against the family's one
        # tag that costs a fifth of the whole family (587 codes in 36h11); a quad of another
        # id is rejected all the same (its code is >= 11 bits from this one, beyond the
        # error correction), and only a miss asks the whole family which ids are there
        one = cv2.aruco.Dictionary(family.bytesList[config.tag_id:config.tag_id + 1],
                                   family.markerSize, family.maxCorrectionBits)
        self._quads = cv2.aruco.ArucoDetector(one, quads)
        # near the last position first ArUco's own contour quads (a third of the AprilTag
        # quad search's time; they miss some tags over ~150 px, which the quad search finds)
        self._quick = cv2.aruco.ArucoDetector(one, quick)
        self._family = cv2.aruco.ArucoDetector(family, quads)
        self._cells = CELLS[config.family]
        self.last_corners = None    # (4, 2) image points of the last detection

    def detect(self, image):
        """``DetectionResult`` of one picture ((h, w, 3) RGB); never raises for a bad image."""
        rgb, problem = as_rgb8(image)
        if rgb is None:
            return DetectionResult(None, f"image: {problem}")
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        corners, why = None, ""
        if self.last_corners is not None:
            window = self._window(gray.shape)
            corners, why = self._search(gray, window, quick=True)
            if corners is None:
                corners, why = self._search(gray, window)
        if corners is None:
            corners, why = self._search(gray, None)
        if corners is None:
            self.last_corners = None
            return DetectionResult(None, why)
        refined = refine_corners(gray, corners, self._cells)
        h, w = gray.shape
        if refined is None:
            self.last_corners = None
            return DetectionResult(None, f"tag {self.config.tag_id} edges: too little contrast "
                                         f"(< {MIN_EDGE_CONTRAST:g} levels) to fit them")
        if (refined.min() < BORDER_MARGIN or np.any(refined[:, 0] > w - BORDER_MARGIN)
                or np.any(refined[:, 1] > h - BORDER_MARGIN)):
            self.last_corners = None
            return DetectionResult(None, f"tag {self.config.tag_id} cut by the image border "
                                         f"(corners within {BORDER_MARGIN:g} px of it)")
        self.last_corners = refined
        points = tag_points(refined, self.config.points)
        return DetectionResult(controller_pixels(points, self.config), "")

    def _window(self, shape):
        h, w = shape
        low, high = self.last_corners.min(axis=0), self.last_corners.max(axis=0)
        margin = max(SEARCH_MARGIN * float(np.max(high - low)), MIN_SEARCH_MARGIN)
        c0, r0 = (int(max(np.floor(v - margin), 0)) for v in low)
        c1, r1 = int(min(np.ceil(high[0] + margin), w)), int(min(np.ceil(high[1] + margin), h))
        return r0, r1, c0, c1

    def _search(self, gray, window, quick=False):
        """(corners (4, 2) image points, "") of the tag, or (None, why not).

        ``quick``: ArUco's contour quads instead of the AprilTag quad search.
        """
        r0, r1, c0, c1 = window or (0, gray.shape[0], 0, gray.shape[1])
        part = gray[r0:r1, c0:c1]
        found, ids, _ = (self._quick if quick else self._quads).detectMarkers(part)
        mine = 0 if ids is None else ids.size          # every id found is this tag's
        where = "" if window is None else " near its last position"
        if not mine:
            others = [] if window is not None else self._family.detectMarkers(part)[1]
            others = [] if others is None else sorted(set(np.ravel(others).tolist()))
            return None, f"tag {self.config.tag_id} missing{where} (ids found: {others or 'none'})"
        if mine > 1:
            return None, f"tag {self.config.tag_id} ambiguous: found {mine} times"
        # ArUco's contour corners count pixel centres from 0, this module's image points
        # (and the AprilTag quads, nearly) the picture's corner (module docstring)
        shift = 0.5 if quick else 0.0
        return np.asarray(found[0], float).reshape(4, 2) + (c0 + shift, r0 + shift), ""


def tag_points(corners, names):
    """(m, 2) the named points of a tag whose corners (4, 2) are in ``CORNER_NAMES`` order."""
    points = []
    for name in names:
        if name == "center":
            # diagonals c0 + s (c2 - c0) and c1 + t (c3 - c1) meet
            d0, d1 = corners[2] - corners[0], corners[3] - corners[1]
            s, _ = np.linalg.solve(np.column_stack([d0, -d1]), corners[1] - corners[0])
            points.append(corners[0] + s * d0)
        else:
            points.append(corners[CORNER_NAMES.index(name)])
    return np.array(points)


def refine_corners(gray, corners, cells=8):
    """Sub-pixel corners (4, 2) by fitting the square's edges (module docstring, step 3).

    ``gray`` (h, w) uint8; ``corners`` (4, 2) image points (col_c, row_c) of the dark
    square, in order around it.  None when an edge has too little contrast.
    """
    # the profiles reach at most 4 px (plus a move of the corners) beyond the square: the
    # fit works on that part of the picture only
    h, w = gray.shape
    (c0, r0), (c1, r1) = corners.min(axis=0) - CROP_MARGIN, corners.max(axis=0) + CROP_MARGIN
    c0, r0 = max(int(c0), 0), max(int(r0), 0)
    c1, r1 = min(int(np.ceil(c1)), w), min(int(np.ceil(r1)), h)
    image = gray[r0:r1, c0:c1].astype(np.float32)
    offset = np.array([c0, r0], dtype=float)
    corners = corners - offset
    for _ in range(MAX_REFINEMENTS):
        new = _fit_edges(image, corners, cells)
        if new is None:
            return None
        moved = float(np.max(np.abs(new - corners)))
        corners = new
        if moved < 0.01:
            break
    return corners + offset


def _fit_edges(image, corners, cells):
    centre = corners.mean(axis=0)
    edges, maps = [], []
    for i in range(4):
        a, b = corners[i], corners[(i + 1) % 4]
        length = float(np.hypot(*(b - a)))
        along = (b - a) / length
        normal = np.array([along[1], -along[0]])
        if normal @ (a - centre) < 0.0:
            normal = -normal                                  # outwards, towards the white
        half = float(np.clip(0.45 * length / cells, 1.5, 4.0))
        s = np.linspace(0.1 * length, 0.9 * length, max(int(0.8 * length), 8))
        offsets = np.arange(-half, half + 0.5 * PROFILE_STEP, PROFILE_STEP)
        grid = a + s[:, None, None] * along + offsets[None, :, None] * normal
        edges.append((a, along, normal, half, s, grid.shape[:2]))
        maps.append(grid.reshape(-1, 2))
    # one remap for the four edges; samples at array indices: the centre of pixel [r, c] is
    # (c + 0.5, r + 0.5)
    samples = np.concatenate(maps).astype(np.float32) - np.float32(0.5)
    count = len(samples)
    rows = -(-count // REMAP_COLUMNS)           # remap takes maps under 32767 a side
    samples = np.concatenate([samples, np.zeros((rows * REMAP_COLUMNS - count, 2), np.float32)])
    values = cv2.remap(image, samples[:, 0].reshape(rows, -1), samples[:, 1].reshape(rows, -1),
                       cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(-1)[:count]
    lines, start = [], 0
    for a, along, normal, half, s, shape in edges:
        profiles = values[start:start + shape[0] * shape[1]].reshape(shape)
        start += shape[0] * shape[1]
        dark = _median(profiles[:, :3])
        bright = _median(profiles[:, -3:])
        if bright - dark < MIN_EDGE_CONTRAST:
            return None
        bright_part = np.clip((profiles - dark) / (bright - dark), 0.0, 1.0)
        # trapezoid area over [-half, half]: an ideal step at e has area half - e
        area = (bright_part.sum(axis=1)
                - 0.5 * (bright_part[:, 0] + bright_part[:, -1])) * PROFILE_STEP
        points = a + s[:, None] * along + (half - area)[:, None] * normal
        mean = points.mean(axis=0)
        _, _, vt = np.linalg.svd(points - mean, full_matrices=False)
        lines.append((vt[1], vt[1] @ mean))
    refined = np.empty((4, 2))
    for i in range(4):
        (n0, d0), (n1, d1) = lines[i - 1], lines[i]
        refined[i] = np.linalg.solve(np.array([n0, n1]), [d0, d1])
    return refined


def _median(values):
    """np.median of a small array, without its overhead: the mean of the middle two."""
    flat = values.ravel()
    k = flat.size // 2
    part = np.partition(flat, (k - 1, k) if flat.size % 2 == 0 else k)
    return float(part[k]) if flat.size % 2 else 0.5 * (float(part[k - 1]) + float(part[k]))
