"""Message <-> core conversions (no rclpy context): quaternion order, round trips, refusals."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from builtin_interfaces.msg import Time
from conftest import random_rotation
from geometry_msgs.msg import Inertia, Point, Pose, PoseArray, PoseStamped, Quaternion, Vector3
from hypothesis import given, settings
from hypothesis import strategies as st
from nav_msgs.msg import Path
from std_msgs.msg import Header
from visualization_msgs.msg import Marker

from grasp_safety_ros.core import (
    Grasp,
    GraspSafetyEvaluator,
    InvalidInputError,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.ranking import GraspEvaluation, Ranking
from grasp_safety_ros.ros.conversions import (
    check_grasp_array,
    grasps_from_pose_array,
    inertia_msg_from_object,
    markers_msg,
    object_inertia_from_msg,
    pose_msg_from_transform,
    quat_xyzw_from_msg,
    rank_color,
    ranking_msg,
    seed_from_joint_state,
    trajectory_from_path,
    transform_from_pose_msg,
)


def pose(xyz: tuple[float, float, float], xyzw: tuple[float, float, float, float]) -> Pose:
    return Pose(
        position=Point(x=xyz[0], y=xyz[1], z=xyz[2]),
        orientation=Quaternion(x=xyzw[0], y=xyzw[1], z=xyzw[2], w=xyzw[3]),
    )


IDENTITY = (0.0, 0.0, 0.0, 1.0)


# --- Poses -------------------------------------------------------------------------------------


def test_quaternion_order_is_x_y_z_w() -> None:
    half = math.sqrt(0.5)
    about_z = transform_from_pose_msg(pose((1.0, 2.0, 3.0), (0.0, 0.0, half, half)), "p")
    np.testing.assert_allclose(
        about_z.rotation, pin.rpy.rpyToMatrix(0, 0, math.pi / 2), atol=1e-15
    )
    np.testing.assert_allclose(about_z.translation, [1.0, 2.0, 3.0])
    about_x = transform_from_pose_msg(pose((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)), "p")
    np.testing.assert_allclose(about_x.rotation, np.diag([1.0, -1.0, -1.0]), atol=1e-15)
    message = pose_msg_from_transform(about_z)
    np.testing.assert_allclose(quat_xyzw_from_msg(message.orientation), [0, 0, half, half])


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_pose_round_trip(seed: int) -> None:
    rng = np.random.default_rng(seed)
    transform = pin.SE3(random_rotation(rng), rng.uniform(-2, 2, 3))
    back = transform_from_pose_msg(pose_msg_from_transform(transform), "p")
    np.testing.assert_allclose(back.rotation, transform.rotation, atol=1e-14)
    np.testing.assert_allclose(back.translation, transform.translation, atol=0)
    assert pose_msg_from_transform(transform).orientation.w >= 0.0


def test_near_unit_quaternion_is_normalised() -> None:
    transform = transform_from_pose_msg(pose((0, 0, 0), (0.0, 0.0, 0.0, 1.0005)), "p")
    np.testing.assert_allclose(transform.rotation, np.eye(3), atol=1e-15)


@pytest.mark.parametrize(
    ("xyz", "xyzw", "pattern"),
    [
        ((math.nan, 0, 0), IDENTITY, r"^g\.position: must be finite"),
        ((0, math.inf, 0), IDENTITY, r"^g\.position: must be finite"),
        ((0, 0, 0), (0, 0, 0, 0), r"^g\.orientation: must be a unit quaternion .* got norm 0$"),
        ((0, 0, 0), (0, 0, 0, 2.0), r"^g\.orientation: must be a unit quaternion .* norm 2$"),
        ((0, 0, 0), (0, math.nan, 0, 1.0), r"^g\.orientation: must be finite"),
    ],
)
def test_bad_pose_is_refused(xyz: tuple, xyzw: tuple, pattern: str) -> None:
    with pytest.raises(InvalidInputError, match=pattern):
        transform_from_pose_msg(pose(xyz, xyzw), "g")


# --- Trajectory --------------------------------------------------------------------------------

START = ((1.0, 0.0, 0.03), (0.5, 0.5, 0.5, 0.5))
GOAL = ((1.1, -0.38, 0.16), (0.5, 0.5, 0.5, 0.5))


def path(stamps: list[Time] | None = None, frame: str = "base", poses: list | None = None) -> Path:
    poses = poses if poses is not None else [START, GOAL]
    stamps = stamps if stamps is not None else [Time()] * len(poses)
    return Path(
        header=Header(frame_id=frame),
        poses=[
            PoseStamped(header=Header(stamp=stamp), pose=pose(*p))
            for stamp, p in zip(stamps, poses, strict=True)
        ],
    )


def to_trajectory(message: Path, max_samples: int = 20000) -> ObjectTrajectory:
    return trajectory_from_path(message, "base", 0.1, 2.0, max_samples)


def test_trajectory_duration_from_stamps_or_parameter() -> None:
    timed = to_trajectory(path([Time(sec=10, nanosec=500_000_000), Time(sec=13)]))
    assert timed.duration_s == pytest.approx(2.5, abs=1e-9)
    assert timed.num_samples == 26
    untimed = to_trajectory(path())
    assert untimed.duration_s == 2.0
    np.testing.assert_allclose(untimed.transform_object_to_base_start.translation, START[0])
    np.testing.assert_allclose(untimed.transform_object_to_base_goal.translation, GOAL[0])


@pytest.mark.parametrize(
    ("message", "pattern"),
    [
        (path(frame="world"), r"^traj\.header\.frame_id: unknown frame_id 'world'; accepted: 'ba"),
        (path(frame=""), r"^traj\.header\.frame_id: unknown frame_id ''"),
        (path(poses=[]), r"^traj\.poses: has 0 poses; exactly 2"),
        (path(poses=[START]), r"^traj\.poses: has 1 pose; exactly 2"),
        (path(poses=[START, GOAL, START]), r"^traj\.poses: has 3 poses; exactly 2"),
        (path([Time(sec=3), Time(sec=1)]), r"^traj\.poses: stamps are not in order"),
        (path([Time(sec=0), Time(nanosec=50_000_000)]), r"duration 0.05 s is shorter than"),
        (path([Time(sec=0), Time(sec=10_000)]), r"gives 100001 samples; at most max_samples="),
        (path(poses=[START, ((0, 0, 0), (0, 0, 0, 0))]), r"^traj\.poses\[1\]\.pose\.orientation"),
    ],
)
def test_bad_path_is_refused(message: Path, pattern: str) -> None:
    with pytest.raises(InvalidInputError, match=pattern):
        trajectory_from_path(message, "base", 0.1, 2.0, 20000, field="traj")


def test_pose_frame_in_path_must_be_base_or_empty() -> None:
    message = path()
    message.poses[0].header.frame_id = "base"
    to_trajectory(message)
    message.poses[1].header.frame_id = "map"
    with pytest.raises(InvalidInputError, match=r"poses\[1\]\.header: unknown frame_id 'map'"):
        to_trajectory(message)


# --- Grasps ------------------------------------------------------------------------------------


def test_grasps_in_base_frame_are_moved_to_the_object_frame() -> None:
    trajectory = to_trajectory(path())
    rng = np.random.default_rng(3)
    in_object = [pin.SE3(random_rotation(rng), rng.uniform(-0.1, 0.1, 3)) for _ in range(4)]
    start = trajectory.transform_object_to_base_start
    base_msg = PoseArray(
        header=Header(frame_id="base"),
        poses=[pose_msg_from_transform(start * g) for g in in_object],
    )
    object_msg = PoseArray(
        header=Header(frame_id="object"), poses=[pose_msg_from_transform(g) for g in in_object]
    )
    from_base = grasps_from_pose_array(base_msg, "object", "base", trajectory, 10)
    from_object = grasps_from_pose_array(object_msg, "object", "base", trajectory, 10)
    for a, b, want in zip(from_base, from_object, in_object, strict=True):
        assert a.name == b.name
        np.testing.assert_allclose(
            a.transform_tip_to_object.homogeneous, want.homogeneous, atol=1e-14
        )
        np.testing.assert_allclose(
            b.transform_tip_to_object.homogeneous, want.homogeneous, atol=1e-14
        )


def test_bad_grasp_arrays_are_refused() -> None:
    good = [pose((0.0, 0.0, 0.0), IDENTITY)]
    with pytest.raises(InvalidInputError, match=r"^c\.header\.frame_id: unknown frame_id 'tool'"):
        check_grasp_array(PoseArray(header=Header(frame_id="tool"), poses=good), "o", "b", 5, "c")
    with pytest.raises(InvalidInputError, match=r"^c\.poses: is empty"):
        check_grasp_array(PoseArray(header=Header(frame_id="o")), "o", "b", 5, "c")
    with pytest.raises(InvalidInputError, match=r"^c\.poses: has 6 grasps; at most max_grasps=5"):
        check_grasp_array(PoseArray(header=Header(frame_id="o"), poses=good * 6), "o", "b", 5, "c")


# --- Inertia -----------------------------------------------------------------------------------


def test_inertia_round_trip_and_zero_mass() -> None:
    book = solid_box(0.34, [0.15, 0.22, 0.015], com_in_object_m=[0.01, -0.02, 0.0])
    back = object_inertia_from_msg(inertia_msg_from_object(book), 1000.0)
    assert back is not None and back.mass_kg == book.mass_kg
    np.testing.assert_array_equal(back.com_in_object_m, book.com_in_object_m)
    np.testing.assert_array_equal(back.inertia_about_com_kgm2, book.inertia_about_com_kgm2)
    assert object_inertia_from_msg(Inertia(), 1000.0) is None


def test_inertia_off_diagonal_order() -> None:
    message = Inertia(m=1.0, ixx=1.0, ixy=0.1, ixz=0.2, iyy=1.1, iyz=0.3, izz=1.2)
    inertia = object_inertia_from_msg(message, 1000.0)
    assert inertia is not None
    np.testing.assert_array_equal(
        inertia.inertia_about_com_kgm2, [[1.0, 0.1, 0.2], [0.1, 1.1, 0.3], [0.2, 0.3, 1.2]]
    )


@pytest.mark.parametrize(
    ("changes", "pattern"),
    [
        ({"m": -1.0}, r"^i\.m: must be in \(0, inf\], got -1"),
        ({"m": math.nan}, r"^i\.m: must be finite"),
        ({"m": 5000.0}, r"^i\.m: must be at most max_mass_kg=1000, got 5000"),
        ({"com": Vector3(x=math.inf)}, r"^i\.com: must be finite"),
        ({"izz": math.nan}, r"^i\.ixx\.\.izz: must be finite"),
        ({"ixx": 0.0}, r"^i\.ixx\.\.izz: must be positive definite"),
        ({"izz": 5.0}, r"^i\.ixx\.\.izz: principal moments must satisfy the triangle"),
    ],
)
def test_bad_inertia_is_refused(changes: dict, pattern: str) -> None:
    message = Inertia(m=1.0, ixx=1.0, iyy=1.0, izz=1.0)
    for key, value in changes.items():
        setattr(message, key, value)
    with pytest.raises(InvalidInputError, match=pattern):
        object_inertia_from_msg(message, 1000.0, field="i")


# --- Joint states ------------------------------------------------------------------------------


def test_seed_from_joint_state(arm6: RobotModel) -> None:
    names = list(arm6.joint_names)
    positions = [0.1 * (k + 1) for k in range(6)]
    shuffled = ["gripper", *reversed(names)]
    seed = seed_from_joint_state(shuffled, [0.0, *reversed(positions)], arm6)
    assert seed is not None
    np.testing.assert_allclose(seed, positions)
    assert seed_from_joint_state(names[:-1], positions[:-1], arm6) is None  # a joint missing
    assert seed_from_joint_state(names, positions[:-1], arm6) is None  # lengths differ
    assert seed_from_joint_state(names, [*positions[:-1], 5.0], arm6) is None  # outside limits
    assert seed_from_joint_state(names, [*positions[:-1], math.nan], arm6) is None


# --- Results -----------------------------------------------------------------------------------


def _ranking(arm6: RobotModel) -> tuple[Ranking, list[Grasp], ObjectTrajectory]:
    trajectory = ObjectTrajectory(
        pin.SE3(np.eye(3), np.array([0.3, 0.1, 0.4])),
        pin.SE3(np.eye(3), np.array([0.35, 0.05, 0.45])),
        1.0,
        0.25,
    )
    rng = np.random.default_rng(0)
    q = rng.uniform(-1, 1, 6)
    tip = arm6.transform_tip_to_base(q)
    grasps = [
        Grasp(trajectory.transform_object_to_base_start.actInv(tip), "near"),
        Grasp(
            pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.03]))
            * trajectory.transform_object_to_base_start.actInv(tip),
            "shifted",
        ),
        Grasp(pin.SE3(np.eye(3), np.array([5.0, 0.0, 0.0])), "unreachable"),
    ]
    evaluator = GraspSafetyEvaluator(arm6)
    ranking = evaluator.rank(grasps, solid_box(0.5, [0.1, 0.1, 0.1]), trajectory, q)
    return ranking, grasps, trajectory


def test_ranking_message(arm6: RobotModel) -> None:
    ranking, grasps, _ = _ranking(arm6)
    assert len(ranking.order) == 2 and not ranking.evaluations[2].feasible
    request = PoseArray(
        header=Header(frame_id="object", stamp=Time(sec=7)),
        poses=[pose_msg_from_transform(g.transform_tip_to_object) for g in grasps],
    )
    message = ranking_msg(ranking, request, "base_link", Time(sec=9), 0.25)
    assert message.header.frame_id == "base_link" and message.header.stamp.sec == 9
    assert list(message.order) == list(ranking.order)
    assert message.joint_names == list(arm6.joint_names)
    assert message.compute_time_s == 0.25
    assert message.ranked_grasps.header == request.header
    assert list(message.ranked_grasps.poses) == [request.poses[i] for i in ranking.order]
    for got, want in zip(message.evaluations, ranking.evaluations, strict=True):
        assert (got.index, got.name, got.feasible, got.reason) == (
            want.index,
            want.name,
            want.feasible,
            want.reason,
        )
        np.testing.assert_array_equal(got.effective_mass_kg, want.effective_mass_kg)
        np.testing.assert_array_equal(got.time_from_start_s, want.times_s)
        directions = np.array([[d.x, d.y, d.z] for d in got.direction]).reshape(-1, 3)
        np.testing.assert_array_equal(directions, want.directions_in_base)
        assert list(got.direction_is_worst_case) == want.direction_is_worst_case.tolist()
    unreachable = message.evaluations[2]
    assert math.isnan(unreachable.score) and math.isnan(unreachable.peak_effective_mass_kg)
    assert unreachable.reason and len(unreachable.effective_mass_kg) == 0


def test_markers(arm6: RobotModel) -> None:
    ranking, grasps, trajectory = _ranking(arm6)
    markers = markers_msg(ranking, grasps, trajectory, "base_link", Time(sec=1)).markers
    assert markers[0].action == Marker.DELETEALL
    added = markers[1:]
    assert all(m.header.frame_id == "base_link" and m.action == Marker.ADD for m in added)
    arrows = {m.id: m for m in added if m.type == Marker.ARROW}
    labels = {m.id: m for m in added if m.type == Marker.TEXT_VIEW_FACING}
    assert set(arrows) == set(labels) == {0, 1, 2}
    safest, least = ranking.order[0], ranking.order[-1]
    assert (arrows[safest].color.r, arrows[safest].color.g) == (0.0, 1.0)
    assert (arrows[least].color.r, arrows[least].color.g) == (1.0, 0.0)
    assert arrows[2].color.r == arrows[2].color.g == arrows[2].color.b == 0.5
    assert labels[safest].text.startswith(f"#1 {grasps[safest].name}: ")
    assert labels[2].text == "unreachable: infeasible"
    start = trajectory.transform_object_to_base_start
    for index, arrow in arrows.items():
        tip = (start * grasps[index].transform_tip_to_object).translation
        np.testing.assert_allclose([arrow.points[1].x, arrow.points[1].y, arrow.points[1].z], tip)


def test_rank_colors() -> None:
    assert rank_color(0, 1) == (0.0, 1.0, 0.0, 1.0)
    assert rank_color(0, 3) == (0.0, 1.0, 0.0, 1.0)
    assert rank_color(1, 3) == (0.5, 0.5, 0.0, 1.0)
    assert rank_color(2, 3) == (1.0, 0.0, 0.0, 1.0)


def test_infeasible_evaluation_fields_are_empty() -> None:
    evaluation = GraspEvaluation(
        index=0,
        name="g",
        feasible=False,
        reason="IK failed",
        score=float("nan"),
        times_s=np.empty(0),
        joint_positions=np.empty((0, 6)),
        directions_in_base=np.empty((0, 3)),
        effective_mass_kg=np.empty(0),
        direction_is_worst_case=np.empty(0, dtype=bool),
        tip_speed_m_s=np.empty(0),
        ik_iterations=np.empty(0, dtype=int),
    )
    ranking = Ranking(("j",), "mean", (), (evaluation,))
    message = ranking_msg(ranking, PoseArray(poses=[Pose()]), "b", Time(), 0.0)
    assert list(message.order) == [] and list(message.ranked_grasps.poses) == []
    assert message.evaluations[0].direction == []
