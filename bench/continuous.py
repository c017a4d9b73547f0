"""bench/run.py's section on a chain with continuous joints ((cos, sin) in q): the compiled
path's time per (grasp, sample) and its identity with the Python backend."""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np
from _common import python_backend_agreement, summary, timed
from workload import ArmWorkload, box_object, grasps_around_box

from grasp_safety_ros.core import GraspSafetyEvaluator
from grasp_safety_ros.core.method.ranking import EvaluationConfig, Ranking


def bench_continuous(arm: ArmWorkload, repeats: int) -> dict[str, Any]:
    """The compiled path on a chain with continuous joints ((cos, sin) in q): µs per (grasp,
    sample) with IK, serial, as for the revolute arms; compiled vs Python identity."""
    robot = arm.robot()
    trajectory = arm.trajectory(2.0, 0.01)
    obj = box_object()
    grasps = grasps_around_box(np.array(arm.approach_from), 100)
    seed = np.array(arm.seed_positions)
    serial = GraspSafetyEvaluator(robot, EvaluationConfig(workers=1))
    fallback = GraspSafetyEvaluator(robot, EvaluationConfig(backend="python", workers=1))

    def rank(evaluator: GraspSafetyEvaluator) -> Ranking:
        return evaluator.rank(grasps, obj, trajectory, seed_positions=seed)

    print(f"[{arm.name}] continuous joints: warm-up, then {repeats} repeats", file=sys.stderr)
    ranking = rank(serial)
    total = len(grasps) * trajectory.num_samples
    wall, cpu = [], []
    for _ in range(repeats):
        cpu_start = time.process_time()
        wall.append(timed(lambda: rank(serial))[0])
        cpu.append(time.process_time() - cpu_start)
    python_s, python = timed(lambda: rank(fallback))
    pairs = list(zip(python.evaluations, ranking.evaluations, strict=True))
    model = robot.model
    return {
        "robot": f"{arm.urdf} {arm.base_frame} -> {arm.tip_frame}",
        "continuous_joints": [
            name
            for name, joint in zip(robot.joint_names, list(model.joints)[1:], strict=True)
            if joint.nq == 2
        ],
        "nq_nv": [model.nq, model.nv],
        "backend": "compiled" if serial.ik.compiled else "python",
        "grasps": len(grasps),
        "samples_per_grasp": trajectory.num_samples,
        "feasible_grasps": sum(e.feasible for e in ranking.evaluations),
        "us_per_sample_with_ik": summary([t / total * 1e6 for t in wall]),
        "cpu_us_per_sample_with_ik": summary([t / total * 1e6 for t in cpu]),
        "python_backend_us_per_sample_with_ik": python_s / total * 1e6,
        **python_backend_agreement(pairs),
    }
