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

"""The controllers by name: the paper's and the baselines it is compared with.

``vas run --controller NAME``, the campaigns' ``controller`` factor and
``vas compare`` all pick a controller here:

``observer``
    the paper's controller (H. Wang 2015): image-space observer, no image velocity,
    late frames applied at their capture time and predicted to now;
``observer-uncompensated``
    the same controller taking each frame as current when it arrives;
``velocity-diff``
    :class:`~.baselines.VelocityAdaptiveTracker` on the raw backward difference
    of the pixels (prediction-error gain 1e-3);
``velocity-lp``
    the same with a first-order low-pass of time constant 0.1 s;
``ibvs-calibrated``
    :class:`~.baselines.CalibratedIBVS`, true camera and arm: the upper reference.

A factory is called with the controller's configuration
(``config.controller.ControllerConfig``) and returns the controller.
"""

from __future__ import annotations

import functools

from ..schema import ConfigError
from .baselines import CalibratedIBVS, FrameHoldingTracker, VelocityAdaptiveTracker
from .controller import AdaptiveVisualTracker

CONTROLLER_NAMES = ("observer", "observer-uncompensated", "velocity-diff", "velocity-lp",
                    "ibvs-calibrated")
LOW_PASS_S = 0.1
PREDICTION_GAIN = 1e-3


def controllers():
    """(name, description, factory) of every controller, in :data:`CONTROLLER_NAMES` order."""
    return (
        ("observer", "Wang 2015: observer, no image velocity (this package)",
         AdaptiveVisualTracker),
        ("observer-uncompensated", "the same, each camera frame taken as current when it "
         "arrives (no latency compensation)", FrameHoldingTracker),
        ("velocity-diff", "velocity-based adaptive, backward-difference image velocity",
         functools.partial(VelocityAdaptiveTracker, prediction_gain=PREDICTION_GAIN)),
        ("velocity-lp", f"velocity-based adaptive, backward difference + {LOW_PASS_S:g} s "
         "first-order low-pass",
         functools.partial(VelocityAdaptiveTracker, filter_time=LOW_PASS_S,
                           prediction_gain=PREDICTION_GAIN)),
        ("ibvs-calibrated", "calibrated IBVS + computed torque (true camera and arm)",
         CalibratedIBVS),
    )


def controller_factory(name):
    """The factory of the controller called ``name`` (one of :data:`CONTROLLER_NAMES`)."""
    for known, _, factory in controllers():
        if known == name:
            return factory
    raise ConfigError(f"controller: must be one of {list(CONTROLLER_NAMES)}, got {name!r}")
