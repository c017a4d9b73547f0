"""Robots and frames for a newcomer: every chain `grasp-safety robots` lists works from its seed,
every URDF of example-robot-data can be named, `grasp-safety frames` shows kinds and the tree,
and an unknown frame gets the closest names first, links and joints apart, in a short line."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import serial_arm_urdf

from grasp_safety_ros.cli.main import main
from grasp_safety_ros.cli.robots import load_any_model
from grasp_safety_ros.core.exceptions import FrameNotFoundError, InvalidInputError
from grasp_safety_ros.core.method.ranking import EvaluationConfig, Grasp, GraspSafetyEvaluator
from grasp_safety_ros.core.model.bundled_robots import BUNDLED_ROBOTS
from grasp_safety_ros.core.model.description import (
    example_robot_data_dirs,
    example_robot_data_names,
    is_mjcf,
    load_urdf_model,
    resolve_urdf,
)
from grasp_safety_ros.core.model.inertia import solid_box
from grasp_safety_ros.core.model.robot import RobotModel, frames_by_kind
from grasp_safety_ros.core.model.trajectory import ObjectTrajectory

MIN_SINGULAR_VALUE = 0.03
"""Least sixth singular value of the tip Jacobian at a listed seed (away from singularities)."""


@pytest.mark.parametrize("entry", BUNDLED_ROBOTS, ids=lambda entry: entry.name)
def test_each_listed_robot_loads_and_ranks_from_its_seed(entry) -> None:
    robot = RobotModel.from_urdf(entry.urdf, entry.base_frame, entry.tip_frame)
    assert robot.num_joints == len(entry.seed)
    seed = robot.check_positions(entry.seed, "seed")  # within the joint limits
    tip_in_base = robot.transform_tip_to_base(seed)
    assert np.isfinite(tip_in_base.homogeneous).all()
    data = robot.model.createData()
    jacobian = pin.computeFrameJacobian(
        robot.model, data, robot.q_from_positions(seed), robot.tip_frame_id, pin.LOCAL
    )
    assert np.linalg.svd(jacobian, compute_uv=False)[5] > MIN_SINGULAR_VALUE
    # a tiny ranking: the object held at the tip (identity grasp) moved 3 cm along the base z
    goal = pin.SE3(tip_in_base.rotation, tip_in_base.translation + np.array([0.0, 0.0, 0.03]))
    trajectory = ObjectTrajectory(tip_in_base, goal, 1.0, 0.25)
    evaluator = GraspSafetyEvaluator(robot, EvaluationConfig(metric="mean"))
    ranking = evaluator.rank(
        [Grasp(np.eye(4), "at_tip")], solid_box(0.3, [0.1, 0.1, 0.1]), trajectory, seed
    )
    evaluation = ranking.evaluations[0]
    assert evaluation.feasible, evaluation.reason
    assert np.isfinite(evaluation.score) and evaluation.score > 0.0
    np.testing.assert_allclose(evaluation.joint_positions[0], seed, atol=1e-3)


def test_robots_command_lists_every_chain(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    for entry in BUNDLED_ROBOTS:
        line = next(line for line in out.splitlines() if line.startswith(f"{entry.name} "))
        assert f"{entry.base_frame} -> {entry.tip_frame}" in line
        assert line.split()[1] == str(len(entry.seed))
    assert "talos_left_arm" in out and "example-robot-data:<name>" in out


def test_every_urdf_of_the_data_is_nameable_or_refused_with_its_path_forms() -> None:
    folder = example_robot_data_dirs()[0]
    names = example_robot_data_names()
    files = sorted(folder.rglob("*.urdf"))
    assert len(files) > 20
    for path in files:
        relative = str(path.relative_to(folder))
        assert resolve_urdf(f"example-robot-data:{relative}")[0] == str(path)  # the path form
        if path.stem in names:
            assert resolve_urdf(f"example-robot-data:{path.stem}")[0] == str(
                folder / names[path.stem]
            )
        else:  # a file name shared by several URDFs: the refusal gives each path form
            with pytest.raises(InvalidInputError) as info:
                resolve_urdf(f"example-robot-data:{path.stem}")
            assert f"'example-robot-data:{relative}'" in str(info.value)
    robot = RobotModel.from_urdf(
        "example-robot-data:talos_left_arm", "arm_left_1_link", "gripper_left_base_link"
    )
    assert robot.num_joints == 6


def test_unknown_robot_name_suggests_close_names_and_the_path_form() -> None:
    with pytest.raises(InvalidInputError) as info:
        resolve_urdf("example-robot-data:talos_left_amr")
    message = str(info.value)
    assert "did you mean 'talos_left_arm'" in message
    assert "example-robot-data:<path>" in message and str(example_robot_data_dirs()[0]) in message


@pytest.mark.parametrize(
    ("robot", "base", "tip", "expected"),
    [
        ("ur10", "base_link", "tool", "tool0"),
        ("pr2", "torso_lift_link", "r_gripper_tool_fram", "r_gripper_tool_frame"),
        ("baxter", "base", "right_hand_gripper", "right_gripper"),
    ],
)
def test_unknown_frame_suggests_the_closest_first_links_and_joints_apart(
    robot: str, base: str, tip: str, expected: str
) -> None:
    with pytest.raises(FrameNotFoundError) as info:
        RobotModel.from_urdf(f"example-robot-data:{robot}", base, tip)
    reason = info.value.reason
    assert re.search(rf"not found; did you mean '{expected}'", reason), reason  # closest first
    links = reason.split("links: ")[1].split(";")[0]
    joints = reason.split("; joints: ")[1].split(";")[0]
    kinds = frames_by_kind(load_urdf_model(f"example-robot-data:{robot}"))
    for name in links.split(" (+")[0].split(", "):  # the kinds are not mixed
        assert name in kinds["links"]
    for name in joints.split(" (+")[0].split(", "):
        assert name in kinds["joints"] + kinds["fixed joints"]
    assert len(reason) < 400
    assert expected in info.value.available  # the full list stays on the error


def test_frames_command_lists_kinds_and_the_tree(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(serial_arm_urdf(("z", "y", "y", "x", "y", "z")))
    assert main(["frames", str(urdf)]) == 0
    out = capsys.readouterr().out
    assert "joints (6): j1 (revolute)" in out
    assert "fixed joints" in out and "tool_joint" in out
    tool = next(line for line in out.splitlines() if line.strip().startswith("tool "))
    assert "6 DOF" not in tool and "leaf" in tool  # attached by a fixed joint below link6
    link6 = next(line for line in out.splitlines() if line.strip().startswith("link6 "))
    assert "'j6', 6 DOF" in link6
    assert len(tool) - len(tool.lstrip()) == len(link6) - len(link6.lstrip()) + 2  # a child


def test_frames_command_reads_mjcf_and_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mjcf = tmp_path / "arm.xml"
    mjcf.write_text(
        """<mujoco model="two"><worldbody><body name="upper" pos="0 0 0.1">
        <joint name="shoulder" type="hinge" axis="0 0 1"/>
        <geom type="capsule" size="0.02 0.1" mass="1"/>
        <body name="lower" pos="0 0 0.2"><joint name="elbow" type="hinge" axis="0 1 0"/>
        <geom type="capsule" size="0.02 0.1" mass="1"/></body></body></worldbody></mujoco>"""
    )
    assert main(["frames", str(mjcf)]) == 0
    out = capsys.readouterr().out
    assert "(MJCF)" in out and "shoulder (revolute)" in out and "elbow (revolute)" in out
    assert "'elbow', 2 DOF" in out
    assert main(["frames", "talos_left_arm"]) == 0
    assert "gripper_left_base_link" in capsys.readouterr().out
    assert main(["frames", "talos_left_amr"]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'talos_left_arm'" in err and len(err.splitlines()) == 1


_MJCF_WITH_PROLOGUE = """<?xml version="1.0"?>
<!-- converted from <robot name="two"> -->
<mujoco model="two"><worldbody><body name="upper" pos="0 0 0.1">
<joint name="shoulder" type="hinge" axis="0 0 1"/>
<inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.001"/>
<body name="lower" pos="0 0 0.2"><joint name="elbow" type="hinge" axis="0 1 0"/>
<inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.001"/></body></body></worldbody>
</mujoco>"""


@pytest.mark.parametrize(
    ("text", "mjcf"),
    [(_MJCF_WITH_PROLOGUE, True), (serial_arm_urdf(("z", "y")), False)],
    ids=["mjcf", "urdf"],
)
def test_one_mjcf_detector_for_frames_and_loading(tmp_path: Path, text: str, mjcf: bool) -> None:
    """`grasp-safety frames` and the core loader tell MJCF from URDF with the one detector
    (a file and the same XML as text alike), and read the same joints from either form."""
    path = tmp_path / "robot.xml"
    path.write_text(text)
    assert is_mjcf(str(path), False) is mjcf
    assert is_mjcf(text, True) is mjcf
    model, where = load_any_model(str(path))
    assert where.endswith("(MJCF)") is mjcf
    assert list(model.names) == list(load_urdf_model(text).names)
    assert list(model.names) == list(load_urdf_model(str(path)).names)
