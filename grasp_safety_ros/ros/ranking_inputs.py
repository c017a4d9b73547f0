"""A ranking request converted and checked against the node's settings, and its computation:
GraspSafetyEvaluator.rank, select_postures, then analyse (plain Python, no rclpy)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Inertia, PoseArray
from nav_msgs.msg import Path
from trajectory_msgs.msg import JointTrajectory, MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from ..core.analyses.exposed_points import check_metric_point
from ..core.analyses.safety_report import AnalysisOptions, SafetyReport, analyse, posture_criterion
from ..core.exceptions import InvalidInputError
from ..core.method.posture import select_postures
from ..core.method.ranking import Grasp, Ranking, check_metric
from ..core.model.inertia import ObjectInertia
from ..core.model.trajectory import ObjectTrajectory
from ..core.model.waypoint_trajectory import WaypointTrajectory
from .conversions import (
    grasps_from_pose_array,
    grasps_with_joint_trajectories,
    markers_msg,
    object_inertia_from_msg,
    seed_from_joint_state,
    trajectory_from_msg,
)
from .parameters import NodeSettings
from .ranking_job import Snapshot, labels_only
from .robot_bundle import RobotBundle


@dataclass(frozen=True)
class RankingInputs:
    """What one ranking computes: the request in core types, checked against the settings."""

    trajectory: ObjectTrajectory | WaypointTrajectory
    grasps: list[Grasp]
    object_inertia: ObjectInertia
    metric: str
    options: AnalysisOptions
    seed: np.ndarray | None


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
) -> RankingInputs:
    """The request's messages converted and checked (GraspSafetyNode._rank's arguments).
    Raises GraspSafetyError naming the field."""
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
    seed = bundle.seed
    if seed is None and settings.use_joint_states_seed and state.joint_state is not None:
        seed = seed_from_joint_state(*state.joint_state, bundle.robot)
    return RankingInputs(trajectory, grasps, object_inertia, metric, options, seed)


def compute_ranking(
    bundle: RobotBundle,
    settings: NodeSettings,
    inputs: RankingInputs,
    deadline_check: Callable[[int, int], None],
) -> tuple[Ranking, SafetyReport]:
    """Rank, select postures, analyse; ``deadline_check`` is the progress callback."""
    grasps, object_inertia, trajectory = inputs.grasps, inputs.object_inertia, inputs.trajectory
    metric, options, seed = inputs.metric, inputs.options, inputs.seed
    ranking = bundle.evaluator.rank(
        grasps,
        object_inertia,
        trajectory,
        seed_positions=seed,
        metric=metric,
        progress=deadline_check,
    )
    ranking = select_postures(
        bundle.evaluator,
        grasps,
        object_inertia,
        trajectory,
        ranking,
        settings.posture,
        progress=deadline_check,
        criterion=posture_criterion(bundle.robot, options),
    )
    report = analyse(
        bundle.evaluator,
        grasps,
        object_inertia,
        trajectory,
        options,
        ranking=ranking,
        progress=deadline_check,
    )
    return ranking, report


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
    if metric_point != "tip" and defaults.points_in_object_m is None:
        raise InvalidInputError(
            "metric_point",
            f"{metric_point!r} needs the object's points: set the node parameter "
            "object.points_in_object_m, object.box_size_m or object.cylinder_*",
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
