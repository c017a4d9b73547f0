"""Prune the per-machine cache of built upstream interfaces, as the kernels' cache is pruned
(grasp_safety_ros/core/kernels/_jit.py).

scripts/build_interfaces.sh builds the upstream subsets once per key (a digest of what the
build depends on) into CACHE_ROOT/<key>/ (~/.cache/grasp_safety_ros/interfaces), marks the key
it installs from as used (its folder's mtime) and then calls this script:
  python scripts/interface_cache.py CACHE_ROOT
The KEPT_KEYS most recently used key folders stay, and any used within KEEP_RECENT_S (another
checkout may be installing from it); a build's temporary folder (``.tmp.*``, left by an
interrupted build) goes once older than KEEP_RECENT_S. Nothing else in CACHE_ROOT is touched.
A venv keeps working when its key is pruned: build_interfaces.sh copies the packages into it.
"""

from __future__ import annotations

import re
import shutil
import sys
import time
from pathlib import Path

KEPT_KEYS = 6
"""Key folders kept (one per build input recently used), as the kernels' KEPT_CACHES."""
KEEP_RECENT_S = 86_400.0
"""A key folder used (or a temporary folder written) within this time [s] is kept whatever
their number."""
_KEY = re.compile("[0-9a-f]{16}")
"""A key folder's name (build_interfaces.sh: the first 16 hex digits of a sha256)."""
_TEMPORARY = re.compile(r"\.tmp\..+")


def prune(root: Path, keep: int = KEPT_KEYS, now: float | None = None) -> list[Path]:
    """Delete the key folders of ``root`` beyond the ``keep`` most recently used, unless used
    within KEEP_RECENT_S, and the temporary folders older than that; the deleted folders."""
    now = time.time() if now is None else now
    try:
        folders = [p for p in root.iterdir() if p.is_dir() and not p.is_symlink()]
        keys = sorted((p for p in folders if _KEY.fullmatch(p.name)), key=_mtime, reverse=True)
    except OSError:  # no cache yet, or unreadable: nothing to prune
        return []
    candidates = keys[keep:] + [p for p in folders if _TEMPORARY.fullmatch(p.name)]
    deleted = []
    for stale in candidates:
        if now - _mtime(stale) > KEEP_RECENT_S:
            shutil.rmtree(stale, ignore_errors=True)
            deleted.append(stale)
    return deleted


def _mtime(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except OSError:  # deleted meanwhile (another checkout pruning): counts as in use
        return time.time()


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python scripts/interface_cache.py CACHE_ROOT", file=sys.stderr)
        return 2
    for path in prune(Path(argv[0])):
        print(f"upstream interfaces: pruned the unused cache {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
