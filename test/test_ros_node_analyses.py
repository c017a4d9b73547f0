"""ros.node over real rclpy: the analyses beyond the paper (ISO/TS 15066, grasp quality, leading
point, uncertainty, redundancy) equal the core's (harness: ros_node_harness.py)."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
from grasp_safety_msgs.msg import GraspRanking
from nav_msgs.msg import Path
from ros_node_harness import (
    BOOK,
    BOOK_GRASPS,
    LATCHED,
    NodeUnderTest,
    _localhost_only,  # noqa: F401  (autouse fixture)
    assert_matches_core,
    book_path,
    book_request,
    book_trajectory,
    core_report,
)
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import Marker, MarkerArray

from grasp_safety_ros.core import (
    GraspSafetyEvaluator,
    solid_box,
)
from grasp_safety_ros.core.analyses.iso15066 import assess_grasp
from grasp_safety_ros.core.analyses.multi_objective import rank_with_quality
from grasp_safety_ros.core.analyses.uncertainty import InertiaUncertainty
from grasp_safety_ros.ros.conversions import inertia_msg_from_object

# --- Analyses beyond the paper (issue #6) ------------------------------------------------------


def nan_equal(got: float, want: float) -> bool:
    return (math.isnan(got) and math.isnan(want)) or got == pytest.approx(want, rel=1e-9, abs=1e-9)


def test_default_analyses_leave_the_paper_fields_and_order(
    ros: NodeUnderTest, core_ranking: Any
) -> None:
    response = ros.rank(book_request())
    assert response.success, response.message
    ranking = response.ranking
    assert_matches_core(ranking, core_ranking)  # the old fields, order included
    assert tuple(ranking.safety_order) == tuple(ranking.paper_order) == core_ranking.order
    assert (ranking.metric_point, ranking.rank_by) == ("tip", "safety")
    assert list(ranking.pareto_set) == [] and math.isnan(ranking.safety_weight)
    assert ranking.uncertainty_message == "" and math.isnan(ranking.order_stability)
    for evaluation in ranking.evaluations:
        assert evaluation.safety_score == evaluation.score
        assert math.isnan(evaluation.grasp_quality) and math.isnan(evaluation.combined_score)
        assert math.isnan(evaluation.worst_case_score) and not evaluation.redundancy_applied
        # effort is on by default (core.options): its torques, the order unchanged
        assert len(evaluation.peak_abs_torque) == len(ranking.joint_names)
        # the box gives the exposed points; they do not change the tip score
        count = len(evaluation.effective_mass_kg)
        assert len(evaluation.leading_point_effective_mass_kg) == count
        assert len(evaluation.worst_point_effective_mass_kg) == count


def test_iso_fields_equal_the_core_assessment(ros: NodeUnderTest, core_ranking: Any) -> None:
    response = ros.rank(book_request())
    assert response.success, response.message
    for got, evaluation in zip(
        response.ranking.evaluations, core_ranking.evaluations, strict=True
    ):
        want = assess_grasp(evaluation)  # tip, every region
        assert got.iso_admissible == want.admissible_where_permitted
        assert got.iso_limiting_region == want.limiting_region
        assert got.iso_min_duration_s == pytest.approx(want.min_duration_s, rel=1e-9)
        assert [r.region for r in got.iso_ts_15066] == [r.region.name for r in want.regions]
        for region, expected in zip(got.iso_ts_15066, want.regions, strict=True):
            permitted = expected.transient_contact_permitted
            assert region.transient_contact_permitted == permitted
            assert region.admissible == expected.admissible
            limit = expected.region.max_transient_force_n
            assert nan_equal(region.max_transient_force_n, math.nan if limit is None else limit)
            ratio = expected.worst_force_ratio if permitted else math.nan
            assert nan_equal(region.worst_force_ratio, ratio)
            assert nan_equal(region.peak_contact_force_n, expected.peak_contact_force_n)
            speed = float(np.min(expected.max_permissible_speed_m_s))
            assert nan_equal(region.min_max_permissible_speed_m_s, speed)
            assert region.min_duration_s == pytest.approx(expected.min_duration_s, rel=1e-9)


def test_too_fast_motion_is_not_iso_admissible_and_labelled(ros: NodeUnderTest) -> None:
    markers: list[MarkerArray] = []
    subscription = ros.client.create_subscription(
        MarkerArray, "/grasp_safety/markers", markers.append, LATCHED
    )
    try:
        request = book_request()
        # a book ten times heavier, in 1 s: contact forces above the ISO/TS 15066 limits
        request.object_inertia = inertia_msg_from_object(solid_box(3.4, [0.15, 0.22, 0.015]))
        request.object_trajectory = book_path(duration_s=1.0)
        response = ros.rank(request)
        assert response.success, response.message
        stamp = response.ranking.header.stamp
        assert ros.spin_until(lambda: any(a.markers[0].header.stamp == stamp for a in markers))
        array = next(a for a in markers if a.markers[0].header.stamp == stamp)
        labels = [m.text for m in array.markers if m.type == Marker.TEXT_VIEW_FACING]
        for evaluation in response.ranking.evaluations:
            assert evaluation.feasible, evaluation.reason
            assert not evaluation.iso_admissible
            assert evaluation.iso_min_duration_s > 1.0
        assert len(labels) == 3
        assert all(text.endswith(", ISO/TS 15066: not admissible") for text in labels)
    finally:
        ros.client.destroy_subscription(subscription)


def test_grasp_quality_gives_the_core_combination_and_pareto_set(
    ros: NodeUnderTest, core_ranking: Any
) -> None:
    quality = [0.1, 1.0, 0.0]  # grasp 1 (least safe) has the best quality
    request = book_request()
    request.grasp_quality = quality
    response = ros.rank(request)
    assert response.success, response.message
    ranking = response.ranking
    scores = [e.score for e in core_ranking.evaluations]
    expected = rank_with_quality(scores, quality, 0.5)
    assert tuple(ranking.order) == expected.order
    assert tuple(ranking.pareto_set) == expected.pareto_set == (0, 1)
    assert tuple(ranking.order) != core_ranking.order  # quality changed the order
    assert tuple(ranking.safety_order) == tuple(ranking.paper_order) == core_ranking.order
    assert ranking.safety_weight == 0.5
    request_poses = book_request().grasps.poses
    assert list(ranking.ranked_grasps.poses) == [request_poses[i] for i in expected.order]
    for k, evaluation in enumerate(ranking.evaluations):
        assert evaluation.grasp_quality == quality[k]
        assert evaluation.combined_score == pytest.approx(expected.combined[k], rel=1e-9)
        assert evaluation.pareto_optimal == (k in expected.pareto_set)


def test_leading_point_metric_scores_the_leading_point(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator, core_ranking: Any
) -> None:
    request = book_request()
    request.metric_point = "leading_point"
    response = ros.rank(request)
    assert response.success, response.message
    ranking = response.ranking
    want = core_report(core_evaluator, core_ranking, metric_point="leading_point")
    assert ranking.metric_point == "leading_point"
    assert tuple(ranking.order) == tuple(ranking.safety_order) == want.order
    assert tuple(ranking.paper_order) == core_ranking.order
    for k, evaluation in enumerate(ranking.evaluations):
        masses = evaluation.leading_point_effective_mass_kg
        assert evaluation.safety_score == pytest.approx(np.mean(masses), rel=1e-12)
        assert evaluation.safety_score == pytest.approx(want.scores[k], rel=1e-9)
        np.testing.assert_allclose(masses, want.exposed[k].leading_effective_mass_kg, rtol=1e-9)
        np.testing.assert_allclose(
            evaluation.worst_point_effective_mass_kg,
            want.exposed[k].worst_effective_mass_kg,
            rtol=1e-9,
        )
        assert evaluation.iso_min_duration_s == pytest.approx(want.iso[k].min_duration_s, 1e-9)
    scores = [ranking.evaluations[i].safety_score for i in ranking.order]
    assert scores == sorted(scores)


def test_analyses_switched_on_by_parameters(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator, core_ranking: Any
) -> None:
    results = ros.set_parameters(
        uncertainty__mass_fraction=0.3,
        uncertainty__samples=4,
        effort__enabled=True,
        iso_ts_15066__regions=["chest", "face"],
        rank_by="effort",
    )
    assert all(r.successful for r in results), results
    try:
        response = ros.rank(book_request())
    finally:
        results = ros.set_parameters(
            uncertainty__mass_fraction=0.0,
            uncertainty__samples=64,
            effort__enabled=False,
            iso_ts_15066__regions=[],  # all regions
            rank_by="safety",
        )
        assert all(r.successful for r in results), results
    assert response.success, response.message
    ranking = response.ranking
    want = core_report(
        core_evaluator,
        core_ranking,
        uncertainty=InertiaUncertainty(mass_fraction=0.3, num_random_samples=4),
        effort=True,
        iso_regions=("chest", "face"),
        rank_by="effort",
    )
    assert ranking.rank_by == "effort" and ranking.effort_criterion == "peak_fraction"
    assert tuple(ranking.order) == want.order
    assert tuple(ranking.safety_order) == core_ranking.order
    uncertainty = want.uncertainty
    assert ranking.uncertainty_message == uncertainty.message
    assert ranking.ranking_flips == uncertainty.ranking_flips
    assert ranking.order_stability == pytest.approx(uncertainty.order_stability)
    assert tuple(ranking.worst_case_order) == uncertainty.worst_case_order
    for k, evaluation in enumerate(ranking.evaluations):
        spread, effort = uncertainty.grasps[k], want.effort[k]
        assert evaluation.worst_case_score == pytest.approx(spread.worst_case_score, rel=1e-9)
        assert evaluation.percentile_score == pytest.approx(spread.percentile_score, rel=1e-9)
        assert evaluation.probability_safest == spread.probability_safest
        np.testing.assert_allclose(evaluation.peak_abs_torque, effort.peak_abs_torque, 1e-9)
        np.testing.assert_allclose(evaluation.rms_torque, effort.rms_torque, 1e-9)
        assert evaluation.effort_score == pytest.approx(effort.score("peak_fraction"), 1e-9)
        assert [r.region for r in evaluation.iso_ts_15066] == ["chest", "face"]
    efforts = [ranking.evaluations[i].effort_score for i in ranking.order]
    assert efforts == sorted(efforts)


def test_redundancy_resolution(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator, core_ranking: Any
) -> None:
    (result,) = ros.set_parameters(redundancy__enabled=True)
    assert result.successful, result.reason
    try:
        request = book_request()
        request.grasps.poses = request.grasps.poses[:1]  # ~0.4 s per grasp
        response = ros.rank(request)
    finally:
        (result,) = ros.set_parameters(redundancy__enabled=False)
        assert result.successful, result.reason
    assert response.success, response.message
    (evaluation,) = response.ranking.evaluations
    first = GraspSafetyEvaluator(core_evaluator.robot).rank(
        BOOK_GRASPS[:1], BOOK.object_inertia, book_trajectory(), BOOK.robot.seed, "mean"
    )
    (resolution,) = core_report(core_evaluator, first, redundancy=True).redundancy
    assert evaluation.redundancy_applied and resolution.applied  # Baxter's arm: 7 joints
    assert evaluation.score_without_redundancy == pytest.approx(evaluation.score, rel=1e-12)
    assert evaluation.safety_score == pytest.approx(resolution.score, rel=1e-9)
    assert evaluation.safety_score < evaluation.score
    np.testing.assert_allclose(
        evaluation.effective_mass_with_redundancy_kg, resolution.effective_mass_kg, rtol=1e-9
    )


def test_quality_topic_pairs_with_candidate_sets(own_ros: NodeUnderTest) -> None:
    received: list[GraspRanking] = []
    diagnostics: list[DiagnosticArray] = []
    subs = [
        own_ros.client.create_subscription(
            GraspRanking, "/grasp_safety/ranking", received.append, LATCHED
        ),
        own_ros.client.create_subscription(
            DiagnosticArray, "/diagnostics", diagnostics.append, 10
        ),
    ]
    quality_pub = own_ros.client.create_publisher(
        Float64MultiArray, "/grasp_safety/candidate_grasp_quality", 10
    )
    grasps_pub = own_ros.client.create_publisher(PoseArray, "/grasp_safety/candidate_grasps", 10)
    path_pub = own_ros.client.create_publisher(Path, "/grasp_safety/object_trajectory", 10)
    publishers = (quality_pub, grasps_pub, path_pub)
    request = book_request()
    two = PoseArray(header=request.grasps.header, poses=request.grasps.poses[:2])
    three = request.grasps

    def next_ranking() -> GraspRanking:
        """The first ranking computed after now (not the latched one of an earlier test)."""
        now = own_ros.node.get_clock().now().nanoseconds

        def new() -> list[GraspRanking]:
            stamps = [(r.header.stamp.sec * 10**9 + r.header.stamp.nanosec, r) for r in received]
            return [r for t, r in stamps if t > now]

        assert own_ros.spin_until(lambda: bool(new()))
        time.sleep(0.1)  # a second ranking would have come by now
        own_ros.client_executor.spin_once(timeout_sec=0.05)
        assert len(new()) == 1
        return new()[0]

    try:
        assert own_ros.spin_until(lambda: min(p.get_subscription_count() for p in publishers) > 0)
        path_pub.publish(request.object_trajectory)
        # 1. quality first, then its set: ranked with the quality
        quality_pub.publish(Float64MultiArray(data=[0.0, 1.0]))
        time.sleep(0.2)  # one publisher per topic: let the quality arrive first
        grasps_pub.publish(two)
        ranking = next_ranking()
        assert [e.grasp_quality for e in ranking.evaluations] == [0.0, 1.0]
        assert len(ranking.pareto_set) > 0
        # 2. a new set alone: the used quality is not reused
        grasps_pub.publish(two)
        ranking = next_ranking()
        assert all(math.isnan(e.grasp_quality) for e in ranking.evaluations)
        # 3. the quality after its set: the set is ranked again, with it
        quality_pub.publish(Float64MultiArray(data=[0.5, 0.25]))
        ranking = next_ranking()
        assert [e.grasp_quality for e in ranking.evaluations] == [0.5, 0.25]
        # 4. a waiting quality of another length is discarded by the next set, with a warning
        quality_pub.publish(Float64MultiArray(data=[1.0, 2.0, 3.0, 4.0]))
        time.sleep(0.2)
        grasps_pub.publish(three)
        ranking = next_ranking()
        assert len(ranking.evaluations) == 3
        assert all(math.isnan(e.grasp_quality) for e in ranking.evaluations)

        def warned() -> bool:
            return any(
                "candidate_grasp_quality.data: has 4 values but the new candidate set has 3"
                in s.message
                for array in diagnostics
                for s in array.status
            )

        assert own_ros.spin_until(warned)
    finally:
        for subscription in subs:
            own_ros.client.destroy_subscription(subscription)
        for publisher in publishers:
            own_ros.client.destroy_publisher(publisher)
