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

"""The control law against the paper's own theory.

* eq (19) is the exact time derivative of eq (18) along closed-loop motion;
* the proof's V1 obeys dV1/dt = -s' J*' K J* s, and V2 of eq (30) -- the quadratic
  terms plus Pi* = (1/gamma)(l_M - int s'J*'Z^-1 J* s) -- obeys eq (32) and is
  non-increasing; integrated in continuous time (RK4, 0.1 ms) on the true model.
"""

import numpy as np
import pytest

from conftest import paper_gains, simulate_continuous, unpack
from visual_adaptive_servo.config.controller import ControllerConfig
from visual_adaptive_servo.schema import ConfigError
from visual_adaptive_servo.control.controller import EstimatorState, Gains
from visual_adaptive_servo.control.trajectory import SinusoidTrajectory

Q0 = np.array([1.0807, 0.5756, -0.5000])


def paper_setup(scenario, obs_offset=(0.0, 0.0)):
    c = scenario.controller
    model = c.model
    traj = SinusoidTrajectory(c["trajectory.offset"], c["trajectory.a_cos"],
                              c["trajectory.a_sin"], c["trajectory.omega"])
    x0, _ = model.project(Q0)
    state0 = EstimatorState(x0 + np.asarray(obs_offset), np.array(c.a_z_perp_init),
                            np.array(c.a_z_init), np.array(c.a_d_init))
    return model, paper_gains(c), traj, state0


def test_qr_ddot_is_time_derivative_of_qr_dot(scenario):
    model, gains, traj, state0 = paper_setup(scenario, obs_offset=(1.5, -1.0))
    dt, log = 2e-4, []
    simulate_continuous(model, gains, traj, Q0, np.zeros(3), state0, dt, 1500,
                        lambda t, y, out, x, d: log.append((out.qr_dot, out.qr_ddot)))
    qr_dot = np.array([a for a, _ in log])
    qr_ddot = np.array([b for _, b in log])
    numeric = (qr_dot[2:] - qr_dot[:-2]) / (2 * dt)
    scale = np.abs(qr_ddot).max()
    assert scale > 0.1, "the trajectory must actually accelerate for this check to mean anything"
    np.testing.assert_allclose(numeric, qr_ddot[1:-1], atol=2e-4 * scale)


def test_qr_ddot_includes_adaptation_rate_terms(scenario):
    """Dropping the adaptation rates from the total derivatives must break eq (19)."""
    model, gains, traj, state0 = paper_setup(scenario, obs_offset=(1.5, -1.0))
    strong = Gains(gains.K, gains.alpha, gains.gamma, gains.Gamma_d,
                   gains.Gamma_z_perp * 5, gains.Gamma_z * 5)
    dt, log = 2e-4, []
    simulate_continuous(model, strong, traj, Q0, np.zeros(3), state0, dt, 400,
                        lambda t, y, out, x, d: log.append((out.qr_dot, out.qr_ddot, out.rates)))
    qr_dot = np.array([e[0] for e in log])
    numeric = (qr_dot[2:] - qr_dot[:-2]) / (2 * dt)
    qr_ddot = np.array([e[1] for e in log])[1:-1]
    np.testing.assert_allclose(numeric, qr_ddot, atol=1e-3 * np.abs(qr_ddot).max())
    adapt = np.array([np.abs(e[2].a_z).max() + np.abs(e[2].a_z_perp).max() for e in log])
    assert adapt.max() > 1e-2, "adaptation must be active for the check to be meaningful"


def lyapunov_terms(model, gains, y, out, x, desired):
    q, qd, st = unpack(y, model)
    xd = desired[0]
    z = np.repeat(model.project(q)[1], 2)
    d_xo, d_x = st.x_obs - x, x - xd
    d_ad = st.a_d - model.a_d
    d_ap, d_az = st.a_z_perp - model.a_z_perp, st.a_z - model.a_z
    s, Js = out.s, out.J_star @ out.s
    V1 = 0.5 * s @ model.mass_matrix(q) @ s + 0.5 * d_ad @ (d_ad / gains.Gamma_d)
    V2 = (0.5 * d_xo @ (z * d_xo) + 0.5 * d_x @ (z * d_x)
          + 0.5 * d_ap @ (d_ap / gains.Gamma_z_perp) + 0.5 * d_az @ (d_az / gains.Gamma_z))
    V1_rate = -Js @ (gains.K * Js)
    integrand = Js @ (Js / z) / gains.gamma      # -d(Pi*)/dt
    # eq (32): the exact rate of V2, Pi* included
    V2_rate = (-gains.alpha * d_xo @ (z * d_xo) - gains.gamma * d_x @ (z * d_x)
               - gains.gamma * d_x @ (z * d_xo) + d_x @ Js - integrand)
    return V1, V2, V1_rate, integrand, V2_rate


@pytest.fixture(scope="module")
def lyapunov_run(scenario):
    model, gains, traj, state0 = paper_setup(scenario, obs_offset=(3.0, -2.0))
    rows = []
    simulate_continuous(model, gains, traj, Q0, np.zeros(3), state0, 1e-4, 3000,
                        lambda t, y, out, x, d: rows.append(
                            lyapunov_terms(model, gains, y, out, x, d)))
    return np.array(rows), 1e-4


def cumtrapz(f, dt):
    return np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * dt)])


def test_v1_is_non_increasing_and_its_rate_is_the_paper_rate(lyapunov_run):
    rows, dt = lyapunov_run
    V1, V1_rate = rows[:, 0], rows[:, 2]
    assert V1[0] > 1e-3
    assert np.all(np.diff(V1) <= 1e-9 * V1[0])
    # dV1/dt = -s'J*'KJ*s: the integrated rate reproduces V1 itself
    np.testing.assert_allclose(V1 - V1[0], cumtrapz(V1_rate, dt), atol=1e-5 * V1[0])


def test_v2_with_integral_term_is_non_increasing(lyapunov_run):
    rows, dt = lyapunov_run
    V2_quadratic, integrand, V2_rate = rows[:, 1], rows[:, 3], rows[:, 4]
    V2 = V2_quadratic - cumtrapz(integrand, dt)   # eq (30) up to the constant l_M / gamma
    assert V2[0] - V2[-1] > 1e-2 * V2[0], "the errors must actually decay in this run"
    assert np.all(np.diff(V2) <= 1e-9 * V2[0])
    # eq (32) holds along the motion: the adaptation laws (24), (25) cancel every
    # parameter-error term, so integrating the parameter-free rate gives V2 back
    np.testing.assert_allclose(V2 - V2[0], cumtrapz(V2_rate, dt), atol=1e-5 * V2[0])
    assert np.all(V2_rate <= 0.0)


def test_alpha_at_or_below_gamma_over_3_is_refused(scenario):
    params = dict(scenario.controller.params)
    params.update(alpha=3.0, gamma=9.0)
    with pytest.raises(ConfigError, match=r"alpha > gamma/3.*alpha=3.0 and gamma=9.0"):
        ControllerConfig.from_params(params)
    c = scenario.controller
    with pytest.raises(ConfigError, match="alpha > gamma/3"):
        Gains(c.K, 1.0, 3.0, c.Gamma_d, c.Gamma_z_perp, c.Gamma_z)


def test_joint_damping_keeps_v1_rate_and_v2(scenario):
    """With tau -= D s (joint_damping), dV1/dt = -s'(J*'KJ*s + D s) and V2 still follows eq (32).

    D is a constant symmetric positive definite matrix (a scaled inertia matrix here);
    the proof's V2 argument only needs the L2 bound on J*s that V1 gives, unchanged.
    """
    from dataclasses import replace

    model, gains, traj, state0 = paper_setup(scenario, obs_offset=(3.0, -2.0))
    D = 5.0 * model.mass_matrix(Q0)
    damped = replace(gains, D=D)
    rows, extra = [], []
    simulate_continuous(model, damped, traj, Q0, np.zeros(3), state0, 1e-4, 2000,
                        lambda t, y, out, x, d: (rows.append(lyapunov_terms(model, damped, y,
                                                                            out, x, d)),
                                                 extra.append(-out.s @ D @ out.s)))
    rows, dt = np.array(rows), 1e-4
    V1, V1_rate = rows[:, 0], rows[:, 2] + np.array(extra)
    assert np.all(np.diff(V1) <= 1e-9 * V1[0]) and V1[0] - V1[-1] > 1e-3 * V1[0]
    np.testing.assert_allclose(V1 - V1[0], cumtrapz(V1_rate, dt), atol=1e-5 * V1[0])
    V2 = rows[:, 1] - cumtrapz(rows[:, 3], dt)
    np.testing.assert_allclose(V2 - V2[0], cumtrapz(rows[:, 4], dt), atol=1e-5 * V2[0])
