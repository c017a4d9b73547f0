"""MuJoCo validation (issue #4): the engine model agrees with the core, and the quick run.

The model-builder tests use independent oracles: Pinocchio's ``crba``, forward kinematics and
gravity on the same URDF, and the core's effective mass. The quick run checks the claims
the full run reports (docs/validation/results.md) with thresholds justified below.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
from conftest import ARM7_AXES, BAXTER_SEED, random_positions, random_rotation, serial_arm_urdf

mujoco = pytest.importorskip("mujoco")

from grasp_safety_ros.core import GraspSafetyEvaluator, RobotModel  # noqa: E402
from grasp_safety_ros.core.exceptions import InvalidInputError, RobotModelError  # noqa: E402
from grasp_safety_ros.core.method.effective_mass import (  # noqa: E402
    augmented_model,
    effective_mass_along,
    translational_mobility_in_base,
)
from grasp_safety_ros.core.method.ranking import Grasp  # noqa: E402
from grasp_safety_ros.core.model.inertia import TensorObjectGeometry, solid_box  # noqa: E402
from grasp_safety_ros.validation import format_summary, reproduce  # noqa: E402
from grasp_safety_ros.validation.experiments import (  # noqa: E402
    ROBOT_SOURCE,
    SEED_POSITIONS,
    book_experiment,
)
from grasp_safety_ros.validation.scene import (  # noqa: E402
    ContactConfig,
    SensorConfig,
    add_object,
    add_obstacle,
    add_tip_sphere,
    arm_urdf_for_mujoco,
    base_spec,
    compile_scene,
    engine_effective_mass,
    joint_space_inertia,
)
from grasp_safety_ros.validation.simulation import (  # noqa: E402
    CollisionSetup,
    ControllerGains,
    ImpulseChecker,
    ImpulseSetup,
)

ARM7_URDF = serial_arm_urdf(ARM7_AXES, seed=1)
TIGHT = 1e-10
"""Relative agreement of two rigid-body engines on the same model (both are exact)."""


def _symmetric(upper: np.ndarray) -> np.ndarray:
    return np.triu(upper) + np.triu(upper, 1).T


def _robot_scene(robot: RobotModel, source: str, obj=None, grasp=None):
    spec = base_spec(robot, source, timestep_s=1e-4)
    if obj is not None:
        add_object(spec, robot.tip_frame, obj, grasp)
    return compile_scene(spec, robot)


def _some_object_and_grasp(rng: np.random.Generator):
    obj = TensorObjectGeometry().inertia(0.05, 0.12)
    grasp = pin.SE3(random_rotation(rng), rng.uniform(-0.15, 0.15, 3))
    return obj, grasp


# --- the MuJoCo model builder -------------------------------------------------------------


@pytest.mark.parametrize("source", ["arm7", "baxter"])
def test_engine_mass_matrix_equals_pinocchio_crba(source: str, request) -> None:
    robot = request.getfixturevalue(source)
    urdf = ARM7_URDF if source == "arm7" else ROBOT_SOURCE
    scene = _robot_scene(robot, urdf)
    rng = np.random.default_rng(0)
    for _ in range(5):
        positions = random_positions(robot, rng)
        expected = _symmetric(
            pin.crba(robot.model, robot.model.createData(), robot.q_from_positions(positions))
        )
        got = joint_space_inertia(scene, positions)
        assert np.abs(got - expected).max() <= TIGHT * np.abs(expected).max()


def test_engine_mass_matrix_with_armature_equals_pinocchio_crba(arm7: RobotModel) -> None:
    armature = [0.5, 0.4, 0.3, 0.2, 0.1, 0.05, 0.02]
    geared = arm7.with_armature(armature)
    scene = _robot_scene(geared, ARM7_URDF)
    np.testing.assert_array_equal(scene.model.dof_armature[scene.arm_dof], armature)
    rng = np.random.default_rng(4)
    for _ in range(5):
        positions = random_positions(arm7, rng)
        q = arm7.q_from_positions(positions)
        expected = _symmetric(pin.crba(geared.model, geared.model.createData(), q))
        links = _symmetric(pin.crba(arm7.model, arm7.model.createData(), q))
        np.testing.assert_allclose(expected, links + np.diag(armature), atol=1e-12)
        got = joint_space_inertia(scene, positions)
        assert np.abs(got - expected).max() <= TIGHT * np.abs(expected).max()


def test_engine_mass_matrix_with_object_equals_augmented_crba(baxter: RobotModel) -> None:
    rng = np.random.default_rng(1)
    obj, grasp = _some_object_and_grasp(rng)
    scene = _robot_scene(baxter, ROBOT_SOURCE, obj, grasp)
    model = augmented_model(baxter, obj, grasp)
    bare = _robot_scene(baxter, ROBOT_SOURCE)
    for _ in range(5):
        positions = random_positions(baxter, rng)
        expected = _symmetric(pin.crba(model, model.createData(), positions))
        got = joint_space_inertia(scene, positions)
        assert np.abs(got - expected).max() <= TIGHT * np.abs(expected).max()
        # The object is really there: without it the matrices differ clearly.
        assert np.abs(joint_space_inertia(bare, positions) - expected).max() > 1e-3


def test_engine_tip_pose_and_gravity_equal_pinocchio(baxter: RobotModel) -> None:
    rng = np.random.default_rng(2)
    obj, grasp = _some_object_and_grasp(rng)
    scene = _robot_scene(baxter, ROBOT_SOURCE, obj, grasp)
    model = augmented_model(baxter, obj, grasp)
    for _ in range(5):
        positions = random_positions(baxter, rng)
        joint_space_inertia(scene, positions)  # sets the state and runs mj_forward
        tip = baxter.transform_base_to_world.act(baxter.transform_tip_to_base(positions))
        assert np.allclose(scene.data.xpos[scene.tip_body], tip.translation, atol=1e-12)
        assert np.allclose(scene.data.xmat[scene.tip_body].reshape(3, 3), tip.rotation, atol=1e-12)
        gravity = pin.computeGeneralizedGravity(model, model.createData(), positions)
        bias = scene.data.qfrc_bias[scene.arm_dof]
        assert np.abs(bias - gravity).max() <= 1e-10 * np.abs(gravity).max()


def test_engine_effective_mass_equals_core(baxter: RobotModel) -> None:
    rng = np.random.default_rng(3)
    obj, grasp = _some_object_and_grasp(rng)
    scene = _robot_scene(baxter, ROBOT_SOURCE, obj, grasp)
    model = augmented_model(baxter, obj, grasp)
    data = model.createData()
    for _ in range(10):
        positions = random_positions(baxter, rng)
        direction = rng.normal(size=3)
        joint_space_inertia(scene, positions)
        mobility = translational_mobility_in_base(baxter, model, data, positions)
        expected = effective_mass_along(mobility, direction)
        assert engine_effective_mass(scene, direction) == pytest.approx(expected, rel=TIGHT)


def test_only_the_chain_moves_and_only_added_geoms_exist(baxter: RobotModel) -> None:
    scene = _robot_scene(baxter, ROBOT_SOURCE)
    model = scene.model
    assert model.nv == 7
    assert [model.joint(i).name for i in range(model.njnt)] == list(baxter.joint_names)
    assert model.ngeom == 0  # every URDF visual and collision is stripped
    assert np.all(model.dof_damping == 0.0)
    assert np.all(model.dof_armature == 0.0)
    assert np.all(model.dof_frictionloss == 0.0)


def test_urdf_without_a_chain_joint_is_refused(baxter: RobotModel) -> None:
    with pytest.raises(RobotModelError, match=r"right_s0"):
        arm_urdf_for_mujoco(baxter, ARM7_URDF)


def test_scene_parts_collide_only_with_each_other(baxter: RobotModel) -> None:
    spec = base_spec(baxter, ROBOT_SOURCE, timestep_s=1e-4)
    add_object(spec, baxter.tip_frame, solid_box(0.34, (0.15, 0.22, 0.015)), pin.SE3.Identity())
    contact = ContactConfig()
    add_tip_sphere(spec, baxter.tip_frame, 0.02, contact)
    add_obstacle(
        spec, np.array([1.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0]), contact, SensorConfig()
    )
    scene = compile_scene(spec, baxter)
    model = scene.model
    colliding = [
        g for g in range(model.ngeom) if model.geom_contype[g] or model.geom_conaffinity[g]
    ]
    assert sorted(colliding) == sorted([scene.sphere_geom, scene.face_geom])
    assert scene.sensor_dof >= 0
    assert model.body_mass[model.body("grasped_object").id] == pytest.approx(0.34)


@pytest.mark.parametrize(
    ("factory", "message"),
    [
        (lambda: ContactConfig(friction=-0.1), "contact.friction"),
        (lambda: ContactConfig(timeconst_s=0.0), "contact.timeconst_s"),
        (lambda: ContactConfig(impedance=1.0), "contact.impedance"),
        (lambda: SensorConfig(stiffness_n_m=-1.0), "sensor.stiffness_n_m"),
        (lambda: ControllerGains(kp_per_s2=0.0), "controller.kp_per_s2"),
        (lambda: ControllerGains(period_s=0.0), "controller.period_s"),
        (lambda: CollisionSetup(start_time_s=1.6, impact_time_s=1.5), "collision.times"),
        (lambda: ImpulseSetup(contact=ContactConfig(friction=0.5)), "frictionless"),
    ],
)
def test_settings_are_validated(factory, message: str) -> None:
    with pytest.raises(InvalidInputError, match=message):
        factory()


# --- the free-impact check -----------------------------------------------------------------


@pytest.fixture(scope="module")
def book_spine_evaluation(baxter: RobotModel):
    experiment = book_experiment()
    grasp = experiment.grasps[0]
    evaluation = GraspSafetyEvaluator(baxter).evaluate(
        Grasp(grasp.transform_tip_to_object),
        grasp.object_inertia,
        experiment.trajectory,
        seed_positions=SEED_POSITIONS,
    )
    assert evaluation.feasible
    checker = ImpulseChecker(
        baxter, ROBOT_SOURCE, grasp.object_inertia, grasp.transform_tip_to_object
    )
    return evaluation, checker


def test_free_impact_impulse_is_restitution_times_effective_mass(book_spine_evaluation) -> None:
    evaluation, checker = book_spine_evaluation
    for index in (50, 150):
        mass = float(evaluation.effective_mass_kg[index])
        case = checker.run(
            evaluation.joint_positions[index], evaluation.directions_in_base[index], mass
        )
        assert not case.limit_active
        assert 0.0 < case.restitution < 0.5  # stiff, critically damped contact: e ~ e^-2
        assert case.rel_error <= 0.005
        assert case.engine_effective_mass_kg == pytest.approx(mass, rel=TIGHT)


def test_free_impacts_at_random_states_match_the_core(baxter: RobotModel) -> None:
    rng = np.random.default_rng(4)
    obj, grasp = _some_object_and_grasp(rng)
    checker = ImpulseChecker(baxter, ROBOT_SOURCE, obj, grasp)
    model = augmented_model(baxter, obj, grasp)
    data = model.createData()
    for _ in range(6):
        positions = random_positions(baxter, rng)
        direction = rng.normal(size=3)
        mass = effective_mass_along(
            translational_mobility_in_base(baxter, model, data, positions), direction
        )
        case = checker.run(positions, direction, mass)
        assert not case.limit_active
        assert case.rel_error <= 0.005


def test_free_impact_check_fails_for_a_wrong_effective_mass(book_spine_evaluation) -> None:
    evaluation, checker = book_spine_evaluation
    index = 150
    wrong = 1.05 * float(evaluation.effective_mass_kg[index])
    case = checker.run(
        evaluation.joint_positions[index], evaluation.directions_in_base[index], wrong
    )
    assert case.rel_error > 0.03


# --- the quick run ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("validation")
    return out, reproduce(out, quick=True)


REQUIRED = {
    "tensor_object": ("spearman_meff_vs_peak_force", "grasps"),
    "book": ("peak_force_ratio_worst_to_best", "grasps"),
    "impulse_check": ("worst_rel_error", "cases"),
}
PER_GRASP = (
    "mean_effective_mass_kg",
    "effective_mass_at_impact_kg",
    "peak_force_n",
    "impulse_n_s",
)


def test_quick_run_writes_results_figures_and_report(quick_run) -> None:
    out, results = quick_run
    written = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert written == results
    for section, keys in REQUIRED.items():
        for key in keys:
            assert key in results[section]
    for section in ("tensor_object", "book"):
        for grasp in results[section]["grasps"]:
            for key in PER_GRASP:
                assert isinstance(grasp[key], float) and grasp[key] > 0.0
    assert len(results["tensor_object"]["grasps"]) == 6
    assert len(results["book"]["grasps"]) == 3
    assert results["figures"]
    for name in results["figures"]:
        assert (out / name).stat().st_size > 10_000
    report = (out / "results.md").read_text(encoding="utf-8")
    assert "grasp-safety reproduce --out" in report and "--quick" in report
    assert "1.30" in report  # the paper's ratio next to ours
    summary = format_summary(results)
    assert "Spearman" in summary and "impulse check" in summary


def test_quick_run_impulse_check(quick_run) -> None:
    check = quick_run[1]["impulse_check"]
    assert check["cases"] == 9 * 2
    # The criterion is 3 %; the physics gives ~2e-4 (finite contact duration), so
    # 0.5 % still leaves a margin of 20 and catches a model error of that size.
    assert check["worst_rel_error"] <= 0.03
    assert check["worst_rel_error"] <= 0.005
    assert check["joint_limit_active_cases"] == 0
    assert check["engine_vs_core_effective_mass_max_rel_diff"] <= 1e-9


def test_quick_run_peak_force_follows_effective_mass(quick_run) -> None:
    results = quick_run[1]
    tensor, book = results["tensor_object"], results["book"]
    # Tensor: the simulation gives Spearman 1.0 on these 6 configurations (0.97 on all 20 in
    # the full run). The closest pair here (T04, T17) differs by 0.10 % in effective mass and
    # by ~0.05 % in peak force, within the numerical noise of a peak (up to 0.14 % between
    # repeats of the full run); one swap of that pair gives 0.943, two swaps 0.886.
    assert tensor["spearman_meff_vs_peak_force"] >= 0.9
    # Book: the effective masses at impact are 1.0 % and 1.3 % apart, the peaks 0.7 % and
    # 0.8 % (noise <= 0.14 %): the order holds; worst/best ~1.015 (the paper's Gazebo: 1.3).
    assert book["ordering_holds"]
    assert 1.005 < book["peak_force_ratio_worst_to_best"] < 1.05
    for grasp in tensor["grasps"] + book["grasps"]:
        assert grasp["tracking_error_before_contact_rad"] < 1e-3
        assert abs(grasp["contact_time_s"] - 1.5) < 2e-3
        assert grasp["approach_speed_m_s"] == pytest.approx(0.2182, rel=0.01)


def test_quick_run_posture_selection_against_single_ik(quick_run) -> None:
    out, results = quick_run
    postures = results["posture_selection"]
    assert postures["experiment"] == "book" and len(postures["grasps"]) == 3
    for g in postures["grasps"]:
        assert g["mean_effective_mass_selected_kg"] <= g["mean_effective_mass_single_ik_kg"]
        assert 1 <= g["postures_feasible"] <= g["postures_tried"]
        if g["selected_is_single_ik"]:
            assert g["peak_force_change"] == 0.0
            continue
        assert g["start_positions_selected"] != g["start_positions_single_ik"]
        # a change of the effective mass at impact well above the peak's numerical noise
        # (0.14 %) moves the peak force the same way
        if abs(g["effective_mass_at_impact_change"]) > 0.005:
            assert g["peak_force_change"] * g["effective_mass_at_impact_change"] > 0.0
    report = (out / "results.md").read_text(encoding="utf-8")
    assert "## Posture selection: single IK against the selected posture" in report
    assert "posture selection vs single IK" in format_summary(results)


def test_baxter_seed_is_the_validation_seed() -> None:
    assert tuple(SEED_POSITIONS) == tuple(BAXTER_SEED)


def test_quick_run_waypoint_path(quick_run) -> None:
    """The book along the three-waypoint path: simulated with the same pillar setup; its
    effective masses at impact are about 8 % apart (quick run), far above the noise, and the
    peak forces follow them; the report shows the change from the straight path."""
    out, results = quick_run
    waypoints, straight = results["book_waypoints"], results["book"]
    assert len(waypoints["grasps"]) == 3
    assert waypoints["ordering_holds"]
    assert waypoints["effective_mass_ratio_worst_to_best"] > 1.05
    for grasp, other in zip(waypoints["grasps"], straight["grasps"], strict=True):
        assert grasp["tracking_error_before_contact_rad"] < 1e-3
        assert abs(grasp["contact_time_s"] - 1.5) < 2e-3
        # Another path: the effective mass at impact is not the straight path's.
        assert (
            abs(grasp["effective_mass_at_impact_kg"] / other["effective_mass_at_impact_kg"] - 1)
            > 0.01
        )
    changes = waypoints["change_from_straight_path"]
    assert [c["name"] for c in changes] == [g["name"] for g in straight["grasps"]]
    report = (out / "results.md").read_text(encoding="utf-8")
    assert "## Book along a timed waypoint path" in report


def test_quick_run_elbow_impact(quick_run) -> None:
    """A free impact at the elbow site follows the whole-arm effective mass (MuJoCo's own M and
    J agree with it), and the tip's effective mass in its place is far off."""
    results = quick_run[1]
    elbow = results["elbow_impact"]
    assert (elbow["site"], elbow["link"]) == ("right_e1", "right_lower_elbow")
    assert not elbow["stationary"] and not elbow["joint_limit_active"]
    assert elbow["engine_effective_mass_kg"] == pytest.approx(elbow["effective_mass_kg"], 1e-9)
    assert elbow["rel_error"] <= 0.005
    assert elbow["rel_error_with_tip_mass"] >= 1.0
    assert "elbow impact (right_e1" in format_summary(results)
    report = (quick_run[0] / "results.md").read_text()
    assert "- Elbow impact: a free impact at the whole-arm site right_e1" in report


def test_free_impacts_with_armature_follow_the_effective_mass_with_it() -> None:
    """MuJoCo's dof_armature set from the same values: the impulse is (1 + e)·M_eff·v with the
    armature's effective mass; the links-only prediction misses it by far more."""
    from grasp_safety_ros.validation.armature_check import armature_impulse_check
    from grasp_safety_ros.validation.simulation import ImpulseSetup

    result = armature_impulse_check(3, ImpulseSetup(), seed=1)
    assert result["valid_cases"] >= 2
    assert result["worst_rel_error"] < 5e-3
    assert result["links_only_min_rel_error"] > 0.1
    # The peak force follows the same M_eff: peak / (M_eff v) is one constant with armature.
    assert result["peak_force_per_mass_spread"] < 1.05
    assert result["links_only_peak_force_per_mass_spread"] > result["peak_force_per_mass_spread"]
    for case in result["per_case"]:
        assert case["engine_effective_mass_kg"] == pytest.approx(
            case["effective_mass_kg"], rel=1e-9
        )
