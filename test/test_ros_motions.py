"""The node over real rclpy with real motions: a Path of 3+ timed poses, a
MultiDOFJointTrajectory of the object (service and topic), planned joint trajectories per
grasp; every bad input answered success=false naming the field."""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import PoseArray, PoseStamped, Quaternion, Transform, Vector3
from grasp_safety_msgs.msg import GraspRanking
from grasp_safety_msgs.srv import RankGrasps
from nav_msgs.msg import Path
from ros_node_harness import (
    BOOK,
    BOOK_GRASPS,
    DT_S,
    LATCHED,
    NODE_PARAMETERS,
    NodeUnderTest,
    _localhost_only,  # noqa: F401  (autouse fixture: localhost discovery, log dir)
    assert_matches_core,
    book_request,
)
from std_msgs.msg import Header
from trajectory_msgs.msg import (
    JointTrajectory,
    JointTrajectoryPoint,
    MultiDOFJointTrajectory,
    MultiDOFJointTrajectoryPoint,
)

from grasp_safety_ros.core import Grasp, GraspSafetyEvaluator
from grasp_safety_ros.core.input_checks import pose_from_position_quat
from grasp_safety_ros.core.method.joint_trajectory import PlannedJointTrajectory
from grasp_safety_ros.core.model.waypoint_trajectory import WaypointTrajectory
from grasp_safety_ros.ros.conversions import pose_msg_from_transform, quaternion_msg_from_rotation

WAYPOINT_TIMES_S = (0.0, 1.2, 2.5)
WAYPOINT_POSES = (
    pose_from_position_quat([1.0, 0.0, 0.03], [0.5, 0.5, 0.5, 0.5], "w0"),
    pose_from_position_quat([1.05, -0.2, 0.12], [0.419666, 0.569105, 0.569105, 0.419666], "w1"),
    pose_from_position_quat([1.1, -0.38, 0.16], [0.5, 0.5, 0.5, 0.5], "w2"),
)


@pytest.fixture(scope="module")
def ros() -> Iterator[NodeUnderTest]:
    harness = NodeUnderTest(NODE_PARAMETERS)
    yield harness
    harness.close()


def _time(seconds: float, kind: type) -> Any:
    sec = math.floor(seconds)
    return kind(sec=sec, nanosec=round((seconds - sec) * 1e9))


def waypoint_path(offset_s: float = 100.0) -> Path:
    """The waypoints as a Path; stamps absolute (only differences matter)."""
    return Path(
        header=Header(frame_id="base"),
        poses=[
            PoseStamped(
                header=Header(stamp=_time(offset_s + t, Time)), pose=pose_msg_from_transform(p)
            )
            for t, p in zip(WAYPOINT_TIMES_S, WAYPOINT_POSES, strict=True)
        ],
    )


def waypoint_multi_dof() -> MultiDOFJointTrajectory:
    points = []
    for t, pose in zip(WAYPOINT_TIMES_S, WAYPOINT_POSES, strict=True):
        x, y, z = (float(v) for v in pose.translation)
        transform = Transform(
            translation=Vector3(x=x, y=y, z=z),
            rotation=quaternion_msg_from_rotation(pose.rotation),
        )
        points.append(
            MultiDOFJointTrajectoryPoint(
                transforms=[transform], time_from_start=_time(t, Duration)
            )
        )
    return MultiDOFJointTrajectory(
        header=Header(frame_id="base"), joint_names=["object"], points=points
    )


def waypoint_request(multi_dof: bool = False) -> RankGrasps.Request:
    request = book_request()
    if multi_dof:
        request.object_trajectory = Path()
        request.object_multi_dof_trajectory = waypoint_multi_dof()
    else:
        request.object_trajectory = waypoint_path()
    return request


@pytest.fixture(scope="module")
def waypoint_trajectory() -> WaypointTrajectory:
    return WaypointTrajectory(WAYPOINT_TIMES_S, WAYPOINT_POSES, DT_S)


@pytest.fixture(scope="module")
def core_waypoint_ranking(
    core_evaluator: GraspSafetyEvaluator,
    waypoint_trajectory: WaypointTrajectory,
) -> Any:
    return core_evaluator.rank(
        BOOK_GRASPS, BOOK.object_inertia, waypoint_trajectory, BOOK.robot.seed, "mean"
    )


def test_path_with_three_poses_equals_core(ros: NodeUnderTest, core_waypoint_ranking) -> None:
    response = ros.rank(waypoint_request())
    assert response.success, response.message
    assert_matches_core(response.ranking, core_waypoint_ranking)
    times = list(response.ranking.evaluations[0].time_from_start_s)
    assert len(times) == 26 and min(abs(t - 1.2) for t in times) < 1e-9


def test_multi_dof_trajectory_equals_the_path(ros: NodeUnderTest, core_waypoint_ranking) -> None:
    response = ros.rank(waypoint_request(multi_dof=True))
    assert response.success, response.message
    assert_matches_core(response.ranking, core_waypoint_ranking)


def planned_message(positions: np.ndarray, times: np.ndarray, names: list[str]) -> JointTrajectory:
    return JointTrajectory(
        joint_names=names,
        points=[
            JointTrajectoryPoint(
                positions=[float(v) for v in row], time_from_start=_time(float(t), Duration)
            )
            for row, t in zip(positions, times, strict=True)
        ],
    )


def test_joint_trajectories_per_grasp(
    ros: NodeUnderTest,
    core_evaluator: GraspSafetyEvaluator,
    core_waypoint_ranking,
    waypoint_trajectory: WaypointTrajectory,
) -> None:
    """Grasp 1 brings the IK's joint trajectory (shuffled columns, an extra joint), grasps 0
    and 2 send empty entries (IK): the node evaluates exactly what the core does."""
    ik = core_waypoint_ranking.evaluations[1]
    names = [*list(core_evaluator.robot.joint_names)[::-1], "head_pan"]
    positions = np.column_stack([ik.joint_positions[:, ::-1], np.zeros(len(ik.times_s))])
    request = waypoint_request()
    request.joint_trajectories = [
        JointTrajectory(),
        planned_message(positions, ik.times_s, names),
        JointTrajectory(),
    ]
    response = ros.rank(request)
    assert response.success, response.message
    planned = PlannedJointTrajectory(tuple(names), ik.times_s, positions)
    grasps = list(BOOK_GRASPS)
    grasps[1] = Grasp(grasps[1].transform_tip_to_object, grasps[1].name, planned)
    expected = core_evaluator.rank(
        grasps, BOOK.object_inertia, waypoint_trajectory, BOOK.robot.seed, "mean"
    )
    assert_matches_core(response.ranking, expected)
    got = response.ranking.evaluations
    np.testing.assert_allclose(
        got[0].effective_mass_kg, core_waypoint_ranking.evaluations[0].effective_mass_kg, rtol=1e-9
    )
    # The planned grasp moves the arm as sent; between the ends its masses follow the IK's
    # (same configurations, directions from the spline's joint velocities). At the ends the
    # not-a-knot spline through positions alone is not at rest, unlike the path.
    np.testing.assert_allclose(np.array(got[1].time_from_start_s), ik.times_s, atol=1e-9)
    np.testing.assert_allclose(
        np.array(got[1].effective_mass_kg)[1:-1], ik.effective_mass_kg[1:-1], rtol=1e-2
    )


def test_multi_dof_on_the_topic_is_ranked(ros: NodeUnderTest, core_waypoint_ranking) -> None:
    received: list[GraspRanking] = []
    subscription = ros.client.create_subscription(
        GraspRanking, "/grasp_safety/ranking", received.append, LATCHED
    )
    trajectory_pub = ros.client.create_publisher(
        MultiDOFJointTrajectory, "/grasp_safety/object_multi_dof_trajectory", 10
    )
    grasps_pub = ros.client.create_publisher(PoseArray, "/grasp_safety/candidate_grasps", 10)
    try:
        assert ros.spin_until(
            lambda: min(p.get_subscription_count() for p in (trajectory_pub, grasps_pub)) > 0
        )
        now = ros.node.get_clock().now().nanoseconds
        trajectory_pub.publish(waypoint_multi_dof())
        time.sleep(0.2)
        grasps_pub.publish(book_request().grasps)

        def fresh() -> list[GraspRanking]:
            return [
                r for r in received if r.header.stamp.sec * 10**9 + r.header.stamp.nanosec > now
            ]

        assert ros.spin_until(lambda: bool(fresh()), timeout_s=20.0)
        assert_matches_core(fresh()[0], core_waypoint_ranking)
    finally:
        ros.client.destroy_subscription(subscription)
        ros.client.destroy_publisher(trajectory_pub)
        ros.client.destroy_publisher(grasps_pub)


def _set(obj: Any, **values: Any) -> None:
    for key, value in values.items():
        setattr(obj, key, value)


def _joint(request: RankGrasps.Request, **changes: Any) -> None:
    """Give grasp 1 a planned trajectory (3 points at the seed), then apply ``changes``."""
    seed = np.array(BOOK.robot.seed)
    names = [f"right_{j}" for j in ("s0", "s1", "e0", "e1", "w0", "w1", "w2")]
    message = planned_message(np.tile(seed, (3, 1)), np.array([0.0, 0.5, 1.0]), names)
    for key, value in changes.items():
        value(message) if key == "edit" else setattr(message, key, value)
    request.joint_trajectories = [JointTrajectory(), message, JointTrajectory()]


def _point(message: JointTrajectory, k: int) -> JointTrajectoryPoint:
    return message.points[k]


BAD_REQUESTS: dict[str, tuple[Callable[[RankGrasps.Request], None], str]] = {
    "path_repeated_stamp": (
        lambda r: _set(
            r.object_trajectory.poses[2].header, stamp=r.object_trajectory.poses[1].header.stamp
        ),
        r"^object_trajectory\.poses\[2\]\.header\.stamp: times must increase strictly; equal",
    ),
    "path_unsorted_stamps": (
        lambda r: _set(r.object_trajectory.poses[1].header, stamp=Time(sec=200)),
        r"^object_trajectory\.poses\[2\]\.header\.stamp: times must increase strictly",
    ),
    "path_one_pose": (
        lambda r: _set(r.object_trajectory, poses=r.object_trajectory.poses[:1]),
        r"^object_trajectory\.poses: has 1 pose; at least 2",
    ),
    "path_non_finite": (
        lambda r: _set(r.object_trajectory.poses[1].pose.position, y=math.nan),
        r"^object_trajectory\.poses\[1\]\.pose\.position: must be finite",
    ),
    "path_too_many_samples": (
        lambda r: _set(r.object_trajectory.poses[2].header, stamp=Time(sec=100_000)),
        r"^object_trajectory\.poses: .* at most max_samples=",
    ),
    "path_and_multi_dof": (
        lambda r: _set(r, object_multi_dof_trajectory=waypoint_multi_dof()),
        r"^object_multi_dof_trajectory: give the object trajectory once",
    ),
    "multi_dof_two_joints": (
        lambda r: (
            _set(r, object_trajectory=Path(), object_multi_dof_trajectory=waypoint_multi_dof()),
            _set(r.object_multi_dof_trajectory, joint_names=["object", "other"]),
        ),
        r"^object_multi_dof_trajectory\.joint_names: must name exactly one joint",
    ),
    "multi_dof_no_transform": (
        lambda r: (
            _set(r, object_trajectory=Path(), object_multi_dof_trajectory=waypoint_multi_dof()),
            _set(r.object_multi_dof_trajectory.points[1], transforms=[]),
        ),
        r"^object_multi_dof_trajectory\.points\[1\]\.transforms: must hold exactly one",
    ),
    "multi_dof_repeated_time": (
        lambda r: (
            _set(r, object_trajectory=Path(), object_multi_dof_trajectory=waypoint_multi_dof()),
            _set(
                r.object_multi_dof_trajectory.points[2],
                time_from_start=Duration(sec=1, nanosec=200_000_000),
            ),
        ),
        r"^object_multi_dof_trajectory\.points\[2\]\.time_from_start: times must increase",
    ),
    "multi_dof_bad_quaternion": (
        lambda r: (
            _set(r, object_trajectory=Path(), object_multi_dof_trajectory=waypoint_multi_dof()),
            _set(
                r.object_multi_dof_trajectory.points[0].transforms[0], rotation=Quaternion(w=0.0)
            ),
        ),
        r"^object_multi_dof_trajectory\.points\[0\]\.transforms\[0\]\.rotation: must be a unit",
    ),
    "multi_dof_wrong_frame": (
        lambda r: (
            _set(r, object_trajectory=Path(), object_multi_dof_trajectory=waypoint_multi_dof()),
            _set(r.object_multi_dof_trajectory.header, frame_id="map"),
        ),
        r"^object_multi_dof_trajectory\.header\.frame_id: unknown frame_id 'map'",
    ),
    "joint_trajectories_count": (
        lambda r: _set(r, joint_trajectories=[JointTrajectory()]),
        r"^joint_trajectories: must have one entry per grasp \(3\) or none, got 1",
    ),
    "joint_missing_chain_joint": (
        lambda r: _joint(r, edit=lambda m: _set(m, joint_names=[*m.joint_names[:6], "head_pan"])),
        r"^joint_trajectories\[1\]\.joint_names: missing chain joint\(s\) right_w2",
    ),
    "joint_limit": (
        lambda r: _joint(r, edit=lambda m: _point(m, 2).positions.__setitem__(1, 5.0)),
        r"^joint_trajectories\[1\]\.points\[2\]\.positions: joint 'right_s1' = 5 is outside",
    ),
    "joint_time_not_increasing": (
        lambda r: _joint(r, edit=lambda m: _set(_point(m, 2), time_from_start=Duration(sec=0))),
        r"^joint_trajectories\[1\]\.points\[2\]\.time_from_start: must be > points\[1\]",
    ),
    "joint_non_finite": (
        lambda r: _joint(r, edit=lambda m: _point(m, 1).positions.__setitem__(0, math.inf)),
        r"^joint_trajectories\[1\]\.points\[1\]\.positions: must be finite",
    ),
    "joint_positions_short": (
        lambda r: _joint(r, edit=lambda m: _set(_point(m, 0), positions=[0.0, 0.0])),
        r"^joint_trajectories\[1\]\.points\[0\]\.positions: must have shape \[7\]",
    ),
    "joint_one_point": (
        lambda r: _joint(r, edit=lambda m: _set(m, points=m.points[:1])),
        r"^joint_trajectories\[1\]\.points: needs at least 2 points, got 1",
    ),
    "joint_some_velocities": (
        lambda r: _joint(r, edit=lambda m: _set(_point(m, 1), velocities=[0.0] * 7)),
        r"^joint_trajectories\[1\]\.points\[\d\]\.velocities: give velocities for every point",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_REQUESTS))
def test_bad_motion_request_is_refused_then_good_request_succeeds(
    ros: NodeUnderTest, core_waypoint_ranking: Any, case: str
) -> None:
    mutate, pattern = BAD_REQUESTS[case]
    request = waypoint_request()
    mutate(request)
    response = ros.rank(request)
    assert not response.success
    assert re.search(pattern, response.message), response.message
    assert response.ranking.evaluations == []
    good = ros.rank(waypoint_request())
    assert good.success, good.message
    assert tuple(good.ranking.order) == core_waypoint_ranking.order
