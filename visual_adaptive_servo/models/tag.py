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

"""A printed AprilTag on a flat plate on the tip link: where its feature points are.

numpy only.  The one definition of the tag's geometry: the simulator places and
textures the plate from it (``sim_bridge.scene``), the configuration checks that the
feature points of the simulator and of the controller are its points
(``config.sim``, ``config.checks``), and the detector reports the same points in the
same order (``vision.apriltag``), so the model's ``feature_points`` and the picture
agree by construction.

Tag frame: origin at the centre of the tag's black square, X_T to the right and Y_T
up in the printed picture, Z_T out of the printed face (towards whoever can read
it).  ``edge`` is the side of the black square (the tag's outer border, what
AprilTag calls the tag size); the plate adds a white margin around it.  The
corners are named as in the printed picture, and OpenCV's ArUco detector returns
them in the same order: top left, top right, bottom right, bottom left.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .urdf_chain import rpy_matrix

#: the tag's points in the tag frame, in units of half the edge
TAG_POINTS = {"top_left": (-1.0, 1.0), "top_right": (1.0, 1.0),
              "bottom_right": (1.0, -1.0), "bottom_left": (-1.0, -1.0), "center": (0.0, 0.0)}
CORNER_NAMES = ("top_left", "top_right", "bottom_right", "bottom_left")
#: the points a tag gives by default for m = 1, 2, 3 (the centre, a diagonal, three corners)
DEFAULT_POINTS = {1: ("center",), 2: ("top_left", "bottom_right"),
                  3: ("top_left", "top_right", "bottom_right")}
FAMILIES = ("16h5", "25h9", "36h10", "36h11")
#: cells across the black square (data bits plus the 1-cell black border)
CELLS = {"16h5": 6, "25h9": 7, "36h10": 8, "36h11": 8}


def check_points(points, where):
    """``points`` (names of :data:`TAG_POINTS`, 1 to 3 of them, no repeats); ValueError."""
    points = tuple(points)
    unknown = [p for p in points if p not in TAG_POINTS]
    if unknown:
        raise ValueError(f"{where}: unknown tag point(s) {unknown}; choose from "
                         f"{list(TAG_POINTS)}")
    if not 1 <= len(points) <= 3 or len(set(points)) != len(points):
        raise ValueError(f"{where}: 1 to 3 different tag points, got {list(points)}")
    return points


@dataclass(frozen=True)
class TagPlate:
    """An AprilTag of ``family`` and ``tag_id``, black square of ``edge`` [m], on the tip.

    ``position`` (3,) [m] and ``rpy`` (3,) [rad]: the tag frame in the tip frame (URDF
    roll-pitch-yaw); ``points``: names of :data:`TAG_POINTS`, the feature points in
    feature order; ``margin``: white border around the black square, in cells (the
    printed tag's quiet zone; the detector needs at least one).
    """

    family: str
    tag_id: int
    edge: float
    position: tuple
    rpy: tuple
    points: tuple
    margin: float = 1.0

    def __post_init__(self):
        if self.family not in FAMILIES:
            raise ValueError(f"tag family: one of {list(FAMILIES)}, got {self.family!r}")
        if not self.edge > 0.0:
            raise ValueError(f"tag edge: must be > 0, got {self.edge}")
        check_points(self.points, "tag points")

    @property
    def rotation(self):
        """(3, 3): tag axes X_T, Y_T, Z_T as columns, in the tip frame."""
        return rpy_matrix(self.rpy)

    def tag_frame_points(self, names):
        """(k, 3) named points in the tag frame [m]."""
        half = 0.5 * self.edge
        return np.array([[half * TAG_POINTS[n][0], half * TAG_POINTS[n][1], 0.0]
                         for n in names])

    def to_tip(self, points):
        """(k, 3) tag-frame points in the tip frame."""
        return np.asarray(points, float) @ self.rotation.T + np.asarray(self.position, float)

    def feature_points(self):
        """(m, 3) offsets c_i of the feature points in the tip frame [m], feature order."""
        return self.to_tip(self.tag_frame_points(self.points))

    def corners(self):
        """(4, 3) the black square's corners in the tip frame, in :data:`CORNER_NAMES` order."""
        return self.to_tip(self.tag_frame_points(CORNER_NAMES))

    def plate_corners(self):
        """(4, 3) the white plate's corners in the tip frame, in :data:`CORNER_NAMES` order."""
        return self.to_tip(self.tag_frame_points(CORNER_NAMES) * (self.plate_edge / self.edge))

    @property
    def plate_edge(self):
        """Side of the white plate [m]: the black square plus ``margin`` cells each side."""
        return self.edge * (1.0 + 2.0 * self.margin / CELLS[self.family])
