#!/usr/bin/env python3
"""Service cost of the grasp_safety node (issue 12): latency, where it goes, large requests.

Baxter's right arm (example-robot-data), the benchmark box, grasps around it, a 2 s quintic
trajectory; the node runs in-process (rclpy, its NodeExecutor spun in a thread, as its
console script runs it) and the client is a separate process (bench/service_client.py, a
small rclpy node as a user's), driven over a pipe. Four node configurations:

- ``issue_comparable``: ``posture.restarts`` 0 (the paper's single IK, what the node ran when
  issue 12's targets were written) and the default response;
- ``issue_comparable_per_sample_off``: the same with ``response.per_sample`` false (scores
  and aggregates only, the first grasp's joint trajectory);
- ``node_defaults``: the node's default parameters (posture selection with 8 restarts), the
  benchmark box described by ``object.box_size_m`` (its corners: the exposed points, as
  issue 21's targets count them);
- ``least_response``: the least the node can be set to return (no per-sample arrays, no
  joint trajectory, one ISO/TS 15066 region): what the round trip costs beyond the ranking
  when the messages are as small as they get.

All four pin ``effort.enabled`` false (EFFORT_OFF), as the committed figures were measured.

Each is measured for:

- latency, 10 grasps x 101 samples (dt 0.02 s): median and p90 of the round trip from a
  client on rclpy's EventsExecutor (the headline; the ``spin_once`` loop where rclpy has no
  EventsExecutor) and, secondary, from a client waiting with
  ``SingleThreadedExecutor.spin_until_future_complete`` (what the obvious client pays); the
  floor of each (an empty request: GetParameters of one name). Interleaved with the calls,
  with the node idle: the ranking's own time (``GraspSafetyEvaluator.rank`` of the node's
  evaluator on the same inputs, in this process) and the spans of the node's work done by
  hand with the node's settings (request conversion, ranking, posture selection, analyses,
  response message, serialisation, and the client's deserialisation of it); the rest of the
  round trip is the executors and the middleware. The headline's round trips also split
  into legs (LEGS: client call to node callback, the callback, callback end to client) by
  readings of the machine's monotonic clock in both processes. The markers and the
  ``~/ranking`` publication are made only for a subscriber (none here): the markers are
  timed apart, not in the sum;
- end to end, 100 and 1,000 grasps x 201 samples (dt 0.01 s), from the EventsExecutor
  client: wall time of the call (median of ``--mid-repeats``, ``--large-repeats`` calls)
  and the response's size in bytes (serialised RankGrasps response), with the same spans
  measured between the calls and the legs of each call (LEGS). For both, the rest is split
  by leg (rest_split).

At the end, issue 21's three service targets (node defaults: 10 x 101 median, 100 x 201 and
1,000 x 201 end to end) beside the core's own ranking time of the same run (the ``rank``
span), with what posture selection, the analyses, the node's own work (request conversion,
response message, serialisation, the client's deserialisation) and the executors take.

Usage: .venv/bin/python bench/service.py [--repeats 30] [--large-repeats 2] [--mid-repeats 5]
[--configurations node_defaults,...] [--json OUT]
(not a test; also run by bench/run.py). Figures are wall-clock: other processes on the cores
inflate them (the load average is recorded).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np
from service_processes import CallbackClock, clients, running_node
from workload import ARMS, BOX_SIZE_M, ArmWorkload, box_object, grasps_around_box

EFFORT_OFF = {"effort.enabled": False}
"""Pinned in every configuration: the committed figures (bench/results.json,
docs/performance_pipeline.md) were measured without the effort analysis, then the node's
default (now on: core.options)."""
CONFIGURATIONS: dict[str, dict[str, Any]] = {
    "issue_comparable": {"posture.restarts": 0, **EFFORT_OFF},
    "issue_comparable_per_sample_off": {
        "posture.restarts": 0,
        "response.per_sample": False,
        **EFFORT_OFF,
    },
    "node_defaults": {"object.box_size_m": list(BOX_SIZE_M), **EFFORT_OFF},
    "least_response": {
        "posture.restarts": 0,
        "response.per_sample": False,
        "response.joint_trajectories": 0,
        "iso_ts_15066.regions": ["chest"],
        **EFFORT_OFF,
    },
}
"""Node parameters of each measured configuration, on top of the benchmark's."""
DESCRIPTIONS = {
    "issue_comparable": "posture.restarts 0 (the paper's single IK), default response",
    "issue_comparable_per_sample_off": "posture.restarts 0, response.per_sample false",
    "node_defaults": (
        "the node's defaults (posture.restarts 8, default response) but effort.enabled "
        "false (EFFORT_OFF), the box described (object.box_size_m: its corners are the "
        "exposed points analysed)"
    ),
    "least_response": (
        "the least the node returns: posture.restarts 0, response.per_sample false, "
        "response.joint_trajectories 0, one ISO/TS 15066 region (chest)"
    ),
}
SPANS = ("convert", "rank", "posture", "analyse", "response", "serialise", "deserialise")
"""The node's steps in a round trip, and the client's deserialisation."""
REST = "rest (executors, middleware)"
LEGS = (
    "request (client call to node callback)",
    "node callback",
    "response (node callback end to client)",
)
"""The legs of a round trip, by clock readings in the client and the node's callback: the
request leg is the client's serialisation, the transport and the node's executor; the
response leg the node's serialisation, the transport, the client's executor and its
deserialisation."""
WAITS = ("events", "spin_once", "spin_until")
"""How the clients wait for the answer (service_client.py): the headline's first."""


def summary_ms(values_s: Sequence[float]) -> dict[str, float]:
    """Median, p90, min and max of durations given in seconds, in milliseconds."""
    values = np.asarray(values_s, dtype=float) * 1e3
    return {
        "median": float(np.median(values)),
        "p90": float(np.percentile(values, 90)),
        "min": float(values.min()),
        "max": float(values.max()),
    }


def legs_s(answer: dict[str, Any], call: tuple[float, float]) -> dict[str, float]:
    """The legs of one round trip [s]: ``answer`` the client's, ``call`` the node callback's
    (start, end) of that request (CallbackClock)."""
    return {
        LEGS[0]: call[0] - answer["sent_s"],
        LEGS[1]: call[1] - call[0],
        LEGS[2]: answer["received_s"] - call[1],
    }


def rest_split(spans_ms: dict[str, float], legs_ms: dict[str, float]) -> dict[str, float]:
    """Where the rest of a round trip (REST: executors, middleware) sits, from the medians of
    its legs and of the spans [ms]: the request leg; the callback beyond the node's spans
    (publishing, diagnostics, the compute lock, the spans' own variation); the response leg
    beyond the response's serialisation and deserialisation (the node's conversion of the
    response for the middleware, the transport, the client's executor)."""
    in_callback = ("convert", "rank", "posture", "analyse", "response")
    return {
        "request leg": legs_ms[LEGS[0]],
        "callback beyond its spans": legs_ms[LEGS[1]] - sum(spans_ms[n] for n in in_callback),
        "response leg beyond (de)serialisation": legs_ms[LEGS[2]]
        - spans_ms["serialise"]
        - spans_ms["deserialise"],
    }


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


def node_spans(node: Any, request: Any) -> dict[str, float]:
    """Durations [s] of the node's steps for ``request``, done by hand with the functions its
    service callback calls and its settings, and of the client's deserialisation of the
    response.

    ``convert`` is the request's checks and conversion (check_no_subnormals, ranking_inputs);
    ``rank``, ``posture`` and ``analyse`` the stages rank, postures and analyses of
    core.pipeline.run_pipeline (``rank`` is the core's own ranking: GraspSafetyEvaluator.rank,
    the single IK), timed by its ``timings``; ``response`` report_msg and
    check_finite_result. ``<step>`` is the wall-clock time, ``<step>_cpu`` the CPU time of
    this thread (less affected by other processes; the ranking's pool threads are not counted
    in it). ``markers`` (built only for a subscriber) is timed too but is not a step of the
    round trip.
    """
    from grasp_safety_msgs.srv import RankGrasps
    from rclpy.serialization import deserialize_message, serialize_message

    from grasp_safety_ros.core.pipeline import run_pipeline
    from grasp_safety_ros.ros import conversions
    from grasp_safety_ros.ros.service.message_checks import (
        check_finite_result,
        check_no_subnormals,
    )
    from grasp_safety_ros.ros.service.ranking_inputs import markers_builder, ranking_inputs

    spans: dict[str, float] = {}
    snapshot = node._snapshot()
    settings, bundle = snapshot.settings, snapshot.bundle

    def span(name: str, function: Callable[[], Any]) -> Any:
        started, started_cpu = time.perf_counter(), time.thread_time()
        result = function()
        spans[name] = time.perf_counter() - started
        spans[f"{name}_cpu"] = time.thread_time() - started_cpu
        return result

    def convert() -> Any:
        check_no_subnormals(request)
        return ranking_inputs(
            snapshot,
            bundle,
            request.grasps,
            conversions.object_trajectory_of_request(
                request.object_trajectory, request.object_multi_dof_trajectory
            ),
            request.object_inertia,
            request.metric,
            "grasps",
            None,
            request.metric_point,
            "grasp_quality",
            request.joint_trajectories,
        )

    inputs = span("convert", convert)
    stages: dict[str, float] = {}
    report = run_pipeline(bundle.evaluator, inputs, timings=stages)
    for stage, name in (("rank", "rank"), ("postures", "posture"), ("analyses", "analyse")):
        spans[name], spans[f"{name}_cpu"] = stages[stage], stages[f"{stage}_cpu"]
    ranking, grasps, trajectory = report.ranking, inputs.grasps, inputs.trajectory
    stamp = node.get_clock().now().to_msg()

    def response() -> Any:
        message = conversions.report_msg(
            report, request.grasps, settings.base_frame, stamp, 0.0, settings.response
        )
        check_finite_result(message)
        return RankGrasps.Response(success=True, ranking=message)

    message = span("response", response)
    data = span("serialise", lambda: serialize_message(message))
    span("deserialise", lambda: deserialize_message(data, RankGrasps.Response))
    span(
        "markers",
        markers_builder(ranking, report, grasps, trajectory, settings.base_frame, stamp),
    )
    return spans


def latency(arm: ArmWorkload, repeats: int, overrides: dict[str, Any]) -> dict[str, Any]:
    """Round trip of 10 grasps x 101 samples from each client (WAITS), the ranking's own time
    and the spans; the floor of each client (an empty request, GetParameters of one name)."""
    request = rank_request(arm, 10)
    round_trips: dict[str, list[float]] = {wait: [] for wait in WAITS}
    empty: dict[str, list[float]] = {wait: [] for wait in WAITS}
    computes: list[float] = []
    spans: dict[str, list[float]] = {}
    legs: dict[str, list[float]] = {leg: [] for leg in LEGS}
    with (
        running_node(arm, 0.02, overrides) as (node, environment),
        clients(environment, *WAITS) as processes,
    ):
        clock = CallbackClock(node)
        for k in range(repeats + 3):
            answers, empties = {}, {}
            for wait, process in zip(WAITS, processes, strict=True):
                answers[wait] = process.command("rank 10")
                empties[wait] = process.command("empty")
                if wait == WAITS[0]:
                    call = clock.calls[-1]  # this rank request's (empty is another service)
                    steps = node_spans(node, request)  # the node idle, between the calls
            if k >= 3:  # the first calls warm caches up
                for wait in WAITS:
                    round_trips[wait].append(answers[wait]["round_trip_s"])
                    empty[wait].append(empties[wait]["round_trip_s"])
                computes.append(answers[WAITS[0]]["compute_time_s"])
                for name, value in steps.items():
                    spans.setdefault(name, []).append(value)
                for leg, value in legs_s(answers[WAITS[0]], call).items():
                    legs[leg].append(value)
        headline_wait = processes[0].wait
    answer = answers[WAITS[0]]
    result = {
        "robot": arm.name,
        "grasps": answer["grasps"],
        "samples_per_grasp": samples_per_grasp(0.02),
        "feasible_grasps": answer["feasible_grasps"],
        "joint_trajectories_sent": answer["joint_trajectories_sent"],
        "response_bytes": answer["response_bytes"],
        "repeats": repeats,
        "client": f"separate process, {headline_wait}",
        "latency_ms": summary_ms(round_trips[WAITS[0]]),
        **{f"latency_{wait}_ms": summary_ms(round_trips[wait]) for wait in WAITS[1:]},
        "ranking_ms": summary_ms(spans["rank"]),
        "node_compute_ms": summary_ms(computes),
        "empty_request_ms": summary_ms(empty[WAITS[0]]),
        **{f"empty_request_{wait}_ms": summary_ms(empty[wait]) for wait in WAITS[1:]},
        "spans_ms": {name: summary_ms(spans[name])["median"] for name in SPANS},
        "spans_cpu_ms": {name: summary_ms(spans[f"{name}_cpu"])["median"] for name in SPANS},
        "markers_when_subscribed_ms": summary_ms(spans["markers"])["median"],
        "legs_ms": {leg: summary_ms(values)["median"] for leg, values in legs.items()},
    }
    result["median_ms"] = result["latency_ms"]["median"]
    result["latency_over_ranking"] = result["median_ms"] / result["ranking_ms"]["median"]
    result["spans_ms"][REST] = result["median_ms"] - sum(result["spans_ms"].values())
    result["rest_split_ms"] = rest_split(result["spans_ms"], result["legs_ms"])
    return result


def end_to_end(
    arm: ArmWorkload, num_grasps: int, repeats: int, overrides: dict[str, Any]
) -> dict[str, Any]:
    """End to end: ``num_grasps`` grasps x 201 samples through the service, from the
    EventsExecutor client (median of ``repeats`` calls); the response's size; the spans,
    measured by hand between the calls, and the legs of the calls (LEGS) (medians)."""
    request = rank_request(arm, num_grasps)
    spans: dict[str, list[float]] = {}
    legs: dict[str, list[float]] = {leg: [] for leg in LEGS}
    with (
        running_node(arm, 0.01, overrides) as (node, environment),
        clients(environment, "events") as (client,),
    ):
        clock = CallbackClock(node)
        client.command("rank 10")  # warm-up
        walls, computes = [], []
        for _ in range(repeats):
            answer = client.command(f"rank {num_grasps}")
            walls.append(answer["round_trip_s"])
            computes.append(answer["compute_time_s"])
            for leg, value in legs_s(answer, clock.calls[-1]).items():
                legs[leg].append(value)
            for name, value in node_spans(node, request).items():
                spans.setdefault(name, []).append(value)
        wait = client.wait
    median = {name: float(np.median(values)) for name, values in spans.items()}
    result = {
        "robot": arm.name,
        "grasps": answer["grasps"],
        "samples_per_grasp": samples_per_grasp(0.01),
        "feasible_grasps": answer["feasible_grasps"],
        "joint_trajectories_sent": answer["joint_trajectories_sent"],
        "repeats": repeats,
        "client": f"separate process, {wait}",
        "wall_s": summary_ms(walls)["median"] / 1e3,
        "wall_ms": summary_ms(walls),
        "node_compute_ms": summary_ms(computes),
        "ranking_ms": summary_ms(spans["rank"]),
        "response_bytes": answer["response_bytes"],
        "spans_ms": {name: 1e3 * median[name] for name in SPANS},
        "spans_cpu_ms": {name: 1e3 * median[f"{name}_cpu"] for name in SPANS},
        "markers_when_subscribed_ms": 1e3 * median["markers"],
        "legs_ms": {leg: 1e3 * float(np.median(values)) for leg, values in legs.items()},
    }
    result["wall_over_ranking"] = result["wall_s"] * 1e3 / result["ranking_ms"]["median"]
    result["spans_ms"][REST] = 1e3 * result["wall_s"] - sum(result["spans_ms"].values())
    result["rest_split_ms"] = rest_split(result["spans_ms"], result["legs_ms"])
    return result


TARGETS = (
    ("latency_10x101", "10 grasps x 101 samples, median", 20.0),
    ("end_to_end_100x201", "100 grasps x 201 samples, one client", 200.0),
    ("end_to_end_1000x201", "1,000 grasps x 201 samples, end to end", 3000.0),
)
"""Issue 21's service targets, node defaults: (result key, what, target [ms])."""
NODE_SHARE = ("convert", "response", "serialise", "deserialise")
"""The spans that are the node's own work around the core (and the client's decoding)."""


def run(
    repeats: int,
    large_repeats: int,
    mid_repeats: int = 5,
    configurations: Sequence[str] = tuple(CONFIGURATIONS),
) -> dict[str, Any]:
    """The measurements on Baxter for each configuration, with the load average around them.

    Returns:
        ``{configuration: {"parameters", "description", "latency_10x101",
        "end_to_end_100x201", "end_to_end_1000x201"}, "load_average_1min": [before,
        after], "targets": target_rows(...)}`` with ``configurations`` (of CONFIGURATIONS); an
        end-to-end row is left out when its repeats are 0.
    """
    load_before = os.getloadavg()[0]
    arm = ARMS["baxter"]
    results: dict[str, Any] = {}
    for name in configurations:
        overrides = CONFIGURATIONS[name]
        results[name] = {
            "parameters": overrides,
            "description": DESCRIPTIONS[name],
            "latency_10x101": latency(arm, repeats, overrides),
        }
        if mid_repeats > 0:
            results[name]["end_to_end_100x201"] = end_to_end(arm, 100, mid_repeats, overrides)
        if large_repeats > 0:
            results[name]["end_to_end_1000x201"] = end_to_end(arm, 1000, large_repeats, overrides)
    results["load_average_1min"] = [load_before, os.getloadavg()[0]]
    results["targets"] = target_rows(results)
    return results


def target_rows(results: dict[str, Any]) -> list[dict[str, Any]]:
    """Issue 21's three service rows (node defaults) beside the core's own ranking time of
    the same run (``rank`` span: GraspSafetyEvaluator.rank on the same inputs) and the node's
    own share (NODE_SHARE spans); empty when node_defaults was not measured."""
    measured = results.get("node_defaults")
    rows: list[dict[str, Any]] = []
    for key, what, target_ms in TARGETS if measured else ():
        figures = measured.get(key)
        if figures is None:
            continue
        wall_ms = figures["median_ms"] if key == "latency_10x101" else 1e3 * figures["wall_s"]
        spans = figures["spans_ms"]
        rows.append(
            {
                "row": what,
                "measured_ms": wall_ms,
                "target_ms": target_ms,
                "core_ranking_ms": spans["rank"],
                "over_core_ranking": wall_ms / spans["rank"],
                "posture_ms": spans["posture"],
                "analyse_ms": spans["analyse"],
                "node_share_ms": sum(spans[name] for name in NODE_SHARE),
                "rest_ms": spans[REST],
            }
        )
    return rows


def print_results(results: dict[str, Any]) -> None:
    def spans(values: dict[str, float]) -> str:
        return ", ".join(f"{k} {v:.2f}" for k, v in values.items())

    for name in (name for name in CONFIGURATIONS if name in results):
        print(f"[{name}] {results[name]['description']}")
        small = results[name]["latency_10x101"]
        lat, rank = small["latency_ms"], small["ranking_ms"]
        print(
            f"  service latency 10 x 101 (Baxter, client: {small['client']}): median "
            f"{lat['median']:.2f} ms, p90 {lat['p90']:.2f} ms "
            f"[{lat['min']:.2f}..{lat['max']:.2f}]; ranking alone {rank['median']:.2f} ms "
            f"(latency / ranking = {small['latency_over_ranking']:.2f}); node compute "
            f"{small['node_compute_ms']['median']:.2f} ms; response {small['response_bytes']} B"
        )
        print(f"    spans (median ms): {spans(small['spans_ms'])}")
        print(f"    spans (median CPU ms of the calling thread): {spans(small['spans_cpu_ms'])}")
        print(f"    legs of the round trip (median ms): {spans(small['legs_ms'])}")
        print(f"    the rest, by leg (ms): {spans(small['rest_split_ms'])}")
        for wait in WAITS[1:]:
            other = small[f"latency_{wait}_ms"]
            print(
                f"    client waiting with {wait}: median {other['median']:.2f} ms, p90 "
                f"{other['p90']:.2f} ms"
            )
        floors = [f"{small['empty_request_ms']['median']:.2f} ms ({WAITS[0]})"] + [
            f"{small[f'empty_request_{wait}_ms']['median']:.2f} ms ({wait})" for wait in WAITS[1:]
        ]
        print(
            f"    empty request (GetParameters), median: {', '.join(floors)}; markers (built "
            f"only for a subscriber) {small['markers_when_subscribed_ms']:.2f} ms"
        )
        for key in ("end_to_end_100x201", "end_to_end_1000x201"):
            big = results[name].get(key)
            if not big:
                continue
            print(
                f"  service end to end {big['grasps']} x {big['samples_per_grasp']} (Baxter, "
                f"client: {big['client']}, median of {big['repeats']}): {big['wall_s']:.3f} s "
                f"(node compute {big['node_compute_ms']['median']:.0f} ms; ranking alone "
                f"{big['ranking_ms']['median']:.1f} ms, wall / ranking = "
                f"{big['wall_over_ranking']:.1f}), response {big['response_bytes']} bytes "
                f"({big['response_bytes'] / 1e6:.2f} MB)"
            )
            print(f"    spans (median ms): {spans(big['spans_ms'])}")
            print(f"    spans (median CPU ms): {spans(big['spans_cpu_ms'])}")
            print(f"    legs of the round trip (median ms): {spans(big['legs_ms'])}")
            print(f"    the rest, by leg (ms): {spans(big['rest_split_ms'])}")
    rows = results.get("targets") or target_rows(results)
    if rows:
        print("issue 21's service targets (node defaults), beside the core's ranking of this run:")
    for row in rows:
        print(
            f"  {row['row']}: {row['measured_ms']:.1f} ms (target {row['target_ms']:.0f} ms); "
            f"core ranking {row['core_ranking_ms']:.1f} ms (x{row['over_core_ranking']:.1f}); "
            f"posture selection {row['posture_ms']:.1f} ms, analyses {row['analyse_ms']:.1f} "
            f"ms, the node's own work ({', '.join(NODE_SHARE)}) {row['node_share_ms']:.1f} ms, "
            f"executors and middleware {row['rest_ms']:.1f} ms"
        )
    print(f"load average (1 min) before/after: {results['load_average_1min']}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--large-repeats", type=int, default=2, help="1,000 x 201 calls")
    parser.add_argument("--mid-repeats", type=int, default=5, help="100 x 201 calls")
    parser.add_argument(
        "--configurations",
        default=",".join(CONFIGURATIONS),
        help=f"comma-separated, of: {', '.join(CONFIGURATIONS)}",
    )
    parser.add_argument("--json", type=Path, help="write the results as JSON here")
    args = parser.parse_args(argv)
    names = [name for name in args.configurations.split(",") if name]
    unknown = sorted(set(names) - set(CONFIGURATIONS))
    if unknown:
        parser.error(f"--configurations: unknown {unknown}; valid: {', '.join(CONFIGURATIONS)}")
    results = run(args.repeats, args.large_repeats, args.mid_repeats, names)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    print_results(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
