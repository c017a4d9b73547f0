"""ROS-free core of grasp_safety_ros (numpy + pinocchio; numba optional).

Rooms, imported one way: ``exceptions`` and ``input_checks`` <- ``model`` (robot, object
inertia, trajectory) <- ``method`` (the paper: IK, effective mass, ranking; the bridge to the
compiled ``kernels`` and the worker pool) <- ``analyses`` (beyond the paper). The public names
of the paper's method are re-exported here, each loaded on first use (PEP 562), so importing
a light submodule (``core.exceptions``) does not load Pinocchio.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .exceptions import (
        FrameNotFoundError,
        GraspSafetyError,
        InvalidInputError,
        RobotModelError,
    )
    from .method.ik import IKConfig, IKSolver
    from .method.metrics import METRICS
    from .method.ranking import EvaluationConfig, GraspSafetyEvaluator
    from .method.results import Grasp, GraspEvaluation, Ranking
    from .model.inertia import ObjectInertia, solid_box, solid_cylinder, solid_sphere
    from .model.robot import RobotModel
    from .model.trajectory import ObjectTrajectory

_HOMES = {
    "METRICS": ".method.metrics",
    "EvaluationConfig": ".method.ranking",
    "FrameNotFoundError": ".exceptions",
    "Grasp": ".method.ranking",
    "GraspEvaluation": ".method.ranking",
    "GraspSafetyError": ".exceptions",
    "GraspSafetyEvaluator": ".method.ranking",
    "IKConfig": ".method.ik",
    "IKSolver": ".method.ik",
    "InvalidInputError": ".exceptions",
    "ObjectInertia": ".model.inertia",
    "ObjectTrajectory": ".model.trajectory",
    "Ranking": ".method.ranking",
    "RobotModel": ".model.robot",
    "RobotModelError": ".exceptions",
    "solid_box": ".model.inertia",
    "solid_cylinder": ".model.inertia",
    "solid_sphere": ".model.inertia",
}
"""Module (relative to this package) of each public name."""

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


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(home, __name__), name)
    globals()[name] = value
    return value
