"""Effective mass at exposed points of the carried object (corners, rims), not at the wrist.

A point p of the object is rigidly attached to the tip, so its velocity is v_p = v_tip + ω × r
(r = tip -> p, world axes) and its Jacobian J_p = J_v − r̂ J_ω. With the object merged into the
tip body (the augmented joint-space inertia M_aug), the point's translational mobility is
A_p = J_p M_aug⁻¹ J_pᵀ [1/kg] and its effective mass along its own unit direction of motion u_p
is M_eff,p = 1 / (u_pᵀ A_p u_p). u_p is the tangent of the point's path (like the tip's, from
the trajectory's ``tip_motion``); where a point does not translate (|tangent| < 1e-9 m), its
direction of largest effective mass is used, as for the tip.

Per sample, the *leading point* is the one furthest ahead along its own direction of motion,
measured from the centroid p̄ of the points: argmax_k (p_k − p̄)·u_k over the points that
translate (for a pure translation: the point with the largest p·u). The *worst point* is the
one with the largest effective mass. Ties go to the lower point index.
"""

from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import finite_array, finite_float, read_only
from ..method.compiled import pose_arrays
from ..method.effective_mass import STATIONARY_TANGENT_M, augmented_model
from ..method.points import tip_point_masses
from ..method.ranking import Grasp, GraspEvaluation, aggregate, check_metric
from ..method.terms import SampleTerms
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from ..model.trajectory import ObjectPath, Trajectory

METRIC_POINTS = ("tip", "leading_point", "worst_point")
"""Which point's effective mass a score uses: the tip, the leading point, the worst point."""


def check_metric_point(metric_point: str, field: str = "metric_point") -> str:
    """Return ``metric_point`` if it is one of METRIC_POINTS, else raise InvalidInputError."""
    if metric_point not in METRIC_POINTS:
        raise InvalidInputError(
            field, f"must be one of {', '.join(METRIC_POINTS)}, got {metric_point!r}"
        )
    return metric_point


def check_metric_point_has_points(metric_point: str, points: object | None, how: str) -> None:
    """Raise InvalidInputError on ``metric_point`` when a point other than the tip is asked
    for with no object points (``points`` None); ``how``: how the caller's interface sets
    them (its own field names), the end of the message."""
    if metric_point != "tip" and points is None:
        raise InvalidInputError(
            "metric_point", f"{metric_point!r} needs the object's points: {how}"
        )


def box_corners_in_object(
    size_m: Sequence[float] | np.ndarray,
    center_in_object_m: Sequence[float] | np.ndarray = (0.0, 0.0, 0.0),
) -> np.ndarray:
    """The 8 corners (8, 3) [m] of a box with edges ``size_m`` along the object axes."""
    size = finite_array(size_m, "object.box_size_m", (3,))
    if np.any(size <= 0.0):
        raise InvalidInputError("object.box_size_m", f"edges must be > 0, got {size.tolist()}")
    center = finite_array(center_in_object_m, "object.box_center_in_object_m", (3,))
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return read_only(center + 0.5 * signs * size)


def cylinder_rim_points_in_object(
    radius_m: float,
    length_m: float,
    center_in_object_m: Sequence[float] | np.ndarray = (0.0, 0.0, 0.0),
    points_per_rim: int = 8,
) -> np.ndarray:
    """Points (2·points_per_rim, 3) [m] on both rims of a cylinder whose axis is object z.

    The first rim is at z = −length/2, the second at +length/2 (about the centre); points are
    at angles 2πj/points_per_rim from the object x axis.
    """
    radius = finite_float(radius_m, "object.cylinder.radius_m", 0.0, None, True)
    length = finite_float(length_m, "object.cylinder.length_m", 0.0, None, True)
    center = finite_array(center_in_object_m, "object.cylinder.center_in_object_m", (3,))
    if (
        not isinstance(points_per_rim, int)
        or isinstance(points_per_rim, bool)
        or (points_per_rim < 3)
    ):
        raise InvalidInputError(
            "object.cylinder.points_per_rim", f"must be an integer >= 3, got {points_per_rim!r}"
        )
    angles = 2.0 * np.pi * np.arange(points_per_rim) / points_per_rim
    ring = np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=1)
    rims = [np.column_stack([ring, np.full(points_per_rim, z)]) for z in (-length / 2, length / 2)]
    return read_only(center + np.vstack(rims))


def check_points_in_object(points_in_object_m: Any, field: str = "object.points_m") -> np.ndarray:
    """Validate a (K, 3) array of points [m] in the object frame, K >= 1."""
    points = finite_array(points_in_object_m, field)
    if points.ndim != 2 or points.shape[1] != 3 or points.shape[0] < 1:
        raise InvalidInputError(
            field, f"must be a list of [x, y, z] points (K x 3, K >= 1), got {list(points.shape)}"
        )
    return points


def point_jacobian_in_base(
    robot: RobotModel,
    model: pin.Model,
    data: pin.Data,
    q: np.ndarray,
    point_in_tip_m: np.ndarray,
) -> np.ndarray:
    """Jacobians (K, 3, nv) of points rigidly attached to the tip, base axes.

    ``point_in_tip_m`` (K, 3) [m] are points in the tip frame; ``model`` is the chain model
    or an augmented copy (same kinematics). J_p = J_v − r̂ J_ω with r = tip -> p (world axes).
    """
    pin.computeJointJacobians(model, data, q)
    rotation_tip_to_world = pin.updateFramePlacement(model, data, robot.tip_frame_id).rotation
    jacobian_tip_in_world = pin.getFrameJacobian(
        model, data, robot.tip_frame_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    ).reshape(6, model.nv)
    return _point_jacobians(
        robot, jacobian_tip_in_world, rotation_tip_to_world, np.atleast_2d(point_in_tip_m)
    )


def _point_jacobians(
    robot: RobotModel,
    jacobian_tip_in_world: np.ndarray,
    rotation_tip_to_world: np.ndarray,
    points: np.ndarray,
) -> np.ndarray:
    """(..., K, 3, nv) Jacobians of the K tip-fixed ``points`` (tip frame [m]) from tip
    Jacobians (..., 6, nv) and tip rotations (..., 3, 3), world; base axes."""
    # (..., K, 3): tip -> point, world axes
    levers = points @ np.swapaxes(rotation_tip_to_world, -1, -2)
    linear, angular = jacobian_tip_in_world[..., :3, :], jacobian_tip_in_world[..., 3:, :]
    # J_p = J_v − r̂ J_ω: row a of r̂ J_ω is r_b J_ω,c − r_c J_ω,b ((a, b, c) cyclic)
    r = levers[..., :, :, None]  # (..., K, 3, 1)
    w = angular[..., None, :, :]  # (..., 1, 3, nv)
    jacobians = np.empty((*np.broadcast_shapes(r.shape[:-2], w.shape[:-2]), 3, linear.shape[-1]))
    for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        jacobians[..., a, :] = linear[..., None, a, :] - (
            r[..., b, :] * w[..., c, :] - r[..., c, :] * w[..., b, :]
        )
    return robot.transform_base_to_world.rotation.T @ jacobians


def point_mobility_in_base(
    robot: RobotModel,
    model: pin.Model,
    data: pin.Data,
    q: np.ndarray,
    point_in_tip_m: np.ndarray,
) -> np.ndarray:
    """Translational mobilities A_p = J_p M⁻¹ J_pᵀ (K, 3, 3) [1/kg] of tip-fixed points.

    ``model`` is usually the augmented model (core.effective_mass.augmented_model).
    """
    pin.computeMinverse(model, data, q)
    minv_upper = np.triu(data.Minv)
    minv = minv_upper + np.triu(minv_upper, 1).T
    jacobians = point_jacobian_in_base(robot, model, data, q, point_in_tip_m)
    return np.einsum("kan,nm,kbm->kab", jacobians, minv, jacobians)


def _worst_directions(mobility: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (mobility + np.swapaxes(mobility, -1, -2)))
    return eigenvectors[..., :, 0], 1.0 / eigenvalues[..., 0]


@dataclass(frozen=True)
class ExposedPointsEvaluation:
    """Effective mass at K object points along one grasp's trajectory (N samples).

    Attributes:
        index, name: The grasp, as in its GraspEvaluation.
        feasible: False when the grasp's trajectory is infeasible (then arrays are empty).
        times_s: Sample times (N,) [s].
        points_in_object_m: The points (K, 3) [m], object frame.
        positions_in_base_m: Point positions (N, K, 3) [m], base frame.
        directions_in_base: Unit directions of motion (N, K, 3), base axes.
        direction_is_worst_case: (N, K) True where the point does not translate and its
            direction of largest effective mass was used.
        speed_m_s: Point speeds (N, K) [m/s].
        effective_mass_kg: Effective mass (N, K) [kg] at each point along its direction.
        leading_point_index: (N,) index of the leading point per sample.
        worst_point_index: (N,) index of the point of largest effective mass per sample.
    """

    index: int
    name: str
    feasible: bool
    times_s: np.ndarray
    points_in_object_m: np.ndarray
    positions_in_base_m: np.ndarray
    directions_in_base: np.ndarray
    direction_is_worst_case: np.ndarray
    speed_m_s: np.ndarray
    effective_mass_kg: np.ndarray
    leading_point_index: np.ndarray
    worst_point_index: np.ndarray

    def _pick(self, values: np.ndarray, which: np.ndarray) -> np.ndarray:
        return values[np.arange(len(which)), which]

    @property
    def leading_effective_mass_kg(self) -> np.ndarray:
        """(N,) effective mass at the leading point [kg]."""
        return self._pick(self.effective_mass_kg, self.leading_point_index)

    @property
    def leading_speed_m_s(self) -> np.ndarray:
        """(N,) speed of the leading point [m/s]."""
        return self._pick(self.speed_m_s, self.leading_point_index)

    @property
    def worst_effective_mass_kg(self) -> np.ndarray:
        """(N,) largest effective mass over the points [kg]."""
        return self._pick(self.effective_mass_kg, self.worst_point_index)

    @property
    def worst_speed_m_s(self) -> np.ndarray:
        """(N,) speed of the worst point [m/s]."""
        return self._pick(self.speed_m_s, self.worst_point_index)


def evaluate_exposed_points(
    robot: RobotModel,
    evaluation: GraspEvaluation,
    object_inertia: ObjectInertia,
    grasp: Grasp,
    trajectory: Trajectory,
    points_in_object_m: Any,
    model: pin.Model | None = None,
) -> ExposedPointsEvaluation:
    """Effective mass, speed and direction of motion at each object point, per sample.

    Reuses the evaluation's joint positions (no IK). ``grasp`` and ``trajectory`` must be the
    ones the evaluation was computed with; ``model``: their ``augmented_model``, when already
    built (shared across analyses). Pinocchio per sample: the reference of the compiled
    path, ``evaluate_exposed_points_on_terms`` (equal to rounding, test_terms).
    """
    points = check_points_in_object(points_in_object_m)
    count_points = len(points)
    if not evaluation.feasible:
        per_point = np.empty((0, count_points))
        return ExposedPointsEvaluation(
            index=evaluation.index,
            name=evaluation.name,
            feasible=False,
            times_s=np.empty(0),
            points_in_object_m=points,
            positions_in_base_m=np.empty((0, count_points, 3)),
            directions_in_base=np.empty((0, count_points, 3)),
            direction_is_worst_case=per_point.astype(bool),
            speed_m_s=per_point,
            effective_mass_kg=per_point,
            leading_point_index=np.empty(0, dtype=int),
            worst_point_index=np.empty(0, dtype=int),
        )
    times = np.asarray(evaluation.times_s, dtype=float)
    if len(times) != evaluation.joint_positions.shape[0]:
        raise InvalidInputError("evaluation.times_s", "must have one entry per joint sample")
    count = len(times)
    positions, tangents, speeds = _point_motion(trajectory, times, points)
    if model is None:
        model = augmented_model(robot, object_inertia, grasp.transform_tip_to_object)
    data = model.createData()
    mobilities = np.empty((count, count_points, 3, 3))
    points_in_tip = _points_in_tip(points, [grasp])[0]
    for i, positions_i in enumerate(evaluation.joint_positions):
        q = robot.q_from_positions(positions_i)
        mobilities[i] = point_mobility_in_base(robot, model, data, q, points_in_tip)
    stationary, directions = _directions(tangents)
    masses = 1.0 / np.einsum("nka,nkab,nkb->nk", directions, mobilities, directions)
    if stationary.any():
        worst_dirs, worst_masses = _worst_directions(mobilities[stationary])
        directions[stationary] = worst_dirs
        masses[stationary] = worst_masses
    leading = _leading_points(positions, directions, stationary)
    worst = np.argmax(masses, axis=1)
    leading = np.where(stationary.all(axis=1), worst, leading)
    return ExposedPointsEvaluation(
        index=evaluation.index,
        name=evaluation.name,
        feasible=True,
        times_s=read_only(times.copy()),
        points_in_object_m=points,
        positions_in_base_m=read_only(positions),
        directions_in_base=read_only(directions),
        direction_is_worst_case=read_only(stationary),
        speed_m_s=read_only(speeds),
        effective_mass_kg=read_only(masses),
        leading_point_index=read_only(leading),
        worst_point_index=read_only(worst),
    )


def evaluate_exposed_points_on_terms(
    robot: RobotModel,
    evaluations: Sequence[GraspEvaluation],
    grasps: Sequence[Grasp],
    trajectories: Sequence[Trajectory],
    points_in_object_m: Any,
    terms: SampleTerms,
    counts: np.ndarray,
    executor: Executor | None = None,
) -> list[ExposedPointsEvaluation]:
    """``evaluate_exposed_points`` of G feasible grasps at once, on their shared terms
    (``method.terms.grasps_terms``: axis 0 the grasp, in the order of ``evaluations``, with
    ``counts`` samples each): the mobilities by one compiled call over (grasp, sample, point)
    (``method.points.tip_point_masses``), the points' motions once per distinct motion (an
    object path moves the object's points alike whatever the grasp). Equal to the Pinocchio
    path to rounding; each grasp's result is the one it gets alone, bit for bit. It reads the
    tip's rotations and 6x6 mobility: the terms must have been computed with the optional
    ``mobilities_tip_in_base`` (``method.terms.OPTIONAL_TERMS``), M⁻¹ is not read.
    ``executor``: a thread pool that shares the compiled call out (``method.pool.split_grasps``;
    the same bits); None: serial."""
    points = check_points_in_object(points_in_object_m)
    count_points, grasp_count = len(points), len(evaluations)
    motion_keys: dict[tuple[int, bytes], int] = {}
    motions: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    motion_of = np.empty(grasp_count, dtype=np.int64)
    for g, (evaluation, trajectory) in enumerate(zip(evaluations, trajectories, strict=True)):
        times = np.asarray(evaluation.times_s, dtype=float)
        if not evaluation.feasible or len(times) != counts[g]:
            raise InvalidInputError(
                "evaluation", f"grasp {evaluation.index}: must be feasible, one term per sample"
            )
        key = (id(trajectory), times.tobytes())
        if key not in motion_keys:
            motion_keys[key] = len(motions)
            motions.append((times, *_point_motion(trajectory, times, points)))
        motion_of[g] = motion_keys[key]
    samples = terms.jacobians_tip_in_world.shape[1]
    directions = np.zeros((len(motions), samples, count_points, 3))
    stationary = np.zeros((len(motions), samples, count_points), dtype=bool)
    leading_moving = np.zeros((len(motions), samples), dtype=np.int64)
    for m, (times, positions, tangents, _) in enumerate(motions):
        still, unit = _directions(tangents)
        directions[m, : len(times)], stationary[m, : len(times)] = unit, still
        leading_moving[m, : len(times)] = _leading_points(positions, unit, still)
    masses, mask, mobilities = tip_point_masses(
        terms,
        counts,
        robot.transform_base_to_world.rotation,
        _points_in_tip(points, grasps),
        directions,
        stationary,
        motion_of,
        executor,
    )
    grasp_directions = directions[motion_of] if len(mobilities) else None  # else shared
    if grasp_directions is not None:
        grasp_directions[mask], masses[mask] = _worst_directions(mobilities)
    if grasp_directions is None:  # a motion's grasps share its directions
        grasp_directions, direction_of = directions, motion_of
    else:  # a still point's worst direction is the grasp's
        direction_of = np.arange(grasp_count)
    return _results_on_terms(
        evaluations,
        points,
        motions,
        motion_of,
        stationary,
        leading_moving,
        masses,
        grasp_directions,
        direction_of,
    )


def _results_on_terms(
    evaluations: Sequence[GraspEvaluation],
    points: np.ndarray,
    motions: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    motion_of: np.ndarray,
    stationary: np.ndarray,
    leading_moving: np.ndarray,
    masses: np.ndarray,
    directions: np.ndarray,
    direction_of: np.ndarray,
) -> list[ExposedPointsEvaluation]:
    """``evaluate_exposed_points_on_terms``' results, read-only views of its arrays: motion
    m's (times, positions, tangents, speeds), its still points ``stationary[m]`` and moving
    leading points ``leading_moving[m]``; grasp g's motion ``motion_of[g]``, masses row g,
    directions ``directions[direction_of[g]]``. Where all points are still, the leading
    point is the worst (largest mass)."""
    worst = np.argmax(masses, axis=2)
    all_still = np.logical_and.reduce(stationary, axis=2)[motion_of]  # per motion, then grasp
    leading = np.where(all_still, worst, leading_moving[motion_of])
    for array in (directions, stationary, masses, leading, worst):  # views frozen too
        read_only(array)
    shared = [  # per motion: times (a copy), positions, speeds, still points
        (read_only(times, copy=True), read_only(positions), read_only(speeds), still[: len(times)])
        for (times, positions, _, speeds), still in zip(motions, stationary, strict=True)
    ]
    samples = masses.shape[1]
    rows = list(masses), list(leading), list(worst), list(directions)  # views per grasp
    results = []
    for g, evaluation in enumerate(evaluations):
        m = motion_of[g]
        times, positions, speeds, still = shared[m]
        per_sample = [row[g] for row in rows[:3]] + [rows[3][direction_of[g]]]
        if len(times) < samples:
            per_sample = [row[: len(times)] for row in per_sample]
        grasp_masses, grasp_leading, grasp_worst, grasp_directions = per_sample
        results.append(
            ExposedPointsEvaluation(  # positional: the fields in order
                evaluation.index,
                evaluation.name,
                True,
                times,
                points,
                positions,
                grasp_directions,
                still,
                speeds,
                grasp_masses,
                grasp_leading,
                grasp_worst,
            )
        )
    return results


def _points_in_tip(points: np.ndarray, grasps: Sequence[Grasp]) -> np.ndarray:
    """(G, K, 3) the object points in each grasp's tip frame [m]: R_otᵀ (p − t_ot), summed
    in a fixed order (the same bits for a grasp alone or in a batch)."""
    rotations, translations = pose_arrays([grasp.transform_tip_to_object for grasp in grasps])
    relative = points[None] - translations[:, None]  # (G, K, 3)
    return (
        relative[..., 0, None] * rotations[:, None, 0]
        + relative[..., 1, None] * rotations[:, None, 1]
        + relative[..., 2, None] * rotations[:, None, 2]
    )


def _point_motion(
    trajectory: Trajectory, times: np.ndarray, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (N, K, 3) [m] and tangents (N, K, 3) (base frame) and speeds (N, K) [m/s] of
    the object points along ``trajectory`` at ``times``."""
    count, count_points = len(times), len(points)
    positions = np.empty((count, count_points, 3))
    tangents = np.empty((count, count_points, 3))
    speeds = np.empty((count, count_points))
    object_motion = (  # sampled once for every point
        trajectory.object_motion(times) if isinstance(trajectory, ObjectPath) else None
    )
    for k, point in enumerate(points):
        frame = pin.SE3(np.eye(3), point)
        motion = (
            trajectory.tip_motion(frame, times)
            if object_motion is None
            else object_motion.tip_motion(frame)
        )
        positions[:, k] = motion.positions
        tangents[:, k] = motion.tangents
        speeds[:, k] = motion.speeds
    return positions, tangents, speeds


def _directions(tangents: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(stationary (N, K), unit directions (N, K, 3); 0 where stationary) of the tangents."""
    norms = np.linalg.norm(tangents, axis=2)
    stationary = norms < STATIONARY_TANGENT_M
    return stationary, tangents / np.where(stationary, 1.0, norms)[..., None]


def _leading_points(
    positions: np.ndarray, directions: np.ndarray, stationary: np.ndarray
) -> np.ndarray:
    """(N,) the leading point among those that translate (module docstring); 0 where none."""
    centroid = positions.mean(axis=1, keepdims=True)
    ahead = np.einsum("nka,nka->nk", positions - centroid, directions)
    return np.argmax(np.where(stationary, -np.inf, ahead), axis=1)


def metric_point_series(
    evaluation: GraspEvaluation,
    exposed: ExposedPointsEvaluation | None,
    metric_point: str,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample (effective mass [kg], speed [m/s]) of the chosen metric point.

    ``exposed`` may be None only for ``metric_point="tip"``.
    """
    check_metric_point(metric_point)
    if metric_point == "tip":
        return evaluation.effective_mass_kg, evaluation.tip_speed_m_s
    if exposed is None:
        raise InvalidInputError(
            "metric_point", f"{metric_point!r} needs the object's points (shape or point list)"
        )
    if exposed.index != evaluation.index or exposed.feasible != evaluation.feasible:
        raise InvalidInputError(
            "exposed_points", f"belongs to grasp {exposed.index}, not {evaluation.index}"
        )
    if metric_point == "leading_point":
        return exposed.leading_effective_mass_kg, exposed.leading_speed_m_s
    return exposed.worst_effective_mass_kg, exposed.worst_speed_m_s


def score_with_metric_point(
    evaluation: GraspEvaluation,
    exposed: ExposedPointsEvaluation | None,
    metric_point: str,
    metric: str,
) -> float:
    """Score of one grasp (core.ranking.aggregate of the chosen point's mass); NaN if infeasible.

    ``metric_point="tip"`` reproduces evaluation.score computed with the same metric.
    """
    check_metric(metric)
    if not evaluation.feasible:
        return float("nan")
    masses, _ = metric_point_series(evaluation, exposed, metric_point)
    return aggregate(masses, evaluation.times_s, metric)


def order_by_metric_point(
    evaluations: Sequence[GraspEvaluation],
    exposed: Sequence[ExposedPointsEvaluation | None],
    metric_point: str,
    metric: str,
) -> tuple[tuple[int, ...], np.ndarray]:
    """Feasible grasp indices, safest first, and the scores (NaN if infeasible) per grasp.

    ``exposed[i]`` belongs to ``evaluations[i]`` (None allowed for ``tip``); ties keep input
    order, as core.ranking.order_by_score does.
    """
    check_metric_point(metric_point)
    if len(exposed) != len(evaluations):
        raise InvalidInputError(
            "exposed_points",
            f"must have one entry per grasp ({len(evaluations)}), got {len(exposed)}",
        )
    scores = np.array(
        [
            score_with_metric_point(e, x, metric_point, metric)
            for e, x in zip(evaluations, exposed, strict=True)
        ]
    )
    feasible = [k for k, e in enumerate(evaluations) if e.feasible]
    order = tuple(evaluations[k].index for k in sorted(feasible, key=lambda k: scores[k]))
    return order, read_only(scores)
