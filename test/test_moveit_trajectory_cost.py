"""robot_trajectory_cost (grasp_safety_ros.ros.moveit.trajectory_cost), the MoveIt Task
Constructor cost term, on moveit_msgs/RobotTrajectory messages.

Oracle: a one-joint arm turning about z. The tip, r from the axis, moves tangentially, so the
effective mass along its motion is the inertia about the axis over r squared,
I_total / r^2, at every sample (Steiner's theorem for the link and the payload).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectoryPoint, MultiDOFJointTrajectoryPoint

from grasp_safety_ros.core import RobotModel
from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.core.method.ranking import GraspSafetyEvaluator
from grasp_safety_ros.core.model.inertia import ObjectInertia

pytest.importorskip("moveit_msgs.msg", reason="moveit_msgs not built (make setup)")
from moveit_msgs.msg import RobotTrajectory

from grasp_safety_ros.ros.moveit.trajectory_cost import robot_trajectory_cost

LINK_MASS_KG, LINK_COM_M, LINK_IZZ_KGM2, TIP_M = 2.0, 0.2, 0.01, 0.5
URDF = f"""<robot name="one_joint"><link name="base"/>
<link name="arm"><inertial><origin xyz="{LINK_COM_M} 0 0"/><mass value="{LINK_MASS_KG}"/>
<inertia ixx="0.001" ixy="0" ixz="0" iyy="{LINK_IZZ_KGM2}" iyz="0" izz="{LINK_IZZ_KGM2}"/>
</inertial></link>
<joint name="j1" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
<limit lower="-3" upper="3" effort="10" velocity="5"/></joint>
<link name="tool"/><joint name="tool_joint" type="fixed"><parent link="arm"/>
<child link="tool"/><origin xyz="{TIP_M} 0 0"/></joint></robot>"""
# the same closed form computed in another order: a few ulps apart
RTOL = 1e-12


@pytest.fixture(scope="module")
def evaluator() -> GraspSafetyEvaluator:
    return GraspSafetyEvaluator(RobotModel.from_urdf(URDF, "base", "tool"))


def trajectory(points: list[tuple[float, float]], names: tuple[str, ...] = ("j1",)):
    """A RobotTrajectory of (time [s], position [rad]) points."""
    message = RobotTrajectory()
    message.joint_trajectory.joint_names = list(names)
    for t, q in points:
        sec = math.floor(t)
        message.joint_trajectory.points.append(
            JointTrajectoryPoint(
                positions=[q], time_from_start=Duration(sec=sec, nanosec=round((t - sec) * 1e9))
            )
        )
    return message


MOTION = [(0.0, 0.0), (0.5, 0.3), (1.0, 0.6)]


def expected_mass(payload: ObjectInertia, radius_m: float) -> float:
    """I_total / r^2 with the payload's CoM radius_m from the axis."""
    inertia = (
        LINK_IZZ_KGM2
        + LINK_MASS_KG * LINK_COM_M**2
        + payload.mass_kg * radius_m**2
        + payload.inertia_about_com_kgm2[2, 2]
    )
    return inertia / TIP_M**2


@pytest.mark.parametrize("mass_kg", [0.1, 1.0, 5.0])
def test_cost_is_the_closed_form_effective_mass(evaluator, mass_kg: float) -> None:
    payload = ObjectInertia(mass_kg, np.zeros(3), np.eye(3) * 1e-3 * mass_kg)
    cost = robot_trajectory_cost(evaluator, trajectory(MOTION), payload)
    assert cost == pytest.approx(expected_mass(payload, TIP_M), rel=RTOL)
    # constant effective mass: max = mean, integral = mean x duration (1 s)
    for metric in ("max", "integral"):
        assert robot_trajectory_cost(evaluator, trajectory(MOTION), payload, metric=metric) == (
            pytest.approx(cost, rel=RTOL)
        )


def test_grasp_offset_moves_the_payload(evaluator) -> None:
    """The tip 0.1 m behind the object's origin (T_object_tip translation -0.1 x): the
    payload's CoM is TIP_M + 0.1 from the axis."""
    payload = ObjectInertia(1.0, np.zeros(3), np.eye(3) * 1e-3)
    grasp = pin.SE3(np.eye(3), np.array([-0.1, 0.0, 0.0]))
    cost = robot_trajectory_cost(evaluator, trajectory(MOTION), payload, grasp)
    assert cost == pytest.approx(expected_mass(payload, TIP_M + 0.1), rel=RTOL)


def test_joints_off_the_chain_are_ignored_and_missing_ones_refused(evaluator) -> None:
    payload = ObjectInertia(1.0, np.zeros(3), np.eye(3) * 1e-3)
    with_gripper = trajectory(MOTION)
    for point in with_gripper.joint_trajectory.points:
        point.positions = [*point.positions, 0.02]
    with_gripper.joint_trajectory.joint_names = ["j1", "finger"]
    assert robot_trajectory_cost(evaluator, with_gripper, payload) == pytest.approx(
        expected_mass(payload, TIP_M), rel=RTOL
    )
    with pytest.raises(InvalidInputError, match="joint_names"):
        robot_trajectory_cost(evaluator, trajectory(MOTION, ("other",)), payload)


def test_bad_trajectories_are_refused_naming_the_field(evaluator) -> None:
    payload = ObjectInertia(1.0, np.zeros(3), np.eye(3) * 1e-3)
    with pytest.raises(InvalidInputError, match=r"joint_trajectory\.points: is empty"):
        robot_trajectory_cost(evaluator, trajectory([]), payload)
    with pytest.raises(InvalidInputError, match=r"points\[2\]\.positions"):
        robot_trajectory_cost(evaluator, trajectory([*MOTION[:2], (1.0, 3.5)]), payload)
    with pytest.raises(InvalidInputError, match=r"points\[1\]\.time_from_start"):
        robot_trajectory_cost(evaluator, trajectory([(0.0, 0.0), (0.0, 0.1)]), payload)
    multi = trajectory(MOTION)
    multi.multi_dof_joint_trajectory.points.append(MultiDOFJointTrajectoryPoint())
    with pytest.raises(InvalidInputError, match="multi_dof_joint_trajectory"):
        robot_trajectory_cost(evaluator, multi, payload)
