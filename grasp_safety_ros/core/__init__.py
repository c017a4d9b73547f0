"""ROS-free core of grasp_safety_ros (numpy + pinocchio only)."""

from .exceptions import FrameNotFoundError, GraspSafetyError, InvalidInputError, RobotModelError
from .method.ik import IKConfig, IKSolver
from .method.ranking import (
    METRICS,
    EvaluationConfig,
    Grasp,
    GraspEvaluation,
    GraspSafetyEvaluator,
    Ranking,
)
from .model.inertia import ObjectInertia, solid_box, solid_cylinder, solid_sphere
from .model.robot import RobotModel
from .model.trajectory import ObjectTrajectory

__all__ = [
    "METRICS",
    "EvaluationConfig",
    "FrameNotFoundError",
    "Grasp",
    "GraspEvaluation",
    "GraspSafetyError",
    "GraspSafetyEvaluator",
    "IKConfig",
    "IKSolver",
    "InvalidInputError",
    "ObjectInertia",
    "ObjectTrajectory",
    "Ranking",
    "RobotModel",
    "RobotModelError",
    "solid_box",
    "solid_cylinder",
    "solid_sphere",
]
