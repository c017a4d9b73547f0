"""The node's response built the fast way (message slots filled directly, point arrays from
byte slices) equals the plain way (keyword constructors and property setters) bit for bit, on
a mixed request: an unreachable grasp, continuous and revolute joints, posture selection, every
analysis, per-sample arrays on and off, joint trajectories for all, one or no grasp."""

from __future__ import annotations

import array
import copy
import struct
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
from builtin_interfaces.msg import Time
from conftest import ARM6_AXES, serial_arm_urdf
from geometry_msgs.msg import PoseArray
from grasp_safety_msgs.msg import BodyRegionAssessment, GraspRanking
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header

from grasp_safety_ros.core import GraspSafetyEvaluator, ObjectTrajectory, RobotModel, solid_box
from grasp_safety_ros.core.analyses.exposed_points import box_corners_in_object
from grasp_safety_ros.core.analyses.safety_report import AnalysisOptions, SafetyReport
from grasp_safety_ros.core.method.posture import PostureConfig
from grasp_safety_ros.core.method.ranking import Grasp
from grasp_safety_ros.core.pipeline import PipelineRequest, run_pipeline
from grasp_safety_ros.ros.conversions import pose_msg_from_transform, report_msg, results
from grasp_safety_ros.ros.service.response import ResponseContent

CONTENTS = (
    ResponseContent(),  # every joint trajectory, per-sample arrays
    ResponseContent(joint_trajectories=1),  # the node's default
    ResponseContent(joint_trajectories=0, per_sample=False),
    ResponseContent(joint_trajectories=2, per_sample=False),
)


def differences(got: Any, want: Any, path: str = "") -> list[str]:
    """Where two messages differ: floats by their bits (NaN and -0.0 included), float arrays
    by their bytes, everything else by value, recursively."""
    if type(got) is not type(want):
        return [f"{path}: {type(got).__name__} != {type(want).__name__}"]
    if hasattr(got, "get_fields_and_field_types"):
        return [
            d
            for name in got.get_fields_and_field_types()
            for d in differences(getattr(got, name), getattr(want, name), f"{path}.{name}")
        ]
    if isinstance(got, array.array):
        same = got.typecode == want.typecode and got.tobytes() == want.tobytes()
        return [] if same else [f"{path}: {got} != {want}"]
    if isinstance(got, list):
        if len(got) != len(want):
            return [f"{path}: {len(got)} != {len(want)} items"]
        return [
            d
            for k, (a, b) in enumerate(zip(got, want, strict=True))
            for d in differences(a, b, f"{path}[{k}]")
        ]
    if isinstance(got, float):
        return (
            []
            if struct.pack("d", got) == struct.pack("d", want)
            else [f"{path}: {got!r} != {want!r}"]
        )
    return [] if got == want else [f"{path}: {got!r} != {want!r}"]


def mixed_report(robot: RobotModel) -> tuple[SafetyReport, PoseArray]:
    """Four grasps (one out of reach) ranked with posture selection and every analysis."""
    trajectory = ObjectTrajectory(
        pin.SE3(np.eye(3), np.array([0.3, 0.1, 0.4])),
        pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.4), np.array([0.35, 0.05, 0.45])),
        1.0,
        0.05,
    )
    seed = np.random.default_rng(0).uniform(-1.0, 1.0, len(robot.joint_names))
    tip_in_object = trajectory.transform_object_to_base_start.actInv(
        robot.transform_tip_to_base(seed)
    )
    shifts = ([0.0, 0.0, 0.0], [0.0, 0.0, 0.03], [0.01, 0.02, 0.0])
    grasps = [
        Grasp(pin.SE3(np.eye(3), np.array(shift)) * tip_in_object, f"g{k}")
        for k, shift in enumerate(shifts)
    ]
    grasps.insert(2, Grasp(pin.SE3(np.eye(3), np.array([5.0, 0.0, 0.0])), "unreachable"))
    evaluator = GraspSafetyEvaluator(robot)
    inertia = solid_box(0.5, [0.1, 0.1, 0.1])
    options = AnalysisOptions(
        metric_point="worst_point",
        points_in_object_m=box_corners_in_object([0.1, 0.1, 0.1]),
        effort=True,
        effort_criterion="rms_fraction",
        grasp_quality=(0.2, 0.9, 0.5, 0.1),
        safety_weight=0.25,
    )
    request = PipelineRequest(
        tuple(grasps), inertia, trajectory, None, options, PostureConfig(restarts=2), seed
    )
    report = run_pipeline(evaluator, request)
    request = PoseArray(
        header=Header(frame_id="object", stamp=Time(sec=4)),
        poses=[pose_msg_from_transform(g.transform_tip_to_object) for g in grasps],
    )
    return report, request


def keyword_evaluation(**values: Any) -> Any:
    """The plain way to make an evaluation message: a copy of the template, fields set
    through the generated property setters."""
    message = copy.deepcopy(results._EVALUATION_TEMPLATE)
    for name, value in values.items():
        setattr(message, name, value)
    return message


def keyword_region(*values: Any) -> BodyRegionAssessment:
    return BodyRegionAssessment(**dict(zip(results._REGION_FIELDS, values, strict=True)))


@pytest.mark.parametrize("joint_type", ["revolute", "continuous"])
def test_fast_response_equals_the_keyword_built_one(
    joint_type: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    robot = RobotModel.from_urdf(
        serial_arm_urdf(ARM6_AXES, joint_type=joint_type), "base_link", "tool"
    )
    report, request = mixed_report(robot)
    feasible = [e.feasible for e in report.ranking.evaluations]
    assert feasible.count(False) == 1 and len(feasible) == 4  # the mix this test is about
    regions = [len(a.regions) for a in report.iso if a.feasible]
    assert regions == [12, 12, 12]  # every ISO/TS 15066 region of each feasible grasp
    fast = [report_msg(report, request, "base_link", Time(sec=3), 0.5, c) for c in CONTENTS]
    monkeypatch.setattr(results, "_FAST_POINTS", False)
    monkeypatch.setattr(results, "_copy_pose", results._copy_pose_by_constructors)
    monkeypatch.setattr(results, "_body_region_assessment", keyword_region)
    monkeypatch.setattr(results, "_new_evaluation", keyword_evaluation)
    for content, got in zip(CONTENTS, fast, strict=True):
        want = report_msg(report, request, "base_link", Time(sec=3), 0.5, content)
        assert differences(got, want) == [], content
        # and through the wire: what the client reads back is the same
        wire = deserialize_message(serialize_message(got), GraspRanking)
        assert differences(wire, deserialize_message(serialize_message(want), GraspRanking)) == []
        trajectories = [e for e in got.evaluations if e.joint_trajectory.points]
        assert len(trajectories) == min(content.joint_trajectories, 3)
        assert all(
            len(e.effective_mass_kg) == (21 if content.per_sample else 0) for e in trajectories
        )


def test_differences_sees_a_changed_bit() -> None:
    report, request = mixed_report(
        RobotModel.from_urdf(serial_arm_urdf(ARM6_AXES), "base_link", "tool")
    )
    message = report_msg(report, request, "base_link", Time(), 0.0)
    other = copy.deepcopy(message)
    assert differences(message, other) == []
    point = other.evaluations[other.order[0]].joint_trajectory.points[3]
    point.velocities[1] = np.nextafter(point.velocities[1], np.inf)
    other.evaluations[0].iso_ts_15066[2].worst_force_ratio = -0.0
    assert len(differences(message, other)) == 2
