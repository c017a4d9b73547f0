"""Profile of bench/whole_arm.py's row: CPU time of each step of the whole arm on the shared
compiled terms, µs per (grasp, sample).

The workload of ``whole_arm.py`` (the default sites and the box's 8 corners on the tip's
link, the feasible grasps of one compiled ranking); each step is timed by a probe around it
(``time.process_time``) over ``--calls`` calls of ``grasps_terms`` then
``evaluate_whole_arm_on_terms``, after five warm-up calls, beside the compiled ranking of the
same candidates. "the rest" is the analysis' time outside the probed steps (its own array
work and Python).

Run alone: cd bench && ../.venv/bin/python whole_arm_steps.py [--arm panda] [--calls 100]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from typing import Any

from whole_arm import _prepare
from workload import ARMS

from grasp_safety_ros.core.analyses import whole_arm
from grasp_safety_ros.core.method.terms import grasps_terms

STEPS = (
    "joint_path_velocities",
    "tip_following_rates",
    "tip_twists_into",
    "arm_site_exposure",
    "site_mobilities",
    "_largest_mass_directions",
    "assess_sites_batch",
    "_whole_arm_result",
)
"""The functions ``evaluate_whole_arm_on_terms`` calls that are timed (module attributes)."""


def _probed(spent: dict[str, float], name: str, function: Callable[..., Any]) -> Callable:
    """``function`` adding its CPU time [s] to spent[name]."""

    def probe(*args: Any, **kwargs: Any) -> Any:
        start = time.process_time()
        result = function(*args, **kwargs)
        spent[name] += time.process_time() - start
        return result

    return probe


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arm", default="panda")
    parser.add_argument("--calls", type=int, default=100)
    args = parser.parse_args(argv)
    case = _prepare(ARMS[args.arm], 10)
    spent: dict[str, float] = defaultdict(float)
    for name in STEPS:
        setattr(whole_arm, name, _probed(spent, name, getattr(whole_arm, name)))
    grasps = [grasp for grasp, _ in case.pairs]
    evaluations = [evaluation for _, evaluation in case.pairs]

    def analysis() -> None:
        terms = _probed(spent, "terms", grasps_terms)(
            case.robot,
            case.evaluator.ik.chain,
            case.obj,
            [grasp.transform_tip_to_object for grasp in grasps],
            [evaluation.joint_positions for evaluation in evaluations],
            optional=whole_arm.WHOLE_ARM_TERMS,
        )
        _probed(spent, "analysis", whole_arm.evaluate_whole_arm_on_terms)(
            case.robot,
            evaluations,
            [case.trajectory] * len(grasps),
            grasps,
            case.sites,
            case.regions,
            *terms,
        )
        case.evaluator.rank(
            case.candidates, case.obj, case.trajectory, seed_positions=case.arm.seed_positions
        )

    ranking = _probed(spent, "ranking", analysis)
    for _ in range(5):
        ranking()
    spent.clear()
    for _ in range(args.calls):
        ranking()
    spent["ranking"] -= spent["terms"] + spent["analysis"]
    spent["the rest"] = spent["analysis"] - sum(spent[name] for name in STEPS)
    ranked = len(case.candidates) * case.trajectory.num_samples
    print(f"{args.arm}: {len(case.sites)} sites, {len(grasps)} grasps x 201, {args.calls} calls")
    for name, seconds in spent.items():
        count = ranked if name == "ranking" else case.samples
        print(f"{name:26s} {seconds / args.calls / count * 1e6:6.3f} us per (grasp, sample)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
