"""Posture selection (core.method.posture) and joint velocities (core.method.executable)."""

from __future__ import annotations

import copy
import math
import pickle
from unittest.mock import Mock

import numpy as np
import pinocchio as pin
import pytest
from conftest import ARM7_AXES, BAXTER_SEED, book_trajectory, random_positions, serial_arm_urdf
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tolerances import path_tolerance

from grasp_safety_ros.core import (
    EvaluationConfig,
    Grasp,
    GraspSafetyEvaluator,
    InvalidInputError,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.analyses.safety_report import (
    AnalysisOptions,
    analyse,
    posture_criterion,
)
from grasp_safety_ros.core.analyses.whole_arm import (
    evaluate_whole_arm,
    resolve_arm_sites,
    whole_arm_score,
)
from grasp_safety_ros.core.input_checks import pose_from_position_quat
from grasp_safety_ros.core.method import ranking as ranking_module
from grasp_safety_ros.core.method.effective_mass import worst_direction
from grasp_safety_ros.core.method.executable import joint_velocities_accelerations
from grasp_safety_ros.core.method.halton import scrambled_halton
from grasp_safety_ros.core.method.metrics import METRICS
from grasp_safety_ros.core.method.posture import PostureConfig, restart_seeds, select_postures
from grasp_safety_ros.core.method.ranking import sample_trajectory
from grasp_safety_ros.core.method.results import SAMPLE_ARRAYS

BOOK = solid_box(0.34, (0.15, 0.22, 0.015))


def book_grasps() -> list[Grasp]:
    return [
        Grasp(pose_from_position_quat([-0.075, y, 0.0], [0, 0, 0, 1], "g"), f"spine_{y}")
        for y in (-0.1, 0.0, 0.1)
    ]


@pytest.fixture(scope="module")
def baxter_book(baxter: RobotModel):
    evaluator = GraspSafetyEvaluator(baxter, EvaluationConfig(workers=1))
    trajectory = book_trajectory(dt_s=0.05)
    grasps = book_grasps()
    ranking = evaluator.rank(grasps, BOOK, trajectory, seed_positions=BAXTER_SEED)
    return evaluator, grasps, trajectory, ranking


def test_config_rejects_bad_values() -> None:
    with pytest.raises(InvalidInputError, match=r"posture\.restarts: must be an integer"):
        PostureConfig(restarts=-1)
    with pytest.raises(InvalidInputError, match=r"posture\.restarts"):
        PostureConfig(restarts=True)  # type: ignore[arg-type]
    with pytest.raises(InvalidInputError, match=r"posture\.duplicate_tolerance_rad"):
        PostureConfig(duplicate_tolerance_rad=0.0)
    with pytest.raises(InvalidInputError, match=r"posture\.early_stop: must be true or false"):
        PostureConfig(early_stop=1)  # type: ignore[arg-type]
    for bad in (0, 10_001, 2.0, True):
        with pytest.raises(InvalidInputError, match=r"posture\.restart_iterations: must be"):
            PostureConfig(restart_iterations=bad)  # type: ignore[arg-type]
        with pytest.raises(InvalidInputError, match=r"posture\.restart_stall_iterations: must"):
            PostureConfig(restart_stall_iterations=bad)  # type: ignore[arg-type]


def test_restart_iterations_cut_the_restart_ik_short(baxter, baxter_book) -> None:
    """Gauss-Newton's state is its iterate: a restart that converges within k iterations
    converges with k, to the same configuration bit for bit, and one that converges only
    later does not (compiled and Python IK); giving up on a stall every k iterations keeps a
    subset of the solutions, bit for bit, all those within 2k iterations (the first check);
    the config's own limit selects as None."""
    evaluator, grasps, trajectory, ranking = baxter_book
    python = GraspSafetyEvaluator(baxter, EvaluationConfig(workers=1, backend="python"))
    poses = [
        trajectory.transform_object_to_base_start * pin.SE3(g.transform_tip_to_object)
        for g in grasps
    ]
    seeds = np.array(
        [baxter.q_from_positions(s) for s in restart_seeds(evaluator, PostureConfig(16))]
    )
    for solver in (evaluator.ik, python.ik):
        q, converged = solver.solve_poses(poses, seeds)
        iterations = np.array([[solver.solve(pose, s)[2] for s in seeds] for pose in poses])
        for k in (1, 10, 30):
            q_k, converged_k = solver.solve_poses(poses, seeds, max_iterations=k)
            assert np.array_equal(converged_k, converged & (iterations <= k))
            assert np.array_equal(q_k[converged_k], q[converged_k])
            # giving up on a stall: a subset of the same solutions, the same iterates
            q_s, converged_s = solver.solve_poses(poses, seeds, stall_iterations=k)
            assert np.array_equal(converged_s, converged_s & converged)
            assert np.array_equal(q_s[converged_s], q[converged_s])
            assert np.array_equal(converged_s[iterations <= 2 * k], converged[iterations <= 2 * k])
    limit = evaluator.ik.config.max_iterations
    same = [
        select_postures(evaluator, grasps, BOOK, trajectory, ranking, PostureConfig(8, **c))
        for c in ({}, {"restart_iterations": limit})
    ]
    assert pickle.dumps(same[0].postures) == pickle.dumps(same[1].postures)


def test_zero_restarts_is_the_single_ik_bit_for_bit(baxter_book) -> None:
    evaluator, grasps, trajectory, ranking = baxter_book
    selected = select_postures(
        evaluator, grasps, BOOK, trajectory, ranking, PostureConfig(restarts=0)
    )
    fresh = evaluator.rank(grasps, BOOK, trajectory, seed_positions=BAXTER_SEED)
    assert selected.order == fresh.order
    for a, b in zip(selected.evaluations, fresh.evaluations, strict=True):
        assert a.score == b.score
        assert np.array_equal(a.joint_positions, b.joint_positions)
        assert np.array_equal(a.effective_mass_kg, b.effective_mass_kg)
    for p, e in zip(selected.postures, selected.evaluations, strict=True):
        assert (p.postures_tried, p.postures_feasible, p.selected) == (1, 1, 0)
        assert p.score == p.score_single_ik == e.score
        assert np.array_equal(p.start_positions, e.joint_positions[0])


def test_selection_never_scores_worse_and_reports_consistently(baxter_book) -> None:
    evaluator, grasps, trajectory, ranking = baxter_book
    selected = select_postures(
        evaluator, grasps, BOOK, trajectory, ranking, PostureConfig(restarts=12)
    )
    for p, e, single in zip(
        selected.postures, selected.evaluations, ranking.evaluations, strict=True
    ):
        assert e.feasible and single.feasible
        assert p.score_single_ik == single.score
        assert p.score == e.score <= single.score
        assert p.score_range[0] == p.score <= p.score_range[1]
        assert 1 <= p.postures_feasible <= p.postures_tried <= 13
        assert np.array_equal(p.start_positions, e.joint_positions[0])
        # the kept posture is really followed from its start: the tip is where the grasp says
        tip = evaluator.robot.transform_tip_to_base(e.joint_positions[0])
        target = (
            trajectory.transform_object_to_base_start * grasps[e.index].transform_tip_to_object
        )
        assert np.linalg.norm(pin.log6(tip.actInv(target)).vector) < 1e-5
    scores = [e.score for e in selected.evaluations]
    assert list(selected.order) == sorted(range(3), key=lambda k: scores[k])
    assert any(p.score < p.score_single_ik - 1e-4 for p in selected.postures)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.integers(0, 2**16),
    st.lists(st.sampled_from("xyz"), min_size=6, max_size=7),
    st.sampled_from(METRICS),
)
def test_never_worse_than_the_single_ik_on_random_arms(
    seed: int, axes: list[str], metric: str
) -> None:
    """The property of the module docstring, on a random 6- or 7-joint arm, random grasps
    and every metric: the kept posture is feasible whenever the single IK is and scores at
    most its score, exactly (a kept restart scores strictly lower, else the single IK
    itself is kept); the early stop keeps the same posture, bit for bit, and only moves
    postures from the feasible count to the stopped count."""
    robot = RobotModel.from_urdf(serial_arm_urdf(axes, seed=seed), "base_link", "tool")
    rng = np.random.default_rng(seed)
    evaluator = GraspSafetyEvaluator(robot, EvaluationConfig(workers=1, metric=metric))
    start_positions = random_positions(robot, rng)
    grasps = [
        Grasp(pin.SE3(pin.exp3(rng.normal(scale=0.3, size=3)), rng.normal(scale=0.05, size=3)))
        for _ in range(4)
    ]
    # grasp 0's tip is at the start posture's tip pose: its single IK starts feasible
    start = (
        robot.transform_tip_to_base(start_positions) * grasps[0].transform_tip_to_object.inverse()
    )
    goal = pin.SE3(start.rotation @ pin.exp3(rng.normal(scale=0.2, size=3)), start.translation)
    goal.translation = goal.translation + rng.normal(scale=0.03, size=3)
    trajectory = ObjectTrajectory(start, goal, 1.0, 0.05)
    ranking = evaluator.rank(grasps, BOOK, trajectory, seed_positions=start_positions)
    full, early = (
        select_postures(
            evaluator, grasps, BOOK, trajectory, ranking, PostureConfig(8, seed, 1e-3, stop)
        )
        for stop in (False, True)
    )
    for k, single in enumerate(ranking.evaluations):
        kept, p, q = full.evaluations[k], full.postures[k], early.postures[k]
        if single.feasible:
            assert kept.feasible and kept.score <= single.score
            assert (p.selected == 0) == (kept is single)
            assert p.selected == 0 or kept.score < single.score
        else:
            assert kept.feasible == (p.postures_feasible > 0)
        assert p.postures_stopped == 0
        assert (q.selected, q.postures_tried) == (p.selected, p.postures_tried)
        assert np.array_equal([q.score], [p.score], equal_nan=True)
        assert pickle.dumps(early.evaluations[k]) == pickle.dumps(kept)  # bit for bit
        assert np.array_equal([q.score_range[0]], [p.score_range[0]], equal_nan=True)
        assert (
            q.postures_feasible <= p.postures_feasible <= q.postures_feasible + q.postures_stopped
        )
        assert q.postures_feasible + q.postures_stopped <= q.postures_tried


def test_seven_dof_start_posture_as_good_as_many_random_ik_solutions(baxter_book) -> None:
    """The independent oracle: 150 IK solutions of the start pose from uniformly random seeds
    (another generator than the selection's), each followed along the trajectory."""
    evaluator, grasps, trajectory, ranking = baxter_book
    robot = evaluator.robot
    selected = select_postures(
        evaluator, grasps[:1], BOOK, trajectory, _subset(ranking, 0), PostureConfig(restarts=16)
    )
    rng = np.random.default_rng(2024)
    start = trajectory.transform_object_to_base_start * grasps[0].transform_tip_to_object
    best = np.inf
    feasible = 0
    for _ in range(150):
        q, converged, _ = evaluator.ik.solve(
            start, robot.q_from_positions(random_positions(robot, rng))
        )
        if not converged:
            continue
        e = evaluator.evaluate(grasps[0], BOOK, trajectory, seed_positions=q)
        if e.feasible:
            feasible += 1
            best = min(best, e.score)
    assert feasible >= 20
    assert selected.evaluations[0].score <= 1.01 * best


def _subset(ranking, k: int):
    from dataclasses import replace

    e = ranking.evaluations[k]
    return replace(ranking, order=(0,) if e.feasible else (), evaluations=(e,))


PLANAR_URDF = """<robot name="planar"><link name="base"/>
<link name="l1"><inertial><origin xyz="0.25 0 0"/><mass value="2"/>
 <inertia ixx="0.01" iyy="0.05" izz="0.05" ixy="0" ixz="0" iyz="0"/></inertial></link>
<link name="l2"><inertial><origin xyz="0.2 0 0"/><mass value="1.5"/>
 <inertia ixx="0.01" iyy="0.03" izz="0.03" ixy="0" ixz="0" iyz="0"/></inertial></link>
<link name="l3"><inertial><origin xyz="0.05 0 0"/><mass value="0.5"/>
 <inertia ixx="0.002" iyy="0.002" izz="0.002" ixy="0" ixz="0" iyz="0"/></inertial></link>
<link name="tool"/>
<joint name="shoulder" type="revolute"><parent link="base"/><child link="l1"/>
 <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="50" velocity="10"/></joint>
<joint name="elbow" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.5 0 0"/>
 <axis xyz="0 0 1"/><limit lower="-1.0" upper="2.5" effort="50" velocity="10"/></joint>
<joint name="wrist" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.4 0 0"/>
 <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="50" velocity="10"/></joint>
<joint name="tool_joint" type="fixed"><parent link="l3"/><child link="tool"/>
 <origin xyz="0.1 0 0"/></joint></robot>"""


def _planar_case(goal_x: float):
    """A planar 3R arm (two IK branches: elbow up / down), the object carried from x = 0.95
    to ``goal_x`` at constant orientation; the seed is on the elbow-negative branch, whose
    elbow limit (-1 rad) it reaches when the wrist comes closer than 0.79 m to the base."""
    robot = RobotModel.from_urdf(PLANAR_URDF, "base", "tool")
    evaluator = GraspSafetyEvaluator(robot, EvaluationConfig(workers=1))
    start = pin.SE3(np.eye(3), np.array([0.95, 0.0, 0.0]))
    goal = pin.SE3(np.eye(3), np.array([goal_x, 0.0, 0.0]))
    trajectory = ObjectTrajectory(start, goal, 1.0, 0.02)
    grasps = [Grasp(pin.SE3.Identity(), "centre")]
    seed = (0.3, -0.6, 0.3)
    return evaluator, grasps, trajectory, seed


def test_grasp_infeasible_only_by_joint_limits_becomes_feasible() -> None:
    evaluator, grasps, trajectory, seed = _planar_case(goal_x=0.6)
    ranking = evaluator.rank(grasps, BOOK, trajectory, seed_positions=seed)
    single = ranking.evaluations[0]
    assert not single.feasible and "joint limits reached: elbow" in single.reason
    selected = select_postures(
        evaluator, grasps, BOOK, trajectory, ranking, PostureConfig(restarts=8)
    )
    kept, posture = selected.evaluations[0], selected.postures[0]
    assert kept.feasible and selected.order == (0,)
    assert np.isnan(posture.score_single_ik) and posture.postures_feasible >= 1
    assert kept.joint_positions[0][1] > 0.0  # the other (elbow-positive) branch
    assert np.all(kept.joint_positions[:, 1] <= 2.5)


def test_infeasible_reason_says_how_many_seeds_were_tried() -> None:
    evaluator, grasps, trajectory, seed = _planar_case(goal_x=1.2)  # beyond the 1 m reach
    ranking = evaluator.rank(grasps, BOOK, trajectory, seed_positions=seed)
    selected = select_postures(
        evaluator, grasps, BOOK, trajectory, ranking, PostureConfig(restarts=5)
    )
    kept, posture = selected.evaluations[0], selected.postures[0]
    assert not kept.feasible and selected.order == ()
    assert kept.reason.startswith("no feasible posture from 6 IK seeds")
    assert ranking.evaluations[0].reason in kept.reason
    assert posture.postures_feasible == 0 and posture.postures_tried >= 1


def test_redundancy_refinement_starts_from_the_selected_posture(baxter_book) -> None:
    evaluator, grasps, trajectory, ranking = baxter_book
    selected = select_postures(
        evaluator, grasps, BOOK, trajectory, ranking, PostureConfig(restarts=8)
    )
    report = analyse(
        evaluator, grasps, BOOK, trajectory, AnalysisOptions(redundancy=True), ranking=selected
    )
    for r, e in zip(report.redundancy, selected.evaluations, strict=True):
        assert np.array_equal(r.original_joint_positions, e.joint_positions)
        assert r.score <= e.score


def test_joint_velocities_match_finite_differences_and_minimum_norm_rate(baxter) -> None:
    evaluator = GraspSafetyEvaluator(baxter, EvaluationConfig(workers=1))
    trajectory = book_trajectory(dt_s=0.01)
    grasp = book_grasps()[0]
    e = evaluator.evaluate(grasp, BOOK, trajectory, seed_positions=BAXTER_SEED)
    qd, qdd = joint_velocities_accelerations(e.times_s, e.joint_positions)
    q, t = e.joint_positions, e.times_s
    assert np.abs(qd[[0, -1]]).max() < 1e-12  # at rest at both ends
    central = (q[2:] - q[:-2]) / (t[2:] - t[:-2])[:, None]
    scale = np.abs(central).max()
    assert np.abs(qd[1:-1] - central).max() < 2e-3 * scale
    # accelerations: piecewise linear, they integrate to the velocities exactly ...
    h = np.diff(t)[:, None]
    assert np.abs(qd[1:] - qd[:-1] - 0.5 * h * (qdd[1:] + qdd[:-1])).max() < 1e-9 * scale
    # ... and follow a wider (5-sample) second difference, except where the IK's 1e-6
    # tolerance shows as noise of order 1e-6 / dt^2 (a Gauss-Newton correction)
    k = 5
    central2 = (q[2 * k :] - 2 * q[k:-k] + q[: -2 * k]) / ((k * 0.01) ** 2)
    errors2 = np.abs(qdd[k:-k] - central2).max(axis=1)
    assert np.percentile(errors2, 90) < 0.02 * np.abs(central2).max()
    assert errors2.max() < 0.2 * np.abs(central2).max()
    # the IK tracks the tip minimum-norm: qd = J^+ V, V the analytic tip twist (LOCAL)
    s, s_rate, _ = trajectory.path_parameter(t)
    model, data = baxter.model, baxter.model.createData()
    errors = []
    for i in range(5, len(t) - 5, 10):
        h = 1e-6
        poses, _ = trajectory.tip_path(grasp.transform_tip_to_object, np.array([s[i], s[i] + h]))
        twist = pin.log6(poses[0].actInv(poses[1])).vector / h * s_rate[i]
        jac = pin.computeFrameJacobian(model, data, q[i], baxter.tip_frame_id, pin.LOCAL)
        errors.append(np.abs(np.linalg.pinv(jac) @ twist - qd[i]).max())
    assert max(errors) < 1e-2 * scale


def test_joint_velocities_reject_bad_shapes() -> None:
    with pytest.raises(InvalidInputError, match="joint_positions"):
        joint_velocities_accelerations(np.arange(3.0), np.zeros((4, 2)))
    with pytest.raises(InvalidInputError, match="times_s"):
        joint_velocities_accelerations(np.array([0.0, 1.0, 1.0]), np.zeros((3, 2)))


def test_seven_dof_inline_arm_selection_finds_lower_score() -> None:
    robot = RobotModel.from_urdf(serial_arm_urdf(ARM7_AXES, seed=1), "base_link", "tool")
    evaluator = GraspSafetyEvaluator(robot, EvaluationConfig(workers=1))
    rng = np.random.default_rng(3)
    seed = random_positions(robot, rng) * 0.5
    start = robot.transform_tip_to_base(seed)
    goal = pin.SE3(start.rotation, start.translation + np.array([0.05, 0.05, 0.0]))
    trajectory = ObjectTrajectory(start, goal, 1.0, 0.05)
    grasps = [Grasp(pin.SE3.Identity(), "tip")]
    ranking = evaluator.rank(grasps, BOOK, trajectory, seed_positions=seed)
    selected = select_postures(
        evaluator, grasps, BOOK, trajectory, ranking, PostureConfig(restarts=16)
    )
    p = selected.postures[0]
    assert p.postures_feasible >= 2 and p.score_range[1] > p.score_range[0]
    assert p.score <= p.score_single_ik


def test_scenario_posture_section_and_cli_json() -> None:
    import yaml

    from grasp_safety_ros.cli.main import rank_scenario
    from grasp_safety_ros.cli.report import report_to_dict
    from grasp_safety_ros.paths import config_file
    from grasp_safety_ros.scenario.schema import parse_scenario

    path = config_file("book_baxter.yaml")
    data = yaml.safe_load(path.read_text())
    assert parse_scenario(data, path.parent).posture == PostureConfig(restarts=8)
    for bad, field in (({"restarts": -1}, "restarts"), ({"restarts": "8"}, "restarts")):
        with pytest.raises(InvalidInputError, match=rf"posture\.{field}: must be an integer"):
            parse_scenario({**data, "posture": bad}, path.parent)
    with pytest.raises(InvalidInputError, match=r"posture\.tries: unknown field"):
        parse_scenario({**data, "posture": {"tries": 3}}, path.parent)
    scenario = parse_scenario({**data, "posture": {"restarts": 0}}, path.parent)
    paper = GraspSafetyEvaluator(scenario.robot.load(path.parent)).rank(
        scenario.grasps, scenario.object_inertia, scenario.trajectory, scenario.robot.seed
    )
    result = report_to_dict(rank_scenario(scenario))
    assert result["paper_ranking"] == list(paper.order)
    for grasp, e in zip(result["grasps"], paper.evaluations, strict=True):
        assert grasp["score"] == e.score and grasp["posture"]["restarts"] == 0
        assert grasp["samples"]["q"] == e.joint_positions.tolist()
        qd, _ = joint_velocities_accelerations(e.times_s, e.joint_positions)
        assert grasp["samples"]["qd"] == qd.tolist()


def test_a_criterion_builds_each_feasible_posture_once(baxter_book, monkeypatch) -> None:
    """With a criterion every feasible posture's GraspEvaluation is built once (the criterion
    reads them all; the kept one is not built again); without, the kept new posture alone."""
    from grasp_safety_ros.core.method.results import FollowedPosture

    evaluator, grasps, trajectory, ranking = baxter_book
    built: list[int] = []
    evaluation = FollowedPosture.evaluation
    monkeypatch.setattr(
        FollowedPosture, "evaluation", lambda self: built.append(1) or evaluation(self)
    )
    options = AnalysisOptions(rank_by="whole_arm", whole_arm_region="upper_arm_elbow")
    criterion = posture_criterion(evaluator.robot, options)
    config = PostureConfig(restarts=8)
    by_arm = select_postures(evaluator, grasps, BOOK, trajectory, ranking, config, None, criterion)
    assert len(built) == sum(p.postures_feasible for p in by_arm.postures)
    assert any(p.selected > 0 for p in by_arm.postures)  # a kept new posture: a rebuild counts
    built.clear()
    by_tip = select_postures(evaluator, grasps, BOOK, trajectory, ranking, config)
    assert len(built) == sum(p.selected > 0 for p in by_tip.postures)


def test_selection_by_the_whole_arm(baxter_book) -> None:
    """rank_by whole_arm: each grasp keeps the start posture of least worst predicted force
    over the arm's sites for the region; never worse than the single IK by it, deterministic,
    among the same candidates as the selection by the tip score."""
    evaluator, grasps, trajectory, ranking = baxter_book
    region = "upper_arm_elbow"
    options = AnalysisOptions(rank_by="whole_arm", whole_arm_region=region)
    criterion = posture_criterion(evaluator.robot, options)
    assert criterion is not None and posture_criterion(evaluator.robot, AnalysisOptions()) is None
    assert pickle.loads(pickle.dumps(criterion)).name == criterion.name  # for a process pool
    config = PostureConfig(restarts=8)
    by_arm = select_postures(evaluator, grasps, BOOK, trajectory, ranking, config, None, criterion)
    again = select_postures(evaluator, grasps, BOOK, trajectory, ranking, config, None, criterion)
    by_tip = select_postures(evaluator, grasps, BOOK, trajectory, ranking, config)
    sites = resolve_arm_sites(evaluator.robot)

    def force(evaluation, grasp) -> float:  # every region assessed, a model of its own
        whole = evaluate_whole_arm(evaluator.robot, evaluation, BOOK, grasp, trajectory, sites)
        return whole_arm_score(whole, region)

    differs = 0
    for k, grasp in enumerate(grasps):
        chosen, evaluation = by_arm.postures[k], by_arm.evaluations[k]
        assert chosen.criterion == "whole_arm:upper_arm_elbow" and chosen.postures_feasible > 1
        # compiled (the selection) vs Pinocchio (evaluate_whole_arm without terms)
        tolerance = path_tolerance(evaluator.robot, BOOK, grasp, evaluation.joint_positions)
        assert chosen.criterion_value == pytest.approx(force(evaluation, grasp), rel=tolerance)
        single = force(ranking.evaluations[k], grasp)
        first = path_tolerance(
            evaluator.robot, BOOK, grasp, ranking.evaluations[k].joint_positions
        )
        assert chosen.criterion_single_ik == pytest.approx(single, rel=first)
        assert chosen.criterion_value <= chosen.criterion_single_ik
        assert chosen.score == evaluation.score  # score: still the kept posture's tip score
        # the same candidates: each choice is the best of them by its own criterion
        other = path_tolerance(evaluator.robot, BOOK, grasp, by_tip.evaluations[k].joint_positions)
        assert chosen.criterion_value <= force(by_tip.evaluations[k], grasp) * (1 + other)
        assert by_tip.evaluations[k].score <= evaluation.score
        assert by_tip.postures[k].criterion == "score"
        repeated = again.postures[k]
        assert (repeated.selected, repeated.criterion_value) == (
            chosen.selected,
            chosen.criterion_value,
        )
        assert np.array_equal(again.evaluations[k].joint_positions, evaluation.joint_positions)
        differs += chosen.selected != by_tip.postures[k].selected
    assert differs  # on this arm and book, the whole arm picks other postures than the tip
    report = analyse(evaluator, grasps, BOOK, trajectory, options, ranking=by_arm)
    for k, whole in enumerate(report.whole_arm):  # what ranks is what chose the posture
        assert whole_arm_score(whole, region) == pytest.approx(
            by_arm.postures[k].criterion_value, rel=1e-12
        )


def test_a_kept_restart_posture_holds_no_kernel_buffer(baxter_book) -> None:
    """Every per-sample array of a posture kept from a restart owns its memory (a view would
    keep the batch's whole kernel buffer alive), the links-only masses too."""
    evaluator, grasps, trajectory, ranking = baxter_book
    selected = select_postures(
        evaluator, grasps, BOOK, trajectory, ranking, PostureConfig(restarts=12)
    )
    pairs = zip(selected.postures, selected.evaluations, strict=True)
    kept = [e for p, e in pairs if p.selected > 0]
    assert kept
    for e in kept:
        for name in (
            "joint_positions",
            "effective_mass_kg",
            "links_only_effective_mass_kg",
            "tip_speed_m_s",
        ):
            assert getattr(e, name).base is None, name
        assert np.array_equal(e.links_only_effective_mass_kg, e.effective_mass_kg)


def test_scrambled_halton_is_scipys_bit_for_bit() -> None:
    """The restart seeds' sequence, drawn without scipy.stats, is the one main drew with
    scipy (its ``seed`` keyword: the numpy Generator default_rng(seed) itself)."""
    from scipy.stats import qmc

    for dimensions, count, seed in ((1, 5, 0), (6, 8, 0), (7, 64, 12345), (14, 300, 2**32 - 1)):
        expected = qmc.Halton(d=dimensions, scramble=True, seed=seed).random(count)
        assert np.array_equal(scrambled_halton(dimensions, count, seed), expected)
    assert scrambled_halton(3, 0, 0).shape == (0, 3)


def test_scrambled_halton_is_kept_per_process_and_handed_out_as_copies() -> None:
    """The points of one (dimensions, count, seed) are computed once; a caller that writes
    into its copy changes nobody else's."""
    from grasp_safety_ros.core.method.halton import _scrambled_halton

    first = scrambled_halton(7, 8, 99)
    expected = first.copy()
    first[:] = -1.0
    hits = _scrambled_halton.cache_info().hits
    again = scrambled_halton(7, 8, 99)
    assert _scrambled_halton.cache_info().hits == hits + 1
    assert np.array_equal(again, expected)
    assert again.flags.writeable and again is not first


def test_restart_seeds_do_not_import_scipy_stats() -> None:
    """scipy.stats costs 0.5-1 s to import; posture selection's seeds do not need it."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from grasp_safety_ros.core import GraspSafetyEvaluator, RobotModel\n"
        "from grasp_safety_ros.core.method.posture import PostureConfig, restart_seeds\n"
        f"robot = RobotModel.from_urdf({PLANAR_URDF!r}, 'base', 'tool')\n"
        "seeds = restart_seeds(GraspSafetyEvaluator(robot), PostureConfig(restarts=8))\n"
        "print(seeds.shape, 'scipy.stats' in sys.modules)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.split("\n")[0] == "(8, 3) False"


def _reference_choice(evaluator, grasp, trajectory, single, seeds, metric):
    """The selection as specified, one start posture at a time with the public API: each
    seed's IK solution of the start pose, the new distinct ones (1e-3 rad) followed by
    ``evaluate_batch`` seeded with them, the lowest score kept (the first of equal ones)."""
    robot = evaluator.robot
    start = trajectory.transform_object_to_base_start * grasp.transform_tip_to_object
    found = [single.joint_positions[0]] if single.feasible else []
    for seed in seeds:
        q, converged, _ = evaluator.ik.solve(start, robot.q_from_positions(seed))
        positions = robot.positions_from_q(q)
        if converged and all(np.max(np.abs(positions - p)) >= 1e-3 for p in found):
            found.append(positions)
    sampled = sample_trajectory(trajectory)
    candidates = [single] + [
        evaluator.evaluate_batch(
            [single.index], [grasp], BOOK, sampled, metric, robot.q_from_positions(p)
        )[0]
        for p in found[1 if single.feasible else 0 :]
    ]
    feasible = [e for e in candidates if e.feasible]
    return min(feasible, key=lambda e: e.score) if feasible else None, len(candidates)


@pytest.mark.parametrize("metric", METRICS)
def test_batched_selection_keeps_the_reference_posture_bit_for_bit(baxter, metric) -> None:
    """All grasps' restarts and postures in batched kernel calls, with and without the early
    stop: each grasp keeps the posture the one-at-a-time reference keeps, with the same
    per-sample results bit for bit, never scoring above the single IK; the early stop only
    drops postures from the record."""
    evaluator = GraspSafetyEvaluator(baxter, EvaluationConfig(workers=1, metric=metric))
    trajectory = book_trajectory(dt_s=0.05)
    grasps = book_grasps()
    ranking = evaluator.rank(grasps, BOOK, trajectory, seed_positions=BAXTER_SEED)
    config = PostureConfig(restarts=8, early_stop=False)
    seeds = restart_seeds(evaluator, config)
    full = select_postures(evaluator, grasps, BOOK, trajectory, ranking, config)
    early = select_postures(evaluator, grasps, BOOK, trajectory, ranking, PostureConfig(8))
    for k, (grasp, single) in enumerate(zip(grasps, ranking.evaluations, strict=True)):
        expected, tried = _reference_choice(evaluator, grasp, trajectory, single, seeds, metric)
        assert expected is not None
        for selected in (full, early):
            kept, posture = selected.evaluations[k], selected.postures[k]
            assert kept.score == expected.score <= single.score
            assert posture.postures_tried == tried
            for name in ("joint_positions", "effective_mass_kg", "directions_in_base"):
                assert np.array_equal(getattr(kept, name), getattr(expected, name)), name
            assert np.array_equal(kept.ik_iterations, expected.ik_iterations)
        assert early.postures[k].postures_feasible <= full.postures[k].postures_feasible
    assert early.order == full.order
    assert not any(p.postures_stopped for p in full.postures)
    assert any(p.postures_stopped for p in early.postures)  # the default stops some here


def test_early_stop_stops_only_postures_that_score_higher(baxter_book) -> None:
    """follow_postures: a bound equal to a posture's own score never stops it (the kernel's
    running bound never exceeds the score, rounding included) and it equals evaluate_batch
    bit for bit; a bound of half the score stops every posture."""
    evaluator, grasps, trajectory, _ = baxter_book
    sampled = sample_trajectory(trajectory)
    rows = list(range(len(grasps)))
    for metric in METRICS:
        singles = [
            evaluator.evaluate(g, BOOK, trajectory, seed_positions=BAXTER_SEED, metric=metric)
            for g in grasps
        ]
        seeds = np.array([evaluator.robot.q_from_positions(e.joint_positions[0]) for e in singles])
        full = evaluator.evaluate_batch(rows, grasps, BOOK, sampled, metric, seeds)
        scores = np.array([e.score for e in full])
        same = evaluator.follow_postures(rows, grasps, BOOK, sampled, metric, seeds, scores)
        for followed, b in zip(same, full, strict=True):
            assert followed is not None and followed.feasible
            a = followed.evaluation()  # built on demand; the score read before it is its own
            assert followed.score == a.score == b.score
            assert np.array_equal(a.effective_mass_kg, b.effective_mass_kg)
            assert np.array_equal(a.directions_in_base, b.directions_in_base)
            assert np.array_equal(a.joint_positions, b.joint_positions)
        halves = evaluator.follow_postures(rows, grasps, BOOK, sampled, metric, seeds, scores / 2)
        assert halves == [None] * len(grasps), metric


def test_a_followed_postures_score_is_its_evaluations_where_the_tip_only_rotates(
    baxter, monkeypatch
) -> None:
    """follow_postures scores a posture before its GraspEvaluation is built (on demand): where
    the tip does not translate (the object turns about it: every sample's direction and mass
    the worst case, filled in after the kernel) that score is the built evaluation's and
    evaluate_batch's, bit for bit, for every metric. Each sample's worst case is computed
    once: the evaluation is built on the masses filled for the score."""
    evaluator = GraspSafetyEvaluator(baxter, EvaluationConfig(workers=1))
    start = baxter.transform_tip_to_base(BAXTER_SEED)
    turned = start * pin.SE3(pin.utils.rotate("z", 0.4), np.zeros(3))
    sampled = sample_trajectory(ObjectTrajectory(start, turned, 1.0, 0.05))
    grasps, seeds = [Grasp(pin.SE3.Identity())], baxter.q_from_positions(BAXTER_SEED)[None]
    for metric in METRICS:
        (full,) = evaluator.evaluate_batch([0], grasps, BOOK, sampled, metric, seeds)
        assert full.feasible and full.direction_is_worst_case.all(), metric
        spy = Mock(wraps=worst_direction)
        monkeypatch.setattr(ranking_module, "worst_direction", spy)
        (followed,) = evaluator.follow_postures(
            [0], grasps, BOOK, sampled, metric, seeds, np.array([np.inf])
        )
        assert followed is not None and followed.feasible
        built = followed.evaluation()
        monkeypatch.undo()
        assert spy.call_count == len(sampled.times_s)
        assert followed.score == built.score == full.score, metric
        for name in (*SAMPLE_ARRAYS, "links_only_effective_mass_kg"):  # every number
            assert np.array_equal(getattr(built, name), getattr(full, name)), name


def _unchecked_mass(mass_kg: float):
    """BOOK with a mass ObjectInertia rejects (NaN, negative): effective masses that are
    NaN or not > 0, as an indefinite or broken mass matrix would give."""
    book = copy.copy(BOOK)
    object.__setattr__(book, "mass_kg", mass_kg)
    return book


@pytest.mark.parametrize("mass_kg", [-1000.0, math.nan])
def test_early_stop_never_stops_a_posture_whose_masses_bound_nothing(baxter_book, mass_kg) -> None:
    """Masses that are NaN or not > 0 make the running max or sum no lower bound of the
    score: the kernel then never stops the row. The bound here lies above each row's score
    (negative masses: half the negative score) or is -1 (NaN scores), so a stop would be
    wrong; every row equals evaluate_batch bit for bit, and the kept posture is the one
    without the stop."""
    evaluator, grasps, trajectory, ranking = baxter_book
    sampled = sample_trajectory(trajectory)
    rows = list(range(len(grasps)))
    seeds = np.array(
        [evaluator.robot.q_from_positions(e.joint_positions[0]) for e in ranking.evaluations]
    )
    book = _unchecked_mass(mass_kg)
    for metric in METRICS:
        full = evaluator.evaluate_batch(rows, grasps, book, sampled, metric, seeds)
        masses = np.concatenate([e.effective_mass_kg for e in full])
        assert all(e.feasible for e in full) and not np.all(masses > 0.0)
        scores = np.array([e.score for e in full])
        bounds = np.where(np.isnan(scores), -1.0, scores / 2)
        assert not np.any(scores > bounds)  # no row scores above its bound
        followed = evaluator.follow_postures(rows, grasps, book, sampled, metric, seeds, bounds)
        for row, b in zip(followed, full, strict=True):
            assert row is not None, metric
            a = row.evaluation()
            assert np.array_equal(a.effective_mass_kg, b.effective_mass_kg, equal_nan=True)
            assert np.array_equal(a.joint_positions, b.joint_positions)
    if mass_kg < 0.0:
        config = PostureConfig(restarts=8, early_stop=False)
        ranked = evaluator.rank(grasps, book, trajectory, seed_positions=BAXTER_SEED)
        full_choice = select_postures(evaluator, grasps, book, trajectory, ranked, config)
        early = select_postures(evaluator, grasps, book, trajectory, ranked, PostureConfig(8))
        for ours, theirs in zip(early.evaluations, full_choice.evaluations, strict=True):
            assert np.array_equal(ours.joint_positions, theirs.joint_positions)


def test_selection_is_deterministic_and_independent_of_the_workers(baxter) -> None:
    trajectory = book_trajectory(dt_s=0.05)
    grasps = [
        Grasp(pose_from_position_quat([-0.075, y, 0.0], [0, 0, 0, 1], "g"), f"spine_{y:.3f}")
        for y in np.linspace(-0.1, 0.1, 20)
    ]
    results = []
    for workers in (1, 2, 2):
        evaluator = GraspSafetyEvaluator(
            baxter, EvaluationConfig(workers=workers, parallel_min_samples=1)
        )
        ranking = evaluator.rank(grasps, BOOK, trajectory, seed_positions=BAXTER_SEED)
        config = PostureConfig(restarts=8, early_stop=True)
        results.append(select_postures(evaluator, grasps, BOOK, trajectory, ranking, config))
    first = results[0]
    for other in results[1:]:
        assert other.order == first.order
        for a, b in zip(first.evaluations, other.evaluations, strict=True):
            assert a.score == b.score
            assert np.array_equal(a.joint_positions, b.joint_positions)
            assert np.array_equal(a.effective_mass_kg, b.effective_mass_kg)
        for a, b in zip(first.postures, other.postures, strict=True):
            assert (a.selected, a.postures_tried, a.postures_feasible) == (
                b.selected,
                b.postures_tried,
                b.postures_feasible,
            )


def test_a_small_request_shared_out_over_the_workers_keeps_every_record(baxter) -> None:
    """10 grasps (one out of reach) on a 2-worker pool go out as two jobs of 5
    (pool.job_ranges); every evaluation and selection record equals the serial one's."""
    trajectory = book_trajectory(dt_s=0.05)
    grasps = [
        Grasp(pose_from_position_quat([-0.075, y, 0.0], [0, 0, 0, 1], "g"), f"spine_{y:.3f}")
        for y in np.linspace(-0.1, 0.1, 9)
    ] + [Grasp(pose_from_position_quat([5.0, 0.0, 0.0], [0, 0, 0, 1], "g"), "far")]
    kept = []
    for workers in (1, 2):
        evaluator = GraspSafetyEvaluator(
            baxter, EvaluationConfig(workers=workers, parallel_min_samples=1)
        )
        ranking = evaluator.rank(grasps, BOOK, trajectory, seed_positions=BAXTER_SEED)
        kept.append(
            select_postures(
                evaluator, grasps, BOOK, trajectory, ranking, PostureConfig(restarts=8)
            )
        )
    serial, shared = kept
    assert shared.order == serial.order
    assert not serial.evaluations[-1].feasible and serial.evaluations[0].feasible
    for a, b in zip(serial.evaluations, shared.evaluations, strict=True):
        assert (a.feasible, a.reason, a.score) == (b.feasible, b.reason, b.score) or (
            np.isnan(a.score) and np.isnan(b.score) and a.reason == b.reason
        )
        for name in ("joint_positions", "effective_mass_kg", "directions_in_base"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
    for a, b in zip(serial.postures, shared.postures, strict=True):
        assert pickle.dumps(a) == pickle.dumps(b)


def test_python_backend_selects_the_same_postures(baxter, baxter_book) -> None:
    """Without the kernels (IKSolver.solve_poses one pose at a time, no early stop) the same
    postures are kept, to rounding."""
    evaluator, grasps, trajectory, _ = baxter_book
    python = GraspSafetyEvaluator(baxter, EvaluationConfig(workers=1, backend="python"))
    config = PostureConfig(restarts=8, early_stop=True)
    kept = [
        select_postures(
            e, grasps, BOOK, trajectory, e.rank(grasps, BOOK, trajectory, BAXTER_SEED), config
        )
        for e in (evaluator, python)
    ]
    for a, b in zip(kept[0].postures, kept[1].postures, strict=True):
        assert (a.selected, a.postures_tried) == (b.selected, b.postures_tried)
        assert a.score == pytest.approx(b.score, rel=1e-9)
        assert a.postures_feasible <= b.postures_feasible  # the kernels stopped some
