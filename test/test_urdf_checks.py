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

"""URDF problems PyBullet or Pinocchio would pass silently are refused, naming link and file.

The oracle for every rule is the library itself, loading the same file without
the check: PyBullet's own mass properties (``getDynamicsInfo``), its "Bad
inertia tensor" warning, its refusal to load, its motion under torque, and
Pinocchio's inertias.
"""

import glob
import os
import xml.etree.ElementTree as ET

import numpy as np
import pybullet
import pybullet_data
import pytest
import yaml

from conftest import ROOT
from sim_bridge.plant import URDF_DIR, ArmPlant
from visual_adaptive_servo import cli
from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.models.resources import resolve_path
from visual_adaptive_servo.models.urdf_arm import UrdfArmCamera
from visual_adaptive_servo.models.urdf_checks import check_urdf, inertia_rule_broken, UrdfError
from visual_adaptive_servo.schema import ConfigError

PAPER_URDF = os.path.join(URDF_DIR, "paper_rrr.urdf")
PAPER_URDF_CONFIG = os.path.join(ROOT, "config", "paper_3dof_urdf.yaml")
DIAG = np.diag([0.1, 0.1, 0.1])
#: a tetrahedron, the smallest mesh PyBullet reads
OBJ = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"


def inertial(mass=1.0, tensor=DIAG):
    t = np.asarray(tensor, dtype=float).tolist()     # repr of a float: every digit
    return (f'<inertial><mass value="{float(mass)!r}"/><inertia ixx="{t[0][0]!r}" '
            f'ixy="{t[0][1]!r}" ixz="{t[0][2]!r}" iyy="{t[1][1]!r}" iyz="{t[1][2]!r}" '
            f'izz="{t[2][2]!r}"/></inertial>')


def mesh(filename, kind="visual"):
    return f'<{kind}><geometry><mesh filename="{filename}"/></geometry></{kind}>'


def write_arm(folder, link2=None, tip="", name="arm.urdf"):
    """A 2-joint arm (revolute, prismatic) on a tilted mount; root and mount have no <inertial>.

    ``link2`` is the body of the prismatic joint's link (default: 1 kg,
    diag(0.1)); ``tip`` that of the fixed tip link (default: a bare frame).
    """
    link2 = inertial() if link2 is None else link2
    limit = '<limit lower="-3" upper="3" effort="100" velocity="10"/>'
    text = f"""<robot name="arm">
  <link name="base_link"/>
  <joint name="mount_joint" type="fixed"><parent link="base_link"/><child link="mount"/>
    <origin xyz="0 0 0.1" rpy="0.3 0 0"/></joint>
  <link name="mount"/>
  <joint name="joint1" type="revolute"><parent link="mount"/><child link="link1"/>
    <axis xyz="0 0 1"/>{limit}</joint>
  <link name="link1">{inertial(2.0, np.diag([0.2, 0.3, 0.4]))}</link>
  <joint name="joint2" type="prismatic"><parent link="link1"/><child link="link2"/>
    <origin xyz="0.5 0 0"/><axis xyz="1 0 0"/>{limit}</joint>
  <link name="link2">{link2}</link>
  <joint name="tip_joint" type="fixed"><parent link="link2"/><child link="tip"/>
    <origin xyz="0.3 0 0"/></joint>
  <link name="tip">{tip}</link>
</robot>"""
    path = os.path.join(str(folder), name)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(text)
    return path


def raw_pybullet(path):
    """A PyBullet client with ``path`` loaded as the plant loads it, but without the check."""
    client = pybullet.connect(pybullet.DIRECT)
    try:
        body = pybullet.loadURDF(path, useFixedBase=True,
                                 flags=pybullet.URDF_USE_INERTIA_FROM_FILE,
                                 physicsClientId=client)
    except pybullet.error:
        pybullet.disconnect(client)
        raise
    return client, body


def link_index(client, body, name):
    return [pybullet.getJointInfo(body, j, physicsClientId=client)[12].decode()
            for j in range(pybullet.getNumJoints(body, physicsClientId=client))].index(name)


def pybullet_mass_properties(path, link):
    """(mass, principal moments (3,)) PyBullet simulates for ``link`` of ``path``."""
    client, body = raw_pybullet(path)
    try:
        info = pybullet.getDynamicsInfo(body, link_index(client, body, link),
                                        physicsClientId=client)
        return info[0], np.array(info[2])
    finally:
        pybullet.disconnect(client)


def test_a_complete_arm_passes_and_its_inertial_less_root_and_mount_are_accepted(tmp_path):
    path = write_arm(tmp_path, tip=inertial(0.0, np.zeros((3, 3))))
    check_urdf(path, ("joint1", "joint2"))
    with ArmPlant(path, tip_link="tip", joint_names=("joint1", "joint2")) as plant:
        assert plant.n == 2


def test_a_moving_link_without_inertial_is_refused_and_pybullet_would_give_it_1_kg(tmp_path):
    path = write_arm(tmp_path, link2="")
    message = (r"sim_node\.urdf: link 'link2' in .*arm\.urdf \(moved by joint 'joint2'\) has no "
               r"<inertial>: PyBullet simulates .* as 1 kg with inertia diag\(1, 1, 1\) kg m\^2, "
               r"Pinocchio \(the controller's model\) as massless")
    with pytest.raises(UrdfError, match=message):
        check_urdf(path)
    with pytest.raises(ConfigError, match=message):
        ArmPlant(path, tip_link="tip")
    # what the message says each library does
    mass, moments = pybullet_mass_properties(path, "link2")
    assert mass == 1.0
    np.testing.assert_array_equal(moments, [1.0, 1.0, 1.0])
    import pinocchio

    model = pinocchio.buildModelFromUrdf(path)
    assert model.inertias[model.getJointId("joint2")].mass == 0.0


def test_a_bare_frame_below_the_tip_is_massless_for_the_model_but_refused_for_pybullet(tmp_path):
    """tool0-like frames (no inertial, no shape): the URDF convention is massless."""
    path = write_arm(tmp_path)
    model = UrdfArmCamera(path, "base_link", "tip", [0.0, 0.0, 0.0])
    assert model.n == 2
    with pytest.raises(UrdfError, match=r"sim_node\.urdf: link 'tip' .* has no <inertial>"):
        check_urdf(path)
    assert pybullet_mass_properties(path, "tip")[0] == 1.0


def test_a_link_with_a_shape_but_no_inertial_is_refused_for_the_model_too(tmp_path):
    (tmp_path / "part.obj").write_text(OBJ)
    path = write_arm(tmp_path, tip=mesh("part.obj"))
    with pytest.raises(ValueError, match=r"controller_node\.urdf: link 'tip' in .*arm\.urdf "
                       r"\(moved by joint 'joint2'\) has no <inertial> but a visual or "
                       r"collision shape"):
        UrdfArmCamera(path, "base_link", "tip", [0.0, 0.0, 0.0])


def random_rotation(rng):
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    return Q * np.sign(np.diag(R))


def tensors():
    """(tensor, valid) cases: diagonal ones at and off the boundary, random rotated ones."""
    cases = [(np.diag([0.1, 0.2, 0.3]), True), (np.zeros((3, 3)), True),
             (np.diag([0.0, 0.5, 0.5]), True),          # a thin rod: on the boundary
             (np.diag([1.0, 0.1, 0.1]), False), (np.diag([-0.1, 0.5, 0.5]), False),
             (np.array([[0.1, 0.2, 0.0], [0.2, 0.1, 0.0], [0.0, 0.0, 0.1]]), False)]
    rng = np.random.default_rng(16)
    for k in range(12):
        moments = rng.uniform(0.05, 1.0, 3)
        valid = k % 2 == 0
        if valid:
            moments[2] = rng.uniform(abs(moments[0] - moments[1]) + 0.01,
                                     moments[0] + moments[1] - 0.01)
        else:
            moments[2] = moments[0] + moments[1] + rng.uniform(0.02, 0.5)
        R = random_rotation(rng)
        cases.append((R @ np.diag(moments) @ R.T, valid))
    return cases


@pytest.mark.parametrize("tensor, valid", tensors())
def test_inertia_check_agrees_with_pybullets_own(tensor, valid, tmp_path, capfd):
    """Accepted: PyBullet keeps the principal moments and says nothing; refused: it zeroes them."""
    tensor = (tensor + tensor.T) / 2
    assert (inertia_rule_broken(tensor) == "") == valid
    path = write_arm(tmp_path, link2=inertial(1.0, tensor), tip=inertial(0.0, np.zeros((3, 3))))
    capfd.readouterr()
    mass, moments = pybullet_mass_properties(path, "link2")
    warned = "Bad inertia tensor properties" in capfd.readouterr().out
    assert warned == (not valid)
    if valid:
        np.testing.assert_allclose(np.sort(moments), np.linalg.eigvalsh(tensor), atol=1e-9)
        check_urdf(path)
    else:
        np.testing.assert_array_equal(moments, 0.0)
        with pytest.raises(UrdfError, match=r"sim_node\.urdf: link 'link2' in .*arm\.urdf "
                           r"\(moved by joint 'joint2'\): inertia tensor \[\[.*\]\] kg m\^2 is "
                           r"not a rigid body's: .*(< 0|triangle inequality).*Bad inertia "
                           r"tensor properties"):
            check_urdf(path)


@pytest.mark.parametrize("body, message", [
    (inertial(-1.0), r"mass must be >= 0, got -1\.0 kg"),
    ('<inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1"/></inertial>',
     r"needs <inertia> with all of ixx, ixy, ixz, iyy, iyz, izz .*missing: ixy, ixz, iyz"),
    ('<inertial><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>',
     r'needs <mass value="\.\.\."/>'),
    (inertial(float("nan")), r"must be finite"),
    (inertial(1.0).replace('"1.0"', '"heavy"'), r"must be numbers"),
])
def test_bad_mass_properties_are_refused_naming_the_link(body, message, tmp_path):
    path = write_arm(tmp_path, link2=body, tip=inertial(0.0, np.zeros((3, 3))))
    for simulator in (True, False):
        with pytest.raises(UrdfError, match=r"\.urdf: link 'link2' in .*arm\.urdf .*" + message):
            check_urdf(path, simulator=simulator)


def test_a_joint_that_moves_no_mass_is_refused_and_pybullet_would_leave_it_still(tmp_path):
    zero = inertial(0.0, np.zeros((3, 3)))
    path = write_arm(tmp_path, link2=zero, tip=zero)
    with pytest.raises(UrdfError, match=r"sim_node\.urdf: joint 'joint2' in .*arm\.urdf moves no "
                       r"mass: every link below it \(link2, tip\) has zero mass and zero inertia"):
        check_urdf(path)
    client, body = raw_pybullet(path)
    try:
        j = link_index(client, body, "link2")
        pybullet.setJointMotorControl2(body, j, pybullet.VELOCITY_CONTROL, force=0.0,
                                       physicsClientId=client)
        for _ in range(100):
            pybullet.setJointMotorControl2(body, j, pybullet.TORQUE_CONTROL, force=10.0,
                                           physicsClientId=client)
            pybullet.stepSimulation(physicsClientId=client)
        assert pybullet.getJointState(body, j, physicsClientId=client)[0] == 0.0
    finally:
        pybullet.disconnect(client)


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    """Run in an empty folder (PyBullet also looks for meshes relative to the current one)."""
    work = tmp_path / "cwd"
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    return tmp_path


def mesh_arm(folder, filename, kind="visual"):
    body = inertial() + mesh(filename, kind)
    return write_arm(folder, link2=body, tip=inertial(0.0, np.zeros((3, 3))))


@pytest.mark.parametrize("layout, filename", [
    ("urdf/meshes/part.obj", "meshes/part.obj"),                    # relative to the URDF
    ("meshes/part.obj", "../meshes/part.obj"),
    ("src/my_arm/meshes/part.obj", "package://my_arm/meshes/part.obj"),   # a source checkout
])
def test_meshes_pybullet_finds_pass_the_check(layout, filename, in_tmp):
    (in_tmp / layout).parent.mkdir(parents=True)
    (in_tmp / layout).write_text(OBJ)
    folder = in_tmp / ("src/my_arm/urdf" if filename.startswith("package") else "urdf")
    path = mesh_arm(folder, filename)
    check_urdf(path)
    with ArmPlant(path, tip_link="tip") as plant:
        assert plant.n == 2


@pytest.mark.parametrize("kind", ["visual", "collision"])
@pytest.mark.parametrize("filename, message", [
    ("meshes/missing.obj", r"not found: PyBullet .* looks for 'meshes/missing\.obj' as given, in "
     r"the URDF's folder .*urdf and every folder above it, and in the current folder .*cwd and "
     r"the two above it; write the mesh path absolute or relative to the URDF's folder"),
    ("package://my_arm/meshes/missing.stl", r"looks for 'my_arm/meshes/missing\.stl' .*PyBullet "
     r"finds package://my_arm/\.\.\. only in a folder named 'my_arm'"),
    ("meshes/part.ply", r"PyBullet reads only \.obj, \.stl, \.dae, \.cdf, \.vtk files"),
])
def test_a_mesh_pybullet_cannot_load_is_refused_naming_link_and_file(kind, filename, message,
                                                                     in_tmp):
    (in_tmp / "urdf/meshes").mkdir(parents=True)
    (in_tmp / "urdf/meshes/part.ply").write_text("ply\n")
    path = mesh_arm(in_tmp / "urdf", filename, kind)
    with pytest.raises(pybullet.error, match="Cannot load URDF file"):
        raw_pybullet(path)
    full = (rf"sim_node\.urdf: link 'link2' in .*arm\.urdf: {kind} mesh '{filename}'.*"
            + message)
    with pytest.raises(UrdfError, match=full):
        check_urdf(path)
    with pytest.raises(ConfigError, match=full):
        ArmPlant(path, tip_link="tip")


def ament_prefix(folder, package):
    """An install prefix whose ament index lists ``package`` (the layout colcon writes)."""
    index = folder / "share" / "ament_index" / "resource_index" / "packages"
    index.mkdir(parents=True)
    (index / package).write_text("")
    (folder / "share" / package).mkdir()
    return folder


def test_a_package_mesh_pybullet_cannot_see_names_where_the_ament_index_has_it(
        in_tmp, monkeypatch):
    prefix = ament_prefix(in_tmp / "install", "my_arm")
    (prefix / "share/my_arm/meshes").mkdir()
    (prefix / "share/my_arm/meshes/part.obj").write_text(OBJ)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(prefix))
    path = mesh_arm(in_tmp / "generated", "package://my_arm/meshes/part.obj")
    with pytest.raises(pybullet.error, match="Cannot load URDF file"):
        raw_pybullet(path)
    with pytest.raises(UrdfError, match=r"the file is at .*install/share/my_arm/meshes/part\.obj "
                       r"\(package 'my_arm' of the ament index\), but PyBullet reads no ament "
                       r"index"):
        check_urdf(path)


def test_package_urdf_without_ros_says_which_package_and_what_would_resolve_it(
        in_tmp, monkeypatch):
    name = "package://my_arm/urdf/arm.urdf"
    with pytest.raises(FileNotFoundError, match=r"sim_node\.urdf: 'package://my_arm/urdf/arm\."
                       r"urdf' not found: package 'my_arm' is needed and AMENT_PREFIX_PATH is "
                       r"not set \(no ROS 2 workspace sourced\); without ROS only "
                       r"package://visual_adaptive_servo/urdf/\.\.\. and .* resolve .*source "
                       r"the ROS 2 workspace that installs 'my_arm'"):
        resolve_path(name, what="sim_node.urdf")
    other = ament_prefix(in_tmp / "other", "other_pkg")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(other))
    with pytest.raises(FileNotFoundError, match=r"no prefix of AMENT_PREFIX_PATH \(.*other\) has "
                       r"it in its ament index \(share/ament_index/resource_index/packages/"
                       r"my_arm\)"):
        resolve_path(name, what="sim_node.urdf")
    prefix = ament_prefix(in_tmp / "install", "my_arm")
    path = write_arm(prefix / "share/my_arm/urdf")
    monkeypatch.setenv("AMENT_PREFIX_PATH", os.pathsep.join([str(other), str(prefix)]))
    assert resolve_path(name) == path


def paper_copy_without_inertial(folder, link):
    tree = ET.parse(PAPER_URDF)
    element = next(e for e in tree.getroot().findall("link") if e.get("name") == link)
    element.remove(element.find("inertial"))
    path = str(folder / f"paper_without_{link}_inertial.urdf")
    tree.write(path)
    return path


@pytest.mark.parametrize("section", ["sim_node", "controller_node"])
def test_vas_run_prints_the_urdf_error_and_no_traceback(section, tmp_path, capsys):
    bad = paper_copy_without_inertial(tmp_path, "link2")
    code = cli.main(["run", "--config", PAPER_URDF_CONFIG, "--out", str(tmp_path / "out"),
                     "--set", f"{section}.urdf={bad}"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith(f"vas: invalid configuration: {section}.urdf: link 'link2' in {bad} "
                          f"(moved by joint 'joint2') has no <inertial>")
    assert "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_vas_run_names_the_package_a_package_url_needs(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    code = cli.main(["run", "--config", PAPER_URDF_CONFIG, "--out", str(tmp_path / "out"),
                     "--set", "sim_node.urdf=package://ur_description/urdf/ur5.urdf"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("vas: invalid configuration: sim_node.urdf: 'package://ur_description/"
                          "urdf/ur5.urdf' not found: package 'ur_description' is needed")


def _is_scenario(path):
    """A scenario file: a sim_node and a controller_node section (not a controllers YAML)."""
    with open(path, encoding="utf-8") as handle:
        sections = yaml.safe_load(handle)
    return isinstance(sections, dict) and {"sim_node", "controller_node"} <= set(sections)


SHIPPED = sorted(p for p in glob.glob(os.path.join(ROOT, "config", "*.yaml")) if _is_scenario(p))


@pytest.mark.parametrize("config", SHIPPED, ids=os.path.basename)
def test_shipped_configs_and_their_arms_pass_the_checks(config):
    scenario = load_scenario(config)
    chain = scenario.sim.arm.chain
    with ArmPlant(chain.urdf, tip_link=chain.tip_link, joint_names=chain.joint_names) as plant:
        assert plant.n == chain.n


@pytest.mark.parametrize("urdf", ["kuka_iiwa/model.urdf", "franka_panda/panda.urdf"])
def test_pybullet_data_arms_of_the_shipped_configs_pass_for_both_libraries(urdf):
    path = os.path.join(pybullet_data.getDataPath(), urdf)
    check_urdf(path)
    check_urdf(path, section="controller_node", simulator=False)
