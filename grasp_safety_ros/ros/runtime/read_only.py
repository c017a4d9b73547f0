"""Read-only parameters in ``ros2 param load``: a file that repeats their value is not an error.

``ros2 param dump`` writes every parameter, the read-only ones too (``robot_description_timeout_s``
and rclpy's ``start_type_description_service``); loading that file back with ``ros2 param load``
printed "Set parameter ... failed: Trying to set a read-only parameter" for each, which reads as
if the load had gone wrong. rclpy refuses a read-only parameter before any node callback sees
it, so the node answers them on its ``set_parameters`` service itself (the service's callback
wrapped, in rclpy_private: rclpy has no public hook there): the current value again is a
success that says nothing changed; another value is refused with what to do instead.
Everything else goes to rclpy's own callback unchanged.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.node import Node
from rclpy.parameter import Parameter

from .rclpy_private import replace_service_callback

UNCHANGED = "unchanged: read-only, and already this value (read at start-up)"


def _same_number(value: Any, current: Any) -> bool:
    """``ros2 param dump`` writes a double such as 1e-06 without a decimal point, which
    ``ros2 param load`` (YAML 1.1) reads back as the string '1e-06': the same number."""
    if not isinstance(value, str) or not isinstance(current, float):
        return False
    try:
        return float(value) == current
    except ValueError:
        return False


def read_only_result(name: str, value: Any, current: Any) -> SetParametersResult:
    """The answer to setting read-only parameter ``name`` to ``value`` (now ``current``)."""
    if value == current or _same_number(value, current):
        return SetParametersResult(successful=True, reason=UNCHANGED)
    return SetParametersResult(
        successful=False,
        reason=(
            f"read-only: {name} is read at start-up (now {current!r}); give {value!r} in the "
            "params file or with -p when starting the node"
        ),
    )


def answer_read_only_parameters(node: Node) -> None:
    """Wrap ``node``'s ``set_parameters`` service so that read-only parameters are answered by
    read_only_result (module docstring); nothing to wrap without parameter services
    (``start_parameter_services=False``). The swap is private rclpy API
    (rclpy_private.replace_service_callback; test_ros_read_only.py fails if rclpy changes it)."""

    def answering(delegate: Callable[[Any, Any], Any]) -> Callable[[Any, Any], Any]:
        def set_parameters(
            request: SetParameters.Request, response: SetParameters.Response
        ) -> SetParameters.Response:
            for message in request.parameters:
                parameter = Parameter.from_parameter_msg(message)
                if node.has_parameter(parameter.name) and (
                    node.describe_parameter(parameter.name).read_only
                ):
                    current = node.get_parameter(parameter.name).value
                    result = read_only_result(parameter.name, parameter.value, current)
                    response.results.append(result)
                else:
                    alone = SetParameters.Request(parameters=[message])
                    answer: SetParameters.Response = delegate(alone, SetParameters.Response())
                    response.results.extend(answer.results)
            return response

        return set_parameters

    # no set_parameters service: nobody can load a params file into the node
    replace_service_callback(node, f"{node.get_fully_qualified_name()}/set_parameters", answering)
