"""Request messages to core types: object trajectories, grasps, object inertia, IK seed.

Each function raises InvalidInputError naming the message field (e.g.
``grasps.poses[2].orientation``), so the node can answer with that message.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import pinocchio as pin
from geometry_msgs.msg import Inertia, Pose, PoseArray
from nav_msgs.msg import Path
from trajectory_msgs.msg import JointTrajectory, MultiDOFJointTrajectory

from ...core.exceptions import InvalidInputError
from ...core.input_checks import (
    MAX_ABS_POSITION_M,
    QUATERNION_NORM_TOLERANCE,
    check_within_reach,
    finite_array,
    finite_float,
)
from ...core.method.joint_trajectory import PlannedJointTrajectory
from ...core.method.ranking import Grasp
from ...core.model.inertia import ObjectInertia
from ...core.model.robot import RobotModel
from ...core.model.trajectory import ObjectTrajectory
from ...core.model.waypoint_trajectory import WaypointTrajectory
from .geometry import (
    _pose_numbers,
    check_frame_id,
    duration_to_seconds,
    inertia_tensor_from_components,
    stamp_to_seconds,
    transform_from_pose_msg,
    transform_from_transform_msg,
    vector3_msg,
)


def timed_trajectory(
    times_s: Sequence[float],
    poses: Sequence[pin.SE3],
    time_fields: Sequence[str],
    dt_s: float,
    default_duration_s: float,
    max_samples: int,
    field: str,
) -> ObjectTrajectory | WaypointTrajectory:
    """The object trajectory of timed poses (times as sent; only differences matter).

    Two poses: the quintic from the first to the second over their time difference, or
    ``default_duration_s`` when the times are equal. N >= 3: the waypoint trajectory through
    all of them (times strictly increasing). ``time_fields`` name each time in messages.
    """
    count = len(poses)
    if count < 2:
        raise InvalidInputError(
            field,
            f"has {count} pose{'s' if count != 1 else ''}; at least 2 (start, goal) are needed",
        )
    relative = [t - times_s[0] for t in times_s]
    for k in range(1, count):
        if (
            not math.isfinite(relative[k])
            or relative[k] < relative[k - 1]
            or (count > 2 and relative[k] == relative[k - 1])
        ):
            equal = "; equal times are allowed only for 2 poses" if count > 2 else ""
            raise InvalidInputError(
                time_fields[k],
                f"times must increase strictly{equal}: {relative[k]:.9f} s after the first "
                f"pose, previous {relative[k - 1]:.9f} s",
            )
    duration = relative[-1] if relative[-1] > 0 else default_duration_s
    if dt_s > duration:
        raise InvalidInputError(
            field, f"duration {duration:g} s is shorter than trajectory.dt_s={dt_s:g} s"
        )
    samples = math.ceil(duration / dt_s - 1e-9) + 1 + max(count - 2, 0)
    if samples > max_samples:
        raise InvalidInputError(
            field,
            f"duration {duration:g} s at trajectory.dt_s={dt_s:g} s gives {samples} samples; "
            f"at most max_samples={max_samples} are allowed",
        )
    if count == 2:
        return ObjectTrajectory(poses[0], poses[1], duration, dt_s)
    return WaypointTrajectory(tuple(relative), tuple(poses), dt_s)


def trajectory_from_path(
    path: Path,
    base_frame: str,
    dt_s: float,
    default_duration_s: float,
    max_samples: int,
    field: str = "object_trajectory",
) -> ObjectTrajectory | WaypointTrajectory:
    """The object trajectory of a nav_msgs/Path of N >= 2 object poses in the base frame.

    Two poses: the quintic from the first to the second; duration = stamp difference, or
    ``default_duration_s`` when the stamps are equal (e.g. both zero). N >= 3: timed waypoints
    at their stamps (strictly increasing), relative to the first (see ``timed_trajectory``).
    """
    check_frame_id(path.header.frame_id, [base_frame], f"{field}.header.frame_id")
    for i, stamped in enumerate(path.poses):
        if stamped.header.frame_id:
            check_frame_id(stamped.header.frame_id, [base_frame], f"{field}.poses[{i}].header")
    poses = transforms_from_pose_msgs([p.pose for p in path.poses], f"{field}.poses", ".pose")
    return timed_trajectory(
        [stamp_to_seconds(p.header.stamp) for p in path.poses],
        poses,
        [f"{field}.poses[{i}].header.stamp" for i in range(len(poses))],
        dt_s,
        default_duration_s,
        max_samples,
        f"{field}.poses",
    )


def trajectory_from_multi_dof(
    trajectory: MultiDOFJointTrajectory,
    base_frame: str,
    dt_s: float,
    default_duration_s: float,
    max_samples: int,
    field: str = "object_multi_dof_trajectory",
) -> ObjectTrajectory | WaypointTrajectory:
    """The object trajectory of a trajectory_msgs/MultiDOFJointTrajectory of the object.

    One joint (the object frame, any name), one transform per point: the object pose in the
    base frame (``header.frame_id``) at ``time_from_start``. Times as for a Path
    (``timed_trajectory``); the points' velocities and accelerations are not used (the
    interpolation through the poses is the waypoint trajectory's).
    """
    check_frame_id(trajectory.header.frame_id, [base_frame], f"{field}.header.frame_id")
    if len(trajectory.joint_names) != 1:
        raise InvalidInputError(
            f"{field}.joint_names",
            f"must name exactly one joint (the object), got {list(trajectory.joint_names)}",
        )
    poses = []
    for i, point in enumerate(trajectory.points):
        if len(point.transforms) != 1:
            raise InvalidInputError(
                f"{field}.points[{i}].transforms",
                f"must hold exactly one transform (the object), got {len(point.transforms)}",
            )
        poses.append(
            transform_from_transform_msg(point.transforms[0], f"{field}.points[{i}].transforms[0]")
        )
    return timed_trajectory(
        [duration_to_seconds(p.time_from_start) for p in trajectory.points],
        poses,
        [f"{field}.points[{i}].time_from_start" for i in range(len(poses))],
        dt_s,
        default_duration_s,
        max_samples,
        f"{field}.points",
    )


def _point_rows(rows: Sequence[Sequence[float]]) -> np.ndarray:
    """(N,) object array of the points' rows (each a list [rad or m, per second...]): the core
    checks them row by row, so a point with too few or too many values gets its error naming
    that point (numpy would refuse the ragged (N, K) array first)."""
    array = np.empty(len(rows), dtype=object)
    for k, row in enumerate(rows):
        array[k] = list(row)
    return array


def planned_from_joint_trajectory(
    trajectory: JointTrajectory, field: str
) -> PlannedJointTrajectory | None:
    """The planned joint trajectory of a trajectory_msgs/JointTrajectory; None when it has no
    points (IK for that grasp).

    Times are ``time_from_start`` (strictly increasing); ``velocities`` are used when every
    point has one per joint, ignored when every point has none; accelerations, given alike,
    are checked (finite, bounded by the joints' velocity limits), not used.
    Joint names may be in any order and include joints off the chain.
    """
    points = trajectory.points
    if not points:
        return None
    times = [duration_to_seconds(p.time_from_start) for p in points]
    for k in range(1, len(times)):
        if times[k] <= times[k - 1]:
            raise InvalidInputError(
                f"{field}.points[{k}].time_from_start",
                f"must be > points[{k - 1}].time_from_start={times[k - 1]:.9f} s (strictly "
                f"increasing), got {times[k]:.9f} s",
            )
    rates: dict[str, np.ndarray | None] = {}
    for name in ("velocities", "accelerations"):
        given = [len(getattr(p, name)) > 0 for p in points]
        if any(given) and not all(given):
            k = given.index(not given[0])
            raise InvalidInputError(
                f"{field}.points[{k}].{name}", f"give {name} for every point or for none"
            )
        rates[name] = _point_rows([getattr(p, name) for p in points]) if all(given) else None
    return PlannedJointTrajectory(
        tuple(trajectory.joint_names),
        np.array(times),
        _point_rows([p.positions for p in points]),
        rates["velocities"],
        field,
        rates["accelerations"],
    )


def trajectory_from_msg(
    message: Path | MultiDOFJointTrajectory,
    base_frame: str,
    dt_s: float,
    default_duration_s: float,
    max_samples: int,
) -> ObjectTrajectory | WaypointTrajectory:
    """``trajectory_from_path`` or ``trajectory_from_multi_dof``, by message type."""
    if isinstance(message, MultiDOFJointTrajectory):
        return trajectory_from_multi_dof(
            message, base_frame, dt_s, default_duration_s, max_samples
        )
    return trajectory_from_path(message, base_frame, dt_s, default_duration_s, max_samples)


def object_trajectory_of_request(
    path: Path, multi_dof: MultiDOFJointTrajectory
) -> Path | MultiDOFJointTrajectory:
    """The request's object trajectory: the Path, or the MultiDOFJointTrajectory when the
    Path is empty; both given is refused."""
    if path.poses and multi_dof.points:
        raise InvalidInputError(
            "object_multi_dof_trajectory",
            "give the object trajectory once: object_trajectory (Path) or "
            "object_multi_dof_trajectory, not both",
        )
    return multi_dof if multi_dof.points else path


def grasps_with_joint_trajectories(
    grasps: Sequence[Grasp],
    joint_trajectories: Sequence[JointTrajectory],
    field: str = "joint_trajectories",
    max_samples: int | None = None,
) -> list[Grasp]:
    """Attach one planned joint trajectory per grasp (empty list: IK for all; an entry
    without points: IK for that grasp); each has at most ``max_samples`` points (its samples),
    checked before any is converted."""
    if not joint_trajectories:
        return list(grasps)
    if len(joint_trajectories) != len(grasps):
        raise InvalidInputError(
            field,
            f"must have one entry per grasp ({len(grasps)}) or none, got "
            f"{len(joint_trajectories)}",
        )
    for i, message in enumerate(joint_trajectories):
        if max_samples is not None and len(message.points) > max_samples:
            raise InvalidInputError(
                f"{field}[{i}].points",
                f"has {len(message.points)} points; at most max_samples={max_samples} are allowed",
            )
    return [
        replace(grasp, joint_trajectory=planned_from_joint_trajectory(message, f"{field}[{i}]"))
        for i, (grasp, message) in enumerate(zip(grasps, joint_trajectories, strict=True))
    ]


def check_grasp_array(
    grasps: PoseArray, object_frame: str, base_frame: str, max_grasps: int, field: str = "grasps"
) -> list[pin.SE3]:
    """Validate a PoseArray of grasps (frame, count, values); return the poses as given."""
    check_frame_id(grasps.header.frame_id, [object_frame, base_frame], f"{field}.header.frame_id")
    count = len(grasps.poses)
    if count == 0:
        raise InvalidInputError(f"{field}.poses", "is empty; give at least one grasp")
    if count > max_grasps:
        raise InvalidInputError(
            f"{field}.poses", f"has {count} grasps; at most max_grasps={max_grasps} are allowed"
        )
    return transforms_from_pose_msgs(grasps.poses, f"{field}.poses")


def transforms_from_pose_msgs(
    poses: Sequence[Pose], field: str, member: str = ""
) -> list[pin.SE3]:
    """transform_from_pose_msg of each pose (``field[i]member`` names a bad one), checked at
    once.

    The numbers are read into one array and checked together (the checks of
    transform_from_pose_msg: keep them the same); only when one is bad does each pose go
    through transform_from_pose_msg, for the message naming it. The transforms are computed
    exactly as there (same norm, same normalisation).
    """
    try:
        values = np.array([_pose_numbers(p) for p in poses], dtype=float).reshape(-1, 7)
    except (TypeError, ValueError):  # not numbers: the per-pose check names the field
        values = np.full((len(poses), 7), np.nan)
    quats = values[:, 3:]
    with np.errstate(over="ignore"):  # a huge component: the norm is inf, refused below
        # np.linalg.norm of a vector is sqrt(q.dot(q)): the same numbers, without its checks
        norms = np.sqrt(np.array([q.dot(q) for q in quats]).reshape(-1))
    if not (
        np.all(np.isfinite(values))
        and np.all(np.abs(norms - 1.0) <= QUATERNION_NORM_TOLERANCE)
        and np.all(np.abs(values[:, :3]) <= MAX_ABS_POSITION_M)
    ):
        return [transform_from_pose_msg(p, f"{field}[{i}]{member}") for i, p in enumerate(poses)]
    units = (quats / norms[:, None]).tolist()  # each row divided by its norm, as there
    return [
        pin.SE3(pin.Quaternion(w, x, y, z).toRotationMatrix(), position)
        for (x, y, z, w), position in zip(units, values[:, :3], strict=True)
    ]


def grasps_from_pose_array(
    grasps: PoseArray,
    object_frame: str,
    base_frame: str,
    trajectory: ObjectTrajectory | WaypointTrajectory,
    max_grasps: int,
    field: str = "grasps",
) -> list[Grasp]:
    """Core grasps (tip poses in the object frame) of a PoseArray of tip poses.

    frame_id ``object_frame``: the poses are the tip in the object frame. frame_id
    ``base_frame``: the poses are the tip in the base frame with the object at the start of
    ``trajectory``: transform_tip_to_object =
    transform_object_to_base(start)⁻¹ · transform_tip_to_base.
    """
    poses = check_grasp_array(grasps, object_frame, base_frame, max_grasps, field)
    if grasps.header.frame_id == base_frame:
        start = trajectory.transform_object_to_base_start
        poses = [start.actInv(pose) for pose in poses]
    return [Grasp(pose, f"grasp_{i}") for i, pose in enumerate(poses)]


def object_inertia_from_msg(
    inertia: Inertia, max_mass_kg: float, field: str = "object_inertia"
) -> ObjectInertia | None:
    """ObjectInertia of a geometry_msgs/Inertia (CoM and tensor about the CoM, object frame).

    Returns:
        None when ``m`` is exactly 0 (meaning: use the configured object).
    """
    if inertia.m == 0.0:
        return None
    mass = finite_float(inertia.m, f"{field}.m", minimum=0.0, strict_minimum=True)
    if mass > max_mass_kg:
        raise InvalidInputError(
            f"{field}.m", f"must be at most max_mass_kg={max_mass_kg:g}, got {mass:g}"
        )
    com = finite_array([inertia.com.x, inertia.com.y, inertia.com.z], f"{field}.com", (3,))
    check_within_reach(com, f"{field}.com")  # 1e300 m gave NaN effective masses
    components = [inertia.ixx, inertia.ixy, inertia.ixz, inertia.iyy, inertia.iyz, inertia.izz]
    tensor = inertia_tensor_from_components(components, f"{field}.ixx..izz", mass)
    try:
        return ObjectInertia(mass, np.array(com), tensor)
    except InvalidInputError as error:
        message = str(error).split(": ", 1)[-1]
        raise InvalidInputError(f"{field}.ixx..izz", message) from None


def inertia_msg_from_object(inertia: ObjectInertia) -> Inertia:
    """geometry_msgs/Inertia of an ObjectInertia (round trip of object_inertia_from_msg)."""
    tensor = inertia.inertia_about_com_kgm2
    return Inertia(
        m=float(inertia.mass_kg),
        com=vector3_msg(inertia.com_in_object_m),
        ixx=float(tensor[0, 0]),
        ixy=float(tensor[0, 1]),
        ixz=float(tensor[0, 2]),
        iyy=float(tensor[1, 1]),
        iyz=float(tensor[1, 2]),
        izz=float(tensor[2, 2]),
    )


def seed_from_joint_state(
    names: Sequence[str], positions: Sequence[float], robot: RobotModel
) -> np.ndarray | None:
    """Chain joint positions from a JointState's names/positions, or None if unusable.

    Usable means: every chain joint is named, names and positions have the same length, and
    the chain's positions are finite and inside the joint limits.
    """
    if len(names) != len(positions):
        return None
    by_name = dict(zip(names, positions, strict=True))
    if not all(name in by_name for name in robot.joint_names):
        return None
    seed = np.array([by_name[name] for name in robot.joint_names], dtype=float)
    try:
        return robot.check_positions(seed, "joint_states")
    except InvalidInputError:
        return None
