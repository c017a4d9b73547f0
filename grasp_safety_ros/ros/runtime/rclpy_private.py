"""Every use of private rclpy API in the node, in one place; each fails loudly in a test if
rclpy changes under it.

- NodeExecutor overrides ``Executor._take_service`` so a synchronous service callback can read
  its request's header (request_header: sequence number, reception time); with it the node finds
  the client that sent the request among its service's introspection events, to stop the
  ranking when that client leaves (service.ranking_job.ClientWatch). Public replacement: a
  service callback that receives the request header (rclpy hands it the request only).
  Checked by test_ros_rclpy_private.py.
- join_callbacks joins the executor's callback thread pool (``MultiThreadedExecutor._executor``)
  because Jazzy's ``Executor.shutdown`` does not wait for outstanding callbacks as documented.
  Public replacement: an ``Executor.shutdown`` that waits. Checked by test_ros_rclpy_private.py.
- replace_service_callback swaps the callback of one of the node's own services
  (``Node.services``, ``Service.callback``), used by read_only.py on ``set_parameters``.
  Public replacement: a hook on the parameter services that can answer a request
  (``add_pre_set_parameters_callback`` cannot: rclpy refuses the list it empties). Checked by
  test_ros_read_only.py.
"""

from __future__ import annotations

import inspect
import threading
from collections.abc import Callable
from typing import Any, cast

from rclpy.exceptions import InvalidHandle
from rclpy.executors import MultiThreadedExecutor, await_or_execute
from rclpy.node import Node

_CALLBACK = threading.local()
"""``header``: the request header of the service callback running in this thread (set by
NodeExecutor)."""


class NodeExecutor(MultiThreadedExecutor):
    """The node's executor: a MultiThreadedExecutor whose service callbacks can read their
    request's header (``request_header()``: sequence number, reception time).

    rclpy hands a service callback the request only; with the header the node finds the
    client that sent it among its service's introspection events, to stop the ranking when
    that client leaves (ClientWatch). In another executor the node falls back to the clients
    present at the request's arrival. The header is for synchronous callbacks only: a
    coroutine callback (~/plan_grasps) may suspend, leaving its header to the next callback of
    its thread, and resume on another thread, so it is taken by rclpy's own code (no header).
    """

    def _take_service(self, srv: Any) -> Callable[[], Any] | None:
        if inspect.iscoroutinefunction(srv.callback):  # rclpy's own, no header (see above)
            take = super()._take_service(srv)  # type: ignore[no-untyped-call]
            return cast(Callable[[], Any] | None, take)
        try:
            with srv.handle:
                request, header = srv.handle.service_take_request(srv.srv_type.Request)
        except InvalidHandle:  # destroyed meanwhile: no work (as rclpy's own)
            return None
        if header is None:
            return None

        async def execute() -> None:
            _CALLBACK.header = header
            try:
                response = await await_or_execute(srv.callback, request, srv.srv_type.Response())
            finally:
                _CALLBACK.header = None
            srv.send_response(response, header)

        return execute


def request_header() -> Any:
    """The rmw service info of the request whose callback runs in this thread, or None."""
    return getattr(_CALLBACK, "header", None)


def join_callbacks(executor: MultiThreadedExecutor) -> None:
    """Wait until every callback the executor started has returned (its response sent).

    Jazzy's ``Executor.shutdown`` is documented to wait for outstanding callbacks but does not
    (its wait is skipped once the shut-down flag is set), so a service callback abandoned at
    shut-down could still be sending its response while the node is destroyed, which crashed
    the process. The callbacks run on the executor's thread pool; joining it waits for them
    (an abandoned ranking stops within one grasp).
    """
    pool = getattr(executor, "_executor", None)  # rclpy's ThreadPoolExecutor of callbacks
    if pool is not None:
        pool.shutdown(wait=True)


def replace_service_callback(
    node: Node, service_name: str, wrap: Callable[[Callable[[Any, Any], Any]], Any]
) -> bool:
    """Replace the callback of ``node``'s service ``service_name`` (fully qualified) by
    ``wrap(current callback)``; False (nothing replaced) when the node has no such service."""
    service = next((s for s in node.services if s.service_name == service_name), None)
    if service is None:
        return False
    service.callback = wrap(service.callback)
    return True
