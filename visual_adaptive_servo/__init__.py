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

"""visual_adaptive_servo: H. Wang's observer-based adaptive visual tracking (Automatica 2015).

ROS-free core in subpackages by concern, lowest first: :mod:`.models` (robot +
camera regressors), :mod:`.schema` (parameter specs and their rules),
:mod:`.vision` (feature detection), :mod:`.control` (the law, the sampled
controller, trajectories, baselines), :mod:`.recording` (messages, MCAP,
summaries, plots), :mod:`.config` (the parameter file), :mod:`.runner` (the
in-process closed loop) and :mod:`.teach`, :mod:`.campaigns` (many runs), and
:mod:`.cli` (``vas``).  The simulator is the sibling package :mod:`sim_bridge`.
The ROS 2 nodes are in :mod:`.ros`.  ``.importlinter`` states the layers.
"""

__version__ = "0.1.0"
