"""The processes of bench/service.py: the node spinning in a thread of this process, the
client processes (bench/service_client.py) driven over a pipe, and a clock on the node's
service callback."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from workload import ArmWorkload

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "test"))  # a ROS domain of our own

from ros_domains import claim_ros_domain


@contextmanager
def running_node(
    arm: ArmWorkload, dt_s: float, overrides: dict[str, Any] | None = None
) -> Iterator[tuple[Any, dict[str, str]]]:
    """The node for ``arm`` spinning in a thread; yields (node, environment of its clients).

    ``overrides``: node parameters on top of the benchmark's (robot, seed, ``dt_s``). The
    node runs on a ROS domain claimed for it (``test/ros_domains.py``: never one a test suite
    or another bench on the machine uses; a random one was, and a test's node then served the
    bench's requests) with localhost discovery; the environment names both.
    Its middleware is set up as its console script sets it up (ros.runtime.middleware); the
    clients' is not (Fast DDS's defaults, as a user's client).
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.parameter import Parameter

    from grasp_safety_ros.ros.node import EXECUTOR_THREADS, GraspSafetyNode
    from grasp_safety_ros.ros.runtime.middleware import (
        PROFILE_VARIABLE,
        size_shared_memory_for_large_responses,
    )
    from grasp_safety_ros.ros.runtime.process import spin_until
    from grasp_safety_ros.ros.runtime.rclpy_private import NodeExecutor, join_callbacks

    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    claim = claim_ros_domain()
    domain_id = claim.domain_id
    context = Context()
    profile = size_shared_memory_for_large_responses()  # as the console script (node.main)
    rclpy.init(context=context, domain_id=domain_id)
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
    if profile is not None:  # the node's participant has it; the clients are a user's
        del os.environ[PROFILE_VARIABLE]
    executor = NodeExecutor(num_threads=EXECUTOR_THREADS, context=context)
    executor.add_node(node)
    spinning = threading.Event()
    spinning.set()
    thread = threading.Thread(target=spin_until, args=(executor, spinning), daemon=True)
    thread.start()
    try:
        yield node, {**os.environ, "ROS_DOMAIN_ID": str(domain_id)}
    finally:  # as the console script stops (node.run)
        spinning.clear()
        thread.join(timeout=10.0)
        executor.shutdown()
        join_callbacks(executor)
        node.destroy_node()
        rclpy.shutdown(context=context)
        claim.release()


class ClientProcess:
    """bench/service_client.py in its own process, waiting the ``wait`` way (see there)."""

    def __init__(self, wait: str, environment: dict[str, str]) -> None:
        self.process = subprocess.Popen(
            [sys.executable, str(Path(__file__).with_name("service_client.py")), "--wait", wait],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            env=environment,
            text=True,
        )
        ready = self._answer()
        if not ready["ready"]:
            self.close()
            raise RuntimeError("service /grasp_safety/rank_grasps not found")
        self.wait: str = ready["wait"]
        """How it waits: the requested way, or spin_once for events without EventsExecutor."""

    def _answer(self) -> dict[str, Any]:
        assert self.process.stdout is not None
        line = self.process.stdout.readline()
        if not line:
            raise RuntimeError(f"the client process ended (status {self.process.wait()})")
        return json.loads(line)

    def command(self, line: str) -> dict[str, Any]:
        """Send one command (``rank GRASPS`` or ``empty``); its answer."""
        assert self.process.stdin is not None
        self.process.stdin.write(line + "\n")
        self.process.stdin.flush()
        return self._answer()

    def close(self) -> None:
        try:
            if self.process.poll() is None and self.process.stdin is not None:
                self.process.stdin.write("quit\n")
                self.process.stdin.close()
            self.process.wait(timeout=20.0)
        except (OSError, subprocess.TimeoutExpired):
            self.process.kill()
            self.process.wait()


@contextmanager
def clients(environment: dict[str, str], *waits: str) -> Iterator[list[ClientProcess]]:
    """Client processes, one per way of waiting, closed at the end."""
    started: list[ClientProcess] = []
    try:
        for wait in waits:
            started.append(ClientProcess(wait, environment))
        yield started
    finally:
        for client in started:
            client.close()


class CallbackClock:
    """Records ``time.monotonic()`` at the start and end of each call of the node's
    ``~/rank_grasps`` callback (wrapped): with the client's clock readings at the call and
    at the response, a round trip splits into its legs."""

    def __init__(self, node: Any) -> None:
        self.calls: list[tuple[float, float]] = []
        (service,) = [s for s in node.services if s.srv_name.endswith("/rank_grasps")]
        callback = service.callback

        def timed(request: Any, response: Any) -> Any:
            started = time.monotonic()
            try:
                return callback(request, response)
            finally:
                self.calls.append((started, time.monotonic()))

        service.callback = timed
