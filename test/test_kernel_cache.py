"""numba's disk cache of the kernels is dropped when any kernel file changes (kernels call
each other across files, and numba only watches a function's own file)."""

from __future__ import annotations

from pathlib import Path

import pytest

from grasp_safety_ros.core.kernels._jit import SOURCES_STAMP, VALUE_TYPES, drop_stale_cache
from grasp_safety_ros.core.method.ik import compiled_available


def test_cache_is_dropped_when_any_kernel_file_changes(tmp_path: Path) -> None:
    (tmp_path / "caller.py").write_text("x = 1\n")
    (tmp_path / "callee.py").write_text("y = 2\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()

    def cached_files() -> set[str]:
        return {p.name for p in cache.iterdir() if p.suffix in (".nbi", ".nbc")}

    def fill_cache() -> None:
        for name in ("caller.f-1.py311.nbi", "caller.f-1.py311.1.nbc", "callee.g-1.py311.nbi"):
            (cache / name).write_bytes(b"compiled")

    fill_cache()
    assert drop_stale_cache(tmp_path)  # no digest yet: unknown sources, dropped
    assert cached_files() == set() and (cache / SOURCES_STAMP).is_file()
    fill_cache()
    assert not drop_stale_cache(tmp_path)  # sources unchanged: the cache stays
    assert len(cached_files()) == 3
    (tmp_path / "callee.py").write_text("y = 3\n")  # only the callee's file changes
    assert drop_stale_cache(tmp_path)
    assert cached_files() == set()  # the caller's cache went too
    (cache / "caller.cpython-311.pyc").write_bytes(b"bytecode")
    fill_cache()
    (tmp_path / "new_kernel.py").write_text("z = 0\n")  # a new file counts as a change
    assert drop_stale_cache(tmp_path)
    assert cached_files() == set() and (cache / "caller.cpython-311.pyc").is_file()


@pytest.mark.skipif(not compiled_available(), reason="numba is not installed")
def test_installed_kernels_are_stamped() -> None:
    from grasp_safety_ros.core.kernels import grasp  # imports _jit, which checks the cache

    assert not drop_stale_cache(Path(grasp.__file__).parent)  # up to date now


def test_moving_a_kernel_argument_type_drops_the_cache(tmp_path: Path) -> None:
    """numba's cache index names the module of each named-tuple argument: a change in
    method/packed.py (where they live) must drop the cache like a kernel edit."""
    kernels, packed = tmp_path / "kernels", tmp_path / VALUE_TYPES
    (kernels / "__pycache__").mkdir(parents=True)
    packed.parent.mkdir(parents=True)
    (kernels / "grasp.py").write_text("x = 1\n")
    packed.write_text("class ChainArrays: ...\n")
    drop_stale_cache(kernels)
    (kernels / "__pycache__" / "grasp.f-1.py311.nbi").write_bytes(b"compiled")
    assert not drop_stale_cache(kernels)
    packed.write_text("class ChainArrays: ...\nclass IKSettings: ...\n")
    assert drop_stale_cache(kernels)
    assert not (kernels / "__pycache__" / "grasp.f-1.py311.nbi").exists()
