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

"""Markers drawn on pictures land in the pixel that contains their image point."""

import numpy as np
import pytest

from visual_adaptive_servo.vision import overlay


@pytest.mark.parametrize("col, row, pixel", [(10.9, 5.2, (5, 10)), (10.0, 5.0, (5, 10)),
                                             (0.4, 0.6, (0, 0))])
def test_cross_is_centred_on_the_pixel_containing_the_point(col, row, pixel):
    rgb = np.zeros((20, 30, 3), np.uint8)
    overlay.draw_marker(rgb, col, row, (1, 2, 3), radius=2, shape="cross")
    drawn = np.argwhere(np.all(rgb == (1, 2, 3), axis=2))
    r, c = pixel
    expected = {(r + d, c) for d in range(-2, 3)} | {(r, c + d) for d in range(-2, 3)}
    assert {tuple(p) for p in drawn} == {(i, j) for i, j in expected if i >= 0 and j >= 0}


def test_ring_surrounds_the_point_and_leaves_its_centre():
    rgb = np.zeros((20, 20, 3), np.uint8)
    overlay.draw_marker(rgb, 10.5, 10.5, overlay.COLOR_MEASURED)
    drawn = np.argwhere(np.all(rgb == overlay.COLOR_MEASURED, axis=2))
    assert tuple(rgb[10, 10]) == (0, 0, 0)
    np.testing.assert_allclose(drawn.mean(axis=0), [10.0, 10.0])
    assert np.all(np.abs(drawn - 10) <= 4)


def test_points_outside_the_picture_or_not_finite_draw_nothing_there():
    rgb = np.zeros((10, 10, 3), np.uint8)
    overlay.draw_points(rgb, [[np.nan, 3.0], [-50.0, 3.0], [np.inf, np.inf]], (9, 9, 9), "ring")
    overlay.draw_points(rgb, None, (9, 9, 9), "ring")
    assert not rgb.any()
    overlay.draw_points(rgb, [[9.5, 9.5]], (9, 9, 9), "cross")     # cut by the border
    assert tuple(rgb[9, 9]) == (9, 9, 9) and rgb.sum() == 9 * 3 * 9
