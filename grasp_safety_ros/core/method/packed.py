"""The packed values the compiled kernels take and fill (named tuples of arrays, one value
each, shape and units per field); numpy only, so every module of the method can name them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class ChainArrays(NamedTuple):
    """A serial chain of one-degree-of-freedom joints as flat arrays, for the compiled kernels
    (one value, passed to them as a whole).

    Joint k (chain order) moves in the frame ``placement_k`` of joint k-1 (of the world for
    k = 0): rotation about, or translation along, the unit ``axis_k`` (joint frame). Its
    position is q[q_index[k]]; a continuous joint holds (cos, sin) of its angle in
    q[q_index[k]], q[q_index[k] + 1] (Pinocchio's representation, nq = 2, nv = 1).
    """

    placement_rotations: np.ndarray  # (n, 3, 3)
    placement_translations: np.ndarray  # (n, 3) [m]
    axes: np.ndarray  # (n, 3), unit
    prismatic: np.ndarray  # (n,) 1.0 for prismatic joints, 0.0 for revolute ones
    continuous: np.ndarray  # (n,) bool: revolute without limits, (cos, sin) in q
    q_index: np.ndarray  # (n,) int64: first entry of joint k in q
    tip_rotation: np.ndarray  # (3, 3): tip frame in the last joint's frame
    tip_translation: np.ndarray  # (3,) [m]
    base_rotation: np.ndarray  # (3, 3): base frame in the world frame
    base_translation: np.ndarray  # (3,) [m]
    lower_q: np.ndarray  # (nq,) -inf for continuous joints
    upper_q: np.ndarray  # (nq,) +inf for continuous joints
    armature: np.ndarray  # (n,) reflected rotor inertia [kg m^2, kg if prismatic]


STALL_RATIO = 0.9
"""IKSettings.stall_iterations = k > 0: a solve gives up at iteration 2k, 3k, ... when its
error's norm (the tip pose error's 6-vector log) is above STALL_RATIO times its norm k
iterations before (posture selection's restarts: PostureConfig.restart_stall_iterations)."""


class IKSettings(NamedTuple):
    """IKConfig and the velocity limits as the compiled IK reads them (one value)."""

    position_tolerance: float  # [m]
    orientation_tolerance: float  # [rad]
    max_iterations: int
    max_iteration_step: float
    max_joint_step: float
    predictor_max_ratio: float  # ik.PREDICTOR_MAX_RATIO
    any_velocity_check: bool
    check_velocity: np.ndarray  # (n,) bool: joint speed checked against velocity_limits
    velocity_limits: np.ndarray  # (n,) [rad/s or m/s]
    stall_iterations: int = 0  # k > 0: give up when k iterations cut the error < stall_ratio
    stall_ratio: float = STALL_RATIO


class BodyInertias(NamedTuple):
    """The bodies of a chain as arrays (one value, as the compiled kernels take it)."""

    masses: np.ndarray  # (n,) [kg]
    levers: np.ndarray  # (n, 3) centre of mass in the joint frame [m]
    rotational_inertias: np.ndarray  # (n, 3, 3) about the centre of mass, joint axes [kg m^2]


class GraspBuffers(NamedTuple):
    """Outputs and scratch of the fused kernel for G grasps of N samples (one value; axis 0
    is the grasp)."""

    target_rotations: np.ndarray  # (G, N, 3, 3) tip targets, world frame
    target_translations: np.ndarray  # (G, N, 3) [m]
    tangents: np.ndarray  # (G, N, 3) [m] tip tangents, base axes (ObjectMotion's scale)
    tangent_norms: np.ndarray  # (G, N) their norms [m]
    q_all: np.ndarray  # (G, N, nq)
    iterations: np.ndarray  # (G, N) int64
    q_fail: np.ndarray  # (G, nq) last iterate of a failed sample
    guess: np.ndarray  # (G, nq) predictor scratch
    tip_twists: np.ndarray  # (G, N, 6) log6(T_{i-1}^-1 T_i) of the tip targets, tip frame
    mobilities: np.ndarray  # (G, N, 3, 3) [1/kg], base axes
    effective_masses: np.ndarray  # (G, N) [kg]
    directions: np.ndarray  # (G, N, 3) unit, base axes
    worst: np.ndarray  # (G, N) bool: tip not translating
    outcomes: np.ndarray  # (G, 3) int64: status, sample, joint (kernels.grasp)
    outcome_values: np.ndarray  # (G,) the value of a failed check (jump [rad], speed [rad/s])


def grasp_buffers(grasps: int, count: int, nq: int) -> GraspBuffers:
    """Fresh GraspBuffers for ``grasps`` grasps of count samples of a chain with nq
    configuration entries."""
    return GraspBuffers(
        np.empty((grasps, count, 3, 3)),
        np.empty((grasps, count, 3)),
        np.empty((grasps, count, 3)),
        np.empty((grasps, count)),
        np.empty((grasps, count, nq)),
        np.zeros((grasps, count), dtype=np.int64),
        np.empty((grasps, nq)),
        np.empty((grasps, nq)),
        np.empty((grasps, count, 6)),
        np.empty((grasps, count, 3, 3)),
        np.empty((grasps, count)),
        np.empty((grasps, count, 3)),
        np.zeros((grasps, count), dtype=np.bool_),
        np.zeros((grasps, 3), dtype=np.int64),
        np.zeros(grasps),
    )


class CompiledGraspResult(NamedTuple):
    """One grasp's result of ``evaluate_grasps_compiled``: arrays have one row per sample if
    feasible (up to the failing sample otherwise)."""

    reason: str
    q: np.ndarray
    iterations: np.ndarray
    mobilities: np.ndarray
    effective_masses: np.ndarray
    directions: np.ndarray
    worst: np.ndarray
    tangent_norms: np.ndarray
