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
print(sum(exp3.stats.cache_hits.values()), on_load, len(parsed) > on_load,
      direct.tobytes() == linked.tobytes())
"""


@pytest.mark.skipif(not compiled_available(), reason="numba is not installed")
def test_a_cached_kernel_loads_without_its_bitcode_and_still_links(tmp_path: Path) -> None:
    """A kernel loaded from the cache parses no LLVM bitcode (its machine code is loaded); a
    compilation in the same process that calls it parses its linking bitcode then, and the
    kernel it links computes the same bits as the loaded one."""
    env = {**os.environ, "GRASP_SAFETY_NUMBA_CACHE": str(tmp_path / "cache")}
    runs = [
        subprocess.run(
            [sys.executable, "-c", LINK_AFTER_LOAD],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
            check=True,
        ).stdout.split()
        for _ in range(2)
    ]
    assert runs[0][0] == "0" and runs[0][3] == "True"  # compiled in the first process
    assert runs[1] == ["1", "0", "True", "True"]  # loaded, no bitcode parsed until linked
