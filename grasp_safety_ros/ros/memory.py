"""The node process's memory: what /diagnostics reports, and giving freed heap back to the
system after large requests. Plain Python (ctypes on glibc; elsewhere the allocator figures
are left out and nothing is trimmed)."""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import tracemalloc


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
