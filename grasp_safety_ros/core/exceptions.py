"""Exceptions of grasp_safety_ros: one base class, subclasses that carry context."""

from __future__ import annotations

from collections.abc import Iterable


class GraspSafetyError(Exception):
    """Base class of every error raised by grasp_safety_ros."""


class InvalidInputError(GraspSafetyError, ValueError):
    """A value is out of its valid range or of the wrong type.

    Attributes:
        field: Dotted name of the offending field, e.g. ``object.mass_kg``.
        reason: What is wrong and what is allowed, without the field name.
    """

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        self.reason = message
        super().__init__(f"{field}: {message}")


MAX_LISTED_FRAMES = 40
"""Frame names listed in a FrameNotFoundError message (all are in its ``available``)."""


class FrameNotFoundError(GraspSafetyError, KeyError):
    """A frame name is not in the robot model.

    Attributes:
        field: Name of the offending field.
        frame: The requested frame name.
        available: Frame names that exist in the model.
        reason: The message without the field name.
    """

    def __init__(self, field: str, frame: str, available: Iterable[str]) -> None:
        self.field = field
        self.frame = frame
        self.available = sorted(set(available))
        listed = ", ".join(self.available[:MAX_LISTED_FRAMES])
        more = len(self.available) - MAX_LISTED_FRAMES
        if more > 0:
            listed += f" and {more} more"
        self.reason = f"frame '{frame}' not found; available frames: {listed}"
        super().__init__(f"{field}: {self.reason}")

    def __str__(self) -> str:  # KeyError would add quotes around the message
        return str(self.args[0])


class RobotModelError(GraspSafetyError):
    """The robot description cannot be read or does not fit the method."""
