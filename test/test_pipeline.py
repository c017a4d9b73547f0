"""core.pipeline: one orchestration behind every interface.

The CLI (``grasp-safety rank``), the node (in-process, over the middleware) and the batch give
the same report for the same input and the defaults; the node returns the armature range as
the CLI does; the progress hook sees every stage in order and can abandon the request.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

pytest.importorskip("rclpy")

from ros_node_harness import BOOK, BOOK_YAML, NodeUnderTest, book_request
from tolerances import effort_tolerances, path_tolerance

from grasp_safety_ros.cli.main import rank_scenario
from grasp_safety_ros.core.method.ranking import GraspSafetyEvaluator
from grasp_safety_ros.core.pipeline import STAGES, run_pipeline
from grasp_safety_ros.scenario.schema import load_scenario

DT_S = 0.1
LOWER_KGM2 = [0.0, 0.05, 0.0, 0.05, 0.0, 0.02, 0.0]
UPPER_KGM2 = [0.1, 0.25, 0.1, 0.25, 0.05, 0.05, 0.05]
"""Armature ranges of Baxter's right arm [kg m^2], chain order (made up: any 0 <= lo <= hi)."""


@pytest.fixture(scope="module")
def scenario_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The book scenario at DT_S with armature ranges; every other option left to its default."""
    data = copy.deepcopy(BOOK_YAML)
    data["trajectory"]["dt_s"] = DT_S
    data["robot"]["armature_kgm2"] = [
        [lo, hi] for lo, hi in zip(LOWER_KGM2, UPPER_KGM2, strict=True)
    ]
    folder = tmp_path_factory.mktemp("pipeline") / "scenarios"
    folder.mkdir()
    path = folder / "book.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture(scope="module")
def cli_report(scenario_path: Path) -> Any:
    return rank_scenario(load_scenario(scenario_path))


@pytest.fixture(scope="module")
def tolerances(scenario_path: Path, cli_report: Any) -> dict[int, dict[str, float]]:
    """Relative tolerances of the node's numbers against the CLI's, per feasible grasp.

    The node's grasps and trajectory pass through messages (quaternions normalised again,
    times in sec + nanosec): its inputs differ from the CLI's by a few roundings, which the
    IK and the dynamics amplify by the path's conditioning. So: ``path`` = path_tolerance
    (k · cond · eps, cond the worse of M's and the tip Jacobian's along the grasp's path,
    k = ROUNDINGS_PER_JOINT per joint, which also covers the inputs' few roundings) for the
    scores, effective masses, the ISO/TS 15066 durations (from the effective mass) and the
    start posture (relative to its largest joint value, at least 1 rad); ``lower`` the same
    with the armature's lower ends (their M); ``effort`` =
    effort_tolerances' of the ranked criterion (the torques' finite differences included)."""
    scenario = load_scenario(scenario_path)
    robot = scenario.robot.load(scenario.base_dir)
    criterion = f"{cli_report.options.effort_criterion}_of_limit"
    result = {}
    for k, evaluation in enumerate(cli_report.ranking.evaluations):
        if not evaluation.feasible:
            continue
        grasp = scenario.grasps[k]
        path = path_tolerance(robot, scenario.object_inertia, grasp, evaluation.joint_positions)
        lower = path_tolerance(
            robot.with_armature(LOWER_KGM2),
            scenario.object_inertia,
            grasp,
            evaluation.joint_positions,
        )
        result[k] = {"path": path, "lower": lower}
        if cli_report.effort:
            effort = effort_tolerances(
                robot, evaluation, scenario.object_inertia, grasp, cli_report.effort[k]
            )
            result[k]["effort"] = effort[criterion]
    return result


@pytest.fixture(scope="module")
def node_response(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """The node's answer to the book request, every parameter but the input ones at its
    default (the default posture selection and analyses included)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        patch.setenv("ROS_LOG_DIR", str(tmp_path_factory.mktemp("ros_log")))
        node = NodeUnderTest(
            {
                "urdf": "example-robot-data:baxter",
                "base_frame": "base",
                "tip_frame": "right_gripper",
                "ik_seed": list(BOOK.robot.seed),
                "object.box_size_m": BOOK_YAML["object"]["box_size_m"],  # the exposed points
                "trajectory.dt_s": DT_S,
                "robot.armature_kgm2": UPPER_KGM2,
                "robot.armature_lower_kgm2": LOWER_KGM2,
            }
        )
        try:
            response = node.rank(book_request())
        finally:
            node.close()
    assert response.success, response.message
    return response.ranking


def test_node_equals_the_cli_with_the_defaults(
    cli_report: Any, node_response: Any, tolerances: dict[int, dict[str, float]]
) -> None:
    report, ranking = cli_report, node_response
    assert tuple(ranking.order) == report.order
    assert tuple(ranking.safety_order) == report.safety_order
    assert ranking.rank_by == report.options.rank_by
    assert ranking.effort_criterion == (report.options.effort_criterion if report.effort else "")
    iso = {a.index: a for a in report.iso}
    for k, (got, e) in enumerate(
        zip(ranking.evaluations, report.ranking.evaluations, strict=True)
    ):
        posture = report.ranking.postures[k]
        assert got.feasible == e.feasible and got.reason == e.reason
        assert (got.postures_tried, got.postures_stopped) == (
            posture.postures_tried,
            posture.postures_stopped,
        )
        if not e.feasible:
            continue
        rel = tolerances[k]["path"]
        assert got.score == pytest.approx(e.score, rel=rel)
        assert got.safety_score == pytest.approx(report.scores[k], rel=rel)
        assert got.iso_min_duration_s == pytest.approx(iso[k].min_duration_s, rel=rel)
        scale_rad = max(float(np.abs(posture.start_positions).max()), 1.0)
        np.testing.assert_allclose(
            got.start_positions, posture.start_positions, rtol=0.0, atol=rel * scale_rad
        )
        if report.effort:
            effort = report.effort[k].score(report.options.effort_criterion)
            assert got.effort_score == pytest.approx(effort, rel=tolerances[k]["effort"])


def test_the_service_returns_the_armature_range(
    cli_report: Any, node_response: Any, tolerances: dict[int, dict[str, float]]
) -> None:
    spread, ranking = cli_report.armature_range, node_response
    assert spread is not None  # the scenario's ranges ran in the CLI
    np.testing.assert_array_equal(ranking.armature_lower_kgm2, LOWER_KGM2)
    np.testing.assert_array_equal(ranking.armature_upper_kgm2, UPPER_KGM2)
    assert tuple(ranking.armature_order_lower) == spread.order_lower
    assert tuple(ranking.armature_order_upper) == spread.order_upper
    assert ranking.armature_ranking_flips == spread.ranking_flips
    assert ranking.armature_range_message == spread.message
    for k, got in enumerate(ranking.evaluations):
        if not got.feasible:
            continue
        rel, lower = tolerances[k]["path"], tolerances[k]["lower"]
        assert got.score_armature_lower == pytest.approx(spread.scores_lower[k], rel=lower)
        assert got.score_armature_upper == pytest.approx(spread.scores_upper[k], rel=rel)
        low, high = spread.effective_mass_range_kg[k]
        assert got.armature_min_effective_mass_kg == pytest.approx(low, rel=lower)
        assert got.armature_max_effective_mass_kg == pytest.approx(high, rel=rel)
        # the ends bound the effective mass (M + diag(a) grows with a), the upper is ranked
        assert got.score_armature_lower <= got.score <= got.score_armature_upper * (1 + rel)


def test_batch_equals_the_cli(scenario_path: Path, cli_report: Any, tmp_path: Path) -> None:
    pytest.importorskip("pyarrow")
    from grasp_safety_ros.dataset.batch import read_batch, run_batch

    spec = scenario_path.parent.parent / "spec.yaml"
    spec.write_text(yaml.safe_dump({"sources": [{"format": "scenarios", "path": "scenarios/*"}]}))
    run_batch(spec, tmp_path / "out", workers=1)
    rows = read_batch(tmp_path / "out").to_pylist()
    report = cli_report
    assert len(rows) == len(report.ranking.evaluations)
    for k, (row, e) in enumerate(zip(rows, report.ranking.evaluations, strict=True)):
        posture = report.ranking.postures[k]
        assert row["feasible"] == e.feasible and row["restarts"] == posture.restarts
        if e.feasible:  # the same process and inputs: the same arithmetic, bit for bit
            assert (row["score"], row["safety_score"]) == (e.score, report.scores[k])
            assert row["start_positions"] == posture.start_positions.tolist()


def test_progress_sees_every_stage_in_order_and_can_abandon() -> None:
    scenario = load_scenario(Path(__file__).resolve().parents[1] / "config" / "book_baxter.yaml")
    robot = scenario.robot.load(scenario.base_dir)
    evaluator = GraspSafetyEvaluator(robot)
    request = scenario.request(robot)
    seen: list[str] = []
    timings: dict[str, float] = {}
    report = run_pipeline(
        evaluator, request, lambda stage, done, total: seen.append(stage), timings
    )
    assert [s for i, s in enumerate(seen) if i == 0 or seen[i - 1] != s] == list(STAGES[:3])
    assert set(timings) == {s + x for s in STAGES[:3] for x in ("", "_cpu", "_process_cpu")}
    assert report.armature_range is None  # no ranges in the book scenario

    class AbandonError(Exception):
        pass

    def stop_in_postures(stage: str, done: int, total: int) -> None:
        if stage == "postures":
            raise AbandonError

    with pytest.raises(AbandonError):
        run_pipeline(evaluator, request, stop_in_postures)
    again = run_pipeline(evaluator, request)
    assert again.order == report.order  # an abandoned request leaves nothing behind
    np.testing.assert_array_equal(again.scores, report.scores)
