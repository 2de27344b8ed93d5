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

"""Drawing x, x_d and x_o on a picture, for image viewers (rqt_image_view, Foxglove).

Used by the simulator's rendered view (``sim_bridge.render``) and the feature
detector's ``~/overlay``.  Positions are continuous image coordinates
(col_c, row_c): (0, 0) is the top-left corner of the top-left pixel, so a
point lies in the pixel with index [floor(row_c), floor(col_c)]
(see :mod:`.detection` for the convention and the mapping from controller pixels).
"""

from __future__ import annotations

import numpy as np

# marker colours (RGB) of the measured feature x, the desired x_d and the observer x_o
COLOR_MEASURED = (230, 30, 30)
COLOR_DESIRED = (30, 200, 30)
COLOR_OBSERVED = (40, 90, 255)


def draw_marker(rgb, col, row, color, radius=4, shape="ring"):
    """Draw a ``ring`` or ``cross`` centred at image point (col, row) into ``rgb`` (h, w, 3).

    In place; parts outside the picture and non-finite positions are skipped.
    """
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
    rows = int(np.floor(row)) + rr[mask]
    cols = int(np.floor(col)) + cc[mask]
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    rgb[rows[inside], cols[inside]] = color


def draw_points(rgb, points, color, shape):
    """Draw one marker per image point of ``points`` (m, 2) [(col, row), ...]; None: nothing."""
    if points is None:
        return
    for col, row in np.asarray(points, dtype=float).reshape(-1, 2):
        draw_marker(rgb, col, row, color, shape=shape)
