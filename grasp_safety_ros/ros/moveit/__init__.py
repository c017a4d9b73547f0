"""MoveIt's own types: the ``~/plan_grasps`` GraspPlanning server (server.py, grasps.py) and
a cost term for MoveIt Task Constructor (trajectory_cost.py); docs/ros/moveit.md.

They need ``moveit_msgs``, which ``make setup`` builds from ../shared/interfaces; without it
the node runs without ``~/plan_grasps`` (offer_plan_grasps says so once)."""

from __future__ import annotations

from typing import Any


def offer_plan_grasps(node: Any, **hooks: Any) -> Any:
    """The node's GraspPlanningServer (``hooks``: its arguments after the node), or None with
    an info line when moveit_msgs is not installed."""
    try:
        from .server import GraspPlanningServer
    except ModuleNotFoundError as error:  # moveit_msgs missing; any other import error raises
        if (error.name or "").partition(".")[0] != "moveit_msgs":
            raise
        node.get_logger().info(
            f"~/plan_grasps not offered: {error} (make setup builds moveit_msgs from "
            "../shared/interfaces)"
        )
        return None
    return GraspPlanningServer(node, **hooks)
