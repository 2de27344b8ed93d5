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

"""The controller: H. Wang's law (eqs 10-25), the sampled tracker, and what it compares with.

* :mod:`.controller`: :func:`~.controller.control_law` (the paper's section 3 as one
  pure function), :class:`~.controller.AdaptiveVisualTracker` (the sampled
  controller: projection, saturation, safety, late frames), the Theorem 1 check;
* :mod:`.prediction`: :class:`~.prediction.FramePredictor`, late camera frames
  applied at their capture time and predicted to now from the joints;
* :mod:`.trajectory`: desired image trajectories x_d and the blended start;
* :mod:`.baselines`: the velocity-based adaptive controller, calibrated IBVS and the
  frame-holding observer;
* :mod:`.registry`: every controller by name (``vas run --controller``, campaigns).

numpy only; the model of the arm and camera is any
:class:`~visual_adaptive_servo.models.RobotCameraModel`.
"""
