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

"""The random arms of benchmarks/unseen_arms.py: the guess's errors scaled by guess_scale."""

import numpy as np
import yaml

from visual_adaptive_servo.campaigns.unseen_arms import random_arm


def _sections(arm):
    with open(arm.path, encoding="utf-8") as handle:
        data = yaml.safe_load(handle)
    return data["sim_node"]["ros__parameters"], data["controller_node"]["ros__parameters"]


def test_guess_scale_multiplies_the_guess_errors_of_the_same_arm(tmp_path):
    arms = {g: random_arm(3, str(tmp_path / str(g)), guess_scale=g) for g in (1.0, 2.0)}
    (sim1, ctl1), (sim2, ctl2) = _sections(arms[1.0]), _sections(arms[2.0])
    assert sim1 == sim2                         # the same arm, camera and start
    with open(arms[1.0].path.replace(".yaml", "_trajectory.csv"), encoding="utf-8") as one, \
            open(arms[2.0].path.replace(".yaml", "_trajectory.csv"), encoding="utf-8") as two:
        assert one.read() == two.read()         # taught on the same arm
    truth = sim1["camera"]
    guess1, guess2 = (c["initial_estimate"]["camera"] for c in (ctl1, ctl2))
    for key in ("position", "look_at"):
        np.testing.assert_allclose(np.subtract(guess2[key], truth[key]),
                                   2.0 * np.subtract(guess1[key], truth[key]), rtol=1e-12)
    np.testing.assert_allclose(guess2["focal_length"] / truth["focal_length"] - 1.0,
                               2.0 * (guess1["focal_length"] / truth["focal_length"] - 1.0),
                               rtol=1e-9)
    np.testing.assert_allclose(np.divide(guess2["pixel_scale"], truth["pixel_scale"]) - 1.0,
                               2.0 * (np.divide(guess1["pixel_scale"], truth["pixel_scale"])
                                      - 1.0), rtol=1e-9)
    np.testing.assert_allclose(ctl2["initial_estimate"]["length_scale"] - 1.0,
                               2.0 * (ctl1["initial_estimate"]["length_scale"] - 1.0),
                               rtol=1e-12)
    # the inertial guess is not a kinematic error: drawn as before
    assert ctl2["initial_estimate"]["inertia_scale"] == ctl1["initial_estimate"]["inertia_scale"]
