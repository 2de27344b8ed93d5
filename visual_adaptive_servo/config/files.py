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

"""Reading a ROS 2 parameter file, and ``--set section.param=value`` overrides (PyYAML only)."""

from __future__ import annotations

import yaml

from ..schema import CONTROLLER_SECTION, ConfigError, DETECTOR_SECTION, SIM_SECTION


def flatten(mapping, prefix=""):
    """Flatten nested mappings to dotted names, as ROS 2 does with parameter files."""
    flat = {}
    for key, value in mapping.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def _coerce_numbers(value):
    """Read '1e9' as a number like ROS 2's parameter parser does (YAML 1.1 keeps it a string)."""
    if isinstance(value, list):
        return [_coerce_numbers(v) for v in value]
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def read_param_file(path):
    """Read a ROS 2 parameter YAML into {section: flat params}.

    ``sim_node`` and ``controller_node`` are required; a ``feature_detector``
    section (the detector of ``camera_mode: rendered``) is read when present.
    """
    with open(path, encoding="utf-8") as handle:
        try:
            data = yaml.safe_load(handle)
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: must be a mapping with sim_node and controller_node")
    sections = {}
    for section in (SIM_SECTION, CONTROLLER_SECTION, DETECTOR_SECTION):
        body = data.get(section) or data.get("/" + section)
        if body is None and section == DETECTOR_SECTION:
            continue
        if not isinstance(body, dict) or not isinstance(body.get("ros__parameters"), dict):
            raise ConfigError(f"{path}: needs a '{section}: ros__parameters:' mapping")
        sections[section] = {k: _coerce_numbers(v)
                             for k, v in flatten(body["ros__parameters"]).items()}
    return sections


def apply_overrides(sections, overrides):
    """Apply ``section.param=value`` strings (values parsed as YAML); returns a new dict."""
    result = {name: dict(body) for name, body in sections.items()}
    for item in overrides:
        key, sep, text = item.partition("=")
        section, dot, name = key.partition(".")
        if section == DETECTOR_SECTION:
            result.setdefault(section, {})
        if not sep or not dot or section not in result:
            raise ConfigError(f"--set {item!r}: expected sim_node.NAME=VALUE, "
                              f"controller_node.NAME=VALUE or feature_detector.NAME=VALUE")
        try:
            result[section][name] = _coerce_numbers(yaml.safe_load(text))
        except yaml.YAMLError as exc:
            raise ConfigError(f"--set {item!r}: value is not valid YAML: {exc}") from None
    return result
