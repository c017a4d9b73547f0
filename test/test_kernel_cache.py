"""numba's disk cache of the kernels: one folder per digest of all kernel sources (kernels call
each other across files, and numba only watches a function's own file), shared by checkouts."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from grasp_safety_ros.core.kernels import _jit
from grasp_safety_ros.core.method.ik import compiled_available

PACKAGE = Path(_jit.__file__).resolve().parents[2]


def test_digest_follows_every_kernel_file_and_not_the_location(tmp_path: Path) -> None:
    first, second = tmp_path / "a" / "kernels", tmp_path / "b" / "kernels"
    for folder in (first, second):
        folder.mkdir(parents=True)
        (folder / "caller.py").write_text("x = 1\n")
        (folder / "callee.py").write_text("y = 2\n")
    assert _jit.sources_digest(first) == _jit.sources_digest(second)  # another checkout
    (second / "callee.py").write_text("y = 3\n")  # only the callee's file changes
    assert _jit.sources_digest(first) != _jit.sources_digest(second)
    (second / "callee.py").write_text("y = 2\n")
    (second / "new_kernel.py").write_text("z = 0\n")  # a new file counts as a change
    assert _jit.sources_digest(first) != _jit.sources_digest(second)


def test_digest_follows_the_packed_types_handed_to_the_kernels(tmp_path: Path) -> None:
    """numba keys a NamedTuple argument by its field types only: swapping two fields of the same
    type in the module that defines it must select another cache folder."""
    kernels = tmp_path / "core" / "kernels"
    kernels.mkdir(parents=True)
    (kernels / "k.py").write_text("x = 1\n")
    packed = tmp_path / "core" / "method" / "packed.py"
    packed.parent.mkdir()
    packed.write_text("class C(NamedTuple):\n    lower: float\n    upper: float\n")
    (tmp_path / "core" / "method" / "plain.py").write_text("y = 1\n")
    before = _jit.sources_digest(kernels)
    (tmp_path / "core" / "method" / "plain.py").write_text("y = 2\n")  # no packed type
    assert _jit.sources_digest(kernels) == before
    packed.write_text("class C(NamedTuple):\n    upper: float\n    lower: float\n")
    assert _jit.sources_digest(kernels) != before
    assert packed in _jit.kernel_sources(kernels)
    mention = tmp_path / "core" / "method" / "mention.py"  # the word alone defines nothing
    mention.write_text('"""Uses a frozen dataclass, not a NamedTuple."""\n')
    assert mention not in _jit.kernel_sources(kernels)
    assert _jit.sources_digest(kernels) == _jit.sources_digest(kernels)
    derived = tmp_path / "core" / "method" / "derived.py"
    derived.write_text("class D(typing.NamedTuple):\n    a: float\n")
    assert derived in _jit.kernel_sources(kernels)
    real = {p.name for p in _jit.kernel_sources()}
    assert {"compiled.py", "effective_mass.py", "trajectory.py"} <= real or "packed.py" in real


def test_cache_folder_is_shared_and_old_ones_are_pruned(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    root = tmp_path / "cache"
    monkeypatch.setenv("GRASP_SAFETY_NUMBA_CACHE", str(root))
    kernels = tmp_path / "kernels"
    kernels.mkdir()
    other = root / "not_a_digest"
    other.mkdir(parents=True)
    os.utime(other, (0, 0))  # old, but not ours: never deleted
    used = []
    for version in range(_jit.KEPT_CACHES + 3):
        (kernels / "k.py").write_text(f"v = {version}\n")
        used.append(_jit.cache_folder(kernels))
        os.utime(used[-1], (1 + version, 1 + version))  # long unused, distinct ages
    assert all(path is not None and path.parent == root for path in used)
    _jit.prune(root)
    assert set(root.iterdir()) == {*used[-_jit.KEPT_CACHES :], other}
    for path in used[-_jit.KEPT_CACHES :]:
        os.utime(path)  # used just now, e.g. by a running process of another checkout
    for version in range(3):
        (kernels / "k.py").write_text(f"w = {version}\n")
        used.append(_jit.cache_folder(kernels))
    assert set(root.iterdir()) == {*used[-_jit.KEPT_CACHES - 3 :], other}  # all recent: kept


def test_unwritable_shared_root_falls_back_to_pycache(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("")
    monkeypatch.setenv("GRASP_SAFETY_NUMBA_CACHE", str(blocker / "cache"))
    kernels = tmp_path / "kernels"
    kernels.mkdir()
    (kernels / "k.py").write_text("v = 1\n")
    folder = _jit.cache_folder(kernels)
    assert folder is not None and folder.parent == kernels / "__pycache__" / "numba"


@pytest.mark.skipif(not compiled_available(), reason="numba is not installed")
def test_a_second_checkout_loads_the_first_ones_kernels(tmp_path: Path) -> None:
    """Two copies of the package at different paths, one cache root: the second compiles
    nothing (numba's cache hits, no misses)."""
    probe = (
        "import numpy as np\n"
        "from grasp_safety_ros.core.kernels.lie_group import _exp3 as exp3\n"
        "exp3(0.1, 0.2, 0.3, np.empty((3, 3)))\n"
        "print(sum(exp3.stats.cache_hits.values()), sum(exp3.stats.cache_misses.values()))\n"
    )
    env = {**os.environ, "GRASP_SAFETY_NUMBA_CACHE": str(tmp_path / "cache")}
    counts = []
    for checkout in ("one", "two"):
        copy = tmp_path / checkout
        shutil.copytree(
            PACKAGE, copy / "grasp_safety_ros", ignore=shutil.ignore_patterns("__pycache__")
        )
        completed = subprocess.run(
            [sys.executable, "-c", probe],
            env={**env, "PYTHONPATH": str(copy)},
            cwd=copy,
            capture_output=True,
            text=True,
            timeout=300,
            check=True,
        )
        counts.append(tuple(int(n) for n in completed.stdout.split()))
    assert counts[0] == (0, 1)  # compiled in the first checkout
    assert counts[1] == (1, 0)  # loaded in the second


LINK_AFTER_LOAD = """
import numba, numpy as np
from llvmlite import binding
from grasp_safety_ros.core.kernels.lie_group import _exp3 as exp3
parsed = []
real_parse = binding.parse_bitcode
binding.parse_bitcode = lambda data: parsed.append(len(data)) or real_parse(data)
direct = np.empty((3, 3))
exp3(0.1, 0.2, 0.3, direct)
on_load = len(parsed)

@numba.njit
def caller(out):
    exp3(0.1, 0.2, 0.3, out)

linked = np.empty((3, 3))
caller(linked)
(library,) = [result.library for result in exp3.overloads.values()]
print(sum(exp3.stats.cache_hits.values()), on_load, getattr(library, "linking_bitcode", None)
      is None and len(parsed) > on_load, direct.tobytes() == linked.tobytes())
"""


def run_with_cache(code: str, cache: Path) -> list[str]:
    """The words ``code`` prints, run in a fresh Python with its kernels cached in ``cache``."""
    return subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, "GRASP_SAFETY_NUMBA_CACHE": str(cache)},
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    ).stdout.split()


@pytest.mark.skipif(not compiled_available(), reason="numba is not installed")
def test_a_cached_kernel_loads_without_its_bitcode_and_still_links(tmp_path: Path) -> None:
    """A kernel loaded from the cache parses no LLVM bitcode (its machine code is loaded); a
    compilation in the same process that calls it parses its linking bitcode then, and the
    kernel it links computes the same bits as the loaded one."""
    runs = [run_with_cache(LINK_AFTER_LOAD, tmp_path / "cache") for _ in range(2)]
    assert runs[0][0] == "0" and runs[0][3] == "True"  # compiled in the first process
    assert runs[1] == ["1", "0", "True", "True"]  # loaded, no bitcode parsed until linked


FIRST_CLASS_AFTER_LOAD = """
import numba, numpy as np
from numba import types
from grasp_safety_ros.core.kernels.lie_group import _exp3 as exp3
direct = np.empty((3, 3))
exp3(0.4, 0.5, 0.6, direct)
(sig,) = exp3.signatures
result = exp3.overloads[sig]
addresses = [result.library.get_pointer_to_function(name) for name in (
    result.fndesc.llvm_cfunc_wrapper_name, result.fndesc.llvm_func_name)]

@numba.njit(types.none(types.FunctionType(types.none(*sig)), types.float64[:, ::1]))
def use(kernel, out):
    kernel(0.4, 0.5, 0.6, out)

passed = np.empty((3, 3))
use(exp3, passed)
print(sum(exp3.stats.cache_hits.values()), all(a > 0 for a in addresses),
      direct.tobytes() == passed.tobytes())
"""


@pytest.mark.skipif(not compiled_available(), reason="numba is not installed")
def test_a_cached_kernel_has_its_addresses_and_passes_as_a_first_class_function(
    tmp_path: Path,
) -> None:
    """A kernel loaded lazily (its bitcode not parsed) still gives numba the address of its
    C wrapper and of its own function (numba's load marks every symbol defined), so it can be
    handed to another kernel as a first-class function and computes the same bits."""
    runs = [run_with_cache(FIRST_CLASS_AFTER_LOAD, tmp_path / "cache") for _ in range(2)]
    assert runs[0] == ["0", "True", "True"]  # compiled in the first process
    assert runs[1] == ["1", "True", "True"]  # loaded from the cache in the second


NUMBA_INTERNALS_SHA256 = {
    "0.68.1": "e4e1b30d96fbf5aeba002e3d0f9a57e324470b17c506ef29a0901b9214ef58a8",
}
"""sha256 of the sources of the numba functions ``_jit._lazy_overload`` re-implements or
extends, per numba version of ``_jit.LAZY_LOADING_NUMBA``: a change there needs a re-read."""


def _numba_internals_digest() -> str:
    import hashlib
    import inspect

    from numba.core import codegen, compiler

    sources = [
        inspect.getsource(function)
        for function in (
            compiler.CompileResult._rebuild,
            codegen.CPUCodeLibrary._unserialize,
            codegen.CPUCodeLibrary._get_module_for_linking,
            codegen.JITCodeLibrary.get_pointer_to_function,
            codegen.JitEngine._load_defined_symbols,
        )
    ]
    return hashlib.sha256("".join(sources).encode()).hexdigest()


@pytest.mark.skipif(not compiled_available(), reason="numba is not installed")
def test_the_lazy_loading_runs_only_on_the_numba_it_was_checked_against() -> None:
    """``_jit._lazy_overload`` copies numba's rebuild of a cached kernel: it runs only for
    numba versions whose rebuild was read (their sources pinned here); any other version
    gets numba's own rebuild (``_lazy_overload`` returns None before touching anything)."""
    import numba

    from grasp_safety_ros.core.kernels import _jit

    assert set(_jit.LAZY_LOADING_NUMBA) == set(NUMBA_INTERNALS_SHA256)
    if numba.__version__ in _jit.LAZY_LOADING_NUMBA:
        assert _numba_internals_digest() == NUMBA_INTERNALS_SHA256[numba.__version__]


OTHER_NUMBA = """
from grasp_safety_ros.core.kernels import _jit
_jit.LAZY_LOADING_NUMBA = ()  # as for a numba the lazy loading was not checked against
import numpy as np
from grasp_safety_ros.core.kernels.lie_group import _exp3 as exp3
out = np.empty((3, 3))
exp3(0.4, 0.5, 0.6, out)
(result,) = exp3.overloads.values()
print(sum(exp3.stats.cache_hits.values()), type(result.library).__name__, out.tobytes().hex())
"""


@pytest.mark.skipif(not compiled_available(), reason="numba is not installed")
def test_another_numba_loads_cached_kernels_with_its_own_rebuild(tmp_path: Path) -> None:
    """A numba version not in LAZY_LOADING_NUMBA: the cached kernel is loaded by numba's own
    rebuild (its code library numba's class), the same machine code as the lazy load's.
    (Faking numba.__version__ would not do: numba's cache index rejects another version.)"""
    checked = OTHER_NUMBA.replace("_jit.LAZY_LOADING_NUMBA = ()", "")
    compiled, lazy, other = (
        run_with_cache(code, tmp_path / "cache") for code in (checked, checked, OTHER_NUMBA)
    )
    assert compiled[0] == "0" and lazy[0] == other[0] == "1"  # loaded from the cache twice
    assert lazy[1] == "LazyLinkingLibrary" and other[1] != "LazyLinkingLibrary"
    assert compiled[2] == lazy[2] == other[2]  # the same machine code
