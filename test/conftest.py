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

"""Shared fixtures: the reference scenario and a continuous-time closed loop.

``simulate_continuous`` integrates the paper's closed loop -- true rigid-body
dynamics of the model, true projection, and :func:`control_law` -- with RK4,
so the proof's Lyapunov functions and the derivative in eq (19) can be checked
against the continuous-time theory, independently of sampling.
"""

import os

import numpy as np
import pytest

from visual_adaptive_servo.config import load_scenario
from visual_adaptive_servo.controller import EstimatorState, Gains, control_law

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PAPER_CONFIG = os.path.join(ROOT, "config", "paper_3dof.yaml")


@pytest.fixture
def rng():
    return np.random.default_rng(20150101)


@pytest.fixture(scope="session")
def scenario():
    return load_scenario(PAPER_CONFIG)


def paper_gains(config):
    return Gains(config.K, config.alpha, config.gamma, config.Gamma_d, config.Gamma_z_perp,
                 config.Gamma_z)


def pack(q, qd, st):
    return np.concatenate([q, qd, st.x_obs, st.a_z_perp, st.a_z, st.a_d])


def unpack(y, model):
    n, m2 = model.n, 2 * model.m
    sizes = [n, n, m2, model.p_perp, model.p_z, model.p_d]
    parts = np.split(y, np.cumsum(sizes)[:-1])
    return parts[0], parts[1], EstimatorState(*parts[2:])


def closed_loop_rates(model, gains, trajectory, t, y):
    """Time derivative of the packed closed-loop state and the law's output."""
    q, qd, st = unpack(y, model)
    x, _ = model.project(q)
    xd, xd_dot, xd_ddot = trajectory(t)
    out = control_law(model, gains, st, q, qd, x, xd, xd_dot, xd_ddot)
    M = model.mass_matrix(q)
    qdd = np.linalg.solve(M, out.tau - model.coriolis_matrix(q, qd) @ qd
                          - model.gravity_torque(q))
    r = out.rates
    dy = np.concatenate([qd, qdd, r.x_obs, r.a_z_perp, r.a_z, r.a_d])
    return dy, out, x, (xd, xd_dot, xd_ddot)


def simulate_continuous(model, gains, trajectory, q0, qd0, state0, dt, steps, observe):
    """RK4 of the closed loop; ``observe(t, y, out, x, desired)`` at every step."""
    y = pack(q0, qd0, state0)
    t = 0.0
    for _ in range(steps + 1):
        k1, out, x, desired = closed_loop_rates(model, gains, trajectory, t, y)
        observe(t, y, out, x, desired)
        k2 = closed_loop_rates(model, gains, trajectory, t + dt / 2, y + dt / 2 * k1)[0]
        k3 = closed_loop_rates(model, gains, trajectory, t + dt / 2, y + dt / 2 * k2)[0]
        k4 = closed_loop_rates(model, gains, trajectory, t + dt, y + dt * k3)[0]
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += dt
