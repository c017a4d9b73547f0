"""The node's executor: service callbacks that can read their request's header.

rclpy hands a service callback the request only; the header (sequence number, reception time)
lets the node find the client that sent it among its service's introspection events, to stop
the ranking when that client leaves (ranking_job.ClientWatch).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from rclpy.exceptions import InvalidHandle
from rclpy.executors import (
    Executor,
    ExternalShutdownException,
    MultiThreadedExecutor,
    await_or_execute,
)

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


SPIN_PERIOD_S = 0.1
"""How often the spin thread of main() looks whether it should stop [s]."""


def spin_until(executor: Executor, spinning: threading.Event) -> None:
    """Spin ``executor`` while ``spinning`` is set. Executor.shutdown destroys its guard
    condition at once, so it must not run while another thread waits in spin()
    (std::terminate at exit)."""
    try:
        while spinning.is_set() and executor.context.ok():
            executor.spin_once(timeout_sec=SPIN_PERIOD_S)
    except ExternalShutdownException:  # rclpy.shutdown() elsewhere: main() then stops
        pass


def join_started(thread: threading.Thread, timeout_s: float) -> None:
    """Join ``thread`` (at most ``timeout_s``) even when its ``start()`` was cut short: a
    signal handler's exception in the main thread can interrupt ``start()`` after the thread
    was launched but before it counts as started, and ``join()`` then raises ("cannot join
    thread before it is started") while the thread runs on. Waits for it to count as started;
    a thread never launched is given up after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            thread.join(timeout=max(0.0, deadline - time.monotonic()))
            return
        except RuntimeError:  # launched, not yet started (or never launched)
            if time.monotonic() >= deadline:
                return
            time.sleep(0.001)


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
