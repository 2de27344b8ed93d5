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

"""Property 4 for URDF arms (:class:`RigidBodyDynamics`) checked against independent oracles.

Oracles: the paper's hand-derived RRR model (:class:`PaperRRRCamera`), PyBullet's
inverse dynamics and mass matrix of the same URDF files (KUKA iiwa and Franka
Panda from pybullet_data; Bullet's Featherstone code, not Pinocchio's), a
central finite difference of M, Pinocchio's own Coriolis matrix (a different
algorithm from the regressor's), and an SVD rank of sampled regressors.

Tolerances: both sides are double-precision recursive algorithms; they agree
to ~5e-15 of each case's largest torque, 5e-14 at worst over 1000 random
motions (through the base parameters, whose map E = R11^-1 R12 has
cond(R11) ~ 40, and where the largest torque is small, e.g. gravity near the
upright pose).  ``TORQUE_RTOL = 1e-11`` of that largest torque leaves a margin
for other BLAS and Pinocchio builds, and fails at once for a wrong inertia,
frame, sign or dropped parameter (1e-3 or more).  The paper's RRR model is
compared at 1e-9 absolute: its URDF lists inertias to 12 digits (3e-13 from
the exact cylinders).
"""

import os
import re

import numpy as np
import pinocchio as pin
import pybullet
import pybullet_data
import pytest

from sim_bridge.plant import URDF_DIR
from visual_adaptive_servo.models import PaperRRRCamera
from visual_adaptive_servo.models.rigid_body import RigidBodyDynamics

TORQUE_RTOL = 1e-11
IIWA = ("kuka_iiwa/model.urdf", "lbr_iiwa_link_0", "lbr_iiwa_link_7")
PANDA = ("franka_panda/panda.urdf", "panda_link0", "panda_hand")
PANDA_FINGER = ("franka_panda/panda.urdf", "panda_link0", "panda_leftfinger")


def data_urdf(relative):
    return os.path.join(pybullet_data.getDataPath(), relative)


def random_motion(rng, n, size=2.0):
    """(q, q_dot, xi, xi_dot), each (n,)."""
    return rng.uniform(-np.pi, np.pi, n), *rng.uniform(-size, size, (3, n))


@pytest.fixture(scope="module")
def rrr():
    return RigidBodyDynamics(os.path.join(URDF_DIR, "paper_rrr.urdf"), "base_link", "tip")


@pytest.fixture(scope="module")
def paper():
    return PaperRRRCamera()


@pytest.fixture(scope="module")
def iiwa():
    return RigidBodyDynamics(data_urdf(IIWA[0]), *IIWA[1:])


class BulletArm:
    """PyBullet's dynamics of a URDF; joints not named are held at zero (position, rate)."""

    def __init__(self, urdf, joint_names, gravity=9.81):
        self.client = pybullet.connect(pybullet.DIRECT)
        pybullet.setGravity(0.0, 0.0, -gravity, physicsClientId=self.client)
        self.body = pybullet.loadURDF(urdf, useFixedBase=True,
                                      flags=pybullet.URDF_USE_INERTIA_FROM_FILE,
                                      physicsClientId=self.client)
        movable = []
        for j in range(pybullet.getNumJoints(self.body, physicsClientId=self.client)):
            info = pybullet.getJointInfo(self.body, j, physicsClientId=self.client)
            if info[2] in (pybullet.JOINT_REVOLUTE, pybullet.JOINT_PRISMATIC):
                movable.append(info[1].decode())
        self.n_dof = len(movable)
        self.index = [movable.index(name) for name in joint_names]

    def _all(self, x):
        full = np.zeros(self.n_dof)
        full[self.index] = x
        return full.tolist()

    def inverse_dynamics(self, q, qd, qdd):
        tau = pybullet.calculateInverseDynamics(self.body, self._all(q), self._all(qd),
                                                self._all(qdd), physicsClientId=self.client)
        return np.array(tau)[self.index]

    def mass_matrix(self, q):
        M = pybullet.calculateMassMatrix(self.body, self._all(q), physicsClientId=self.client)
        return np.array(M)[np.ix_(self.index, self.index)]

    def close(self):
        pybullet.disconnect(self.client)


@pytest.fixture(scope="module", params=[IIWA, PANDA, PANDA_FINGER],
                ids=["iiwa", "panda_fingers_locked", "panda_to_left_finger"])
def arm_and_bullet(request):
    urdf, base, tip = request.param
    arm = RigidBodyDynamics(data_urdf(urdf), base, tip)
    bullet = BulletArm(data_urdf(urdf), arm.joint_names)
    yield arm, bullet
    bullet.close()


# -- structure -------------------------------------------------------------------------
def test_joints_are_the_chain_in_order_with_other_joints_locked(rrr, iiwa):
    assert rrr.joint_names == ("joint1", "joint2", "joint3")
    assert rrr.link_names == ("link1", "link2", "link3")
    assert iiwa.joint_names == tuple(f"lbr_iiwa_joint_{i}" for i in range(1, 8))
    panda = RigidBodyDynamics(data_urdf(PANDA[0]), *PANDA[1:])
    assert panda.joint_names == tuple(f"panda_joint{i}" for i in range(1, 8))
    finger = RigidBodyDynamics(data_urdf(PANDA_FINGER[0]), *PANDA_FINGER[1:])
    assert finger.joint_names == panda.joint_names + ("panda_finger_joint1",)


def test_full_parameters_are_the_urdf_link_inertias(rrr):
    # link2 of the shipped URDF: 2 kg, centre of mass 1 m along x, axial 0.0025, transverse
    # 0.667916666667 kg m^2 about the centre; about the joint: Iyy = Izz = 0.6679... + 2 * 1^2
    a = rrr.full_parameters()
    assert a.shape == (30,)
    np.testing.assert_allclose(a[10:20], [2.0, 2.0, 0.0, 0.0, 0.0025, 0.0, 2.667916666667,
                                          0.0, 0.0, 2.667916666667], rtol=1e-12, atol=0)
    assert rrr.parameter_labels[0].startswith("link")


def test_base_parameter_count_is_the_rank_of_sampled_regressors(rrr, iiwa, rng):
    # an SVD of the 10 n-column regressor at samples other than the reduction's own
    for arm, chain in ((rrr, (os.path.join(URDF_DIR, "paper_rrr.urdf"), "base_link", "tip")),
                       (iiwa, (data_urdf(IIWA[0]), *IIWA[1:]))):
        full = RigidBodyDynamics(*chain, reduce=False)
        stacked = np.vstack([full.regressor(*random_motion(rng, arm.n)) for _ in range(40)])
        s = np.linalg.svd(stacked, compute_uv=False)
        assert np.count_nonzero(s > 1e-9 * s[0]) == arm.p_d
        assert len(arm.parameter_labels) == arm.p_d == arm.parameters().size
        assert arm.base_map.shape == (arm.p_d, 10 * arm.n)
        links = "|".join(arm.link_names)
        label = re.compile(rf"({links})\.(m|mc[xyz]|I[xyz][xyz])(\+\.\.\.)?")
        assert all(label.fullmatch(text) for text in arm.parameter_labels)
        assert len(set(arm.parameter_labels)) == arm.p_d


def test_regressor_shapes_dtype_and_inputs_untouched(iiwa, rng):
    q, qd, xi, xi_dot = random_motion(rng, iiwa.n)
    copies = [v.copy() for v in (q, qd, xi, xi_dot)]
    Y = iiwa.regressor(q, qd, xi, xi_dot)
    assert Y.shape == (7, iiwa.p_d) and Y.dtype == np.float64
    assert iiwa.mass_matrix(q).shape == (7, 7)
    assert iiwa.coriolis_matrix(q, qd).shape == (7, 7)
    assert iiwa.gravity_torque(q).shape == (7,)
    for v, c in zip((q, qd, xi, xi_dot), copies):
        np.testing.assert_array_equal(v, c)


# -- the paper's RRR arm: the hand-derived model is the oracle -------------------------
def test_rrr_regressor_matches_paper_model(rrr, paper, rng):
    for _ in range(20):
        q, qd, xi, xi_dot = random_motion(rng, 3)
        np.testing.assert_allclose(rrr.regressor(q, qd, xi, xi_dot) @ rrr.parameters(),
                                   paper.dynamic_regressor(q, qd, xi, xi_dot) @ paper.a_d,
                                   rtol=0, atol=1e-9)


def test_rrr_true_dynamics_match_paper_model(rrr, paper, rng):
    for _ in range(20):
        q, qd, _, _ = random_motion(rng, 3)
        np.testing.assert_allclose(rrr.mass_matrix(q), paper.mass_matrix(q), rtol=0, atol=1e-9)
        np.testing.assert_allclose(rrr.coriolis_matrix(q, qd), paper.coriolis_matrix(q, qd),
                                   rtol=0, atol=1e-9)
        np.testing.assert_allclose(rrr.gravity_torque(q), paper.gravity_torque(q),
                                   rtol=0, atol=1e-9)


# -- URDF arms from pybullet_data: PyBullet is the oracle ------------------------------
def test_regressor_matches_pybullet_inverse_dynamics(arm_and_bullet, rng):
    arm, bullet = arm_and_bullet
    a = arm.parameters()
    for _ in range(20):
        q, qd, _, qdd = random_motion(rng, arm.n)
        tau = bullet.inverse_dynamics(q, qd, qdd)
        np.testing.assert_allclose(arm.regressor(q, qd, qd, qdd) @ a, tau,
                                   rtol=0, atol=TORQUE_RTOL * np.abs(tau).max())


def test_mass_matrix_and_gravity_match_pybullet(arm_and_bullet, rng):
    arm, bullet = arm_and_bullet
    zero = np.zeros(arm.n)
    for _ in range(20):
        q = random_motion(rng, arm.n)[0]
        M = bullet.mass_matrix(q)
        np.testing.assert_allclose(arm.mass_matrix(q), M, rtol=0,
                                   atol=TORQUE_RTOL * np.abs(M).max())
        g = bullet.inverse_dynamics(q, zero, zero)
        np.testing.assert_allclose(arm.gravity_torque(q), g, rtol=0,
                                   atol=TORQUE_RTOL * np.abs(g).max())
        np.testing.assert_allclose(arm.regressor(q, zero, zero, zero) @ arm.parameters(), g,
                                   rtol=0, atol=TORQUE_RTOL * np.abs(g).max())


def test_gravity_scales_with_the_gravity_argument(rng):
    urdf = data_urdf(IIWA[0])
    moon = RigidBodyDynamics(urdf, *IIWA[1:], gravity=1.62)
    bullet = BulletArm(urdf, moon.joint_names, gravity=1.62)
    try:
        q = random_motion(rng, 7)[0]
        g = bullet.inverse_dynamics(q, np.zeros(7), np.zeros(7))
        np.testing.assert_allclose(moon.gravity_torque(q), g, rtol=0,
                                   atol=TORQUE_RTOL * np.abs(g).max())
    finally:
        bullet.close()


# -- Property 3 and the polarisation identity -----------------------------------------
def test_mdot_minus_2c_is_skew_symmetric(iiwa, rng):
    # M_dot along q(t) = q + t qd by the five-point central difference: truncation
    # h^4/30 |d^5M/dt^5| and round-off ~1.5 eps |M| / h are each ~1e-11 here
    # (|M| ~ 3, |qd| <= 2; 7e-12 largest seen over 100 samples)
    h = 3e-4

    def M_at(q, qd, t):
        return iiwa.mass_matrix(q + t * qd)

    for _ in range(10):
        q, qd, _, _ = random_motion(rng, 7)
        M_dot = (M_at(q, qd, -2 * h) - 8 * M_at(q, qd, -h) + 8 * M_at(q, qd, h)
                 - M_at(q, qd, 2 * h)) / (12 * h)
        N = M_dot - 2.0 * iiwa.coriolis_matrix(q, qd)
        np.testing.assert_allclose(N + N.T, 0.0, atol=1e-9)


def test_polarised_regressor_splits_into_m_c_and_g(iiwa, rng):
    a = iiwa.parameters()
    zero = np.zeros(7)
    for _ in range(10):
        q, qd, xi, xi_dot = random_motion(rng, 7)
        g = iiwa.gravity_torque(q)
        C_xi = iiwa.regressor(q, qd, xi, zero) @ a - g
        scale = np.abs(C_xi).max()
        np.testing.assert_allclose(C_xi, iiwa.coriolis_matrix(q, qd) @ xi, rtol=0,
                                   atol=TORQUE_RTOL * scale)
        # C xi is bilinear and symmetric in (q_dot, xi): the Christoffel form
        np.testing.assert_allclose(iiwa.regressor(q, xi, qd, zero) @ a - g, C_xi, rtol=0,
                                   atol=TORQUE_RTOL * scale)
        M_xi_dot = iiwa.regressor(q, qd, zero, xi_dot) @ a - g
        np.testing.assert_allclose(M_xi_dot, iiwa.mass_matrix(q) @ xi_dot, rtol=0,
                                   atol=TORQUE_RTOL * np.abs(M_xi_dot).max())


def test_two_call_regressor_equals_the_five_call_polarisation(rng):
    # Y_d = Y(q, 0, xi_dot) + 1/2 [Y(q, qd + xi, 0) - Y(q, qd, 0) - Y(q, xi, 0) + Y(q, 0, 0)]
    arm = RigidBodyDynamics(data_urdf(IIWA[0]), *IIWA[1:], reduce=False)
    zero = np.zeros(7)

    def Y(q, v, a):
        return pin.computeJointTorqueRegressor(arm.model, arm.data, q, v, a).copy()

    for _ in range(10):
        q, qd, xi, xi_dot = random_motion(rng, 7)
        polarised = Y(q, zero, xi_dot) + 0.5 * (Y(q, qd + xi, zero) - Y(q, qd, zero)
                                                - Y(q, xi, zero) + Y(q, zero, zero))
        np.testing.assert_allclose(arm.regressor(q, qd, xi, xi_dot), polarised, rtol=0,
                                   atol=1e-12 * np.abs(polarised).max())


def test_base_parameters_reproduce_full_parameter_torques(rng):
    urdf = data_urdf(PANDA[0])
    full = RigidBodyDynamics(urdf, *PANDA[1:], reduce=False)
    base = RigidBodyDynamics(urdf, *PANDA[1:])
    assert full.p_d == 70 and base.p_d < full.p_d
    np.testing.assert_array_equal(full.parameters(), full.full_parameters())
    for _ in range(20):
        motion = random_motion(rng, 7)
        tau = full.regressor(*motion) @ full.parameters()
        np.testing.assert_allclose(base.regressor(*motion) @ base.parameters(), tau, rtol=0,
                                   atol=TORQUE_RTOL * np.abs(tau).max())


# -- errors users will read ------------------------------------------------------------
BRANCHED_URDF = """<?xml version="1.0"?>
<robot name="branched">
  <link name="world"/>
  <link name="pedestal"/>
  <link name="table"/>
  <link name="arm"><inertial><mass value="1"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <joint name="to_pedestal" type="fixed"><parent link="world"/><child link="pedestal"/></joint>
  <joint name="to_table" type="fixed"><parent link="world"/><child link="table"/></joint>
  <joint name="shoulder" type="revolute"><parent link="pedestal"/><child link="arm"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
</robot>
"""


@pytest.fixture
def branched_urdf(tmp_path):
    path = tmp_path / "branched.urdf"
    path.write_text(BRANCHED_URDF)
    return str(path)


def test_missing_links_are_refused_naming_the_parameter(branched_urdf):
    with pytest.raises(ValueError, match=r"base_link: no link named 'plinth'"):
        RigidBodyDynamics(branched_urdf, "plinth", "arm")
    with pytest.raises(ValueError, match=r"tip_link: no link named 'hand'"):
        RigidBodyDynamics(branched_urdf, "pedestal", "hand")


def test_tip_off_the_base_subtree_is_not_a_chain(branched_urdf):
    with pytest.raises(ValueError, match=r"tip_link: link 'arm' is not a descendant of "
                                         r"base_link 'table'.*no kinematic chain"):
        RigidBodyDynamics(branched_urdf, "table", "arm")
    with pytest.raises(ValueError, match=r"tip_link: link 'world' is not a descendant"):
        RigidBodyDynamics(branched_urdf, "pedestal", "world")


def test_base_moved_by_a_joint_is_refused(branched_urdf):
    with pytest.raises(ValueError, match=r"base_link: link 'arm' is moved relative to the URDF "
                                         r"root 'world' by joint\(s\) \['shoulder'\]"):
        RigidBodyDynamics(branched_urdf, "arm", "arm")


def test_chain_without_movable_joints_is_refused(branched_urdf):
    with pytest.raises(ValueError, match=r"tip_link: there is no revolute, continuous or "
                                         r"prismatic joint between"):
        RigidBodyDynamics(branched_urdf, "world", "table")


def test_unloadable_files_are_refused(tmp_path):
    with pytest.raises(ValueError, match=r"urdf: no such file"):
        RigidBodyDynamics(str(tmp_path / "missing.urdf"), "a", "b")
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='broken'><link name='a'></robot>")
    with pytest.raises(ValueError, match=r"urdf: .*bad.urdf' does not load as a URDF model"):
        RigidBodyDynamics(str(bad), "a", "b")
