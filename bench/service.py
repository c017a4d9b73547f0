#!/usr/bin/env python3
"""Service cost of the grasp_safety node (issue 12): latency, where it goes, large requests.

Baxter's right arm (example-robot-data), the benchmark box, grasps around it, a 2 s quintic
trajectory; the node runs in-process (rclpy, MultiThreadedExecutor thread) and a client node
in the same context calls ``~/rank_grasps``:

- latency, 10 grasps x 101 samples (dt 0.02 s): median and p90 of the round trip; interleaved
  with each call, the ranking's own time (``GraspSafetyEvaluator.rank`` of the node's
  evaluator on the same inputs, in this thread) and the spans of the node's work done by hand
  (request conversion, ranking, analyses, response message, markers, serialisation); the rest
  of the round trip is the executor, the middleware and the client's deserialisation;
- end to end, 1,000 grasps x 201 samples (dt 0.01 s): wall time of the call and the
  response's size in bytes (serialised GraspRanking response).

Usage: .venv/bin/python bench/service.py [--repeats 30] [--large-repeats 3] [--json OUT]
(not a test; also run by bench/run.py). Figures are wall-clock: other processes on the cores
inflate them (the load average is recorded).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np
from workload import ARMS, ArmWorkload, box_object, grasps_around_box

SPANS = ("convert", "rank", "analyse", "response", "markers", "serialise")


def summary_ms(values_s: Sequence[float]) -> dict[str, float]:
    """Median, p90, min and max of durations given in seconds, in milliseconds."""
    values = np.asarray(values_s, dtype=float) * 1e3
    return {
        "median": float(np.median(values)),
        "p90": float(np.percentile(values, 90)),
        "min": float(values.min()),
        "max": float(values.max()),
    }


@contextmanager
def running_node(arm: ArmWorkload, dt_s: float) -> Iterator[tuple[Any, Any, Any, Any]]:
    """The node for ``arm`` spinning in a thread; yields (node, client_node, executor, client)."""
    import rclpy
    from grasp_safety_msgs.srv import RankGrasps
    from rclpy.context import Context
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from grasp_safety_ros.ros.node import EXECUTOR_THREADS, GraspSafetyNode

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    context = Context()
    rclpy.init(context=context, domain_id=random.SystemRandom().randint(0, 101))
    parameters = {
        "urdf": arm.urdf,
        "base_frame": arm.base_frame,
        "tip_frame": arm.tip_frame,
        "ik_seed": [float(x) for x in arm.seed_positions],
        "use_joint_states_seed": False,
        "trajectory.dt_s": dt_s,
        "diagnostics_period_s": 5.0,
    }
    node = GraspSafetyNode(
        context=context,
        parameter_overrides=[Parameter(k, value=v) for k, v in parameters.items()],
    )
    executor = MultiThreadedExecutor(num_threads=EXECUTOR_THREADS, context=context)
    executor.add_node(node)
    thread = threading.Thread(target=executor.spin, daemon=True)
    thread.start()
    client_node = rclpy.create_node("grasp_safety_bench_client", context=context)
    client_executor = SingleThreadedExecutor(context=context)
    client_executor.add_node(client_node)
    client = client_node.create_client(RankGrasps, "/grasp_safety/rank_grasps")
    try:
        if not client.wait_for_service(timeout_sec=20.0):
            raise RuntimeError("service /grasp_safety/rank_grasps not found")
        yield node, client_node, client_executor, client
    finally:
        executor.shutdown()
        node.destroy_node()
        client_node.destroy_node()
        rclpy.shutdown(context=context)
        thread.join(timeout=5.0)


def rank_request(arm: ArmWorkload, num_grasps: int) -> Any:
    """RankGrasps request: ``num_grasps`` grasps around the box, the arm's 2 s trajectory."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import PoseArray, PoseStamped
    from grasp_safety_msgs.srv import RankGrasps
    from nav_msgs.msg import Path as PathMsg
    from std_msgs.msg import Header

    from grasp_safety_ros.ros.conversions import inertia_msg_from_object, pose_msg_from_transform

    trajectory = arm.trajectory(2.0, 0.02)
    grasps = grasps_around_box(np.array(arm.approach_from), num_grasps)
    request = RankGrasps.Request()
    request.grasps = PoseArray(
        header=Header(frame_id="object"),
        poses=[pose_msg_from_transform(g.transform_tip_to_object) for g in grasps],
    )
    ends = (trajectory.transform_object_to_base_start, trajectory.transform_object_to_base_goal)
    request.object_trajectory = PathMsg(
        header=Header(frame_id=arm.base_frame),
        poses=[
            PoseStamped(header=Header(stamp=stamp), pose=pose_msg_from_transform(pose))
            for stamp, pose in zip((Time(sec=0), Time(sec=2)), ends, strict=True)
        ],
    )
    request.object_inertia = inertia_msg_from_object(box_object())
    request.metric = "mean"
    return request


def call(client_executor: Any, client: Any, request: Any, timeout_s: float = 60.0) -> Any:
    """Call the service; return the response (raise when it fails)."""
    future = client.call_async(request)
    client_executor.spin_until_future_complete(future, timeout_sec=timeout_s)
    response = future.result()
    if response is None or not response.success:
        raise RuntimeError("no answer" if response is None else response.message)
    return response


def node_spans(node: Any, request: Any) -> dict[str, float]:
    """Durations [s] of the node's steps for ``request``, done by hand with its functions.

    ``<step>`` is the wall-clock time, ``<step>_cpu`` the CPU time of this thread (less
    affected by other processes; the ranking's pool threads are not counted in it).
    """
    from rclpy.serialization import serialize_message

    from grasp_safety_ros.core.analyses.safety_report import analyse
    from grasp_safety_ros.ros import conversions

    spans: dict[str, float] = {}
    settings = node._snapshot().settings
    bundle = node._snapshot().bundle

    def span(name: str, function: Callable[[], Any]) -> Any:
        started, started_cpu = time.perf_counter(), time.thread_time()
        result = function()
        spans[name] = time.perf_counter() - started
        spans[f"{name}_cpu"] = time.thread_time() - started_cpu
        return result

    def convert() -> tuple[Any, Any, Any]:
        trajectory = conversions.trajectory_from_path(
            request.object_trajectory,
            settings.base_frame,
            settings.trajectory_dt_s,
            settings.trajectory_duration_s,
            settings.max_samples,
        )
        grasps = conversions.grasps_from_pose_array(
            request.grasps,
            settings.object_frame,
            settings.base_frame,
            trajectory,
            settings.max_grasps,
        )
        inertia = conversions.object_inertia_from_msg(request.object_inertia, settings.max_mass_kg)
        return trajectory, grasps, inertia

    trajectory, grasps, inertia = span("convert", convert)
    evaluator = bundle.evaluator
    ranking = span(
        "rank", lambda: evaluator.rank(grasps, inertia, trajectory, bundle.seed, "mean")
    )
    report = span(
        "analyse",
        lambda: analyse(
            evaluator, grasps, inertia, trajectory, settings.analysis, ranking=ranking
        ),
    )
    stamp = node.get_clock().now().to_msg()
    message = span(
        "response",
        lambda: conversions.report_msg(report, request.grasps, settings.base_frame, stamp, 0.0),
    )
    span(
        "markers",
        lambda: conversions.markers_msg(
            ranking, grasps, trajectory, settings.base_frame, stamp, order=report.order
        ),
    )
    span("serialise", lambda: serialize_message(message))
    return spans


def latency(arm: ArmWorkload, repeats: int) -> dict[str, Any]:
    """Round trip of 10 grasps x 101 samples, the ranking's own time and the node's spans.

    Also the round trip of an empty request to the same node (GetParameters of one name):
    the floor set by the executor and the middleware.
    """
    from rcl_interfaces.srv import GetParameters

    request = rank_request(arm, 10)
    with running_node(arm, 0.02) as (node, client_node, client_executor, client):
        get = client_node.create_client(GetParameters, "/grasp_safety/get_parameters")
        get.wait_for_service(timeout_sec=20.0)
        round_trips, computes, empty = [], [], []
        spans: dict[str, list[float]] = {}
        for k in range(repeats + 3):
            started = time.perf_counter()
            response = call(client_executor, client, request)
            elapsed = time.perf_counter() - started
            steps = node_spans(node, request)
            started = time.perf_counter()
            future = get.call_async(GetParameters.Request(names=["metric"]))
            client_executor.spin_until_future_complete(future, timeout_sec=30.0)
            empty_elapsed = time.perf_counter() - started
            if k >= 3:  # the first calls warm caches up
                round_trips.append(elapsed)
                empty.append(empty_elapsed)
                computes.append(response.ranking.compute_time_s)
                for name, value in steps.items():
                    spans.setdefault(name, []).append(value)
        evaluations = response.ranking.evaluations
    result = {
        "robot": arm.name,
        "grasps": len(evaluations),
        "samples_per_grasp": len(evaluations[0].time_from_start_s),
        "feasible_grasps": sum(1 for e in evaluations if e.feasible),
        "repeats": repeats,
        "latency_ms": summary_ms(round_trips),
        "ranking_ms": summary_ms(spans["rank"]),
        "node_compute_ms": summary_ms(computes),
        "empty_request_ms": summary_ms(empty),
        "spans_ms": {name: summary_ms(spans[name])["median"] for name in SPANS},
        "spans_cpu_ms": {name: summary_ms(spans[f"{name}_cpu"])["median"] for name in SPANS},
    }
    result["median_ms"] = result["latency_ms"]["median"]
    result["latency_over_ranking"] = result["median_ms"] / result["ranking_ms"]["median"]
    result["spans_ms"]["rest (executor, middleware, client)"] = result["median_ms"] - sum(
        result["spans_ms"].values()
    )
    return result


def large(arm: ArmWorkload, repeats: int) -> dict[str, Any]:
    """End to end: 1,000 grasps x 201 samples through the service; the response's size."""
    from rclpy.serialization import serialize_message

    request = rank_request(arm, 1000)
    with running_node(arm, 0.01) as (node, _, client_executor, client):
        call(client_executor, client, rank_request(arm, 10))  # warm-up
        walls, computes = [], []
        for _ in range(repeats):
            started = time.perf_counter()
            response = call(client_executor, client, request)
            walls.append(time.perf_counter() - started)
            computes.append(response.ranking.compute_time_s)
        evaluations = response.ranking.evaluations
        spans = node_spans(node, request)
    return {
        "robot": arm.name,
        "grasps": len(evaluations),
        "samples_per_grasp": max(len(e.time_from_start_s) for e in evaluations),
        "feasible_grasps": sum(1 for e in evaluations if e.feasible),
        "repeats": repeats,
        "wall_s": summary_ms(walls)["median"] / 1e3,
        "wall_ms": summary_ms(walls),
        "node_compute_ms": summary_ms(computes),
        "response_bytes": len(serialize_message(response)),
        "spans_ms": {name: 1e3 * spans[name] for name in SPANS},
        "spans_cpu_ms": {name: 1e3 * spans[f"{name}_cpu"] for name in SPANS},
    }


def run(repeats: int, large_repeats: int) -> dict[str, Any]:
    """Both measurements on Baxter, with the load average around them."""
    load_before = os.getloadavg()[0]
    arm = ARMS["baxter"]
    results = {"latency_10x101": latency(arm, repeats)}
    if large_repeats > 0:
        results["end_to_end_1000x201"] = large(arm, large_repeats)
    results["load_average_1min"] = [load_before, os.getloadavg()[0]]
    return results


def print_results(results: dict[str, Any]) -> None:
    def spans(values: dict[str, float]) -> str:
        return ", ".join(f"{k} {v:.2f}" for k, v in values.items())

    small = results["latency_10x101"]
    lat, rank = small["latency_ms"], small["ranking_ms"]
    print(
        f"service latency 10 x 101 (Baxter): median {lat['median']:.2f} ms, p90 "
        f"{lat['p90']:.2f} ms [{lat['min']:.2f}..{lat['max']:.2f}]; ranking alone "
        f"{rank['median']:.2f} ms (latency / ranking = {small['latency_over_ranking']:.2f})"
    )
    print(f"  spans (median ms): {spans(small['spans_ms'])}")
    print(f"  spans (median CPU ms of the calling thread): {spans(small['spans_cpu_ms'])}")
    print(f"  empty request (GetParameters): {small['empty_request_ms']['median']:.2f} ms")
    big = results.get("end_to_end_1000x201")
    if big:
        print(
            f"service end to end {big['grasps']} x {big['samples_per_grasp']} (Baxter): "
            f"{big['wall_s']:.3f} s (node compute {big['node_compute_ms']['median']:.0f} ms), "
            f"response {big['response_bytes']} bytes ({big['response_bytes'] / 1e6:.1f} MB)"
        )
        print(f"  spans (ms): {spans(big['spans_ms'])}")
        print(f"  spans (CPU ms): {spans(big['spans_cpu_ms'])}")
    print(f"load average (1 min) before/after: {results['load_average_1min']}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--large-repeats", type=int, default=3)
    parser.add_argument("--json", type=Path, help="write the results as JSON here")
    args = parser.parse_args(argv)
    results = run(args.repeats, args.large_repeats)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    print_results(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
