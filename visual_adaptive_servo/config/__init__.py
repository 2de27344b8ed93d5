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

"""Configuration: one ROS-style YAML file sets up the simulator, the controller and the detector.

The file has a ``sim_node:``, a ``controller_node:`` and optionally a
``feature_detector:`` section, each with ``ros__parameters:``; nested mappings
become dotted parameter names (``projection: {min_depth: 0.5}`` is
``projection.min_depth``), exactly as ROS 2 flattens them.  The same specs drive
the ROS nodes' parameter declarations and ``vas run``, and each section's
``from_params`` validates a complete parameter set at once: an invalid value is
refused with the parameter name and the rule it breaks, and nothing is partially
applied.

One module per seam, each importable without the others' dependencies:

* :mod:`.common`: what the sections share (camera and arm-structure specs);
* :mod:`.sim`, :mod:`.controller`, :mod:`.detector`: each section's parameter
  specs (``SIM_PARAMS``, ``CONTROLLER_PARAMS``, ``DETECTOR_PARAMS``) and its
  validated configuration (``SimConfig``, ``ControllerConfig``, ``detector_config``);
* :mod:`.files`: reading a parameter file and ``--set`` overrides (PyYAML only);
* :mod:`.checks`: the start-up checks of a simulator + controller pair;
* :mod:`.scenario`: :func:`~.scenario.load_scenario`, the three wired together.

The rules every spec is resolved by (:class:`~visual_adaptive_servo.schema.ParamSpec`,
``ConfigError``) are in :mod:`visual_adaptive_servo.schema`.
"""
