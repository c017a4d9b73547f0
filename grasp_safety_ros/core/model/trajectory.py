"""Quintic object trajectories and the tip trajectories that grasps induce."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import finite_float

MAX_SAMPLES = 1_000_000
"""Upper bound on the number of samples of one trajectory."""


def quintic_time_scaling(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ and its derivatives ds/dτ, d²s/dτ² (τ in [0, 1])."""
    tau = np.asarray(tau, dtype=float)
    s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)
    ds = 30.0 * tau**2 * (1.0 - tau) ** 2
    dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau)
    return s, ds, dds


@dataclass(frozen=True)
class ObjectTrajectory:
    """Object-frame poses in the base frame, quintic in time from ``start`` to ``goal``.

    Position is linear in s, orientation geodesic: R(s) = R0 exp(s log(R0ᵀ Rf)).
    Samples are at t = i·dt, i = 0..N with N = ceil(T/dt) (= round(T/dt) when T/dt is an
    integer); the last sample is clipped to t = T, so the goal is always sampled.

    Attributes:
        transform_object_to_base_start: Object pose in the base frame at t = 0.
        transform_object_to_base_goal: Object pose in the base frame at t = T.
        duration_s: T [s], > 0.
        dt_s: Sampling period [s], in (0, T].
    """

    transform_object_to_base_start: pin.SE3
    transform_object_to_base_goal: pin.SE3
    duration_s: float
    dt_s: float
    rotation_log_in_object: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        duration = finite_float(
            self.duration_s, "trajectory.duration_s", minimum=0.0, strict_minimum=True
        )
        dt = finite_float(self.dt_s, "trajectory.dt_s", minimum=0.0, strict_minimum=True)
        if dt > duration:
            raise InvalidInputError(
                "trajectory.dt_s", f"must be in (0, duration_s={duration:g}], got {dt:g}"
            )
        if duration / dt > MAX_SAMPLES:
            raise InvalidInputError(
                "trajectory.dt_s",
                f"gives {duration / dt:.0f} samples; at most {MAX_SAMPLES} are allowed",
            )
        start = pin.SE3(self.transform_object_to_base_start)
        goal = pin.SE3(self.transform_object_to_base_goal)
        log = pin.log3(start.rotation.T @ goal.rotation)
        log.setflags(write=False)
        object.__setattr__(self, "duration_s", duration)
        object.__setattr__(self, "dt_s", dt)
        object.__setattr__(self, "transform_object_to_base_start", start)
        object.__setattr__(self, "transform_object_to_base_goal", goal)
        object.__setattr__(self, "rotation_log_in_object", log)

    @property
    def num_samples(self) -> int:
        """N + 1 samples, N = ceil(T/dt) up to a 1e-9 rounding tolerance."""
        return math.ceil(self.duration_s / self.dt_s - 1e-9) + 1

    def times_s(self) -> np.ndarray:
        """Sample times t_i = min(i·dt, T) [s]."""
        return np.minimum(np.arange(self.num_samples) * self.dt_s, self.duration_s)

    def path_parameter(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """s(t), ds/dt [1/s] and d²s/dt² [1/s²] at the given times."""
        tau = np.clip(np.asarray(times_s, dtype=float) / self.duration_s, 0.0, 1.0)
        s, ds, dds = quintic_time_scaling(tau)
        return s, ds / self.duration_s, dds / self.duration_s**2

    def transform_object_to_base(self, s: float) -> pin.SE3:
        """Object pose in the base frame at path parameter s in [0, 1]."""
        start = self.transform_object_to_base_start
        goal = self.transform_object_to_base_goal
        rotation = start.rotation @ pin.exp3(s * self.rotation_log_in_object)
        translation = (1.0 - s) * start.translation + s * goal.translation
        return pin.SE3(rotation, translation)

    def object_poses(self, s_values: np.ndarray) -> list[pin.SE3]:
        """Object poses in the base frame at each path parameter (``transform_object_to_base``)."""
        return [self.transform_object_to_base(float(s)) for s in s_values]

    def tip_path(
        self,
        transform_tip_to_object: pin.SE3,
        s_values: np.ndarray,
        object_poses: Sequence[pin.SE3] | None = None,
    ) -> tuple[list[pin.SE3], np.ndarray]:
        """Tip poses in base and path tangents d p_tip/ds [m] (base axes) for a grasp.

        Args:
            transform_tip_to_object: The grasp: pose of the tip frame in the object frame.
            s_values: Path parameters in [0, 1].
            object_poses: ``object_poses(s_values)`` when already computed (they are the same
                for every grasp).

        Returns:
            The tip poses T_base_tip(s) = T_base_object(s)·T_object_tip and, per sample, the
            derivative of the tip position with respect to s, in base axes.
        """
        grasp = pin.SE3(transform_tip_to_object)
        poses: list[pin.SE3] = []
        tangents = np.empty((len(s_values), 3))
        linear = self.transform_object_to_base_goal.translation - (
            self.transform_object_to_base_start.translation
        )
        angular_in_object = self.rotation_log_in_object
        lever_in_object = np.cross(angular_in_object, grasp.translation)
        if object_poses is None:
            object_poses = self.object_poses(s_values)
        for i, object_pose in enumerate(object_poses):
            poses.append(object_pose * grasp)
            tangents[i] = linear + object_pose.rotation @ lever_in_object
        return poses, tangents
