"""Faults around the node: a burst of requests beyond the service queue, a client killed in
the middle of a long request, SIGINT/SIGTERM during a ranking, a robot model replaced while
requests arrive, and bugs (unexpected exceptions) in topic and parameter callbacks."""

from __future__ import annotations

import copy
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import rclpy
from grasp_safety_msgs.msg import GraspRanking
from grasp_safety_msgs.srv import RankGrasps
from nav_msgs.msg import Path as PathMsg
from rcl_interfaces.srv import SetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from test_ros_node import (  # noqa: F401  (_localhost_only: autouse fixture)
    NODE_PARAMETERS,
    NodeUnderTest,
    _localhost_only,
    book_path,
    book_request,
    same_messages,
)
from test_ros_node_process import (  # noqa: F401  (ros_env: fixture)
    PARAMS,
    command,
    first_answer,
    ros_env,
)

from grasp_safety_ros.ros import node as node_module
from grasp_safety_ros.ros.node import EXECUTOR_THREADS

TEST_DIR = Path(__file__).resolve().parent


@pytest.fixture(scope="module")
def ros() -> Iterator[NodeUnderTest]:
    harness = NodeUnderTest(NODE_PARAMETERS)
    yield harness
    harness.close()


def handled(harness: NodeUnderTest) -> int:
    """Requests and topic inputs the node has answered or refused so far."""
    values = {kv.key: kv.value for kv in harness.node.diagnostics_status().values}
    return int(values["rankings"]) + int(values["refused_inputs"])


def same_ranking(got: GraspRanking, want: GraspRanking) -> bool:
    """Equal in every field but the stamp and the compute time."""
    return all(
        same_messages(getattr(got, f), getattr(want, f))
        for f in want.get_fields_and_field_types()
        if f not in ("header", "compute_time_s")
    )


def long_request(grasps: int = 400, duration_s: float = 200.0) -> RankGrasps.Request:
    """Many grasps on a long trajectory: seconds of work, whatever the machine."""
    request = book_request()
    request.grasps.poses = [copy.deepcopy(request.grasps.poses[i % 3]) for i in range(grasps)]
    request.object_trajectory = book_path(duration_s=duration_s)
    return request


def test_a_burst_beyond_the_service_queue_is_answered_in_full(ros: NodeUnderTest) -> None:
    # With the lock held every request waits service_busy_timeout_s and is answered busy;
    # EXECUTOR_THREADS are taken at a time, the others queue. The default service QoS (keep
    # the last 10) dropped the oldest of them silently.
    count = EXECUTOR_THREADS + 20
    assert ros.node._compute_lock.acquire(timeout=10.0)
    try:
        futures = [ros.rank_client.call_async(book_request()) for _ in range(count)]
        assert ros.spin_until(lambda: all(f.done() for f in futures), 60.0), (
            f"{sum(not f.done() for f in futures)} of {count} requests never answered"
        )
    finally:
        ros.node._compute_lock.release()
    messages = [f.result().message for f in futures]
    assert all(m.startswith("busy:") for m in messages), messages
    assert ros.rank(book_request()).success


DOOMED_CLIENT = """
import sys
sys.path.insert(0, sys.argv[1])
import rclpy
from grasp_safety_msgs.srv import RankGrasps
from test_ros_faults import long_request
rclpy.init()
node = rclpy.create_node("doomed_client")
client = node.create_client(RankGrasps, "/grasp_safety/rank_grasps")
assert client.wait_for_service(timeout_sec=30.0)
future = client.call_async(long_request())
print("sent", flush=True)
rclpy.spin_until_future_complete(node, future)
"""


def test_client_killed_in_the_middle_of_a_long_request(ros: NodeUnderTest, tmp_path: Path) -> None:
    results = ros.set_parameters(
        max_grasps=1000, max_total_samples=2_000_000, max_compute_time_s=4.0
    )
    assert all(r.successful for r in results), results
    try:
        before = handled(ros)
        env = {**os.environ, "ROS_DOMAIN_ID": str(ros.context.get_domain_id())}
        client = subprocess.Popen(
            [sys.executable, "-c", DOOMED_CLIENT, str(TEST_DIR)],
            env=env,
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            assert client.stdout is not None
            assert client.stdout.readline().strip() == "sent"
            busy_seen = ros.spin_until(lambda: ros.node._compute_lock.locked(), 30.0)
            assert busy_seen, "the long request did not start"
            client.kill()  # in the middle of the ranking
            client.wait(timeout=10)
        finally:
            if client.poll() is None:
                client.kill()
        # The node finishes (or abandons) the orphaned ranking and serves the next request.
        deadline = time.monotonic() + 60.0
        response = ros.rank(book_request())
        while response.message.startswith("busy:") and time.monotonic() < deadline:
            response = ros.rank(book_request())
        assert response.success, response.message
        assert handled(ros) >= before + 2  # the orphaned request was answered too
        assert ros.thread.is_alive()
    finally:
        results = ros.set_parameters(
            max_grasps=NODE_PARAMETERS["max_grasps"],
            max_total_samples=NODE_PARAMETERS["max_total_samples"],
            max_compute_time_s=NODE_PARAMETERS["max_compute_time_s"],
        )
        assert all(r.successful for r in results), results


def test_request_during_a_robot_model_change_uses_one_model(ros: NodeUnderTest) -> None:
    """tip_frame flips between right_gripper and right_wrist (each flip rebuilds the model)
    while requests keep arriving: every answer is exactly one of the two models' answers."""
    gripper = ros.rank(book_request())
    assert gripper.success, gripper.message
    (result,) = ros.set_parameters(tip_frame="right_wrist")
    assert result.successful, result.reason
    try:
        wrist = ros.rank(book_request())
        assert wrist.success, wrist.message
        assert not same_ranking(wrist.ranking, gripper.ranking)  # the test can tell them apart

        flips = 6
        context = ros.context
        setter = rclpy.create_node("fault_parameter_setter", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(setter)
        set_client = setter.create_client(SetParameters, "/grasp_safety/set_parameters")
        assert set_client.wait_for_service(timeout_sec=10.0)
        outcomes: list[bool] = []
        done = threading.Event()

        def flip() -> None:
            try:
                for k in range(flips):
                    frame = "right_gripper" if k % 2 == 0 else "right_wrist"
                    request = SetParameters.Request(
                        parameters=[Parameter("tip_frame", value=frame).to_parameter_msg()]
                    )
                    future = set_client.call_async(request)
                    executor.spin_until_future_complete(future, timeout_sec=60.0)
                    outcomes.append(bool(future.done() and future.result().results[0].successful))
            finally:
                done.set()

        thread = threading.Thread(target=flip)
        thread.start()
        answers = []
        while not done.is_set() or not answers:
            answers.append(ros.rank(book_request()))
        thread.join(timeout=60.0)
        setter.destroy_node()
        assert outcomes == [True] * flips
        for answer in answers:
            assert answer.success, answer.message
            assert same_ranking(answer.ranking, gripper.ranking) or same_ranking(
                answer.ranking, wrist.ranking
            )
        # the last flip set right_wrist: the node answers with that model now
        assert same_ranking(ros.rank(book_request()).ranking, wrist.ranking)
    finally:
        (result,) = ros.set_parameters(tip_frame="right_gripper")
        assert result.successful, result.reason


def test_bug_in_a_topic_callback_is_reported_not_fatal(
    ros: NodeUnderTest, monkeypatch: pytest.MonkeyPatch
) -> None:
    def broken(*args: Any, **kwargs: Any) -> None:
        raise RuntimeError("simulated bug")

    monkeypatch.setattr(node_module, "trajectory_from_msg", broken)
    publisher = ros.client.create_publisher(PathMsg, "/grasp_safety/object_trajectory", 10)
    try:
        assert ros.spin_until(lambda: publisher.get_subscription_count() > 0)
        publisher.publish(book_path())

        def last_error() -> str:
            values = {kv.key: kv.value for kv in ros.node.diagnostics_status().values}
            return values["last_error"]

        expected = "object_trajectory: internal error: RuntimeError: simulated bug"
        assert ros.spin_until(lambda: last_error() == expected), last_error()
    finally:
        ros.client.destroy_publisher(publisher)
        monkeypatch.undo()
    assert ros.rank(book_request()).success  # the executor still runs


def test_bug_in_a_parameter_change_is_refused_not_fatal(
    ros: NodeUnderTest, monkeypatch: pytest.MonkeyPatch
) -> None:
    def broken(*args: Any, **kwargs: Any) -> None:
        raise ValueError("Several frames match the filter - please specify the FrameType")

    monkeypatch.setattr(node_module, "build_robot", broken)
    (result,) = ros.set_parameters(tip_frame="right_wrist")
    monkeypatch.undo()
    assert not result.successful
    assert result.reason == (
        "internal error: ValueError: Several frames match the filter - please specify the "
        "FrameType"
    )
    response = ros.rank(book_request())  # the old model still answers
    assert response.success, response.message


# --- Signals -----------------------------------------------------------------------------------


@pytest.mark.parametrize("signal_number", [signal.SIGINT, signal.SIGTERM], ids=["INT", "TERM"])
def test_signal_during_a_ranking_shuts_down_cleanly(
    ros_env: dict[str, str],  # noqa: F811
    signal_number: int,
) -> None:
    process = subprocess.Popen(
        command(
            *("--params-file", PARAMS, "-p", "use_joint_states_seed:=false"),
            *("-p", "max_total_samples:=20000000"),
        ),
        env=ros_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    context = rclpy.context.Context()
    rclpy.init(context=context, domain_id=int(ros_env["ROS_DOMAIN_ID"]))
    try:
        client_node = rclpy.create_node("signal_test_client", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(client_node)
        client = client_node.create_client(RankGrasps, "/grasp_safety/rank_grasps")
        assert client.wait_for_service(timeout_sec=90.0), "service did not appear"
        warm = first_answer(executor, client, book_request(with_inertia=False), process)
        assert warm.success, warm.message
        # ~1000 grasps x 10001 samples: minutes of work, abandoned at the signal
        future = client.call_async(long_request(grasps=1000, duration_s=200.0))
        executor.spin_until_future_complete(future, timeout_sec=2.0)  # the ranking runs
        assert not future.done(), future.result()
        signalled = time.monotonic()
        process.send_signal(signal_number)
        try:
            _, stderr = process.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            _, stderr = process.communicate()
            pytest.fail(f"the node did not exit within 30 s of the signal:\n{stderr}")
        exit_time_s = time.monotonic() - signalled
        client_node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 0, stderr
    assert "Traceback" not in stderr, stderr
    assert exit_time_s < 20.0
