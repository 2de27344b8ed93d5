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

"""The controller is written for any n >= 2m, m <= 3: eq (19) checked with m = 2 and 3.

A synthetic model supplies smooth kinematic tensors (analytic derivatives) for
n joints and m feature points.  Along a prescribed smooth motion q(t), x(t),
with the observer and the estimates integrated by RK4 from the law's own rates,
q_ddot_r of eq (19) must be the time derivative of q_dot_r of eq (18).
"""

import numpy as np
import pytest

from visual_adaptive_servo.control.controller import EstimatorState, Gains, control_law
from visual_adaptive_servo.models import RobotCameraModel


class SyntheticModel(RobotCameraModel):
    """Entries sin(A q + b) with analytic joint gradients; depth kept near 5 m."""

    def __init__(self, n, m, p_perp=3, p_z=3, seed=0):
        rng = np.random.default_rng(seed)
        self.n, self.m, self.p_perp, self.p_z, self.p_d = n, m, p_perp, p_z, 1
        self.A = rng.normal(size=(2 * m, p_perp, n))
        self.b = rng.normal(size=(2 * m, p_perp))
        self.C = 0.3 * rng.normal(size=(m, p_z, n))
        self.d = rng.normal(size=(m, p_z))

    @staticmethod
    def _tensors(A, b, q, qd):
        phase = A @ q + b
        grad = np.cos(phase)[..., None] * A                   # (rows, p, n)
        rate = (-np.sin(phase) * (A @ qd))[..., None] * A
        return np.sin(phase), grad.transpose(0, 2, 1), rate.transpose(0, 2, 1)

    def kinematic_tensors(self, q, qd):
        h, dH, dH_rate = self._tensors(self.C, self.d, q, qd)
        _, W, W_rate = self._tensors(self.A, self.b, q, qd)
        return h + 5.0, dH, dH_rate, W, W_rate

    def dynamic_regressor(self, q, qd, xi, xi_dot):
        return np.zeros((self.n, 1))

    def feature_positions(self, q):
        raise NotImplementedError

    def project(self, q):
        raise NotImplementedError

    def estimate(self, camera_matrix, length_scale=1.0, inertia_scale=1.0):
        raise NotImplementedError

    def set_ground_truth(self, camera_matrix, chain=None, offsets=None):
        raise NotImplementedError

    def mass_matrix(self, q):
        raise NotImplementedError

    def coriolis_matrix(self, q, qd):
        raise NotImplementedError

    def gravity_torque(self, q):
        raise NotImplementedError


@pytest.mark.parametrize("n, m", [(3, 1), (4, 1), (4, 2), (6, 3), (7, 3)])
def test_qr_ddot_is_time_derivative_of_qr_dot_for_several_features(n, m):
    model = SyntheticModel(n, m, seed=n + m)
    rng = np.random.default_rng(n * m)
    gains = Gains(np.full(2 * m, 0.01), 4.0, 3.0, np.ones(1), np.full(3, 5.0), np.full(3, 0.05))
    q0, w = rng.normal(size=n), rng.uniform(0.5, 1.5, n)
    x0, wx = rng.normal(size=2 * m) * 30, rng.uniform(0.5, 1.5, 2 * m)

    def motion(t):
        return (q0 + 0.3 * np.sin(w * t), 0.3 * w * np.cos(w * t),
                x0 + 5 * np.sin(wx * t), x0 + 4 * np.sin(wx * t), 4 * wx * np.cos(wx * t),
                -4 * wx**2 * np.sin(wx * t))

    def law(t, st):
        q, qd, x, xd, xd_dot, xd_ddot = motion(t)
        return control_law(model, gains, st, q, qd, x, xd, xd_dot, xd_ddot)

    def advance(st, rates, h):
        return st.advanced(rates, h)

    st = EstimatorState(x0 + 1.0, rng.uniform(1, 2, 3), rng.uniform(0.5, 1, 3), np.zeros(1))
    dt, log = 2.5e-4, []
    for k in range(800):
        t = k * dt
        o1 = law(t, st)
        log.append((o1.qr_dot, o1.qr_ddot, o1.sigma_min))
        o2 = law(t + dt / 2, advance(st, o1.rates, dt / 2))
        o3 = law(t + dt / 2, advance(st, o2.rates, dt / 2))
        o4 = law(t + dt, advance(st, o3.rates, dt))
        r1, r2, r3, r4 = (o.rates for o in (o1, o2, o3, o4))
        st = EstimatorState(*(
            getattr(st, f) + dt / 6 * (getattr(r1, f) + 2 * getattr(r2, f)
                                       + 2 * getattr(r3, f) + getattr(r4, f))
            for f in ("x_obs", "a_z_perp", "a_z", "a_d")))
    qr_dot = np.array([e[0] for e in log])
    qr_ddot = np.array([e[1] for e in log])[1:-1]
    assert min(e[2] for e in log) > 0.1, "keep J* well away from singular for this check"
    numeric = (qr_dot[2:] - qr_dot[:-2]) / (2 * dt)
    assert qr_dot.shape[1] == n
    np.testing.assert_allclose(numeric, qr_ddot, atol=1e-4 * np.abs(qr_ddot).max())
