"""Core results to messages: evaluations, rankings, safety reports, joint trajectories."""

from __future__ import annotations

import array
from collections.abc import Collection, Mapping, Sequence

import numpy as np
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, Pose, PoseArray, Quaternion
from grasp_safety_msgs.msg import BodyRegionAssessment, GraspRanking
from grasp_safety_msgs.msg import GraspEvaluation as GraspEvaluationMsg
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ...core.analyses.iso15066 import PowerForceLimitAssessment, RegionAssessment
from ...core.analyses.retime import most_binding
from ...core.analyses.safety_report import SafetyReport
from ...core.analyses.whole_arm import WholeArmEvaluation, whole_arm_score
from ...core.method.executable import rates_for_execution
from ...core.method.posture import single_posture
from ...core.method.ranking import GraspEvaluation, Ranking
from ...core.method.results import PostureSelection
from ...core.model.armature import armature_ratio
from ...core.model.robot import NO_ARMATURE_NOTE
from ..service.response import ResponseContent
from ._fast import (
    _slot_constructor,
    _template_constructor,
    collector_paused,
    float64_array,
    has_slots,
)

NAN = float("nan")
FULL_RESPONSE = ResponseContent()
"""Every joint trajectory and every per-sample array: what a message built without the node's
``response.*`` parameters carries."""


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


_new_pose = _slot_constructor(Pose, ("position", "orientation"))
_new_point = _slot_constructor(Point, ("x", "y", "z"))
_new_quaternion = _slot_constructor(Quaternion, ("x", "y", "z", "w"))
_EVALUATION_TEMPLATE = GraspEvaluationMsg(
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
    score_armature_lower=NAN,
    score_armature_upper=NAN,
    armature_min_effective_mass_kg=NAN,
    armature_max_effective_mass_kg=NAN,
    safe_duration_s=NAN,
)
"""A GraspEvaluation message whose analysis fields say "not computed" (NaN, empty, false)."""
_new_evaluation = _template_constructor(_EVALUATION_TEMPLATE)
"""GraspEvaluation messages equal to _EVALUATION_TEMPLATE but for the fields given."""


_FAST_POINTS = has_slots(
    JointTrajectoryPoint, ("positions", "velocities", "accelerations", "effort", "time_from_start")
) and has_slots(Duration, ("sec", "nanosec"))
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
    if not _FAST_POINTS:
        rows = zip(
            nanoseconds,
            np.asarray(joint_positions, dtype=float).tolist(),
            velocities.tolist(),
            accelerations.tolist(),
            strict=True,
        )
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
    # Each row's array('d') is made from a slice of its field's bytes (one buffer per field),
    # a third of the cost of converting the row's floats one by one.
    positions, rates, second = (
        np.ascontiguousarray(a, dtype=np.float64).tobytes()
        for a in (joint_positions, velocities, accelerations)
    )
    width = 8 * np.shape(joint_positions)[1]
    new_point, new_duration = JointTrajectoryPoint.__new__, Duration.__new__
    check_point, check_duration = _POINT_CHECK_FIELDS, _DURATION_CHECK_FIELDS
    points = []
    for start, ns in zip(range(0, len(positions), width), nanoseconds, strict=True):
        end = start + width
        stamp = new_duration(Duration)
        stamp._sec, stamp._nanosec = ns // 1_000_000_000, ns % 1_000_000_000
        stamp._check_fields = check_duration
        point = new_point(JointTrajectoryPoint)
        point._positions = array.array("d", positions[start:end])
        point._velocities = array.array("d", rates[start:end])
        point._accelerations, point._effort = array.array("d", second[start:end]), array.array("d")
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
    message.postures_stopped = int(posture.postures_stopped)


def ranked_pose_array(grasps: PoseArray, order: Sequence[int]) -> PoseArray:
    """The feasible grasps of a request, safest first, in the request's frame (poses as given)."""
    return PoseArray(
        header=Header(stamp=grasps.header.stamp, frame_id=grasps.header.frame_id),
        poses=[_copy_pose(grasps.poses[i]) for i in order],
    )


def _copy_pose_by_constructors(pose: Pose) -> Pose:
    p, q = pose.position, pose.orientation
    return _new_pose(_new_point(p.x, p.y, p.z), _new_quaternion(q.x, q.y, q.z, q.w))


def _copy_pose_by_slots(pose: Pose) -> Pose:
    """_copy_pose_by_constructors for Jazzy's classes: each slot stored by name, a fifth of
    the cost of the slot constructors' loops."""
    p, q = pose.position, pose.orientation
    point, quaternion, copy = _NEW_POINT(Point), _NEW_QUATERNION(Quaternion), _NEW_POSE(Pose)
    point._x, point._y, point._z, point._check_fields = p.x, p.y, p.z, _POINT_CHECKS
    quaternion._x, quaternion._y, quaternion._z, quaternion._w = q.x, q.y, q.z, q.w
    quaternion._check_fields = _QUATERNION_CHECKS
    copy._position, copy._orientation, copy._check_fields = point, quaternion, _POSE_CHECKS
    return copy


_NEW_POINT, _NEW_QUATERNION, _NEW_POSE = Point.__new__, Quaternion.__new__, Pose.__new__
_POINT_CHECKS, _QUATERNION_CHECKS = Point()._check_fields, Quaternion()._check_fields
_POSE_CHECKS = Pose()._check_fields
_copy_pose = (
    _copy_pose_by_slots
    if has_slots(Point, ("x", "y", "z"))
    and has_slots(Quaternion, ("x", "y", "z", "w"))
    and has_slots(Pose, ("position", "orientation"))
    else _copy_pose_by_constructors
)
"""A copy of a Pose message (the request's grasp, in ``ranked_grasps``)."""


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


_REGION_FIELDS = (
    "region",
    "transient_contact_permitted",
    "worst_force_ratio",
    "peak_contact_force_n",
    "max_transient_force_n",
    "min_max_permissible_speed_m_s",
    "admissible",
    "min_duration_s",
)
_NEW_REGION, _REGION_CHECKS = BodyRegionAssessment.__new__, BodyRegionAssessment()._check_fields


def _region_by_slots(
    region: str,
    permitted: bool,
    worst_force_ratio: float,
    peak_contact_force_n: float,
    max_transient_force_n: float,
    min_speed_m_s: float,
    admissible: bool,
    min_duration_s: float,
) -> BodyRegionAssessment:
    """A BodyRegionAssessment of its fields (in _REGION_FIELDS order, field types) with each
    slot stored by name: a fifth of the cost of _slot_constructor's loop (12 regions per
    grasp)."""
    message = _NEW_REGION(BodyRegionAssessment)
    message._region, message._transient_contact_permitted = region, permitted
    message._worst_force_ratio, message._peak_contact_force_n = (
        worst_force_ratio,
        peak_contact_force_n,
    )
    message._max_transient_force_n = max_transient_force_n
    message._min_max_permissible_speed_m_s = min_speed_m_s
    message._admissible, message._min_duration_s = admissible, min_duration_s
    message._check_fields = _REGION_CHECKS
    return message


_body_region_assessment = (
    _region_by_slots
    if has_slots(BodyRegionAssessment, _REGION_FIELDS)
    else _slot_constructor(BodyRegionAssessment, _REGION_FIELDS)
)


def region_assessment_msg(assessment: RegionAssessment) -> BodyRegionAssessment:
    """grasp_safety_msgs/BodyRegionAssessment of one region's ISO/TS 15066 assessment.

    Where transient contact is not permitted, the core's ratio (inf while the point moves)
    becomes NaN, as does the null limit F_tr; ``min_duration_s`` keeps the core's inf.
    """
    region = assessment.region
    permitted = region.transient_contact_permitted
    limit = region.max_transient_force_n
    return _body_region_assessment(
        region.name,
        bool(permitted),
        float(assessment.worst_force_ratio) if permitted else NAN,
        float(assessment.peak_contact_force_n),
        float(limit) if limit is not None else NAN,
        assessment.min_max_permissible_speed_m_s,
        bool(assessment.admissible),
        float(assessment.min_duration_s),
    )


def _set_iso(message: GraspEvaluationMsg, assessment: PowerForceLimitAssessment) -> None:
    message.iso_ts_15066 = [region_assessment_msg(r) for r in assessment.regions]
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
    _set_armature_range(message, report)
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
    carried = content.with_joint_trajectory(report.order, len(message.evaluations))
    _set_joint_trajectories(message, report.ranking.joint_names, motions, carried, base_frame)
    _set_retimed(message, report, carried, base_frame)
    return message


def _set_retimed(
    message: GraspRanking, report: SafetyReport, carried: Collection[int], base_frame: str
) -> None:
    """``safe_duration_s`` and ``retime_binding`` of every retimed grasp, ``retime_reason`` of
    the others, and ``retimed_trajectory`` of those among ``carried`` (the grasps that carry
    their joint trajectory)."""
    for k, motion in enumerate(report.retimed):
        evaluation = message.evaluations[k]
        if motion is None:
            evaluation.retime_reason = report.retime_reasons[k]
            continue
        evaluation.safe_duration_s = float(motion.safe_duration_s)
        evaluation.retime_binding = most_binding(motion)
        if evaluation.index in carried:
            evaluation.retimed_trajectory = joint_trajectory_msg(
                report.ranking.joint_names,
                motion.times_s,
                motion.positions,
                Header(frame_id=base_frame),
                (motion.velocities, motion.accelerations),
            )


def _set_armature_range(message: GraspRanking, report: SafetyReport) -> None:
    """The armature-range fields (GraspRanking and each GraspEvaluation), when ranges ran."""
    spread = report.armature_range
    if spread is None:
        return
    message.armature_lower_kgm2 = float64_array(spread.lower_kgm2)
    message.armature_upper_kgm2 = float64_array(spread.upper_kgm2)
    message.armature_order_lower = [int(i) for i in spread.order_lower]
    message.armature_order_upper = [int(i) for i in spread.order_upper]
    message.armature_ranking_flips = bool(spread.ranking_flips)
    message.armature_range_message = spread.message
    for k, evaluation in enumerate(message.evaluations):
        evaluation.score_armature_lower = float(spread.scores_lower[k])
        evaluation.score_armature_upper = float(spread.scores_upper[k])
        low, high = spread.effective_mass_range_kg[k]
        evaluation.armature_min_effective_mass_kg = float(low)
        evaluation.armature_max_effective_mass_kg = float(high)
