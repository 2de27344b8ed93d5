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

"""What the rendered camera sees besides the arm: the tag plate, a floor, clutter, light.

ROS-free (PyBullet, numpy, OpenCV for the texture files).  Visual bodies only: no
mass, no collision, so the dynamics are those of the arm alone.

* :class:`TagBody`: the printed AprilTag of a
  :class:`~visual_adaptive_servo.models.tag.TagPlate`, a textured square of the
  plate's size, moved with the tip link before each picture;
* :func:`add_surroundings`: a textured floor and boxes behind the arm, placed from
  the camera (beyond what it looks at), so any scenario gets a cluttered background;
* :data:`CAMERA_LIGHT`: directional light with diffuse and specular shading.

Textures are written as PNG files into a cache folder (``VAS_TEXTURE_DIR``, default
a ``visual_adaptive_servo_textures`` folder in the system's temporary directory),
named by their content, then loaded with ``pybullet.loadTexture``.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np
import pybullet

from visual_adaptive_servo.models.tag import CELLS

TEXTURE_DIR = os.environ.get("VAS_TEXTURE_DIR",
                             os.path.join(tempfile.gettempdir(), "visual_adaptive_servo_textures"))
TAG_TEXTURE_CELL = 24      # texture pixels per tag cell
FLOOR_HALF = 4.0           # m, half the side of the floor around the world origin
FLOOR_TILES = 16
# shading for camera-like pictures: light from above and beside the camera
CAMERA_LIGHT = {"lightDirection": (0.4, -0.3, 1.0), "lightColor": (1.0, 0.97, 0.92),
                "lightAmbientCoeff": 0.45, "lightDiffuseCoeff": 0.55,
                "lightSpecularCoeff": 0.08}


def _write_texture(name, rgb):
    """Path of a PNG holding ``rgb`` (h, w, 3) uint8 (written once per content)."""
    import cv2

    os.makedirs(TEXTURE_DIR, exist_ok=True)
    path = os.path.join(TEXTURE_DIR, f"{name}.png")
    if not os.path.exists(path):
        tmp = f"{path}.{os.getpid()}.tmp.png"
        cv2.imwrite(tmp, cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2BGR))
        os.replace(tmp, path)        # atomic: campaign workers may write the same file
    return path


def tag_image(plate, cell=TAG_TEXTURE_CELL):
    """(s, s, 3) uint8 picture of the printed tag: black square and white margin."""
    import cv2

    cells = CELLS[plate.family]
    dictionary = cv2.aruco.getPredefinedDictionary(
        getattr(cv2.aruco, f"DICT_APRILTAG_{plate.family}"))
    tag = cv2.aruco.generateImageMarker(dictionary, plate.tag_id, cells * cell)
    border = int(round(plate.margin * cell))
    tag = cv2.copyMakeBorder(tag, border, border, border, border, cv2.BORDER_CONSTANT,
                             value=255)
    return cv2.cvtColor(tag, cv2.COLOR_GRAY2RGB)


def _textured_quad(client, half_x, half_y, texture_path, tiles=1, position=(0.0, 0.0, 0.0)):
    """A visual body: the rectangle [-hx, hx] x [-hy, hy] in its XY plane, facing +Z.

    Texture column 0 at -X, row 0 at +Y: the picture reads as printed when seen from +Z.
    ``tiles`` x ``tiles`` quads: the TinyRenderer rasterises a triangle over its whole
    bounding box in the picture, so a large surface seen at a grazing angle costs
    far less as many small triangles (a 6 m floor in one quad: ~200 ms a picture).
    """
    grid = np.linspace(0.0, 1.0, tiles + 1)
    vertices, uvs, indices = [], [], []
    for v in grid:
        for u in grid:
            vertices.append([(2.0 * u - 1.0) * half_x, (2.0 * v - 1.0) * half_y, 0.0])
            uvs.append([u, v])
    for row in range(tiles):
        for col in range(tiles):
            a = row * (tiles + 1) + col
            b, c, d = a + 1, a + tiles + 2, a + tiles + 1
            indices += [a, b, c, a, c, d]
    shape = pybullet.createVisualShape(
        pybullet.GEOM_MESH, vertices=vertices, indices=indices, uvs=uvs,
        normals=[[0.0, 0.0, 1.0]] * len(vertices), physicsClientId=client)
    body = pybullet.createMultiBody(baseMass=0.0, baseVisualShapeIndex=shape,
                                    baseCollisionShapeIndex=-1, basePosition=list(position),
                                    physicsClientId=client)
    texture = pybullet.loadTexture(texture_path, physicsClientId=client)
    pybullet.changeVisualShape(body, -1, textureUniqueId=texture, rgbaColor=(1, 1, 1, 1),
                               physicsClientId=client)
    return body


class TagBody:
    """The tag plate in a PyBullet scene; :meth:`place` puts it on the tip link."""

    def __init__(self, client, plate):
        self.client, self.plate = client, plate
        image = tag_image(plate)
        path = _write_texture(f"tag{plate.family}_{plate.tag_id}_{image.shape[0]}", image)
        half = 0.5 * plate.plate_edge
        self.body = _textured_quad(client, half, half, path)
        self._rotation = plate.rotation
        self._position = np.asarray(plate.position, float)

    def place(self, tip_rotation, tip_position):
        """Move the plate to the tip pose (world rotation (3, 3), origin (3,))."""
        R = tip_rotation @ self._rotation
        p = tip_position + tip_rotation @ self._position
        pybullet.resetBasePositionAndOrientation(self.body, p.tolist(), rotation_quaternion(R),
                                                 physicsClientId=self.client)


def rotation_quaternion(R):
    """(x, y, z, w) of a rotation matrix (Shepperd's method, the largest pivot)."""
    t = np.trace(R)
    if t > 0.0:
        s = 2.0 * np.sqrt(t + 1.0)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, s / 4]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = [0.0, 0.0, 0.0, (R[k, j] - R[j, k]) / s]
        q[i] = s / 4
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
    return [float(v) for v in q]


def _noise_texture(rng, size, base, contrast, tiles):
    """A wood- or concrete-like texture: smoothed noise over ``tiles`` x ``tiles`` tiles."""
    import cv2

    noise = rng.normal(0.0, 1.0, (size, size)).astype(np.float32)
    grain = cv2.GaussianBlur(noise, (0, 0), 3.0)
    grain = grain / (np.abs(grain).max() + 1e-9)
    tile = size // tiles
    checker = ((np.arange(size)[:, None] // tile + np.arange(size)[None, :] // tile) % 2) * 2 - 1
    shade = 1.0 + contrast * (0.6 * grain + 0.4 * checker)
    rgb = np.clip(np.asarray(base, float)[None, None, :] * shade[..., None], 0, 255)
    return rgb.astype(np.uint8)


def add_surroundings(client, camera, seed=0):
    """A textured floor (z = 0) and boxes of several colours behind the arm (list of bodies).

    The boxes stand 1 to 2.5 m beyond the camera's ``look_at`` distance (taken as
    the distance to the world origin), spread across the view, so they show behind
    the arm for any camera pose; the floor is a square of 2 ``FLOOR_HALF`` around the world origin.
    """
    rng = np.random.default_rng(seed)
    bodies = []
    floor = _write_texture("floor_v1", _noise_texture(rng, 512, (150, 128, 100), 0.25, 8))
    bodies.append(_textured_quad(client, FLOOR_HALF, FLOOR_HALF, floor, FLOOR_TILES))
    R = np.asarray(camera.rotation, float)
    eye = np.asarray(camera.position, float)
    reach = float(np.linalg.norm(eye)) or 2.0
    crate = _write_texture("crate_v1", _noise_texture(rng, 256, (170, 170, 170), 0.3, 4))
    texture = pybullet.loadTexture(crate, physicsClientId=client)
    colours = [(0.55, 0.35, 0.25), (0.35, 0.45, 0.6), (0.6, 0.6, 0.55), (0.3, 0.5, 0.35),
               (0.7, 0.55, 0.3), (0.45, 0.4, 0.5)]
    for colour in colours:
        depth = reach + rng.uniform(1.0, 2.5)
        across = rng.uniform(-0.6, 0.6) * depth * camera.width / (2.0 * camera.fx)
        centre = eye + depth * R[2] + across * R[0]
        half = rng.uniform(0.15, 0.45, 3) * max(reach / 2.0, 0.5)
        centre[2] = half[2]
        shape = pybullet.createVisualShape(pybullet.GEOM_BOX, halfExtents=half.tolist(),
                                           rgbaColor=list(colour) + [1.0],
                                           physicsClientId=client)
        body = pybullet.createMultiBody(baseMass=0.0, baseVisualShapeIndex=shape,
                                        baseCollisionShapeIndex=-1, basePosition=centre.tolist(),
                                        baseOrientation=pybullet.getQuaternionFromEuler(
                                            (0.0, 0.0, rng.uniform(-np.pi, np.pi))),
                                        physicsClientId=client)
        pybullet.changeVisualShape(body, -1, textureUniqueId=texture, physicsClientId=client)
        bodies.append(body)
    return bodies
