"""ros.conversions.results, .markers and ._fast (no rclpy context): core rankings and safety
reports to messages, the markers, and the fast message constructors."""

from __future__ import annotations

import copy
import gc
import math
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import (
    Pose,
    PoseArray,
)
from grasp_safety_msgs.msg import BodyRegionAssessment
from grasp_safety_msgs.msg import GraspEvaluation as GraspEvaluationMsg
from std_msgs.msg import Header
from trajectory_msgs.msg import (
    JointTrajectory,
)
from visualization_msgs.msg import Marker

from grasp_safety_ros.core import (
    Grasp,
    GraspSafetyEvaluator,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.analyses.exposed_points import box_corners_in_object
from grasp_safety_ros.core.analyses.safety_report import AnalysisOptions, SafetyReport, analyse
from grasp_safety_ros.core.analyses.uncertainty import InertiaUncertainty
from grasp_safety_ros.core.method.executable import joint_velocities_accelerations
from grasp_safety_ros.core.method.posture import PostureConfig
from grasp_safety_ros.core.method.ranking import GraspEvaluation, Ranking
from grasp_safety_ros.core.pipeline import PipelineRequest, run_pipeline
from grasp_safety_ros.ros import conversions
from grasp_safety_ros.ros.conversions import (
    _fast,
    duration_msg,
    markers_msg,
    pose_msg_from_transform,
    rank_color,
    ranking_msg,
    report_msg,
    results,
)
from grasp_safety_ros.ros.service.response import ResponseContent

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
        directions = np.reshape(got.direction_xyz, (-1, 3))
        np.testing.assert_array_equal(directions, want.directions_in_base)
        assert list(got.direction_is_worst_case) == want.direction_is_worst_case.tolist()
    unreachable = message.evaluations[2]
    assert math.isnan(unreachable.score) and math.isnan(unreachable.peak_effective_mass_kg)
    assert unreachable.reason and len(unreachable.effective_mass_kg) == 0


def test_duration_message_rounds_to_the_nanosecond_with_carry() -> None:
    assert (duration_msg(0.0).sec, duration_msg(0.0).nanosec) == (0, 0)
    assert (duration_msg(1.25).sec, duration_msg(1.25).nanosec) == (1, 250_000_000)
    assert (duration_msg(1.9999999999).sec, duration_msg(1.9999999999).nanosec) == (2, 0)
    assert (duration_msg(0.02).sec, duration_msg(0.02).nanosec) == (0, 20_000_000)


def test_joint_trajectory_and_posture_fields_round_trip(arm6: RobotModel) -> None:
    _, grasps, trajectory = _ranking(arm6)
    obj = solid_box(0.5, [0.1, 0.1, 0.1])
    request = PipelineRequest(tuple(grasps), obj, trajectory, posture=PostureConfig(4))
    selected = run_pipeline(GraspSafetyEvaluator(arm6), request).ranking
    request = PoseArray(
        header=Header(frame_id="object"),
        poses=[pose_msg_from_transform(g.transform_tip_to_object) for g in grasps],
    )
    message = ranking_msg(selected, request, "base_link", Time(sec=9), 0.25)
    for got, want, posture in zip(
        message.evaluations, selected.evaluations, selected.postures, strict=True
    ):
        trajectory_msg = got.joint_trajectory
        assert trajectory_msg.header.frame_id == "base_link"
        assert list(trajectory_msg.joint_names) == list(arm6.joint_names)
        assert len(trajectory_msg.points) == len(want.times_s)
        positions = np.array([p.positions for p in trajectory_msg.points]).reshape(-1, 6)
        velocities = np.array([p.velocities for p in trajectory_msg.points]).reshape(-1, 6)
        accelerations = np.array([p.accelerations for p in trajectory_msg.points]).reshape(-1, 6)
        times = [
            p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in trajectory_msg.points
        ]
        qd, qdd = joint_velocities_accelerations(want.times_s, want.joint_positions)
        np.testing.assert_array_equal(positions, want.joint_positions)
        np.testing.assert_array_equal(velocities, qd.reshape(-1, 6))
        np.testing.assert_array_equal(accelerations, qdd.reshape(-1, 6))
        np.testing.assert_allclose(times, want.times_s, rtol=0, atol=1e-9)
        assert got.postures_tried == posture.postures_tried
        assert got.postures_feasible == posture.postures_feasible
        assert got.postures_stopped == posture.postures_stopped
        np.testing.assert_array_equal(got.start_positions, posture.start_positions)
        for field, value in (
            ("score_single_ik", posture.score_single_ik),
            ("score_range_min", posture.score_range[0]),
            ("score_range_max", posture.score_range[1]),
        ):
            assert getattr(got, field) == value or (
                math.isnan(getattr(got, field)) and math.isnan(value)
            )
    unreachable = message.evaluations[2]
    assert not unreachable.joint_trajectory.points and unreachable.postures_feasible == 0
    assert list(unreachable.start_positions) == []


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
    assert len(message.evaluations[0].direction_xyz) == 0


# --- Safety reports (issue #6) -----------------------------------------------------------------


def _report(arm6: RobotModel, **options: object) -> tuple[SafetyReport, PoseArray]:
    ranking, grasps, trajectory = _ranking(arm6)
    inertia = solid_box(0.5, [0.1, 0.1, 0.1])
    report = analyse(
        GraspSafetyEvaluator(arm6),
        grasps,
        inertia,
        trajectory,
        AnalysisOptions(**options),  # type: ignore[arg-type]
        ranking=ranking,
    )
    request = PoseArray(
        header=Header(frame_id="object"),
        poses=[pose_msg_from_transform(g.transform_tip_to_object) for g in grasps],
    )
    return report, request


def test_report_message_with_default_options_is_the_ranking_message(arm6: RobotModel) -> None:
    report, request = _report(arm6)
    message = report_msg(report, request, "base_link", Time(sec=3), 0.5)
    plain = ranking_msg(report.ranking, request, "base_link", Time(sec=3), 0.5)
    assert list(message.order) == list(plain.order) == list(report.ranking.order)
    assert list(message.safety_order) == list(message.paper_order) == list(message.order)
    assert list(message.ranked_grasps.poses) == list(plain.ranked_grasps.poses)
    assert (message.metric_point, message.rank_by) == ("tip", "safety")
    assert list(message.pareto_set) == [] and math.isnan(message.safety_weight)
    assert math.isnan(message.order_stability) and message.uncertainty_message == ""
    for got, old in zip(message.evaluations, plain.evaluations, strict=True):
        for name in ("index", "feasible", "effective_mass_kg", "time_from_start_s"):
            assert getattr(got, name) == getattr(old, name)
        assert got.score == old.score or (math.isnan(got.score) and math.isnan(old.score))
        for name in ("grasp_quality", "combined_score", "worst_case_score"):
            assert math.isnan(getattr(got, name)), name
        assert len(got.leading_point_effective_mass_kg) == 0
        # effort is on by default (core.options): the torques, without changing the order
        effort = report.effort[got.index]
        assert got.effort_score == effort.score() or math.isnan(effort.score())
        assert len(got.peak_abs_torque) == (len(message.joint_names) if got.feasible else 0)
        assert not got.redundancy_applied and math.isnan(got.score_without_redundancy)
        if got.feasible:
            assert got.safety_score == got.score
            assert len(got.iso_ts_15066) == 12  # every region by default
        else:
            assert math.isnan(got.safety_score) and got.iso_ts_15066 == []
            assert not got.iso_admissible and math.isnan(got.iso_min_duration_s)


def test_report_message_content_drops_only_what_it_is_told(arm6: RobotModel) -> None:
    report, request = _report(arm6, points_in_object_m=box_corners_in_object([0.1, 0.1, 0.1]))
    full = report_msg(report, request, "base_link", Time(sec=3), 0.5)
    first = report.order[0]
    for content, with_trajectory in (
        (ResponseContent(1, per_sample=False), {first}),
        (ResponseContent(0, per_sample=True), set()),
    ):
        message = report_msg(report, request, "base_link", Time(sec=3), 0.5, content)
        expected = copy.deepcopy(full)
        for item in expected.evaluations:
            if item.index not in with_trajectory:
                item.joint_trajectory = JointTrajectory()
            if not content.per_sample:
                for name in (
                    "time_from_start_s",
                    "effective_mass_kg",
                    "direction_xyz",
                    "direction_is_worst_case",
                    "leading_point_effective_mass_kg",
                    "worst_point_effective_mass_kg",
                    "links_only_effective_mass_kg",
                ):
                    setattr(item, name, getattr(GraspEvaluationMsg(), name))  # empty
        assert repr(message) == repr(expected)  # every field; NaN-safe, unlike ==
        assert len(full.evaluations[first].leading_point_effective_mass_kg) > 0
        assert len(full.evaluations[first].joint_trajectory.points) > 0


PER_SAMPLE_BYTES = 8 + 8 + 8 + 3 * 8 + 1
"""A feasible grasp's per-sample arrays by default, per sample (CDR: float64 8 bytes, bool 1):
time_from_start_s, effective_mass_kg, links_only_effective_mass_kg, direction_xyz (3), and
direction_is_worst_case; docs/ros/interface.md quotes it."""


def test_response_grows_by_the_per_sample_arrays_per_grasp_and_sample(arm6: RobotModel) -> None:
    """The serialised response (default analyses, no joint trajectory) of the same motion
    sampled 101 and 201 times grows by PER_SAMPLE_BYTES per feasible grasp and sample, to
    the CDR alignment padding (at most 7 bytes per array, five arrays per grasp)."""
    from rclpy.serialization import serialize_message

    sizes, samples, feasible = [], [], []
    for dt_s in (0.01, 0.005):
        ranking, grasps, trajectory = _ranking(arm6)
        moved = ObjectTrajectory(
            trajectory.transform_object_to_base_start,
            trajectory.transform_object_to_base_goal,
            1.0,
            dt_s,
        )
        inertia = solid_box(0.5, [0.1, 0.1, 0.1])
        evaluator = GraspSafetyEvaluator(arm6)
        seed = ranking.evaluations[0].joint_positions[0]
        ranked = evaluator.rank(grasps, inertia, moved, seed)
        report = analyse(evaluator, grasps, inertia, moved, AnalysisOptions(), ranking=ranked)
        request = PoseArray(
            header=Header(frame_id="object"),
            poses=[pose_msg_from_transform(g.transform_tip_to_object) for g in grasps],
        )
        content = ResponseContent(joint_trajectories=0)
        message = report_msg(report, request, "base_link", Time(), 0.0, content)
        sizes.append(len(serialize_message(message)))
        samples.append(len(moved.times_s()))
        feasible.append(sum(e.feasible for e in ranked.evaluations))
    assert samples == [101, 201] and feasible[0] == feasible[1] == 2
    growth = sizes[1] - sizes[0]
    assert abs(growth - PER_SAMPLE_BYTES * 2 * 100) <= 2 * 5 * 7, growth


def test_collector_is_paused_while_building_and_restored_after(arm6: RobotModel) -> None:
    report, request = _report(arm6)
    states: list[bool] = []
    original = results._report_msg

    def spying(*args: Any) -> Any:
        states.append(gc.isenabled())
        with _fast.collector_paused:  # nested (as a concurrent build): still paused
            states.append(gc.isenabled())
        states.append(gc.isenabled())
        return original(*args)

    assert gc.isenabled()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(results, "_report_msg", spying)
        report_msg(report, request, "base_link", Time(), 0.0)
        assert states == [False, False, False] and gc.isenabled()
        gc.disable()  # someone else's choice is kept
        try:
            report_msg(report, request, "base_link", Time(), 0.0)
            assert not gc.isenabled()
        finally:
            gc.enable()
        patch.setattr(results, "_report_msg", lambda *args: 1 / 0)
        with pytest.raises(ZeroDivisionError):
            report_msg(report, request, "base_link", Time(), 0.0)
        assert gc.isenabled()


def test_report_message_carries_every_analysis(arm6: RobotModel) -> None:
    points = box_corners_in_object([0.1, 0.1, 0.1])
    report, request = _report(
        arm6,
        metric_point="worst_point",
        points_in_object_m=points,
        iso_regions=("chest", "face"),
        uncertainty=InertiaUncertainty(mass_fraction=0.3, num_random_samples=3),
        grasp_quality=(0.2, 0.9, 0.5),
        safety_weight=0.25,
        effort=True,
        effort_criterion="rms_fraction",
    )
    message = report_msg(report, request, "base_link", Time(), 0.0)
    assert list(message.order) == list(report.order) == list(report.quality.order)
    assert list(message.safety_order) == list(report.safety_order)
    assert list(message.paper_order) == list(report.ranking.order)
    assert list(message.ranked_grasps.poses) == [request.poses[i] for i in report.order]
    assert list(message.pareto_set) == list(report.quality.pareto_set)
    assert message.metric_point == "worst_point" and message.safety_weight == 0.25
    assert message.effort_criterion == "rms_fraction"
    uncertainty = report.uncertainty
    assert uncertainty is not None
    assert message.ranking_flips == uncertainty.ranking_flips
    assert message.order_stability == uncertainty.order_stability
    assert list(message.worst_case_order) == list(uncertainty.worst_case_order)
    assert message.uncertainty_message == uncertainty.message
    for k, got in enumerate(message.evaluations):
        assert got.grasp_quality == (0.2, 0.9, 0.5)[k]
        assert got.pareto_optimal == (k in report.quality.pareto_set)
        if not got.feasible:
            assert got.iso_ts_15066 == [] and len(got.peak_abs_torque) == 0
            assert math.isnan(got.combined_score) and math.isnan(got.effort_score)
            assert got.probability_safest == 0.0
            continue
        exposed, effort, spread = report.exposed[k], report.effort[k], uncertainty.grasps[k]
        assert got.safety_score == report.scores[k] == np.mean(exposed.worst_effective_mass_kg)
        np.testing.assert_array_equal(
            got.worst_point_effective_mass_kg, exposed.worst_effective_mass_kg
        )
        np.testing.assert_array_equal(
            got.leading_point_effective_mass_kg, exposed.leading_effective_mass_kg
        )
        assert got.combined_score == report.quality.combined[k]
        assert (got.worst_case_score, got.percentile_score, got.probability_safest) == (
            spread.worst_case_score,
            spread.percentile_score,
            spread.probability_safest,
        )
        np.testing.assert_array_equal(got.peak_abs_torque, effort.peak_abs_torque)
        np.testing.assert_array_equal(got.rms_torque, effort.rms_torque)
        assert got.effort_score == effort.score("rms_fraction")
        iso = report.iso[k]
        assert [r.region for r in got.iso_ts_15066] == ["chest", "face"]
        assert got.iso_admissible == iso.admissible_where_permitted
        assert got.iso_limiting_region == iso.limiting_region == "chest"
        assert got.iso_min_duration_s == iso.min_duration_s
        chest, face = got.iso_ts_15066
        want = iso.region("chest")
        assert chest.transient_contact_permitted and chest.max_transient_force_n == 280.0
        assert chest.worst_force_ratio == want.worst_force_ratio
        assert chest.peak_contact_force_n == want.peak_contact_force_n
        assert chest.min_max_permissible_speed_m_s == np.min(want.max_permissible_speed_m_s)
        assert chest.min_duration_s == want.min_duration_s and chest.admissible == want.admissible
        # face: no transient contact permitted; the core's inf ratio and null limit are NaN
        assert not face.transient_contact_permitted and not face.admissible
        assert math.isnan(face.worst_force_ratio) and math.isnan(face.max_transient_force_n)
        assert face.min_max_permissible_speed_m_s == 0.0 and math.isinf(face.min_duration_s)


def test_report_message_carries_the_whole_arm(arm6: RobotModel) -> None:
    report, request = _report(
        arm6,
        rank_by="whole_arm",
        whole_arm_region="upper_arm_elbow",
        arm_points_m={"link4": [[0.1, 0, 0]]},
    )
    message = report_msg(report, request, "base_link", Time(), 0.0)
    assert message.rank_by == "whole_arm" and message.whole_arm_region == "upper_arm_elbow"
    assert list(message.whole_arm_sites) == ["j3", "j4", "j5", "j6", "tool", "link4[0]"]
    assert list(message.order) == list(report.order)
    forces = []
    for k, got in enumerate(message.evaluations):
        whole = report.whole_arm[k]
        if not got.feasible:
            assert math.isnan(got.whole_arm_rank_force_n) and got.whole_arm_worst_site == ""
            continue
        elbow = whole.region("upper_arm_elbow")
        assert got.whole_arm_rank_force_n == elbow.peak_contact_force_n
        forces.append((got.whole_arm_rank_force_n, k))
        limiting = whole.region(whole.limiting_region)
        assert got.whole_arm_limiting_region == whole.limiting_region
        assert got.whole_arm_worst_force_ratio == limiting.worst_force_ratio
        assert got.whole_arm_worst_site == whole.site_names[limiting.worst_site]
        assert got.whole_arm_worst_link == whole.site_links[limiting.worst_site]
        assert got.whole_arm_min_duration_s == whole.min_duration_s
        assert got.whole_arm_admissible == whole.admissible_where_permitted
        assert got.whole_arm_worst_energy_j == whole.worst_energy[0] > 0.0
    assert list(message.order) == [k for _, k in sorted(forces)]


def test_markers_follow_the_given_order_and_flag_iso(arm6: RobotModel) -> None:
    ranking, grasps, trajectory = _ranking(arm6)
    order = tuple(reversed(ranking.order))
    scores = [1.5, 2.5, float("nan")]
    markers = markers_msg(
        ranking,
        grasps,
        trajectory,
        "base_link",
        Time(),
        order=order,
        scores=scores,
        not_admissible={order[0]},
    ).markers
    labels = {m.id: m for m in markers if m.type == Marker.TEXT_VIEW_FACING}
    arrows = {m.id: m for m in markers if m.type == Marker.ARROW}
    first = order[0]
    assert labels[first].text == (
        f"#1 {grasps[first].name}: {scores[first]:.3f} kg, ISO/TS 15066: not admissible"
    )
    assert (arrows[first].color.r, arrows[first].color.g) == (0.0, 1.0)
    assert labels[order[1]].text == f"#2 {grasps[order[1]].name}: {scores[order[1]]:.3f} kg"
    left_out = markers_msg(ranking, grasps, trajectory, "b", Time(), order=order[:1]).markers
    text = {m.id: m.text for m in left_out if m.type == Marker.TEXT_VIEW_FACING}
    assert text[order[1]].endswith("not ranked") and text[2] == "unreachable: infeasible"


def test_directions_round_trip_through_the_flat_field_exactly() -> None:
    """numpy (N, 3) -> GraspEvaluation.direction_xyz -> serialised and read back ->
    reshape(-1, 3): the same numbers, bit for bit, rows in sample order."""
    from rclpy.serialization import deserialize_message, serialize_message

    rng = np.random.default_rng(6)
    directions = rng.normal(size=(7, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    directions[3] = [np.nextafter(1.0, 0.0), -0.0, 5e-324]  # exact to the last bit
    evaluation = GraspEvaluation(
        index=0,
        name="g",
        feasible=True,
        reason="",
        score=1.0,
        times_s=np.linspace(0.0, 1.0, 7),
        joint_positions=np.zeros((7, 2)),
        directions_in_base=np.asfortranarray(directions),  # column-major in memory
        effective_mass_kg=np.ones(7),
        direction_is_worst_case=np.zeros(7, dtype=bool),
        tip_speed_m_s=np.ones(7),
        ik_iterations=np.zeros(7, dtype=int),
    )
    message = conversions.evaluation_msg(evaluation)
    assert message.direction_xyz.typecode == "d" and len(message.direction_xyz) == 21
    assert list(message.direction_xyz[3:6]) == list(directions[1])  # sample 1: x, y, z
    back = deserialize_message(serialize_message(message), GraspEvaluationMsg)
    np.testing.assert_array_equal(np.reshape(back.direction_xyz, (-1, 3)), directions)
    assert np.signbit(np.reshape(back.direction_xyz, (-1, 3))[3, 1])
    assert len(conversions.evaluation_msg(evaluation, per_sample=False).direction_xyz) == 0


def test_evaluation_messages_equal_the_keyword_constructor_and_share_nothing() -> None:
    """The slot-filling construction of GraspEvaluation gives what the generated keyword
    constructor gives, and two messages share no mutable field."""
    evaluation = GraspEvaluation(
        index=3,
        name="g",
        feasible=True,
        reason="",
        score=1.25,
        times_s=np.array([0.0, 0.5]),
        joint_positions=np.zeros((2, 2)),
        directions_in_base=np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
        effective_mass_kg=np.array([1.0, 1.5]),
        direction_is_worst_case=np.array([False, True]),
        tip_speed_m_s=np.zeros(2),
        ik_iterations=np.zeros(2, dtype=int),
    )
    nan = float("nan")
    expected = GraspEvaluationMsg(
        index=3,
        name="g",
        feasible=True,
        reason="",
        score=1.25,
        peak_effective_mass_kg=1.5,
        mean_effective_mass_kg=1.25,
        time_from_start_s=[0.0, 0.5],
        effective_mass_kg=[1.0, 1.5],
        direction_xyz=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        direction_is_worst_case=[False, True],
        safety_score=1.25,
        iso_min_duration_s=nan,
        worst_case_score=nan,
        percentile_score=nan,
        probability_safest=nan,
        grasp_quality=nan,
        combined_score=nan,
        score_without_redundancy=nan,
        effort_score=nan,
        score_single_ik=nan,
        score_range_min=nan,
        score_range_max=nan,
        whole_arm_rank_force_n=nan,
        whole_arm_worst_force_ratio=nan,
        whole_arm_min_duration_s=nan,
        whole_arm_worst_energy_j=nan,
        links_only_effective_mass_kg=[1.0, 1.5],  # no armature: the same masses
        links_only_mean_effective_mass_kg=1.25,
        score_armature_lower=nan,
        score_armature_upper=nan,
        armature_min_effective_mass_kg=nan,
        armature_max_effective_mass_kg=nan,
        safe_duration_s=nan,
    )
    first, second = (conversions.evaluation_msg(evaluation) for _ in range(2))
    assert repr(first) == repr(expected)  # every field; NaN-safe, unlike ==
    first.iso_ts_15066.append(BodyRegionAssessment())
    first.peak_abs_torque.append(1.0)
    first.joint_trajectory.joint_names.append("j")
    first.retimed_trajectory.joint_names.append("j")
    assert repr(second) == repr(expected)
    empty = conversions.evaluation_msg(evaluation, per_sample=False)
    assert len(empty.time_from_start_s) == len(empty.direction_is_worst_case) == 0
