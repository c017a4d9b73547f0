"""MJCF (MuJoCo XML) robot descriptions: read with Pinocchio's MJCF reader, armature included;
the same arm as URDF + robot.armature_kgm2 gives the same numbers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_positions

from grasp_safety_ros.core import (
    EvaluationConfig,
    Grasp,
    GraspSafetyEvaluator,
    InvalidInputError,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.method.joint_trajectory import PlannedJointTrajectory

LINKS = (  # (body position in parent [m], joint axis, mass [kg], CoM [m], diagonal inertia)
    ((0.0, 0.0, 0.1), (0, 0, 1), 3.0, (0.0, 0.01, 0.12), (0.03, 0.03, 0.01)),
    ((0.0, 0.05, 0.25), (0, 1, 0), 2.5, (0.1, 0.0, 0.02), (0.01, 0.04, 0.04)),
    ((0.3, 0.0, 0.0), (0, 1, 0), 1.5, (0.12, 0.0, 0.0), (0.005, 0.02, 0.02)),
    ((0.25, 0.0, 0.02), (1, 0, 0), 0.8, (0.03, 0.0, 0.01), (0.002, 0.003, 0.003)),
)
ARMATURE = (0.4, 0.35, 0.2, 0.05)
TOOL = (0.1, 0.0, 0.0)


def vector(values) -> str:
    return " ".join(f"{v:g}" for v in values)


def arm_mjcf(armature: tuple[float, ...] = ARMATURE, mesh: bool = True) -> str:
    """The arm in MJCF: radians, armature per joint, a mesh geom whose file does not exist."""
    parts = [
        '<mujoco model="arm"><compiler angle="radian"/>',
        '<asset><mesh name="shell" file="no/such/shell.stl"/></asset>' if mesh else "",
        '<worldbody><body name="base_link">',
    ]
    for k, (position, axis, mass, com, inertia) in enumerate(LINKS):
        parts.append(
            f'<body name="link{k + 1}" pos="{vector(position)}">'
            f'<joint name="j{k + 1}" type="hinge" axis="{vector(axis)}" range="-2.5 2.5" '
            f'armature="{armature[k]:g}"/>'
            f'<inertial pos="{vector(com)}" mass="{mass:g}" diaginertia="{vector(inertia)}"/>'
            + ('<geom type="mesh" mesh="shell"/>' if mesh else "")
        )
    parts.append(f'<site name="tool" pos="{vector(TOOL)}"/>')
    parts.append("</body>" * len(LINKS) + "</body></worldbody></mujoco>")
    return "".join(parts)


def arm_urdf() -> str:
    parts = ['<robot name="arm"><link name="base_link"/>']
    parent = "base_link"
    for k, (position, axis, mass, com, inertia) in enumerate(LINKS):
        ixx, iyy, izz = inertia
        parts.append(
            f'<link name="link{k + 1}"><inertial><origin xyz="{vector(com)}"/>'
            f'<mass value="{mass:g}"/><inertia ixx="{ixx:g}" ixy="0" ixz="0" iyy="{iyy:g}" '
            f'iyz="0" izz="{izz:g}"/></inertial></link>'
            f'<joint name="j{k + 1}" type="revolute"><parent link="{parent}"/>'
            f'<child link="link{k + 1}"/><origin xyz="{vector(position)}"/>'
            f'<axis xyz="{vector(axis)}"/>'
            '<limit lower="-2.5" upper="2.5" effort="50" velocity="2"/></joint>'
        )
        parent = f"link{k + 1}"
    parts.append(
        f'<link name="tool"/><joint name="tool_joint" type="fixed"><parent link="{parent}"/>'
        f'<child link="tool"/><origin xyz="{vector(TOOL)}"/></joint></robot>'
    )
    return "".join(parts)


def symmetric(upper: np.ndarray) -> np.ndarray:
    upper = np.triu(upper)
    return upper + np.triu(upper, 1).T


def test_mjcf_text_and_file_load_with_their_armature_and_missing_meshes(tmp_path: Path) -> None:
    from_text = RobotModel.from_urdf(arm_mjcf(), "base_link", "tool")
    (tmp_path / "arm.xml").write_text(arm_mjcf())
    from_file = RobotModel.from_urdf("arm.xml", "base_link", "tool", relative_to=tmp_path)
    for robot in (from_text, from_file):
        assert robot.joint_names == ("j1", "j2", "j3", "j4")
        np.testing.assert_array_equal(robot.armature_kgm2, ARMATURE)
        assert robot.armature_given
    override = RobotModel.from_urdf(arm_mjcf(), "base_link", "tool", armature_kgm2={"j1": 1.0})
    np.testing.assert_array_equal(override.armature_kgm2, [1.0, *ARMATURE[1:]])


def test_a_partial_armature_mapping_keeps_the_mjcf_armature_of_the_other_joints(
    tmp_path: Path,
) -> None:
    """Naming one joint must not zero the others' rotor inertia (that would lower every
    effective mass): in the model, a scenario (value and range) and the node parameters."""
    from grasp_safety_ros.ros.parameters import settings_from_parameters
    from grasp_safety_ros.ros.robot_bundle import build_robot
    from grasp_safety_ros.scenario.schema import parse_robot

    kept = [*ARMATURE[:3], 0.1]
    robot = RobotModel.from_urdf(arm_mjcf(), "base_link", "tool")
    np.testing.assert_array_equal(robot.with_armature({"j4": 0.1}).armature_kgm2, kept)
    (tmp_path / "arm.xml").write_text(arm_mjcf())
    for armature, lower in (({"j4": 0.1}, kept), ({"j4": [0.0, 0.1]}, [*ARMATURE[:3], 0.0])):
        spec = parse_robot(
            {
                "urdf": "arm.xml",
                "base_frame": "base_link",
                "tip_frame": "tool",
                "armature_kgm2": armature,
            }
        )
        loaded = spec.load(tmp_path)
        np.testing.assert_array_equal(loaded.armature_kgm2, kept)
        bounds = spec.armature_range(loaded)
        np.testing.assert_array_equal(bounds.lower_kgm2, lower)
        np.testing.assert_array_equal(bounds.upper_kgm2, kept)
    settings = settings_from_parameters(
        {
            "robot_description": arm_mjcf(),
            "base_frame": "base_link",
            "tip_frame": "tool",
            "robot.armature_kgm2": [0.1],
            "robot.armature_joint_names": ["j4"],
        }
    )
    bundle = build_robot(settings, None)
    assert bundle is not None
    np.testing.assert_array_equal(bundle.robot.armature_kgm2, kept)


def test_mjcf_equals_urdf_with_armature_to_1e_12() -> None:
    mjcf = RobotModel.from_urdf(arm_mjcf(), "base_link", "tool")
    urdf = RobotModel.from_urdf(arm_urdf(), "base_link", "tool", armature_kgm2=list(ARMATURE))
    np.testing.assert_array_equal(mjcf.lower_limits, urdf.lower_limits)
    rng = np.random.default_rng(2)
    mjcf_data, urdf_data = mjcf.model.createData(), urdf.model.createData()
    for _ in range(5):
        positions = random_positions(urdf, rng)
        q = urdf.q_from_positions(positions)
        np.testing.assert_allclose(
            symmetric(pin.crba(mjcf.model, mjcf_data, q)),
            symmetric(pin.crba(urdf.model, urdf_data, q)),
            rtol=0,
            atol=1e-12,
        )
        pose_mjcf, pose_urdf = (
            mjcf.transform_tip_to_base(positions),
            urdf.transform_tip_to_base(positions),
        )
        np.testing.assert_allclose(pose_mjcf.homogeneous, pose_urdf.homogeneous, atol=1e-12)
    seed = np.array([0.3, -0.4, 0.9, 0.2])
    start = urdf.transform_tip_to_base(seed)
    trajectory = ObjectTrajectory(start, start, 1.0, 0.1)  # unused: the grasp has its plan
    times = np.linspace(0.0, 1.0, 6)
    positions = seed + np.outer(times, [0.3, -0.2, 0.4, 0.5])
    plan = PlannedJointTrajectory(urdf.joint_names, times, positions)
    box = solid_box(0.3, [0.05, 0.05, 0.08])
    grasps = [Grasp(pin.SE3.Identity(), "tip", plan)]
    config = EvaluationConfig(workers=1)
    a = GraspSafetyEvaluator(mjcf, config).rank(grasps, box, trajectory, seed).evaluations[0]
    b = GraspSafetyEvaluator(urdf, config).rank(grasps, box, trajectory, seed).evaluations[0]
    assert a.feasible and b.feasible
    np.testing.assert_allclose(a.effective_mass_kg, b.effective_mass_kg, rtol=1e-12)
    np.testing.assert_allclose(
        a.links_only_effective_mass_kg, b.links_only_effective_mass_kg, rtol=1e-12
    )


def test_mjcf_body_with_geoms_and_no_inertial_is_refused() -> None:
    text = arm_mjcf().replace(
        '<inertial pos="0.12 0 0" mass="1.5" diaginertia="0.005 0.02 0.02"/>', ""
    )
    with pytest.raises(InvalidInputError, match=r"robot.urdf: MJCF bodies link3 have geoms"):
        RobotModel.from_urdf(text, "base_link", "tool")
    with pytest.raises(InvalidInputError, match=r"robot.urdf: cannot read MJCF XML"):
        RobotModel.from_urdf("<mujoco><worldbody><body", "base_link", "tool")


def test_node_takes_an_mjcf_robot_description() -> None:
    from grasp_safety_ros.ros.parameters import settings_from_parameters
    from grasp_safety_ros.ros.robot_bundle import build_robot

    settings = settings_from_parameters(
        {"robot_description": arm_mjcf(), "base_frame": "base_link", "tip_frame": "tool"}
    )
    bundle = build_robot(settings, None)
    assert bundle is not None and bundle.origin == "robot_description"
    np.testing.assert_array_equal(bundle.robot.armature_kgm2, ARMATURE)
    from_topic = build_robot(
        settings_from_parameters({"base_frame": "base_link", "tip_frame": "tool"}), arm_mjcf()
    )
    assert from_topic is not None and from_topic.origin == "/robot_description"
    assert from_topic.robot.joint_names == ("j1", "j2", "j3", "j4")
