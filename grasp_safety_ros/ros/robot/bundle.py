"""The robot the node serves: its chain from the parameters or /robot_description, with the
armature parameters applied, its evaluator (kernels warmed up) and its validated IK seed."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ...core.exceptions import FrameNotFoundError, GraspSafetyError, InvalidInputError
from ...core.method.ranking import EvaluationConfig, GraspSafetyEvaluator
from ...core.method.warm_up import warm_up
from ...core.model.armature import (
    ArmatureRange,
    armature_range,
    published_for,
    published_values,
)
from ...core.model.robot import RobotModel
from ..parameters import PUBLISHED_PARAMETER, NodeSettings
from ..parameters.arm_points import check_arm_point_links

PARALLEL_MIN_SAMPLES = 1000
"""The node's evaluator ranks on its workers from this many grasps x samples (the core's
default is 4000): its pool is kept between requests, and 10 grasps x 101 samples on the two
workers take 0.84 ms against 1.09 serial (fastest of 57, docs/performance_pipeline.md). The
same threshold gates the evaluator's other pooled stages, not measured apart: posture
selection (from grasps x samples x (restarts + 1) = 1000: with 8 restarts, 112 grasp-samples
instead of 445), the inertia-uncertainty analysis's chunks and the kernel calls of the
analyses on the shared terms (from 1000 feasible grasps x samples: 10 x 101 included)."""


@dataclass(frozen=True)
class RobotBundle:
    """A loaded robot chain with its evaluator and the validated ``ik_seed`` (or None).

    Attributes:
        origin: Where the description came from: a parameter name or the topic.
        armature_range: The armature bounds when some joint has a range (the chain carries
            the upper ends); None otherwise.
    """

    robot: RobotModel
    evaluator: GraspSafetyEvaluator
    seed: tuple[float, ...] | None
    origin: str
    armature_range: ArmatureRange | None = None


_CORE_FIELDS = {
    "robot.urdf": None,  # replaced by the parameter (or topic) the description came from
    "robot.base_frame": "base_frame",
    "robot.tip_frame": "tip_frame",
    "robot.seed": "ik_seed",
}


def _renamed(error: GraspSafetyError, origin: str) -> GraspSafetyError:
    """The core's error with its field renamed to the node parameter to change."""
    field = getattr(error, "field", None)
    if field not in _CORE_FIELDS:
        return error
    new_field = _CORE_FIELDS[field] or origin
    if isinstance(error, FrameNotFoundError):
        return error.renamed(new_field)
    message = str(error)[len(field) + 2 :] if str(error).startswith(f"{field}: ") else str(error)
    return InvalidInputError(new_field, message)


def _with_armature_parameters(
    robot: RobotModel, settings: NodeSettings, source: str
) -> tuple[RobotModel, ArmatureRange | None]:
    """The chain with the armature of the ``robot.armature_*`` parameters (if any), and the
    armature range when ``robot.armature_lower_kgm2`` gives lower ends (the chain carries the
    upper ends, ``robot.armature_kgm2``)."""
    lower = settings.armature_lower_kgm2
    if settings.armature_published:
        if lower:
            raise InvalidInputError(
                "robot.armature_lower_kgm2",
                "must be empty with robot.armature_published (a published entry has values, "
                "not ranges)",
            )
        try:
            entry = published_for(settings.armature_published, source, robot.joint_names)
            published = published_values(entry, robot.joint_names)
        except InvalidInputError as error:  # the core names its scenario key
            raise InvalidInputError(PUBLISHED_PARAMETER, error.reason) from None
        return robot.with_armature(published), None
    values = settings.armature_kgm2
    names = settings.armature_joint_names
    if not values and not names and not lower:
        return robot, None
    if names and len(names) != len(values):
        raise InvalidInputError(
            "robot.armature_joint_names",
            f"has {len(names)} names for {len(values)} values of robot.armature_kgm2",
        )
    if not lower:
        given: Any = dict(zip(names, values, strict=True)) if names else values
        return robot.with_armature(given), None
    if len(lower) != len(values):
        raise InvalidInputError(
            "robot.armature_lower_kgm2",
            f"has {len(lower)} values for the {len(values)} of robot.armature_kgm2",
        )
    for k, (lo, hi) in enumerate(zip(lower, values, strict=True)):
        if lo > hi:
            raise InvalidInputError(
                f"robot.armature_lower_kgm2[{k}]",
                f"must be at most robot.armature_kgm2[{k}] = {hi:g}, got {lo:g}",
            )
    pairs = [[lo, hi] for lo, hi in zip(lower, values, strict=True)]
    given = dict(zip(names, pairs, strict=True)) if names else pairs
    bounds = armature_range(given, robot.joint_names, robot.armature_kgm2)
    return robot.with_armature(bounds.upper_kgm2), bounds if bounds.is_range else None


def build_robot(settings: NodeSettings, topic_description: str | None) -> RobotBundle | None:
    """Load the robot chain of ``settings`` (parameters first, then the topic's description).

    Returns:
        None when neither the parameters nor the topic gave a description yet.

    Raises:
        GraspSafetyError: the description, a frame or the seed is wrong (field renamed to the
            node parameter, or ``/robot_description`` for the topic).
    """
    if settings.robot_description:
        source, origin = settings.robot_description, "robot_description"
    elif settings.urdf:
        source, origin = settings.urdf, "urdf"
    elif topic_description:
        source, origin = topic_description, "/robot_description"
    else:
        return None
    try:
        robot = RobotModel.from_urdf(source, settings.base_frame, settings.tip_frame)
        robot, armature_bounds = _with_armature_parameters(robot, settings, source)
        check_arm_point_links(settings.analysis.arm_points_m, robot)
        seed = None
        if settings.ik_seed is not None:
            seed = tuple(float(x) for x in robot.check_positions(settings.ik_seed, "robot.seed"))
    except GraspSafetyError as error:
        raise _renamed(error, origin) from None
    config = EvaluationConfig(
        metric=settings.metric, ik=settings.ik, parallel_min_samples=PARALLEL_MIN_SAMPLES
    )
    evaluator = GraspSafetyEvaluator(robot, config)
    warm_up(evaluator)  # compile or load the kernels now, not on the first request
    return RobotBundle(robot, evaluator, seed, origin, armature_bounds)
