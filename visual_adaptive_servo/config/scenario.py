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

"""A whole scenario: the parameter file read, overridden, validated and checked."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Callable

from ..schema import CONTROLLER_SECTION, DETECTOR_SECTION, SIM_SECTION
from .checks import check_pair, check_start
from .controller import ControllerConfig
from .files import apply_overrides, read_param_file
from .sim import SimConfig


@dataclass(frozen=True, eq=False)
class Scenario:
    """A validated simulator + controller configuration."""

    sim: SimConfig
    controller: ControllerConfig
    detector: object = None     # vision.detection.DetectorConfig when the camera renders


def load_scenario(path, overrides=(), edit: Callable[[dict], None] | None = None):
    """Read, override and validate a parameter file; both sections or nothing.

    File names inside (URDFs, trajectory tables) may be relative to the file's
    folder.  The controller's model gets the simulator's camera and arm as its
    ground truth, and the start is checked: every feature point in front of the
    camera and inside both the picture and the controller's ``image_bounds``,
    the true and the estimated image Jacobian of full row rank (Assumption 2).
    """
    sections = apply_overrides(read_param_file(path), overrides)
    if edit is not None:
        edit(sections)
    search_dirs = (os.path.dirname(os.path.abspath(path)),)
    sim = SimConfig.from_params(sections[SIM_SECTION], search_dirs=search_dirs)
    ctrl = ControllerConfig.from_params(sections[CONTROLLER_SECTION], search_dirs=search_dirs)
    check_pair(sim, ctrl)
    check_start(sim, ctrl)
    detector = None
    if sim.camera_mode == "rendered":
        # the detector (and OpenCV, ~0.1 s to import) only for a rendered camera: `vas`
        # starts without it
        from .detector import detector_for

        detector = detector_for(sim, sections.get(DETECTOR_SECTION))
    return Scenario(sim, ctrl, detector)
