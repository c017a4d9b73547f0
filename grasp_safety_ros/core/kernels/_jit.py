"""The jit decorator of the kernels, numba's disk cache shared by checkouts and kept
consistent across kernel files, and Pinocchio's Taylor-branch thresholds.

The kernels are compiled without numba's runtime (``_nrt=False``): they allocate nothing
(every array, scratch included, comes from the caller, see ``ik.workspace``), so they need no
reference counting. With it, every array view and every array read from a tuple costs an
atomic increment and decrement; that was half the fused kernel's time (2.1x, measured).
Without numba (an optional accelerator) the decorator returns the function unchanged.

numba's disk cache: numba keys a cached function by its own file only, yet the kernels call
each other across files, and it keeps the cache beside the sources, so every checkout compiles
again (70-90 s). Here the cache of the kernels lives in one folder per digest of all kernel
sources and the numba version (``cache_folder``): in ``$GRASP_SAFETY_NUMBA_CACHE``, else
``$XDG_CACHE_HOME/grasp_safety_ros/numba`` (default ``~/.cache/...``), else, when that is not
writable, the kernels' ``__pycache__``. An edit of any kernel file (or of a core module defining
the packed NamedTuples they take) selects a new folder (nothing stale can load), and a second
checkout of the same sources loads the first one's kernels. The most recently used
``KEPT_CACHES`` folders, and any used within a day, are kept; older digest folders are deleted.
A kernel loaded from the cache skips numba's import of its lowering registries (every numpy
and Python implementation it knows, with scipy.linalg: about 1 s of start-up; ``KernelCache``):
only a kernel compiled in this process needs them, and numba's compiler loads them itself. Nor
does it parse the LLVM bitcode numba keeps beside the machine code for linking the kernel into
another compilation (7 ms per kernel, 50 ms of a ranking's start-up): that happens when such a
compilation first asks for it (``LazyLinkingLibrary``).
``announce_compiles`` prints a line per kernel compiled (first use on a machine). numba is
imported without its coverage support unless coverage is already running (``_import_numba``).
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import numpy as np


def _import_numba() -> Any:
    """numba, or None without it. numba imports the coverage package when installed (0.1-0.2 s
    of every start-up) to report compiled lines to a coverage run; when no coverage run has
    started in this process (it imports coverage first), numba is imported with coverage
    hidden, which it reads as not installed."""
    hide = "coverage" not in sys.modules
    if hide:
        sys.modules["coverage"] = None  # type: ignore[assignment]
    try:
        import numba
    except ImportError:  # pragma: no cover - exercised on machines without numba
        return None
    finally:
        if hide and sys.modules.get("coverage", 0) is None:
            del sys.modules["coverage"]
    return numba


numba = _import_numba()  # optional accelerator
if numba is not None:
    from numba.core import caching as _numba_caching
    from numba.core import event as _numba_event

KERNELS_FOLDER = Path(__file__).resolve().parent
KEPT_CACHES = 6
"""Digest folders kept in a cache root (one per kernel version recently used)."""
KEEP_RECENT_S = 86_400.0
"""A digest folder used within this time [s] is kept whatever their number (a running process
may load from it)."""
DIGEST_LENGTH = 20
_DIGEST_NAME = re.compile(f"[0-9a-f]{{{DIGEST_LENGTH}}}")
_DEFINES_NAMED_TUPLE = re.compile(r"^class \w+\(.*\bNamedTuple\b", re.M)
"""A class statement deriving from NamedTuple (a word in a docstring does not count; the
Makefile's kernel step selects the same files with the same pattern)."""


def kernel_sources(folder: Path = KERNELS_FOLDER) -> list[Path]:
    """The kernel files, and the core modules that define NamedTuples (the packed values handed
    to the kernels): numba keys a NamedTuple argument by its field types, not its field names,
    so a cached kernel would read a reordered field at its old place."""
    core = folder.parent
    typed = {path for path in core.rglob("*.py") if _DEFINES_NAMED_TUPLE.search(path.read_text())}
    return sorted(set(folder.glob("*.py")) | typed)


def sources_digest(folder: Path = KERNELS_FOLDER) -> str:
    """Digest of ``kernel_sources`` (paths relative to the core, contents) and numba's version."""
    digest = hashlib.sha256(numba.__version__.encode() if numba is not None else b"")
    for source in kernel_sources(folder):
        name = source.relative_to(folder.parent).as_posix().encode()
        digest.update(b"\0" + name + b"\0" + source.read_bytes())
    return digest.hexdigest()[:DIGEST_LENGTH]


def cache_roots(folder: Path = KERNELS_FOLDER) -> list[Path]:
    """Where the kernels' cache may live, in order of preference (module docstring)."""
    shared = os.environ.get("GRASP_SAFETY_NUMBA_CACHE")
    if not shared:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        shared = os.path.join(base, "grasp_safety_ros", "numba")
    return [Path(shared), folder / "__pycache__" / "numba"]


def cache_folder(folder: Path = KERNELS_FOLDER) -> Path | None:
    """The cache folder of the current kernel sources, created and marked as used, in the first
    writable root; older digest folders beyond KEPT_CACHES are deleted. None: none writable."""
    digest = sources_digest(folder)
    for root in cache_roots(folder):
        path = root / digest
        try:
            path.mkdir(parents=True, exist_ok=True)
            os.utime(path)
            probe = path / f".probe-{os.getpid()}"
            probe.write_bytes(b"")
            probe.unlink()
        except OSError:
            continue
        prune(root)
        return path
    return None


def prune(root: Path, keep: int = KEPT_CACHES) -> None:
    """Delete the digest folders of ``root`` beyond the ``keep`` most recently used, unless used
    within ``KEEP_RECENT_S``; nothing else in ``root`` is touched."""
    try:
        folders = sorted(
            (p for p in root.iterdir() if p.is_dir() and _DIGEST_NAME.fullmatch(p.name)),
            key=lambda p: p.stat().st_mtime,
        )
    except OSError:
        return
    now = time.time()
    for stale in folders[: max(len(folders) - keep, 0)]:
        try:
            if now - stale.stat().st_mtime > KEEP_RECENT_S:
                shutil.rmtree(stale, ignore_errors=True)
        except OSError:
            continue


def _share_the_cache() -> bool:
    """Route numba's cache of the kernel files to ``cache_folder()``; False where that cannot
    be done (no numba, no writable folder, numba's caching internals moved): no disk cache."""
    caching_impl = getattr(_numba_caching, "CacheImpl", None) or getattr(
        _numba_caching, "_CacheImpl", None
    )  # CacheImpl since numba 0.62
    found = cache_folder()
    if caching_impl is None or found is None:
        return False
    folder: Path = found  # narrowed for the locator's closure

    class KernelCacheLocator(
        _numba_caching._SourceFileBackedLocatorMixin, _numba_caching._CacheLocator
    ):
        """numba cache locator of the kernel files (module docstring)."""

        def __init__(self, py_func: Any, py_file: str) -> None:
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno

        def get_cache_path(self) -> str:
            os.makedirs(folder, exist_ok=True)  # another checkout may have pruned it
            return str(folder)

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> KernelCacheLocator | None:
            if Path(py_file).resolve().parent != KERNELS_FOLDER:
                return None  # not a kernel: numba's own locators take it
            return cls(py_func, py_file)

    caching_impl._locator_classes.insert(0, KernelCacheLocator)
    return True


def _kernel_cache_class() -> type | None:
    """numba's FunctionCache without the registry refresh on load (module docstring); None
    where numba's caching internals moved (then numba's own class is kept)."""
    base = getattr(_numba_caching, "FunctionCache", None)
    if base is None or not all(
        hasattr(base, name) for name in ("_load_overload", "_guard_against_spurious_io_errors")
    ):
        return None

    class KernelCache(base):  # type: ignore[misc, valid-type]
        """Loads a cached kernel without ``target_context.refresh()``: the object code needs
        numba's C helpers only, which its target context installs when created; compiling
        (a cache miss) refreshes the context in numba's compiler as before. The machine code
        is loaded as numba does, its linking bitcode parsed on demand (``_lazy_overload``)."""

        def load_overload(self, sig: Any, target_context: Any) -> Any:
            with self._guard_against_spurious_io_errors():
                if not self._enabled:
                    return None
                data = self._cache_file.load(self._index_key(sig, target_context.codegen()))
                if data is None:
                    return None
                lazy = _lazy_overload(target_context, data)
                return lazy if lazy is not None else self._impl.rebuild(target_context, data)

    return KernelCache


REBUILT_FIELDS = 9
"""The fields of a cached compile result (numba's ``CompileResult._reduce``): the library's
data, fndesc, env, signature, objectmode, lifted, typeann, reload_init, referenced_envs."""
LAZY_LOADING_NUMBA = ("0.68.1",)
"""numba versions whose ``CompileResult._rebuild`` and ``CPUCodeLibrary._unserialize`` this
module's lazy loading was checked against (``test_kernel_cache.py`` pins their sources); any
other version loads its kernels with numba's own rebuild (correct, 7 ms more per kernel)."""
_COMPILE_RESULT_FIELDS = frozenset(
    "typing_context target_context entry_point typing_error type_annotation signature "
    "objectmode lifted fndesc library call_helper environment metadata reload_init "
    "referenced_envs".split()
)
_LIBRARY_METHODS = (
    "enable_object_caching",
    "_set_compiled_object",
    "_finalize_final_module",
    "_get_module_for_linking",
    "get_pointer_to_function",
)


def _lazy_overload(target_context: Any, data: tuple[Any, ...]) -> Any:
    """numba's ``CompileResult._rebuild`` of a cached kernel, but its library a
    ``LazyLinkingLibrary``; None where the cached data is not the machine code and linking
    bitcode this knows (then numba's own rebuild loads it)."""
    from numba.core import compiler

    if numba is None or numba.__version__ not in LAZY_LOADING_NUMBA:
        return None
    if len(data) != REBUILT_FIELDS or len(data[0]) != 3:
        return None
    libdata, fndesc, env, signature, objectmode, lifted, typeann, reload_init, envs = data
    name, kind, payload = libdata
    codegen = target_context.codegen()
    engine: Any = getattr(codegen, "_engine", None)
    base = getattr(codegen, "_library_class", None)
    if (
        kind != "object"
        or reload_init
        or not isinstance(payload, tuple)
        or len(payload) != 2
        or not hasattr(engine, "_defined_symbols")
        or not all(hasattr(base, method) for method in _LIBRARY_METHODS)
        or set(getattr(compiler.CompileResult, "_fields", ())) != _COMPILE_RESULT_FIELDS
    ):
        return None  # not machine code, or numba's code generator moved: nothing done yet
    object_code, linking_bitcode = payload
    library = _lazy_library_class(base)(codegen, name)
    library.enable_object_caching()
    library._set_compiled_object(object_code)
    library.linking_bitcode = linking_bitcode
    engine._defined_symbols.add(fndesc.llvm_cpython_wrapper_name)  # what numba looks up
    library._finalize_final_module()  # the engine loads the machine code
    compile_result: Any = compiler.CompileResult  # a namedtuple subclass (mypy: untyped)
    result = compile_result(
        target_context=target_context,
        typing_context=target_context.typing_context,
        library=library,
        environment=env,
        entry_point=target_context.get_executable(library, fndesc, env),
        fndesc=fndesc,
        type_annotation=typeann,
        signature=signature,
        objectmode=objectmode,
        lifted=lifted,
        typing_error=None,
        call_helper=None,
        metadata=None,
        reload_init=reload_init,
        referenced_envs=envs,
    )
    for referenced in envs:
        codegen.set_env(referenced.env_name, referenced)
    return result


_LAZY_CLASSES: dict[Any, type] = {}


def _lazy_library_class(base: Any) -> type:
    """``base`` (numba's code library class) whose module for linking into another
    compilation is parsed from the cached bitcode when first asked for."""
    found = _LAZY_CLASSES.get(base)
    if found is not None:
        return found

    class LazyLinkingLibrary(base):  # type: ignore[misc]
        """A cached kernel's code library: the machine code loaded, the bitcode kept."""

        linking_bitcode: bytes | None = None
        _shared_module: Any  # numba's: the parsed module for linking, None until parsed

        def _get_module_for_linking(self) -> Any:
            if self._shared_module is None and self.linking_bitcode is not None:
                from llvmlite import binding

                self._shared_module = binding.parse_bitcode(self.linking_bitcode)
                self._codegen._engine._load_defined_symbols(self._shared_module)
                self.linking_bitcode = None
            return super()._get_module_for_linking()

        def get_pointer_to_function(self, name: str) -> Any:
            """numba's, after marking the kernel's symbols defined as its own load does
            (only the CPython wrapper's is marked at load): a cfunc or first-class use of a
            loaded kernel gets its address, not 0."""
            if self.linking_bitcode is not None and not self._codegen._engine.is_symbol_defined(
                name
            ):
                from numba.core.compiler_lock import global_compiler_lock

                with global_compiler_lock:
                    self._get_module_for_linking()
            return super().get_pointer_to_function(name)

    _LAZY_CLASSES[base] = LazyLinkingLibrary
    return LazyLinkingLibrary


_OPTIONS = {
    "cache": numba is not None and _share_the_cache(),
    "nogil": True,
    "error_model": "numpy",
    "_nrt": False,
    "fastmath": {"contract"},
}
"""numba.njit options of every kernel (module docstring). ``fastmath`` only lets LLVM fuse a
multiply and an add into one FMA (one rounding instead of two): no reassociation, NaN and
infinity keep their meaning."""


_KERNEL_CACHE = _kernel_cache_class() if _OPTIONS["cache"] else None


def _njit(function: Callable[..., Any], **options: Any) -> Callable[..., Any]:
    if numba is None:  # pragma: no cover
        return function
    dispatcher = numba.njit(**{**_OPTIONS, **options})(function)
    if _KERNEL_CACHE is not None:
        dispatcher._cache = _KERNEL_CACHE(function)
    return dispatcher


def _jit(function: Callable[..., Any]) -> Callable[..., Any]:
    return _njit(function)


def _jit_exact(function: Callable[..., Any]) -> Callable[..., Any]:
    """``_jit`` without the fused multiply-adds: for the few sums that must round as numpy's
    do (a difference quotient over samples 1e-6 apart amplifies one rounding 1e6-fold)."""
    return _njit(function, fastmath=False)


def _jit_inline(function: Callable[..., Any]) -> Callable[..., Any]:
    """``_jit`` for small helpers called per joint: inlined into the caller by numba, so the
    named tuples they take are not passed through a call each time."""
    return _njit(function, inline="always")


class TextSink(Protocol):
    """Where ``announce_compiles`` writes: a text stream's ``write`` and ``flush``."""

    def write(self, text: str, /) -> object: ...

    def flush(self) -> object: ...


_announcing: list[TextSink] = []


def announce_compiles(stream: TextSink | None = None) -> None:
    """From now on, write a line to ``stream`` (default stderr) for each kernel this process
    compiles, with its time; kernels loaded from the cache and the helpers compiled inside a
    kernel's compilation are not listed. Calling again changes the stream only."""
    stream = stream or sys.stderr
    if _announcing:
        _announcing[0] = stream
        return
    _announcing.append(stream)
    if numba is None:  # pragma: no cover
        return
    started: list[float] = []

    class Announcer(_numba_event.Listener):
        def on_start(self, event: Any) -> None:
            started.append(time.perf_counter())
            if len(started) == 1:
                function = event.data["dispatcher"].py_func
                name = f"{function.__module__.rpartition('.')[2]}.{function.__qualname__}"
                _announcing[0].write(f"compiling kernel {name} (first use on this machine) ...")
                _announcing[0].flush()

        def on_end(self, event: Any) -> None:
            seconds = time.perf_counter() - started.pop()
            if not started:
                _announcing[0].write(f" {seconds:.1f} s\n")
                _announcing[0].flush()

    _numba_event.register("numba:compile", Announcer())


_EPS = float(np.finfo(np.float64).eps)
_PREC2 = _EPS ** (1.0 / 3.0)  # Pinocchio's TaylorSeriesExpansion<double>::precision<2>()
_PREC3 = _EPS ** (1.0 / 4.0)  # ... precision<3>()
