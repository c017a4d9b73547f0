"""What the analyses of one request compute once and share, instead of once per analysis.

Per request (``SampledTrajectory``): the path parameter s(t), ṡ, s̈ at the sample times and the
object poses T_base_object(s) (an exponential map per sample, the same for every grasp and
every point). Per grasp (``GraspShared``): the augmented model (object merged into the tip
body) and the tip path. Every value is computed exactly as the analyses compute it on their
own (same functions, same order), so sharing changes no result, only the cost.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import pinocchio as pin

from ..method.effective_mass import augmented_model
from ..method.ranking import Grasp
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from ..model.trajectory import ObjectTrajectory


class SampledTrajectory:
    """The object trajectory at the sample times of a ranking (shared by all its grasps).

    Attributes:
        trajectory: The object trajectory.
        times_s: Sample times [s].
        s_values, s_rate, s_accel: s(t), ds/dt [1/s], d²s/dt² [1/s²] at ``times_s``.
    """

    def __init__(self, trajectory: ObjectTrajectory, times_s: np.ndarray) -> None:
        self.trajectory = trajectory
        self.times_s = np.asarray(times_s, dtype=float)
        self.s_values, self.s_rate, self.s_accel = trajectory.path_parameter(self.times_s)

    @cached_property
    def object_poses(self) -> list[pin.SE3]:
        """T_base_object at each sample (ObjectTrajectory.object_poses)."""
        return self.trajectory.object_poses(self.s_values)

    def path(self, transform_frame_to_object: pin.SE3) -> tuple[list[pin.SE3], np.ndarray]:
        """ObjectTrajectory.tip_path of a frame fixed to the object, at the sample times."""
        return self.trajectory.tip_path(
            transform_frame_to_object, self.s_values, self.object_poses
        )

    def matches(self, times_s: np.ndarray) -> bool:
        """Whether ``times_s`` are this request's sample times."""
        return times_s is self.times_s or np.array_equal(times_s, self.times_s)


class GraspShared:
    """One grasp's augmented model and tip path, made on first use and kept for the others.

    Attributes:
        samples: The request's SampledTrajectory.
    """

    def __init__(
        self,
        robot: RobotModel,
        object_inertia: ObjectInertia,
        grasp: Grasp,
        samples: SampledTrajectory,
    ) -> None:
        self._robot, self._object_inertia, self._grasp = robot, object_inertia, grasp
        self.samples = samples

    @cached_property
    def augmented_model(self) -> pin.Model:
        """core.method.effective_mass.augmented_model of the grasp (do not modify it)."""
        return augmented_model(
            self._robot, self._object_inertia, self._grasp.transform_tip_to_object
        )

    @cached_property
    def tip_path(self) -> tuple[list[pin.SE3], np.ndarray]:
        """Tip poses in base and tangents d p_tip/ds at the samples (ObjectTrajectory.tip_path)."""
        return self.samples.path(self._grasp.transform_tip_to_object)
