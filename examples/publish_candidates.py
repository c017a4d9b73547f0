"""Feed the grasp_safety node through its topics, as a grasp planner would.

Publishes the book's trajectory on ~/object_trajectory and its three spine grasps on
~/candidate_grasps; the node ranks them and publishes ~/ranked_grasps, ~/ranking, ~/markers.
Watch with examples/echo_ranking.py (or `ros2 topic echo /grasp_safety/ranking`).

    .venv/bin/python examples/publish_candidates.py
"""

from __future__ import annotations

import sys
import time

import rclpy
from geometry_msgs.msg import PoseArray
from nav_msgs.msg import Path
from rank_grasps_client import book_request


def main(args: list[str] | None = None) -> int:
    rclpy.init(args=args)
    node = rclpy.create_node("publish_candidates_example")
    try:
        trajectory_pub = node.create_publisher(Path, "/grasp_safety/object_trajectory", 10)
        grasps_pub = node.create_publisher(PoseArray, "/grasp_safety/candidate_grasps", 10)
        deadline = time.monotonic() + 10.0
        while (
            min(trajectory_pub.get_subscription_count(), grasps_pub.get_subscription_count()) < 1
        ):
            if time.monotonic() > deadline:
                print("the node does not subscribe: is it running (same ROS_DOMAIN_ID)?")
                return 1
            rclpy.spin_once(node, timeout_sec=0.1)
        time.sleep(0.5)  # let the node's side of the discovery complete too
        request = book_request()
        trajectory_pub.publish(request.object_trajectory)  # first the trajectory ...
        grasps_pub.publish(request.grasps)  # ... then each new candidate set is ranked
        time.sleep(0.5)  # let the middleware deliver before the publishers go away
        print("published 1 trajectory and 3 candidate grasps")
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
