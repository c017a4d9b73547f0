"""The node's heap trim (memory.IdleTrim) beside requests: never between the requests of a
stream, only once the node is idle and enough heap is free (a trim stalls the whole process
for its duration: bench/trim_latency.py, docs/ros/reliability.md)."""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest
from ros_node_harness import (
    NODE_PARAMETERS,
    NodeUnderTest,
    _localhost_only,  # noqa: F401  (autouse fixture)
    book_request,
)

from grasp_safety_ros.ros.runtime import memory
from grasp_safety_ros.ros.runtime.memory import IDLE_BEFORE_TRIM_S, TRIM_MIN_FREE_KIB, IdleTrim
from grasp_safety_ros.ros.service.ranking_job import FairComputeLock


class Clock:
    def __init__(self) -> None:
        self.now_s = 100.0

    def __call__(self) -> float:
        return self.now_s


def test_the_heap_is_trimmed_once_idle_and_only_with_enough_free() -> None:
    clock, trimmed, free_kib = Clock(), [], [TRIM_MIN_FREE_KIB]
    trim = IdleTrim(clock, lambda: free_kib[0], lambda: trimmed.append(clock.now_s) or True)
    lock = FairComputeLock()
    assert not trim.run(lock)  # no ranking yet: nothing freed
    for _ in range(50):  # a stream: a ranking ends every 0.1 s, the timer ticks between
        trim.ranking_done()
        clock.now_s += 0.1
        assert not trim.run(lock)
    clock.now_s += IDLE_BEFORE_TRIM_S
    assert lock.acquire(timeout=0.0)  # a ranking computes: not now
    assert not trim.run(lock)
    lock.release()
    assert trim.run(lock) and trimmed == [clock.now_s] and trim.trims == 1
    assert not trim.run(lock)  # once per idle period
    trim.ranking_done()
    free_kib[0] = TRIM_MIN_FREE_KIB - 1  # little freed: not worth a stall
    clock.now_s += IDLE_BEFORE_TRIM_S
    assert not trim.run(lock) and trim.trims == 1
    assert not lock.locked()


def test_no_trim_while_a_ranking_publishes_after_releasing_the_lock() -> None:
    """The node lets the compute lock go before it publishes the response; a diagnostics
    tick then (with an earlier ranking's heap pending and long idle) must not trim."""
    clock, trimmed = Clock(), []
    trim = IdleTrim(clock, lambda: TRIM_MIN_FREE_KIB, lambda: trimmed.append(1) or True)
    lock = FairComputeLock()
    trim.ranking_done()  # an earlier ranking freed heap ...
    clock.now_s += 2 * IDLE_BEFORE_TRIM_S  # ... and the node has been idle since
    assert lock.acquire(timeout=0.0)  # a request: the node's _rank
    trim.ranking_started()
    lock.release()  # computed; its response is being published
    assert not trim.run(lock) and trimmed == []
    trim.ranking_done()
    assert not trim.run(lock)  # just ended: not idle
    clock.now_s += IDLE_BEFORE_TRIM_S
    assert trim.run(lock) and trimmed == [1]


@pytest.fixture()
def trims(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """Every heap trim the node makes (the glibc call replaced by a recorder), by thread."""
    calls: list[str] = []

    def record() -> bool:
        calls.append(threading.current_thread().name)
        return True

    monkeypatch.setattr(memory, "release_free_heap", record)
    # A fresh node has about 1.5 MB of free heap, under TRIM_MIN_FREE_KIB: without this no
    # trim could ever run and the test below could not fail; now only the idle rule holds
    # trims back.
    monkeypatch.setattr(memory, "TRIM_MIN_FREE_KIB", 0)
    yield calls


def test_a_stream_of_small_requests_never_meets_a_trim(trims: list[str]) -> None:
    """The diagnostics timer at 100 Hz beside 40 back-to-back small requests: no trim runs
    between them (before IdleTrim one ran at nearly every tick after a ranking, holding the
    compute lock, and a request arriving then waited for it)."""
    harness = NodeUnderTest({**NODE_PARAMETERS, "diagnostics_period_s": 0.01})
    try:
        request = book_request()
        for _ in range(40):
            answer = harness.rank(request)
            assert answer.success, answer.message
        assert trims == []
    finally:
        harness.close()
