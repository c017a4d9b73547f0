"""Benchmark section: cost of the whole-arm exposure (core.analyses.whole_arm) per sample.

Per arm workload (bench/workload.py: a box, grasps around it, 2 s at dt 0.01 s), on the
feasible grasps of one compiled ranking, one core, median over repeats, CPU time of the
process (less inflated than wall-clock time when other processes share the cores), µs per
(grasp, sample):

- ``us_per_sample``: the whole arm as the report runs it with a compiled evaluator: the shared
  terms of all feasible grasps in one kernel call (``method.terms.grasps_terms``), then
  ``evaluate_whole_arm_on_terms`` (q̇, the site kernel over (grasp, sample, site), ISO/TS
  15066's peaks over every body region; per step: ``whole_arm_steps.py``), the default sites
  (joint origins from the third, the tip) + 8 points: the box's corners as user points on the
  tip's link (``arm_points_m``, placed by the first candidate grasp; what a user declares for a
  held box), as issue 30's row "default sites + 8 points" and bench/retime.py's 14 Panda
  sites;
- ``us_per_sample_pinocchio``: ``evaluate_whole_arm`` per grasp on the Pinocchio reference path
  (per-sample placements, Jacobians, M⁻¹ of the augmented model; q̇; vectorised site arrays);
- ``us_per_sample_given_terms``: the reference's vectorised part alone (``site_exposure`` +
  ``assess_sites``) from precomputed Pinocchio terms;
- ``ranking_us_per_sample``: the compiled ranking of the same candidates (IK + tip effective
  mass) in the same run, per (grasp, sample) of all candidates, for the ratio;
- ``posture_ms_per_grasp``: posture selection (the pipeline's ``postures`` stage,
  POSTURE_RESTARTS restarts) of the same candidates, ms per grasp, by the tip score and by the
  whole arm's chest force (``rank_by: whole_arm``'s criterion).

Run alone: .venv/bin/python bench/whole_arm.py [--arms panda,baxter] [--grasps 10]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from workload import ARMS, BOX_SIZE_M, ArmWorkload, box_object, grasps_around_box

from grasp_safety_ros.core import EvaluationConfig, GraspSafetyEvaluator
from grasp_safety_ros.core.analyses.body_regions import select_regions
from grasp_safety_ros.core.analyses.exposed_points import box_corners_in_object
from grasp_safety_ros.core.analyses.safety_report import AnalysisOptions
from grasp_safety_ros.core.analyses.whole_arm import (
    WHOLE_ARM_TERMS,
    ArmTerms,
    assess_sites,
    evaluate_whole_arm,
    evaluate_whole_arm_on_terms,
    jacobians_tip_in_world,
    pinocchio_kinematic_terms,
    resolve_arm_sites,
    site_exposure,
    tip_following_joint_velocities,
    tip_twists_in_base,
)
from grasp_safety_ros.core.method.effective_mass import augmented_model
from grasp_safety_ros.core.method.posture import PostureConfig
from grasp_safety_ros.core.method.terms import grasps_terms
from grasp_safety_ros.core.pipeline import PipelineRequest, run_pipeline

POSTURE_RESTARTS = 8


@dataclass(frozen=True)
class _Case:
    """One arm's workload: the candidates, the compiled ranking's feasible (grasp, evaluation)
    pairs, the sites (default + the box's corners on the tip's link) and their Pinocchio
    terms."""

    arm: ArmWorkload
    robot: Any
    obj: Any
    trajectory: Any
    candidates: list[Any]
    evaluator: GraspSafetyEvaluator
    pairs: list[tuple[Any, Any]]
    arm_points: dict[str, np.ndarray]
    sites: Any
    regions: Any
    terms: list[ArmTerms]

    @property
    def samples(self) -> int:
        """The (grasp, sample) pairs of the feasible grasps."""
        return sum(len(e.times_s) for _, e in self.pairs)


def _prepare(arm: ArmWorkload, grasps: int) -> _Case:
    """The workload of ``arm`` with ``grasps`` candidates, ranked once."""
    robot = arm.robot()
    trajectory = arm.trajectory(2.0, 0.01)
    obj = box_object()
    candidates = grasps_around_box(np.array(arm.approach_from), grasps)
    evaluator = GraspSafetyEvaluator(robot, EvaluationConfig(workers=1))
    ranking = evaluator.rank(candidates, obj, trajectory, seed_positions=arm.seed_positions)
    pairs = [(g, e) for g, e in zip(candidates, ranking.evaluations, strict=True) if e.feasible]
    tip_to_object = candidates[0].transform_tip_to_object
    corners_in_tip = [tip_to_object.actInv(c) for c in box_corners_in_object(BOX_SIZE_M)]
    arm_points = {arm.tip_frame: np.array(corners_in_tip)}
    return _Case(
        arm,
        robot,
        obj,
        trajectory,
        candidates,
        evaluator,
        pairs,
        arm_points,
        resolve_arm_sites(robot, arm_points),
        select_regions(None),
        _pinocchio_terms(robot, obj, trajectory, pairs),
    )


def _pinocchio_terms(
    robot: Any, obj: Any, trajectory: Any, pairs: list[tuple[Any, Any]]
) -> list[ArmTerms]:
    """The reference path's per-grasp terms (placements, Jacobians, M⁻¹, q̇), precomputed."""
    terms = []
    for grasp, evaluation in pairs:
        model = augmented_model(robot, obj, grasp.transform_tip_to_object)
        q_all = np.array([robot.q_from_positions(p) for p in evaluation.joint_positions])
        kinematics = pinocchio_kinematic_terms(model, q_all)
        twists = tip_twists_in_base(trajectory, grasp.transform_tip_to_object, evaluation.times_s)
        rotation = robot.transform_base_to_world.rotation
        twists = np.concatenate([twists[:, :3] @ rotation.T, twists[:, 3:] @ rotation.T], 1)
        rates = tip_following_joint_velocities(
            robot,
            jacobians_tip_in_world(robot, kinematics),
            twists,
            evaluation.times_s,
            evaluation.joint_positions,
        )
        terms.append(ArmTerms(*kinematics, rates))
    return terms


def _timed_functions(case: _Case) -> dict[str, tuple[Callable[[], float | None], float]]:
    """Each figure's function (None: time it here; a float: its own CPU time [s]) and the
    count its time is divided by (times 1e6: µs per sample, or ms per grasp)."""
    robot, obj, trajectory, pairs, sites = (
        case.robot,
        case.obj,
        case.trajectory,
        case.pairs,
        case.sites,
    )

    def full() -> None:
        for grasp, evaluation in pairs:
            evaluate_whole_arm(robot, evaluation, obj, grasp, trajectory, sites)

    def compiled() -> None:
        shared = grasps_terms(
            robot,
            case.evaluator.ik.chain,
            obj,
            [grasp.transform_tip_to_object for grasp, _ in pairs],
            [evaluation.joint_positions for _, evaluation in pairs],
            optional=WHOLE_ARM_TERMS,  # what the whole arm reads of the optional terms
        )
        evaluate_whole_arm_on_terms(
            robot,
            [evaluation for _, evaluation in pairs],
            [trajectory] * len(pairs),
            [grasp for grasp, _ in pairs],
            sites,
            case.regions,
            *shared,
        )

    def given_terms() -> None:
        for term in case.terms:
            exposure = site_exposure(sites, term, robot.transform_base_to_world)
            assess_sites(exposure.speed_m_s, exposure.effective_mass_kg, 2.0, case.regions)

    def rank() -> None:
        case.evaluator.rank(
            case.candidates, obj, trajectory, seed_positions=case.arm.seed_positions
        )

    def postures(options: AnalysisOptions) -> float:
        """The process CPU time [s] of the pipeline's posture stage."""
        request = PipelineRequest(
            tuple(case.candidates),
            obj,
            trajectory,
            options=options,
            posture=PostureConfig(restarts=POSTURE_RESTARTS),
            seed_positions=case.arm.seed_positions,
        )
        stages: dict[str, float] = {}
        run_pipeline(case.evaluator, request, timings=stages)
        return stages["postures_process_cpu"]

    def postures_by_score() -> float:
        return postures(AnalysisOptions(iso_regions=(), effort=False))

    def postures_by_whole_arm() -> float:
        return postures(
            AnalysisOptions(rank_by="whole_arm", arm_points_m=case.arm_points, effort=False)
        )

    samples = case.samples
    per_grasp_ms = 1e3 * len(case.candidates)  # seconds / (1e3 grasps) * 1e6 = ms per grasp
    return {
        "compiled": (compiled, samples),
        "full": (full, samples),
        "given_terms": (given_terms, samples),
        "rank": (rank, len(case.candidates) * trajectory.num_samples),
        "postures_by_score": (postures_by_score, per_grasp_ms),
        "postures_by_whole_arm": (postures_by_whole_arm, per_grasp_ms),
    }


def bench_whole_arm(arm: ArmWorkload, grasps: int = 10, repeats: int = 5) -> dict[str, Any]:
    """The section's figures for one arm (module docstring)."""
    case = _prepare(arm, grasps)
    functions = _timed_functions(case)
    timings: dict[str, list[float]] = {key: [] for key in functions}
    for _ in range(repeats):
        for key, (function, count) in functions.items():
            start = time.process_time()
            seconds = function()  # the functions of a pipeline stage time it themselves
            if seconds is None:
                seconds = time.process_time() - start
            timings[key].append(seconds / max(count, 1) * 1e6)
    return {
        "robot": f"{arm.urdf} {arm.base_frame} -> {arm.tip_frame}",
        "sites": len(case.sites),
        "arm_points": len(case.arm_points[arm.tip_frame]),
        "feasible_grasps": len(case.pairs),
        "samples": case.samples,
        "us_per_sample": statistics.median(timings["compiled"]),
        "us_per_sample_pinocchio": statistics.median(timings["full"]),
        "us_per_sample_given_terms": statistics.median(timings["given_terms"]),
        "ranking_us_per_sample": statistics.median(timings["rank"]),
        "posture_restarts": POSTURE_RESTARTS,
        "posture_ms_per_grasp": {
            "score": statistics.median(timings["postures_by_score"]),
            "whole_arm": statistics.median(timings["postures_by_whole_arm"]),
        },
    }


def print_whole_arm(results: dict[str, dict[str, Any]]) -> None:
    """One line per arm."""
    for name, r in results.items():
        print(
            f"whole arm ({name}, {r['sites']} sites, {r['feasible_grasps']} grasps x 201): "
            f"{r['us_per_sample']:.1f} us/sample on the shared compiled terms, "
            f"{r['us_per_sample_pinocchio']:.1f} us/sample on the Pinocchio reference path "
            f"({r['us_per_sample_given_terms']:.1f} given its terms); the ranking "
            f"{r['ranking_us_per_sample']:.1f} us/sample (CPU time, median); posture "
            f"selection ({r['posture_restarts']} restarts) by the tip score "
            f"{r['posture_ms_per_grasp']['score']:.1f} ms/grasp, by the whole arm "
            f"{r['posture_ms_per_grasp']['whole_arm']:.1f} ms/grasp"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", default="panda,baxter")
    parser.add_argument("--grasps", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    results = {
        name: bench_whole_arm(ARMS[name], args.grasps, args.repeats)
        for name in args.arms.split(",")
    }
    print_whole_arm(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
