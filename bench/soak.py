"""Soak and load benchmark of the grasp_safety node (not part of ``make test``).

Starts the node as its own process (the bundled params file: Baxter, the book; trajectory.dt_s
0.1 s unless --dt-s) and sends mixed requests through real rclpy service clients: good ones
(the book, 3 grasps x 21 samples, all analyses of the params file) and malformed ones (NaN
positions, zero quaternions, empty grasps, one-pose Paths, unknown frames, negative mass,
indefinite inertia, bogus metric strings, quality of the wrong length). A warm-up phase is
followed by phases with 1, 4 and 16 concurrent clients.

Prints, per phase and in total: requests sent / answered (ranked) / refused with a reason
naming the expected field / refused otherwise / busy answers / lost (sent, never answered),
latency median and p99; the node's memory after each phase: RSS, its peak (VmHWM), and what
the node reports on /diagnostics (C heap in use and free inside the RSS, glibc mallinfo2);
then the memory one request of N grasps x S samples needs (the rise of the peak RSS over
the RSS before it, --sizes). Targets: 0 lost, 0 crashes (the node still runs and exits 0
on SIGINT), RSS growth < 5 % after warm-up.

    .venv/bin/python bench/soak.py                    # 10^4 requests after a warm-up
    .venv/bin/python bench/soak.py --requests 500     # short run
    .venv/bin/python bench/soak.py --clients 16 --requests 2000   # one phase, 16 clients
"""

from __future__ import annotations

import argparse
import math
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "test"))

import rclpy  # noqa: E402
import yaml  # noqa: E402
from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import Point, Pose, PoseArray, PoseStamped, Quaternion  # noqa: E402
from grasp_safety_msgs.srv import RankGrasps  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from ros_domains import claim_ros_domain  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from grasp_safety_ros.paths import config_file  # noqa: E402

PARAMS = str(config_file("grasp_safety_node.yaml"))
BOOK = yaml.safe_load(config_file("book_baxter.yaml").read_text())
CLIENT_COUNTS = (1, 4, 16)
ANSWER_TIMEOUT_S = 120.0
"""A request not answered within this is counted lost."""


def _pose(item: dict[str, Any]) -> Pose:
    x, y, z = (float(v) for v in item["position_m"])
    qx, qy, qz, qw = (float(v) for v in item["quat_xyzw"])
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def good_request() -> RankGrasps.Request:
    """The book experiment; object_inertia.m = 0: the node's default object (the book)."""
    request = RankGrasps.Request()
    request.grasps = PoseArray(
        header=Header(frame_id="object"), poses=[_pose(g) for g in BOOK["grasps"]]
    )
    request.object_trajectory = PathMsg(
        header=Header(frame_id="base"),
        poses=[
            PoseStamped(header=Header(stamp=Time(sec=s)), pose=_pose(BOOK["trajectory"][key]))
            for s, key in ((0, "start"), (2, "goal"))
        ],
    )
    return request


def _set(obj: Any, **values: Any) -> Any:
    for key, value in values.items():
        setattr(obj, key, value)
    return obj


BAD: dict[str, tuple[Callable[[RankGrasps.Request], Any], str]] = {
    "nan_position": (lambda r: _set(r.grasps.poses[1].position, y=math.nan), "grasps.poses[1]"),
    "zero_quaternion": (
        lambda r: _set(r.grasps.poses[0].orientation, x=0.0, y=0.0, z=0.0, w=0.0),
        "grasps.poses[0].orientation",
    ),
    "empty_grasps": (lambda r: _set(r.grasps, poses=[]), "grasps.poses"),
    "one_pose_path": (
        lambda r: _set(r.object_trajectory, poses=r.object_trajectory.poses[:1]),
        "object_trajectory",
    ),
    "unknown_frame": (lambda r: _set(r.grasps.header, frame_id="wörld"), "grasps.header"),
    "negative_mass": (lambda r: _set(r.object_inertia, m=-1.0), "object_inertia.m"),
    "indefinite_inertia": (
        lambda r: _set(r.object_inertia, m=1.0, ixx=0.01, iyy=0.01, izz=0.01, ixy=0.05),
        "object_inertia",
    ),
    "bogus_metric": (lambda r: _set(r, metric="médian\u2603"), "metric"),
    "quality_length": (lambda r: _set(r, grasp_quality=[0.5]), "grasp_quality"),
    "inf_path": (
        lambda r: _set(r.object_trajectory.poses[1].pose.position, x=math.inf),
        "object_trajectory.poses[1]",
    ),
}


@dataclass
class Tally:
    """Outcomes of one phase."""

    sent: int = 0
    ranked: int = 0
    refused_with_reason: int = 0
    refused_otherwise: list[str] = field(default_factory=list)
    busy: int = 0
    lost: int = 0
    wrong_answer: int = 0
    latencies_s: list[float] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def add(self, other: Tally) -> None:
        self.sent += other.sent
        self.ranked += other.ranked
        self.refused_with_reason += other.refused_with_reason
        self.refused_otherwise += other.refused_otherwise
        self.busy += other.busy
        self.lost += other.lost
        self.wrong_answer += other.wrong_answer
        self.latencies_s += other.latencies_s

    def row(self, name: str) -> str:
        lat = sorted(self.latencies_s)
        median = statistics.median(lat) * 1e3 if lat else math.nan
        p99 = lat[min(len(lat) - 1, math.ceil(0.99 * len(lat)) - 1)] * 1e3 if lat else math.nan
        return (
            f"{name:<12} {self.sent:>7} {self.ranked:>7} {self.refused_with_reason:>8} "
            f"{len(self.refused_otherwise):>6} {self.busy:>5} {self.lost:>5} "
            f"{self.wrong_answer:>6} {median:>9.1f} {p99:>9.1f}"
        )


HEADER = (
    f"{'phase':<12} {'sent':>7} {'ranked':>7} {'refused':>8} {'other':>6} {'busy':>5} "
    f"{'lost':>5} {'wrong':>6} {'median ms':>9} {'p99 ms':>9}"
)


def rss_kib(pid: int, field: str = "VmRSS") -> int:
    """Resident set size (``VmRSS``) or its peak (``VmHWM``) of process ``pid`` [KiB]."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1])
    raise RuntimeError(f"no {field} for process {pid}")


def reset_peak(pid: int) -> None:
    """Reset the process's VmHWM to its current RSS (Linux: clear_refs 5)."""
    Path(f"/proc/{pid}/clear_refs").write_text("5")


class NodeMemory:
    """The node's memory figures: /proc, and the memory.* values of its /diagnostics."""

    def __init__(self, clients: Clients, pid: int) -> None:
        self.pid = pid
        self.reported: dict[str, str] = {}
        self._subscription = clients.nodes[0].create_subscription(
            DiagnosticArray, "/diagnostics", self._on_diagnostics, 10
        )

    def _on_diagnostics(self, message: DiagnosticArray) -> None:
        for status in message.status:
            if status.name.startswith("grasp_safety"):
                self.reported = {kv.key: kv.value for kv in status.values}

    def row(self, name: str) -> str:
        time.sleep(2.5)  # two diagnostics periods: the node trims its heap while idle
        heap = self.reported.get("memory.heap_in_use_kib", "nan")
        free = self.reported.get("memory.heap_free_kib", "nan")
        return (
            f"  memory after {name}: RSS {rss_kib(self.pid) / 1024:.1f} MiB, peak "
            f"{rss_kib(self.pid, 'VmHWM') / 1024:.1f} MiB, heap in use {float(heap) / 1024:.1f}"
            f" MiB, free in the heap {float(free) / 1024:.1f} MiB"
        )


def sized_request(grasps: int, samples: int, dt_s: float) -> RankGrasps.Request:
    """``grasps`` copies of the book's grasps on the book's motion lasting (samples - 1) dt."""
    request = good_request()
    poses = request.grasps.poses
    request.grasps.poses = [poses[k % len(poses)] for k in range(grasps)]
    duration_ns = round((samples - 1) * dt_s * 1e9)
    request.object_trajectory.poses[1].header.stamp = Time(
        sec=duration_ns // 1_000_000_000, nanosec=duration_ns % 1_000_000_000
    )
    return request


def memory_per_request(
    clients: Clients, memory: NodeMemory, sizes: Sequence[tuple[int, int]], dt_s: float
) -> None:
    """Per size: the rise of the node's peak RSS during one request over the RSS before it."""
    print("memory per request (peak RSS rise during one request):")
    for grasps, samples in sizes:
        time.sleep(2.5)  # trimmed after the previous one
        before = rss_kib(memory.pid)
        reset_peak(memory.pid)
        response, latency = call(clients.clients[0], sized_request(grasps, samples, dt_s))
        rise = rss_kib(memory.pid, "VmHWM") - before
        ok = response is not None and response.success
        print(
            f"  {grasps:>5} x {samples:<5} {'ranked' if ok else 'FAILED'} in {latency:6.2f} s:"
            f" +{rise / 1024:7.1f} MiB, {1024 * rise / (grasps * samples):6.0f} B per grasp-sample"
        )


class Clients:
    """``count`` service clients in one context, spun by one background executor."""

    def __init__(self, context: Context, count: int) -> None:
        self.nodes = [rclpy.create_node(f"soak_client_{k}", context=context) for k in range(count)]
        self.clients = [
            n.create_client(RankGrasps, "/grasp_safety/rank_grasps") for n in self.nodes
        ]
        self.executor = MultiThreadedExecutor(num_threads=4, context=context)
        for node in self.nodes:
            self.executor.add_node(node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        for client in self.clients:
            if not client.wait_for_service(timeout_sec=60.0):
                raise RuntimeError("service /grasp_safety/rank_grasps did not appear")

    def close(self) -> None:
        self.executor.shutdown()
        self.thread.join(timeout=10.0)  # stop spinning before the nodes are destroyed
        for node in self.nodes:
            node.destroy_node()


def call(client: Any, request: RankGrasps.Request) -> tuple[Any, float]:
    """Send one request; wait for the answer; return (response or None, latency [s])."""
    done = threading.Event()
    started = time.perf_counter()
    future = client.call_async(request)
    future.add_done_callback(lambda _: done.set())
    if not done.wait(ANSWER_TIMEOUT_S):
        future.cancel()
        return None, time.perf_counter() - started
    return future.result(), time.perf_counter() - started


def run_phase(
    clients: Clients, count: int, requests: int, seed: int, reference: list[int]
) -> Tally:
    """``requests`` mixed requests, shared among the first ``count`` clients in threads."""
    tally = Tally()
    shares = [requests // count + (1 if k < requests % count else 0) for k in range(count)]

    def worker(k: int) -> None:
        rng = random.Random(seed * 1000 + k)
        mine = Tally()
        for _ in range(shares[k]):
            request = good_request()
            kind = rng.choice(["good"] * len(BAD) + sorted(BAD))
            expected_field = ""
            if kind != "good":
                mutate, expected_field = BAD[kind]
                mutate(request)
            mine.sent += 1
            response, latency = call(clients.clients[k], request)
            if response is None:
                mine.lost += 1
                continue
            mine.latencies_s.append(latency)
            if response.success:
                mine.ranked += 1
                if kind != "good" or list(response.ranking.order) != reference:
                    mine.wrong_answer += 1
            elif response.message.startswith("busy:"):
                mine.busy += 1
            elif kind != "good" and response.message.startswith(expected_field):
                mine.refused_with_reason += 1
            else:
                mine.refused_otherwise.append(f"{kind}: {response.message}")
        with tally.lock:
            tally.add(mine)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(count)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return tally


def start_node(domain_id: int, log_dir: Path, dt_s: float) -> subprocess.Popen[str]:
    """The node process; its output goes to log_dir/node.log (a pipe could fill up)."""
    log_dir.mkdir(parents=True, exist_ok=True)
    env = {
        **os.environ,
        "ROS_DOMAIN_ID": str(domain_id),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "ROS_LOG_DIR": str(log_dir),
        "RCUTILS_COLORIZED_OUTPUT": "0",
    }
    with open(log_dir / "node.log", "w") as log:
        return subprocess.Popen(
            [
                *(sys.executable, "-m", "grasp_safety_ros.ros.node", "--ros-args"),
                *("--params-file", PARAMS, "-p", "use_joint_states_seed:=false"),
                *("-p", f"trajectory.dt_s:={float(dt_s)!r}"),
                *("--log-level", "warn"),
            ],
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
            text=True,
        )


def _arguments(argv: Sequence[str] | None) -> argparse.Namespace:
    """The command line (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--requests", type=int, default=10_000, help="requests after the warm-up (all phases)"
    )
    parser.add_argument("--warm-up", type=int, default=None, help="default: requests / 10")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--dt-s", type=float, default=0.1, help="node parameter trajectory.dt_s")
    parser.add_argument(
        "--clients",
        type=int,
        nargs="+",
        default=list(CLIENT_COUNTS),
        help="client counts, one phase each (the requests are shared among the phases)",
    )
    parser.add_argument(
        "--sizes",
        nargs="*",
        default=["10x101", "100x201", "1000x201", "1000x481"],
        help="grasps x samples of the memory-per-request figures (none: skip)",
    )
    return parser.parse_args(argv)


def _run_phases(
    clients: Clients,
    memory: NodeMemory,
    pid: int,
    args: argparse.Namespace,
    warm_up: int,
    reference: list[int],
) -> tuple[Tally, int]:
    """The warm-up, then one phase per client count sharing ``args.requests``, a table row
    each; returns the phases' tally and the node's RSS [KiB] after the warm-up."""
    total = Tally()
    print(HEADER)
    warm = run_phase(clients, min(4, max(args.clients)), warm_up, args.seed, reference)
    print(warm.row("warm-up"))
    print(memory.row("warm-up"))
    rss_warm = rss_kib(pid)
    reset_peak(pid)
    phases = len(args.clients)
    shares = [
        args.requests // phases + (1 if k < args.requests % phases else 0) for k in range(phases)
    ]
    for phase, (count, share) in enumerate(zip(args.clients, shares, strict=True)):
        tally = run_phase(clients, count, share, args.seed + 1 + phase, reference)
        print(tally.row(f"{count} client{'s' if count > 1 else ''}"))
        print(memory.row(f"{count} client{'s' if count > 1 else ''}"))
        total.add(tally)
    print(total.row("total"))
    return total, rss_warm


def main(argv: Sequence[str] | None = None) -> int:
    args = _arguments(argv)
    sizes = [tuple(int(v) for v in size.split("x")) for size in args.sizes]
    warm_up = args.warm_up if args.warm_up is not None else max(20, args.requests // 10)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    started = time.perf_counter()
    with claim_ros_domain() as claim:
        log_dir = Path(tempfile.mkdtemp(prefix="grasp_safety_soak_"))
        node = start_node(claim.domain_id, log_dir, args.dt_s)
        context = Context()
        rclpy.init(context=context, domain_id=claim.domain_id)
        clients: Clients | None = None
        try:
            clients = Clients(context, max(args.clients))
            memory = NodeMemory(clients, node.pid)
            rss_start = rss_kib(node.pid)
            first, _ = call(clients.clients[0], good_request())
            if first is None or not first.success:
                raise RuntimeError(f"the good request failed: {first}")
            reference = list(first.ranking.order)
            total, rss_warm = _run_phases(clients, memory, node.pid, args, warm_up, reference)
            rss_end = rss_kib(node.pid)
            rss_peak = rss_kib(node.pid, "VmHWM")
            if sizes:
                memory_per_request(clients, memory, sizes, args.dt_s)
                print(memory.row("them"))
            alive = node.poll() is None
        finally:
            if clients is not None:
                clients.close()
            rclpy.shutdown(context=context)
            node.send_signal(signal.SIGINT)
            try:
                node.wait(timeout=30)
            except subprocess.TimeoutExpired:
                node.kill()
                node.wait()
            log = (log_dir / "node.log").read_text(errors="replace")
    growth = (rss_end - rss_warm) / rss_warm
    print(
        f"node RSS: {rss_start / 1024:.1f} MiB at start, {rss_warm / 1024:.1f} MiB after "
        f"warm-up, {rss_end / 1024:.1f} MiB at the end ({100 * growth:+.2f} % after warm-up), "
        f"peak after warm-up {rss_peak / 1024:.1f} MiB"
    )
    print(
        f"node alive at the end: {alive}; exit status on SIGINT: {node.returncode}; "
        f"tracebacks in its log: {log.count('Traceback')} ({log_dir / 'node.log'})"
    )
    for line in sorted(set(total.refused_otherwise))[:10]:
        print(f"  refused otherwise: {line}")
    print(f"wall time {time.perf_counter() - started:.1f} s")
    ok = (
        total.lost == 0
        and not total.refused_otherwise
        and total.wrong_answer == 0
        and alive
        and node.returncode == 0
        and "Traceback" not in log
        and growth < 0.05
    )
    print("targets met" if ok else "TARGETS MISSED")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
