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

"""Property 1 and Property 4 of the paper checked against independent oracles.

Oracles: finite differences of the true projection and of the model tensors,
and PyBullet's own mass matrix and inverse dynamics of the shipped URDF.
"""

import numpy as np
import pytest

from sim_bridge.camera import PinholeCamera
from sim_bridge.plant import URDF_DIR, ArmPlant
from visual_adaptive_servo.models import PaperRRRCamera, make_model

PAPER_URDF = f"{URDF_DIR}/paper_rrr.urdf"

H_FD = 1e-6


@pytest.fixture(scope="module")
def model():
    return PaperRRRCamera()


@pytest.fixture(scope="module")
def plant():
    with ArmPlant(PAPER_URDF, physics_dt=0.001) as arm:
        yield arm


def random_state(rng):
    q = rng.uniform([-1.5, -1.0, -1.5], [1.5, 1.0, 1.5])
    return q, rng.uniform(-2.0, 2.0, 3)


def fd(fun, q, qd, h=H_FD):
    """Central difference of fun along q(t) = q + t qd at t = 0."""
    return (fun(q + h * qd) - fun(q - h * qd)) / (2 * h)


def test_image_velocity_matches_finite_difference(model, rng):
    for _ in range(20):
        q, qd = random_state(rng)
        x, z = model.project(q)
        x_dot = model.true_image_jacobian(q, x) @ qd / np.repeat(z, 2)   # eq (4)
        np.testing.assert_allclose(x_dot, fd(lambda p: model.project(p)[0], q, qd),
                                   rtol=1e-6, atol=1e-6)


def test_depth_rate_matches_finite_difference(model, rng):
    for _ in range(20):
        q, qd = random_state(rng)
        _, dH, _, _, _ = model.kinematic_tensors(q, qd)
        z_dot = (dH @ model.a_z) @ qd                                     # eq (a2)
        np.testing.assert_allclose(z_dot, fd(lambda p: model.project(p)[1], q, qd),
                                   rtol=1e-7, atol=1e-8)


def test_regressors_reproduce_Z_psi_Zdot_phi_and_Jperp_qdot(model, rng):
    fb = model.focal_length * model.scale
    for _ in range(20):
        q, qd = random_state(rng)
        psi, phi = rng.normal(size=2), rng.normal(size=2)
        H, dH, _, W, _ = model.kinematic_tensors(q, qd)
        z = model.project(q)[1]
        z_dot = fd(lambda p: model.project(p)[1], q, qd)
        np.testing.assert_allclose(model.Y_z(H, psi) @ model.a_z, np.repeat(z, 2) * psi,
                                   rtol=1e-12)
        np.testing.assert_allclose(model.Y_z_bar(qd @ dH, phi) @ model.a_z,
                                   np.repeat(z_dot, 2) * phi, rtol=1e-6, atol=1e-8)
        # J_z_perp q_dot = D_bar r_dot = f beta [r_y_dot, r_z_dot] for this camera
        r_dot = fd(lambda p: model.feature_positions(p)[0], q, qd)
        np.testing.assert_allclose(model.Y_z_perp(W, qd) @ model.a_z_perp, fb * r_dot[1:],
                                   rtol=1e-6, atol=1e-6)


def test_kinematic_tensor_rates_match_finite_difference(model, rng):
    for _ in range(10):
        q, qd = random_state(rng)
        _, _, dH_rate, _, W_rate = model.kinematic_tensors(q, qd)

        def tensor(index, qd=qd):
            return lambda p: model.kinematic_tensors(p, qd)[index]

        np.testing.assert_allclose(dH_rate, fd(tensor(1), q, qd), atol=1e-7)
        np.testing.assert_allclose(W_rate, fd(tensor(3), q, qd), atol=1e-7)


def test_image_jacobian_decomposition_matches_eq_a5(model, rng):
    q, qd = random_state(rng)
    x, _ = model.project(q)
    _, dH, _, W, _ = model.kinematic_tensors(q, qd)
    J = model.image_jacobian(W, dH, x, model.a_z_perp, model.a_z)
    # eq (a5): J q_dot = Y_z_perp a_z_perp - Y_z_bar(q, q_dot, x) a_z
    np.testing.assert_allclose(J @ qd, model.Y_z_perp(W, qd) @ model.a_z_perp
                               - model.Y_z_bar(qd @ dH, x) @ model.a_z, rtol=1e-12)


def test_projection_matches_pybullet_tip_and_pinhole_camera(model, plant, rng):
    camera = PinholeCamera.paper()
    for _ in range(5):
        q, _ = random_state(rng)
        plant.reset(q)
        pixels, depth = camera.project(plant.feature_positions())
        x, z = model.project(q)
        np.testing.assert_allclose(pixels, x, atol=1e-5)
        np.testing.assert_allclose(depth, z, atol=1e-7)


def test_mass_matrix_matches_pybullet(model, plant, rng):
    for _ in range(10):
        q, _ = random_state(rng)
        np.testing.assert_allclose(model.mass_matrix(q), plant.mass_matrix(q), atol=1e-9)


def test_regressor_matches_pybullet_inverse_dynamics(model, plant, rng):
    for _ in range(10):
        q, qd = random_state(rng)
        qdd = rng.uniform(-3, 3, 3)
        Y = model.dynamic_regressor(q, qd, qd, qdd)
        np.testing.assert_allclose(Y @ model.a_d, plant.inverse_dynamics(q, qd, qdd), atol=1e-9)


def test_regressor_separates_xi_from_qdot(model, rng):
    """Y_d(q, qd, xi, xi_dot) a_d = M xi_dot + C(q, qd) xi + g with xi != qd (Slotine-Li)."""
    q, qd = random_state(rng)
    xi, xi_dot = rng.normal(size=3), rng.normal(size=3)
    expected = (model.mass_matrix(q) @ xi_dot + model.coriolis_matrix(q, qd) @ xi
                + model.gravity_torque(q))
    np.testing.assert_allclose(model.dynamic_regressor(q, qd, xi, xi_dot) @ model.a_d, expected,
                               rtol=1e-12, atol=1e-12)


def test_mdot_minus_2c_is_skew_symmetric(model, rng):
    for _ in range(10):
        q, qd = random_state(rng)
        M_dot = fd(model.mass_matrix, q, qd)
        S = M_dot - 2 * model.coriolis_matrix(q, qd)
        np.testing.assert_allclose(S + S.T, 0.0, atol=1e-7)


def test_plant_follows_rigid_body_model_without_damping_or_motors(model, rng):
    """Forward dynamics of the plant over one 1 ms step equals M^-1 (tau - C qd - g)."""
    with ArmPlant(PAPER_URDF, physics_dt=1e-4) as arm:
        q, qd = random_state(rng)
        tau = rng.uniform(-20, 20, 3)
        arm.reset(q, qd)
        arm.advance(tau, 1)
        _, qd1 = arm.joint_state()
        qdd = np.linalg.solve(model.mass_matrix(q), tau - model.coriolis_matrix(q, qd) @ qd
                              - model.gravity_torque(q))
        np.testing.assert_allclose((qd1 - qd) / 1e-4, qdd, rtol=1e-6, atol=1e-6)


def test_unknown_model_name_is_refused():
    with pytest.raises(ValueError, match="unknown model name 'ur5'"):
        make_model("ur5")


def test_paper_camera_matrix_is_the_general_cameras_paper_case(model):
    np.testing.assert_allclose(PinholeCamera.paper().projection_matrix, model.camera_matrix,
                               atol=1e-12)


def test_paper_model_refuses_another_camera(model):
    camera = PinholeCamera.look_at((-5.0, 1.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 135.0,
                                   135.0, 320.0, 240.0, 640, 480, (320.0, 240.0), (-1.0, -1.0))
    with pytest.raises(ValueError, match="model paper_rrr assumes the paper's camera"):
        PaperRRRCamera().set_ground_truth(camera.projection_matrix)


def test_paper_estimate_from_the_guessed_camera_is_the_papers_initial_estimate():
    guess = PinholeCamera.paper(focal_length=0.1, scale=700.0, distance=3.0)
    a_perp, a_z, a_d = PaperRRRCamera().estimate(guess.projection_matrix, length_scale=1.5,
                                                 inertia_scale=0.0)
    np.testing.assert_allclose(a_perp, [210.0, 210.0])
    np.testing.assert_allclose(a_z, [3.0, 3.0, 3.0])
    np.testing.assert_array_equal(a_d, np.zeros(8))
