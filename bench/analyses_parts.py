"""Benchmark section: each analysis of ``safety_report.analyse`` alone, beside the ranking of
the same run (issue 21: all default analyses together at most the ranking's time).

Workload: the book scenario of ``pipeline.book_scenario`` (Baxter, G grasps along the spine,
201 samples), ranked once (compiled, one core) and given to ``analyse`` as the ranking, with
the options of one analysis at a time: exposed points (the box's 8 corners), ISO/TS 15066
over every region (on the tip), the whole arm (default sites, with ISO), effort, and the scenario's
defaults together (with and without effort, with the whole arm). Each figure is the median
time over repeats (wall, or with ``--cpu`` the process's CPU time, which other processes on a
shared machine disturb less) and its ratio to the median time of the ranking measured in the
same loop. Only options of ``AnalysisOptions`` are used, so the same file measures older
checkouts. ``--workers 2`` gives the evaluator the node's pool (two threads from the node's
threshold, ``ros.robot.bundle.PARALLEL_MIN_SAMPLES``): the ranking and the analyses' kernels
then share out (wall time: ``--cpu`` would count every thread's CPU).

Run alone: .venv/bin/python bench/analyses_parts.py [--grasps 1000] [--repeats 3] [--cpu]
[--workers 1]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from pipeline import book_scenario


def bench_parts(
    grasps: int, repeats: int = 3, cpu: bool = False, workers: int = 1
) -> dict[str, Any]:
    """Median seconds (CPU time if ``cpu``, else wall) per part and per ranking, and each
    part's ratio to the ranking; the evaluator has ``workers`` (above 1: the node's pool)."""
    from grasp_safety_ros.core.analyses.safety_report import AnalysisOptions, analyse
    from grasp_safety_ros.core.method.ranking import EvaluationConfig, GraspSafetyEvaluator
    from grasp_safety_ros.scenario.schema import load_scenario

    with tempfile.TemporaryDirectory() as folder:
        scenario = load_scenario(book_scenario(grasps, Path(folder)))
    robot = scenario.robot.load(scenario.base_dir)
    config = EvaluationConfig(metric=scenario.metric, workers=workers)
    if workers > 1:  # (only then: older checkouts have no such constant)
        from grasp_safety_ros.ros.robot.bundle import PARALLEL_MIN_SAMPLES

        config = replace(config, parallel_min_samples=PARALLEL_MIN_SAMPLES)
    evaluator = GraspSafetyEvaluator(robot, config)
    args = (scenario.grasps, scenario.object_inertia, scenario.trajectory)
    corners = scenario.options.points_in_object_m
    parts = {
        "exposed_points": AnalysisOptions(
            points_in_object_m=corners, iso_regions=(), effort=False
        ),
        "iso_15066": AnalysisOptions(effort=False),
        "whole_arm_and_iso": AnalysisOptions(whole_arm=True, effort=False),
        "effort": AnalysisOptions(effort=True, iso_regions=()),
        "defaults": scenario.options,
        "defaults_without_effort": replace(scenario.options, effort=False),
        "defaults_and_whole_arm": replace(scenario.options, whole_arm=True),
    }
    clock = time.process_time if cpu else time.perf_counter

    def rank() -> Any:
        return evaluator.rank(*args, seed_positions=scenario.robot.seed)

    ranking = rank()
    for options in parts.values():  # warm: kernels loaded
        analyse(evaluator, *args, options, ranking=ranking)
    timings: dict[str, list[float]] = {name: [] for name in ("ranking", *parts)}
    for _ in range(repeats):
        start = clock()
        ranking = rank()
        timings["ranking"].append(clock() - start)
        for name, options in parts.items():
            start = clock()
            analyse(evaluator, *args, options, ranking=ranking)
            timings[name].append(clock() - start)
    seconds = {name: statistics.median(values) for name, values in timings.items()}
    return {
        "grasps": grasps,
        "workers": workers,
        "clock": "CPU" if cpu else "wall",
        "feasible": sum(e.feasible for e in ranking.evaluations),
        "seconds": seconds,
        "vs_ranking": {name: seconds[name] / seconds["ranking"] for name in parts},
    }


def print_parts(results: dict[str, Any]) -> None:
    seconds = results["seconds"]
    print(
        f"analyses alone, book on Baxter, {results['grasps']} grasps x 201 "
        f"({results['feasible']} feasible), {results['clock']} time, "
        f"{results.get('workers', 1)} worker(s); ranking "
        f"{1e3 * seconds['ranking']:.0f} ms"
    )
    for name, ratio in results["vs_ranking"].items():
        print(f"  {name}: {1e3 * seconds[name]:.0f} ms = x{ratio:.2f} the ranking")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grasps", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--cpu", action="store_true", help="CPU time of this process")
    parser.add_argument("--workers", type=int, default=1, help="2: the node's pool")
    args = parser.parse_args(argv)
    print_parts(bench_parts(args.grasps, args.repeats, args.cpu, args.workers))
    return 0


if __name__ == "__main__":
    sys.exit(main())
