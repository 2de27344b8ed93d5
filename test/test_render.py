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

"""The rendered camera view agrees with the feature camera's pinhole projection.

Oracle: PyBullet's own segmentation mask of the same view.  The midpoint of
link 3 and the tip, projected by :class:`PinholeCamera` and mapped by
:func:`render.image_coordinates`, must fall on pixels of the arm.
"""

import numpy as np
import pybullet
import pytest

from sim_bridge import render
from sim_bridge.camera import PinholeCamera
from sim_bridge.plant import URDF_DIR, ArmPlant
from visual_adaptive_servo.vision import overlay

WIDTH, HEIGHT = 320, 240


@pytest.fixture()
def plant():
    with ArmPlant(f"{URDF_DIR}/paper_rrr.urdf") as arm:
        yield arm


def _segmentation(plant, camera):
    view, projection = render.view_matrices(camera)
    _, _, _, _, seg = pybullet.getCameraImage(
        WIDTH, HEIGHT, viewMatrix=view, projectionMatrix=projection,
        renderer=pybullet.ER_TINY_RENDERER, physicsClientId=plant.client)
    return np.asarray(seg, dtype=np.int64).reshape(HEIGHT, WIDTH)


def _link_origin(plant, link):
    state = pybullet.getLinkState(plant.body, link, computeForwardKinematics=True,
                                  physicsClientId=plant.client)
    return np.array(state[4])


@pytest.mark.parametrize("q", [(1.0807, 0.5756, -0.5), (0.3, 0.2, 0.4), (-0.6, 0.9, -1.2)])
def test_projected_arm_points_land_on_the_rendered_arm(plant, q):
    plant.reset(q)
    camera = PinholeCamera.paper()
    seg = _segmentation(plant, camera)
    tip = plant.tip_position()
    elbow = _link_origin(plant, plant.joints[2])
    for point in (tip, 0.5 * (tip + elbow)):
        pixels, depth = camera.project(point[None, :])
        assert depth[0] > 0.0
        cols, rows = render.image_coordinates(pixels, camera, WIDTH, HEIGHT)
        r, c = int(rows[0]), int(cols[0])
        window = seg[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2]
        assert np.any(window == plant.body), (q, point, r, c)


def test_image_coordinates_put_the_optical_axis_in_the_centre_and_u_to_the_left():
    camera = PinholeCamera.paper()
    cols, rows = render.image_coordinates([0.0, 0.0, 100.0, 50.0], camera, WIDTH, HEIGHT)
    np.testing.assert_allclose(cols, [160.0, 110.0])
    np.testing.assert_allclose(rows, [120.0, 95.0])


@pytest.mark.parametrize("rpy", [(0.3, -0.2, 0.1), (-0.5, 0.4, 2.0)])
def test_a_general_camera_renders_a_point_where_it_projects(plant, rpy):
    """Off-centre principal point, unequal scales, odd size: the marker is drawn at its pixel."""
    plant.reset((0.4, 0.3, -0.6))
    target = plant.feature_positions()[0]
    R = PinholeCamera.from_rpy((0.0, 0.0, 0.0), rpy, 1.0, 1.0, 0.0, 0.0, 1, 1).rotation
    camera = PinholeCamera(R, target - 3.0 * R[2] + 0.2 * R[0], 420.0, 380.0, 150.3, 101.7, 301,
                           211)
    plant.add_markers(0.12, [(255, 0, 255)])          # encloses the URDF's 8 cm tip sphere
    rgb = render.render_image(plant.client, camera).astype(int)
    pixels, depth = camera.project(plant.feature_positions())
    # the renderer shades the sphere: magenta = red and blue high, green low
    magenta = np.argwhere((rgb[..., 0] > 120) & (rgb[..., 2] > 120) & (rgb[..., 1] < 60))
    assert len(magenta) > 50 and depth[0] > 0
    centroid = magenta.mean(axis=0) + 0.5             # (row, col) of pixel centres
    np.testing.assert_allclose(centroid[::-1], camera.to_raw(pixels)[0], atol=0.5)


def test_render_draws_markers_in_their_colours(plant):
    plant.reset((1.0807, 0.5756, -0.5))
    camera = PinholeCamera.paper()
    x = np.array([65.0, 65.0])
    x_d = np.array([-100.0, -100.0])
    rgb = render.render_camera_view(plant.client, camera, WIDTH, HEIGHT, [
        (x, overlay.COLOR_MEASURED, "ring"), (x_d, overlay.COLOR_DESIRED, "cross"),
        (np.array([np.nan, np.nan]), overlay.COLOR_OBSERVED, "ring"), (None, (0, 0, 0), "ring")])
    assert rgb.shape == (HEIGHT, WIDTH, 3) and rgb.dtype == np.uint8
    cols, rows = render.image_coordinates(x_d, camera, WIDTH, HEIGHT)
    assert tuple(rgb[int(rows[0]), int(cols[0])]) == overlay.COLOR_DESIRED
    cols, rows = render.image_coordinates(x, camera, WIDTH, HEIGHT)
    r, c = int(rows[0]), int(cols[0])
    ring = rgb[r - 5:r + 6, c - 5:c + 6].reshape(-1, 3)
    assert any(tuple(p) == overlay.COLOR_MEASURED for p in ring)
    assert not np.any(np.all(rgb == overlay.COLOR_OBSERVED, axis=2))


def test_unknown_marker_shape_is_refused():
    with pytest.raises(ValueError, match="marker shape"):
        overlay.draw_marker(np.zeros((10, 10, 3), np.uint8), 5, 5, (1, 2, 3), shape="star")


def test_rendered_marker_centroid_lands_on_its_projection():
    """A lone marker ball, flat-lit, anywhere in view: detected where the camera projects it.

    Pins the half-pixel shift of PyBullet's TinyRenderer (render.RENDER_PIXEL_SHIFT): without
    it the mean error is (+0.5, -0.5) raw pixels.
    """
    from visual_adaptive_servo.config.detector import detector_config
    from visual_adaptive_servo.vision.detection import detect

    client = pybullet.connect(pybullet.DIRECT)
    try:
        shape = pybullet.createVisualShape(pybullet.GEOM_SPHERE, radius=0.2,
                                           rgbaColor=(230 / 255, 30 / 255, 30 / 255, 1.0),
                                           physicsClientId=client)
        body = pybullet.createMultiBody(baseMass=0.0, baseVisualShapeIndex=shape,
                                        baseCollisionShapeIndex=-1, physicsClientId=client)
        camera = PinholeCamera.paper()
        config = detector_config({"markers.colors": [230.0, 30.0, 30.0],
                                  "pixel_origin": [320.0, 240.0],
                                  "pixel_axes": [-1.0, -1.0]})
        rng = np.random.default_rng(3)
        errors = []
        for _ in range(30):
            point = rng.uniform([-0.5, -1.5, -0.5], [1.5, 1.5, 2.5])
            pybullet.resetBasePositionAndOrientation(body, point.tolist(), (0, 0, 0, 1),
                                                     physicsClientId=client)
            found = detect(render.render_image(client, camera, flat=True), config)
            assert found.pixels is not None, found.reason
            errors.append(found.pixels - camera.project(point[None, :])[0])
        errors = np.array(errors)
        assert np.all(np.abs(errors.mean(axis=0)) < 0.05), errors.mean(axis=0)
        assert np.sqrt(np.mean(np.sum(errors**2, axis=1))) < 0.2
    finally:
        pybullet.disconnect(client)
