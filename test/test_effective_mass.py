"""Effective mass: analytic oracles (free body, prismatic joint), Woodbury, properties."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import ARM6_AXES, random_positions, random_rotation, serial_arm_urdf
from hypothesis import given, settings
from hypothesis import strategies as st

from grasp_safety_ros.core import ObjectInertia, RobotModel, solid_box
from grasp_safety_ros.core.method.compiled import augmented_bodies
from grasp_safety_ros.core.method.effective_mass import (
    augmented_inertia_arrays,
    augmented_model,
    effective_mass_along,
    translational_mobility_in_base,
    worst_direction,
)
from grasp_safety_ros.core.method.ik import compiled_available


def random_object(rng: np.random.Generator) -> ObjectInertia:
    """A box of random size and mass, with a random CoM and rotated principal axes."""
    box = solid_box(rng.uniform(0.1, 3.0), rng.uniform(0.02, 0.4, 3))
    rotation = random_rotation(rng)
    tensor = rotation @ box.inertia_about_com_kgm2 @ rotation.T
    return ObjectInertia(box.mass_kg, rng.uniform(-0.1, 0.1, 3), tensor)


def random_grasp(rng: np.random.Generator) -> pin.SE3:
    return pin.SE3(random_rotation(rng), rng.uniform(-0.15, 0.15, 3))


def mobility(robot: RobotModel, model: pin.Model, positions: np.ndarray) -> np.ndarray:
    return translational_mobility_in_base(
        robot, model, model.createData(), robot.q_from_positions(positions)
    )


def sum_form_mobility(
    robot: RobotModel, obj: ObjectInertia, grasp: pin.SE3, positions: np.ndarray
) -> np.ndarray:
    """The paper's form: [(Λ_robot + Λ_obj)⁻¹]₃ₓ₃ with Λ_obj = Tᵀ Λ_com T (world axes)."""
    model = robot.model
    data = model.createData()
    q = robot.q_from_positions(positions)
    jacobian = pin.computeFrameJacobian(
        model, data, q, robot.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    )
    mass_matrix = np.triu(pin.crba(model, data, q))
    mass_matrix = mass_matrix + np.triu(mass_matrix, 1).T  # crba fills the upper triangle
    pin.framesForwardKinematics(model, data, q)
    lambda_robot = np.linalg.inv(jacobian @ np.linalg.solve(mass_matrix, jacobian.T))
    rotation_tip = data.oMf[robot.tip_frame_id].rotation
    transform_object_to_tip = grasp.inverse()
    rotation_object = rotation_tip @ transform_object_to_tip.rotation
    lever = rotation_tip @ transform_object_to_tip.act(obj.com_in_object_m)  # tip -> CoM, world
    lambda_com = np.zeros((6, 6))
    lambda_com[:3, :3] = obj.mass_kg * np.eye(3)
    lambda_com[3:, 3:] = rotation_object @ obj.inertia_about_com_kgm2 @ rotation_object.T
    transform = np.eye(6)
    transform[:3, 3:] = -pin.skew(lever)  # v_com = v_tip + ω × r = v_tip - r̂ ω
    lambda_object = transform.T @ lambda_com @ transform
    rotation_base = robot.transform_base_to_world.rotation
    block = np.linalg.inv(lambda_robot + lambda_object)[:3, :3]
    return rotation_base.T @ block @ rotation_base


@pytest.mark.parametrize("arm", ["arm6", "arm7"])
def test_augmented_model_equals_sum_form(arm: str, request: pytest.FixtureRequest) -> None:
    robot: RobotModel = request.getfixturevalue(arm)
    rng = np.random.default_rng(7)
    for _ in range(20):
        obj = random_object(rng)
        grasp = random_grasp(rng)
        positions = random_positions(robot, rng)
        augmented = mobility(robot, augmented_model(robot, obj, grasp), positions)
        expected = sum_form_mobility(robot, obj, grasp, positions)
        np.testing.assert_allclose(augmented, expected, rtol=1e-7, atol=1e-10)


def test_tiny_object_gives_robot_only_value(arm7: RobotModel) -> None:
    rng = np.random.default_rng(3)
    obj = ObjectInertia(1e-12, [0.05, 0.0, 0.1], np.eye(3) * 1e-14)
    for _ in range(10):
        positions = random_positions(arm7, rng)
        robot_only = mobility(arm7, arm7.model, positions)
        augmented = mobility(arm7, augmented_model(arm7, obj, random_grasp(rng)), positions)
        np.testing.assert_allclose(augmented, robot_only, rtol=1e-9)


def test_free_rigid_body_closed_form() -> None:
    """Robot inertia negligible: M_eff = 1 / (1/m + (r×u)ᵀ I_c⁻¹ (r×u)) in world axes."""
    urdf = serial_arm_urdf(ARM6_AXES, mass_scale=1e-12, seed=4)
    robot = RobotModel.from_urdf(urdf, "base_link", "tool")
    rng = np.random.default_rng(11)
    for _ in range(20):
        obj = random_object(rng)
        grasp = random_grasp(rng)
        positions = random_positions(robot, rng)
        if (
            np.linalg.svd(
                pin.computeFrameJacobian(
                    robot.model,
                    robot.model.createData(),
                    robot.q_from_positions(positions),
                    robot.tip_frame_id,
                ),
                compute_uv=False,
            )[-1]
            < 1e-2
        ):
            continue  # near a singularity the negligible robot inertia is not negligible
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        measured = effective_mass_along(
            mobility(robot, augmented_model(robot, obj, grasp), positions), direction
        )
        tip = robot.transform_tip_to_base(positions)
        lever = tip.rotation @ grasp.inverse().act(obj.com_in_object_m)
        rotation_object = tip.rotation @ grasp.inverse().rotation
        inertia_world = rotation_object @ obj.inertia_about_com_kgm2 @ rotation_object.T
        arm = np.cross(lever, direction)
        expected = 1.0 / (1.0 / obj.mass_kg + arm @ np.linalg.solve(inertia_world, arm))
        assert measured == pytest.approx(expected, rel=1e-6)


PRISMATIC_URDF = """
<robot name="slider">
  <link name="base"/>
  <link name="carriage">
    <inertial><origin xyz="0.1 0.2 0"/><mass value="2.5"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <joint name="slide" type="prismatic">
    <parent link="base"/><child link="carriage"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="100" velocity="1"/>
  </joint>
  <link name="tip"/>
  <joint name="tip_joint" type="fixed"><parent link="carriage"/><child link="tip"/>
    <origin xyz="0 0 0.2" rpy="0.5 0.1 -0.3"/></joint>
</robot>
"""


def test_prismatic_joint_moving_mass() -> None:
    robot = RobotModel.from_urdf(PRISMATIC_URDF, "base", "tip")
    axis = np.array([1.0, 0.0, 0.0])
    for position in (-0.5, 0.0, 0.7):
        alone = effective_mass_along(mobility(robot, robot.model, [position]), axis)
        assert alone == pytest.approx(2.5, rel=1e-12)
        obj = solid_box(0.8, [0.1, 0.2, 0.3], [0.3, -0.1, 0.2])
        grasp = pin.SE3(random_rotation(np.random.default_rng(0)), np.array([0.1, 0.0, 0.0]))
        carried = effective_mass_along(
            mobility(robot, augmented_model(robot, obj, grasp), [position]), axis
        )
        assert carried == pytest.approx(3.3, rel=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    mass_factor=st.floats(1.01, 20.0),
)
def test_properties(arm7: RobotModel, seed: int, mass_factor: float) -> None:
    """M_eff > 0, even in u, and non-decreasing when the object's mass grows."""
    rng = np.random.default_rng(seed)
    obj = random_object(rng)
    grasp = random_grasp(rng)
    positions = random_positions(arm7, rng)
    direction = rng.normal(size=3)
    light = mobility(arm7, augmented_model(arm7, obj, grasp), positions)
    heavy = mobility(arm7, augmented_model(arm7, obj.scaled(mass_factor), grasp), positions)
    mass = effective_mass_along(light, direction)
    assert mass > 0
    assert effective_mass_along(light, -direction) == pytest.approx(mass, rel=1e-12)
    assert effective_mass_along(heavy, direction) >= mass * (1 - 1e-9)


def test_worst_direction_maximises_effective_mass(arm7: RobotModel) -> None:
    rng = np.random.default_rng(5)
    matrix = mobility(arm7, arm7.model, random_positions(arm7, rng))
    direction, worst = worst_direction(matrix)
    assert effective_mass_along(matrix, direction) == pytest.approx(worst, rel=1e-12)
    for _ in range(200):
        assert effective_mass_along(matrix, rng.normal(size=3)) <= worst * (1 + 1e-12)


@pytest.mark.parametrize("implementation", ["numpy", "kernel"])
def test_augmented_inertia_arrays_equal_the_augmented_model(
    baxter: RobotModel, implementation: str
) -> None:
    """The batched body inertias the kernels take (numpy, or the kernel ``augment_bodies``;
    one row per grasp) equal the bodies of Pinocchio's augmented model, grasp by grasp; other
    bodies are the robot's own."""
    if implementation == "kernel" and not compiled_available():
        pytest.skip("numba is not installed")
    rng = np.random.default_rng(21)
    obj = random_object(rng)
    grasps = [random_grasp(rng) for _ in range(5)]
    augment = augmented_inertia_arrays if implementation == "numpy" else augmented_bodies
    batch = augment(
        baxter,
        obj,
        np.array([g.rotation for g in grasps]),
        np.array([g.translation for g in grasps]),
    )
    for g, grasp in enumerate(grasps):
        model = augmented_model(baxter, obj, grasp)
        for k in range(baxter.model.nv):
            body = model.inertias[k + 1]
            assert batch.masses[g, k] == pytest.approx(body.mass, rel=1e-14)
            np.testing.assert_allclose(batch.levers[g, k], body.lever, rtol=0, atol=1e-14)
            np.testing.assert_allclose(
                batch.rotational_inertias[g, k], body.inertia, rtol=0, atol=1e-14
            )
