"""Print every ranking the grasp_safety node publishes on ~/ranking (a small `ros2 topic echo`).

    .venv/bin/python examples/echo_ranking.py             # until Ctrl-C
    .venv/bin/python examples/echo_ranking.py --count 1   # the latest ranking, then exit

The topic is transient-local, so the last ranking arrives at once if there is one. With
--count N the script exits 0 after N rankings, or 1 if none arrived within --timeout seconds.
"""

from __future__ import annotations

import argparse
import sys
import time

import rclpy
from grasp_safety_msgs.msg import GraspRanking
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

TOPIC = "/grasp_safety/ranking"
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)


def describe(ranking: GraspRanking) -> str:
    """A few lines per ranking: the order with scores, then the infeasible candidates."""
    stamp = ranking.header.stamp.sec + 1e-9 * ranking.header.stamp.nanosec
    lines = [
        f"ranking at {stamp:.3f} ({ranking.header.frame_id}), metric {ranking.metric}, "
        f"{len(ranking.evaluations)} candidates, {ranking.compute_time_s:.3f} s"
    ]
    for rank, index in enumerate(ranking.order, start=1):
        e = ranking.evaluations[index]
        iso = "" if e.iso_admissible or not e.iso_ts_15066 else ", ISO/TS 15066: not admissible"
        lines.append(
            f"  #{rank} candidate {index}: score {e.score:.4f}, "
            f"peak {e.peak_effective_mass_kg:.4f} kg over {len(e.effective_mass_kg)} samples{iso}"
        )
    if ranking.uncertainty_message:
        lines.append(f"  inertia uncertainty: {ranking.uncertainty_message}")
    lines += [f"  candidate {e.index}: infeasible ({e.reason})" for e in ranking.evaluations
              if not e.feasible]  # fmt: skip
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=0, help="exit after N rankings (0: never)")
    parser.add_argument("--timeout", type=float, default=30.0, help="[s], with --count")
    options, ros_args = parser.parse_known_args(argv)
    rclpy.init(args=ros_args)
    node = rclpy.create_node("echo_ranking_example")
    received: list[GraspRanking] = []

    def on_ranking(msg: GraspRanking) -> None:
        received.append(msg)
        print(describe(msg), flush=True)

    node.create_subscription(GraspRanking, TOPIC, on_ranking, LATCHED)
    deadline = time.monotonic() + options.timeout
    try:
        while rclpy.ok():
            if options.count and len(received) >= options.count:
                return 0
            if options.count and time.monotonic() > deadline:
                print(f"no ranking on {TOPIC} within {options.timeout:g} s", file=sys.stderr)
                return 1
            rclpy.spin_once(node, timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
