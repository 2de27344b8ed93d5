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

ROS-free core: :mod:`.model` (robot + camera regressors), :mod:`.controller`
(the control law and the sampled controller), :mod:`.trajectory`,
:mod:`.config`, :mod:`.runner` (in-process closed loop) and :mod:`.cli` (``vas``).
The ROS 2 node is :mod:`.controller_node`.
"""

__version__ = "0.1.0"
