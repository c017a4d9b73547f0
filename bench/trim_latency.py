"""Latency of small requests beside the node's idle heap trim (not part of ``make test``).

The node gives freed C heap back to the system (glibc malloc_trim) from its diagnostics timer
after a ranking, holding the compute lock. A known-good request once stalled for seconds in
CI; this runs the timer fast (``diagnostics_period_s`` --period-s) with a /diagnostics
subscriber (the status is built each tick), one large request every --large-every small ones
(it leaves freed heap for the trim), and times the small requests (the book, 3 grasps x 21
samples) from the client: p50, p99, p99.9 and max [ms], with the trim on and, for comparison,
off (release_free_heap replaced by a no-op). In-process node (test/test_ros_node.py's
harness) on its own ROS domain.

It first measures the cause (--stall-mb): the trim of a fragmented heap with that much
freed, in one thread, while another allocates small arrays: how long the trims take and the
longest single allocation meanwhile (glibc holds the arena lock during the trim, and the
waiting thread holds the GIL).

    PYTHONPATH=$PWD .venv/bin/python bench/trim_latency.py                  # 1000 per mode
    PYTHONPATH=$PWD .venv/bin/python bench/trim_latency.py --requests 200   # short
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from ros_node_harness import NODE_PARAMETERS, NodeUnderTest, book_path, book_request  # noqa: E402

from grasp_safety_ros.ros import node as node_module  # noqa: E402
from grasp_safety_ros.ros.runtime.memory import release_free_heap  # noqa: E402


def large_request(grasps: int) -> Any:
    """The book's grasps repeated to ``grasps``, over 20 s (201 samples each)."""
    request = book_request()
    poses = list(request.grasps.poses)
    request.grasps.poses = [copy.deepcopy(poses[k % len(poses)]) for k in range(grasps)]
    request.object_trajectory = book_path(20.0)
    return request


def run_mode(
    trim: bool, requests: int, large_every: int, large_grasps: int, period_s: float
) -> dict[str, float]:
    node_module.release_free_heap = release_free_heap if trim else (lambda: False)
    parameters = {
        **NODE_PARAMETERS,
        "diagnostics_period_s": period_s,
        "max_grasps": max(large_grasps, 40),
        "service_busy_timeout_s": 30.0,
        "max_compute_time_s": 60.0,
        "response.joint_trajectories": 0,
    }
    harness = NodeUnderTest(parameters)
    received: list[Any] = []
    subscription = harness.client.create_subscription(
        DiagnosticArray, "/diagnostics", received.append, 10
    )
    small, large = book_request(), large_request(large_grasps)
    latencies_s = []
    try:
        harness.spin_until(lambda: bool(received), 10.0)
        for k in range(requests):
            if large_every and k % large_every == 0:
                assert harness.rank(large).success
            started = time.perf_counter()
            answer = harness.rank(small)
            latencies_s.append(time.perf_counter() - started)
            assert answer.success, answer.message
    finally:
        harness.client.destroy_subscription(subscription)
        harness.close()
        node_module.release_free_heap = release_free_heap
    ms = np.array(latencies_s) * 1e3
    return {
        "p50_ms": float(np.percentile(ms, 50)),
        "p99_ms": float(np.percentile(ms, 99)),
        "p99.9_ms": float(np.percentile(ms, 99.9)),
        "max_ms": float(ms.max()),
    }


def _fragmented(megabytes: int) -> list[np.ndarray]:
    """Arrays of 160-208 kB (under glibc's mmap threshold once raised), every other one kept:
    ``megabytes`` allocated, about half of it freed in holes."""
    blocks = [np.ones(20_000 + (k % 7) * 1_000) for k in range(megabytes * 1024 * 1024 // 160_000)]
    return blocks[::2]


def allocation_stall(megabytes: int, trims: int = 6) -> dict[str, float]:
    """Trim durations and the longest small allocation of another thread meanwhile [ms]."""
    kept = _fragmented(2 * megabytes)
    durations_s: list[float] = []

    def trimmer() -> None:
        for _ in range(trims):
            freed = _fragmented(megabytes)
            del freed
            started = time.perf_counter()
            release_free_heap()
            durations_s.append(time.perf_counter() - started)
            time.sleep(0.05)

    thread = threading.Thread(target=trimmer)
    thread.start()
    worst_s = 0.0
    while thread.is_alive():
        started = time.perf_counter()
        array = np.empty(30_000)  # 240 kB: the main arena's heap
        array[:] = 1.0
        worst_s = max(worst_s, time.perf_counter() - started)
    del kept
    return {
        "trim_median_ms": float(np.median(durations_s) * 1e3),
        "trim_max_ms": float(max(durations_s) * 1e3),
        "longest_allocation_ms": worst_s * 1e3,
    }


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=1000, help="small requests per mode")
    parser.add_argument("--large-every", type=int, default=20)
    parser.add_argument("--large-grasps", type=int, default=200)
    parser.add_argument("--period-s", type=float, default=0.01, help="diagnostics_period_s")
    parser.add_argument("--stall-mb", type=int, default=300, help="heap freed per trim [MB]")
    args = parser.parse_args(argv)
    stall = allocation_stall(args.stall_mb)
    row = "  ".join(f"{key} {value:7.1f}" for key, value in stall.items())
    print(f"trim of {args.stall_mb} MB freed beside small allocations: {row}")
    for trim in (True, False):
        result = run_mode(trim, args.requests, args.large_every, args.large_grasps, args.period_s)
        row = "  ".join(f"{key} {value:8.1f}" for key, value in result.items())
        print(f"trim {'on ' if trim else 'off'}: {args.requests} small requests: {row}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
