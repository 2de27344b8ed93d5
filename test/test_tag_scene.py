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

"""The tag plate in the simulator: its picture, its feature points and their checks.

Oracles: the pinhole projection of the tag's corners (``PinholeCamera.project`` of
``TagPlate.corners`` at the tip pose PyBullet reports) for the rendered picture;
the pictures' own pixel statistics for the sensor noise.
"""

import os

import numpy as np
import pytest

from conftest import ROOT

from sim_bridge import render
from sim_bridge.simulator import Simulator
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.schema import ConfigError

CONFIG = os.path.join(ROOT, "config", "iiwa_apriltag.yaml")


def _projected_corners(sim):
    R, p = sim.plant.tip_pose()
    pixels, _ = sim.camera.project(p + sim.config.tag.corners() @ R.T)
    return pixels.reshape(4, 2)


@pytest.mark.parametrize("q_change", [(0.0,) * 7, (0.1, -0.05, 0.1, 0.08, -0.1, 0.15, 0.3)])
def test_the_rendered_tag_is_detected_on_its_projected_corners(q_change):
    """A camera-like picture: the detector finds the projected corners within 0.3 px.

    Shading, clutter, noise and gamma on; it reports the configured three corners.
    """
    scenario = load_scenario(CONFIG)
    sim = Simulator(scenario.sim)
    try:
        q = np.asarray(scenario.sim.initial_positions) + q_change
        sim.plant.reset(q)
        picture = sim._render()
        detector = scenario.detector.detector()
        found = detector.detect(picture)
        assert found.pixels is not None, found.reason
        truth = _projected_corners(sim)
        np.testing.assert_allclose(detector.last_corners, truth, atol=0.3)
        np.testing.assert_allclose(found.pixels, truth[:3].reshape(-1), atol=0.3)
        # the model's feature points project to the same pixels (by construction)
        R, p = sim.plant.tip_pose()
        model_pixels, _ = sim.camera.project(p + scenario.sim.arm.offsets @ R.T)
        np.testing.assert_allclose(model_pixels, truth[:3].reshape(-1), atol=1e-9)
    finally:
        sim.close()


def test_feature_points_that_are_not_the_tags_are_refused_with_the_right_values():
    with pytest.raises(ConfigError, match=r"sim_node.feature_points: must be the tag's points "
                                          r"\['top_left', 'top_right', 'bottom_right'\].*"
                                          r"\[-0.08, 0.08, 0.046, 0.08, 0.08, 0.046"):
        load_scenario(CONFIG, ["sim_node.markers.tag.edge=0.16",
                               "sim_node.feature_points=[0.0, 0.0, 0.046, 0.08, 0.08, 0.046, "
                               "0.08, -0.08, 0.046]"])
    with pytest.raises(ConfigError, match="sim_node.feature_points: must be the tag's points"):
        load_scenario(CONFIG, ["sim_node.markers.tag.edge=0.12"])


def test_the_controllers_feature_points_must_be_the_tags():
    with pytest.raises(ConfigError, match="controller_node.feature_points: must be the tag's"):
        load_scenario(CONFIG, ["controller_node.feature_points=[-0.08, 0.08, 0.05, 0.08, "
                               "0.08, 0.046, 0.08, -0.08, 0.046]"])


@pytest.mark.parametrize("override, message", [
    ("sim_node.markers.type=stickers", "markers.type: must be one of"),
    ("sim_node.markers.tag.points=[center]", "markers.tag.points: needs one name per"),
    ("sim_node.markers.tag.family=36h12", "tag family"),
    ("feature_detector.type=blobs", "feature_detector.type: must be one of"),
    ("sim_node.picture.whole_every=0", "picture.whole_every"),
])
def test_bad_marker_settings_are_refused_naming_the_parameter(override, message):
    with pytest.raises(ConfigError, match=message):
        load_scenario(CONFIG, [override])


def test_the_scenarios_detector_is_the_tags():
    scenario = load_scenario(CONFIG)
    assert (scenario.detector.family, scenario.detector.tag_id) == ("36h11", 0)
    assert scenario.detector.points == ("top_left", "top_right", "bottom_right")


class _Flat:
    """A PictureMaker whose scene is one grey level (the noise statistics' oracle)."""

    def __init__(self, level, settings, seed=0):
        self.maker = render.PictureMaker(None, None, settings, seed)
        self.level = level
        self.maker._composite = lambda: np.full((200, 200, 3), level, np.uint8)


@pytest.mark.parametrize("level", [30, 128, 230])
def test_sensor_noise_has_the_stated_standard_deviation(level):
    settings = render.PictureSettings(read_noise=0.01, shot_noise=0.03)
    picture = _Flat(level, settings).maker.picture().astype(float)
    expected = 255.0 * np.sqrt(0.01 ** 2 + 0.03 ** 2 * level / 255.0)
    assert abs(picture.std() - expected) < 0.05 * expected
    assert abs(picture.mean() - level) < 0.2


def test_gamma_maps_the_linear_intensity():
    picture = _Flat(64, render.PictureSettings(gamma=2.2)).maker.picture()
    assert int(picture[0, 0, 0]) == round(255.0 * (64 / 255.0) ** (1 / 2.2))


def test_motion_blur_averages_the_renderings_spread_over_the_exposure():
    """Two renderings before each capture, at the first control instants after its samples.

    30 Hz camera (nominal captures at 33.3 and 66.7 ms), 1 ms control, 10 ms exposure in 3
    samples: renderings at the first instants at or after 10 and 5 ms before each nominal
    capture, the third at the capture itself.
    """
    scenario = load_scenario(CONFIG, ["sim_node.picture.exposure=0.01",
                                      "sim_node.picture.exposure_samples=3"])
    sim = Simulator(scenario.sim)
    rendered_at = []
    original = sim.pictures.exposure_sample
    sim.pictures.exposure_sample = lambda: (rendered_at.append(round(sim.t, 4)), original())
    try:
        for _ in range(70):
            sim.measure()
            sim.apply(np.zeros(7))
    finally:
        sim.close()
    assert rendered_at == [0.024, 0.029, 0.057, 0.062]
