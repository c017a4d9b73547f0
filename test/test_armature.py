"""Reflected rotor inertia (armature): validation, Pinocchio's use of it, closed forms."""

from __future__ import annotations

import pickle

import numpy as np
import pinocchio as pin
import pytest
from conftest import ARM6_AXES, random_positions, serial_arm_urdf

from grasp_safety_ros.core import InvalidInputError, RobotModel
from grasp_safety_ros.core.method.effective_mass import (
    effective_mass_along,
    translational_mobility_in_base,
)

ARMATURE = (0.3, 0.25, 0.2, 0.05, 0.04, 0.03)


def one_joint_urdf(mass_kg: float, com_m: float, izz_kgm2: float, tip_m: float) -> str:
    """A link turning about z, centre of mass at com_m on x, tool frame at tip_m on x."""
    return f"""<robot name="one"><link name="base"/>
<link name="arm"><inertial><origin xyz="{com_m} 0 0"/><mass value="{mass_kg}"/>
<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="{izz_kgm2}"/></inertial></link>
<joint name="j" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
<limit lower="-3" upper="3" effort="10" velocity="3"/></joint>
<link name="tool"/><joint name="t" type="fixed"><parent link="arm"/><child link="tool"/>
<origin xyz="{tip_m} 0 0"/></joint></robot>"""


@pytest.fixture(scope="module")
def geared() -> RobotModel:
    return RobotModel.from_urdf(
        serial_arm_urdf(ARM6_AXES), "base_link", "tool", armature_kgm2=ARMATURE
    )


def symmetric(upper: np.ndarray) -> np.ndarray:
    upper = np.triu(upper)
    return upper + np.triu(upper, 1).T


def test_crba_rnea_minverse_and_aba_include_the_armature(geared: RobotModel) -> None:
    links = geared.links_only()
    assert links.armature_given is False and geared.armature_given is True
    np.testing.assert_array_equal(links.model.armature, 0.0)
    rng = np.random.default_rng(3)
    data, links_data = geared.model.createData(), links.model.createData()
    for _ in range(5):
        q = geared.q_from_positions(random_positions(geared, rng))
        v, a = rng.normal(size=(2, geared.model.nv))
        mass = symmetric(pin.crba(geared.model, data, q))
        links_mass = symmetric(pin.crba(links.model, links_data, q))
        np.testing.assert_allclose(mass, links_mass + np.diag(ARMATURE), rtol=0, atol=1e-12)
        torque = pin.rnea(geared.model, data, q, v, a)
        links_torque = pin.rnea(links.model, links_data, q, v, a)
        np.testing.assert_allclose(torque, links_torque + np.array(ARMATURE) * a, atol=1e-12)
        pin.computeMinverse(geared.model, data, q)
        np.testing.assert_allclose(symmetric(data.Minv), np.linalg.inv(mass), atol=1e-10)
        acceleration = pin.aba(geared.model, data, q, v, torque)
        np.testing.assert_allclose(acceleration, a, atol=1e-9)


def test_one_joint_arm_has_the_closed_form_effective_mass() -> None:
    mass, com, izz, tip, armature = 1.5, 0.2, 0.03, 0.4, 0.5
    robot = RobotModel.from_urdf(
        one_joint_urdf(mass, com, izz, tip), "base", "tool", armature_kgm2=[armature]
    )
    for angle in (-1.0, 0.3, 2.0):
        data = robot.model.createData()
        mobility = translational_mobility_in_base(
            robot, robot.model, data, robot.q_from_positions([angle])
        )
        tangent = np.array([-np.sin(angle), np.cos(angle), 0.0])
        expected = (izz + mass * com**2 + armature) / tip**2
        assert effective_mass_along(mobility, tangent) == pytest.approx(expected, rel=1e-12)
        links = robot.links_only()
        links_mobility = translational_mobility_in_base(
            links, links.model, links.model.createData(), robot.q_from_positions([angle])
        )
        assert effective_mass_along(links_mobility, tangent) == pytest.approx(
            (izz + mass * com**2) / tip**2, rel=1e-12
        )


def test_a_mapping_names_joints_and_the_others_get_zero() -> None:
    robot = RobotModel.from_urdf(
        serial_arm_urdf(ARM6_AXES), "base_link", "tool", armature_kgm2={"j2": 0.4, "j5": 0.1}
    )
    np.testing.assert_array_equal(robot.armature_kgm2, [0, 0.4, 0, 0, 0.1, 0])
    np.testing.assert_array_equal(robot.model.armature, [0, 0.4, 0, 0, 0.1, 0])
    with pytest.raises(ValueError):
        robot.armature_kgm2[0] = 1.0  # read-only


def test_no_armature_leaves_the_model_as_it_was() -> None:
    robot = RobotModel.from_urdf(serial_arm_urdf(ARM6_AXES), "base_link", "tool")
    assert robot.armature_given is False and robot.links_only() is robot
    np.testing.assert_array_equal(robot.model.armature, 0.0)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ([0.1] * 5, r"robot.armature_kgm2: must have one value per chain joint \(6: j1"),
        ([0.1, -0.2, 0, 0, 0, 0], r"robot.armature_kgm2\[1\] \(joint 'j2'\): must be finite"),
        ([0.1, 0, float("nan"), 0, 0, 0], r"\(joint 'j3'\): must be finite and >= 0"),
        ([0.1, 0, 0, float("inf"), 0, 0], r"\(joint 'j4'\): must be finite and >= 0"),
        ([0.1, 0, 0, 0, "heavy", 0], r"\(joint 'j5'\): must be a number >= 0"),
        ([True, 0, 0, 0, 0, 0], r"\(joint 'j1'\): must be a number >= 0"),
        ({"j9": 0.1}, r"robot.armature_kgm2: unknown chain joint 'j9'; chain joints: j1, j2"),
        ({"j3": -1.0}, r"robot.armature_kgm2.j3: must be finite and >= 0"),
        ("0.1", r"robot.armature_kgm2: must be a list of 6 values"),
    ],
)
def test_bad_armature_is_refused_naming_the_joint(value: object, message: str) -> None:
    with pytest.raises(InvalidInputError, match=message):
        RobotModel.from_urdf(serial_arm_urdf(ARM6_AXES), "base_link", "tool", armature_kgm2=value)


def test_the_armature_survives_pickling_for_the_worker_pool(geared: RobotModel) -> None:
    copy = pickle.loads(pickle.dumps(geared))
    np.testing.assert_array_equal(copy.model.armature, ARMATURE)
    np.testing.assert_array_equal(copy.links_only().model.armature, 0.0)


@pytest.mark.parametrize("backend", ["python", "compiled"])
def test_links_only_column_is_the_run_without_armature(geared: RobotModel, backend: str) -> None:
    from test_performance_paths import BOX, grasps_near_identity, reach_trajectory

    from grasp_safety_ros.core import EvaluationConfig, GraspSafetyEvaluator
    from grasp_safety_ros.core.method.ik import compiled_available

    if backend == "compiled" and not compiled_available():
        pytest.skip("numba is not installed")
    plain = RobotModel.from_urdf(serial_arm_urdf(ARM6_AXES), "base_link", "tool")
    seed = np.array([0.2, -0.5, 0.9, 0.3, 0.6, -0.2])
    trajectory = reach_trajectory(plain, seed, dt=0.05)
    grasps = grasps_near_identity(3)
    config = EvaluationConfig(backend=backend, workers=1)
    with_armature = GraspSafetyEvaluator(geared, config).rank(grasps, BOX, trajectory, seed)
    without = GraspSafetyEvaluator(plain, config).rank(grasps, BOX, trajectory, seed)
    for a, b in zip(with_armature.evaluations, without.evaluations, strict=True):
        assert a.feasible and b.feasible
        np.testing.assert_array_equal(a.joint_positions, b.joint_positions)  # IK: no inertia
        np.testing.assert_allclose(
            a.links_only_effective_mass_kg, b.effective_mass_kg, rtol=1e-12, atol=0
        )
        assert np.all(a.effective_mass_kg > a.links_only_effective_mass_kg)
        assert b.links_only_effective_mass_kg is b.effective_mass_kg  # bit for bit: the same


# --- Scenario files and the CLI --------------------------------------------------------------


def arm_scenario(tmp_path, armature: object | None) -> dict:
    from test_performance_paths import reach_trajectory

    from grasp_safety_ros.core.input_checks import quat_xyzw_from_rotation

    (tmp_path / "arm.urdf").write_text(serial_arm_urdf(ARM6_AXES))
    plain = RobotModel.from_urdf(serial_arm_urdf(ARM6_AXES), "base_link", "tool")
    seed = [0.2, -0.5, 0.9, 0.3, 0.6, -0.2]
    trajectory = reach_trajectory(plain, np.array(seed), dt=0.1)
    ends = {}
    for key, pose in (
        ("start", trajectory.transform_object_to_base_start),
        ("goal", trajectory.transform_object_to_base_goal),
    ):
        ends[key] = {
            "position_m": pose.translation.tolist(),
            "quat_xyzw": quat_xyzw_from_rotation(pose.rotation).tolist(),
        }
    robot = {"urdf": "arm.urdf", "base_frame": "base_link", "tip_frame": "tool", "seed": seed}
    if armature is not None:
        robot["armature_kgm2"] = armature
    return {
        "robot": robot,
        "object": {"mass_kg": 0.4, "box_size_m": [0.05, 0.08, 0.1]},
        "trajectory": {**ends, "duration_s": 1.0, "dt_s": 0.1},
        "grasps": [
            {"name": "a", "position_m": [0, 0, 0], "quat_xyzw": [0, 0, 0, 1]},
            {"name": "b", "position_m": [0.02, 0, 0.03], "quat_xyzw": [0, 0, 0, 1]},
        ],
        "posture": {"restarts": 0},
    }


def run_cli(tmp_path, data: dict, name: str, capsys) -> tuple[int, dict | None, str]:
    import json

    import yaml

    from grasp_safety_ros.cli.main import main

    path, out = tmp_path / f"{name}.yaml", tmp_path / f"{name}.json"
    path.write_text(yaml.safe_dump(data))
    code = main(["rank", str(path), "--json", str(out)])
    captured = capsys.readouterr()
    return code, json.loads(out.read_text()) if code == 0 else None, captured.out + captured.err


def test_armature_given_as_zero_is_given_not_missing(tmp_path, capsys) -> None:
    """A direct-drive arm (armature_kgm2: zeros, stated) has known rotor inertia, nil: no
    "not given ... a lower bound" note, in the core, the CLI's text and its JSON; leaving it
    out still gives the note. Its masses are the links' (equal to the plain arm's)."""
    from grasp_safety_ros.core.model.robot import NO_ARMATURE_NOTE

    urdf = serial_arm_urdf(ARM6_AXES)
    stated = RobotModel.from_urdf(urdf, "base_link", "tool", armature_kgm2=[0.0] * 6)
    assert stated.armature_given and stated.links_only() is stated
    np.testing.assert_array_equal(stated.model.armature, 0.0)
    assert not RobotModel.from_urdf(urdf, "base_link", "tool").armature_given
    code, direct, text = run_cli(tmp_path, arm_scenario(tmp_path, [0.0] * 6), "direct", capsys)
    assert code == 0 and NO_ARMATURE_NOTE not in text
    assert direct["armature"]["given"] is True and direct["armature"]["note"] == ""
    code, plain, text = run_cli(tmp_path, arm_scenario(tmp_path, None), "plain", capsys)
    assert code == 0 and text.count(NO_ARMATURE_NOTE) == 1 and not plain["armature"]["given"]
    for ours, theirs in zip(direct["grasps"], plain["grasps"], strict=True):
        assert ours["samples"]["effective_mass_kg"] == theirs["samples"]["effective_mass_kg"]


def test_scenario_armature_gives_both_columns_and_the_note_once(tmp_path, capsys) -> None:
    from grasp_safety_ros.core.model.robot import NO_ARMATURE_NOTE

    code, plain, text = run_cli(tmp_path, arm_scenario(tmp_path, None), "plain", capsys)
    assert code == 0 and text.count(NO_ARMATURE_NOTE) == 1
    assert plain["armature"]["given"] is False and plain["armature"]["ratio_median"] == 1.0
    for grasp in plain["grasps"]:
        samples = grasp["samples"]  # the links-only column is today's number, bit for bit
        assert samples["links_only_effective_mass_kg"] == samples["effective_mass_kg"]
    as_list = arm_scenario(tmp_path, list(ARMATURE))
    code, geared, text = run_cli(tmp_path, as_list, "geared", capsys)
    assert code == 0 and NO_ARMATURE_NOTE not in text and "links [kg]" in text
    named = {f"j{k + 1}": value for k, value in enumerate(ARMATURE)}
    code, mapped, _ = run_cli(tmp_path, arm_scenario(tmp_path, named), "mapped", capsys)
    assert mapped["grasps"] == geared["grasps"]
    assert geared["armature"]["given"] is True and geared["armature"]["ratio_p10"] > 1.0
    for grasp, base in zip(geared["grasps"], plain["grasps"], strict=True):
        samples, reference = grasp["samples"], base["samples"]
        assert samples["links_only_effective_mass_kg"] == pytest.approx(
            reference["effective_mass_kg"], rel=1e-12
        )
        assert np.all(
            np.array(samples["effective_mass_kg"])
            > np.array(samples["links_only_effective_mass_kg"])
        )


@pytest.mark.parametrize(
    ("armature", "message"),
    [
        ([0.1, 0.1, -1, 0, 0, 0], "robot.armature_kgm2[2] (joint 'j3'): must be finite and >= 0"),
        ({"j7": 0.1}, "robot.armature_kgm2: unknown chain joint 'j7'"),
        ("heavy", "robot.armature_kgm2: must be a list, a mapping"),
        ("published", "robot.armature_kgm2: no published armature for 'arm.urdf'"),
        ("published:franka_fr3", "published entry 'franka_fr3' names none of the chain joints"),
        ([[0.3, 0.1], 0, 0, 0, 0, 0], "robot.armature_kgm2[0] (joint 'j1'): range [lo, hi]"),
    ],
)
def test_bad_scenario_armature_exits_2_naming_the_field(
    tmp_path, capsys, armature: object, message: str
) -> None:
    code, _, text = run_cli(tmp_path, arm_scenario(tmp_path, armature), "bad", capsys)
    assert code == 2 and message in text, text


def test_published_fr3_values_go_to_the_panda() -> None:
    from grasp_safety_ros.core.model.armature import published_armatures
    from grasp_safety_ros.scenario.schema import RobotSpec

    entry = published_armatures()["franka_fr3"]
    assert entry.status == "identified" and "panda" in entry.robots
    spec = RobotSpec(
        "example-robot-data:panda", "panda_link0", "panda_hand", None, None, "published"
    )
    robot = spec.load()
    np.testing.assert_array_equal(robot.armature_kgm2, [0.195] * 4 + [0.074] * 3)
    assert spec.published_armature(robot) is entry


def test_armature_ranges_bound_the_effective_mass_by_their_ends(tmp_path, capsys) -> None:
    lower, upper = np.array(ARMATURE) * 0.5, np.array(ARMATURE) * 2.0
    ranges = [[float(lo), float(hi)] for lo, hi in zip(lower, upper, strict=True)]
    ranged = arm_scenario(tmp_path, ranges)
    code, result, text = run_cli(tmp_path, ranged, "ranged", capsys)
    assert code == 0 and "armature ranges (tip effective mass): ranking" in text
    assert result["grasps"][0]["feasible"]
    _, at_lower, _ = run_cli(tmp_path, arm_scenario(tmp_path, lower.tolist()), "low", capsys)
    spread = result["armature_range"]
    assert spread["upper_kgm2"] == upper.tolist() and spread["lower_kgm2"] == lower.tolist()
    for k, (grasp, low) in enumerate(zip(result["grasps"], at_lower["grasps"], strict=True)):
        if not grasp["feasible"]:
            assert spread["effective_mass_range_kg"][k] == [None, None]
            continue
        masses = grasp["samples"]["effective_mass_kg"]  # ranked: the upper ends
        masses_low = low["samples"]["effective_mass_kg"]
        assert spread["effective_mass_range_kg"][k] == pytest.approx(
            [min(masses_low), max(masses)], rel=1e-12
        )
        assert spread["scores_lower"][k] == pytest.approx(low["score"], rel=1e-12)
        assert spread["scores_upper"][k] == pytest.approx(grasp["score"], rel=1e-12)
    assert spread["order_upper"] == result["paper_ranking"]
    assert spread["order_lower"] == at_lower["paper_ranking"]
    assert spread["ranking_flips"] == (spread["order_lower"] != spread["order_upper"])


# --- Node parameters (pure: no rclpy) --------------------------------------------------------


def node_settings(**values: object):
    from grasp_safety_ros.ros.parameters import settings_from_parameters

    return settings_from_parameters(
        {
            "urdf": "example-robot-data:panda",
            "base_frame": "panda_link0",
            "tip_frame": "panda_hand",
            **values,
        }
    )


def test_node_armature_parameters_build_the_chain_with_it() -> None:
    from grasp_safety_ros.ros.robot.bundle import build_robot

    fr3 = [0.195] * 4 + [0.074] * 3
    for values in (
        {"robot.armature_kgm2": fr3},
        {"robot.armature_published": "published"},
        {"robot.armature_published": "published:franka_fr3"},
        {
            "robot.armature_kgm2": fr3[::-1],
            "robot.armature_joint_names": [f"panda_joint{k}" for k in range(7, 0, -1)],
        },
    ):
        bundle = build_robot(node_settings(**values), None)
        assert bundle is not None
        np.testing.assert_array_equal(bundle.robot.armature_kgm2, fr3)
    plain = build_robot(node_settings(), None)
    assert plain is not None and not plain.robot.armature_given


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"robot.armature_kgm2": [0.1, -0.2]}, r"robot.armature_kgm2\[1\]: must be >= 0"),
        ({"robot.armature_kgm2": [0.1] * 3}, "robot.armature_kgm2: must have one value per"),
        (
            {"robot.armature_kgm2": [0.1], "robot.armature_joint_names": ["elbow"]},
            "robot.armature_kgm2: unknown chain joint 'elbow'",
        ),
        (
            {"robot.armature_kgm2": [0.1], "robot.armature_joint_names": ["a", "b"]},
            "robot.armature_joint_names: has 2 names for 1 values",
        ),
        ({"robot.armature_published": "yes"}, "robot.armature_published: must be empty"),
        ({"robot.armature_published": "published:kuka"}, "no published entry 'kuka'"),
    ],
)
def test_bad_node_armature_parameters_are_refused_by_name(values: dict, message: str) -> None:
    from grasp_safety_ros.ros.robot.bundle import build_robot

    with pytest.raises(InvalidInputError, match=message):
        build_robot(node_settings(**values), None)


# --- Service response and diagnostics ---------------------------------------------------------


@pytest.mark.parametrize("backend", ["python"])
def test_response_carries_both_masses_the_ratio_and_the_note(geared: RobotModel, backend) -> None:
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Pose, PoseArray
    from test_performance_paths import BOX, grasps_near_identity, reach_trajectory

    from grasp_safety_ros.core import EvaluationConfig, GraspSafetyEvaluator
    from grasp_safety_ros.core.model.robot import NO_ARMATURE_NOTE
    from grasp_safety_ros.ros.conversions import ranking_msg

    seed = np.array([0.2, -0.5, 0.9, 0.3, 0.6, -0.2])
    plain = geared.links_only()
    trajectory = reach_trajectory(plain, seed, dt=0.1)
    grasps = grasps_near_identity(2)
    poses = PoseArray(poses=[Pose(), Pose()])
    config = EvaluationConfig(backend=backend, workers=1)
    direct_drive = plain.with_armature(np.zeros(plain.num_joints))  # given as zero: given
    assert direct_drive.armature_given and not plain.armature_given
    for robot in (geared, plain, direct_drive):
        ranking = GraspSafetyEvaluator(robot, config).rank(grasps, BOX, trajectory, seed)
        message = ranking_msg(ranking, poses, "base_link", Time(), 0.0)
        assert message.armature_given == robot.armature_given
        assert message.armature_note == ("" if robot.armature_given else NO_ARMATURE_NOTE)
        ratios = []
        for got, want in zip(message.evaluations, ranking.evaluations, strict=True):
            np.testing.assert_array_equal(
                got.links_only_effective_mass_kg, want.links_only_effective_mass_kg
            )
            assert got.links_only_mean_effective_mass_kg == pytest.approx(
                np.mean(want.links_only_effective_mass_kg), rel=1e-15
            )
            ratios.append(want.effective_mass_kg / want.links_only_effective_mass_kg)
        assert message.armature_ratio_median == pytest.approx(np.median(ratios), rel=1e-15)
        if not robot.armature_given:
            assert message.armature_ratio_median == 1.0


# --- The analyses inherit the armature ----------------------------------------------------------


def test_effort_and_uncertainty_include_the_armature(geared: RobotModel) -> None:
    from test_performance_paths import BOX, grasps_near_identity, reach_trajectory

    from grasp_safety_ros.core import EvaluationConfig, GraspSafetyEvaluator
    from grasp_safety_ros.core.analyses.effort import evaluate_effort
    from grasp_safety_ros.core.analyses.uncertainty import (
        InertiaUncertainty,
        analyse_inertia_uncertainty,
    )

    plain = geared.links_only()
    seed = np.array([0.2, -0.5, 0.9, 0.3, 0.6, -0.2])
    trajectory = reach_trajectory(plain, seed, dt=0.05)
    grasps = grasps_near_identity(2)
    config = EvaluationConfig(workers=1)
    ranking = GraspSafetyEvaluator(geared, config).rank(grasps, BOX, trajectory, seed)
    evaluation = ranking.evaluations[0]
    assert evaluation.feasible
    with_armature = evaluate_effort(geared, evaluation, BOX, grasps[0], trajectory)
    links_only = evaluate_effort(plain, evaluation, BOX, grasps[0], trajectory)
    np.testing.assert_array_equal(
        with_armature.joint_accelerations, links_only.joint_accelerations
    )
    assert np.abs(links_only.joint_accelerations).max() > 1e-2  # the armature term shows
    np.testing.assert_allclose(  # rnea adds a_k q̈_k per joint
        with_armature.joint_torques,
        links_only.joint_torques + np.array(ARMATURE) * links_only.joint_accelerations,
        rtol=0,
        atol=1e-10,
    )
    feasible = [e for e in ranking.evaluations if e.feasible]
    spread = analyse_inertia_uncertainty(
        geared,
        feasible,
        [grasps[e.index] for e in feasible],
        BOX,
        InertiaUncertainty(mass_fraction=0.1, num_random_samples=2),
    )
    for result, e in zip(spread.grasps, feasible, strict=True):
        assert result.nominal_score == pytest.approx(e.score, rel=1e-9)
        assert result.nominal_score > 1.05 * np.mean(e.links_only_effective_mass_kg)


def test_cli_header_names_the_published_entry(tmp_path, capsys) -> None:
    start = {"position_m": [0.45, 0.0, 0.4], "quat_xyzw": [1, 0, 0, 0]}
    scenario = {
        "robot": {
            "urdf": "example-robot-data:panda",
            "base_frame": "panda_link0",
            "tip_frame": "panda_hand",
            "seed": [0.0, -0.5, 0.0, -2.0, 0.0, 1.6, 0.8],
            "armature_kgm2": "published",
        },
        "object": {"mass_kg": 0.5, "box_size_m": [0.05, 0.1, 0.15]},
        "trajectory": {"start": start, "goal": start, "duration_s": 1.0, "dt_s": 0.5},
        "grasps": [{"name": "a", "position_m": [0, 0, 0], "quat_xyzw": [0, 0, 0, 1]}],
        "posture": {"restarts": 0},
    }
    code, result, text = run_cli(tmp_path, scenario, "panda", capsys)
    assert code == 0 and "armature: published 'franka_fr3' (identified, 2025-04-25)" in text
    assert result["armature"]["given"] is True
