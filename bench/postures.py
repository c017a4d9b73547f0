"""Benchmark section: cost and gain of posture selection (core.method.posture) per grasp.

For each arm workload (bench/workload.py: Panda and Baxter's right arm, a box, grasps around
it, 2 s at dt 0.01 s) and for the paper's book on Baxter (config/book_baxter.yaml), the
ranking is run with ``posture.restarts`` = 0 (the paper's single IK), 2, 4, 8, 16, 32, 64:

- ms per grasp of posture selection (the ``postures`` stage of ``core.pipeline``, after
  ``rank``; the single IK excluded), one core, median over repeats: wall-clock and CPU time
  of the process (the latter less inflated when other processes share the cores); its CPU
  time as a multiple of the ranking's (single IK, measured in the same run; issue 30's
  target: <= 2 at 8 restarts), with the default ``PostureConfig.early_stop``; at 8 restarts
  also without it (``early_stop=False``: every posture followed to the end, the same kept
  postures), and with ``restart_iterations`` = CAPPED_ITERATIONS, or
  ``restart_stall_iterations`` = STALL_ITERATIONS (changes of results: the grasps whose kept
  score or start posture changes are counted);
- the gain: mean over the grasps feasible with the single IK of 1 - score / score_single_ik
  [%], and grasps feasible with selection but not with the single IK.

Run alone: .venv/bin/python bench/run.py --postures-only [--json bench/results_postures.json],
or the smallest meaningful run: .venv/bin/python bench/postures.py --grasps 20 --restarts 0 8
"""

from __future__ import annotations

import argparse
import statistics
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from workload import ARMS, box_object, grasps_around_box

from grasp_safety_ros.core import EvaluationConfig, GraspSafetyEvaluator
from grasp_safety_ros.core.analyses.safety_report import AnalysisOptions
from grasp_safety_ros.core.method.posture import PostureConfig
from grasp_safety_ros.core.pipeline import PipelineRequest, run_pipeline
from grasp_safety_ros.paths import config_file
from grasp_safety_ros.scenario.schema import load_scenario

RESTARTS = (0, 2, 4, 8, 16, 32, 64)
CAPPED_ITERATIONS = 30
STALL_ITERATIONS = 10
VARIANTS = {
    "no_early_stop": {"early_stop": False},
    "capped": {"restart_iterations": CAPPED_ITERATIONS},
    "stall": {"restart_stall_iterations": STALL_ITERATIONS},
}


def _workloads(grasps: int) -> list[tuple[str, Any, Any, Any, Any, Any]]:
    """(name, evaluator, grasps, inertia, trajectory, seed) of each workload."""
    loads = []
    for name in ("panda", "baxter"):
        arm = ARMS[name]
        evaluator = GraspSafetyEvaluator(arm.robot(), EvaluationConfig(workers=1))
        candidates = grasps_around_box(np.array(arm.approach_from), grasps)
        loads.append(
            (
                f"{name} ({grasps} grasps)",
                evaluator,
                candidates,
                box_object(),
                arm.trajectory(2.0, 0.01),
                np.array(arm.seed_positions),
            )
        )
    book = load_scenario(config_file("book_baxter.yaml"))
    evaluator = GraspSafetyEvaluator(book.robot.load(book.base_dir), EvaluationConfig(workers=1))
    loads.append(
        (
            "baxter book (3 grasps)",
            evaluator,
            list(book.grasps),
            book.object_inertia,
            book.trajectory,
            book.robot.seed,
        )
    )
    return loads


def bench_postures(
    grasps: int = 20, repeats: int = 3, restart_counts: Sequence[int] = RESTARTS
) -> dict[str, Any]:
    """Cost [ms per grasp] and gain [%] of posture selection per restart count and workload."""
    results: dict[str, Any] = {}
    for name, evaluator, candidates, inertia, trajectory, seed in _workloads(grasps):
        # no analyses but the quality order
        request = PipelineRequest(
            tuple(candidates),
            inertia,
            trajectory,
            options=AnalysisOptions(iso_regions=(), effort=False),
            seed_positions=seed,
        )

        def run(config: PostureConfig, evaluator=evaluator, request=request) -> tuple[Any, Any]:
            """The ranking with ``config`` and the pipeline's stage times."""
            stages: dict[str, float] = {}
            report = run_pipeline(evaluator, replace(request, posture=config), timings=stages)
            return report.ranking, stages

        run(PostureConfig(restarts=0))  # warm: the ranking's kernels
        run(PostureConfig(restarts=8))  # and posture selection's (loaded on first use)
        ranking_cpu = [
            run(PostureConfig(restarts=0))[1]["rank_process_cpu"] for _ in range(repeats)
        ]
        ranking_ms = 1e3 * statistics.median(ranking_cpu) / len(candidates)
        rows = []
        for restarts in restart_counts:
            rows.append(
                _restart_row(run, restarts, repeats, len(candidates), ranking_cpu, ranking_ms)
            )
            _print_row(name, rows[-1], ranking_ms, len(candidates))
        results[name] = rows
    return results


def _restart_row(
    run: Callable[[PostureConfig], tuple[Any, Any]],
    restarts: int,
    repeats: int,
    grasps: int,
    ranking_cpu: list[float],
    ranking_ms: float,
) -> dict[str, Any]:
    """One restart count's figures (at 8 restarts also the VARIANTS' cost and changes)."""
    config = PostureConfig(restarts=restarts)
    times, cpu_times = [], []
    variant_cpu: dict[str, list[float]] = {name: [] for name in VARIANTS}
    variants: dict[str, Any] = {}
    for _ in range(repeats):
        selected, stages = run(config)
        times.append(stages["postures"])
        cpu_times.append(stages["postures_process_cpu"])
        if restarts == 8:
            for variant, changes in VARIANTS.items():
                variants[variant], stages = run(replace(config, **changes))
                variant_cpu[variant].append(stages["postures_process_cpu"])
    gains = [
        1.0 - p.score / p.score_single_ik
        for p in selected.postures
        if np.isfinite(p.score_single_ik)
    ]
    rescued = sum(
        1 for p in selected.postures if np.isfinite(p.score) and np.isnan(p.score_single_ik)
    )
    row = {
        "restarts": restarts,
        "ms_per_grasp": 1e3 * statistics.median(times) / grasps,
        "cpu_ms_per_grasp": 1e3 * statistics.median(cpu_times) / grasps,
        "ranking_cpu_ms_per_grasp": ranking_ms,
        "cpu_vs_ranking": statistics.median(cpu_times) / statistics.median(ranking_cpu),
        "mean_gain_percent": 100.0 * float(np.mean(gains)) if gains else None,
        "max_gain_percent": 100.0 * float(np.max(gains)) if gains else None,
        "feasible": sum(1 for e in selected.evaluations if e.feasible),
        "rescued_by_selection": rescued,
        "postures_tried_mean": float(np.mean([p.postures_tried for p in selected.postures])),
    }
    for variant, other in variants.items():  # at 8 restarts
        row[f"{variant}_cpu_vs_ranking"] = statistics.median(
            variant_cpu[variant]
        ) / statistics.median(ranking_cpu)
        row[f"{variant}_changed_grasps"] = sum(
            1
            for a, b in zip(selected.postures, other.postures, strict=True)
            if not np.array_equal([a.score], [b.score], equal_nan=True)
            or not np.array_equal(a.start_positions, b.start_positions)
        )
    return row


def _print_row(name: str, row: dict[str, Any], ranking_ms: float, grasps: int) -> None:
    """The progress line of one restart count."""
    print(
        f"[postures] {name}: restarts {row['restarts']:>2}: "
        f"{row['ms_per_grasp']:7.2f} ms/grasp "
        f"(CPU {row['cpu_ms_per_grasp']:7.2f} = x{row['cpu_vs_ranking']:.2f} "
        f"the ranking's {ranking_ms:.2f}), gain "
        f"{row['mean_gain_percent'] or 0.0:5.2f} % mean, "
        f"{row['max_gain_percent'] or 0.0:5.2f} % max, feasible "
        f"{row['feasible']}/{grasps}",
        flush=True,
    )


def print_postures(results: dict[str, Any]) -> None:
    """The table of ``bench_postures``."""
    print("\nposture selection: CPU ms per grasp (one core) / mean score gain vs the single IK")
    counts = [row["restarts"] for row in next(iter(results.values()))]
    header = f"{'workload':<24}" + "".join(f"{'r=' + str(r):>16}" for r in counts)
    print(header)
    for name, rows in results.items():
        cells = "".join(
            f"{row['cpu_ms_per_grasp']:>7.1f} / {row['mean_gain_percent'] or 0.0:>5.2f}%"
            for row in rows
        )
        print(f"{name:<24}{cells}")
    print("\nposture selection, 8 restarts: CPU time as a multiple of the ranking's (same run)")
    for name, rows in results.items():
        row = next((row for row in rows if row["restarts"] == 8), None)
        if row is not None:
            print(
                f"{name:<24} x{row['cpu_vs_ranking']:.2f}, without early_stop "
                f"x{row['no_early_stop_cpu_vs_ranking']:.2f} "
                f"({row['no_early_stop_changed_grasps']} changed: must be 0); restart_iterations "
                f"{CAPPED_ITERATIONS} x{row['capped_cpu_vs_ranking']:.2f} "
                f"({row['capped_changed_grasps']} grasps' kept score changed), or "
                f"restart_stall_iterations {STALL_ITERATIONS} x{row['stall_cpu_vs_ranking']:.2f} "
                f"({row['stall_changed_grasps']} changed)"
            )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grasps", type=int, default=20, help="grasps per arm workload")
    parser.add_argument("--repeats", type=int, default=3, help="runs per figure (median)")
    parser.add_argument(
        "--restarts", type=int, nargs="+", default=list(RESTARTS), help="restart counts"
    )
    args = parser.parse_args()
    print_postures(bench_postures(args.grasps, args.repeats, args.restarts))
