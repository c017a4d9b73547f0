"""ros.runtime.rclpy_private: the private rclpy API the node relies on is still there and still
behaves so; each failure names what changed (read_only's service swap: test_ros_read_only.py)."""

from __future__ import annotations

import inspect
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import pytest

pytest.importorskip("rclpy")

from rcl_interfaces.msg import ParameterValue
from rcl_interfaces.srv import GetParameters
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.context import Context
from rclpy.executors import Executor, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.task import Future

from grasp_safety_ros.ros.runtime.rclpy_private import (
    NodeExecutor,
    join_callbacks,
    request_header,
)

TAKE_SERVICE_CHANGED = (
    "rclpy's Executor._take_service changed: ros/runtime/rclpy_private.py NodeExecutor overrides "
    "it to hand service callbacks their request header; port it to a public way of reading "
    "the header if rclpy has one now, or follow the new private signature"
)
POOL_CHANGED = (
    "rclpy's MultiThreadedExecutor no longer keeps its callback pool in ._executor: "
    "ros/runtime/rclpy_private.py join_callbacks waits on it at shut-down"
)


def test_the_overridden_take_service_is_rclpys() -> None:
    original = getattr(Executor, "_take_service", None)
    assert callable(original), TAKE_SERVICE_CHANGED
    assert list(inspect.signature(original).parameters) == ["self", "srv"], TAKE_SERVICE_CHANGED


def test_a_service_callback_in_node_executor_reads_its_request_header(context: Context) -> None:
    node = Node("rclpy_private_server", context=context)
    client_node = Node("rclpy_private_client", context=context)
    executor = NodeExecutor(num_threads=2, context=context)
    seen: list[Any] = []

    def echo(
        request: GetParameters.Request, response: GetParameters.Response
    ) -> GetParameters.Response:
        seen.append(request_header())
        response.values = [ParameterValue(string_value=n) for n in request.names]
        return response

    node.create_service(GetParameters, "echo", echo)
    client = client_node.create_client(GetParameters, "echo")
    executor.add_node(node)
    executor.add_node(client_node)
    try:
        assert client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(GetParameters.Request(names=["a"]))
        executor.spin_until_future_complete(future, timeout_sec=10.0)
        assert future.done(), TAKE_SERVICE_CHANGED
        assert [v.string_value for v in future.result().values] == ["a"], TAKE_SERVICE_CHANGED
        (header,) = seen
        assert header is not None, TAKE_SERVICE_CHANGED
        assert header.request_id.sequence_number >= 1, TAKE_SERVICE_CHANGED
        assert request_header() is None  # reset after the callback, not leaked to this thread
    finally:
        executor.shutdown()
        join_callbacks(executor)
        client_node.destroy_node()
        node.destroy_node()


def test_join_callbacks_waits_for_the_pool_rclpy_keeps(context: Context) -> None:
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    pool = getattr(executor, "_executor", None)
    assert isinstance(pool, ThreadPoolExecutor), POOL_CHANGED
    done = threading.Event()
    pool.submit(done.wait, 0.2)
    join_callbacks(executor)
    assert pool._shutdown, POOL_CHANGED
    executor.shutdown()


def test_a_coroutine_service_callback_leaves_no_header_to_its_thread(context: Context) -> None:
    """One executor thread: the coroutine callback suspends, a timer runs on that thread
    meanwhile and must not read the suspended request's header (nor may the coroutine, which
    could resume on another thread); the callback then answers."""
    node = Node("rclpy_private_async_server", context=context)
    client_node = Node("rclpy_private_async_client", context=context)
    executor = NodeExecutor(num_threads=1, context=context)
    release = Future()
    seen: dict[str, Any] = {}

    async def echo(
        request: GetParameters.Request, response: GetParameters.Response
    ) -> GetParameters.Response:
        seen["coroutine"] = request_header()
        await release
        response.values = [ParameterValue(string_value=n) for n in request.names]
        return response

    def tick() -> None:
        if "coroutine" in seen and not release.done():  # the callback is suspended
            seen["timer"] = request_header()
            release.set_result(None)

    group = ReentrantCallbackGroup()  # the timer runs while the callback is suspended
    node.create_service(GetParameters, "echo_async", echo, callback_group=group)
    node.create_timer(0.01, tick, callback_group=group)
    client = client_node.create_client(GetParameters, "echo_async")
    executor.add_node(node)
    executor.add_node(client_node)
    try:
        assert client.wait_for_service(timeout_sec=10.0)
        future = client.call_async(GetParameters.Request(names=["a"]))
        executor.spin_until_future_complete(future, timeout_sec=10.0)
        assert future.done(), TAKE_SERVICE_CHANGED
        assert [v.string_value for v in future.result().values] == ["a"], TAKE_SERVICE_CHANGED
        assert seen == {"coroutine": None, "timer": None}
    finally:
        executor.shutdown()
        join_callbacks(executor)
        client_node.destroy_node()
        node.destroy_node()
