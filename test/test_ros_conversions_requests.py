"""ros.conversions.geometry and .requests (no rclpy context): quaternion order, pose and
trajectory round trips, grasps, inertia and joint states from messages, and their refusals."""

from __future__ import annotations

import copy
import math
import warnings

import numpy as np
import pinocchio as pin
import pytest
from builtin_interfaces.msg import Duration, Time
from conftest import random_rotation
from geometry_msgs.msg import (
    Inertia,
    Point,
    Pose,
    PoseArray,
    PoseStamped,
    Quaternion,
    Transform,
    Vector3,
)
from hypothesis import given, settings
from hypothesis import strategies as st
from nav_msgs.msg import Path
from std_msgs.msg import Header
from trajectory_msgs.msg import (
    MultiDOFJointTrajectory,
    MultiDOFJointTrajectoryPoint,
)

from grasp_safety_ros.core import (
    InvalidInputError,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.model.waypoint_trajectory import WaypointTrajectory
from grasp_safety_ros.ros import conversions
from grasp_safety_ros.ros.conversions import (
    check_grasp_array,
    grasps_from_pose_array,
    inertia_msg_from_object,
    object_inertia_from_msg,
    pose_msg_from_transform,
    quat_xyzw_from_msg,
    seed_from_joint_state,
    trajectory_from_multi_dof,
    trajectory_from_path,
    transform_from_pose_msg,
    transforms_from_pose_msgs,
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


def test_huge_quaternion_is_refused_without_a_warning() -> None:
    """A component near the float limit overflows the norm: refused, and numpy prints nothing
    (found by test_cli_fuzz)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InvalidInputError, match=r"^g\.orientation: .* got norm inf$"):
            transform_from_pose_msg(pose((0, 0, 0), (1e269, 1e269, 0, 0)), "g")
        with pytest.raises(InvalidInputError, match=r"^g\[1\]\.orientation: .* got norm inf$"):
            conversions.transforms_from_pose_msgs(
                [pose(*START), pose((0, 0, 0), (1e269, 1e269, 0, 0))], "g"
            )


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
        (path(poses=[]), r"^traj\.poses: has 0 poses; at least 2"),
        (path(poses=[START]), r"^traj\.poses: has 1 pose; at least 2"),
        (
            path(poses=[START, GOAL, START]),
            r"^traj\.poses\[1\]\.header\.stamp: times must increase strictly; equal times",
        ),
        (
            path([Time(sec=3), Time(sec=1)]),
            r"^traj\.poses\[1\]\.header\.stamp: times must increase strictly: -2",
        ),
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


def test_poses_checked_at_once_equal_pose_by_pose() -> None:
    rng = np.random.default_rng(5)
    poses = []
    for _ in range(30):
        quat = rng.normal(size=4)
        quat *= (1.0 + rng.uniform(-9e-4, 9e-4)) / np.linalg.norm(quat)  # near-unit too
        poses.append(pose(tuple(rng.uniform(-2, 2, 3)), tuple(quat)))
    batch = transforms_from_pose_msgs(poses, "grasps.poses")
    for got, message in zip(batch, poses, strict=True):
        want = transform_from_pose_msg(message, "grasps.poses[k]")
        assert np.array_equal(got.rotation, want.rotation)
        assert np.array_equal(got.translation, want.translation)
    bad_values = {
        ("orientation", "w"): [math.nan, 2.0, 0.0],
        ("position", "x"): [math.inf, 1e300, -1001.0],
    }
    for (part, axis), values in bad_values.items():
        for value in values:
            broken = [copy.deepcopy(p) for p in poses]
            setattr(getattr(broken[7], part), axis, value)
            with pytest.raises(InvalidInputError) as batch_error:
                transforms_from_pose_msgs(broken, "grasps.poses")
            with pytest.raises(InvalidInputError) as single_error:
                transform_from_pose_msg(broken[7], "grasps.poses[7]")
            assert str(batch_error.value) == str(single_error.value)


def test_object_com_far_away_is_refused() -> None:
    inertia = Inertia(m=0.3, ixx=1e-3, iyy=1e-3, izz=1e-3)
    inertia.com.x = 1e300  # finite, but the effective masses would be NaN
    with pytest.raises(InvalidInputError, match=r"^object_inertia\.com: must be within"):
        object_inertia_from_msg(inertia, 1000.0)
    inertia.com.x = 0.5
    assert object_inertia_from_msg(inertia, 1000.0).com_in_object_m[0] == 0.5


def test_path_with_three_poses_is_a_waypoint_trajectory() -> None:
    middle = ((1.05, -0.2, 0.12), (0.5, 0.5, 0.5, 0.5))
    stamps = [Time(sec=7), Time(sec=8, nanosec=200_000_000), Time(sec=9, nanosec=500_000_000)]
    trajectory = to_trajectory(path(stamps, poses=[START, middle, GOAL]))
    assert isinstance(trajectory, WaypointTrajectory)
    np.testing.assert_allclose(trajectory.waypoint_times_s, [0.0, 1.2, 2.5], atol=1e-9)
    np.testing.assert_allclose(trajectory.transforms_object_to_base[1].translation, middle[0])


def test_multi_dof_trajectory_equals_the_path() -> None:
    points = [
        MultiDOFJointTrajectoryPoint(
            transforms=[
                Transform(
                    translation=Vector3(x=p[0][0], y=p[0][1], z=p[0][2]),
                    rotation=Quaternion(x=p[1][0], y=p[1][1], z=p[1][2], w=p[1][3]),
                )
            ],
            time_from_start=Duration(sec=sec),
        )
        for p, sec in ((START, 1), (GOAL, 3))
    ]
    message = MultiDOFJointTrajectory(
        header=Header(frame_id="base"), joint_names=["book"], points=points
    )
    trajectory = trajectory_from_multi_dof(message, "base", 0.1, 5.0, 20000)
    expected = to_trajectory(path([Time(sec=1), Time(sec=3)]))
    assert trajectory.duration_s == expected.duration_s == 2.0
    np.testing.assert_array_equal(trajectory.times_s(), expected.times_s())
    for a, b in zip(
        trajectory.object_poses(expected.times_s()),
        expected.object_poses(expected.times_s()),
        strict=True,
    ):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-15)
