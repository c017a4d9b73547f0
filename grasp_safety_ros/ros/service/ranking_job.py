"""How rankings share the node: a fair compute lock with time slices, and a watch on the
service's clients that stops a ranking nobody waits for. Plain Python (no rclpy).

Policy (docs/ros/reliability.md): one ranking computes at a time (the core's solvers keep
scratch data), in arrival order. A ranking that has computed for ``SLICE_S`` while others wait
hands the lock over at its next progress check (after a grasp, a batch of grasps, or an
analysis step) and queues behind them; so a small request arriving during a large one waits
for a slice, not for the whole ranking, and long rankings share the CPU in turn. Time spent
queued does not count against ``max_compute_time_s``; a request that cannot get the lock
within ``service_busy_timeout_s`` is answered busy.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ...core.method.ranking import Ranking
from ...core.method.results import SAMPLE_ARRAYS
from ...core.model.inertia import ObjectInertia
from ...core.pipeline import Progress
from ..parameters import NodeSettings
from ..robot.bundle import RobotBundle
from .errors import (
    ClientGoneError,
    ComputeTimeExceededError,
    ShuttingDownError,
)

SLICE_S = 0.2
"""Compute time a ranking keeps the lock for while others wait [s]."""
CLIENT_CHECK_PERIOD_S = 0.5
"""How often a running ranking looks for its clients in the ROS graph [s]."""
CLIENT_ABSENT_CHECKS = 2
"""Consecutive checks that must find the clients gone before the ranking stops."""


class FairComputeLock:
    """A FIFO lock whose holder can hand it to the waiters and queue again (``share``).

    ``acquire(timeout)``/``release()``/``locked()`` as threading.Lock's; waiters are served in
    arrival order. ``stop()`` wakes every waiter, which then gives up (acquire returns False).
    """

    def __init__(self) -> None:
        self._condition = threading.Condition()
        self._queue: deque[object] = deque()
        self._held = False
        self._stopped = False
        self._since = time.perf_counter()  # when the holder got it

    def acquire(self, timeout: float | None = None) -> bool:
        """Wait (at most ``timeout`` s; None: until it is free or stopped) for the lock in
        arrival order; False on timeout or stop."""
        return self._acquire(timeout, give_up_on_stop=True)

    def _acquire(self, timeout: float | None, give_up_on_stop: bool) -> bool:
        ticket = object()
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._condition:
            self._queue.append(ticket)
            while self._held or self._queue[0] is not ticket:
                remaining = None if deadline is None else deadline - time.monotonic()
                if (self._stopped and give_up_on_stop) or (
                    remaining is not None and remaining <= 0.0
                ):
                    self._queue.remove(ticket)
                    self._condition.notify_all()
                    return False
                self._condition.wait(remaining)
            self._queue.popleft()
            self._held = True
            self._since = time.perf_counter()
            self._condition.notify_all()
            return True

    def release(self) -> None:
        with self._condition:
            self._held = False
            self._condition.notify_all()

    def locked(self) -> bool:
        with self._condition:
            return self._held

    def waiting(self) -> int:
        """Requests queued for the lock."""
        with self._condition:
            return len(self._queue)

    def stop(self) -> None:
        """Make every waiter (now and later) give up: for shut-down."""
        with self._condition:
            self._stopped = True
            self._condition.notify_all()

    def share(self, slice_s: float = SLICE_S) -> float:
        """Called by the holder between steps: when others wait and it has held the lock for
        ``slice_s``, hand it over and queue again; return the seconds spent queued (0 when it
        kept the lock). After a stop it keeps the lock (the caller is about to give up)."""
        with self._condition:
            if not self._queue or self._stopped or time.perf_counter() - self._since < slice_s:
                return 0.0
        started = time.perf_counter()
        self.release()
        self._acquire(None, give_up_on_stop=False)  # its turn comes: the others give up
        return time.perf_counter() - started


class ClientWatch:
    """Whether the client that sent a request is still in the ROS graph.

    ``clients()`` gives the GIDs of the service's clients now. With ``identify`` (a callable
    giving the request's client GID once known: the node learns it from its service's
    introspection events when it runs in NodeExecutor), the request is orphaned once that
    client is missing from the graph for CLIENT_ABSENT_CHECKS consecutive checks,
    CLIENT_CHECK_PERIOD_S apart; while it is not known, nothing is judged. Without
    ``identify``, the clients present at the request's arrival stand in: the request is
    orphaned once none of them is left. A client that exits (or is stopped by SIGINT/SIGTERM)
    leaves the graph at once; one killed with SIGKILL when the middleware's liveliness lease
    runs out (Fast DDS: 20 s). The graph is read only by checks, so a request shorter than
    CLIENT_CHECK_PERIOD_S costs nothing (identified) or one graph read (not).
    """

    def __init__(
        self,
        clients: Callable[[], Iterable[bytes]],
        identify: Callable[[], bytes | None] | None = None,
    ) -> None:
        self._clients = clients
        self._identify = identify
        self._client: bytes | None = None
        self._at_arrival = frozenset() if identify is not None else frozenset(clients())
        self._next_check = time.monotonic() + CLIENT_CHECK_PERIOD_S
        self._absent = 0

    def gone(self) -> bool:
        """True once the request's client has left (checked at most every
        CLIENT_CHECK_PERIOD_S; False in between)."""
        if time.monotonic() < self._next_check:
            return False
        self._next_check = time.monotonic() + CLIENT_CHECK_PERIOD_S
        if self._identify is not None and self._client is None:
            self._client = self._identify()
            if self._client is None:
                return False
        present = set(self._clients())
        if self._client is not None:
            missing = self._client not in present
        else:
            missing = bool(self._at_arrival) and self._at_arrival.isdisjoint(present)
        self._absent = self._absent + 1 if missing else 0
        return self._absent >= CLIENT_ABSENT_CHECKS


@dataclass(frozen=True)
class Snapshot:
    """Consistent view of the state one ranking uses."""

    settings: NodeSettings
    bundle: RobotBundle | None
    joint_state: tuple[Sequence[str], Sequence[float]] | None
    inertia_override: ObjectInertia | None


def labels_only(ranking: Ranking) -> Ranking:
    """``ranking`` without its per-sample arrays and postures: what the markers read (index,
    name, feasibility, score, order, metric)."""
    arrays = dict.fromkeys(SAMPLE_ARRAYS, np.empty(0))
    return replace(
        ranking,
        postures=(),
        evaluations=tuple(
            replace(e, **arrays)  # type: ignore[arg-type]  # arrays: the per-sample fields
            for e in ranking.evaluations
        ),
    )


def progress_check(
    settings: NodeSettings,
    stopping: threading.Event,
    lock: FairComputeLock,
    client_watch: ClientWatch | None,
) -> Progress:
    """The pipeline's progress hook (core.pipeline.Progress): abandons the work when the node shuts
    down, after max_compute_time_s of computing (time queued behind other rankings not
    counted), or when the request's clients are gone; between steps it shares the compute
    lock with waiting requests (FairComputeLock.share)."""
    deadline = time.perf_counter() + settings.max_compute_time_s

    def check(_stage: str, done: int, total: int) -> None:
        nonlocal deadline
        if done >= total:
            return
        if stopping.is_set():
            raise ShuttingDownError(
                f"ranking abandoned after {done} of {total} steps: the node is shutting down"
            )
        if time.perf_counter() > deadline:
            raise ComputeTimeExceededError(
                f"ranking abandoned after {done} of {total} steps: longer than "
                f"max_compute_time_s={settings.max_compute_time_s:g} s; send fewer grasps or "
                "raise trajectory.dt_s"
            )
        if client_watch is not None and client_watch.gone():
            raise ClientGoneError(
                f"ranking abandoned after {done} of {total} steps: its client left"
            )
        deadline += lock.share()

    return check
