"""``~/plan_grasps``'s wait for the upstream planner (ros/moveit/server.py) on a bare node:
the server alone, its planner absent or silent, no robot (no request reaches the ranking).

The oracles are the documented answers (docs/ros/moveit.md): COMMUNICATION_FAILURE when the
planner's service does not appear, TIMED_OUT when it does not answer (both after
moveit.planner_timeout_s, also on sim time without /clock), FAILURE naming an internal
error."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
from rclpy.context import Context
from rclpy.exceptions import InvalidHandle
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future

pytest.importorskip("moveit_msgs.msg", reason="moveit_msgs not built (make setup)")
from moveit_msgs.msg import MoveItErrorCodes
from moveit_msgs.srv import GraspPlanning
from test_ros_moveit import assert_refused

from grasp_safety_ros.ros.moveit.server import GraspPlanningServer
from grasp_safety_ros.ros.runtime.rclpy_private import NodeExecutor, join_callbacks

TIMEOUT_S = 0.5
"""moveit.planner_timeout_s of these tests [s]."""
ANSWER_WITHIN_S = 30.0
"""How long a test waits for an answer before calling the request lost [s] (the server
answers within TIMEOUT_S plus a wait step; the margin is for a loaded machine)."""


def not_reached(*_: Any, **__: Any) -> Any:
    raise AssertionError("no request of these tests reaches the ranking")


class Bare:
    """A node serving only ~/plan_grasps (on sim time, no /clock published: ``sim_time``),
    spun by the node's executor in a thread; a client; a planner service nobody spins (it
    never answers)."""

    def __init__(self, context: Context, sim_time: bool) -> None:
        self.node = Node(
            "plan_grasps_wait",
            context=context,
            parameter_overrides=[Parameter("use_sim_time", value=sim_time)],
        )
        self.node.declare_parameter("moveit.grasp_planner_service", "/silent_planner")
        self.node.declare_parameter("moveit.planner_timeout_s", TIMEOUT_S)
        self.node.declare_parameter("moveit.max_waiting", 32)
        self.server = GraspPlanningServer(
            self.node,
            rank=not_reached,
            snapshot=not_reached,
            report_error=lambda source, error: None,
            latest_trajectory=lambda: None,
            stopping=threading.Event(),
        )
        self.silent = Node("silent_planner", context=context)  # never spun: never answers
        self.silent.create_service(GraspPlanning, "/silent_planner", not_reached)
        self.executor = NodeExecutor(num_threads=2, context=context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        self.client_node = Node("plan_grasps_wait_client", context=context)
        self.client_executor = SingleThreadedExecutor(context=context)
        self.client_executor.add_node(self.client_node)
        self.client = self.client_node.create_client(
            GraspPlanning, "/plan_grasps_wait/plan_grasps"
        )
        assert self.client.wait_for_service(timeout_sec=ANSWER_WITHIN_S)

    def call(self) -> GraspPlanning.Response:
        return self.answer(self.client.call_async(GraspPlanning.Request(group_name="arm")))

    def answer(self, future: Future) -> GraspPlanning.Response:
        self.client_executor.spin_until_future_complete(future, timeout_sec=ANSWER_WITHIN_S)
        assert future.done(), f"no answer within {ANSWER_WITHIN_S} s: the request hangs"
        return future.result()

    def close(self) -> None:
        self.executor.shutdown()
        self.thread.join(timeout=10.0)
        join_callbacks(self.executor)
        for node in (self.node, self.silent, self.client_node):
            node.destroy_node()


@pytest.fixture()
def bare(context: Context) -> Iterator[Bare]:
    """On sim time without /clock."""
    harness = Bare(context, sim_time=True)
    yield harness
    harness.close()


@pytest.fixture()
def bare_wall(context: Context) -> Iterator[Bare]:
    """On the system clock."""
    harness = Bare(context, sim_time=False)
    yield harness
    harness.close()


def test_on_sim_time_without_clock_a_silent_planner_times_out(bare: Bare) -> None:
    """The node's ROS clock never advances (use_sim_time, no /clock): the wait, on the steady
    clock, still ends at moveit.planner_timeout_s (a ROS-time timer never fired: a hang)."""
    assert bare.node.get_clock().now().nanoseconds == 0  # sim time that does not advance
    started = time.monotonic()
    answer = bare.call()
    assert time.monotonic() - started >= TIMEOUT_S  # it waited for the answer, then gave up
    assert_refused(answer, MoveItErrorCodes.TIMED_OUT, "/silent_planner", "did not answer")


def test_on_sim_time_without_clock_an_absent_planner_is_refused(bare: Bare) -> None:
    bare.node.set_parameters([Parameter("moveit.grasp_planner_service", value="/nobody")])
    assert_refused(bare.call(), MoveItErrorCodes.COMMUNICATION_FAILURE, "/nobody", "not available")
    deadline = time.monotonic() + ANSWER_WITHIN_S
    while not bare.server._timer.is_canceled() and time.monotonic() < deadline:
        time.sleep(0.01)
    assert bare.server.waiting == 0
    assert bare.server._timer.is_canceled()  # the timer runs only while a request waits


def test_a_look_that_raises_answers_failure_and_the_node_keeps_serving(
    bare_wall: Bare, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The service's readiness raises once the wait has begun (in the server's timer): the
    request is answered FAILURE naming it, not left unanswered; later requests are served."""
    looks: list[str] = []

    class Broken:
        def service_is_ready(self) -> bool:
            looks.append("service_is_ready")
            if len(looks) == 1:  # the look when the wait begins: not ready
                return False
            raise InvalidHandle("client destroyed")  # a look of the timer

    real = bare_wall.server._client
    monkeypatch.setattr(bare_wall.server, "_client", lambda service: Broken())
    assert_refused(bare_wall.call(), MoveItErrorCodes.FAILURE, "internal error", "InvalidHandle")
    assert len(looks) == 2
    monkeypatch.setattr(bare_wall.server, "_client", real)
    assert_refused(bare_wall.call(), MoveItErrorCodes.TIMED_OUT, "/silent_planner")  # still served


def test_a_request_beyond_max_waiting_is_refused_at_once_and_the_others_still_wait(
    bare_wall: Bare,
) -> None:
    """moveit.max_waiting 2: with two requests waiting on the silent planner, a third is
    answered FAILURE naming the parameter while the two wait; they still time out."""
    bare_wall.node.set_parameters(
        [
            Parameter("moveit.max_waiting", value=2),
            Parameter("moveit.planner_timeout_s", value=10 * TIMEOUT_S),  # they outlast it
        ]
    )
    waiting = [
        bare_wall.client.call_async(GraspPlanning.Request(group_name="arm")) for _ in range(2)
    ]
    deadline = time.monotonic() + ANSWER_WITHIN_S
    while bare_wall.server.waiting < 2 and time.monotonic() < deadline:
        bare_wall.client_executor.spin_once(timeout_sec=0.01)
    assert bare_wall.server.waiting == 2
    third = bare_wall.call()
    assert_refused(third, MoveItErrorCodes.FAILURE, "moveit.max_waiting=2", "2 requests")
    assert not any(future.done() for future in waiting)  # refused while the two still waited
    for future in waiting:
        assert_refused(bare_wall.answer(future), MoveItErrorCodes.TIMED_OUT, "/silent_planner")
