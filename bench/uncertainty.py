"""Benchmark: the inertia-uncertainty analysis on the compiled path vs its Pinocchio reference,
each as a ratio to the ranking's own time in the same run (one process): on one core
(workers=1), and on the evaluator's thread pool (one worker per core) for both.

Workload: the Baxter book scenario of ``bench/pipeline.py`` (G grasps along the spine, dt
0.01 s, 201 samples) with bounds mass ±20 %, CoM ±1 cm, second moments ±30 % and 64 random
samples: 1 + 2^7 corners + 64 = 193 inertias per grasp.

Run: .venv/bin/python bench/uncertainty.py [--grasps 100] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from pipeline import book_scenario

from grasp_safety_ros.core.analyses.uncertainty import (
    InertiaUncertainty,
    analyse_inertia_uncertainty,
)
from grasp_safety_ros.core.method.pool import default_workers, executor_for
from grasp_safety_ros.core.method.ranking import EvaluationConfig, GraspSafetyEvaluator
from grasp_safety_ros.scenario.schema import load_scenario

UNCERTAINTY = InertiaUncertainty(0.2, 0.01, 0.3, num_random_samples=64)


def bench_uncertainty(grasps: int, repeats: int = 3) -> dict[str, Any]:
    """Median times [s] of the ranking and of the analysis on both paths, and their ratios."""
    with tempfile.TemporaryDirectory() as folder:
        scenario = load_scenario(book_scenario(grasps, Path(folder)))
    robot = scenario.robot.load(scenario.base_dir)
    evaluator = GraspSafetyEvaluator(robot, EvaluationConfig(metric=scenario.metric, workers=1))
    args = (scenario.grasps, scenario.object_inertia, scenario.trajectory)
    pooled = GraspSafetyEvaluator(robot, EvaluationConfig(metric=scenario.metric))
    ranking = evaluator.rank(*args, seed_positions=scenario.robot.seed)  # warm
    pooled.rank(*args, seed_positions=scenario.robot.seed)
    chain = evaluator.ik.chain
    samples = len(scenario.trajectory.times_s())

    def analysis(compiled: bool, pool: bool = False) -> Any:
        return analyse_inertia_uncertainty(
            robot,
            ranking.evaluations,
            scenario.grasps,
            scenario.object_inertia,
            UNCERTAINTY,
            ranking.metric,
            chain if compiled else None,
            executor_for(pooled, grasps * samples) if pool else None,
        )

    analysis(True)  # warm: the kernel loaded
    timings: dict[str, list[float]] = {
        name: [] for name in ("ranking", "compiled", "ranking_pool", "compiled_pool", "reference")
    }
    for repeat in range(repeats):
        start = time.perf_counter()
        ranking = evaluator.rank(*args, seed_positions=scenario.robot.seed)
        timings["ranking"].append(time.perf_counter() - start)
        start = time.perf_counter()
        compiled = analysis(True)
        timings["compiled"].append(time.perf_counter() - start)
        start = time.perf_counter()
        pooled.rank(*args, seed_positions=scenario.robot.seed)
        timings["ranking_pool"].append(time.perf_counter() - start)
        start = time.perf_counter()
        analysis(True, pool=True)
        timings["compiled_pool"].append(time.perf_counter() - start)
        if repeat == 0:  # the Pinocchio reference, once
            start = time.perf_counter()
            reference = analysis(False)
            timings["reference"].append(time.perf_counter() - start)
    medians = {name: statistics.median(values) for name, values in timings.items()}
    feasible = [g for g in compiled.grasps if g.feasible]
    error = max(
        float(abs(ours.scores - theirs.scores).max() / abs(theirs.scores).max())
        for ours, theirs in zip(compiled.grasps, reference.grasps, strict=True)
        if ours.feasible
    )
    evaluations = len(feasible) * samples * len(compiled.perturbations)
    return {
        "grasps": grasps,
        "feasible": len(feasible),
        "samples": samples,
        "inertias": len(compiled.perturbations),
        "seconds": medians,
        "workers": default_workers(),
        "compiled_vs_ranking": medians["compiled"] / medians["ranking"],
        "pool_compiled_vs_pool_ranking": medians["compiled_pool"] / medians["ranking_pool"],
        "reference_vs_ranking": medians["reference"] / medians["ranking"],
        "speed_up": medians["reference"] / medians["compiled"],
        "compiled_ns_per_grasp_sample_inertia": 1e9 * medians["compiled"] / evaluations,
        "largest_score_difference_relative": error,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grasps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    options = parser.parse_args()
    print(json.dumps(bench_uncertainty(options.grasps, options.repeats), indent=2))


if __name__ == "__main__":
    main()
