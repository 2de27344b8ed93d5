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

"""A serial kinematic chain read from a URDF: the structure the regressors are built on.

Only the standard library reads the file (no ROS, no Pinocchio), so the
forward kinematics here is independent of the dynamics library and of
PyBullet, and the tests can hold each against the others.

Frames, for a chain with n movable joints (0-based index k):

* frame 0 is ``base_link``; frame k + 1 is the frame after joint k has moved;
* joint k sits at origin ``(R_o[k], t_o[k])`` in frame k (fixed joints between
  two movable ones are folded into that origin), turns about (revolute) or
  slides along (prismatic) ``axis[k]`` given in its own frame:
  ``R[k+1] = R[k] R_o[k] Rot(axis[k], q_k)``,
  ``p[k+1] = p[k] + R[k] t_o[k] (+ q_k R[k] R_o[k] axis[k] if prismatic)``;
* the tip link is fixed in frame n at ``(R_tip, t_tip)`` (the fixed joints after
  the last movable joint, folded);
* feature point i is the offset ``c_i`` in the tip frame:
  ``r_i = p[n] + R[n] (t_tip + R_tip c_i)``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

MOVABLE = ("revolute", "continuous", "prismatic")
KNOWN_TYPES = MOVABLE + ("fixed", "floating", "planar")


def rpy_matrix(rpy):
    """URDF roll-pitch-yaw (fixed axes X, Y, Z) as a rotation matrix: Rz(y) Ry(p) Rx(r)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def skew(v):
    """[v]x, the cross-product matrix of a 3-vector."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@dataclass(frozen=True)
class ChainJoint:
    """One movable joint of the chain, its origin folded with the fixed joints before it."""

    name: str
    prismatic: bool
    origin_rotation: np.ndarray     # (3, 3) R_o
    origin_translation: np.ndarray  # (3,) t_o, in the frame before the joint [m]
    axis: np.ndarray                # (3,) unit, in the joint's own frame
    folded: tuple = ()              # names of the fixed joints folded into this origin
    effort: float = float("inf")    # <limit effort> [N m or N]; inf: none given (or 0)
    lower: float = float("-inf")    # <limit lower> [rad or m]; -inf: none (continuous, unset)
    upper: float = float("inf")     # <limit upper> [rad or m]; inf: none


@dataclass(frozen=True)
class KinematicChain:
    """The movable joints from ``base_link`` to ``tip_link`` and the fixed tip transform."""

    urdf: str
    base_link: str
    tip_link: str
    joints: tuple
    tip_rotation: np.ndarray        # (3, 3) R_tip in frame n
    tip_translation: np.ndarray     # (3,) t_tip in frame n [m]
    tip_joints: tuple               # names of the fixed joints folded into the tip transform
    root_link: str
    root_to_base: np.ndarray        # (4, 4) pose of base_link in the URDF root frame

    @property
    def n(self):
        return len(self.joints)

    @property
    def joint_names(self):
        return tuple(j.name for j in self.joints)

    @property
    def effort_limits(self):
        """Each joint's ``<limit effort>`` [N m, N for a prismatic joint]; inf where none."""
        return tuple(j.effort for j in self.joints)

    @property
    def position_limits(self):
        """Each joint's ``(lower, upper)`` [rad, m for a prismatic joint]; infinite where none."""
        return tuple((j.lower, j.upper) for j in self.joints)

    def frames(self, q):
        """Rotations (n+1, 3, 3) and origins (n+1, 3) of frames 0..n in the base frame."""
        q = np.asarray(q, dtype=float)
        R = np.empty((self.n + 1, 3, 3))
        p = np.zeros((self.n + 1, 3))
        R[0] = np.eye(3)
        for k, joint in enumerate(self.joints):
            p[k + 1] = p[k] + R[k] @ joint.origin_translation
            rotated = R[k] @ joint.origin_rotation
            if joint.prismatic:
                p[k + 1] = p[k + 1] + q[k] * (rotated @ joint.axis)
                R[k + 1] = rotated
            else:
                R[k + 1] = rotated @ axis_rotation(joint.axis, q[k])
        return R, p

    def tip_pose(self, q):
        """Rotation (3, 3) and origin (3,) of the tip link in the base frame."""
        R, p = self.frames(q)
        return R[-1] @ self.tip_rotation, p[-1] + R[-1] @ self.tip_translation

    def points(self, q, offsets):
        """Feature points (m, 3) in the base frame for tip-frame offsets (m, 3)."""
        R_tip, p_tip = self.tip_pose(q)
        return p_tip + np.asarray(offsets, dtype=float).reshape(-1, 3) @ R_tip.T


def axis_rotation(axis, angle):
    """Rotation by ``angle`` about the unit ``axis`` (Rodrigues)."""
    K = skew(axis)
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def _vector(element, attribute, default):
    if element is None or element.get(attribute) is None:
        return np.array(default, dtype=float)
    values = element.get(attribute).split()
    if len(values) != 3:
        raise ValueError(f"needs 3 numbers in {attribute}={element.get(attribute)!r}")
    return np.array([float(v) for v in values])


def _transform(rotation, translation):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rotation, translation
    return T


def load_chain(urdf_path, base_link, tip_link, section="urdf"):
    """Read the chain ``base_link`` -> ``tip_link`` of a URDF file.

    Raises ValueError naming the parameter: the file does not parse, a link is
    missing, the tip is not below the base, the base moves relative to the URDF
    root, a joint type is unsupported, or there is no movable joint.
    """
    try:
        root = ET.parse(urdf_path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ValueError(f"{section}.urdf: cannot read {urdf_path}: {exc}") from None
    if root.tag != "robot":
        raise ValueError(f"{section}.urdf: {urdf_path} is not a URDF (root element "
                         f"<{root.tag}>, expected <robot>)")
    links = {link.get("name") for link in root.findall("link")}
    for name, value in (("base_link", base_link), ("tip_link", tip_link)):
        if value not in links:
            raise ValueError(f"{section}.{name}: no link {value!r} in {urdf_path}; "
                             f"links: {sorted(links)}")
    parent_joint = {}
    for joint in root.findall("joint"):
        child = joint.find("child").get("link")
        parent_joint[child] = joint
    # walk up from the tip; the path must pass through the base
    path, link = [], tip_link
    while link != base_link:
        joint = parent_joint.get(link)
        if joint is None:
            raise ValueError(f"{section}.tip_link: {tip_link!r} is not below base_link "
                             f"{base_link!r} in {urdf_path} (not a chain between them)")
        path.append(joint)
        link = joint.find("parent").get("link")
    path.reverse()
    root_to_base = np.eye(4)
    link = base_link
    while link in parent_joint:
        joint = parent_joint[link]
        if joint.get("type") != "fixed":
            raise ValueError(f"{section}.base_link: {base_link!r} moves relative to the URDF "
                             f"root (joint {joint.get('name')!r} is {joint.get('type')}); the "
                             f"base of the arm must be fixed")
        root_to_base = _origin(joint) @ root_to_base
        link = joint.find("parent").get("link")
    root_link = link

    joints, rotation, translation, folded = [], np.eye(3), np.zeros(3), []
    for joint in path:
        kind = joint.get("type")
        if kind not in KNOWN_TYPES:
            raise ValueError(f"{section}.urdf: joint {joint.get('name')!r} has unknown type "
                             f"{kind!r}")
        if kind in ("floating", "planar"):
            raise ValueError(f"{section}.urdf: joint {joint.get('name')!r} is {kind}; only "
                             f"revolute, continuous, prismatic and fixed joints are supported")
        origin = _origin(joint)
        translation = translation + rotation @ origin[:3, 3]
        rotation = rotation @ origin[:3, :3]
        if kind == "fixed":
            folded.append(joint.get("name"))
            continue
        axis = _vector(joint.find("axis"), "xyz", (1.0, 0.0, 0.0))
        norm = np.linalg.norm(axis)
        if norm == 0.0:
            raise ValueError(f"{section}.urdf: joint {joint.get('name')!r} has a zero axis")
        joints.append(ChainJoint(joint.get("name"), kind == "prismatic", rotation, translation,
                                 axis / norm, tuple(folded), _effort(joint, section),
                                 *_position_limits(joint, kind, section)))
        rotation, translation, folded = np.eye(3), np.zeros(3), []
    if not joints:
        raise ValueError(f"{section}.tip_link: no revolute or prismatic joint between "
                         f"{base_link!r} and {tip_link!r} in {urdf_path}")
    return KinematicChain(urdf_path, base_link, tip_link, tuple(joints), rotation, translation,
                          tuple(folded), root_link, root_to_base)


def _effort(joint, section):
    """The joint's ``<limit effort>``; inf without one, or with 0 (URDFs write 0 for "unset").

    A value that is not a number or is negative is refused naming the joint.
    """
    limit = joint.find("limit")
    text = None if limit is None else limit.get("effort")
    if text is None:
        return float("inf")
    try:
        effort = float(text)
    except ValueError:
        effort = float("nan")
    if not effort >= 0.0:
        raise ValueError(f"{section}.urdf: joint {joint.get('name')!r} has <limit effort="
                         f"{text!r}>: must be a number >= 0")
    return effort if effort > 0.0 else float("inf")


def _position_limits(joint, kind, section):
    """The joint's ``(<limit lower>, <limit upper>)``; infinite where the URDF sets none.

    A continuous joint has none; a revolute or prismatic one without the attributes, or
    with lower >= upper (URDFs write 0 and 0 for "unset"), has none either.  A value that
    is not a number is refused naming the joint.
    """
    limit = joint.find("limit")
    if kind == "continuous" or limit is None:
        return float("-inf"), float("inf")
    bounds = []
    for name, default in (("lower", float("-inf")), ("upper", float("inf"))):
        text = limit.get(name)
        try:
            bounds.append(default if text is None else float(text))
        except ValueError:
            raise ValueError(f"{section}.urdf: joint {joint.get('name')!r} has <limit {name}="
                             f"{text!r}>: must be a number") from None
    lower, upper = bounds
    if not lower < upper:
        return float("-inf"), float("inf")
    return lower, upper


def _origin(joint):
    origin = joint.find("origin")
    try:
        return _transform(rpy_matrix(_vector(origin, "rpy", (0.0, 0.0, 0.0))),
                          _vector(origin, "xyz", (0.0, 0.0, 0.0)))
    except ValueError as exc:
        raise ValueError(f"urdf: joint {joint.get('name')!r} origin: {exc}") from None
