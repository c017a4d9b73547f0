"""The jit decorator of the kernels, numba's disk cache kept consistent across kernel files,
and Pinocchio's Taylor-branch thresholds.

The kernels are compiled without numba's runtime (``_nrt=False``): they allocate nothing
(every array, scratch included, comes from the caller, see ``ik.workspace``), so they need no
reference counting. With it, every array view and every array read from a tuple costs an
atomic increment and decrement; that was half the fused kernel's time (2.1x, measured).
Without numba (an optional accelerator) the decorator returns the function unchanged.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

try:  # optional accelerator
    import numba
except ImportError:  # pragma: no cover - exercised on machines without numba
    numba = None

SOURCES_STAMP = "kernels.sources"
"""File in the kernels' ``__pycache__`` holding the digest of the sources it was built from."""


VALUE_TYPES = Path("method") / "packed.py"
"""Where (below ``core``) the named tuples the kernels take are defined: numba's cache index
names their module, so a change there must drop the cache too."""


def drop_stale_cache(folder: Path | None = None) -> bool:
    """Delete numba's cached kernels (``*.nbi``, ``*.nbc``) in ``folder/__pycache__`` when any
    ``folder/*.py`` changed since they were written; returns whether it deleted them.

    numba invalidates a cached function only when its own file changes, but the kernels call
    each other across files: an edit in one file must recompile its callers in the others.
    ``folder/../method/packed.py`` (VALUE_TYPES), where the kernels' argument types live,
    counts as one of the sources.
    """
    folder = folder or Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for source in [*sorted(folder.glob("*.py")), folder.parent / VALUE_TYPES]:
        if source.is_file():
            digest.update(source.name.encode() + b"\0" + source.read_bytes())
    cache = folder / "__pycache__"
    stamp = cache / SOURCES_STAMP
    try:
        if stamp.read_text() == digest.hexdigest():
            return False
    except OSError:
        pass
    try:
        for pattern in ("*.nbi", "*.nbc"):
            for path in cache.glob(pattern):
                path.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest.hexdigest())
    except OSError:  # pragma: no cover - read-only install: numba caches elsewhere
        return False
    return True


if numba is not None:
    drop_stale_cache()


_OPTIONS = {
    "cache": True,
    "nogil": True,
    "error_model": "numpy",
    "_nrt": False,
    "fastmath": {"contract"},
}
"""numba.njit options of every kernel (module docstring). ``fastmath`` only lets LLVM fuse a
multiply and an add into one FMA (one rounding instead of two): no reassociation, NaN and
infinity keep their meaning."""


def _jit(function: Callable[..., Any]) -> Callable[..., Any]:
    if numba is None:  # pragma: no cover
        return function
    return numba.njit(**_OPTIONS)(function)


def _jit_inline(function: Callable[..., Any]) -> Callable[..., Any]:
    """``_jit`` for small helpers called per joint: inlined into the caller by numba, so the
    named tuples they take are not passed through a call each time."""
    if numba is None:  # pragma: no cover
        return function
    return numba.njit(**_OPTIONS, inline="always")(function)


_EPS = float(np.finfo(np.float64).eps)
_PREC2 = _EPS ** (1.0 / 3.0)  # Pinocchio's TaylorSeriesExpansion<double>::precision<2>()
_PREC3 = _EPS ** (1.0 / 4.0)  # ... precision<3>()
