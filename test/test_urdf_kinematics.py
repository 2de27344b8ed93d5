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

"""Property 1 for any URDF chain, against independent oracles.

Oracles: PyBullet's own link frames (the chain's forward kinematics), the
projection of those points by a random camera (depth and image velocity), and
finite differences of the regressor tensors themselves (their joint gradients
and time rates).
"""

import os
import xml.etree.ElementTree as ET

import numpy as np
import pybullet
import pybullet_data
import pytest

from sim_bridge.camera import PinholeCamera
from sim_bridge.plant import URDF_DIR, ArmPlant
from visual_adaptive_servo.models import PaperRRRCamera
from visual_adaptive_servo.models.kinematic_regressor import KinematicRegressor
from visual_adaptive_servo.models.urdf_chain import load_chain

DATA = pybullet_data.getDataPath()
H_FD = 1e-6

# a chain with everything the reader must handle: a fixed root->base joint (the base is
# not the URDF root), a fixed joint between two movable ones, a prismatic joint, rotated
# origins and axes that are not coordinate axes, and a fixed tool frame at the tip
SYNTHETIC = """<?xml version="1.0"?>
<robot name="synthetic">
  <link name="world"/>
  <link name="base"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <joint name="mount" type="fixed"><parent link="world"/><child link="base"/>
    <origin xyz="0.1 -0.2 0.3" rpy="0.1 0.2 0.3"/></joint>
  <link name="a"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/>
    <origin xyz="0 0 0.4" rpy="0 0 0.5"/><axis xyz="0 0 1"/><limit effort="1" velocity="1" lower="-3" upper="3"/></joint>
  <link name="b"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="j2" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0.05 0 0.3" rpy="1.2 0 0"/><axis xyz="0.6 0 0.8"/><limit effort="1" velocity="1" lower="-3" upper="3"/></joint>
  <link name="b2"><inertial><mass value="0.5"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="bracket" type="fixed"><parent link="b"/><child link="b2"/>
    <origin xyz="0.1 0.02 0.25" rpy="0 0.4 0"/></joint>
  <link name="c"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="slide" type="prismatic"><parent link="b2"/><child link="c"/>
    <origin xyz="0 0.1 0.2" rpy="0 0 0"/><axis xyz="0 1 0"/><limit effort="1" velocity="1" lower="-1" upper="1"/></joint>
  <link name="d"><inertial><mass value="1"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="j4" type="continuous"><parent link="c"/><child link="d"/>
    <origin xyz="0.2 0 0" rpy="0 -0.7 0"/><axis xyz="1 0 0"/></joint>
  <link name="tool"><inertial><mass value="0.1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <joint name="tool_joint" type="fixed"><parent link="d"/><child link="tool"/>
    <origin xyz="0.1 0.05 -0.02" rpy="0.3 0 0.2"/></joint>
</robot>
"""


@pytest.fixture(scope="module")
def synthetic_urdf(tmp_path_factory):
    path = tmp_path_factory.mktemp("urdf") / "synthetic.urdf"
    path.write_text(SYNTHETIC)
    return str(path)


def arms(synthetic):
    """(urdf, base, tip, feature offsets) of every chain checked here."""
    return [
        (os.path.join(URDF_DIR, "paper_rrr.urdf"), "base_link", "tip", [[0.0, 0.0, 0.0]]),
        (os.path.join(DATA, "kuka_iiwa/model.urdf"), "lbr_iiwa_link_0", "lbr_iiwa_link_7",
         [[0.06, 0.0, 0.05], [-0.03, 0.052, 0.05], [-0.03, -0.052, 0.05]]),
        (os.path.join(DATA, "xarm/xarm6_robot.urdf"), "link_base", "link6",
         [[0.05, 0.0, 0.02], [-0.05, 0.0, 0.02]]),
        (synthetic, "base", "tool", [[0.02, 0.01, 0.03], [-0.03, 0.02, 0.0], [0.0, -0.04, 0.01]]),
    ]


@pytest.fixture(scope="module", params=range(4), ids=["paper", "iiwa", "xarm6", "synthetic"])
def arm(request, synthetic_urdf):
    urdf, base, tip, offsets = arms(synthetic_urdf)[request.param]
    chain = load_chain(urdf, base, tip)
    return chain, np.array(offsets), KinematicRegressor(chain, offsets)


def random_camera(rng, chain, offsets):
    """A camera about 3 m from the arm's start pose, looking at it, unequal pixel scales."""
    center = chain.points(np.zeros(chain.n), offsets).mean(axis=0)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    return PinholeCamera.look_at(center + 3.0 * direction, center, (0.0, 0.0, 1.0), 800.0, 760.0,
                                 310.0, 250.0, 640, 480, (0.0, 0.0), (1.0, 1.0))


def fd(fun, q, qd, h=H_FD):
    return (fun(q + h * qd) - fun(q - h * qd)) / (2 * h)


def kinematic_copy(urdf, folder):
    """``urdf`` with the same joints; every link 1 kg, inertia diag(0.01), no shapes.

    pybullet_data's xarm6 carries inertia tensors PyBullet zeroes (so the plant
    refuses the file, see test_urdf_checks.py); the frames compared here do
    not depend on any mass property or mesh.
    """
    tree = ET.parse(urdf)
    for link in tree.getroot().findall("link"):
        for child in list(link):
            link.remove(child)
        inertial = ET.SubElement(link, "inertial")
        ET.SubElement(inertial, "mass", value="1")
        ET.SubElement(inertial, "inertia", ixx="0.01", ixy="0", ixz="0", iyy="0.01", iyz="0",
                      izz="0.01")
    path = os.path.join(folder, "kinematics_" + os.path.basename(urdf))
    tree.write(path)
    return path


def test_chain_forward_kinematics_matches_pybullet_link_frames(arm, rng, tmp_path):
    chain, offsets, _ = arm
    with ArmPlant(kinematic_copy(chain.urdf, tmp_path), tip_link=chain.tip_link,
                  joint_names=chain.joint_names, feature_points=offsets) as plant:
        root = chain.root_to_base
        for _ in range(5):
            q = rng.uniform(-1.5, 1.5, chain.n)
            plant.reset(q)
            R_tip, p_tip = chain.tip_pose(q)
            R_pb, p_pb = plant.tip_pose()
            np.testing.assert_allclose(root[:3, :3] @ p_tip + root[:3, 3], p_pb, atol=1e-9)
            # PyBullet's link orientations carry ~1e-7 of error (positions agree to 1e-9)
            np.testing.assert_allclose(root[:3, :3] @ R_tip, R_pb, atol=1e-6)
            points = chain.points(q, offsets) @ root[:3, :3].T + root[:3, 3]
            np.testing.assert_allclose(points, plant.feature_positions(), atol=1e-8)


def test_depth_and_image_velocity_of_the_true_parameters_match_the_projection(arm, rng):
    chain, offsets, kin = arm
    camera = random_camera(rng, chain, offsets)
    P = camera.projection_matrix @ chain.root_to_base
    a_perp, a_z = kin.parameters(P)
    root = chain.root_to_base

    def project(q):
        return camera.project(chain.points(q, offsets) @ root[:3, :3].T + root[:3, 3])

    for _ in range(5):
        q, qd = rng.uniform(-1.5, 1.5, chain.n), rng.uniform(-1.0, 1.0, chain.n)
        H, dH, _, W, _ = kin.tensors(q, qd)
        x, z = project(q)
        np.testing.assert_allclose(H @ a_z, z, rtol=1e-12, atol=1e-12)
        # eq (4): x_dot = Z^-1 J(q, x) q_dot with J = W a_perp - X dH a_z (eq (a1))
        J = W @ a_perp - x[:, None] * np.repeat(dH @ a_z, 2, axis=0)
        np.testing.assert_allclose(J @ qd / np.repeat(z, 2), fd(lambda p: project(p)[0], q, qd),
                                   rtol=1e-6, atol=1e-6)


def test_tensor_gradients_and_rates_match_finite_differences(arm, rng):
    chain, _, kin = arm
    for _ in range(3):
        q, qd = rng.uniform(-1.5, 1.5, chain.n), rng.uniform(-1.0, 1.0, chain.n)
        H, dH, dH_rate, W, W_rate = kin.tensors(q, qd)
        grad = np.array([(kin.tensors(q + H_FD * e, qd)[0] - kin.tensors(q - H_FD * e, qd)[0])
                         / (2 * H_FD) for e in np.eye(chain.n)])          # (n, m, p_z)
        np.testing.assert_allclose(grad.transpose(1, 0, 2), dH, atol=1e-8)
        for index, rate in ((1, dH_rate), (3, W_rate)):
            np.testing.assert_allclose(fd(lambda p, qd=qd, i=index: kin.tensors(p, qd)[i], q, qd),
                                       rate, atol=1e-8)


def test_reduced_parameters_are_an_independent_basis(arm):
    _, _, kin = arm
    for reduction, samples in ((kin.z_reduction, kin._z_samples),
                               (kin.perp_reduction, kin._perp_samples)):
        basis = samples[:, reduction.basis]
        assert np.linalg.matrix_rank(basis) == len(reduction.basis)
        np.testing.assert_allclose(basis @ reduction.E, samples, atol=1e-9)
        assert len(reduction.labels) == len(reduction.basis)


def test_generic_model_equals_the_papers_hand_derived_kinematics(rng):
    chain = load_chain(os.path.join(URDF_DIR, "paper_rrr.urdf"), "base_link", "tip")
    paper = PaperRRRCamera()
    for unknown in ("all", ["joint3.x", "tip_joint.x"]):
        kin = KinematicRegressor(chain, [[0.0, 0.0, 0.0]], unknown)
        a_perp, a_z = kin.parameters(paper.camera_matrix)
        for _ in range(10):
            q, qd = rng.uniform(-2.0, 2.0, 3), rng.uniform(-2.0, 2.0, 3)
            H, dH, _, W, _ = kin.tensors(q, qd)
            x, z = paper.project(q)
            np.testing.assert_allclose(H @ a_z, z, atol=1e-9)
            np.testing.assert_allclose(paper.image_jacobian(W, dH, x, a_perp, a_z),
                                       paper.true_image_jacobian(q, x), atol=1e-9)


def test_known_lengths_leave_fewer_parameters_and_the_same_kinematics(rng):
    chain = load_chain(os.path.join(DATA, "kuka_iiwa/model.urdf"), "lbr_iiwa_link_0",
                       "lbr_iiwa_link_7")
    offsets = [[0.06, 0.0, 0.05], [-0.03, 0.052, 0.05], [-0.03, -0.052, 0.05]]
    full = KinematicRegressor(chain, offsets)
    points_only = KinematicRegressor(chain, offsets, [f"point{i}.{a}" for i in (1, 2, 3)
                                                      for a in "xyz"])
    assert points_only.p_z < full.p_z and points_only.p_perp < full.p_perp
    camera = random_camera(rng, chain, np.array(offsets))
    q, qd = rng.uniform(-1.0, 1.0, 7), rng.uniform(-1.0, 1.0, 7)
    for kin in (full, points_only):
        a_perp, a_z = kin.parameters(camera.projection_matrix)
        H, dH, _, W, _ = kin.tensors(q, qd)
        np.testing.assert_allclose(H @ a_z, camera.project(chain.points(q, offsets))[1],
                                   atol=1e-12)
    J = [kin.tensors(q, qd)[3] @ kin.parameters(camera.projection_matrix)[0]
         for kin in (full, points_only)]
    np.testing.assert_allclose(J[0], J[1], atol=1e-9)


def test_unknown_length_names_are_refused_with_the_known_ones():
    chain = load_chain(os.path.join(URDF_DIR, "paper_rrr.urdf"), "base_link", "tip")
    with pytest.raises(ValueError, match=r"unknown_lengths: no length\(s\) \['joint9.x'\]"):
        KinematicRegressor(chain, [[0.0, 0.0, 0.0]], ["joint9.x"])


@pytest.mark.parametrize("base, tip, message", [
    ("base_link", "nope", r"urdf\.tip_link: no link 'nope'"),
    ("link3", "link2", r"urdf\.tip_link: 'link2' is not below base_link 'link3'"),
    ("link1", "tip", r"urdf\.base_link: 'link1' moves relative to the URDF root"),
    ("base_link", "base_link", r"urdf\.tip_link: no revolute or prismatic joint"),
])
def test_bad_chains_are_refused_naming_the_parameter(base, tip, message):
    with pytest.raises(ValueError, match=message):
        load_chain(os.path.join(URDF_DIR, "paper_rrr.urdf"), base, tip, section="urdf")


def test_unreadable_urdf_is_refused(tmp_path):
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot><link name='a'>")
    with pytest.raises(ValueError, match=r"sim_node\.urdf: cannot read"):
        load_chain(str(bad), "a", "a", section="sim_node")


def test_effort_limits_are_read_as_pybullet_reads_them():
    urdf = os.path.join(DATA, "kuka_iiwa/model.urdf")
    chain = load_chain(urdf, "lbr_iiwa_link_0", "lbr_iiwa_link_7")
    client = pybullet.connect(pybullet.DIRECT)
    try:
        body = pybullet.loadURDF(urdf, useFixedBase=True, physicsClientId=client)
        info = {pybullet.getJointInfo(body, j, physicsClientId=client)[1].decode():
                pybullet.getJointInfo(body, j, physicsClientId=client)[10]
                for j in range(pybullet.getNumJoints(body, physicsClientId=client))}
    finally:
        pybullet.disconnect(client)
    assert chain.effort_limits == tuple(info[name] for name in chain.joint_names)
    # the paper's arm has continuous joints without <limit>: no limit
    paper = load_chain(os.path.join(URDF_DIR, "paper_rrr.urdf"), "base_link", "tip")
    assert paper.effort_limits == (np.inf,) * 3


@pytest.mark.parametrize("limit, effort", [
    ('<limit effort="0" velocity="1"/>', np.inf),     # URDFs write 0 for "not given"
    ('<limit effort="12.5" velocity="1"/>', 12.5),
    ('<limit effort="-3" velocity="1"/>', r"joint 'joint2' has <limit effort='-3'>"),
    ('<limit effort="strong" velocity="1"/>', r"joint 'joint2' has <limit effort='strong'>"),
])
def test_an_effort_limit_of_zero_is_none_and_a_bad_one_is_refused(tmp_path, limit, effort):
    text = open(os.path.join(URDF_DIR, "paper_rrr.urdf")).read()
    at = text.index("</joint>", text.index('<joint name="joint2"'))
    path = tmp_path / "arm.urdf"
    path.write_text(text[:at] + limit + text[at:])
    if isinstance(effort, str):
        with pytest.raises(ValueError, match="controller_node\\.urdf: " + effort):
            load_chain(str(path), "base_link", "tip", section="controller_node")
    else:
        chain = load_chain(str(path), "base_link", "tip")
        assert chain.effort_limits == (np.inf, effort, np.inf)


def test_pybullet_sees_the_synthetic_chain_with_its_fixed_mount(synthetic_urdf):
    """The reader's root->base transform is where PyBullet puts the base link."""
    chain = load_chain(synthetic_urdf, "base", "tool")
    client = pybullet.connect(pybullet.DIRECT)
    try:
        body = pybullet.loadURDF(synthetic_urdf, useFixedBase=True, physicsClientId=client)
        index = [pybullet.getJointInfo(body, j, physicsClientId=client)[12].decode()
                 for j in range(pybullet.getNumJoints(body, physicsClientId=client))].index("base")
        state = pybullet.getLinkState(body, index, computeForwardKinematics=True,
                                      physicsClientId=client)
        np.testing.assert_allclose(state[4], chain.root_to_base[:3, 3], atol=1e-12)
    finally:
        pybullet.disconnect(client)
    assert chain.joint_names == ("j1", "j2", "slide", "j4")
    assert chain.joints[2].folded == ("bracket",) and chain.tip_joints == ("tool_joint",)
