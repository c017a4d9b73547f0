"""The node process's memory: what /diagnostics reports, and giving freed heap back to the
system after large requests. Plain Python (ctypes on glibc; elsewhere the allocator figures
are left out and nothing is trimmed)."""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import threading
import time
import tracemalloc
from collections.abc import Callable
from typing import Protocol


class _MallInfo2(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena",
            "ordblks",
            "smblks",
            "hblks",
            "hblkhd",
            "usmblks",
            "fsmblks",
            "uordblks",
            "fordblks",
            "keepcost",
        )
    ]


def _libc() -> ctypes.CDLL | None:
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
    except OSError:
        return None
    if libc is None or not hasattr(libc, "mallinfo2") or not hasattr(libc, "malloc_trim"):
        return None  # not glibc >= 2.33
    libc.mallinfo2.restype = _MallInfo2
    libc.malloc_trim.argtypes = [ctypes.c_size_t]
    return libc


_LIBC = _libc()
_PAGE_KIB = os.sysconf("SC_PAGE_SIZE") // 1024


def memory_kib() -> dict[str, int]:
    """The process's resident set (``rss_kib``), and where available the C heap in use and
    free inside it (``heap_in_use_kib``, ``heap_free_kib``: glibc's mallinfo2, main arena and
    thread arenas, plus mmapped blocks in use) and the Python allocations traced by
    tracemalloc (``python_traced_kib``, ``python_traced_peak_kib``, when it traces) [KiB]."""
    with open("/proc/self/statm") as statm:
        result = {"rss_kib": int(statm.read().split()[1]) * _PAGE_KIB}
    if _LIBC is not None:
        info = _LIBC.mallinfo2()
        result["heap_in_use_kib"] = (info.uordblks + info.hblkhd) // 1024
        result["heap_free_kib"] = info.fordblks // 1024
    if tracemalloc.is_tracing():
        current, peak = tracemalloc.get_traced_memory()
        result["python_traced_kib"] = current // 1024
        result["python_traced_peak_kib"] = peak // 1024
    return result


def release_free_heap() -> bool:
    """Give the C heap's free pages back to the system (glibc malloc_trim(0)); True if some
    were. After a large request the heap keeps its high-water mark otherwise (freed, not
    returned): RSS then stayed hundreds of MB above what the node uses."""
    return bool(_LIBC.malloc_trim(0)) if _LIBC is not None else False


IDLE_BEFORE_TRIM_S = 2.0
"""The heap is trimmed only after this long without a ranking [s]."""
TRIM_MIN_FREE_KIB = 64 * 1024
"""...and only when at least this much of it is free [KiB] (64 MB)."""


class _Lock(Protocol):
    def acquire(self, timeout: float | None = None) -> bool: ...

    def release(self) -> None: ...


class IdleTrim:
    """When the node gives freed heap back (release_free_heap): once no ranking runs (from
    ranking_started to ranking_done, publication included), none has ended for
    IDLE_BEFORE_TRIM_S and at least TRIM_MIN_FREE_KIB are free, holding the compute lock.

    malloc_trim walks the whole heap and madvises every free page, holding each arena's lock:
    measured 0.2-0.5 ms per MB freed at load 12 on 2 cores (bench/trim_latency.py), during
    which another thread's malloc waits, and that thread holds the GIL (ctypes let it go for
    the trim): the whole process stalls, not only rankings, for as long as the trim. Trimming
    after every ranking (as before, at the next diagnostics tick) put a trim between the
    requests of a stream, and a request arriving then waited for it; now a stream of requests
    never meets one, small rankings (little freed) never cause one, and a request arriving
    during a trim waits at most for one trim of what was freed.
    """

    def __init__(
        self,
        clock: Callable[[], float] = time.monotonic,
        free_kib: Callable[[], int] = lambda: memory_kib().get("heap_free_kib", 0),
        trim: Callable[[], bool] = lambda: release_free_heap(),
    ) -> None:
        self._clock, self._free_kib, self._trim = clock, free_kib, trim
        self._lock = threading.Lock()
        self._pending = False
        self._running = 0
        self._last_ranking = clock()
        self.trims = 0

    def ranking_started(self) -> None:
        """A ranking started: no trim until it is done (ranking_done), also after it let the
        compute lock go while its response is published."""
        with self._lock:
            self._running += 1

    def ranking_done(self) -> None:
        """A ranking (started by ranking_started) ended: it freed heap; the node is not idle."""
        with self._lock:
            self._running = max(self._running - 1, 0)
            self._pending, self._last_ranking = True, self._clock()

    def _due(self) -> bool:
        """A ranking freed heap, none runs, and the last ended IDLE_BEFORE_TRIM_S ago (call
        holding self._lock)."""
        idle_s = self._clock() - self._last_ranking
        return self._pending and self._running == 0 and idle_s >= IDLE_BEFORE_TRIM_S

    def run(self, compute_lock: _Lock) -> bool:
        """Trim if due and no ranking computes (the lock is free now); True if it trimmed."""
        with self._lock:
            due = self._due()
        if not due or not compute_lock.acquire(timeout=0.0):
            return False
        try:
            with self._lock:
                if not self._due():
                    return False  # one started or ended meanwhile
                self._pending = False
            if self._free_kib() < TRIM_MIN_FREE_KIB:
                return False
            self._trim()
            self.trims += 1
            return True
        finally:
            compute_lock.release()
