#!/usr/bin/env python3
"""Cost of the live speed-scaling monitor (issue 29): per-message compute time and the latency
from a /joint_states publish to the factor's arrival, at 500 Hz.

The bundled params file (config/grasp_safety_monitor.yaml): the Panda with the published FR3
rotor inertia, its default sites (chain joints 3..7 and the tip) plus a 1 kg box's 8 corners,
every region that permits transient contact.

- compute: the node's per-message work without ROS (``Governor.on_state``: joints matched by
  name, the core's analysis, the rate limit) on the states of a replayed trajectory, in this
  process: median, p99 and max [ms]; and the core's analysis alone. Target: p99 <= 1 ms.
- end to end: the monitor's console script as a process, a publisher at 500 Hz in this
  process (its executor spun in a thread) for ``--seconds``, ``speed_scaling.closed_loop``
  false (no controller slows the replay); a state's factor is recognised
  on arrival by its value (each state of the replay with a factor below 1 has its own,
  computed here with the same core function), and its latency is the arrival time minus that
  state's publish time (one monotonic clock). Also: the states per second the node assessed and
  how many states had no factor (skipped: only the newest is processed).

Usage: .venv/bin/python bench/monitor.py [--states 5000] [--seconds 10] [--json OUT]
(not a test). Wall-clock figures: other processes on the cores inflate them (the load average
is recorded).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))  # ros_domains: a ROS domain of our own

from ros_domains import claim_ros_domain  # noqa: E402

from grasp_safety_ros.core.analyses.arm_sites import resolve_arm_sites  # noqa: E402
from grasp_safety_ros.core.analyses.speed_scaling import (  # noqa: E402
    IncreaseLimiter,
    SpeedScaling,
    payload_speed_model,
)
from grasp_safety_ros.paths import config_file  # noqa: E402
from grasp_safety_ros.ros.monitor.governor import Governor  # noqa: E402
from grasp_safety_ros.ros.monitor.parameters import monitor_settings  # noqa: E402
from grasp_safety_ros.ros.robot.bundle import build_robot  # noqa: E402

PARAMS = config_file("grasp_safety_monitor.yaml")
RATE_HZ = 500.0
JOINTS = [f"panda_joint{k}" for k in range(1, 8)]
TOPIC = "/bench_controller/speed_scaling_input"


def _flatten(values: dict, prefix: str = "") -> dict:
    flat: dict = {}
    for key, value in values.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def analysis() -> SpeedScaling:
    values = yaml.safe_load(PARAMS.read_text())["grasp_safety_monitor"]["ros__parameters"]
    settings = monitor_settings(_flatten(values))
    bundle = build_robot(settings.node, None)
    payload = settings.payload
    sites = resolve_arm_sites(bundle.robot)
    model = payload_speed_model(
        bundle.robot, sites, payload.inertia, payload.points_in_tip_m, None
    )
    return SpeedScaling(model, settings.margin, settings.rest_speed_m_s)


def states(count: int) -> tuple[np.ndarray, np.ndarray]:
    """A fast periodic motion about the Panda's ready posture: (count, 7) q [rad], q̇ [rad/s]."""
    ready = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
    amplitude = np.array([0.8, 0.5, 0.6, 0.5, 0.9, 0.6, 1.0])
    omega = 2 * np.pi * np.array([0.31, 0.23, 0.37, 0.29, 0.41, 0.19, 0.43])
    t = (np.arange(count) / RATE_HZ + 0.05)[:, None]
    return ready + amplitude * np.sin(omega * t), amplitude * omega * np.cos(omega * t) + 0.8


def percentiles_ms(samples: list[float]) -> dict[str, float]:
    if not samples:
        return {"count": 0}
    array = np.array(samples) * 1e3
    return {
        "median_ms": float(np.median(array)),
        "p99_ms": float(np.percentile(array, 99)),
        "max_ms": float(array.max()),
        "count": len(array),
    }


def compute_times(scaling: SpeedScaling, q: np.ndarray, qd: np.ndarray) -> dict:
    """Wall and CPU (this thread's) time per state of ``Governor.on_state`` and of the core's
    analysis alone; CPU time leaves out the time other processes held the core."""
    governor = Governor(0.1, IncreaseLimiter(2.0, 0.0, 0.0))
    governor.set_scaling(scaling)
    times: dict[str, list[float]] = {"on_state": [], "on_state_cpu": [], "core": []}
    for k in range(len(q)):
        names, position, velocity = JOINTS, q[k].tolist(), qd[k].tolist()
        start, cpu = time.perf_counter(), time.thread_time()
        governor.on_state(names, position, velocity, float(k))
        times["on_state"].append(time.perf_counter() - start)
        times["on_state_cpu"].append(time.thread_time() - cpu)
        start = time.perf_counter()
        scaling.assess(q[k], qd[k])
        times["core"].append(time.perf_counter() - start)
    return {name: percentiles_ms(values[10:]) for name, values in times.items()}


def end_to_end(scaling: SpeedScaling, seconds: float) -> dict:
    count = int(seconds * RATE_HZ)
    q, qd = states(count)
    expected = np.array([scaling.assess(q[k], qd[k]).factor for k in range(count)])
    order = np.argsort(expected)
    order = order[expected[order] < 1.0]  # a factor of 1 says nothing about which state
    with claim_ros_domain() as claim:
        process = _start_monitor(claim.domain_id)
        arrivals, published = _replay(claim.domain_id, q, qd)
        process.terminate()
        process.wait(timeout=20)
    latencies, matched = _match_arrivals(arrivals, published, expected, order)
    return {
        "published_states": count,
        "publish_rate_hz": count / (published[-1] - published[0]),
        "states_below_1": len(order),
        "states_below_1_with_a_factor": len(matched),
        "latency": percentiles_ms(latencies),
    }


def _start_monitor(domain_id: int) -> subprocess.Popen:
    """The monitor node in its own process on ``domain_id``, publishing the replay's own
    factors (open loop, no increase limit) on TOPIC."""
    env = {
        **os.environ,
        "ROS_DOMAIN_ID": str(domain_id),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
    }
    command = [str(Path(sys.executable).parent / "grasp_safety_monitor"), "--ros-args"]
    command += ["--params-file", str(PARAMS), "-r", f"~/speed_scaling:={TOPIC}"]
    command += ["-p", "speed_scaling.max_increase_per_s:=1000000000.0"]
    command += ["-p", "speed_scaling.closed_loop:=false"]  # the replay's own factors
    return subprocess.Popen(command, env=env, stderr=subprocess.DEVNULL)


def _replay(
    domain_id: int, q: np.ndarray, qd: np.ndarray
) -> tuple[list[tuple[float, float]], np.ndarray]:
    """Publishes the states on /joint_states at RATE_HZ once the monitor is up; returns the
    factors received (monotonic arrival time [s], factor) and each state's publication time."""
    import rclpy
    from control_msgs.msg import SpeedScalingFactor
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    count = len(q)
    context = rclpy.context.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node("monitor_bench", context=context)
    arrivals: list[tuple[float, float]] = []
    latched = QoSProfile(
        depth=1,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
    node.create_subscription(
        SpeedScalingFactor,
        TOPIC,
        lambda m: arrivals.append((time.monotonic(), m.factor)),
        latched,
    )
    publisher = node.create_publisher(JointState, "/joint_states", 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinning = threading.Event()
    spinning.set()

    def spin() -> None:
        while spinning.is_set():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    deadline = time.monotonic() + 120.0
    while not arrivals and time.monotonic() < deadline:  # the monitor is up
        time.sleep(0.1)
    published = np.zeros(count)
    start = time.monotonic()
    for k in range(count):
        msg = JointState(name=JOINTS, position=q[k].tolist(), velocity=qd[k].tolist())
        published[k] = time.monotonic()
        publisher.publish(msg)
        wait = start + (k + 1) / RATE_HZ - time.monotonic()
        if wait > 0:
            time.sleep(wait)
    time.sleep(0.5)
    spinning.clear()
    spinner.join()
    node.destroy_node()
    rclpy.shutdown(context=context)
    return arrivals, published


def _match_arrivals(
    arrivals: list[tuple[float, float]],
    published: np.ndarray,
    expected: np.ndarray,
    order: np.ndarray,
) -> tuple[list[float], set[int]]:
    """Pairs each factor below 1 received with the first unmatched state expected to give it
    (``order``: those states by expected factor); returns the latencies [s] and the states."""
    latencies, matched = [], set()
    for arrival, factor in arrivals:
        if factor >= 1.0:
            continue
        where = np.searchsorted(expected[order], factor)
        for candidate in order[max(0, where - 1) : where + 1]:
            if abs(expected[candidate] - factor) <= 1e-12 and candidate not in matched:
                matched.add(int(candidate))
                latencies.append(arrival - published[candidate])
                break
    return latencies, matched


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=5000)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    scaling = analysis()
    q, qd = states(args.states)
    result = {
        "sites": len(scaling.speed_model.sites),
        "regions": len(scaling.speed_model.regions),
        "load_average": os.getloadavg(),
        "compute": compute_times(scaling, q, qd),
        "end_to_end": end_to_end(scaling, args.seconds),
        "load_average_after": os.getloadavg(),
    }
    text = json.dumps(result, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text + "\n")


if __name__ == "__main__":
    main()
