"""The records of the validation: what an experiment is made of and what a run measured
(no simulation here; ``experiments`` runs them, ``figures`` and ``report`` read them)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..core.method.ranking import GraspEvaluation
from ..core.model.inertia import ObjectInertia
from ..core.model.trajectory import ObjectTrajectory
from ..core.model.waypoint_trajectory import WaypointTrajectory
from .scene import ContactConfig, ObjectShape, SensorConfig
from .simulation import (
    CollisionResult,
    CollisionSetup,
    ControllerGains,
    ImpulseCase,
    ImpulseSetup,
)


@dataclass(frozen=True)
class CandidateGrasp:
    """One grasp of one experiment: the object as held, and the grasp pose.

    Attributes:
        name: Label.
        object_inertia: Inertia of the object (object frame).
        transform_tip_to_object: Pose of the tip frame in the object frame.
        parameters: Values that define the grasp, written to results.json.
    """

    name: str
    object_inertia: ObjectInertia
    transform_tip_to_object: pin.SE3
    parameters: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Experiment:
    """Grasps that share an object trajectory and an object shape."""

    key: str
    title: str
    grasps: tuple[CandidateGrasp, ...]
    trajectory: ObjectTrajectory | WaypointTrajectory
    shape: ObjectShape
    description: str


@dataclass(frozen=True)
class Variant:
    """An ablation of the pillar experiment: other contact / sensor / controller settings."""

    key: str
    description: str
    contact: ContactConfig | None = None
    sensor: SensorConfig | None = None
    gains: ControllerGains | None = None
    end_time_s: float | None = None


@dataclass(frozen=True)
class RunConfig:
    """What ``reproduce`` runs.

    Attributes:
        tensor_indices: Tensor configurations (0-based), None for all 20.
        setup: The main pillar experiment.
        variant_setup: Start/end times of the ablations (they start on the reference).
        variants: Ablations to run.
        impulse_times_s: Trajectory times of the free-impact samples, per grasp.
        impulse: Settings of the free impacts.
    """

    tensor_indices: tuple[int, ...] | None
    setup: CollisionSetup
    variant_setup: CollisionSetup
    variants: tuple[Variant, ...]
    impulse_times_s: tuple[float, ...]
    impulse: ImpulseSetup = field(default_factory=ImpulseSetup)


@dataclass
class GraspRun:
    """Everything measured for one grasp (kept in memory for the figures)."""

    grasp: CandidateGrasp
    evaluation: GraspEvaluation
    collision: CollisionResult
    variants: dict[str, CollisionResult]
    impulse_cases: list[tuple[float, ImpulseCase]]
    robot_only_effective_mass_kg: np.ndarray
    """Effective mass of the arm alone (no object) at the same samples [kg]."""
