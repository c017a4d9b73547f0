"""Exposed points: point Jacobian by finite differences, tip oracle, free body, leading point."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import (
    ARM6_AXES,
    BAXTER_SEED,
    book_trajectory,
    random_positions,
    random_rotation,
    serial_arm_urdf,
)
from tolerances import assert_close_to_scale, path_tolerance

from grasp_safety_ros.core import (
    Grasp,
    GraspSafetyEvaluator,
    InvalidInputError,
    ObjectInertia,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.analyses.exposed_points import (
    box_corners_in_object,
    check_points_in_object,
    cylinder_rim_points_in_object,
    evaluate_exposed_points,
    metric_point_series,
    order_by_metric_point,
    point_jacobian_in_base,
    point_mobility_in_base,
    score_with_metric_point,
)
from grasp_safety_ros.core.input_checks import pose_from_position_quat
from grasp_safety_ros.core.method.effective_mass import augmented_model

BOOK_SIZE = (0.15, 0.22, 0.015)
BOOK = solid_box(0.34, BOOK_SIZE)
SPINE_GRASPS = [
    Grasp(pose_from_position_quat([-0.075, y, 0.0], [0, 0, 0, 1], "grasp"), f"spine_{y:+.1f}")
    for y in (-0.1, 0.0, 0.1)
]


TURNING = (0.2, -0.3, 0.25)


def test_box_corners_and_cylinder_rims() -> None:
    corners = box_corners_in_object([0.2, 0.4, 0.6], [1.0, 2.0, 3.0])
    assert corners.shape == (8, 3)
    np.testing.assert_allclose(np.abs(corners - [1.0, 2.0, 3.0]), [[0.1, 0.2, 0.3]] * 8)
    assert len({tuple(c) for c in corners}) == 8
    rims = cylinder_rim_points_in_object(0.05, 0.3, points_per_rim=6)
    assert rims.shape == (12, 3)
    np.testing.assert_allclose(np.hypot(rims[:, 0], rims[:, 1]), 0.05)
    np.testing.assert_allclose(rims[:, 2], [-0.15] * 6 + [0.15] * 6)
    np.testing.assert_allclose(rims[:6].mean(axis=0), [0.0, 0.0, -0.15], atol=1e-15)


@pytest.mark.parametrize("arm", ["arm6", "arm7"])
def test_point_jacobian_matches_finite_differences(
    arm: str, request: pytest.FixtureRequest
) -> None:
    robot: RobotModel = request.getfixturevalue(arm)
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(4)
    h = 1e-6
    for _ in range(5):
        q = robot.q_from_positions(random_positions(robot, rng))
        points = rng.uniform(-0.3, 0.3, (4, 3))
        jacobians = point_jacobian_in_base(robot, model, data, q, points)

        def positions_in_base(q_value: np.ndarray, points: np.ndarray = points) -> np.ndarray:
            tip = robot.transform_tip_to_base(robot.positions_from_q(q_value))
            return points @ tip.rotation.T + tip.translation

        for j in range(model.nv):
            step = np.zeros(model.nv)
            step[j] = h
            plus = positions_in_base(pin.integrate(model, q, step))
            minus = positions_in_base(pin.integrate(model, q, -step))
            np.testing.assert_allclose(jacobians[:, :, j], (plus - minus) / (2 * h), atol=1e-8)


def evaluate_book(baxter: RobotModel, trajectory: ObjectTrajectory) -> list:
    evaluator = GraspSafetyEvaluator(baxter)
    return [
        evaluator.evaluate(g, BOOK, trajectory, k, seed_positions=BAXTER_SEED)
        for k, g in enumerate(SPINE_GRASPS)
    ]


def test_point_at_the_tip_origin_gives_the_tip_values(baxter: RobotModel) -> None:
    trajectory = book_trajectory(goal_rotation_log=TURNING)
    evaluations = evaluate_book(baxter, trajectory)
    for evaluation, grasp in zip(evaluations, SPINE_GRASPS, strict=True):
        assert evaluation.feasible, evaluation.reason
        tip_origin_in_object = grasp.transform_tip_to_object.translation
        exposed = evaluate_exposed_points(
            baxter, evaluation, BOOK, grasp, trajectory, [tip_origin_in_object, [0, 0, 0]]
        )
        # Pinocchio (exposed points) vs the ranking's path (compiled): k · cond · eps
        tolerance = path_tolerance(baxter, BOOK, grasp, evaluation.joint_positions)
        for field, ours, theirs in (
            ("mass", exposed.effective_mass_kg[:, 0], evaluation.effective_mass_kg),
            ("direction", exposed.directions_in_base[:, 0], evaluation.directions_in_base),
            ("speed", exposed.speed_m_s[:, 0], evaluation.tip_speed_m_s),
        ):
            assert_close_to_scale(ours, theirs, field, tolerance)
        for i, positions in enumerate(evaluation.joint_positions):
            tip = baxter.transform_tip_to_base(positions)
            np.testing.assert_allclose(
                exposed.positions_in_base_m[i, 0], tip.translation, atol=2e-6
            )


def random_object(rng: np.random.Generator) -> ObjectInertia:
    box = solid_box(rng.uniform(0.1, 3.0), rng.uniform(0.02, 0.4, 3))
    rotation = random_rotation(rng)
    return ObjectInertia(
        box.mass_kg, rng.uniform(-0.1, 0.1, 3), rotation @ box.inertia_about_com_kgm2 @ rotation.T
    )


def test_free_rigid_body_closed_form_at_a_point() -> None:
    """Robot inertia negligible: 1/M = 1/m + (r×u)ᵀ I_c⁻¹ (r×u), r from the point to the CoM."""
    robot = RobotModel.from_urdf(serial_arm_urdf(ARM6_AXES, 1e-12, seed=4), "base_link", "tool")
    rng = np.random.default_rng(12)
    checked = 0
    while checked < 20:
        obj = random_object(rng)
        grasp = pin.SE3(random_rotation(rng), rng.uniform(-0.15, 0.15, 3))
        positions = random_positions(robot, rng)
        q = robot.q_from_positions(positions)
        jacobian = pin.computeFrameJacobian(
            robot.model, robot.model.createData(), q, robot.tip_frame_id
        )
        if np.linalg.svd(jacobian, compute_uv=False)[-1] < 1e-2:
            continue  # near a singularity the negligible robot inertia is not negligible
        point_in_object = rng.uniform(-0.3, 0.3, 3)
        point_in_tip = grasp.inverse().act(point_in_object)
        model = augmented_model(robot, obj, grasp)
        mobility = point_mobility_in_base(robot, model, model.createData(), q, point_in_tip[None])[
            0
        ]
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        measured = 1.0 / (direction @ mobility @ direction)
        transform_object_to_base = robot.transform_tip_to_base(positions) * grasp.inverse()
        rotation = transform_object_to_base.rotation
        lever = rotation @ (obj.com_in_object_m - point_in_object)  # point -> CoM, base axes
        inertia = rotation @ obj.inertia_about_com_kgm2 @ rotation.T
        arm = np.cross(lever, direction)
        expected = 1.0 / (1.0 / obj.mass_kg + arm @ np.linalg.solve(inertia, arm))
        assert measured == pytest.approx(expected, rel=1e-6)
        checked += 1


def test_leading_and_worst_points_under_pure_translation(baxter: RobotModel) -> None:
    """Constant orientation: every point moves along the same u at the tip's speed."""
    trajectory = book_trajectory()
    evaluation = evaluate_book(baxter, trajectory)[2]
    rotation = random_rotation(np.random.default_rng(1))
    points = box_corners_in_object(BOOK_SIZE) @ rotation.T  # a tilted box: no ties
    exposed = evaluate_exposed_points(
        baxter, evaluation, BOOK, SPINE_GRASPS[2], trajectory, points
    )
    for k in range(len(points)):
        np.testing.assert_allclose(exposed.speed_m_s[:, k], evaluation.tip_speed_m_s, atol=1e-14)
        np.testing.assert_allclose(
            exposed.directions_in_base[:, k], evaluation.directions_in_base, atol=1e-12
        )
    ahead = np.einsum("nka,na->nk", exposed.positions_in_base_m, evaluation.directions_in_base)
    np.testing.assert_array_equal(exposed.leading_point_index, np.argmax(ahead, axis=1))
    np.testing.assert_array_equal(
        exposed.worst_point_index, np.argmax(exposed.effective_mass_kg, axis=1)
    )
    assert np.all(exposed.worst_effective_mass_kg >= exposed.leading_effective_mass_kg)
    assert np.all(exposed.worst_effective_mass_kg >= exposed.effective_mass_kg.max(axis=1))


def test_metric_point_scores_and_order(baxter: RobotModel) -> None:
    trajectory = book_trajectory(goal_rotation_log=TURNING)
    evaluations = evaluate_book(baxter, trajectory)
    corners = box_corners_in_object(BOOK_SIZE)
    exposed = [
        evaluate_exposed_points(baxter, e, BOOK, g, trajectory, corners)
        for e, g in zip(evaluations, SPINE_GRASPS, strict=True)
    ]
    order, scores = order_by_metric_point(evaluations, [None] * 3, "tip", "mean")
    np.testing.assert_allclose(scores, [e.score for e in evaluations], rtol=1e-15)
    assert order == tuple(np.argsort(scores, kind="stable"))
    for metric in ("mean", "max", "integral"):
        leading = [
            score_with_metric_point(e, x, "leading_point", metric)
            for e, x in zip(evaluations, exposed, strict=True)
        ]
        worst = [
            score_with_metric_point(e, x, "worst_point", metric)
            for e, x in zip(evaluations, exposed, strict=True)
        ]
        assert all(w >= lead for w, lead in zip(worst, leading, strict=True))
    masses, speeds = metric_point_series(evaluations[0], exposed[0], "worst_point")
    np.testing.assert_allclose(masses, exposed[0].effective_mass_kg.max(axis=1))
    assert speeds.shape == masses.shape


def test_infeasible_grasp_gives_empty_arrays(baxter: RobotModel) -> None:
    trajectory = book_trajectory()
    far = Grasp(pose_from_position_quat([0.0, 0.0, 3.0], [0, 0, 0, 1], "grasp"), "far")
    evaluation = GraspSafetyEvaluator(baxter).evaluate(
        far, BOOK, trajectory, seed_positions=BAXTER_SEED
    )
    exposed = evaluate_exposed_points(
        baxter, evaluation, BOOK, far, trajectory, box_corners_in_object(BOOK_SIZE)
    )
    assert not exposed.feasible and exposed.effective_mass_kg.shape == (0, 8)
    assert np.isnan(score_with_metric_point(evaluation, exposed, "leading_point", "mean"))


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: check_points_in_object([1.0, 2.0, 3.0]), "object.points_m"),
        (lambda: check_points_in_object(np.zeros((0, 3))), "object.points_m"),
        (lambda: check_points_in_object([[0.0, np.nan, 0.0]]), "object.points_m"),
        (lambda: box_corners_in_object([0.1, 0.0, 0.1]), "object.box_size_m"),
        (lambda: cylinder_rim_points_in_object(0.1, 0.2, points_per_rim=2), "points_per_rim"),
        (lambda: cylinder_rim_points_in_object(-0.1, 0.2), r"cylinder\.radius_m"),
        (lambda: order_by_metric_point([], [], "corner", "mean"), "metric_point"),
        (lambda: order_by_metric_point([], [None], "tip", "mean"), "exposed_points"),
    ],
)
def test_bad_input_is_refused(call: object, field: str) -> None:
    with pytest.raises(InvalidInputError, match=field):
        call()  # type: ignore[operator]


def test_leading_point_needs_the_points(baxter: RobotModel) -> None:
    evaluation = evaluate_book(baxter, book_trajectory())[0]
    with pytest.raises(InvalidInputError, match="metric_point"):
        score_with_metric_point(evaluation, None, "leading_point", "mean")
