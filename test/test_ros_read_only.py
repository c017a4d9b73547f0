"""ros.runtime.read_only: read-only parameters answered on the node's set_parameters service,
whose callback it wraps (rclpy has no public hook there: ros.runtime.rclpy_private), and
nothing wrapped without parameter services."""

from __future__ import annotations

import pytest

pytest.importorskip("rclpy")

from rcl_interfaces.msg import ParameterDescriptor
from rcl_interfaces.srv import SetParameters
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

from grasp_safety_ros.ros.runtime.read_only import UNCHANGED, answer_read_only_parameters

LAYOUT_CHANGED = (
    "rclpy's parameter services changed: ros/runtime/rclpy_private.py replace_service_callback "
    "(used by ros/runtime/read_only.py) relies on Node.services yielding "
    "a Service named <node>/set_parameters whose .callback(request, response) it replaces; "
    "port it to a public hook on that service if rclpy has one now "
    "(add_pre_set_parameters_callback cannot answer: rclpy refuses the list it empties)"
)


def test_without_parameter_services_nothing_is_wrapped(context: Context) -> None:
    node = Node("read_only_none", context=context, start_parameter_services=False)
    try:
        answer_read_only_parameters(node)  # was StopIteration
        assert not any(s.service_name.endswith("/set_parameters") for s in node.services)
    finally:
        node.destroy_node()


def test_the_set_parameters_callback_rclpy_offers_is_wrapped(context: Context) -> None:
    node = Node("read_only_wrapped", context=context)
    try:
        node.declare_parameter("fixed", 1.0, ParameterDescriptor(read_only=True))
        name = f"{node.get_fully_qualified_name()}/set_parameters"
        services = [s for s in node.services if s.service_name == name]
        assert len(services) == 1, LAYOUT_CHANGED
        service = services[0]
        assert callable(getattr(service, "callback", None)), LAYOUT_CHANGED
        original = service.callback
        answer_read_only_parameters(node)
        assert service.callback is not original, LAYOUT_CHANGED

        def set_fixed(value: float) -> object:
            message = Parameter("fixed", value=value).to_parameter_msg()
            request = SetParameters.Request(parameters=[message])
            response = service.callback(request, SetParameters.Response())
            assert isinstance(response, SetParameters.Response), LAYOUT_CHANGED
            (result,) = response.results
            return result

        same = set_fixed(1.0)  # a dump loaded back: the current value is no failure
        assert same.successful and same.reason == UNCHANGED
        other = set_fixed(2.0)
        assert not other.successful and "read-only: fixed" in other.reason
        assert node.get_parameter("fixed").value == 1.0
    finally:
        node.destroy_node()


def test_a_dumped_double_read_back_as_text_is_the_same_value() -> None:
    """``ros2 param dump`` writes 1e-06, which ``ros2 param load`` reads as the string
    '1e-06': a read-only parameter at that value is unchanged, another value is refused."""
    from grasp_safety_ros.ros.runtime.read_only import UNCHANGED, read_only_result

    assert read_only_result("ik.position_tolerance_m", "1e-06", 1e-6).reason == UNCHANGED
    assert read_only_result("ik.position_tolerance_m", 1e-6, 1e-6).successful
    for other in ("2e-06", "not a number", 2e-6):
        result = read_only_result("ik.position_tolerance_m", other, 1e-6)
        assert not result.successful and "read at start-up" in result.reason
