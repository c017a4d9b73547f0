"""Conversions between ROS messages and core types; needs message packages, not rclpy.

One module per concern, imports one way: ``geometry`` (poses, quaternions, stamps; the only
place that knows the x, y, z, w order) <- ``requests`` (messages to core types); ``_fast``
(slot constructors, paused collector) <- ``results`` (core results to messages); ``markers``
(RViz). This package re-exports the names the node, the tests and the benchmarks use.
"""

from .geometry import (
    MAX_ABS_POSITION_M,
    check_frame_id,
    duration_msg,
    pose_msg_from_transform,
    quat_xyzw_from_msg,
    quaternion_msg_from_rotation,
    transform_from_pose_msg,
)
from .markers import markers_msg, rank_color
from .requests import (
    check_grasp_array,
    grasps_from_pose_array,
    grasps_with_joint_trajectories,
    inertia_msg_from_object,
    object_inertia_from_msg,
    object_trajectory_of_request,
    seed_from_joint_state,
    trajectory_from_msg,
    trajectory_from_multi_dof,
    trajectory_from_path,
    transforms_from_pose_msgs,
)
from .results import evaluation_msg, ranking_msg, report_msg

__all__ = [
    "MAX_ABS_POSITION_M",
    "check_frame_id",
    "check_grasp_array",
    "duration_msg",
    "evaluation_msg",
    "grasps_from_pose_array",
    "grasps_with_joint_trajectories",
    "inertia_msg_from_object",
    "markers_msg",
    "object_inertia_from_msg",
    "object_trajectory_of_request",
    "pose_msg_from_transform",
    "quat_xyzw_from_msg",
    "quaternion_msg_from_rotation",
    "rank_color",
    "ranking_msg",
    "report_msg",
    "seed_from_joint_state",
    "trajectory_from_msg",
    "trajectory_from_multi_dof",
    "trajectory_from_path",
    "transform_from_pose_msg",
    "transforms_from_pose_msgs",
]
