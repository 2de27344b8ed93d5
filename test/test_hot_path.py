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

"""The fast paths of the controller sample equal their slow, generic oracles.

* the closed-form Y_d of the paper's RRR arm equals the generic Christoffel
  regressor built from the basis of M and g;
* the closed-form 2x2 damped Gram inverse equals numpy's eigvalsh / inv;
* the projection's shortcuts (nothing at a bound) give what the full projection gives;
* control_law with the kinematic tensors passed in is control_law.
"""

import numpy as np
import pytest

from conftest import paper_gains
from visual_adaptive_servo.control.controller import (
    EstimatorState,
    Projection,
    _damped_gram_inverse,
    control_law,
)
from visual_adaptive_servo.models import PaperRRRCamera


@pytest.fixture
def model():
    return PaperRRRCamera()


def test_closed_form_dynamic_regressor_matches_generic_christoffel_regressor(model, rng):
    for _ in range(200):
        q, qd, xi, xi_dot = (rng.normal(0.0, 2.0, 3) for _ in range(4))
        np.testing.assert_allclose(model.dynamic_regressor(q, qd, xi, xi_dot),
                                   model.generic_dynamic_regressor(q, qd, xi, xi_dot),
                                   rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("min_singular_value", [0.0, 50.0, 1e4])
def test_closed_form_gram_inverse_matches_numpy(rng, min_singular_value):
    for _ in range(100):
        J = rng.normal(0.0, 100.0, (2, 3))
        G = J @ J.T
        G_inv, sigma_min, damped = _damped_gram_inverse(G, min_singular_value)
        sigma_ref = np.sqrt(max(np.linalg.eigvalsh(G)[0], 0.0))
        assert sigma_min == pytest.approx(sigma_ref, rel=1e-9)
        assert damped == (sigma_ref < min_singular_value)
        lam2 = min_singular_value**2 - sigma_ref**2 if damped else 0.0
        np.testing.assert_allclose(G_inv, np.linalg.inv(G + lam2 * np.eye(2)), rtol=1e-9)


def test_singular_gram_matrix_raises_like_numpy():
    with pytest.raises(np.linalg.LinAlgError, match="Singular"):
        _damped_gram_inverse(np.zeros((2, 2)), 0.0)


def test_interior_means_clamp_and_rate_projection_change_nothing(model, rng):
    """step() skips clamp and the law's projection when interior(): check that is exact."""
    bounds = (np.array([20.0, 20.0]), np.array([2000.0, 2000.0]), np.array([0.2, 0.2, 0.5]),
              np.array([10.0, 10.0, 50.0]), np.full(8, -50.0), np.full(8, 50.0), 0.5)
    proj = Projection(*bounds)
    gamma_z = np.full(3, 0.2)
    interior = 0
    for _ in range(500):
        # estimates inside, on and outside the bounds; depths above and below min_depth
        if rng.random() < 0.5:
            a_perp, a_z, a_d = rng.uniform(21, 1999, 2), rng.uniform(0.3, 9, 3), np.ones(8)
        else:
            a_perp = rng.choice([10.0, 20.0, 300.0, 2000.0, 3000.0], 2)
            a_z = np.array([rng.choice([0.1, 0.2, 2.0]), rng.choice([0.2, 3.0, 11.0]),
                            rng.choice([0.5, 4.0])])
            a_d = rng.choice([-60.0, -50.0, 1.0, 50.0], 8)
        H = model.kinematic_tensors(rng.uniform(-np.pi, np.pi, 3), np.zeros(3))[0]
        state = EstimatorState(np.zeros(2), a_perp, a_z, a_d)
        r_perp, r_z, r_d = rng.normal(0, 1, 2), rng.normal(0, 1, 3), rng.normal(0, 1, 8)
        if proj.interior(state, H):
            clamped = proj.clamp(state, H)
            for name in ("a_z_perp", "a_z", "a_d"):
                np.testing.assert_array_equal(getattr(clamped, name), getattr(state, name))
            rates = proj.kinematic_rates(state, r_perp, r_z, H, gamma_z)
            np.testing.assert_array_equal(rates[0], r_perp)
            np.testing.assert_array_equal(rates[1], r_z)
            d_rate, d_active = proj.dynamic_rate(a_d, r_d)
            np.testing.assert_array_equal(d_rate, r_d)
            assert not rates[2] and not d_active
            interior += 1
    assert 50 < interior < 450, interior


def test_control_law_with_precomputed_tensors_is_the_same(model, scenario, rng):
    q, qd = rng.normal(0, 1, 3), rng.normal(0, 1, 3)
    x = rng.uniform(-50, 50, 2)
    state = EstimatorState(x + 1.0, np.array([210.0, 210.0]), np.array([3.0, 3.0, 3.0]),
                           rng.normal(0, 5, 8))
    args = (model, paper_gains(scenario.controller), state, q, qd, x, x - 2.0, np.ones(2),
            np.ones(2))
    a = control_law(*args)
    b = control_law(*args, tensors=model.kinematic_tensors(q, qd))
    for name in ("tau", "qr_dot", "qr_ddot", "J_star"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
