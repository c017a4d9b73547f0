"""moveit_msgs/Grasp lists to and from the node's ranking (plain Python, no rclpy).

The ranking takes a PoseArray of tip poses (one frame for all), optional grasp qualities and a
nav_msgs/Path of the object; the answer is the same Grasp messages, reordered, each with its
``grasp_quality`` replaced by the safety quality below.

Safety quality (``grasp_quality`` of the answer; higher is safer, in [0, 1]):
- ranked by safety and the planner's qualities (``moveit.planner_quality``): the node's
  ``combined_score`` w·(1 − safety_norm) + (1 − w)·quality_norm (``safety_weight`` w);
- otherwise 1 / (1 + key), key ≥ 0 the value the node's ``rank_by`` orders by, lowest first:
  ``safety_score`` (kg, kg·s for the integral metric), ``effort_score`` (fraction of the
  effort limits) or ``whole_arm_rank_force_n`` (N); a key the node did not compute: 0;
  another ``rank_by``: (n − position) / n down the order of n grasps;
- a grasp outside the node's order (infeasible: IK or joint limits fail along the motion)
  has 0, and comes last (``moveit.infeasible: append``) or is left out (``drop``).
Each is a decreasing function of the key the order sorts by, so the answer's qualities never
increase down the list.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from grasp_safety_msgs.msg import GraspRanking
from moveit_msgs.msg import CollisionObject, Grasp
from nav_msgs.msg import Path
from std_msgs.msg import Header
from trajectory_msgs.msg import MultiDOFJointTrajectory

from ...core.exceptions import InvalidInputError
from ..conversions.geometry import (
    check_frame_id,
    duration_msg,
    duration_to_seconds,
    stamp_to_seconds,
)

_KEYS = {"safety": "safety_score", "effort": "effort_score", "whole_arm": "whole_arm_rank_force_n"}
"""The evaluation field each rank_by orders by, lowest first."""


def pose_array_of_grasps(grasps: Sequence[Grasp], field: str) -> PoseArray:
    """The grasps' ``grasp_pose`` poses as one PoseArray; every ``grasp_pose`` must share one
    ``header.frame_id`` (the node then accepts its object frame or base frame)."""
    if not grasps:
        raise InvalidInputError(field, "is empty; give at least one grasp")
    frame = grasps[0].grasp_pose.header.frame_id
    for i, grasp in enumerate(grasps):
        if grasp.grasp_pose.header.frame_id != frame:
            raise InvalidInputError(
                f"{field}[{i}].grasp_pose.header.frame_id",
                f"must be the frame of {field}[0] ({frame!r}), got "
                f"{grasp.grasp_pose.header.frame_id!r}: give every grasp in one frame",
            )
    return PoseArray(header=Header(frame_id=frame), poses=[g.grasp_pose.pose for g in grasps])


def planner_qualities(grasps: Sequence[Grasp]) -> tuple[float, ...] | None:
    """The grasps' ``grasp_quality`` for the quality weighting: a non-finite value counts as
    the lowest finite one of the set (the planner gave no usable quality: not preferred);
    None when no value is finite."""
    values = [g.grasp_quality for g in grasps]
    finite = [q for q in values if math.isfinite(q)]
    if not finite:
        return None
    lowest = min(finite)
    return tuple(q if math.isfinite(q) else lowest for q in values)


def object_path(target: CollisionObject, base_frame: str, goal: Pose, duration_s: float) -> Path:
    """The object's motion: from the target's pose (``target.pose`` in
    ``target.header.frame_id``, which must be ``base_frame``) to ``goal`` (base frame) in
    ``duration_s`` (0: the node's ``trajectory.duration_s``)."""
    if target.header.frame_id != base_frame:
        raise InvalidInputError(
            "target.header.frame_id",
            f"must be the node's base_frame {base_frame!r} (the object's start pose is "
            f"target.pose in it), got {target.header.frame_id!r}",
        )
    end = duration_msg(duration_s)
    header = Header(frame_id=base_frame)
    return Path(
        header=header,
        poses=[
            PoseStamped(header=header, pose=target.pose),
            PoseStamped(
                header=Header(frame_id=base_frame, stamp=Time(sec=end.sec, nanosec=end.nanosec)),
                pose=goal,
            ),
        ],
    )


def goal_pose(values: Sequence[float]) -> Pose:
    """The Pose of a ``moveit.object_goal`` parameter: x y z [m] qx qy qz qw, base frame."""
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in values[:3])
    q = pose.orientation
    q.x, q.y, q.z, q.w = (float(v) for v in values[3:])
    return pose


def trajectory_goal(
    latest: Path | MultiDOFJointTrajectory | None, base_frame: str
) -> tuple[Pose, float] | None:
    """The last pose of an object trajectory (``base_frame``: its frame must be this one) and
    its duration [s], or None for no trajectory or one without poses."""
    if isinstance(latest, Path) and latest.poses:
        field = "object_trajectory"
        check_frame_id(latest.header.frame_id, [base_frame], f"{field}.header.frame_id")
        first, last = latest.poses[0], latest.poses[-1]
        if last.header.frame_id:
            index = len(latest.poses) - 1
            check_frame_id(last.header.frame_id, [base_frame], f"{field}.poses[{index}].header")
        duration = stamp_to_seconds(last.header.stamp) - stamp_to_seconds(first.header.stamp)
        return last.pose, max(duration, 0.0)
    if isinstance(latest, MultiDOFJointTrajectory) and latest.points:
        field = "object_multi_dof_trajectory"
        check_frame_id(latest.header.frame_id, [base_frame], f"{field}.header.frame_id")
        first, last = latest.points[0], latest.points[-1]
        if len(last.transforms) != 1:
            raise InvalidInputError(
                f"{field}.points[{len(latest.points) - 1}].transforms",
                f"must hold exactly one transform (the object), got {len(last.transforms)}",
            )
        end = last.transforms[0]
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = (
            end.translation.x,
            end.translation.y,
            end.translation.z,
        )
        pose.orientation = end.rotation
        duration = duration_to_seconds(last.time_from_start) - duration_to_seconds(
            first.time_from_start
        )
        return pose, max(duration, 0.0)
    return None


def safety_qualities(ranking: GraspRanking) -> dict[int, float]:
    """{candidate index: safety quality} of the grasps in ``ranking.order`` (module
    docstring)."""
    if not math.isnan(ranking.safety_weight) and ranking.rank_by == "safety":
        return {k: ranking.evaluations[k].combined_score for k in ranking.order}
    key = _KEYS.get(ranking.rank_by)
    if key is None:  # an order this module does not know the key of: by position
        count = len(ranking.order)
        return {k: (count - position) / count for position, k in enumerate(ranking.order)}
    qualities = {}
    for k in ranking.order:
        value = getattr(ranking.evaluations[k], key)
        qualities[k] = 0.0 if math.isnan(value) else 1.0 / (1.0 + value)
    return qualities


def ranked_grasps(grasps: Sequence[Grasp], ranking: GraspRanking, infeasible: str) -> list[Grasp]:
    """The grasps in ``ranking.order`` (safest first), each with its safety quality, then
    (``infeasible`` = ``append``) the others in their given order with quality 0; ``id`` and
    every other field as given."""
    qualities = safety_qualities(ranking)
    order = list(ranking.order)
    if infeasible == "append":
        order += [k for k in range(len(grasps)) if k not in qualities]
    answer = []
    for k in order:
        grasp = _copy(grasps[k])
        grasp.grasp_quality = qualities.get(k, 0.0)
        answer.append(grasp)
    return answer


def _copy(grasp: Grasp) -> Grasp:
    """A shallow copy of a Grasp message (its fields shared, the quality its own)."""
    return Grasp(**{name: getattr(grasp, name) for name in Grasp.get_fields_and_field_types()})
