"""Parameter declaration: every parameter statically typed with its descriptor; integers and
empty lists (as ``ros2 param set`` and params files write them) taken as the declared type;
a bad override refused at start-up naming the parameter. In-process node, own rclpy context.
"""

from __future__ import annotations

from typing import Any

import pytest
from conftest import ARM6_AXES, serial_arm_urdf
from rcl_interfaces.msg import ParameterType
from rclpy.context import Context
from rclpy.parameter import Parameter

from grasp_safety_ros.ros.node import GraspSafetyNode, StartupError
from grasp_safety_ros.ros.parameters import PARAMETERS, check_parameter
from grasp_safety_ros.ros.parameters.declaration import declared_type, descriptor, typed

ARM = {"robot_description": serial_arm_urdf(ARM6_AXES), "base_frame": "base_link"}
ARM["tip_frame"] = "tool"
PYTHON_TYPES = {
    ParameterType.PARAMETER_BOOL: bool,
    ParameterType.PARAMETER_INTEGER: int,
    ParameterType.PARAMETER_DOUBLE: float,
    ParameterType.PARAMETER_STRING: str,
}
ARRAY_ITEMS = {
    ParameterType.PARAMETER_DOUBLE_ARRAY: float,
    ParameterType.PARAMETER_STRING_ARRAY: str,
}


@pytest.mark.parametrize("name", list(PARAMETERS))
def test_every_parameter_has_a_static_type_that_fits_its_default(name: str) -> None:
    spec, declared = PARAMETERS[name], descriptor(name)
    assert declared.type == declared_type(name).value and not declared.dynamic_typing
    assert declared.description == spec.description and declared.read_only == spec.read_only
    if declared.type in ARRAY_ITEMS:
        assert isinstance(spec.default, list)
        assert all(type(v) is ARRAY_ITEMS[declared.type] for v in spec.default)
    else:
        assert type(spec.default) is PYTHON_TYPES[declared.type]
    for ranges in (declared.floating_point_range, declared.integer_range):
        for range_ in ranges:  # a ROS range is closed: both ends pass the node's own check
            check_parameter(name, spec.default)
            for end in (range_.from_value, range_.to_value):
                check_parameter(name, end)
            below = range_.from_value - (1 if declared.integer_range else 1e-6)
            with pytest.raises(ValueError, match=name):
                check_parameter(name, below)


@pytest.mark.parametrize(
    ("name", "given", "kind", "value"),
    [
        ("trajectory.duration_s", 3, Parameter.Type.DOUBLE, 3.0),
        ("ik_seed", [0, 1], Parameter.Type.DOUBLE_ARRAY, [0.0, 1.0]),
        ("ik_seed", [], Parameter.Type.DOUBLE_ARRAY, []),  # [] arrives as a byte array
        ("iso_ts_15066.regions", [False], Parameter.Type.BOOL_ARRAY, [False]),  # not empty
        ("iso_ts_15066.regions", [], Parameter.Type.STRING_ARRAY, []),
        ("max_grasps", 10.0, Parameter.Type.DOUBLE, 10.0),  # never a double to an integer
        ("metric", 1, Parameter.Type.INTEGER, 1),
        ("use_sim_time", 1, Parameter.Type.INTEGER, 1),  # not ours: unchanged
    ],
)
def test_typed_converts_only_without_loss(
    name: str, given: Any, kind: Parameter.Type, value: Any
) -> None:
    converted = typed(Parameter(name, value=given))
    assert converted.type_ is kind
    if isinstance(value, list):
        assert list(converted.value) == value
    else:
        assert converted.value == value and type(converted.value) is type(value)


def start(context: Context, **overrides: Any) -> GraspSafetyNode:
    values = {**ARM, **{name.replace("__", "."): value for name, value in overrides.items()}}
    parameters = [Parameter(name, value=value) for name, value in values.items()]
    return GraspSafetyNode(context=context, parameter_overrides=parameters)


def test_overrides_as_params_files_write_them_are_declared_typed(context: Context) -> None:
    node = start(
        context,
        ik_seed=None,  # rcl reads `[]` in a params file as "not set"
        object__points_in_object_m=[],  # ... and rclpy builds [] as a byte array
        object__box_size_m=[1, 2, 3],  # integers where doubles are declared
        trajectory__duration_s=4,
    )
    try:
        for name in PARAMETERS:
            parameter = node.get_parameter(name)
            assert parameter.type_ is declared_type(name), name
        assert node.get_parameter("ik_seed").value == []
        assert list(node.get_parameter("object.box_size_m").value) == [1.0, 2.0, 3.0]
        assert node.get_parameter("trajectory.duration_s").value == 4.0
        assert node.get_parameter("iso_ts_15066.regions").value == []  # default, typed
        results = node.set_parameters([Parameter("ik_seed", value=[0] * 6)])
        assert results[0].successful, results[0].reason
        assert node.get_parameter("ik_seed").value == [0.0] * 6
        (result,) = node.set_parameters([Parameter("robot_description_timeout_s", value=1.0)])
        assert not result.successful and "read-only" in result.reason
    finally:
        node.destroy_node()


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"max_grasps": "lots"}, "max_grasps: must be an integer, got 'lots'"),
        ({"max_grasps": 10.0}, "max_grasps: must be an integer, got 10.0"),
        ({"ik_seed": "null"}, "ik_seed: must be a list of numbers, got 'null'"),
        ({"iso_ts_15066__regions": [1, 2]}, "iso_ts_15066.regions: must be a list of region"),
        ({"safety_weight": 2.0}, r"safety_weight: must be in \[0, 1\], got 2"),
        ({"use_joint_states_seed": 1}, "use_joint_states_seed: must be true or false, got 1"),
    ],
)
def test_bad_override_is_refused_naming_it(
    context: Context, overrides: dict[str, Any], message: str
) -> None:
    with pytest.raises(StartupError, match=message):
        start(context, **overrides)
