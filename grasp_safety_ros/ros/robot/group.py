"""The robot parameter group of the node (urdf or robot_description, base_frame, tip_frame,
ik_seed), applied together: what is pending, and the line that says why (plain Python)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ...core.exceptions import GraspSafetyError
from ..parameters import ROBOT_PARAMETERS
from .bundle import RobotBundle

ROBOT_GROUP = frozenset({*ROBOT_PARAMETERS, "ik_seed"})
"""Parameters that make the robot model; applied together (GraspSafetyNode._apply_parameters)."""

PENDING_FIELDS = frozenset({"base_frame", "tip_frame", "ik_seed"})
"""Fields of build_robot's errors that another robot parameter can resolve (a frame or a seed
that does not fit the description yet): the change is pending, not refused."""


def group_complete(pending: Mapping[str, Any]) -> bool:
    """Whether every robot parameter (urdf or robot_description, base_frame, tip_frame,
    ik_seed) is among the pending ones: no other parameter can make the group consistent."""
    return PENDING_FIELDS <= set(pending) and bool({*ROBOT_PARAMETERS[:2]} & set(pending))


def pending_reason(
    pending: Mapping[str, Any], error: GraspSafetyError, serving: RobotBundle | None
) -> str:
    """The one line that the parameter result, the log and /diagnostics give while the robot
    group is pending."""
    model = (
        f"the model from {serving.origin} ({serving.robot.base_frame} -> "
        f"{serving.robot.tip_frame}) serves until they are"
        if serving is not None
        else "no model serves until they are"
    )
    if group_complete(pending):
        return (
            f"robot parameters {', '.join(sorted(pending))} are not consistent ({error}); {model}"
        )
    return (
        f"robot parameters pending ({', '.join(sorted(pending))}): not consistent yet "
        f"({error}); {model}; set the rest of urdf, base_frame, tip_frame, ik_seed"
    )
