"""Exceptions of grasp_safety_ros: one base class, subclasses that carry context."""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Mapping, Sequence


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


MAX_LISTED_FRAMES = 4
"""Frame names of each kind listed in a FrameNotFoundError message, the closest first (all are
in its ``available``)."""

MAX_SUGGESTIONS = 3
"""Names offered as "did you mean" in a FrameNotFoundError message."""


class FrameNotFoundError(GraspSafetyError, KeyError):
    """A frame name is not in the robot model.

    The message offers the closest names first ("did you mean"), then a few names of each kind
    (links, joints, ...), closest first, with how many more there are.

    Attributes:
        field: Name of the offending field.
        frame: The requested frame name.
        available: Frame names that exist in the model.
        by_kind: The same names by kind (e.g. ``links``, ``joints``), as given.
        reason: The message without the field name.
    """

    def __init__(
        self,
        field: str,
        frame: str,
        available: Iterable[str] | Mapping[str, Iterable[str]],
    ) -> None:
        by_kind = (
            {kind: sorted(set(names)) for kind, names in available.items()}
            if isinstance(available, Mapping)
            else {"frames": sorted(set(available))}
        )
        self.field = field
        self.frame = frame
        self.by_kind = by_kind
        self.available = sorted({name for names in by_kind.values() for name in names})
        self.reason = f"frame '{frame}' not found; " + _frame_choices(frame, by_kind)
        super().__init__(f"{field}: {self.reason}")

    def __str__(self) -> str:  # KeyError would add quotes around the message
        return str(self.args[0])

    def renamed(self, field: str) -> FrameNotFoundError:
        """The same error about another field."""
        return FrameNotFoundError(field, self.frame, self.by_kind)


def _closest_first(name: str, names: Sequence[str]) -> list[str]:
    """``names`` by decreasing similarity to ``name`` (difflib's ratio, case-insensitive)."""
    wanted = name.lower()

    def similarity(other: str) -> float:
        return difflib.SequenceMatcher(None, wanted, other.lower()).ratio()

    return sorted(names, key=lambda other: (-similarity(other), other))


def _frame_choices(frame: str, by_kind: Mapping[str, Sequence[str]]) -> str:
    everything = sorted({name for names in by_kind.values() for name in names})
    close = difflib.get_close_matches(frame, everything, n=MAX_SUGGESTIONS, cutoff=0.6)
    lowered = [name for name in everything if name.lower() == frame.lower()]
    close = list(dict.fromkeys(lowered + close))[:MAX_SUGGESTIONS]
    parts = [f"did you mean {' or '.join(repr(name) for name in close)}? " if close else ""]
    listed = []
    for kind, names in by_kind.items():
        if not names:
            continue
        rest = [name for name in _closest_first(frame, names) if name not in close]
        shown = rest[:MAX_LISTED_FRAMES]
        more = len(rest) - len(shown)
        listed.append(f"{kind}: {', '.join(shown)}" + (f" (+{more} more)" if more > 0 else ""))
    parts.append("; ".join(listed))
    return "".join(parts)


class RobotModelError(GraspSafetyError):
    """The robot description cannot be read or does not fit the method."""


def field_and_reason(error: GraspSafetyError, whole: str = "/") -> tuple[str, str]:
    """The field ``error`` names and what is wrong with it; for an error about no one field
    (only InvalidInputError and FrameNotFoundError name one), ``whole`` and the message."""
    if isinstance(error, (InvalidInputError, FrameNotFoundError)):
        return error.field, error.reason
    return whole, str(error)
