"""Why the node refuses or abandons a ranking (answered to the client, counted on
/diagnostics)."""

from __future__ import annotations

from ...core.exceptions import GraspSafetyError


class StartupError(GraspSafetyError):
    """The node cannot start: bad parameters or no usable robot description."""


class NotReadyError(GraspSafetyError):
    """No robot model yet."""


class BusyError(GraspSafetyError):
    """Another ranking held the compute lock for longer than service_busy_timeout_s."""


class ComputeTimeExceededError(GraspSafetyError):
    """A ranking ran longer than max_compute_time_s and was abandoned."""


class ShuttingDownError(GraspSafetyError):
    """The node is shutting down: the ranking was abandoned."""


class ClientGoneError(GraspSafetyError):
    """The request's client left the ROS graph: the ranking was abandoned."""


def internal_error(error: BaseException) -> str:
    """The answer to an unexpected exception (a bug): its type and text."""
    return f"internal error: {type(error).__name__}: {error}"
