"""Conversions between ROS messages and core types; needs message packages, not rclpy.

The quaternion order is fixed here and only here: ROS messages are (x, y, z, w), Pinocchio's
constructor is (w, x, y, z); every conversion goes through quat_xyzw_from_msg and
quaternion_msg_from_rotation. Each function raises InvalidInputError naming the message field
(e.g. ``grasps.poses[2].orientation``), so the node can answer with that message.
"""

from __future__ import annotations

import array
import copy
import gc
import math
import threading
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pinocchio as pin
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Inertia, Point, Pose, PoseArray, Quaternion, Transform, Vector3
from grasp_safety_msgs.msg import BodyRegionAssessment, GraspRanking
from grasp_safety_msgs.msg import GraspEvaluation as GraspEvaluationMsg
from nav_msgs.msg import Path
from std_msgs.msg import ColorRGBA, Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint, MultiDOFJointTrajectory
from visualization_msgs.msg import Marker, MarkerArray

from ..core.analyses.iso15066 import PowerForceLimitAssessment, RegionAssessment
from ..core.analyses.safety_report import SafetyReport
from ..core.analyses.whole_arm import WholeArmEvaluation, whole_arm_score
from ..core.exceptions import InvalidInputError
from ..core.input_checks import (
    QUATERNION_NORM_TOLERANCE,
    finite_array,
    finite_float,
    quat_xyzw_from_rotation,
    rotation_from_quat_xyzw,
)
from ..core.method.executable import rates_for_execution
from ..core.method.joint_trajectory import PlannedJointTrajectory
from ..core.method.posture import PostureSelection, single_posture
from ..core.method.ranking import Grasp, GraspEvaluation, Ranking
from ..core.model.armature import armature_ratio
from ..core.model.inertia import ObjectInertia
from ..core.model.robot import NO_ARMATURE_NOTE, RobotModel
from ..core.model.trajectory import ObjectTrajectory
from ..core.model.waypoint_trajectory import WaypointTrajectory
from .parameters import ResponseContent, inertia_tensor_from_components

SCORE_UNITS = {"mean": "kg", "max": "kg", "integral": "kg*s"}
ARROW_LENGTH_M = 0.08
"""Length of the grasp arrows in RViz; they end at the grasp point along the tip z axis."""
INFEASIBLE_RGBA = (0.5, 0.5, 0.5, 0.6)
"""Grasps outside the final order (infeasible, or without an effort score) are grey."""
NAN = float("nan")
FULL_RESPONSE = ResponseContent()
"""Every joint trajectory and every per-sample array: what a message built without the node's
``response.*`` parameters carries."""
LABEL_OFFSET_M = np.array([0.0, 0.0, 0.03])
"""Labels float this far above the grasp point (base axes)."""
MAX_ABS_POSITION_M = 1000.0
"""Pose coordinates and object CoMs beyond this are refused: no manipulator reaches them, and
absurd values (1e300) made the IK search for seconds (poses) or the effective mass NaN (CoM)."""


# --- Poses -----------------------------------------------------------------------------------


def quat_xyzw_from_msg(quaternion: Quaternion) -> np.ndarray:
    """The (x, y, z, w) array of a geometry_msgs/Quaternion (the one place the order is set)."""
    return np.array([quaternion.x, quaternion.y, quaternion.z, quaternion.w], dtype=float)


def quaternion_msg_from_rotation(rotation: np.ndarray) -> Quaternion:
    """geometry_msgs/Quaternion of a rotation matrix (w >= 0)."""
    x, y, z, w = quat_xyzw_from_rotation(rotation)
    return Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))


def transform_from_pose_msg(pose: Pose, field: str) -> pin.SE3:
    """Rigid transform of a geometry_msgs/Pose; checks finiteness, a unit quaternion and
    coordinates within +/- MAX_ABS_POSITION_M."""
    quat_xyzw = quat_xyzw_from_msg(pose.orientation)
    rotation = rotation_from_quat_xyzw(quat_xyzw, f"{field}.orientation")
    position = finite_array(
        [pose.position.x, pose.position.y, pose.position.z], f"{field}.position", (3,)
    )
    if np.max(np.abs(position)) > MAX_ABS_POSITION_M:
        raise InvalidInputError(
            f"{field}.position",
            f"must be within +/-{MAX_ABS_POSITION_M:g} m per coordinate, got "
            f"{[float(v) for v in position]}",
        )
    return pin.SE3(rotation, np.array(position))


def _pose_numbers(pose: Pose) -> tuple[float, ...]:
    position, orientation = pose.position, pose.orientation
    x, y, z, w = orientation.x, orientation.y, orientation.z, orientation.w
    return (position.x, position.y, position.z, x, y, z, w)


def pose_msg_from_transform(transform: pin.SE3) -> Pose:
    """geometry_msgs/Pose of a rigid transform."""
    x, y, z = (float(v) for v in transform.translation)
    return Pose(
        position=Point(x=x, y=y, z=z), orientation=quaternion_msg_from_rotation(transform.rotation)
    )


def vector3_msg(vector: Sequence[float] | np.ndarray) -> Vector3:
    """geometry_msgs/Vector3 of three numbers."""
    x, y, z = (float(v) for v in vector)
    return Vector3(x=x, y=y, z=z)


def check_frame_id(frame_id: str, accepted: Sequence[str], field: str) -> str:
    """Return ``frame_id`` if it is one of ``accepted``, else raise naming both."""
    if frame_id not in accepted:
        names = " or ".join(f"'{name}'" for name in accepted)
        raise InvalidInputError(field, f"unknown frame_id '{frame_id}'; accepted: {names}")
    return frame_id


def stamp_to_seconds(stamp: Time) -> float:
    """Seconds of a builtin_interfaces/Time."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


# --- Trajectory, grasps, inertia -------------------------------------------------------------


def duration_to_seconds(duration: Duration) -> float:
    """Seconds of a builtin_interfaces/Duration."""
    return float(duration.sec) + 1e-9 * float(duration.nanosec)


def transform_from_transform_msg(transform: Transform, field: str) -> pin.SE3:
    """Rigid transform of a geometry_msgs/Transform; checks finiteness and a unit quaternion."""
    rotation = rotation_from_quat_xyzw(quat_xyzw_from_msg(transform.rotation), f"{field}.rotation")
    t = transform.translation
    translation = finite_array([t.x, t.y, t.z], f"{field}.translation", (3,))
    return pin.SE3(rotation, np.array(translation))


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


def planned_from_joint_trajectory(
    trajectory: JointTrajectory, field: str
) -> PlannedJointTrajectory | None:
    """The planned joint trajectory of a trajectory_msgs/JointTrajectory; None when it has no
    points (IK for that grasp).

    Times are ``time_from_start`` (strictly increasing); ``velocities`` are used when every
    point has one per joint, ignored when every point has none; accelerations are not used.
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
    with_velocities = [len(p.velocities) > 0 for p in points]
    if any(with_velocities) and not all(with_velocities):
        k = with_velocities.index(not with_velocities[0])
        raise InvalidInputError(
            f"{field}.points[{k}].velocities", "give velocities for every point or for none"
        )
    return PlannedJointTrajectory(
        tuple(trajectory.joint_names),
        np.array(times),
        [list(p.positions) for p in points],
        [list(p.velocities) for p in points] if all(with_velocities) else None,
        field,
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
    with np.errstate(over="ignore"):  # a huge component: the norm is inf, refused below
        norms = [float(np.linalg.norm(quat)) for quat in values[:, 3:]]
    if not (
        np.all(np.isfinite(values))
        and all(abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE for norm in norms)
        and np.all(np.abs(values[:, :3]) <= MAX_ABS_POSITION_M)
    ):
        return [transform_from_pose_msg(p, f"{field}[{i}]{member}") for i, p in enumerate(poses)]
    transforms = []
    for row, norm in zip(values, norms, strict=True):
        x, y, z, w = row[3:] / norm
        transforms.append(pin.SE3(pin.Quaternion(w, x, y, z).toRotationMatrix(), row[:3].copy()))
    return transforms


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
    ``trajectory``; T_object_tip = T_base_object(start)⁻¹ · T_base_tip.
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
    if np.max(np.abs(com)) > MAX_ABS_POSITION_M:  # 1e300 m gave NaN effective masses
        raise InvalidInputError(
            f"{field}.com",
            f"must be within +/-{MAX_ABS_POSITION_M:g} m per coordinate, got "
            f"{[float(v) for v in com]}",
        )
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


# --- Results ---------------------------------------------------------------------------------


class _CollectorPause:
    """Context manager: the cyclic garbage collector paused while a result message is built.

    A response holds a Python object per trajectory point and per region; none of them forms a
    reference cycle, but their allocation triggers the collector over and over (it walks every
    tracked object of the process): 40 % of the building time of a 1,000 x 201 response (when
    ``direction`` was a Vector3 per sample). Reference counting still frees everything; the
    collector resumes (if it was running) when the last of concurrent builds ends.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._depth = 0
        self._resume = False

    def __enter__(self) -> None:
        with self._lock:
            if self._depth == 0:
                self._resume = gc.isenabled()
                gc.disable()
            self._depth += 1

    def __exit__(self, *exc_info: object) -> None:
        with self._lock:
            self._depth -= 1
            if self._depth == 0 and self._resume:
                gc.enable()


collector_paused = _CollectorPause()
"""Pauses the garbage collector for ranking_msg and report_msg (re-entrant, thread-safe)."""


def float64_array(values: Sequence[float] | np.ndarray) -> array.array:
    """``array('d')`` of ``values``: what a float64[] field holds; built from the bytes, so
    the message setter stores it as is instead of converting element by element."""
    return array.array("d", np.ascontiguousarray(values, dtype=np.float64).tobytes())


def evaluation_msg(evaluation: GraspEvaluation, per_sample: bool = True) -> GraspEvaluationMsg:
    """grasp_safety_msgs/GraspEvaluation of a core evaluation (NaN scores when infeasible).

    The analysis fields say "not computed" (NaN, empty, false), except ``safety_score``: the
    tip score, as with the default analysis options; report_msg fills them in. Without
    ``per_sample`` the per-sample arrays stay empty (the scores and aggregates are kept).
    """
    score = float(evaluation.score)
    message = _new_evaluation(
        index=int(evaluation.index),
        name=evaluation.name,
        feasible=bool(evaluation.feasible),
        reason=evaluation.reason,
        score=score,
        peak_effective_mass_kg=float(evaluation.peak_effective_mass_kg),
        mean_effective_mass_kg=float(evaluation.mean_effective_mass_kg),
        safety_score=score,
    )
    links_only = evaluation.links_only_effective_mass_kg
    message.links_only_mean_effective_mass_kg = (
        float(np.mean(links_only)) if evaluation.feasible and len(links_only) else NAN
    )
    if per_sample:
        message.time_from_start_s = float64_array(evaluation.times_s)
        message.effective_mass_kg = float64_array(evaluation.effective_mass_kg)
        message.links_only_effective_mass_kg = float64_array(links_only)
        message.direction_xyz = float64_array(evaluation.directions_in_base)  # row-major
        message.direction_is_worst_case = np.asarray(
            evaluation.direction_is_worst_case, bool
        ).tolist()
    return message


def duration_msg(seconds: float) -> Duration:
    """builtin_interfaces/Duration of a non-negative time [s], rounded to the nanosecond."""
    nanoseconds = round(float(seconds) * 1e9)
    return Duration(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def _slot_constructor(message_type: Any, fields: tuple[str, ...]) -> Callable[..., Any]:
    """A constructor of ``message_type`` from all its ``fields``, given positionally.

    It fills the generated class's slots directly, where the keyword constructor runs a
    property setter per field (several times the cost; it counts for messages made per
    sample or per region of every grasp). The values must already have the field types
    (float, bool, str, int, ``array('d')`` for float64[], messages). A class whose slots are
    not exactly these fields gets its keyword constructor.
    """
    slots = tuple(f"_{name}" for name in fields)
    if set(message_type.__slots__) != {*slots, "_check_fields"}:
        return lambda *values: message_type(**dict(zip(fields, values, strict=True)))
    check_fields = message_type()._check_fields

    def construct(*values: Any) -> Any:
        message = message_type.__new__(message_type)
        for slot, value in zip(slots, values, strict=True):
            setattr(message, slot, value)
        message._check_fields = check_fields
        return message

    return construct


def _template_constructor(template: Any) -> Callable[..., Any]:
    """A constructor of messages equal to ``template`` but for the fields given by keyword.

    Like _slot_constructor it fills the generated class's slots directly: numbers and strings
    of ``template`` are shared, every sequence and nested message is made anew (empty; the
    template's must be empty), the keyword fields are stored as given (they must already have
    the field types, as for _slot_constructor). A class that is not the kind this was written
    for (slots other than its fields and ``_check_fields``) gets a copy of ``template`` with
    the fields set through its setters.
    """
    message_type = type(template)
    fields = message_type.get_fields_and_field_types()
    if set(message_type.__slots__) != {*(f"_{name}" for name in fields), "_check_fields"}:

        def set_fields(**values: Any) -> Any:
            message = copy.deepcopy(template)
            for name, value in values.items():
                setattr(message, name, value)
            return message

        return set_fields
    shared, arrays, lists, messages = [], [], [], []
    for name in fields:
        value = getattr(template, name)
        if isinstance(value, array.array):
            arrays.append((f"_{name}", value.typecode))
        elif isinstance(value, list):
            lists.append(f"_{name}")
        elif isinstance(value, bool | int | float | str):
            shared.append((f"_{name}", value))
        else:
            messages.append((f"_{name}", type(value)))
    check_fields, new = template._check_fields, message_type.__new__

    def construct(**values: Any) -> Any:
        message = new(message_type)
        for slot, value in shared:
            setattr(message, slot, value)
        for slot, typecode in arrays:
            setattr(message, slot, array.array(typecode))
        for slot in lists:
            setattr(message, slot, [])
        for slot, nested_type in messages:
            setattr(message, slot, nested_type())
        for name, value in values.items():
            setattr(message, f"_{name}", value)
        message._check_fields = check_fields
        return message

    return construct


_new_pose = _slot_constructor(Pose, ("position", "orientation"))
_new_point = _slot_constructor(Point, ("x", "y", "z"))
_new_quaternion = _slot_constructor(Quaternion, ("x", "y", "z", "w"))
_new_evaluation = _template_constructor(
    GraspEvaluationMsg(
        iso_min_duration_s=NAN,
        worst_case_score=NAN,
        percentile_score=NAN,
        probability_safest=NAN,
        grasp_quality=NAN,
        combined_score=NAN,
        score_without_redundancy=NAN,
        effort_score=NAN,
        score_single_ik=NAN,
        score_range_min=NAN,
        score_range_max=NAN,
        whole_arm_rank_force_n=NAN,
        whole_arm_worst_force_ratio=NAN,
        whole_arm_min_duration_s=NAN,
        whole_arm_worst_energy_j=NAN,
    )
)
"""GraspEvaluation messages whose analysis fields say "not computed" (NaN, empty, false)."""


_FAST_POINTS = set(JointTrajectoryPoint.__slots__) == {
    "_positions",
    "_velocities",
    "_accelerations",
    "_effort",
    "_time_from_start",
    "_check_fields",
} and set(Duration.__slots__) == {"_sec", "_nanosec", "_check_fields"}
"""Whether joint_trajectory_msg may fill the slots of the points directly (Jazzy's classes)."""
_POINT_CHECK_FIELDS = JointTrajectoryPoint()._check_fields
_DURATION_CHECK_FIELDS = Duration()._check_fields


def joint_trajectory_msg(
    joint_names: Sequence[str],
    times_s: np.ndarray,
    joint_positions: np.ndarray,
    header: Header,
    planned_rates: tuple[np.ndarray, np.ndarray] | None = None,
) -> JointTrajectory:
    """trajectory_msgs/JointTrajectory of sampled joint positions [rad or m] at times [s]:
    velocities and accelerations the planner's (``planned_rates``), else from
    core.method.executable (C2 spline, at rest at both ends); no points when there are no
    samples. Give ``header`` a zero stamp: in a JointTrajectory the stamp is when execution
    starts, and 0 means on receipt."""
    message = JointTrajectory(header=header, joint_names=list(joint_names))
    if len(times_s) == 0:
        return message
    velocities, accelerations = rates_for_execution(times_s, joint_positions, planned_rates)
    # One point per sample: made by filling the messages' slots when the classes are the
    # ones this was written for (the keyword constructors cost several times more); stamps
    # rounded as duration_msg rounds them.
    nanoseconds = np.round(np.asarray(times_s, dtype=float) * 1e9).astype(np.int64).tolist()
    rows = zip(
        nanoseconds,
        np.asarray(joint_positions, dtype=float).tolist(),
        velocities.tolist(),
        accelerations.tolist(),
        strict=True,
    )
    if not _FAST_POINTS:
        message.points = [
            JointTrajectoryPoint(
                positions=q,
                velocities=qd,
                accelerations=qdd,
                time_from_start=Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000),
            )
            for ns, q, qd, qdd in rows
        ]
        return message
    new_point, new_duration = JointTrajectoryPoint.__new__, Duration.__new__
    check_point, check_duration = _POINT_CHECK_FIELDS, _DURATION_CHECK_FIELDS
    points = []
    for ns, q, qd, qdd in rows:
        stamp = new_duration(Duration)
        stamp._sec, stamp._nanosec = ns // 1_000_000_000, ns % 1_000_000_000
        stamp._check_fields = check_duration
        point = new_point(JointTrajectoryPoint)
        point._positions, point._velocities = array.array("d", q), array.array("d", qd)
        point._accelerations, point._effort = array.array("d", qdd), array.array("d")
        point._time_from_start, point._check_fields = stamp, check_point
        points.append(point)
    message.points = points
    return message


def _set_posture(message: GraspEvaluationMsg, posture: PostureSelection) -> None:
    message.score_single_ik = float(posture.score_single_ik)
    message.score_range_min = float(posture.score_range[0])
    message.score_range_max = float(posture.score_range[1])
    message.start_positions = float64_array(posture.start_positions)
    message.postures_tried = int(posture.postures_tried)
    message.postures_feasible = int(posture.postures_feasible)


def ranked_pose_array(grasps: PoseArray, order: Sequence[int]) -> PoseArray:
    """The feasible grasps of a request, safest first, in the request's frame (poses as given)."""
    return PoseArray(
        header=Header(stamp=grasps.header.stamp, frame_id=grasps.header.frame_id),
        poses=[_copy_pose(grasps.poses[i]) for i in order],
    )


def _copy_pose(pose: Pose) -> Pose:
    p, q = pose.position, pose.orientation
    return _new_pose(_new_point(p.x, p.y, p.z), _new_quaternion(q.x, q.y, q.z, q.w))


def ranking_msg(
    ranking: Ranking,
    grasps: PoseArray,
    base_frame: str,
    stamp: Time,
    compute_time_s: float,
    order: Sequence[int] | None = None,
    content: ResponseContent = FULL_RESPONSE,
) -> GraspRanking:
    """grasp_safety_msgs/GraspRanking of a core ranking of the grasps in ``grasps``.

    The paper's ranking only: the analysis fields are those of the default options with
    nothing beyond the tip computed (see evaluation_msg); report_msg gives the full result.
    ``order`` (default: the ranking's) sets ``order`` and ``ranked_grasps``; ``content``
    which grasps carry their ``joint_trajectory`` and whether the per-sample arrays are
    filled (default: all of them).
    """
    with collector_paused:
        message = _ranking_msg_without_trajectories(
            ranking, grasps, base_frame, stamp, compute_time_s, order, content.per_sample
        )
        _set_joint_trajectories(
            message,
            ranking.joint_names,
            {
                e.index: (e.times_s, e.joint_positions, e.planned_joint_rates)
                for e in ranking.evaluations
            },
            content.with_joint_trajectory(message.order, len(ranking.evaluations)),
            base_frame,
        )
    return message


def _ranking_msg_without_trajectories(
    ranking: Ranking,
    grasps: PoseArray,
    base_frame: str,
    stamp: Time,
    compute_time_s: float,
    order: Sequence[int] | None,
    per_sample: bool,
) -> GraspRanking:
    """ranking_msg with every ``joint_trajectory`` left empty."""
    paper_order = [int(i) for i in ranking.order]
    final = paper_order if order is None else [int(i) for i in order]
    message = GraspRanking(
        header=Header(stamp=stamp, frame_id=base_frame),
        metric=ranking.metric,
        order=final,
        ranked_grasps=ranked_pose_array(grasps, final),
        evaluations=[evaluation_msg(e, per_sample) for e in ranking.evaluations],
        joint_names=list(ranking.joint_names),
        compute_time_s=float(compute_time_s),
        backend=ranking.backend,
        metric_point="tip",
        rank_by="safety",
        safety_order=paper_order,
        paper_order=paper_order,
        safety_weight=NAN,
        effort_criterion="",
        order_stability=NAN,
    )
    _set_armature(message, ranking)
    postures = ranking.postures or tuple(single_posture(e) for e in ranking.evaluations)
    for item, posture in zip(message.evaluations, postures, strict=True):
        _set_posture(item, posture)
    return message


def _set_armature(message: GraspRanking, ranking: Ranking) -> None:
    """The armature fields of a GraspRanking: given or the note, and the ratio's median."""
    feasible = [e for e in ranking.evaluations if e.feasible]
    ratio = armature_ratio(
        [e.effective_mass_kg for e in feasible], [e.links_only_effective_mass_kg for e in feasible]
    )
    message.armature_given = bool(ranking.armature_given)
    message.armature_note = "" if ranking.armature_given else NO_ARMATURE_NOTE
    message.armature_ratio_median = float(ratio.median)


def _set_joint_trajectories(
    message: GraspRanking,
    joint_names: Sequence[str],
    motions: Mapping[int, tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray] | None]],
    indices: Collection[int],
    base_frame: str,
) -> None:
    """Fill ``joint_trajectory`` of the evaluations whose index is in ``indices`` from
    ``motions`` (index: sample times [s], joint positions, a planner's own rates or None);
    the others keep an empty one."""
    by_index = {item.index: item for item in message.evaluations}
    for index in sorted(indices):
        times_s, joint_positions, planned_rates = motions[index]
        by_index[index].joint_trajectory = joint_trajectory_msg(
            joint_names, times_s, joint_positions, Header(frame_id=base_frame), planned_rates
        )


_body_region_assessment = _slot_constructor(
    BodyRegionAssessment,
    (
        "region",
        "transient_contact_permitted",
        "worst_force_ratio",
        "peak_contact_force_n",
        "max_transient_force_n",
        "min_max_permissible_speed_m_s",
        "admissible",
        "min_duration_s",
    ),
)


def region_assessment_msg(
    assessment: RegionAssessment, min_speed_m_s: float | None = None
) -> BodyRegionAssessment:
    """grasp_safety_msgs/BodyRegionAssessment of one region's ISO/TS 15066 assessment.

    Where transient contact is not permitted, the core's ratio (inf while the point moves)
    becomes NaN, as does the null limit F_tr; ``min_duration_s`` keeps the core's inf.
    ``min_speed_m_s``: the smallest of its ``max_permissible_speed_m_s`` if already known.
    """
    region = assessment.region
    permitted = region.transient_contact_permitted
    limit = region.max_transient_force_n
    if min_speed_m_s is None:
        speeds = assessment.max_permissible_speed_m_s
        min_speed_m_s = float(speeds.min()) if len(speeds) else NAN
    return _body_region_assessment(
        region.name,
        bool(permitted),
        float(assessment.worst_force_ratio) if permitted else NAN,
        float(assessment.peak_contact_force_n),
        float(limit) if limit is not None else NAN,
        min_speed_m_s,
        bool(assessment.admissible),
        float(assessment.min_duration_s),
    )


def _min_speeds(speeds: Sequence[np.ndarray]) -> list[float]:
    """The smallest value of each array (NaN for an empty one); one array pass when they all
    have the same length (the regions of one motion)."""
    if len({len(s) for s in speeds}) == 1 and len(speeds[0]) > 0:
        return np.min(speeds, axis=1).tolist()
    return [float(s.min()) if len(s) else NAN for s in speeds]


def _set_iso(message: GraspEvaluationMsg, assessment: PowerForceLimitAssessment) -> None:
    regions = assessment.regions
    lowest = _min_speeds([r.max_permissible_speed_m_s for r in regions]) if regions else []
    message.iso_ts_15066 = [
        region_assessment_msg(r, v) for r, v in zip(regions, lowest, strict=True)
    ]
    message.iso_admissible = bool(assessment.feasible and assessment.admissible_where_permitted)
    message.iso_min_duration_s = float(assessment.min_duration_s)
    message.iso_limiting_region = assessment.limiting_region


def _set_whole_arm(message: GraspEvaluationMsg, whole: WholeArmEvaluation, region: str) -> None:
    """The whole_arm_* fields of one grasp (left at "not computed" when infeasible)."""
    if not whole.feasible:
        return
    if any(r.region == region for r in whole.regions):
        message.whole_arm_rank_force_n = float(whole_arm_score(whole, region))
    if whole.limiting_region:
        limiting = whole.region(whole.limiting_region)
        message.whole_arm_limiting_region = whole.limiting_region
        message.whole_arm_worst_force_ratio = float(limiting.worst_force_ratio)
        message.whole_arm_worst_site = whole.site_names[limiting.worst_site]
        message.whole_arm_worst_link = whole.site_links[limiting.worst_site]
    message.whole_arm_admissible = bool(whole.admissible_where_permitted)
    message.whole_arm_min_duration_s = float(whole.min_duration_s)
    energy, site, _ = whole.worst_energy
    message.whole_arm_worst_energy_j = float(energy)
    message.whole_arm_worst_energy_site = whole.site_names[site]


def report_msg(
    report: SafetyReport,
    grasps: PoseArray,
    base_frame: str,
    stamp: Time,
    compute_time_s: float,
    content: ResponseContent = FULL_RESPONSE,
) -> GraspRanking:
    """grasp_safety_msgs/GraspRanking of a core SafetyReport (the content of the CLI's JSON).

    ``order`` and ``ranked_grasps`` follow the report's final order; the paper's fields
    (``score``, per-sample tip effective mass, ...) are those of ranking_msg. ``content`` as
    there: the first grasps of the final order carry their joint trajectory (the
    redundancy-resolved one where it was applied), the per-sample arrays are filled or not.
    """
    with collector_paused:
        return _report_msg(report, grasps, base_frame, stamp, compute_time_s, content)


def _report_msg(
    report: SafetyReport,
    grasps: PoseArray,
    base_frame: str,
    stamp: Time,
    compute_time_s: float,
    content: ResponseContent,
) -> GraspRanking:
    options = report.options
    quality_given = options.grasp_quality is not None
    per_sample = content.per_sample
    message = _ranking_msg_without_trajectories(
        report.ranking, grasps, base_frame, stamp, compute_time_s, report.order, per_sample
    )
    motions = {
        e.index: (e.times_s, e.joint_positions, e.planned_joint_rates)
        for e in report.ranking.evaluations
    }
    message.metric_point = options.metric_point
    message.rank_by = options.rank_by
    message.safety_order = [int(i) for i in report.safety_order]
    message.safety_weight = float(options.safety_weight) if quality_given else NAN
    message.pareto_set = [int(i) for i in report.quality.pareto_set] if quality_given else []
    message.effort_criterion = options.effort_criterion if report.effort else ""
    if report.uncertainty is not None:
        message.ranking_flips = bool(report.uncertainty.ranking_flips)
        message.order_stability = float(report.uncertainty.order_stability)
        message.worst_case_order = [int(i) for i in report.uncertainty.worst_case_order]
        message.uncertainty_message = report.uncertainty.message
    if report.arm_sites is not None:
        message.whole_arm_region = options.whole_arm_region
        message.whole_arm_sites = list(report.arm_sites.names)
    iso = {a.index: a for a in report.iso}
    pareto = set(message.pareto_set)
    for k, evaluation in enumerate(message.evaluations):
        evaluation.safety_score = float(report.scores[k])
        if k in iso:
            _set_iso(evaluation, iso[k])
        if report.whole_arm:
            _set_whole_arm(evaluation, report.whole_arm[k], options.whole_arm_region)
        if per_sample and report.exposed and report.exposed[k].feasible:
            exposed = report.exposed[k]
            evaluation.leading_point_effective_mass_kg = float64_array(
                exposed.leading_effective_mass_kg
            )
            evaluation.worst_point_effective_mass_kg = float64_array(
                exposed.worst_effective_mass_kg
            )
        if report.uncertainty is not None:
            spread = report.uncertainty.grasps[k]
            evaluation.worst_case_score = float(spread.worst_case_score)
            evaluation.percentile_score = float(spread.percentile_score)
            evaluation.probability_safest = float(spread.probability_safest)
        if quality_given:
            evaluation.grasp_quality = float(report.quality.quality[k])
            evaluation.combined_score = float(report.quality.combined[k])
            evaluation.pareto_optimal = k in pareto
        if report.redundancy:
            resolution = report.redundancy[k]
            evaluation.redundancy_applied = bool(resolution.applied)
            evaluation.score_without_redundancy = float(resolution.original_score)
            if resolution.applied:
                motions[k] = (resolution.times_s, resolution.joint_positions, None)
                if per_sample:
                    evaluation.effective_mass_with_redundancy_kg = float64_array(
                        resolution.effective_mass_kg
                    )
        if report.effort:
            effort = report.effort[k]
            evaluation.effort_score = float(effort.score(options.effort_criterion))
            if effort.feasible:
                evaluation.peak_abs_torque = float64_array(effort.peak_abs_torque)
                evaluation.rms_torque = float64_array(effort.rms_torque)
    _set_joint_trajectories(
        message,
        report.ranking.joint_names,
        motions,
        content.with_joint_trajectory(report.order, len(message.evaluations)),
        base_frame,
    )
    return message


def rank_color(rank: int, count: int) -> tuple[float, float, float, float]:
    """RGBA from green (rank 0, safest) to red (rank count-1, least safe)."""
    fraction = rank / (count - 1) if count > 1 else 0.0
    return (fraction, 1.0 - fraction, 0.0, 1.0)


def markers_msg(
    ranking: Ranking,
    grasps: Sequence[Grasp],
    trajectory: ObjectTrajectory | WaypointTrajectory,
    base_frame: str,
    stamp: Time,
    *,
    order: Sequence[int] | None = None,
    scores: Sequence[float] | np.ndarray | None = None,
    not_admissible: Collection[int] = (),
) -> MarkerArray:
    """RViz markers of a ranking: per grasp an arrow and a label, in the base frame.

    The first marker deletes the previous ranking's markers. Each grasp is drawn with the
    object at its start pose: an ARROW of ARROW_LENGTH_M along the tip z axis ending at the
    tip (namespace ``grasps``) and a TEXT_VIEW_FACING label with rank and score (namespace
    ``labels``); ids are the candidate indices. Grasps in ``order`` (default: the ranking's)
    go from green (first) to red (last), the others are grey. The label shows ``scores``
    (default: each evaluation's score) and, for the indices in ``not_admissible``, that
    ISO/TS 15066 does not admit the motion.
    """
    header = Header(stamp=stamp, frame_id=base_frame)
    markers = [Marker(header=header, action=Marker.DELETEALL)]
    order = ranking.order if order is None else order
    rank_of = {index: rank for rank, index in enumerate(order)}
    unit = SCORE_UNITS.get(ranking.metric, "")
    start = trajectory.transform_object_to_base_start
    for evaluation, grasp in zip(ranking.evaluations, grasps, strict=True):
        tip_in_base = start * grasp.transform_tip_to_object
        tip = tip_in_base.translation
        tail = tip - ARROW_LENGTH_M * tip_in_base.rotation[:, 2]
        index = evaluation.index
        score = evaluation.score if scores is None else scores[index]
        if index in rank_of:
            rgba = rank_color(rank_of[index], len(order))
            text = f"#{rank_of[index] + 1} {evaluation.name}: {score:.3f} {unit}"
        elif evaluation.feasible:
            rgba = INFEASIBLE_RGBA
            text = f"{evaluation.name}: {score:.3f} {unit}, not ranked"
        else:
            rgba = INFEASIBLE_RGBA
            text = f"{evaluation.name}: infeasible"
        if index in not_admissible:
            text += ", ISO/TS 15066: not admissible"
        color = ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
        identity = Pose(orientation=Quaternion(w=1.0))
        markers.append(
            Marker(
                header=header,
                ns="grasps",
                id=index,
                type=Marker.ARROW,
                action=Marker.ADD,
                pose=identity,
                points=[_point(tail), _point(tip)],
                scale=Vector3(x=0.008, y=0.016, z=0.02),
                color=color,
            )
        )
        label_pose = Pose(position=_point(tip + LABEL_OFFSET_M), orientation=Quaternion(w=1.0))
        markers.append(
            Marker(
                header=header,
                ns="labels",
                id=index,
                type=Marker.TEXT_VIEW_FACING,
                action=Marker.ADD,
                pose=label_pose,
                scale=Vector3(z=0.02),
                color=color,
                text=text,
            )
        )
    return MarkerArray(markers=markers)


def _point(vector: np.ndarray) -> Point:
    x, y, z = (float(v) for v in vector)
    return Point(x=x, y=y, z=z)
