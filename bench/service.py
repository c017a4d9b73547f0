#!/usr/bin/env python3
"""Service cost of the grasp_safety node (issue 12): latency, where it goes, large requests.

Baxter's right arm (example-robot-data), the benchmark box, grasps around it, a 2 s quintic
trajectory; the node runs in-process (rclpy, MultiThreadedExecutor thread) and a client node
in the same context calls ``~/rank_grasps`` (rclpy's SingleThreadedExecutor, as the README's
example; also rclpy's EventsExecutor, whose own cost is smaller). Two node configurations:

- ``issue_comparable``: ``posture.restarts`` 0 (the paper's single IK, what the node ran when
  issue 12's targets were written) and the default response;
- ``issue_comparable_per_sample_off``: the same with ``response.per_sample`` false (scores
  and aggregates only, the first grasp's joint trajectory);
- ``node_defaults``: the node's default parameters (posture selection with 8 restarts).

Each is measured for:

- latency, 10 grasps x 101 samples (dt 0.02 s): median and p90 of the round trip; interleaved
  with each call, the ranking's own time (``GraspSafetyEvaluator.rank`` of the node's
  evaluator on the same inputs, in this thread) and the spans of the node's work done by hand
  with the node's settings (request conversion, ranking, posture selection, analyses, response
  message, serialisation, and the client's deserialisation of it); the rest of the round trip
  is the executors and the middleware (an empty request, GetParameters, measures that floor).
  The markers are built only for a subscriber (none here): timed apart, not in the sum;
- end to end, 1,000 grasps x 201 samples (dt 0.01 s): wall time of the call and the
  response's size in bytes (serialised RankGrasps response), with the same spans once.

Usage: .venv/bin/python bench/service.py [--repeats 30] [--large-repeats 2] [--json OUT]
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

CONFIGURATIONS: dict[str, dict[str, Any]] = {
    "issue_comparable": {"posture.restarts": 0},
    "issue_comparable_per_sample_off": {"posture.restarts": 0, "response.per_sample": False},
    "node_defaults": {},
}
"""Node parameters of each measured configuration, on top of the benchmark's."""
DESCRIPTIONS = {
    "issue_comparable": "posture.restarts 0 (the paper's single IK), default response",
    "issue_comparable_per_sample_off": "posture.restarts 0, response.per_sample false",
    "node_defaults": "the node's defaults (posture.restarts 8, default response)",
}
SPANS = ("convert", "rank", "posture", "analyse", "response", "serialise", "deserialise")
"""The node's steps in a round trip, and the client's deserialisation."""
REST = "rest (executors, middleware)"


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
def running_node(
    arm: ArmWorkload, dt_s: float, overrides: dict[str, Any] | None = None
) -> Iterator[tuple[Any, Any, Any, Any]]:
    """The node for ``arm`` spinning in a thread; yields (node, client_node, executor, client).

    ``overrides``: node parameters on top of the benchmark's (robot, seed, ``dt_s``).
    """
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
        **(overrides or {}),
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


def samples_per_grasp(dt_s: float) -> int:
    """Samples of rank_request's 2 s trajectory at the node's ``trajectory.dt_s``."""
    return round(2.0 / dt_s) + 1


def call(client_executor: Any, client: Any, request: Any, timeout_s: float = 60.0) -> Any:
    """Call the service; return the response (raise when it fails)."""
    future = client.call_async(request)
    client_executor.spin_until_future_complete(future, timeout_sec=timeout_s)
    response = future.result()
    if response is None or not response.success:
        raise RuntimeError("no answer" if response is None else response.message)
    return response


def node_spans(node: Any, request: Any) -> dict[str, float]:
    """Durations [s] of the node's steps for ``request``, done by hand with its functions and
    its settings, and of the client's deserialisation of the response.

    ``<step>`` is the wall-clock time, ``<step>_cpu`` the CPU time of this thread (less
    affected by other processes; the ranking's pool threads are not counted in it).
    ``markers`` (built only for a subscriber) is timed too but is not a step of the round trip.
    """
    from grasp_safety_msgs.srv import RankGrasps
    from rclpy.serialization import deserialize_message, serialize_message

    from grasp_safety_ros.core.analyses.safety_report import analyse
    from grasp_safety_ros.core.method.posture import select_postures
    from grasp_safety_ros.ros import conversions

    spans: dict[str, float] = {}
    snapshot = node._snapshot()
    settings, bundle = snapshot.settings, snapshot.bundle

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
    ranking = span(
        "posture",
        lambda: select_postures(evaluator, grasps, inertia, trajectory, ranking, settings.posture),
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
        lambda: RankGrasps.Response(
            success=True,
            ranking=conversions.report_msg(
                report, request.grasps, settings.base_frame, stamp, 0.0, settings.response
            ),
        ),
    )
    data = span("serialise", lambda: serialize_message(message))
    span("deserialise", lambda: deserialize_message(data, RankGrasps.Response))
    span(
        "markers",
        lambda: conversions.markers_msg(
            ranking, grasps, trajectory, settings.base_frame, stamp, order=report.order
        ),
    )
    return spans


def _events_client(client_node: Any) -> tuple[Any, Any, Any] | None:
    """(executor, client, node): a second client of the service on rclpy's EventsExecutor, or
    None without it."""
    try:
        from grasp_safety_msgs.srv import RankGrasps
        from rclpy.experimental import EventsExecutor
    except ImportError:
        return None
    import rclpy

    node = rclpy.create_node("grasp_safety_bench_events_client", context=client_node.context)
    executor = EventsExecutor(context=client_node.context)
    executor.add_node(node)
    client = node.create_client(RankGrasps, "/grasp_safety/rank_grasps")
    if not client.wait_for_service(timeout_sec=20.0):
        executor.shutdown()
        node.destroy_node()
        return None
    return executor, client, node


def latency(arm: ArmWorkload, repeats: int, overrides: dict[str, Any]) -> dict[str, Any]:
    """Round trip of 10 grasps x 101 samples, the ranking's own time and the spans.

    Also the round trip of an empty request to the same node (GetParameters of one name):
    the floor set by the executors and the middleware; and the round trip from a client on
    rclpy's EventsExecutor.
    """
    from rcl_interfaces.srv import GetParameters

    request = rank_request(arm, 10)
    with running_node(arm, 0.02, overrides) as (node, client_node, client_executor, client):
        get = client_node.create_client(GetParameters, "/grasp_safety/get_parameters")
        get.wait_for_service(timeout_sec=20.0)
        events = _events_client(client_node)
        round_trips, computes, empty, events_trips = [], [], [], []
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
            if events is not None:
                started = time.perf_counter()
                call(events[0], events[1], request)
                events_trips.append(time.perf_counter() - started)
            if k >= 3:  # the first calls warm caches up
                round_trips.append(elapsed)
                empty.append(empty_elapsed)
                computes.append(response.ranking.compute_time_s)
                for name, value in steps.items():
                    spans.setdefault(name, []).append(value)
        if events is not None:
            events[0].shutdown()
            events[2].destroy_node()
        evaluations = response.ranking.evaluations
    result = {
        "robot": arm.name,
        "grasps": len(evaluations),
        "samples_per_grasp": samples_per_grasp(0.02),
        "feasible_grasps": sum(1 for e in evaluations if e.feasible),
        "joint_trajectories_sent": sum(1 for e in evaluations if e.joint_trajectory.points),
        "repeats": repeats,
        "latency_ms": summary_ms(round_trips),
        "latency_events_client_ms": summary_ms(events_trips[3:]) if events_trips else None,
        "ranking_ms": summary_ms(spans["rank"]),
        "node_compute_ms": summary_ms(computes),
        "empty_request_ms": summary_ms(empty),
        "spans_ms": {name: summary_ms(spans[name])["median"] for name in SPANS},
        "spans_cpu_ms": {name: summary_ms(spans[f"{name}_cpu"])["median"] for name in SPANS},
        "markers_when_subscribed_ms": summary_ms(spans["markers"])["median"],
    }
    result["median_ms"] = result["latency_ms"]["median"]
    result["latency_over_ranking"] = result["median_ms"] / result["ranking_ms"]["median"]
    result["spans_ms"][REST] = result["median_ms"] - sum(result["spans_ms"].values())
    return result


def large(arm: ArmWorkload, repeats: int, overrides: dict[str, Any]) -> dict[str, Any]:
    """End to end: 1,000 grasps x 201 samples through the service; the response's size."""
    from rclpy.serialization import serialize_message

    request = rank_request(arm, 1000)
    with running_node(arm, 0.01, overrides) as (node, _, client_executor, client):
        call(client_executor, client, rank_request(arm, 10))  # warm-up
        walls, computes = [], []
        for _ in range(repeats):
            started = time.perf_counter()
            response = call(client_executor, client, request)
            walls.append(time.perf_counter() - started)
            computes.append(response.ranking.compute_time_s)
        evaluations = response.ranking.evaluations
        spans = node_spans(node, request)
    result = {
        "robot": arm.name,
        "grasps": len(evaluations),
        "samples_per_grasp": samples_per_grasp(0.01),
        "feasible_grasps": sum(1 for e in evaluations if e.feasible),
        "joint_trajectories_sent": sum(1 for e in evaluations if e.joint_trajectory.points),
        "repeats": repeats,
        "wall_s": summary_ms(walls)["median"] / 1e3,
        "wall_ms": summary_ms(walls),
        "node_compute_ms": summary_ms(computes),
        "response_bytes": len(serialize_message(response)),
        "spans_ms": {name: 1e3 * spans[name] for name in SPANS},
        "spans_cpu_ms": {name: 1e3 * spans[f"{name}_cpu"] for name in SPANS},
        "markers_when_subscribed_ms": 1e3 * spans["markers"],
    }
    result["spans_ms"][REST] = 1e3 * result["wall_s"] - sum(result["spans_ms"].values())
    return result


def run(repeats: int, large_repeats: int) -> dict[str, Any]:
    """Both measurements on Baxter for each configuration, with the load average around them.

    Returns:
        ``{configuration: {"parameters", "description", "latency_10x101",
        "end_to_end_1000x201"}, "load_average_1min": [before, after]}`` with the
        configurations of CONFIGURATIONS.
    """
    load_before = os.getloadavg()[0]
    arm = ARMS["baxter"]
    results: dict[str, Any] = {}
    for name, overrides in CONFIGURATIONS.items():
        results[name] = {
            "parameters": overrides,
            "description": DESCRIPTIONS[name],
            "latency_10x101": latency(arm, repeats, overrides),
        }
        if large_repeats > 0:
            results[name]["end_to_end_1000x201"] = large(arm, large_repeats, overrides)
    results["load_average_1min"] = [load_before, os.getloadavg()[0]]
    return results


def print_results(results: dict[str, Any]) -> None:
    def spans(values: dict[str, float]) -> str:
        return ", ".join(f"{k} {v:.2f}" for k, v in values.items())

    for name in CONFIGURATIONS:
        print(f"[{name}] {results[name]['description']}")
        small = results[name]["latency_10x101"]
        lat, rank = small["latency_ms"], small["ranking_ms"]
        print(
            f"  service latency 10 x 101 (Baxter): median {lat['median']:.2f} ms, p90 "
            f"{lat['p90']:.2f} ms [{lat['min']:.2f}..{lat['max']:.2f}]; ranking alone "
            f"{rank['median']:.2f} ms (latency / ranking = {small['latency_over_ranking']:.2f}); "
            f"node compute {small['node_compute_ms']['median']:.2f} ms"
        )
        print(f"    spans (median ms): {spans(small['spans_ms'])}")
        print(f"    spans (median CPU ms of the calling thread): {spans(small['spans_cpu_ms'])}")
        events = small["latency_events_client_ms"]
        print(
            f"    empty request (GetParameters): {small['empty_request_ms']['median']:.2f} ms; "
            + (
                f"round trip from an EventsExecutor client: median {events['median']:.2f} ms, "
                f"p90 {events['p90']:.2f} ms; "
                if events
                else ""
            )
            + f"markers (built only for a subscriber) {small['markers_when_subscribed_ms']:.2f} ms"
        )
        big = results[name].get("end_to_end_1000x201")
        if big:
            print(
                f"  service end to end {big['grasps']} x {big['samples_per_grasp']} (Baxter): "
                f"{big['wall_s']:.3f} s (node compute {big['node_compute_ms']['median']:.0f} ms),"
                f" response {big['response_bytes']} bytes ({big['response_bytes'] / 1e6:.2f} MB)"
            )
            print(f"    spans (ms): {spans(big['spans_ms'])}")
            print(f"    spans (CPU ms): {spans(big['spans_cpu_ms'])}")
    print(f"load average (1 min) before/after: {results['load_average_1min']}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--large-repeats", type=int, default=2)
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
