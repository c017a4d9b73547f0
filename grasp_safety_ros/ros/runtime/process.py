"""The node's process: start-up, signals, the spin thread and an orderly shut-down."""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable
from types import FrameType
from typing import Protocol, cast

import rclpy
import rclpy.utilities
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from ..service.errors import StartupError
from .rclpy_private import NodeExecutor, join_callbacks

SPIN_PERIOD_S = 0.1
"""How often the spin thread of main() looks whether it should stop [s]."""
SETTLE_S = 2.0
"""At shut-down, how long the executor keeps spinning for the suspended requests to be
answered [s] (each sees the shut-down within its wait's step, moveit/server.py)."""
SETTLE_STEP_S = 0.01
"""How often settle looks whether the suspended requests are answered [s]."""


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


class ServedNode(Protocol):
    """What run_node needs of a node (GraspSafetyNode)."""

    @property
    def abandoned_rankings(self) -> int: ...

    def wait_for_robot(self, executor: Executor) -> None: ...

    def abandon_rankings(self) -> None: ...

    @property
    def requests_waiting(self) -> int: ...

    def destroy_node(self) -> None: ...


def settle(node: ServedNode, timeout_s: float, executor: Executor | None = None) -> None:
    """Wait (at most ``timeout_s``) until none of ``node``'s requests is suspended: a service
    callback that awaits another node is resumed only by a spinning executor. ``executor``:
    spin it here (no spin thread spins it: a signal during start-up); None: another thread
    spins it."""
    deadline = time.monotonic() + timeout_s
    try:
        while node.requests_waiting and time.monotonic() < deadline:
            if executor is not None and executor.context.ok():
                executor.spin_once(timeout_sec=SETTLE_STEP_S)
            else:
                time.sleep(SETTLE_STEP_S)
    except ExternalShutdownException:  # rclpy.shutdown() elsewhere: nothing resumes them
        pass


class _Stop(Exception):  # noqa: N818  (a signal, not an error)
    """SIGINT or SIGTERM arrived: raised in the main thread by the node's signal handler."""


def _raise_stop(signal_number: int, frame: FrameType | None) -> None:
    raise _Stop(signal.Signals(signal_number).name)


def run_node(
    make_node: Callable[[], ServedNode], name: str, threads: int, args: list[str] | None
) -> int:
    """Run the node ``make_node()`` makes until SIGINT or SIGTERM, its executor on ``threads``
    threads. Exit status 1 on a start-up error (one log line).

    The node handles the signals itself (rclpy's handlers would shut the context down at
    once, under the running callbacks: their responses and log lines then failed with "Failed
    to publish log message to rosout" and "exception was never retrieved"): the executor spins
    in a thread, the main thread waits; at a signal the rankings are abandoned, their requests
    answered (a suspended request while the executor still spins: settle), the callbacks
    joined, the node destroyed, and one last line logged.
    """
    logger = rclpy.logging.get_logger(name)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RuntimeError as error:  # rclpy's RCLError: bad --ros-args or params file
        first_line = str(error).strip().splitlines()[0] if str(error).strip() else "rcl error"
        logger.error(f"start-up failed: {first_line}")
        return 1
    previous = {n: signal.signal(n, _raise_stop) for n in (signal.SIGINT, signal.SIGTERM)}
    node: ServedNode | None = None
    executor: MultiThreadedExecutor | None = None
    spinner: threading.Thread | None = None
    spinning = threading.Event()
    spinning.set()
    status, reason = 0, "the context was shut down"
    try:
        node = make_node()
        executor = NodeExecutor(num_threads=threads)
        executor.add_node(cast(Node, node))  # a ServedNode is an rclpy Node
        node.wait_for_robot(executor)
        spinner = threading.Thread(
            target=spin_until, args=(executor, spinning), name="executor", daemon=True
        )
        spinner.start()
        spinner.join()  # interrupted by the signal handler's exception
    except StartupError as error:
        logger.error(f"start-up failed: {error}")
        status = 1
    except _Stop as stop:
        reason = str(stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for number, handler in previous.items():  # a second signal no longer interrupts
            signal.signal(number, signal.SIG_IGN if handler is _raise_stop else handler)
        if node is not None:
            node.abandon_rankings()
            settle(node, SETTLE_S, executor if spinner is None else None)  # spun here or there
        if executor is not None:
            spinning.clear()  # the spin thread leaves its wait before the executor goes
            if spinner is not None:  # its start may have been cut short by the signal
                join_started(spinner, 10.0)
            executor.shutdown()
            join_callbacks(executor)
        abandoned = 0 if node is None else node.abandoned_rankings  # None: signal at start-up
        if node is not None:
            node.destroy_node()
        if status == 0:
            logger.info(
                f"shut down ({reason}); {abandoned} ranking(s) abandoned, their requests answered"
            )
        rclpy.try_shutdown()
        rclpy.utilities.get_default_context().destroy()  # the middleware's participant goes
    return status
