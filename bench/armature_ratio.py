"""Effective mass with reflected rotor inertia (armature) over the links' only, on the Panda.

The bundled Panda (example-robot-data, panda_link0 -> panda_hand, no object) with the FR3
armature of data/armature_published.yaml (0.195 kg m^2 on joints 1-4, 0.074 on 5-7), at
200 configurations drawn uniformly within the joint limits and 200 uniformly random unit
directions (seed 0): effective mass at the panda_hand origin along the direction, with and
without the armature. Prints the medians and the ratio's median, p10, p90 and max.

Run: .venv/bin/python bench/armature_ratio.py [--samples N] [--seed S]
"""

from __future__ import annotations

import argparse

import numpy as np

from grasp_safety_ros.core import RobotModel
from grasp_safety_ros.core.method.effective_mass import (
    effective_mass_along,
    translational_mobility_in_base,
)
from grasp_safety_ros.core.model.armature import published_armatures, published_values


def measure(samples: int, seed: int) -> dict[str, float]:
    """Medians [kg] and the ratio's percentiles over ``samples`` configurations."""
    links = RobotModel.from_urdf("example-robot-data:panda", "panda_link0", "panda_hand")
    entry = published_armatures()["franka_fr3"]
    geared = links.with_armature(published_values(entry, links.joint_names))
    rng = np.random.default_rng(seed)
    with_armature, links_only = np.empty(samples), np.empty(samples)
    for i in range(samples):
        q = links.q_from_positions(rng.uniform(links.lower_limits, links.upper_limits))
        direction = rng.normal(size=3)
        for robot, out in ((geared, with_armature), (links, links_only)):
            mobility = translational_mobility_in_base(
                robot, robot.model, robot.model.createData(), q
            )
            out[i] = effective_mass_along(mobility, direction)
    ratio = with_armature / links_only
    p10, median, p90 = np.percentile(ratio, [10, 50, 90])
    return {
        "links_only_median_kg": float(np.median(links_only)),
        "with_armature_median_kg": float(np.median(with_armature)),
        "ratio_median": float(median),
        "ratio_p10": float(p10),
        "ratio_p90": float(p90),
        "ratio_max": float(ratio.max()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    result = measure(args.samples, args.seed)
    print(
        f"Panda (panda_hand), FR3 armature, {args.samples} random configurations and "
        f"directions (seed {args.seed}):\n"
        f"  effective mass median: links only {result['links_only_median_kg']:.2f} kg, "
        f"with armature {result['with_armature_median_kg']:.2f} kg\n"
        f"  ratio with / links only: median x{result['ratio_median']:.2f}, "
        f"p10 x{result['ratio_p10']:.2f}, p90 x{result['ratio_p90']:.2f}, "
        f"max x{result['ratio_max']:.2f}"
    )


if __name__ == "__main__":
    main()
