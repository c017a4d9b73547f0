"""Plain checks of parameter values shared by ``parameters`` and ``arm_points`` (no rclpy)."""

from __future__ import annotations

import array
from typing import Any

from ...core.exceptions import InvalidInputError


def show(value: Any) -> str:
    """``repr(value)``, cut to 80 characters for an error message."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def string_list(name: str, value: Any, what: str) -> list[Any]:
    """The items of a string-array parameter, unchecked. None (an empty list in a params file
    arrives as NOT_SET) and the empty byte or integer array that ``[]`` may arrive as give [];
    a lone string or any other value is refused as not ``a list of <what>``."""
    if value is None:
        value = []
    if isinstance(value, (str, bytes)) or not isinstance(value, (list, tuple, array.array)):
        raise InvalidInputError(name, f"must be a list of {what}, got {show(value)}")
    return list(value)
