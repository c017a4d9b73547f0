#!/usr/bin/env python3
"""A client of the grasp_safety node in its own process, as a user's node: bench/service.py
drives it over stdin/stdout, one command per line, and it answers one JSON line per command.

Commands:
- ``rank GRASPS``: call ``~/rank_grasps`` with service.rank_request's GRASPS grasps; answers
  ``{"round_trip_s", "sent_s", "received_s", "compute_time_s", "grasps", "feasible_grasps",
  "joint_trajectories_sent", "response_bytes"}`` (the round trip from the call to the
  deserialised response; ``time.monotonic()`` at the call and once the response is there, a
  clock shared by the processes of the machine; the size of the serialised response, measured
  after the clock stopped);
- ``empty``: call ``~/get_parameters`` for one name: the floor of a round trip; answers
  ``{"round_trip_s"}``;
- ``quit``.

How the client waits for the answer (``--wait``):
- ``events``: rclpy's EventsExecutor (``rclpy.experimental``) and its
  ``spin_until_future_complete``; if this rclpy has none, ``spin_once`` below (the answer to
  the first command says which ran: ``"wait"``);
- ``spin_once``: SingleThreadedExecutor, ``while not future.done(): spin_once(timeout_sec=1)``;
- ``spin_until``: SingleThreadedExecutor ``spin_until_future_complete(future, timeout_sec)``:
  what the obvious client pays (on Jazzy's rclpy it wakes far later than the answer arrives).

Usage: service_client.py --wait events (ROS_DOMAIN_ID and discovery from the environment;
prints ``{"ready": true, "wait": ...}`` once the service is found).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

WAITS = ("events", "spin_once", "spin_until")
TIMEOUT_S = 120.0


def make_executor(wait: str, context: Any) -> tuple[Any, str]:
    """The executor for ``wait`` and the way of waiting that will run."""
    from rclpy.executors import SingleThreadedExecutor

    if wait == "events":
        try:
            from rclpy.experimental import EventsExecutor
        except ImportError:
            return SingleThreadedExecutor(context=context), "spin_once"
        return EventsExecutor(context=context), "events"
    return SingleThreadedExecutor(context=context), wait


def wait_for(executor: Any, future: Any, wait: str) -> Any:
    """Spin ``executor`` until ``future`` is done, the ``wait`` way; its result."""
    if wait == "spin_once":
        deadline = time.monotonic() + TIMEOUT_S
        while not future.done() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=1.0)
    else:
        executor.spin_until_future_complete(future, timeout_sec=TIMEOUT_S)
    if not future.done():
        raise RuntimeError(f"no answer within {TIMEOUT_S:g} s")
    return future.result()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--wait", choices=WAITS, default="events")
    args = parser.parse_args(argv)

    import rclpy
    from grasp_safety_msgs.srv import RankGrasps
    from rcl_interfaces.srv import GetParameters
    from rclpy.serialization import serialize_message
    from service import rank_request
    from workload import ARMS

    rclpy.init()
    node = rclpy.create_node("grasp_safety_bench_client")
    executor, wait = make_executor(args.wait, node.context)
    executor.add_node(node)
    rank = node.create_client(RankGrasps, "/grasp_safety/rank_grasps")
    get = node.create_client(GetParameters, "/grasp_safety/get_parameters")
    found = rank.wait_for_service(timeout_sec=30.0) and get.wait_for_service(timeout_sec=30.0)
    print(json.dumps({"ready": bool(found), "wait": wait}), flush=True)
    requests: dict[int, Any] = {}
    try:
        for line in sys.stdin:
            command = line.split()
            if not command or command[0] == "quit":
                break
            if command[0] == "empty":
                started = time.perf_counter()
                wait_for(executor, get.call_async(GetParameters.Request(names=["metric"])), wait)
                answer: dict[str, Any] = {"round_trip_s": time.perf_counter() - started}
            else:
                grasps = int(command[1])
                if grasps not in requests:
                    requests[grasps] = rank_request(ARMS["baxter"], grasps)
                sent_s, started = time.monotonic(), time.perf_counter()
                response = wait_for(executor, rank.call_async(requests[grasps]), wait)
                elapsed = time.perf_counter() - started
                received_s = time.monotonic()
                if not response.success:
                    raise RuntimeError(response.message)
                evaluations = response.ranking.evaluations
                answer = {
                    "round_trip_s": elapsed,
                    "sent_s": sent_s,
                    "received_s": received_s,
                    "compute_time_s": response.ranking.compute_time_s,
                    "grasps": len(evaluations),
                    "feasible_grasps": sum(1 for e in evaluations if e.feasible),
                    "joint_trajectories_sent": sum(
                        1 for e in evaluations if e.joint_trajectory.points
                    ),
                    "response_bytes": len(serialize_message(response)),
                }
            print(json.dumps(answer), flush=True)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
