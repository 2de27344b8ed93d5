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

"""The fast pictures (a tag window, OpenCV's noise arithmetic) against the slow ones.

Oracles: the whole picture rendered by the TinyRenderer at the same joint positions
(``picture.whole_every: 1``, same seed), the detector's corners on it, and the
noise formula written out in numpy.
"""

import os

import cv2
import numpy as np
import pytest

from conftest import ROOT

from sim_bridge import render
from sim_bridge.simulator import Simulator
from visual_adaptive_servo.config.scenario import load_scenario

CONFIG = os.path.join(ROOT, "config", "iiwa_apriltag.yaml")
# pixels where a window and the whole picture may differ: a triangle edge through a pixel's
# sample point, decided differently by the float32 rasteriser in the two viewports
SAME_PIXELS = 0.999


def _poses(q0, frames, amplitude=0.05):
    """A smooth path (frames, n) around q0; 0.05 rad moves the tag 5-20 px a frame."""
    phase = np.linspace(0.0, 2.0 * np.pi, frames)[:, None]
    return np.asarray(q0, float) + amplitude * np.sin(phase + np.arange(len(q0))[None, :])


def _simulator(*overrides):
    return Simulator(load_scenario(CONFIG, list(overrides)).sim)


def test_a_window_of_the_frustum_renders_the_whole_pictures_pixels():
    sim = _simulator()
    try:
        maker = sim.pictures
        for q in _poses(sim.config.initial_positions, 3, 0.1):
            sim.plant.reset(q)
            sim._show_markers()
            whole_rgb, whole_depth = maker._render(maker.client)
            for window in ((37, 11, 301, 217), (500, 391, 640, 480), (0, 0, 640, 480),
                           render.tag_window(sim._plate_outline(), 640, 480)):
                rgb, depth = maker._render(maker.client, window)
                c0, r0, c1, r1 = window
                assert rgb.shape == (r1 - r0, c1 - c0, 3)
                same = np.all(rgb == whole_rgb[r0:r1, c0:c1], axis=2)
                assert same.mean() >= SAME_PIXELS, (window, same.mean())
                np.testing.assert_allclose(depth[same], whole_depth[r0:r1, c0:c1][same],
                                           rtol=1e-5)
    finally:
        sim.close()


def test_windowed_pictures_are_the_whole_ones_inside_the_window_and_the_last_whole_outside():
    """Noise off (pixel by pixel): every 4th picture whole, the windows in between.

    Outside the window: the last whole picture without the plate, i.e. the surroundings
    where the plate was (the tag is not shown twice) and the arm elsewhere.
    """
    quiet = ("sim_node.picture.read_noise=0.0", "sim_node.picture.shot_noise=0.0")
    slow = _simulator(*quiet, "sim_node.picture.whole_every=1")
    fast = _simulator(*quiet, "sim_node.picture.whole_every=4")
    detector = load_scenario(CONFIG).detector.detector()
    try:
        base = None
        for k, q in enumerate(_poses(slow.config.initial_positions, 12)):
            for sim in (slow, fast):
                sim.plant.reset(q)
            expected, picture = slow._render(), fast._render()
            window = fast.pictures.last_window
            assert (window is None) == (k % 4 == 0), (k, window)
            if window is None:
                np.testing.assert_array_equal(picture, expected)
                base = cv2.LUT(fast.pictures._base, fast.pictures._gamma_table)
                # the base is the whole picture but for the plate, and holds no tag
                differ = np.any(base != picture, axis=2)
                assert 0 < differ.sum() < 0.1 * differ.size
                assert detector.detect(base).pixels is None
                continue
            c0, r0, c1, r1 = window
            inside = np.zeros(picture.shape[:2], bool)
            inside[r0:r1, c0:c1] = True
            same = np.all(picture == expected, axis=2)
            assert same[inside].mean() >= SAME_PIXELS
            np.testing.assert_array_equal(picture[~inside], base[~inside])
            outline = fast._plate_outline()
            assert np.all(outline >= (c0, r0)) and np.all(outline <= (c1, r1))
        assert fast.pictures.windows == 9
    finally:
        slow.close()
        fast.close()


@pytest.mark.parametrize("noisy", [False, True])
def test_the_detector_finds_the_same_corners_in_windowed_pictures(noisy):
    """The file's camera-like pictures: the same corners, windowed or whole.

    Without the noise within 0.01 px (the renderings agree but for rasteriser ties).
    With it, the window gets its own draws of the noise (the whole picture other ones):
    the corners then differ by two independent noise errors, each 0.03 px RMS on the
    synthetic warps with 2 % noise (test_apriltag.py): within 0.2 px, 0.08 px RMS.
    """
    quiet = () if noisy else ("sim_node.picture.read_noise=0.0",
                              "sim_node.picture.shot_noise=0.0")
    slow = _simulator(*quiet, "sim_node.picture.whole_every=1")
    fast = _simulator(*quiet, "sim_node.picture.whole_every=5")
    scenario = load_scenario(CONFIG)
    detectors = [scenario.detector.detector(), scenario.detector.detector()]
    differences = []
    try:
        for q in _poses(slow.config.initial_positions, 15):
            found = []
            for sim, detector in zip((slow, fast), detectors):
                sim.plant.reset(q)
                result = detector.detect(sim._render())
                assert result.pixels is not None, result.reason
                found.append(detector.last_corners)
            np.testing.assert_allclose(found[1], found[0], atol=0.2 if noisy else 0.01)
            differences.append(np.linalg.norm(found[1] - found[0], axis=1))
        assert fast.pictures.windows == 12
    finally:
        slow.close()
        fast.close()
    rms = float(np.sqrt(np.mean(np.square(differences))))
    print(f"corner differences: RMS {rms:.2g} px, max {np.max(differences):.2g} px")
    assert rms <= (0.08 if noisy else 0.005)


def test_only_the_windows_get_new_noise_and_no_old_tag_is_left():
    """Noise on: outside the box of this picture's and the last one's windows, the last picture.

    Inside that box a picture is new: where the last picture's window was and this one's
    is not, the base (no plate) with new noise, so no copy of the tag is left and a
    detector searching the whole picture finds the tag once.
    """
    fast = _simulator("sim_node.picture.whole_every=4")
    detector = load_scenario(CONFIG).detector.detector()
    try:
        last, last_window = None, None
        for q in _poses(fast.config.initial_positions, 8, 0.1):
            fast.plant.reset(q)
            picture = fast._render()
            window = fast.pictures.last_window
            if window is not None and last_window is not None:
                # the box around both windows is made again
                (c0, r0), (c1, r1) = (np.minimum(window[:2], last_window[:2]),
                                      np.maximum(window[2:], last_window[2:]))
                kept = np.ones(picture.shape[:2], bool)
                kept[r0:r1, c0:c1] = False
                assert kept.mean() > 0.8
                np.testing.assert_array_equal(picture[kept], last[kept])
                # the window's noise is new: the picture differs from the last one there
                c0, r0, c1, r1 = window
                assert np.mean(picture[r0:r1, c0:c1] != last[r0:r1, c0:c1]) > 0.5
                # a fresh detector, searching the whole picture, finds the tag once
                found = load_scenario(CONFIG).detector.detector().detect(picture)
                assert found.pixels is not None, found.reason
            last, last_window = picture, window if window is not None else None
            assert detector.detect(picture).pixels is not None
        assert fast.pictures.windows == 6
    finally:
        fast.close()


def test_the_tag_window_is_the_widened_bounding_box_clipped_to_the_picture():
    points = np.array([[100.0, 5.0], [250.5, 15.0], [150.0, 75.2]])
    pad = render.WINDOW_MARGIN * 150.5                  # the larger side, 150.5 px
    assert pad > render.MIN_WINDOW_MARGIN and 5.0 - pad < 0.0
    assert render.tag_window(points, 640, 480) == (
        int(np.floor(100.0 - pad)), 0, int(np.ceil(250.5 + pad)), int(np.ceil(75.2 + pad)))
    # a small tag: MIN_WINDOW_MARGIN px
    assert render.tag_window([[300.0, 200.0], [310.0, 205.0]], 640, 480) == (
        300 - render.MIN_WINDOW_MARGIN, 200 - render.MIN_WINDOW_MARGIN,
        310 + render.MIN_WINDOW_MARGIN, 205 + render.MIN_WINDOW_MARGIN)


@pytest.mark.parametrize("points", [
    [[np.nan, 3.0], [10.0, 10.0]],                      # not finite
    [[-500.0, 100.0], [-400.0, 150.0]],                 # off the picture
    [[50.0, 50.0], [450.0, 400.0]],                     # most of the picture: whole
])
def test_no_window_when_it_would_not_help(points):
    assert render.tag_window(points, 640, 480) is None


def test_noise_is_the_rounded_and_saturated_float32_formula():
    """OpenCV's multiply/add against np.clip(np.rint(I + n std(I))) in float32, bit for bit."""
    settings = render.PictureSettings(read_noise=0.05, shot_noise=0.2)
    maker = render.PictureMaker(None, None, settings, seed=7)
    rng = np.random.default_rng(1)
    picture = rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)
    maker._composite = lambda: picture.copy()
    oracle = np.random.default_rng(7)
    for _ in range(3):
        noisy = maker.picture()
        cv2.setRNGSeed(int(oracle.integers(2**31)))
        noise = np.empty(picture.shape, np.float32)
        cv2.randn(noise.reshape(noise.shape[0], -1), 0.0, 1.0)
        levels = np.arange(256, dtype=np.float32) / np.float32(255.0)
        std = (255.0 * np.sqrt(0.05 ** 2 + 0.2 ** 2 * levels)).astype(np.float32)
        expected = np.clip(np.rint(picture.astype(np.float32) + noise * std[picture]), 0, 255)
        np.testing.assert_array_equal(noisy, expected.astype(np.uint8))
        assert 0 < np.count_nonzero(noisy == 0) and 0 < np.count_nonzero(noisy == 255)


def test_a_window_after_a_whole_picture_without_the_plates_window_is_made_whole():
    """The plate's outline unknown at a whole picture: the next window's picture is all new."""
    fast = _simulator("sim_node.picture.whole_every=2", "sim_node.picture.read_noise=0.0",
                      "sim_node.picture.shot_noise=0.0")
    slow = _simulator("sim_node.picture.whole_every=1", "sim_node.picture.read_noise=0.0",
                      "sim_node.picture.shot_noise=0.0")
    try:
        poses = _poses(fast.config.initial_positions, 2, 0.1)
        outline = fast.pictures.tag_outline
        fast.pictures.tag_outline = lambda: None          # e.g. the plate off the picture
        fast.plant.reset(poses[0])
        fast._render()
        assert fast.pictures._last_windows == [None]
        fast.pictures.tag_outline = outline
        for sim in (fast, slow):
            sim.plant.reset(poses[1])
        picture, expected = fast._render(), slow._render()
        assert fast.pictures.last_window is not None
        # made from the window and the base, not from the last picture: where the plate was
        # at the whole picture there is no tag left, the same pixels as every-picture-whole
        # but for the arm outside the window (as of the whole picture)
        c0, r0, c1, r1 = fast.pictures.last_window
        same = np.all(picture[r0:r1, c0:c1] == expected[r0:r1, c0:c1], axis=2)
        assert same.mean() >= SAME_PIXELS
        found = load_scenario(CONFIG).detector.detector().detect(picture)
        assert found.pixels is not None, found.reason
    finally:
        fast.close()
        slow.close()


@pytest.mark.parametrize("config, overrides", [
    (CONFIG, ()),                                   # a tag, 30 Hz, 33 ms late, noise, blur
    (os.path.join(ROOT, "config", "paper_3dof.yaml"),
     ("sim_node.camera_mode=rendered",)),          # balls, a frame at every period
    (os.path.join(ROOT, "config", "paper_3dof.yaml"),
     ("sim_node.camera_mode=rendered", "sim_node.camera_latency=0.01"))])
def test_a_picture_rendered_after_the_joint_state_is_the_one_measure_renders(config,
                                                                             overrides):
    # sim_node in realtime publishes the joint state, then renders (defer_picture): the
    # oracle is the same simulator rendering inside measure(), step for step, byte for byte
    sims = [Simulator(load_scenario(config, list(overrides)).sim) for _ in range(2)]
    try:
        rng = np.random.default_rng(3)
        pictures = 0
        for _ in range(int(round(0.15 / sims[0].config.control_period))):
            now, later = sims[0].measure(), sims[1].measure(defer_picture=True)
            later = sims[1].render_deferred(later)
            assert (now.image is None) == (later.image is None)
            if now.image is not None:
                np.testing.assert_array_equal(later.image, now.image)
                pictures += 1
            np.testing.assert_array_equal(later.q, now.q)
            tau = rng.normal(0.0, 2.0, sims[0].n)
            for sim in sims:
                sim.apply(tau)
        assert pictures >= 3
    finally:
        for sim in sims:
            sim.close()
