"""Exceptions of grasp_safety_ros: one base class, subclasses that carry context."""

from __future__ import annotations

from collections.abc import Iterable


class GraspSafetyError(Exception):
    """Base class of every error raised by grasp_safety_ros."""


class InvalidInputError(GraspSafetyError, ValueError):
    """A value is out of its valid range or of the wrong type.

    Attributes:
        field: Dotted name of the offending field, e.g. ``object.mass_kg``.
    """

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        super().__init__(f"{field}: {message}")


class FrameNotFoundError(GraspSafetyError, KeyError):
    """A frame name is not in the robot model.

    Attributes:
        frame: The requested frame name.
        available: Frame names that exist in the model.
    """

    def __init__(self, field: str, frame: str, available: Iterable[str]) -> None:
        self.field = field
        self.frame = frame
        self.available = sorted(set(available))
        super().__init__(
            f"{field}: frame '{frame}' not found; available frames: {', '.join(self.available)}"
        )

    def __str__(self) -> str:  # KeyError would add quotes around the message
        return str(self.args[0])


class RobotModelError(GraspSafetyError):
    """The robot description cannot be read or does not fit the method."""
