"""A ranking request's messages converted and checked against the node's settings into the
core's PipelineRequest (core.pipeline runs it), and the markers of its report (plain Python,
no rclpy)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Inertia, PoseArray
from nav_msgs.msg import Path
from trajectory_msgs.msg import JointTrajectory, MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from ...core.analyses.exposed_points import check_metric_point, check_metric_point_has_points
from ...core.analyses.safety_report import AnalysisOptions, SafetyReport
from ...core.exceptions import InvalidInputError
from ...core.method.ranking import Grasp, Ranking, check_metric
from ...core.model.trajectory import ObjectTrajectory
from ...core.model.waypoint_trajectory import WaypointTrajectory
from ...core.pipeline import PipelineRequest
from ..conversions import (
    grasps_from_pose_array,
    grasps_with_joint_trajectories,
    markers_msg,
    object_inertia_from_msg,
    seed_from_joint_state,
    trajectory_from_msg,
)
from ..robot.bundle import RobotBundle
from .ranking_job import Snapshot, labels_only


def ranking_inputs(
    state: Snapshot,
    bundle: RobotBundle,
    grasps_msg: PoseArray,
    trajectory_msg: Path | MultiDOFJointTrajectory,
    inertia_msg: Inertia | None,
    metric: str,
    grasps_field: str,
    quality: tuple[float, ...] | None,
    metric_point: str,
    quality_field: str,
    joint_trajectories: Sequence[JointTrajectory],
) -> PipelineRequest:
    """The request's messages converted and checked (GraspSafetyNode._rank's arguments), with
    the node's posture settings and the robot's armature range. Raises GraspSafetyError
    naming the field."""
    settings = state.settings
    trajectory = trajectory_from_msg(
        trajectory_msg,
        settings.base_frame,
        settings.trajectory_dt_s,
        settings.trajectory_duration_s,
        settings.max_samples,
    )
    grasps = grasps_from_pose_array(
        grasps_msg,
        settings.object_frame,
        settings.base_frame,
        trajectory,
        settings.max_grasps,
        grasps_field,
    )
    grasps = grasps_with_joint_trajectories(
        grasps, joint_trajectories, max_samples=settings.max_samples
    )
    samples = len(trajectory.times_s())
    total = sum(
        samples if g.joint_trajectory is None else len(g.joint_trajectory.times_s) for g in grasps
    )
    if total > settings.max_total_samples:
        raise InvalidInputError(
            f"{grasps_field}.poses",
            f"{len(grasps)} grasps x {samples} samples = {total} samples; at "
            f"most max_total_samples={settings.max_total_samples} are allowed",
        )
    object_inertia = state.inertia_override
    if inertia_msg is not None:
        object_inertia = object_inertia_from_msg(inertia_msg, settings.max_mass_kg)
    object_inertia = object_inertia or settings.object_inertia
    if object_inertia is None:
        raise InvalidInputError(
            "object_inertia",
            "m is 0 and no default object is configured (parameters object.mass_kg, "
            "object.inertia_about_com_kgm2)",
        )
    metric = check_metric(metric or settings.metric, "metric")
    options = analysis_options(
        settings.analysis, len(grasps), quality, metric_point, quality_field
    )
    seed: tuple[float, ...] | np.ndarray | None = bundle.seed
    if seed is None and settings.use_joint_states_seed and state.joint_state is not None:
        seed = seed_from_joint_state(*state.joint_state, bundle.robot)
    return PipelineRequest(
        grasps=tuple(grasps),
        object_inertia=object_inertia,
        trajectory=trajectory,
        metric=metric,
        options=options,
        posture=settings.posture,
        seed_positions=seed,
        armature_range=bundle.armature_range,
    )


def analysis_options(
    defaults: AnalysisOptions,
    num_grasps: int,
    quality: tuple[float, ...] | None,
    metric_point: str,
    quality_field: str,
) -> AnalysisOptions:
    """The parameters' analysis options with a request's quality and metric point."""
    if quality is not None and len(quality) != num_grasps:
        raise InvalidInputError(
            quality_field, f"must have one value per grasp ({num_grasps}), got {len(quality)}"
        )
    metric_point = check_metric_point(metric_point or defaults.metric_point, "metric_point")
    check_metric_point_has_points(
        metric_point,
        defaults.points_in_object_m,
        "set the node parameter object.points_in_object_m, object.box_size_m or object.cylinder_*",
    )
    return replace(defaults, metric_point=metric_point, grasp_quality=quality)


def markers_builder(
    ranking: Ranking,
    report: SafetyReport,
    grasps: Sequence[Grasp],
    trajectory: ObjectTrajectory | WaypointTrajectory,
    base_frame: str,
    stamp: Time,
) -> Callable[[], MarkerArray]:
    """What builds the ranking's markers, maybe later (on demand): it keeps what they need
    only, not the report and its per-sample arrays (0.5 GB kept after a 1,000 x 481
    request)."""
    labels, order, scores = labels_only(ranking), report.order, report.scores
    not_admissible = {
        a.index for a in report.iso if a.feasible and not a.admissible_where_permitted
    }
    tips = [replace(g, joint_trajectory=None) if g.joint_trajectory else g for g in grasps]
    return lambda: markers_msg(
        labels,
        tips,
        trajectory,
        base_frame,
        stamp,
        order=order,
        scores=scores,
        not_admissible=not_admissible,
    )
