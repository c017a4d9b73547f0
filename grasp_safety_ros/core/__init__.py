"""ROS-free core of grasp_safety_ros (numpy + pinocchio; numba optional).

Rooms, imported one way: ``exceptions`` and ``input_checks`` <- ``model`` (robot, object
inertia, trajectory) <- ``method`` (the paper: IK, effective mass, ranking; the bridge to the
compiled ``kernels`` and the worker pool) <- ``analyses`` (beyond the paper). The public names
of the paper's method are re-exported here.
"""

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
