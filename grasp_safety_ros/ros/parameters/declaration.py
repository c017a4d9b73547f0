"""ROS declaration of the node parameters: static types, descriptors, and lossless conversions.

Every parameter of parameters.PARAMETERS is declared statically typed (the type of its default,
lists of ``ParameterSpec.item_type``) with a descriptor holding its description, constraints and
closed range where it has one, so ``ros2 param describe`` explains it and ``ros2 param dump``
writes a file the node starts from unchanged. Two conversions keep natural YAML working:
an integer where a double is declared (``ros2 param set /grasp_safety trajectory.duration_s 3``)
and an empty list, which ``ros2 param set`` sends as a bool array and rcl reads from a params
file as "not set", become the declared type.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, NamedTuple

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from ...core.exceptions import InvalidInputError
from .checks import ParameterConstraints, check_parameter, parameter_constraints
from .table import PARAMETERS, ParameterSpec


class ParameterTable(NamedTuple):
    """A node's parameters: their specs, the check of one value and its constraints."""

    specs: Mapping[str, ParameterSpec]
    check: Callable[[str, Any], Any]
    constraints: Callable[[str], ParameterConstraints]


RANKING_NODE = ParameterTable(PARAMETERS, check_parameter, parameter_constraints)
"""The ranking node's parameters (the default of every function here)."""

_SCALAR_TYPES = {
    bool: Parameter.Type.BOOL,
    int: Parameter.Type.INTEGER,
    float: Parameter.Type.DOUBLE,
    str: Parameter.Type.STRING,
}
_ARRAY_TYPES = {float: Parameter.Type.DOUBLE_ARRAY, str: Parameter.Type.STRING_ARRAY}
_Declaration = tuple[str] | tuple[str, Parameter.Type] | tuple[str, Any, ParameterDescriptor]
"""An item of ``Node.declare_parameters``'s list (its own type: lists are invariant)."""
_TYPE_WORDS = {
    Parameter.Type.BOOL: "true or false",
    Parameter.Type.INTEGER: "an integer",
    Parameter.Type.DOUBLE: "a number",
    Parameter.Type.STRING: "a string",
    Parameter.Type.DOUBLE_ARRAY: "a list of numbers",
    Parameter.Type.STRING_ARRAY: "a list of strings",
}


def declared_type(name: str, table: ParameterTable = RANKING_NODE) -> Parameter.Type:
    """The static type of node parameter ``name`` (from its default and item_type).

    Raises:
        TypeError: the spec gives no type (a list default without item_type).
    """
    spec = table.specs[name]
    if isinstance(spec.default, (list, tuple)):
        item = spec.item_type or (type(spec.default[0]) if spec.default else None)
        if item not in _ARRAY_TYPES:
            raise TypeError(f"parameter {name}: a list needs item_type float or str")
        return _ARRAY_TYPES[item]
    return _SCALAR_TYPES[type(spec.default)]


def descriptor(name: str, table: ParameterTable = RANKING_NODE) -> ParameterDescriptor:
    """The ParameterDescriptor of node parameter ``name``: type, description, constraints."""
    spec = table.specs[name]
    kind = declared_type(name, table)
    constraints = table.constraints(name)
    result = ParameterDescriptor(
        name=name,
        type=kind.value,
        description=spec.description,
        additional_constraints=constraints.text,
        read_only=spec.read_only,
    )
    if constraints.value_range is not None:
        low, high = constraints.value_range
        if kind is Parameter.Type.INTEGER:
            result.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
        elif kind is Parameter.Type.DOUBLE:
            result.floating_point_range = [
                FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)
            ]
    return result


def typed(parameter: Parameter, table: ParameterTable = RANKING_NODE) -> Parameter:
    """``parameter`` in its declared type where nothing is lost, else unchanged.

    An integer becomes a double, a list of integers a list of doubles, and an empty list of
    any type the declared empty list. Names not in PARAMETERS and values that cannot be
    converted are returned as they are (the type check then refuses them).
    """
    if parameter.name not in table.specs:
        return parameter
    kind, given, value = declared_type(parameter.name, table), parameter.type_, parameter.value
    if given is kind or given is Parameter.Type.NOT_SET:
        return parameter
    if kind is Parameter.Type.DOUBLE and given is Parameter.Type.INTEGER:
        return Parameter(parameter.name, kind, float(value))
    if kind in _ARRAY_TYPES.values() and given.name.endswith("_ARRAY") and len(value) == 0:
        return Parameter(parameter.name, kind, [])
    if kind is Parameter.Type.DOUBLE_ARRAY and given is Parameter.Type.INTEGER_ARRAY:
        return Parameter(parameter.name, kind, [float(v) for v in value])
    return parameter


def typed_parameters(
    parameters: list[Parameter], table: ParameterTable = RANKING_NODE
) -> list[Parameter]:
    """Pre-set callback: every parameter of a set request converted by typed()."""
    return [typed(parameter, table) for parameter in parameters]


def declare_node_parameters(node: Node, table: ParameterTable = RANKING_NODE) -> None:
    """Declare every parameter of ``table`` on ``node``, statically typed, with its descriptor.

    Overrides (params file, ``-p``, ``parameter_overrides``) are converted by typed() and
    checked one by one with the table's check first, in its order, so a bad one is
    reported by name with the reason. rclpy infers the type of a declared value again and
    takes ``[]`` for a byte array, so a list parameter that is to be empty is declared without
    that value and then set to the typed empty list.

    Raises:
        InvalidInputError: naming the first bad override.
    """
    overrides = node._parameter_overrides  # rclpy keeps them here; there is no public setter
    declarations: list[_Declaration] = []
    empty: list[Parameter] = []
    for name, spec in table.specs.items():
        kind = declared_type(name, table)
        value = spec.default
        if name in overrides:
            override = typed(overrides[name], table)
            if override.type_ is Parameter.Type.NOT_SET and kind in _ARRAY_TYPES.values():
                override = Parameter(name, kind, [])  # how rcl reads [] from a params file
            table.check(name, override.value)  # the reason, when it has one
            if override.type_ is not kind:
                raise InvalidInputError(
                    name, f"must be {_TYPE_WORDS[kind]}, got {override.value!r:.80}"
                )
            overrides[name] = override
            value = override.value
        if kind in _ARRAY_TYPES.values() and len(value) == 0:
            overrides.pop(name, None)
            empty.append(Parameter(name, kind, []))
        # an empty default is declared by type alone (an override, if any, gives the value)
        empty_default = isinstance(spec.default, (list, tuple)) and not spec.default
        declarations.append(
            (name, kind if empty_default else spec.default, descriptor(name, table))
        )
    node.declare_parameters("", declarations)
    for parameter, result in zip(empty, node.set_parameters(empty), strict=True):
        if not result.successful:
            raise InvalidInputError(parameter.name, result.reason)
