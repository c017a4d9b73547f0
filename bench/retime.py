"""Benchmark: safe retiming (core.analyses.retime) per grasp, and the cycle time it saves.

1. Cost per grasp on the Panda (bench/workload.py: a 0.8 kg box, 2 s quintic, dt 0.01 s: 201
   samples), feasible grasps of one compiled ranking: ``retime_path`` with the whole arm's
   default sites plus the box's 8 corners (every permitted ISO/TS 15066 region) beside
   toppra's own joint-limits-only parameterisation of the same path in the same run (what a
   user has today), CPU time of the process, median and max over grasps [ms]. Franka's
   published joint acceleration limits (15, 7.5, 10, 12.5, 15, 20, 20 rad/s²), the URDF's
   velocity limits, safety factor 1. Also the largest constraint ratio (value / limit) of the
   retimed motions re-evaluated every FINE_DT_S, between the grid points.
2. Cycle time against uniform scaling on the bundled scenarios (config/book_baxter*.yaml, whole
   arm on, every grasp, acceleration limits 4 rad/s² per joint, an assumption: Baxter
   publishes none): per grasp 1 − safe_duration / T_uniform (T_uniform: the whole motion
   slowed uniformly until every site and joint is within its limit), median and range.

Run alone: .venv/bin/python bench/retime.py [--grasps 10] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from typing import Any

import numpy as np
import yaml
from workload import ARMS, BOX_SIZE_M, box_object, grasps_around_box

from grasp_safety_ros.core import EvaluationConfig, GraspSafetyEvaluator
from grasp_safety_ros.core.analyses.arm_sites import resolve_arm_sites
from grasp_safety_ros.core.analyses.exposed_points import box_corners_in_object
from grasp_safety_ros.core.analyses.retime import RetimeLimits, retime_path
from grasp_safety_ros.core.analyses.site_speeds import SiteSpeedModel
from grasp_safety_ros.paths import config_file

PANDA_ACCELERATIONS = [15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0]
"""Franka Emika Panda's published joint acceleration limits [rad/s²]."""

BAXTER_ACCELERATION = 4.0
"""Assumed joint acceleration limit of Baxter [rad/s²] (none published)."""

FINE_DT_S = 0.001
"""Output step [s] at which the limits are re-evaluated between the grid points."""

SCENARIOS = ("book_baxter.yaml", "book_baxter_extended.yaml", "book_baxter_waypoints.yaml")


def _cpu_ms(function) -> tuple[Any, float]:
    start = time.process_time()
    result = function()
    return result, 1e3 * (time.process_time() - start)


def bench_cost(grasps: int) -> dict[str, Any]:
    """Retiming cost per grasp on the Panda, with and without the site limits."""
    arm = ARMS["panda"]
    robot = arm.robot()
    inertia = box_object()

    corners = box_corners_in_object(BOX_SIZE_M)
    candidates = grasps_around_box(np.array(arm.approach_from), grasps)
    trajectory = arm.trajectory(2.0, 0.01)
    evaluator = GraspSafetyEvaluator(robot, EvaluationConfig(metric="mean"))
    ranking = evaluator.rank(candidates, inertia, trajectory, seed_positions=arm.seed_positions)
    limits = RetimeLimits.from_input(robot, PANDA_ACCELERATIONS)
    sites = resolve_arm_sites(robot)
    safe_ms, joint_ms, rows, between = [], [], [], []
    warm = next(e for e in ranking.evaluations if e.feasible)  # imports toppra once
    retime_path(robot, None, limits, warm.times_s, warm.joint_positions)
    for grasp, evaluation in zip(candidates, ranking.evaluations, strict=True):
        if not evaluation.feasible:
            continue
        times, path = evaluation.times_s, evaluation.joint_positions
        model, build_ms = _cpu_ms(
            lambda g=grasp: SiteSpeedModel.build(
                robot, inertia, g.transform_tip_to_object, sites, corners
            )
        )
        safe, ms = _cpu_ms(lambda m=model, t=times, p=path: retime_path(robot, m, limits, t, p))
        safe_ms.append(ms + build_ms)
        joint, ms = _cpu_ms(lambda t=times, p=path: retime_path(robot, None, limits, t, p))
        joint_ms.append(ms)
        fine = retime_path(robot, model, limits, times, path, output_dt_s=FINE_DT_S)
        between.append(float(fine.binding_ratio.max()))
        rows.append(
            (safe.safe_duration_s, joint.safe_duration_s, safe.uniform_feasible_duration_s)
        )
    return {
        "arm": "panda",
        "samples": len(trajectory.times_s()),
        "sites": len(sites) + len(corners),
        "grasps_retimed": len(rows),
        "safe_ms_median": statistics.median(safe_ms),
        "safe_ms_max": max(safe_ms),
        "joint_limits_only_ms_median": statistics.median(joint_ms),
        "joint_limits_only_ms_max": max(joint_ms),
        "max_ratio_at_fine_dt": max(between),
        "safe_duration_s_median": statistics.median(r[0] for r in rows),
        "joint_limits_only_duration_s_median": statistics.median(r[1] for r in rows),
        "uniform_feasible_duration_s_median": statistics.median(r[2] for r in rows),
    }


def bench_scenarios() -> dict[str, Any]:
    """Cycle time saved against uniform scaling on the bundled scenarios."""
    from grasp_safety_ros.cli.main import rank_scenario
    from grasp_safety_ros.scenario.schema import parse_scenario

    gains, per_scenario = [], {}
    for name in SCENARIOS:
        path = config_file(name)
        data = yaml.safe_load(path.read_text())
        data["whole_arm"] = {"enabled": True}
        data["retime"] = {"joint_acceleration_limits": [BAXTER_ACCELERATION] * 7}
        report = rank_scenario(parse_scenario(data, path.parent))
        saved = [
            1.0 - m.safe_duration_s / m.uniform_feasible_duration_s
            for m in report.retimed
            if m is not None
        ]
        per_scenario[name] = [round(s, 4) for s in saved]
        gains += saved
    return {
        "grasps": len(gains),
        "saved_vs_uniform_median": statistics.median(gains),
        "saved_vs_uniform_min": min(gains),
        "saved_vs_uniform_max": max(gains),
        "per_scenario": per_scenario,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grasps", type=int, default=10, help="Panda candidates (default 10)")
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args(argv)
    results = {"cost": bench_cost(args.grasps), "scenarios": bench_scenarios()}
    text = json.dumps(results, indent=2)
    print(text)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as file:
            file.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
