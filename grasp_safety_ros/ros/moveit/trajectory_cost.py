"""A cost term for MoveIt Task Constructor: the effective mass of a planned arm motion that
carries a known payload (docs/ros/moveit.md).

MTC's Python bindings take a cost term as a callable of a sub-solution, e.g.
``stage.setCostTerm(lambda solution: robot_trajectory_cost(evaluator, to_msg(solution),
payload))``; MTC then orders its solutions by it, lowest first. The score is the node's and the
CLI's for a grasp given a planned joint trajectory: the effective mass of robot + payload at
the tip along the tip's direction of motion, aggregated over the samples by ``metric``
(``mean`` [kg], ``max`` [kg] or ``integral`` [kg s]).
"""

from __future__ import annotations

import math

import pinocchio as pin
from moveit_msgs.msg import RobotTrajectory

from ...core.exceptions import InvalidInputError
from ...core.method.joint_trajectory import JointSpaceTrajectory
from ...core.method.ranking import Grasp, GraspSafetyEvaluator
from ...core.model.inertia import ObjectInertia
from ..conversions.requests import planned_from_joint_trajectory


def robot_trajectory_cost(
    evaluator: GraspSafetyEvaluator,
    trajectory: RobotTrajectory,
    payload: ObjectInertia,
    transform_tip_to_object: pin.SE3 | None = None,
    metric: str = "mean",
) -> float:
    """The effective-mass score of an arm motion carrying ``payload``; lower is safer.

    Args:
        evaluator: The robot's evaluator (``GraspSafetyEvaluator(RobotModel.from_urdf(...))``;
            the chain's joints must all be in the trajectory, others are ignored).
        trajectory: ``joint_trajectory``: joint names and at least two points with strictly
            increasing ``time_from_start`` (velocities used when every point has them);
            ``multi_dof_joint_trajectory`` must be empty.
        payload: The carried object's inertia, in the object frame.
        transform_tip_to_object: Pose of the tip frame in the object frame (the grasp);
            None: the object frame is the tip frame.
        metric: ``mean`` | ``max`` | ``integral`` of the per-sample effective mass.

    Returns:
        The score (kg, or kg s for ``integral``); ``math.inf`` when the model finds the motion
        infeasible (the evaluation's ``reason``), so MTC ranks it last.

    Raises:
        InvalidInputError: a malformed trajectory or a position outside the joint limits,
            naming the field (e.g. ``trajectory.joint_trajectory.points[2].positions``).
    """
    if trajectory.multi_dof_joint_trajectory.points:
        raise InvalidInputError(
            "trajectory.multi_dof_joint_trajectory",
            "must be empty: give the arm's motion as joint_trajectory",
        )
    field = "trajectory.joint_trajectory"
    planned = planned_from_joint_trajectory(trajectory.joint_trajectory, field)
    if planned is None:
        raise InvalidInputError(f"{field}.points", "is empty; give at least two points")
    grasp = Grasp(
        pin.SE3.Identity() if transform_tip_to_object is None else transform_tip_to_object,
        "trajectory",
        planned,
    )
    motion = JointSpaceTrajectory(evaluator.robot, planned, grasp.transform_tip_to_object)
    evaluation = evaluator.evaluate(grasp, payload, motion, metric=metric)
    return float(evaluation.score) if evaluation.feasible else math.inf
