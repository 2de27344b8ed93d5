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

The cases (start offsets, noise with the noise preset, late and slow cameras,
wrong initial estimates, NaN bursts, lost frames, a rendered camera with a hidden
marker, the URDF arms) are config/campaigns/robustness.yaml, run here by the
campaign engine exactly as ``vas robustness`` runs them; the bounds are
:data:`visual_adaptive_servo.campaigns.robustness.BOUNDS`.
"""

import os

import numpy as np
import pytest

from conftest import ROOT

from visual_adaptive_servo.config.scenario import load_scenario
from visual_adaptive_servo.campaigns.robustness import BOUNDS, FAULT_CASES, run_matrix

CONFIG = os.path.join(ROOT, "config")


@pytest.fixture(scope="module")
def matrix(tmp_path_factory):
    return run_matrix(str(tmp_path_factory.mktemp("robustness")), workers=2, progress=False)


def test_every_case_of_the_spec_has_a_bound_and_ran(matrix):
    assert sorted(r["case"] for r in matrix) == sorted(BOUNDS)
    failed = [(r["case"], r["reason"]) for r in matrix if r["status"] != "finished"]
    assert not failed


@pytest.mark.parametrize("name", sorted(BOUNDS))
def test_case_is_bounded_and_tracks(matrix, name):
    row = next(r for r in matrix if r["case"] == name)
    assert not row["diverged"], row["command"]
    limit = np.max(load_scenario(os.path.join(CONFIG, row["config"])).controller.torque_limit)
    assert row["max_abs_torque"] <= limit
    assert row["final_rms_true_error_px"] <= row["bound"], row["command"]
    assert row["min_estimated_depth"] > 0.0
    if name in FAULT_CASES:
        assert row["rejected"] + row["frames_dropped"] > 0, "the faults must reach the controller"
