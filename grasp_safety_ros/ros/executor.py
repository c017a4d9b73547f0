"""The node's executor: service callbacks that can read their request's header.

rclpy hands a service callback the request only; the header (sequence number, reception time)
lets the node find the client that sent it among its service's introspection events, to stop
the ranking when that client leaves (ranking_job.ClientWatch).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from rclpy.exceptions import InvalidHandle
from rclpy.executors import MultiThreadedExecutor, await_or_execute

_CALLBACK = threading.local()
"""``header``: the request header of the service callback running in this thread (set by
NodeExecutor)."""


class NodeExecutor(MultiThreadedExecutor):
    """The node's executor: a MultiThreadedExecutor whose service callbacks can read their
    request's header (``request_header()``: sequence number, reception time).

    rclpy hands a service callback the request only; with the header the node finds the
    client that sent it among its service's introspection events, to stop the ranking when
    that client leaves (ClientWatch). In another executor the node falls back to the clients
    present at the request's arrival.
    """

    def _take_service(self, srv: Any) -> Callable[[], Any] | None:
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
