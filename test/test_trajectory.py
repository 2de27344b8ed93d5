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

"""Tabulated desired trajectories: scipy's CubicSpline as the oracle, C2 across the seam."""

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from visual_adaptive_servo.control.trajectory import TabulatedTrajectory


def table(periodic=True, m=2, n=201, duration=10.0):
    t = np.linspace(0.0, duration, n)
    x = np.column_stack([100.0 + 20.0 * np.sin(2 * np.pi * (k + 1) * t / duration + k)
                         for k in range(2 * m)])
    if not periodic:
        x = x + 3.0 * t[:, None]          # the sines alone close exactly: make it drift
    return t, x


@pytest.mark.parametrize("periodic", [True, False])
def test_values_and_derivatives_are_scipys_spline(periodic, rng):
    t, x = table(periodic)
    trajectory = TabulatedTrajectory(t, x)
    oracle = CubicSpline(t, x, bc_type="periodic" if periodic else "clamped")
    for ti in rng.uniform(0.0, 10.0, 50):
        got = trajectory(ti)
        for order in range(3):
            np.testing.assert_allclose(got[order], oracle(ti, order), rtol=0, atol=1e-9)


def test_a_periodic_table_repeats_and_is_c2_across_the_seam():
    trajectory = TabulatedTrajectory(*table(True))
    assert trajectory.periodic
    for a, b in zip(trajectory(10.0 - 1e-9), trajectory(10.0 + 1e-9)):
        np.testing.assert_allclose(a, b, atol=1e-5)
    for a, b in zip(trajectory(3.7), trajectory(23.7)):
        np.testing.assert_allclose(a, b, atol=1e-9)


def test_a_non_periodic_table_holds_its_last_point_at_rest():
    t, x = table(False)
    trajectory = TabulatedTrajectory(t, x)
    x_end, v_end, a_end = trajectory(12.0)
    np.testing.assert_allclose(x_end, x[-1])
    assert not v_end.any() and not a_end.any()


@pytest.mark.parametrize("text, message", [
    ("t,u1,v1\n0,1,2\n0.1,1,2\n", "needs at least 4 rows"),
    ("t,u1,v1\n0,1,2\n0.1,1\n", r"line 3 has 2 columns, needs 3"),
    ("t,u1,v1\n0.5,1,2\n0.6,1,2\n0.7,1,2\n0.8,1,2\n", "times must start at 0"),
    ("t,u1,v1\n0,1,2\n0.1,nan,2\n0.2,1,2\n0.3,1,2\n", "NaN or inf"),
    ("t,u1,v1,u2,v2\n0,1,2,3,4\n0.1,1,2,3,4\n0.2,1,2,3,4\n0.3,1,2,3,4\n",
     "line 2 has 5 columns, needs 3"),
])
def test_bad_tables_are_refused_with_the_reason(tmp_path, text, message):
    path = tmp_path / "x.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        TabulatedTrajectory.from_csv(path, 1)
