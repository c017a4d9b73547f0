"""ros.node over real rclpy: posture selection, the executable joint trajectories, what the
response carries (parameters response.*) and the whole arm (harness: ros_node_harness.py)."""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np
import pytest
from grasp_safety_msgs.msg import GraspRanking
from rcl_interfaces.srv import GetParameters, SetParametersAtomically
from rclpy.parameter import Parameter
from ros_node_harness import (
    MAX_GRASPS,
    NODE_PARAMETERS,
    NodeUnderTest,
    _localhost_only,  # noqa: F401  (autouse fixture)
    assert_matches_core,
    book_request,
    core_pipeline,
    core_report,
)

from grasp_safety_ros.core import (
    GraspSafetyEvaluator,
)
from grasp_safety_ros.core.method.executable import joint_velocities_accelerations
from grasp_safety_ros.core.method.posture import PostureConfig

# --- Posture selection and the executable joint trajectory -----------------------------------


def _seconds(duration: Any) -> float:
    return duration.sec + 1e-9 * duration.nanosec


def assert_joint_trajectory(evaluation: Any, joint_names: Any, times: Any, positions: Any) -> None:
    trajectory = evaluation.joint_trajectory
    assert list(trajectory.joint_names) == list(joint_names)
    assert len(trajectory.points) == len(times)
    velocities, accelerations = joint_velocities_accelerations(times, positions)
    for point, t, q, qd, qdd in zip(
        trajectory.points, times, positions, velocities, accelerations, strict=True
    ):
        assert _seconds(point.time_from_start) == pytest.approx(t, abs=1e-9)
        np.testing.assert_allclose(point.positions, q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(point.velocities, qd, rtol=0, atol=1e-12)
        np.testing.assert_allclose(point.accelerations, qdd, rtol=0, atol=1e-12)


def test_single_ik_posture_fields_and_joint_trajectory(
    ros: NodeUnderTest, core_ranking: Any
) -> None:
    response = ros.rank(book_request())
    assert response.success, response.message
    ranking = response.ranking
    for got, want in zip(ranking.evaluations, core_ranking.evaluations, strict=True):
        assert got.score_single_ik == got.score == got.score_range_min == got.score_range_max
        assert (got.postures_tried, got.postures_feasible) == (1, 1)
        np.testing.assert_allclose(got.start_positions, want.joint_positions[0], atol=1e-12)
        assert_joint_trajectory(got, ranking.joint_names, want.times_s, want.joint_positions)
        header = got.joint_trajectory.header
        assert header.frame_id == "base" and (header.stamp.sec, header.stamp.nanosec) == (0, 0)


def test_posture_selection_by_parameter_equals_the_core(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator
) -> None:
    (result,) = ros.set_parameters(posture__restarts=6)
    assert result.successful, result.reason
    try:
        response = ros.rank(book_request())
    finally:
        (result,) = ros.set_parameters(posture__restarts=0)
        assert result.successful, result.reason
    assert response.success, response.message
    expected = core_pipeline(core_evaluator, PostureConfig(restarts=6), iso_regions=()).ranking
    assert_matches_core(response.ranking, expected)
    for got, want, posture in zip(
        response.ranking.evaluations, expected.evaluations, expected.postures, strict=True
    ):
        assert got.score_single_ik == pytest.approx(posture.score_single_ik, rel=1e-12)
        assert got.score_range_min == pytest.approx(posture.score_range[0], rel=1e-12)
        assert got.score_range_max == pytest.approx(posture.score_range[1], rel=1e-12)
        assert got.score <= got.score_single_ik
        assert (got.postures_tried, got.postures_feasible, got.postures_stopped) == (
            posture.postures_tried,
            posture.postures_feasible,
            posture.postures_stopped,
        )
        np.testing.assert_allclose(got.start_positions, posture.start_positions, atol=1e-12)
        assert_joint_trajectory(
            got, response.ranking.joint_names, want.times_s, want.joint_positions
        )


def test_posture_restarts_parameter_is_typed_and_bounded(ros: NodeUnderTest) -> None:
    (result,) = ros.set_parameters(posture__restarts=-1)
    assert not result.successful and result.reason
    (result,) = ros.set_parameters(posture__restarts=1.5)
    assert not result.successful and result.reason
    future = ros.get_client.call_async(GetParameters.Request(names=["posture.restarts"]))
    (value,) = ros.wait(future).values
    assert value.integer_value == 0
    descriptor = ros.node.describe_parameter("posture.restarts")
    assert descriptor.integer_range[0].from_value == 0
    assert descriptor.integer_range[0].to_value >= 100
    assert "restarts" in descriptor.description


# --- What the response carries (parameters response.*) ----------------------------------------

PER_SAMPLE_FIELDS = (
    "time_from_start_s",
    "effective_mass_kg",
    "direction_xyz",
    "direction_is_worst_case",
    "leading_point_effective_mass_kg",
    "worst_point_effective_mass_kg",
    "links_only_effective_mass_kg",
)


def _with_trajectory(ranking: GraspRanking) -> list[int]:
    return [e.index for e in ranking.evaluations if e.joint_trajectory.points]


def test_response_joint_trajectories_counts_grasps_of_the_final_order(ros: NodeUnderTest) -> None:
    request = book_request()
    request.grasp_quality = [0.9, 0.1, 0.5]  # a final order that is not the index order
    full = ros.rank(request)
    assert full.success, full.message
    order = list(full.ranking.order)
    assert len(order) == 3 and order != sorted(order)
    assert _with_trajectory(full.ranking) == [0, 1, 2]  # the tests' setting: all
    try:
        for count, expected in ((1, order[:1]), (2, order[:2]), (0, []), (3, order)):
            (result,) = ros.set_parameters(response__joint_trajectories=count)
            assert result.successful, result.reason
            response = ros.rank(request)
            assert response.success, response.message
            assert sorted(_with_trajectory(response.ranking)) == sorted(expected), count
            assert list(response.ranking.order) == order
            for got, want in zip(
                response.ranking.evaluations, full.ranking.evaluations, strict=True
            ):
                if got.joint_trajectory.points:  # the same motion as in the full response
                    assert got.joint_trajectory == want.joint_trajectory
                else:
                    assert got.joint_trajectory.points == []
    finally:
        (result,) = ros.set_parameters(response__joint_trajectories=MAX_GRASPS)
        assert result.successful, result.reason


def test_response_per_sample_false_leaves_the_arrays_empty_and_keeps_the_scores(
    ros: NodeUnderTest,
) -> None:
    request = book_request()
    request.metric_point = "leading_point"  # fills the exposed-point arrays too
    full = ros.rank(request)
    assert full.success, full.message
    (result,) = ros.set_parameters(response__per_sample=False)
    assert result.successful, result.reason
    try:
        response = ros.rank(request)
    finally:
        (result,) = ros.set_parameters(response__per_sample=True)
        assert result.successful, result.reason
    assert response.success, response.message
    assert list(response.ranking.order) == list(full.ranking.order)
    for got, want in zip(response.ranking.evaluations, full.ranking.evaluations, strict=True):
        assert want.feasible and len(want.leading_point_effective_mass_kg) > 0
        for field in PER_SAMPLE_FIELDS:
            assert len(getattr(got, field)) == 0, field
        for field in ("score", "safety_score", "peak_effective_mass_kg", "iso_min_duration_s"):
            assert getattr(got, field) == getattr(want, field), field
        assert got.mean_effective_mass_kg == pytest.approx(np.mean(want.effective_mass_kg))
        assert repr(got.iso_ts_15066) == repr(want.iso_ts_15066)  # NaN where not permitted
        assert got.joint_trajectory == want.joint_trajectory  # governed by the other parameter


def test_response_parameters_are_typed_bounded_and_refused_by_name(ros: NodeUnderTest) -> None:
    (result,) = ros.set_parameters(response__joint_trajectories=-1)
    assert not result.successful
    # rclpy checks the declared range first: "Parameter response.joint_trajectories out of
    # range. Min: 0, Max: 1000000000, value: -1"
    assert re.search(r"response\.joint_trajectories\b.*\b0\b.*\b1000000000\b.*-1", result.reason)
    (result,) = ros.set_parameters(response__joint_trajectories=1.0)  # declared an integer
    assert not result.successful
    assert "expected 'Type.INTEGER' got 'Type.DOUBLE'" in result.reason
    (result,) = ros.set_parameters(response__per_sample="no")  # declared a bool
    assert not result.successful and "expected 'Type.BOOL'" in result.reason
    names = ["response.joint_trajectories", "response.per_sample"]
    values = ros.wait(ros.get_client.call_async(GetParameters.Request(names=names))).values
    assert (values[0].integer_value, values[1].bool_value) == (MAX_GRASPS, True)
    descriptor = ros.node.describe_parameter("response.joint_trajectories")
    assert (descriptor.integer_range[0].from_value, descriptor.integer_range[0].to_value) == (
        0,
        1_000_000_000,
    )
    response = ros.rank(book_request())  # still serving, with the settings it had
    assert response.success, response.message
    assert _with_trajectory(response.ranking) == [0, 1, 2]


def test_response_defaults_send_the_first_grasps_trajectory_and_every_sample() -> None:
    parameters = {k: v for k, v in NODE_PARAMETERS.items() if k != "response.joint_trajectories"}
    harness = NodeUnderTest(parameters)
    try:
        response = harness.rank(book_request())
    finally:
        harness.close()
    assert response.success, response.message
    ranking = response.ranking
    assert _with_trajectory(ranking) == [ranking.order[0]]
    for evaluation in ranking.evaluations:
        assert len(evaluation.effective_mass_kg) == 21  # 2 s / 0.1
        assert len(evaluation.direction_xyz) == 3 * 21


def test_rank_by_whole_arm_through_the_service(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator, core_ranking: Any
) -> None:
    """The node's rank_by whole_arm: default sites and region (chest), the core's order, the
    response's whole_arm_* fields equal the core's."""
    results = ros.set_parameters(rank_by="whole_arm")
    assert all(r.successful for r in results), results
    try:
        response = ros.rank(book_request())
    finally:
        results = ros.set_parameters(rank_by="safety")
        assert all(r.successful for r in results), results
    assert response.success, response.message
    ranking = response.ranking
    want = core_report(core_evaluator, core_ranking, rank_by="whole_arm")
    assert ranking.rank_by == "whole_arm" and ranking.whole_arm_region == "chest"
    assert want.arm_sites is not None
    assert tuple(ranking.whole_arm_sites) == want.arm_sites.names
    assert tuple(ranking.order) == want.order
    assert tuple(ranking.paper_order) == core_ranking.order
    for k, evaluation in enumerate(ranking.evaluations):
        whole = want.whole_arm[k]
        chest = whole.region("chest")
        assert evaluation.whole_arm_rank_force_n == pytest.approx(chest.peak_contact_force_n, 1e-9)
        assert evaluation.whole_arm_limiting_region == whole.limiting_region
        assert evaluation.whole_arm_min_duration_s == pytest.approx(whole.min_duration_s, 1e-9)
    forces = [ranking.evaluations[i].whole_arm_rank_force_n for i in ranking.order]
    assert forces == sorted(forces)


def set_parameters_atomically(ros: NodeUnderTest, **values: Any) -> Any:
    """All of ``values`` in one change (``~/set_parameters_atomically``): the SetParameters
    service applies its parameters one by one, so a pair validated together (e.g.
    whole_arm.point_links with whole_arm.points_m) must change at once."""
    client = ros.client.create_client(
        SetParametersAtomically, "/grasp_safety/set_parameters_atomically"
    )
    try:
        assert client.wait_for_service(timeout_sec=10.0)
        request = SetParametersAtomically.Request(
            parameters=[
                Parameter(name.replace("__", "."), value=value).to_parameter_msg()
                for name, value in values.items()
            ]
        )
        return ros.wait(client.call_async(request)).result
    finally:
        ros.client.destroy_client(client)


FOREARM_POINT_M = [0.0, 0.0, 0.1]


def test_whole_arm_parameters_through_the_service(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator, core_ranking: Any
) -> None:
    """whole_arm.region, the extra points (whole_arm.point_links + whole_arm.points_m) and
    iso_ts_15066.regions reach the analysis: the response equals the core's report with the
    same options (the scenario's whole_arm section and robot.exposed_points_m)."""
    results = ros.set_parameters(
        iso_ts_15066__regions=["chest", "upper_arm_elbow"],
        whole_arm__region="upper_arm_elbow",
        rank_by="whole_arm",
    )
    assert all(r.successful for r in results), results
    try:
        # one at a time, the pair is refused naming the parameter; together it is taken
        (result,) = ros.set_parameters(whole_arm__point_links=["right_lower_forearm"])
        assert not result.successful
        assert result.reason.startswith(
            "whole_arm.points_m: must hold x y z for each of the 1 whole_arm.point_links"
        )
        points = {"whole_arm__point_links": ["right_lower_forearm"]}
        result = set_parameters_atomically(ros, **points, whole_arm__points_m=FOREARM_POINT_M)
        assert result.successful, result.reason
        response = ros.rank(book_request())
    finally:
        result = set_parameters_atomically(
            ros,
            whole_arm__point_links=[],
            whole_arm__points_m=[],
            rank_by="safety",
            whole_arm__region="chest",
            iso_ts_15066__regions=[],
        )
        assert result.successful, result.reason
    assert response.success, response.message
    ranking = response.ranking
    want = core_report(
        core_evaluator,
        core_ranking,
        iso_regions=("chest", "upper_arm_elbow"),
        rank_by="whole_arm",
        whole_arm_region="upper_arm_elbow",
        arm_points_m={"right_lower_forearm": [FOREARM_POINT_M]},
    )
    assert want.arm_sites is not None and want.arm_sites.names[-1] == "right_lower_forearm[0]"
    assert ranking.rank_by == "whole_arm" and ranking.whole_arm_region == "upper_arm_elbow"
    assert tuple(ranking.whole_arm_sites) == want.arm_sites.names
    assert tuple(ranking.order) == want.order
    for k, evaluation in enumerate(ranking.evaluations):
        whole = want.whole_arm[k]
        elbow = whole.region("upper_arm_elbow")
        assert evaluation.whole_arm_rank_force_n == pytest.approx(elbow.peak_contact_force_n, 1e-9)
        assert evaluation.whole_arm_limiting_region == whole.limiting_region
        limiting = whole.region(whole.limiting_region)
        assert evaluation.whole_arm_worst_site == whole.site_names[limiting.worst_site]
        assert [r.region for r in evaluation.iso_ts_15066] == ["chest", "upper_arm_elbow"]
    forces = [ranking.evaluations[i].whole_arm_rank_force_n for i in ranking.order]
    assert forces == sorted(forces)


def test_whole_arm_enabled_without_ranking_by_it(ros: NodeUnderTest) -> None:
    """whole_arm.enabled fills the whole_arm_* fields and keeps the paper's order."""
    (result,) = ros.set_parameters(whole_arm__enabled=True)
    assert result.successful, result.reason
    try:
        response = ros.rank(book_request())
    finally:
        (result,) = ros.set_parameters(whole_arm__enabled=False)
        assert result.successful, result.reason
    assert response.success, response.message
    ranking = response.ranking
    assert ranking.rank_by == "safety" and tuple(ranking.order) == tuple(ranking.safety_order)
    assert ranking.whole_arm_region == "chest" and len(ranking.whole_arm_sites) == 6
    assert all(math.isfinite(e.whole_arm_rank_force_n) for e in ranking.evaluations if e.feasible)
    response = ros.rank(book_request())  # off again: not computed
    assert response.success and not response.ranking.whole_arm_sites


def test_whole_arm_parameters_are_refused_naming_them(ros: NodeUnderTest) -> None:
    result = set_parameters_atomically(
        ros, whole_arm__point_links=["right_lower_forarm"], whole_arm__points_m=FOREARM_POINT_M
    )
    assert not result.successful
    assert result.reason.startswith(
        "whole_arm.point_links: unknown link 'right_lower_forarm'; did you mean "
        "right_lower_forearm, "
    )
    (result,) = ros.set_parameters(whole_arm__region="elbow")
    assert not result.successful and result.reason.startswith("whole_arm.region: must be one of")
    (result,) = ros.set_parameters(rank_by="whole_arm")
    assert result.successful, result.reason
    try:
        # rank_by whole_arm orders by chest (whole_arm.region), which must stay assessed
        (result,) = ros.set_parameters(iso_ts_15066__regions=["face", "hand_fingers"])
        assert not result.successful
        assert result.reason == (
            "whole_arm.region: rank_by whole_arm ranks by 'chest', which is not among the "
            "assessed iso_ts_15066.regions (face, hand_fingers); add it there or set "
            "whole_arm.region to one of them"
        )
    finally:
        (result,) = ros.set_parameters(rank_by="safety")
        assert result.successful, result.reason
    response = ros.rank(book_request())  # nothing of the refused changes applied
    assert response.success and response.ranking.rank_by == "safety"
    assert not response.ranking.whole_arm_sites


def test_rank_by_whole_arm_selects_postures_by_it(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator
) -> None:
    """With rank_by whole_arm and posture.restarts, the node keeps the postures the core's
    whole-arm criterion keeps, and each grasp's ranking force is its kept posture's value."""
    results = ros.set_parameters(
        whole_arm__region="upper_arm_elbow", rank_by="whole_arm", posture__restarts=6
    )
    assert all(r.successful for r in results), results
    try:
        response = ros.rank(book_request())
    finally:
        results = ros.set_parameters(
            posture__restarts=0, rank_by="safety", whole_arm__region="chest"
        )
        assert all(r.successful for r in results), results
    assert response.success, response.message
    want = core_pipeline(
        core_evaluator,
        PostureConfig(restarts=6),
        rank_by="whole_arm",
        whole_arm_region="upper_arm_elbow",
    )
    expected = want.ranking
    ranking = response.ranking
    assert tuple(ranking.order) == want.order
    for got, posture in zip(ranking.evaluations, expected.postures, strict=True):
        assert posture.criterion == "whole_arm:upper_arm_elbow"
        np.testing.assert_allclose(got.start_positions, posture.start_positions, atol=1e-12)
        assert got.whole_arm_rank_force_n == pytest.approx(posture.criterion_value, rel=1e-9)
        assert posture.criterion_value <= posture.criterion_single_ik
