"""Evaluate candidate grasps along an object trajectory and rank them, safest first."""

from __future__ import annotations

from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ..exceptions import InvalidInputError
from ..model.inertia import ObjectInertia
from ..model.robot import RobotModel
from ..model.trajectory import ObjectMotion, ObjectPath, TipMotion, Trajectory
from .backend import Backend
from .batch import evaluate_grasps_compiled, follow_postures_compiled
from .effective_mass import (
    STATIONARY_TANGENT_M,
    effective_masses_along,
    translational_mobilities_in_base,
    worst_direction,
)
from .ik import IKConfig, IKSolver, check_backend
from .joint_trajectory import JointSpaceTrajectory
from .metrics import METRICS, aggregate, check_metric, score_bound_weights
from .packed import CompiledGraspResult
from .pool import evaluate_jobs, executor_for, job_ranges
from .results import FollowedPosture, Grasp, GraspEvaluation, Ranking

__all__ = [  # the public API, re-exported names included (Grasp ... from results, metrics)
    "BATCH_GRASPS",
    "METRICS",
    "EvaluationConfig",
    "Grasp",
    "GraspEvaluation",
    "GraspSafetyEvaluator",
    "Ranking",
    "SampledTrajectory",
    "aggregate",
    "check_metric",
    "order_by_score",
    "positions_along",
    "sample_trajectory",
]

BATCH_GRASPS = 16
"""Most grasps per call of the fused kernel in ``rank``: one job of the worker pool (its
results, and the ``progress`` calls, come together), fewer so that every worker gets one."""


@dataclass(frozen=True)
class EvaluationConfig:
    """Settings of grasp evaluation.

    Attributes:
        metric: Aggregate used as the score: ``mean`` (default), ``max`` or ``integral``.
        ik: IK settings.
        backend: ``auto`` (compiled kernels when numba is installed and the chain is
            supported, else Pinocchio from Python), ``compiled`` or ``python``; all give the
            same results to rounding.
        workers: Parallel workers for large requests in ``rank``; 0: one per available core,
            1: always serial. Results do not depend on it.
        parallel_min_samples: ``rank`` uses the workers when grasps x samples is at least this.
    """

    metric: str = "mean"
    ik: IKConfig = field(default_factory=IKConfig)
    backend: str = "auto"
    workers: int = 0
    parallel_min_samples: int = 4000

    def __post_init__(self) -> None:
        check_metric(self.metric)
        check_backend(self.backend, "backend")
        for name, value in (
            ("workers", self.workers),
            ("parallel_min_samples", self.parallel_min_samples),
        ):
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise InvalidInputError(name, f"must be an integer >= 0, got {value!r}")


def order_by_score(evaluations: Sequence[GraspEvaluation]) -> tuple[int, ...]:
    """Indices of the feasible evaluations sorted by score ascending; ties keep input order."""
    feasible = [e for e in evaluations if e.feasible]
    return tuple(e.index for e in sorted(feasible, key=lambda e: e.score))


@dataclass(frozen=True)
class SampledTrajectory:
    """An object trajectory sampled once for every grasp evaluated along it.

    Attributes:
        trajectory: The trajectory (a two-waypoint one as its identical quintic).
        times_s: Sample times [s].
        s_values: Path parameters at the times.
        object_motion: The object's motion at the times; None when the trajectory type does
            not give one (then each grasp's ``tip_motion`` is asked for).
    """

    trajectory: Trajectory
    times_s: np.ndarray
    s_values: np.ndarray
    object_motion: ObjectMotion | None


def sample_trajectory(trajectory: Trajectory) -> SampledTrajectory:
    """``trajectory`` sampled at its ``times_s()``, for evaluating many grasps along it."""
    trajectory = _as_quintic(trajectory)
    times = trajectory.times_s()
    s_values, _, _ = trajectory.path_parameter(times)
    motion = trajectory.object_motion(times) if isinstance(trajectory, ObjectPath) else None
    return SampledTrajectory(trajectory, times, s_values, motion)


class GraspSafetyEvaluator:
    """Computes the effective mass of robot + object along each grasp's tip trajectory."""

    def __init__(self, robot: RobotModel, config: EvaluationConfig | None = None) -> None:
        self.robot = robot
        self.config = config or EvaluationConfig()
        self.ik = IKSolver(robot, self.config.ik, self.config.backend)
        self.backend = Backend.of(self.ik)
        """Compiled or Pinocchio, decided once: the ranking's and every analysis's."""

    def seed(
        self, seed_positions: Sequence[float] | np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """An IK seed given in chain joint order (or the default), checked: its Pinocchio
        configuration and its positions as given (continuous joints not wrapped)."""
        if seed_positions is None:
            positions = np.asarray(self.robot.default_seed_positions(), dtype=float)
        else:
            positions = self.robot.check_positions(seed_positions, "robot.seed")
        return self.robot.q_from_positions(positions), np.asarray(positions, dtype=float)

    def trajectory_for(self, grasp: Grasp, trajectory: Trajectory) -> Trajectory:
        """The motion a grasp is evaluated along: its planned joint trajectory if it has one
        (validated against the chain: names and limits), else ``trajectory``."""
        if grasp.joint_trajectory is None:
            return trajectory
        return JointSpaceTrajectory(
            self.robot, grasp.joint_trajectory, grasp.transform_tip_to_object
        )

    def evaluate(
        self,
        grasp: Grasp,
        object_inertia: ObjectInertia,
        trajectory: Trajectory,
        index: int = 0,
        seed_positions: Sequence[float] | np.ndarray | None = None,
        metric: str | None = None,
    ) -> GraspEvaluation:
        """Evaluate one grasp: IK along its tip trajectory, then effective mass per sample."""
        metric = check_metric(metric or self.config.metric)
        seed_q, start = self.seed(seed_positions)
        return self.evaluate_batch(
            (index,),
            (grasp,),
            object_inertia,
            sample_trajectory(trajectory),
            metric,
            seed_q,
            start,
        )[0]

    def evaluate_batch(
        self,
        indices: Sequence[int],
        grasps: Sequence[Grasp],
        object_inertia: ObjectInertia,
        sampled_trajectory: SampledTrajectory,
        metric: str,
        seed_q: np.ndarray,
        seed_positions: np.ndarray | None = None,
    ) -> list[GraspEvaluation]:
        """``evaluate`` of several grasps along a trajectory sampled once
        (``sample_trajectory``), with a checked metric. ``indices``: their positions in the
        candidate list; ``seed_q``: the IK seed as a Pinocchio configuration, one for all
        (nq,) or one per grasp (G, nq); ``seed_positions``: the same seed in chain order,
        continuous joints unwrapped, where the output joint positions start from (None: from
        ``seed_q``, in (−π, π]). With the compiled kernels, the grasps that follow the
        object's motion by IK run in one kernel call."""
        seeds = np.broadcast_to(seed_q, (len(grasps), seed_q.shape[-1]))
        if seed_positions is None:
            starts = np.array([self.robot.positions_from_q(q) for q in seeds])
        else:
            starts = np.broadcast_to(seed_positions, (len(grasps), self.robot.num_joints))
        motion = sampled_trajectory.object_motion
        fused_rows = [
            k
            for k, grasp in enumerate(grasps)
            if self.backend.compiled and motion is not None and grasp.joint_trajectory is None
        ]
        evaluations: dict[int, GraspEvaluation] = {}
        if fused_rows and motion is not None:
            results = evaluate_grasps_compiled(
                self.ik,
                object_inertia,
                [grasps[k].transform_tip_to_object for k in fused_rows],
                motion,
                sampled_trajectory.times_s,
                seeds[fused_rows],
            )
            for k, result in zip(fused_rows, results, strict=True):
                evaluations[k] = self._from_compiled(
                    indices[k],
                    grasps[k],
                    result,
                    motion,
                    sampled_trajectory.times_s,
                    metric,
                    (object_inertia, starts[k]),
                )
        for k, grasp in enumerate(grasps):
            if k not in evaluations:
                evaluations[k] = self._evaluate_one(
                    indices[k],
                    grasp,
                    object_inertia,
                    sampled_trajectory,
                    metric,
                    (seeds[k], starts[k]),
                )
        return [evaluations[k] for k in range(len(grasps))]

    def follow_postures(
        self,
        indices: Sequence[int],
        grasps: Sequence[Grasp],
        object_inertia: ObjectInertia,
        sampled_trajectory: SampledTrajectory,
        metric: str,
        seeds_q: np.ndarray,
        stop_above: np.ndarray,
    ) -> list[FollowedPosture | None]:
        """``evaluate_batch`` of start postures (seeds_q (G, nq): row g an IK solution of its
        grasp's first tip pose), each stopped as soon as its score certainly exceeds
        stop_above[g] (inf: never): None for a stopped row, else its feasibility and score,
        its GraspEvaluation built on demand.

        The early stop runs in the fused kernel (``follow_postures_compiled``); a row that is
        not stopped equals ``evaluate_batch``'s bit for bit. Without the fused kernel
        (Python backend, a trajectory without an ObjectMotion) no row is stopped.
        """
        motion = sampled_trajectory.object_motion
        if not self.backend.compiled or motion is None:
            batch = (indices, grasps, object_inertia, sampled_trajectory, metric, seeds_q)
            return [FollowedPosture.of(evaluation) for evaluation in self.evaluate_batch(*batch)]
        times = sampled_trajectory.times_s
        is_max, weights, margin = score_bound_weights(times, metric)
        bounds = np.asarray(stop_above, dtype=float)
        bounds = bounds + np.abs(bounds) * margin  # inf stays inf
        results = follow_postures_compiled(
            self.ik,
            object_inertia,
            [grasp.transform_tip_to_object for grasp in grasps],
            motion,
            times,
            seeds_q,
            (is_max, weights, bounds),
        )
        followed: list[FollowedPosture | None] = []
        for index, grasp, result, seed in zip(indices, grasps, results, seeds_q, strict=True):
            if result is None:
                followed.append(None)
                continue
            score = float("nan")
            if not result.reason:  # _feasible's score: of the masses with the worst filled in
                masses = result.effective_masses
                _fill_worst(result.mobilities, masses, result.directions, result.worst)
                score = aggregate(masses, times, metric)
            start = (object_inertia, self.robot.positions_from_q(seed))
            build = partial(self._from_compiled, index, grasp, result, motion, times, metric)
            followed.append(FollowedPosture(not result.reason, score, partial(build, start, True)))
        return followed

    def _from_compiled(
        self,
        index: int,
        grasp: Grasp,
        result: CompiledGraspResult,
        motion: ObjectMotion,
        times: np.ndarray,
        metric: str,
        inertia_seed: tuple[ObjectInertia, np.ndarray],
        filled: bool = False,
    ) -> GraspEvaluation:
        """The GraspEvaluation of one grasp's ``evaluate_grasps_compiled`` result, its worst
        case filled in unless ``filled`` (``inertia_seed``: object inertia, seed positions)."""
        if result.reason:
            return _infeasible(index, grasp.name, result.reason, self.robot.num_joints)
        masses_directions_worst = (result.effective_masses, result.directions, result.worst)
        if not filled:
            _fill_worst(result.mobilities, *masses_directions_worst)
        return self._feasible(
            index,
            grasp,
            times,
            metric,
            result.q,
            result.iterations,
            masses_directions_worst,
            result.tangent_norms * motion.speed_per_tangent,
            inertia_seed,
        )

    def _evaluate_one(
        self,
        index: int,
        grasp: Grasp,
        object_inertia: ObjectInertia,
        sampled_trajectory: SampledTrajectory,
        metric: str,
        seed: tuple[np.ndarray, np.ndarray],
    ) -> GraspEvaluation:
        """One grasp outside the batched kernel: a planned joint trajectory, the Python
        backend, or a trajectory type without an ObjectMotion (``seed``: the IK seed q and
        its positions)."""
        robot = self.robot
        seed_q, start = seed
        trajectory, times = sampled_trajectory.trajectory, sampled_trajectory.times_s
        object_motion = sampled_trajectory.object_motion
        sampled = self.trajectory_for(grasp, trajectory)
        if isinstance(sampled, JointSpaceTrajectory):  # the planner's joint positions, no IK
            times = sampled.times_s()
            tip = sampled.tip_motion(grasp.transform_tip_to_object, times)
            q_all = np.array([robot.q_from_positions(p) for p in sampled.joint_positions])
            mobilities = translational_mobilities_in_base(
                robot, object_inertia, grasp.transform_tip_to_object, q_all
            )
            return self._feasible(
                index,
                grasp,
                times,
                metric,
                q_all,
                np.zeros(len(times), dtype=np.int64),
                _masses_along(mobilities, tip.tangents),
                tip.speeds,
                (object_inertia, start),
                sampled,
            )
        if object_motion is not None:
            tip = object_motion.tip_motion(grasp.transform_tip_to_object)
        else:
            tip = trajectory.tip_motion(grasp.transform_tip_to_object, times)
            if self.backend.compiled:  # the tip's own motion, composed with the identity
                motion = _tip_as_object_motion(tip)
                (result,) = evaluate_grasps_compiled(
                    self.ik,
                    object_inertia,
                    [grasp.transform_tip_to_object],
                    motion,
                    times,
                    seed_q,
                    motion_is_tip=True,
                )
                return self._from_compiled(
                    index, grasp, result, motion, times, metric, (object_inertia, start)
                )
        ik = self.ik.solve_trajectory_arrays(
            tip.rotations, tip.positions, times, sampled_trajectory.s_values, seed_q
        )
        if not ik.feasible:
            return _infeasible(index, grasp.name, ik.reason, robot.num_joints)
        mobilities = translational_mobilities_in_base(
            robot, object_inertia, grasp.transform_tip_to_object, ik.q
        )
        return self._feasible(
            index,
            grasp,
            times,
            metric,
            ik.q,
            ik.iterations,
            _masses_along(mobilities, tip.tangents),
            tip.speeds,
            (object_inertia, start),
        )

    def _feasible(
        self,
        index: int,
        grasp: Grasp,
        times: np.ndarray,
        metric: str,
        q_all: np.ndarray,
        iterations: np.ndarray,
        masses_directions_worst: tuple[np.ndarray, np.ndarray, np.ndarray],
        tip_speeds: np.ndarray,
        inertia_seed: tuple[ObjectInertia, np.ndarray],
        planned: JointSpaceTrajectory | None = None,
    ) -> GraspEvaluation:
        """The GraspEvaluation of a feasible grasp from its masses and directions, the worst case
        already in where the tip does not translate (``_fill_worst``); with armature, the
        links-only masses too; joint positions unwrapped from the IK seed
        (``inertia_seed``: the object's inertia and the seed's positions, chain order), or
        the ``planned`` ones."""
        masses, directions, worst = masses_directions_worst
        object_inertia, start = inertia_seed
        links_only = masses  # no armature, or explicit zeros: these are the links' own
        if np.any(self.robot.armature_kgm2 > 0):
            links_only = self._links_only_masses(grasp, object_inertia, q_all, directions, worst)
        if planned is not None:
            positions = np.array(planned.joint_positions)
            rates = planned.joint_rates()
        else:
            positions, rates = positions_along(self.robot, q_all, start), None
        return GraspEvaluation(
            index=index,
            name=grasp.name,
            feasible=True,
            reason="",
            score=aggregate(masses, times, metric),
            times_s=times,
            joint_positions=positions,
            directions_in_base=directions,
            effective_mass_kg=masses,
            direction_is_worst_case=worst,
            tip_speed_m_s=tip_speeds,
            ik_iterations=iterations,
            links_only_effective_mass_kg=links_only,
            planned_joint_rates=rates,
        )

    def _links_only_masses(
        self,
        grasp: Grasp,
        object_inertia: ObjectInertia,
        q_all: np.ndarray,
        directions: np.ndarray,
        worst: np.ndarray,
    ) -> np.ndarray:
        """Effective masses [kg] of the chain without its armature, along ``directions`` (at
        the ``worst`` samples, along its own worst direction), as a run without armature."""
        links = self.robot.links_only()
        chain = self.backend.chain
        if chain is not None:
            chain = chain._replace(armature=np.zeros(links.num_joints))
        mobilities = translational_mobilities_in_base(
            links, object_inertia, grasp.transform_tip_to_object, q_all, chain
        )
        masses = np.empty(len(q_all))
        moving = ~worst
        masses[moving] = effective_masses_along(mobilities[moving], directions[moving])
        for i in np.flatnonzero(worst):
            masses[i] = worst_direction(mobilities[i])[1]
        return masses

    def rank(
        self,
        grasps: Sequence[Grasp],
        object_inertia: ObjectInertia,
        trajectory: Trajectory,
        seed_positions: Sequence[float] | np.ndarray | None = None,
        metric: str | None = None,
        progress: Callable[[int, int], None] | None = None,
    ) -> Ranking:
        """Evaluate every grasp and rank the feasible ones, safest first.

        The grasps go to the kernels in batches of at most BATCH_GRASPS (on the worker pool
        for large requests).

        Args:
            progress: Called as ``progress(done, total)`` after each grasp (the grasps of a
                batch come together; a ``progress`` that raises stops the work after the
                batches already running).
        """
        metric = check_metric(metric or self.config.metric)
        seed_q, start_positions = self.seed(seed_positions)  # validate once, before any work
        grasps = list(grasps)
        sampled = sample_trajectory(trajectory)  # once for every grasp
        for grasp in grasps:
            self.trajectory_for(grasp, sampled.trajectory)  # planned trajectories: validate
        executor = executor_for(self, len(grasps) * len(sampled.times_s))
        jobs = [
            (
                range(start, stop),
                grasps[start:stop],
                object_inertia,
                sampled,
                metric,
                seed_q,
                start_positions,
            )
            for start, stop in job_ranges(executor, len(grasps), BATCH_GRASPS)
        ]
        if executor is None or len(jobs) == 1:  # one job: no hand-off to a worker
            batches: Generator[list[GraspEvaluation], None, None] = (
                self.evaluate_batch(*job) for job in jobs
            )
        else:
            batches = evaluate_jobs(self, executor, jobs, GraspSafetyEvaluator.evaluate_batch)
        evaluations: list[GraspEvaluation] = []
        try:
            for batch in batches:
                for evaluation in batch:
                    evaluations.append(evaluation)
                    if progress is not None:
                        progress(len(evaluations), len(grasps))
        finally:
            batches.close()  # progress raised: stop the work still queued
        return Ranking(
            joint_names=self.robot.joint_names,
            metric=metric,
            order=order_by_score(evaluations),
            evaluations=tuple(evaluations),
            backend=self.ik.backend_used,
            armature_given=self.robot.armature_given,
        )


def positions_along(
    robot: RobotModel, q_all: np.ndarray, start_positions: np.ndarray | None = None
) -> np.ndarray:
    """``robot.positions_from_q`` of every row of q_all (N, nq), vectorised: (N, joints).

    Continuous joints come out unwrapped: continuous along the rows (steps below π), the
    first row within π of ``start_positions`` (chain order; None: in (−π, π]).
    """
    model = robot.model
    if model.nq == model.nv:  # no continuous joint: positions are q
        return np.asarray(q_all, dtype=float)
    joints = list(model.joints)[1:]
    if len(joints) != robot.num_joints:  # not one model joint per chain joint
        return np.array([robot.positions_from_q(q) for q in q_all]).reshape(-1, robot.num_joints)
    q_all = np.asarray(q_all, dtype=float).reshape(-1, model.nq)
    columns = []
    for k, joint in enumerate(joints):
        index = joint.idx_q
        if joint.nq == 2:  # continuous: (cos, sin)
            angles = np.unwrap(np.arctan2(q_all[:, index + 1], q_all[:, index]))
            if start_positions is not None and len(angles):
                turns = np.round((start_positions[k] - angles[0]) / (2.0 * np.pi))
                angles += 2.0 * np.pi * turns
            columns.append(angles)
        else:
            columns.append(q_all[:, index])
    return np.stack(columns, axis=1)


def _tip_as_object_motion(tip: TipMotion) -> ObjectMotion:
    """A tip motion as the ObjectMotion whose identity grasp gives it back."""
    norms = np.linalg.norm(tip.tangents, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        speed_per_tangent = np.where(norms > 0.0, tip.speeds / norms, 0.0)
    return ObjectMotion(
        tip.rotations, tip.positions, tip.tangents, np.zeros_like(tip.tangents), speed_per_tangent
    )


def _as_quintic(trajectory: Trajectory) -> Trajectory:
    """A two-waypoint trajectory as its identical quintic (so it takes the same code path)."""
    return getattr(trajectory, "quintic", None) or trajectory


def _masses_along(
    mobilities: np.ndarray, tangents: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Effective masses along the unit tangents, the directions, and the samples where the tip
    does not translate (their direction and mass: the worst case, ``_fill_worst``)."""
    count = len(tangents)
    masses = np.empty(count)
    directions = np.empty((count, 3))
    tangent_norms = np.linalg.norm(tangents, axis=1)
    worst = tangent_norms < STATIONARY_TANGENT_M
    moving = ~worst
    directions[moving] = tangents[moving] / tangent_norms[moving, None]
    masses[moving] = effective_masses_along(mobilities[moving], directions[moving])
    _fill_worst(mobilities, masses, directions, worst)
    return masses, directions, worst


def _fill_worst(
    mobilities: np.ndarray, masses: np.ndarray, directions: np.ndarray, worst: np.ndarray
) -> None:
    """Where the tip does not translate (``worst``): the largest effective mass, in place."""
    for i in np.flatnonzero(worst):
        directions[i], masses[i] = worst_direction(mobilities[i])


def _infeasible(index: int, name: str, reason: str, num_joints: int) -> GraspEvaluation:
    return GraspEvaluation(
        index=index,
        name=name,
        feasible=False,
        reason=reason,
        score=float("nan"),
        times_s=np.empty(0),
        joint_positions=np.empty((0, num_joints)),
        directions_in_base=np.empty((0, 3)),
        effective_mass_kg=np.empty(0),
        direction_is_worst_case=np.empty(0, dtype=bool),
        tip_speed_m_s=np.empty(0),
        ik_iterations=np.empty(0, dtype=int),
    )
