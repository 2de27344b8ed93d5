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

"""Many closed-loop runs from one YAML spec: the spec, the engine, the report, and their users.

* :mod:`.spec`: campaign specs (factors, cases, grids, random draws) resolved to runs;
* :mod:`.engine`: the worker-process pool and Ray, retries of dead workers;
* :mod:`.report`: summary.json, summary.md and the plots of a campaign;
* :mod:`.campaign`: ``vas campaign``, resumable runs.csv;
* :mod:`.compare` and :mod:`.robustness`: ``vas compare`` and ``vas robustness``,
  both campaigns.
"""
