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

"""Declaring a parameter schema (:class:`visual_adaptive_servo.schema.ParamSpec`) on a node.

Used by the three nodes.  The structure parameters (``model``, ``urdf``,
``feature_points``, ...) are declared first, because the defaults of the
others (list lengths, initial estimates) depend on the model they define;
parameters with computed defaults come last, after the ones they read.  Every parameter gets a
``ParameterDescriptor`` with the schema's description, a range where the
schema has bounds (scalars only: ROS ranges do not apply to arrays, so the
bounds of a list are stated in its description and checked by
``from_params``), and ``read_only`` unless the schema marks it ``runtime``.
"""

from __future__ import annotations

import math

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.exceptions import ParameterException

from ..recording.cadence import checked_rate
from ..schema import ConfigError, did_you_mean

PARAMETER_TYPES = {
    "float": ParameterType.PARAMETER_DOUBLE,
    "int": ParameterType.PARAMETER_INTEGER,
    "bool": ParameterType.PARAMETER_BOOL,
    "str": ParameterType.PARAMETER_STRING,
    "float_list": ParameterType.PARAMETER_DOUBLE_ARRAY,
    "str_list": ParameterType.PARAMETER_STRING_ARRAY,
}
INT64_MAX = 2**63 - 1


def descriptor(spec, read_only=None):
    """ParameterDescriptor of one ParamSpec (type, description, range, read_only)."""
    read_only = (not spec.runtime) if read_only is None else read_only
    text = spec.description
    if spec.kind == "float_list" and (spec.low is not None or spec.high is not None):
        low = "-inf" if spec.low is None else f"{spec.low:g}"
        high = "inf" if spec.high is None else f"{spec.high:g}"
        text = f"{text} Every entry in [{low}, {high}]."
    # an optional parameter may stay unset (derived later) and a diagonal gain may be one
    # number: both need a type that follows the value given.  So does every number: a params
    # file's `30` or `[0, 0, 1]` is an INTEGER (array) to rclpy, which refuses it for a
    # DOUBLE (array) one; the schema takes integers as numbers (as vas run does) and refuses
    # what is not a number, naming the parameter
    dynamic = spec.optional or spec.scalar or spec.kind in ("float", "float_list")
    desc = ParameterDescriptor(name=spec.name, type=PARAMETER_TYPES[spec.kind],
                               description=text, read_only=read_only, dynamic_typing=dynamic)
    if spec.low is None and spec.high is None:
        return desc
    if spec.kind == "float":
        desc.floating_point_range = [FloatingPointRange(
            from_value=-math.inf if spec.low is None else float(spec.low),
            to_value=math.inf if spec.high is None else float(spec.high), step=0.0)]
    elif spec.kind == "int":
        desc.integer_range = [IntegerRange(
            from_value=-INT64_MAX if spec.low is None else int(spec.low),
            to_value=INT64_MAX if spec.high is None else int(spec.high), step=0)]
    return desc


def to_ros(spec, value):
    """A schema value as the Python type rclpy infers the declared type from."""
    if value is None:
        return None
    if spec.kind == "float":
        return float(value)
    if spec.kind == "int":
        return int(value)
    if spec.kind == "float_list":
        return [float(v) for v in value]
    if spec.kind == "str_list":
        return [str(v) for v in value]
    return value


def from_ros(spec, value):
    """An rclpy parameter value (arrays come as array.array) as the schema expects it."""
    if spec.kind in ("float_list", "str_list") and not isinstance(value, (int, float, str,
                                                                          type(None))):
        return list(value)
    return value


def runtime_changes(specs, parameters):
    """The schema values of a parameter-set request: ``(changes, None)``, or ``(None, reason)``.

    ``specs`` maps names to ParamSpecs; parameters it does not know (rclpy's own,
    ``use_sim_time``, ...) are left out.  A read-only one refuses the whole request.
    """
    changes = {}
    for param in parameters:
        spec = specs.get(param.name)
        if spec is None:
            continue
        if not spec.runtime:
            return None, f"{param.name} cannot change while running (restart the node)"
        changes[param.name] = from_ros(spec, param.value)
    return changes, None


def declare_schema(node, specs, section, build_structure=None, given=None):
    """Declare ``specs`` on ``node``; return the flat {name: value} it ends up with.

    ``given``, a set, receives the names whose value is not the schema's default (set by
    a parameter file or override): the controller's start-up report calls the others
    derived.

    ``build_structure(values)`` makes the object computed defaults need (the
    model, or the simulator's arm) from the structure parameters declared so far.
    Raises ConfigError (naming ``section.parameter`` and the rule) when a
    parameter override has the wrong type, is out of range, or the structure
    cannot be built.
    """
    ordered = ([s for s in specs if s.structure] + [s for s in specs if not s.structure
                                                    and not s.computed]
               + [s for s in specs if not s.structure and s.computed])
    values, structure = {}, None
    for spec in ordered:
        if spec.computed and structure is None and build_structure is not None:
            try:
                structure = build_structure(dict(values))
            except (ValueError, FileNotFoundError) as exc:
                text = str(exc)
                raise ConfigError(text if text.startswith(section) else
                                  f"{section}.{text}") from None
        try:
            default = spec.default_for(structure, values)
        except ValueError as exc:
            raise ConfigError(f"{section}.{spec.name}: no default: {exc}") from None
        try:
            param = node.declare_parameter(spec.name, to_ros(spec, default), descriptor(spec))
        except ParameterException as exc:
            raise ConfigError(f"{section}.{spec.name}: {exc}") from None
        values[spec.name] = from_ros(spec, param.value)
        if given is not None and values[spec.name] != from_ros(spec, to_ros(spec, default)):
            given.add(spec.name)
    return values


def declare_node_parameter(node, section, name, default, description, dynamic_typing=False):
    """Declare a read-only parameter outside the schema; return its value.

    A value of the wrong type raises ConfigError naming ``section.name``.
    """
    desc = ParameterDescriptor(name=name, description=description, read_only=True,
                               dynamic_typing=dynamic_typing)
    try:
        return node.declare_parameter(name, default, desc).value
    except ParameterException as exc:
        raise ConfigError(f"{section}.{name}: {exc}") from None


def declare_rate(node, section, name, default, description):
    """Declare a read-only rate [Hz] (an integer is taken too); return it as a float.

    Raises ConfigError naming ``section.name`` unless it is a positive finite number.
    """
    value = declare_node_parameter(node, section, name, float(default),
                                   f"{description} [Hz], positive and finite.",
                                   dynamic_typing=True)
    return checked_rate(f"{section}.{name}", value)


def refuse_unknown_overrides(node, section):
    """ConfigError naming the parameters given to ``node`` that it never declared.

    A params file, a launch file or the constructor may set a name the node does not
    have -- a typo -- and rclpy ignores it silently, while ``vas run`` refuses the same
    file.  Call once every parameter is declared.  rclpy keeps the overrides in
    ``Node._parameter_overrides`` (no public getter in Jazzy); the declared names come
    from ``get_parameters_by_prefix("")``.
    """
    given = getattr(node, "_parameter_overrides", None) or {}
    unknown = sorted(name for name in given if not node.has_parameter(name))
    if unknown:
        known = list(node.get_parameters_by_prefix(""))
        raise ConfigError(f"{section}: unknown parameter(s) {unknown}"
                          + did_you_mean(unknown, known)
                          + " (set in the params file or the launch; the node does not have "
                          "them)")
