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

"""The colour-marker detector: sub-pixel centroids, refusals with reasons, conventions.

Oracles: the exact centroids of supersampled discs (conftest.draw_discs); for
the pixel conventions ``sim_bridge.render.image_coordinates``, which maps the
simulated camera's pixels onto its picture, and the pinhole projection of a
marker sphere that PyBullet renders.

Reached (benchmarks/bench_detection.py, 200 random sub-pixel positions, largest
error per coordinate): noiseless 8-bit discs 0.004 px at radius 4 px and 0.001 px
at 10 px (the thresholded blob's own centroid: 0.23 px and 0.17 px); Gaussian
blur of sigma 1 px 0.012 px, pixel noise of sigma 3 levels 0.031 px at radius 4 px.
"""

import os
import re

import cv2
import numpy as np
import pytest
import yaml

from conftest import ROOT, draw_discs
from sim_bridge import render
from sim_bridge.camera import PinholeCamera
from sim_bridge.plant import URDF_DIR, ArmPlant
from visual_adaptive_servo.config.detector import DETECTOR_PARAMS, detector_config
from visual_adaptive_servo.config.files import flatten
from visual_adaptive_servo.schema import ConfigError
from visual_adaptive_servo.vision.detection import (
    DetectorConfig,
    controller_pixels,
    detect,
    image_points,
)

RED, GREEN, BLUE = (230, 30, 30), (30, 200, 30), (40, 90, 255)
H, W = 480, 640


def _config(colors=RED + GREEN + BLUE, tolerance=40.0, blob_area=(10.0, 5000.0),
            pixel_origin=(0.0, 0.0), pixel_axes=(1.0, 1.0)):
    return DetectorConfig(colors, tolerance, blob_area, pixel_origin, pixel_axes)


def _three_markers(rng, radius):
    """Three discs at random sub-pixel positions, well apart, in feature order."""
    centres = np.array([[150.0, 120.0], [320.0, 300.0], [500.0, 180.0]]) + rng.random((3, 2))
    return [(c, r, radius, color) for (c, r), color in zip(centres, (RED, GREEN, BLUE))]


@pytest.mark.parametrize("radius, bound", [(4.0, 0.01), (6.0, 0.01), (10.0, 0.005)])
def test_centroids_of_antialiased_discs_are_within_a_hundredth_of_a_pixel(
        rng, radius, bound):
    config = _config()
    worst = 0.0
    for _ in range(50):
        image, truth = draw_discs(H, W, _three_markers(rng, radius))
        result = detect(image, config)
        assert result.reason == ""
        assert all(mk.refined for mk in result.markers)
        worst = max(worst, np.max(np.abs(result.pixels - truth.reshape(-1))))
    assert worst < bound


@pytest.mark.parametrize("blur, noise", [(1.0, 0.0), (0.0, 3.0), (1.0, 3.0)])
def test_blur_and_pixel_noise_keep_the_centroid_within_0_05_px(rng, blur, noise):
    config = _config()
    errors = []
    for _ in range(30):
        image, truth = draw_discs(H, W, _three_markers(rng, 6.0))
        picture = image.astype(float)
        if blur:
            picture = cv2.GaussianBlur(picture, (0, 0), blur)
        picture += noise * rng.standard_normal(picture.shape)
        result = detect(np.clip(np.rint(picture), 0, 255).astype(np.uint8), config)
        assert result.reason == ""
        errors.append(np.abs(result.pixels - truth.reshape(-1)))
    assert np.max(errors) < 0.05


def test_missing_marker_gives_no_pixels_and_names_the_marker(rng):
    discs = _three_markers(rng, 6.0)
    image, _ = draw_discs(H, W, discs[:2])
    result = detect(image, _config())
    assert result.pixels is None
    assert result.reason == "marker 3 missing: no pixel within tolerance 40 of RGB (40, 90, 255)"
    assert [mk.blobs for mk in result.markers] == [1, 1, 0]
    assert np.all(np.isfinite(result.markers[0].centroid))


def test_doubled_marker_is_ambiguous_with_the_blob_count(rng):
    discs = _three_markers(rng, 6.0)
    image, _ = draw_discs(H, W, discs + [(400.0, 400.0, 5.0, GREEN)])
    result = detect(image, _config())
    assert result.pixels is None
    assert result.reason.startswith("marker 2 ambiguous: 2 blobs within blob_area [10, 5000]")
    assert result.markers[1].blobs == 2 and result.markers[0].problem == ""


def test_every_unusable_marker_is_named(rng):
    image, _ = draw_discs(H, W, [(100.0, 100.0, 6.0, GREEN), (200.0, 100.0, 6.0, GREEN)])
    first, second, third = detect(image, _config()).reason.split("; ")
    assert first == "marker 1 missing: no pixel within tolerance 40 of RGB (230, 30, 30)"
    assert second.startswith("marker 2 ambiguous: 2 blobs within blob_area [10, 5000]")
    assert third == "marker 3 missing: no pixel within tolerance 40 of RGB (40, 90, 255)"


@pytest.mark.parametrize("channel, offset, found", [(1, 40, True), (1, 41, False),
                                                    (0, -40, True), (0, -41, False)])
def test_colour_tolerance_is_per_channel_and_inclusive(channel, offset, found):
    color = np.array(RED)
    color[channel] += offset
    image = np.full((60, 60, 3), 0, np.uint8)
    image[20:30, 20:30] = color
    result = detect(image, _config(colors=RED))
    assert (result.pixels is not None) == found
    if found:
        np.testing.assert_allclose(result.pixels, [25.0, 25.0], atol=1e-12)
    else:
        assert "marker 1 missing: no pixel within tolerance" in result.reason


def test_blobs_outside_the_area_limits_are_ignored_and_counted():
    config = _config(colors=RED, blob_area=(10.0, 200.0))
    image = np.zeros((100, 100, 3), np.uint8)
    image[10:12, 10:12] = RED                    # 4 px: a speck
    result = detect(image, config)
    assert result.reason == "marker 1 missing: 1 blob rejected by blob_area [10, 200] (areas 4)"
    assert result.markers[0].rejected_by_area == 1

    image[50:60, 50:60] = RED                    # 100 px: the marker
    image[80:95, 70:90] = RED                    # 300 px: too large
    result = detect(image, config)
    np.testing.assert_allclose(result.pixels, [55.0, 55.0], atol=1e-12)
    assert (result.markers[0].blobs, result.markers[0].rejected_by_area) == (1, 2)
    assert result.markers[0].area == 100


def test_speck_of_the_marker_colour_next_to_the_marker_gets_no_weight(rng):
    image, truth = draw_discs(H, W, [(200.3, 200.6, 6.0, RED)])
    image[193:195, 209:211] = RED                # 4 px, 2 px from the disc's edge
    result = detect(image, _config(colors=RED))
    assert result.markers[0].rejected_by_area == 1
    np.testing.assert_allclose(result.pixels, truth.reshape(-1), atol=0.01)


@pytest.mark.parametrize("shape, background, tolerance", [
    ((18, 22, 3), (0, 0, 0), 40.0),          # no background ring inside the picture
    ((100, 100, 3), (108, 100, 100), 3.0),   # background 8 levels off: too little contrast
])
def test_blob_centroid_is_the_fallback_without_usable_background(shape, background,
                                                                 tolerance):
    image = np.full(shape, background, np.uint8)
    image[1:17, 1:21] = (100, 100, 100)
    result = detect(image, _config(colors=(100, 100, 100), tolerance=tolerance))
    assert result.reason == "" and not result.markers[0].refined
    np.testing.assert_allclose(result.pixels, [11.0, 9.0], atol=1e-12)


@pytest.mark.parametrize("col, row, touches", [
    (5.0, 100.0, True), (100.0, 5.5, True), (W - 5.0, 100.0, True), (100.0, H - 5.5, True),
    (7.2, 100.0, False), (100.0, H - 7.2, False)])
def test_marker_touching_the_image_border_is_refused(col, row, touches):
    image, truth = draw_discs(H, W, [(col, row, 6.0, RED)])
    result = detect(image, _config(colors=RED))
    if touches:
        assert result.pixels is None
        assert result.reason == ("marker 1 touches the image border (its centroid would be "
                                 "biased)")
    else:
        # one pixel from the border: the background ring is cut, the centroid is not
        np.testing.assert_allclose(result.pixels, truth.reshape(-1), atol=0.01)


@pytest.mark.parametrize("image, reason", [
    (np.zeros((0, 0, 3), np.uint8), r"image: empty \(0 x 0 pixels\)"),
    (np.zeros((0, 640, 3), np.uint8), r"image: empty \(0 x 640 pixels\)"),
    (np.zeros((48, 64), np.uint8), r"image: expected shape \(h, w, 3\), got \(48, 64\)"),
    (np.zeros((48, 64, 4), np.uint8), r"expected shape \(h, w, 3\), got \(48, 64, 4\)"),
    (np.zeros((2, 48, 64, 3), np.uint8), r"expected shape"),
    (np.full((48, 64, 3), np.nan), r"image: contains NaN or infinite values"),
    (np.full((48, 64, 3), np.inf, np.float32), r"contains NaN or infinite values"),
    (np.full((48, 64, 3), 255.0), r"float values must lie in \[0, 1\], got \[255, 255\]"),
    (np.zeros((48, 64, 3), np.int16), r"image: dtype int16 is not supported"),
    (np.zeros((48, 64, 3), bool), r"dtype bool is not supported"),
    (np.zeros((48, 64, 3), object), r"dtype object is not supported"),
    (np.zeros((48, 64, 3), np.uint16), r"dtype uint16 is not supported"),
    ([[[0, 0, 0]]], r"image: expected a numpy array, got list"),
    (None, r"image: expected a numpy array, got NoneType"),
    (b"\x00" * 9, r"expected a numpy array, got bytes"),
])
def test_bad_images_are_refused_with_a_reason(image, reason):
    result = detect(image, _config())
    assert result.pixels is None and result.markers == ()
    assert re.search(reason, result.reason), result.reason


@pytest.mark.parametrize("shape", [(1, 1, 3), (1, 640, 3), (480, 1, 3), (2, 2, 3), (3, 3, 3)])
def test_tiny_images_are_handled(shape):
    for value in (0, 255):
        image = np.full(shape, value, np.uint8)
        image[..., 1:] = 30
        result = detect(image, _config())
        assert result.pixels is None and result.reason.startswith("marker 1 ")


def test_random_noise_gives_a_reason_not_an_exception(rng):
    config = _config(tolerance=60.0)
    for _ in range(5):
        image = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
        result = detect(image, config)
        assert result.pixels is None
        assert result.reason.startswith("marker 1 missing: ") and "blobs rejected" in result.reason


def test_views_with_any_strides_give_the_mapped_centroids(rng):
    image, truth = draw_discs(H, W, _three_markers(rng, 6.0))
    config = _config()
    mirrored = detect(image[:, ::-1], config).pixels.reshape(-1, 2)
    np.testing.assert_allclose(mirrored, np.column_stack([W - truth[:, 0], truth[:, 1]]),
                               atol=0.01)
    bgr = np.ascontiguousarray(image[..., ::-1])
    np.testing.assert_allclose(detect(bgr[..., ::-1], config).pixels, truth.reshape(-1),
                               atol=0.01)
    # every other pixel: pixel k shows the original's 2k (centre 2k + 0.5 -> k + 0.5), so
    # points map to x / 2 + 0.25; point-sampled, not anti-aliased, hence the looser bound
    every_other = detect(image[::2, ::2], _config(blob_area=(4.0, 5000.0))).pixels
    np.testing.assert_allclose(every_other, truth.reshape(-1) / 2.0 + 0.25, atol=0.1)


def test_float_images_in_0_1_equal_their_8_bit_originals(rng):
    image, _ = draw_discs(H, W, _three_markers(rng, 6.0))
    config = _config()
    np.testing.assert_array_equal(detect(image / 255.0, config).pixels,
                                  detect(image, config).pixels)
    np.testing.assert_array_equal(detect((image / 255.0).astype(np.float32), config).pixels,
                                  detect(image, config).pixels)


def test_standard_camera_convention_is_the_image_coordinates(rng):
    image, truth = draw_discs(H, W, _three_markers(rng, 6.0))
    pixels = detect(image, _config(pixel_origin=(0.0, 0.0), pixel_axes=(1.0, 1.0))).pixels
    np.testing.assert_allclose(pixels, truth.reshape(-1), atol=0.01)


@pytest.mark.parametrize("width, height", [(640, 480), (320, 240)])
def test_paper_convention_is_the_inverse_of_the_simulators_picture_mapping(
        rng, width, height):
    image, truth = draw_discs(height, width, [(width * 0.3 + rng.random(), height * 0.6, 5.0,
                                               RED)])
    config = _config(colors=RED, pixel_origin=(width / 2, height / 2),
                     pixel_axes=(-1.0, -1.0))
    pixels = detect(image, config).pixels
    cols, rows = render.image_coordinates(pixels, PinholeCamera.paper(width=width,
                                                                      height=height))
    np.testing.assert_allclose(np.column_stack([cols, rows]), truth, atol=0.01)
    # left of the centre and below it: u > 0, v < 0 in the paper's camera
    assert pixels[0] > 0.0 and pixels[1] < 0.0


@pytest.mark.parametrize("rpy", [(0.3, -0.2, 0.1), (-0.5, 0.4, 2.0)])
@pytest.mark.parametrize("q", [(0.4, 0.3, -0.6), (1.0807, 0.5756, -0.5)])
def test_simulators_rendered_marker_is_found_where_the_camera_projects_it(q, rpy):
    """A general camera (off-centre principal point, unequal scales, mirrored pixel axes)."""
    with ArmPlant(f"{URDF_DIR}/paper_rrr.urdf") as plant:
        plant.reset(q)
        plant.add_markers(0.12, [RED])
        target = plant.feature_positions()[0]
        R = PinholeCamera.from_rpy((0.0, 0.0, 0.0), rpy, 1.0, 1.0, 0.0, 0.0, 1, 1).rotation
        camera = PinholeCamera(R, target - 3.0 * R[2] + 0.2 * R[0], 420.0, 380.0, 150.3,
                               101.7, 301, 211, (150.3, 101.7), (-1.0, -1.0))
        image = render.render_image(plant.client, camera)
        pixels, _ = camera.project(plant.feature_positions())
    # the renderer shades the sphere (R from ~140 to ~230), hence the wide tolerance; the
    # shading also shifts the blob: 0.1 to 1.2 px measured, where a wrong convention would
    # be tens of pixels off or mirrored
    config = _config(colors=RED, tolerance=100.0, pixel_origin=(150.3, 101.7),
                     pixel_axes=(-1.0, -1.0))
    result = detect(image, config)
    assert result.reason == "" and result.markers[0].area > 500
    np.testing.assert_allclose(result.pixels, pixels, atol=1.5)


@pytest.mark.parametrize("origin, axes", [((0.0, 0.0), (1.0, 1.0)), ((320.0, 240.0), (-1.0, -1.0)),
                                          ((0.5, 480.0), (1.0, -1.0))])
def test_image_points_invert_controller_pixels(rng, origin, axes):
    config = _config(pixel_origin=origin, pixel_axes=axes)
    points = rng.uniform(0.0, 640.0, (3, 2))
    pixels = controller_pixels(points, config)
    np.testing.assert_allclose(pixels.reshape(-1, 2)[:, 0], axes[0] * (points[:, 0] - origin[0]))
    np.testing.assert_allclose(pixels.reshape(-1, 2)[:, 1], axes[1] * (points[:, 1] - origin[1]))
    np.testing.assert_allclose(image_points(pixels, config), points, atol=1e-12)


@pytest.mark.parametrize("changes, message", [
    ({"colors": [230, 30, 30, 1]}, r"feature_detector\.markers\.colors: needs 3 values per "
                                   r"marker, got 4$"),
    ({"colors": [0.0] * 12}, r"markers\.colors: needs 1 to 3 markers \(3 to 9 values\), got 12"),
    ({"colors": []}, r"markers\.colors: needs 1 to 3 markers \(3 to 9 values\), got 0"),
    ({"colors": [230, 30, 300]}, r"markers\.colors: every entry must be in \[0, 255\]"),
    ({"colors": [230, np.nan, 30]}, r"markers\.colors: must not contain NaN"),
    ({"colors": "red"}, r"markers\.colors: must be a list of numbers, got 'red'"),
    ({"tolerance": -1.0}, r"markers\.tolerance: must be in \[0, 255\], got -1"),
    ({"tolerance": [1.0, 2.0]}, r"markers\.tolerance: needs 1 values, got 2"),
    ({"colors": RED + (230, 60, 30)}, r"markers\.tolerance: markers 1 and 2 differ by 30 <= "
                                      r"2 \* tolerance = 80 in every channel"),
    ({"blob_area": [50.0, 10.0]}, r"blob_area: needs 1 <= min <= max \(min finite\), "
                                  r"got \[50\.0, 10\.0\]"),
    ({"blob_area": [0.0, 10.0]}, r"blob_area: needs 1 <= min <= max"),
    ({"blob_area": [np.inf, np.inf]}, r"blob_area: needs 1 <= min <= max \(min finite\)"),
    ({"blob_area": [10.0]}, r"feature_detector\.blob_area: needs 2 values, got 1"),
    ({"pixel_origin": [np.inf, 0.0]}, r"feature_detector\.pixel_origin: must be finite"),
    ({"pixel_origin": [1.0, 2.0, 3.0]}, r"pixel_origin: needs 2 values, got 3"),
    ({"pixel_axes": [1.0, 0.5]}, r"feature_detector\.pixel_axes: every entry must be \+1 or -1"),
    ({"pixel_axes": [1.0, 0.0]}, r"pixel_axes: every entry must be \+1 or -1"),
])
def test_invalid_configuration_is_refused_naming_the_parameter(changes, message):
    kwargs = {"colors": RED + GREEN + BLUE, "tolerance": 40.0, "blob_area": (10.0, 5000.0),
              "pixel_origin": (0.0, 0.0), "pixel_axes": (1.0, 1.0)}
    kwargs.update(changes)
    with pytest.raises(ConfigError, match=message):
        _config(**kwargs)


def test_unbounded_blob_area_is_allowed():
    config = _config(colors=RED, blob_area=(10.0, np.inf))
    image = np.zeros((100, 100, 3), np.uint8)
    image[20:80, 20:80] = RED
    np.testing.assert_allclose(detect(image, config).pixels, [50.0, 50.0], atol=1e-12)


def test_config_is_immutable():
    config = _config()
    assert config.m == 3 and config.colors.shape == (3, 3)
    with pytest.raises(ValueError):
        config.colors[0, 0] = 0.0
    with pytest.raises(AttributeError):
        config.tolerance = 3.0


def test_shipped_parameter_file_is_valid():
    with open(os.path.join(ROOT, "config", "feature_detector.yaml"), encoding="utf-8") as f:
        params = flatten(yaml.safe_load(f)["feature_detector"]["ros__parameters"])
    assert set(params) == {spec.name for spec in DETECTOR_PARAMS}
    assert detector_config(params).m == 1


def test_defaults_are_one_red_marker_in_the_paper_convention_for_640x480():
    config = detector_config({})
    assert config.m == 1
    np.testing.assert_array_equal(config.pixel_origin, [320.0, 240.0])
    np.testing.assert_array_equal(config.pixel_axes, [-1.0, -1.0])
    for spec in DETECTOR_PARAMS:
        assert spec.description.strip(), spec.name


@pytest.mark.parametrize("params, message", [
    ({"markers.colour": [1.0, 2.0, 3.0]}, r"feature_detector: unknown parameter\(s\) "
                                          r"\['markers\.colour'\]"),
    ({"timing_mode": "fast"}, r"feature_detector\.timing_mode: must be one of"),
    ({"markers.tolerance": "wide"}, r"feature_detector\.markers\.tolerance: must be a number"),
    ({"overlay.enabled": "yes"}, r"feature_detector\.overlay\.enabled: must be true or false"),
    ({"markers.colors": [255.0, 0.0, 0.0, 0.0]}, r"markers\.colors: needs 3 values per marker"),
    ({"blob_area": [0.5, 10.0]}, r"feature_detector\.blob_area: must be >= 1\.0, got 0\.5"),
])
def test_parameter_set_is_validated_whole(params, message):
    with pytest.raises(ConfigError, match=message):
        detector_config(params)
