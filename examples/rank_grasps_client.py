"""Call the grasp_safety node's ~/rank_grasps service with the paper's book scenario.

Start the node first (config/grasp_safety_node.yaml is the book on Baxter), then:
    .venv/bin/python examples/rank_grasps_client.py            # here (venv)
    python3 examples/rank_grasps_client.py                    # ROS install, workspace sourced
    .venv/bin/python examples/rank_grasps_client.py --quality 0.2 0.9 0.5 \
        --metric-point leading_point                          # with grasp quality
Exit status 0 when the node ranked the grasps, 1 otherwise.

Two habits of a robust client (docs/ros/reliability.md):
- ROS_PYTHON_CHECK_FIELDS=1, set below before any message module is imported: with it rclpy
  refuses an int in a float64 field at once (``Point(x=1)`` raises); without it, Jazzy's
  rclpy serialises that 1 as 5e-324 (and -1 as NaN), which the node refuses, naming the field.
- Re-send when no answer comes: right after ``wait_for_service`` the node may not have matched
  the client's response reader yet, and Fast DDS then drops the response (rmw_fastrtps#706).
  A ranking is a pure function of the request, so sending it again is safe.
The client waits with rclpy's EventsExecutor: on Jazzy's rclpy,
``rclpy.spin_until_future_complete`` returns milliseconds after the answer has arrived (see
docs/ros/client.md).
"""

from __future__ import annotations

import os

os.environ.setdefault("ROS_PYTHON_CHECK_FIELDS", "1")  # before the message modules are imported

import argparse
import math
import sys
import time

import rclpy
import rclpy.executors
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseArray, PoseStamped, Quaternion
from grasp_safety_msgs.srv import RankGrasps
from nav_msgs.msg import Path
from std_msgs.msg import Header

try:
    from rclpy.experimental import EventsExecutor
except ImportError:  # an rclpy without it
    EventsExecutor = None

SERVICE = "/grasp_safety/rank_grasps"
ATTEMPTS = 3


def wait_for(node: rclpy.node.Node, future: rclpy.task.Future, timeout_s: float) -> None:
    """Spin ``node`` until ``future`` is done or ``timeout_s`` has passed.

    rclpy's EventsExecutor wakes as soon as the answer arrives; an rclpy without it gets
    the same from a SingleThreadedExecutor's spin_once in a loop.
    """
    if EventsExecutor is not None:
        executor = EventsExecutor(context=node.context)
        executor.add_node(node)
        executor.spin_until_future_complete(future, timeout_sec=timeout_s)
    else:
        executor = rclpy.executors.SingleThreadedExecutor(context=node.context)
        executor.add_node(node)
        deadline = time.monotonic() + timeout_s
        while not future.done() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=1.0)
    executor.shutdown()


def call(
    node: rclpy.node.Node,
    client: rclpy.client.Client,
    request: RankGrasps.Request,
    timeout_s: float,
) -> RankGrasps.Response | None:
    """Send ``request`` and wait up to ``timeout_s`` for the answer; re-send (at most ATTEMPTS
    times in all) when none comes: a response the middleware dropped is not lost for good."""
    for _ in range(ATTEMPTS):
        future = client.call_async(request)
        wait_for(node, future, timeout_s)
        if future.done():
            return future.result()
        client.remove_pending_request(future)
    return None


def pose(position_m: tuple[float, float, float], quat_xyzw: tuple[float, ...]) -> Pose:
    """A Pose from a position [m] and a quaternion in ROS order (x, y, z, w)."""
    x, y, z = (float(v) for v in position_m)
    qx, qy, qz, qw = (float(v) for v in quat_xyzw)
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def book_request() -> RankGrasps.Request:
    """Three grasps on the book's spine; the object moves for 2 s; the node's default object."""
    request = RankGrasps.Request()
    # Tip poses in the object frame (frame_id = the node's object_frame parameter).
    request.grasps = PoseArray(
        header=Header(frame_id="object"),
        poses=[pose((-0.075, y, 0.0), (0.0, 0.0, 0.0, 1.0)) for y in (-0.1, 0.0, 0.1)],
    )
    # Object start and goal in the base frame; the duration is the stamp difference.
    request.object_trajectory = Path(
        header=Header(frame_id="base"),
        poses=[
            PoseStamped(header=Header(stamp=Time(sec=0)), pose=pose((1.0, 0.0, 0.03), (0.5,) * 4)),
            PoseStamped(
                header=Header(stamp=Time(sec=2)), pose=pose((1.1, -0.38, 0.16), (0.5,) * 4)
            ),
        ],
    )
    # request.object_inertia.m == 0: use the node's object.* parameters. metric "": its default.
    return request


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quality", type=float, nargs=3, help="grasp quality of the 3 grasps")
    parser.add_argument("--metric-point", default="", help="tip | leading_point | worst_point")
    parser.add_argument(
        "--timeout", type=float, default=60.0, help="wait per attempt for the answer [s]"
    )
    options, ros_args = parser.parse_known_args(argv)
    request = book_request()
    request.grasp_quality = [float(q) for q in options.quality or []]
    request.metric_point = options.metric_point
    rclpy.init(args=ros_args)
    node = rclpy.create_node("rank_grasps_example")
    try:
        client = node.create_client(RankGrasps, SERVICE)
        if not client.wait_for_service(timeout_sec=10.0):
            print(f"no service {SERVICE}: is the node running (same ROS_DOMAIN_ID)?")
            return 1
        response = call(node, client, request, options.timeout)
        if response is None:
            print(f"no answer to {ATTEMPTS} requests within {options.timeout:g} s each")
            return 1
        if not response.success:
            print(f"refused: {response.message}")
            return 1
        ranking = response.ranking
        print(
            f"metric {ranking.metric}, metric point {ranking.metric_point}, rank by "
            f"{ranking.rank_by}, computed in {ranking.compute_time_s:.3f} s"
        )
        print("rank  index  score      peak [kg]  samples  safety     ISO/TS 15066   quality")
        for rank, index in enumerate(ranking.order, start=1):
            e = ranking.evaluations[index]
            iso = f"ok, T>={e.iso_min_duration_s:.2f}s" if e.iso_admissible else "not admissible"
            quality = "" if math.isnan(e.grasp_quality) else f"{e.grasp_quality:g}"
            quality += " pareto" if e.pareto_optimal else ""
            print(
                f"{rank:>4}  {index:>5}  {e.score:<9.4f}  {e.peak_effective_mass_kg:<9.4f}  "
                f"{len(e.effective_mass_kg):<7}  {e.safety_score:<9.4f}  {iso:<13}  {quality}"
            )
        for e in ranking.evaluations:
            if not e.feasible:
                print(f"   -  {e.index:>5}  infeasible: {e.reason}")
        return 0
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
