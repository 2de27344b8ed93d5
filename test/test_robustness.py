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

"""The robustness matrix: every case stays bounded and tracks within its stated bound.

The cases (start offsets, noise with the noise preset, camera delay, wrong
initial estimates, NaN bursts, dropped frames) live in
:mod:`visual_adaptive_servo.robustness`; ``vas robustness`` prints the same table
that the README shows.
"""

import pytest

from visual_adaptive_servo.robustness import CASES, run_case


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_case_is_bounded_and_tracks(case, tmp_path):
    summary = run_case(case, str(tmp_path), duration=10.0)
    assert not summary["diverged"], summary["divergence_reason"]
    assert summary["max_abs_torque"] <= summary["torque_limit"]
    assert summary["final_rms_true_error_px"] <= case.rms_bound_px
    assert summary["min_estimated_depth"] > 0.0
    if case.faults is not None:
        assert summary["rejected"] > 0, "the injected faults must reach the controller"
