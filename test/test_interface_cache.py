"""The per-machine cache of built upstream interfaces (scripts/interface_cache.py, called by
scripts/build_interfaces.sh) keeps the most recently used keys, as the kernels' cache does."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"
sys.path.insert(0, str(SCRIPTS))
import interface_cache  # noqa: E402

DAY_S = interface_cache.KEEP_RECENT_S


def folder(root: Path, name: str, age_s: float, now: float) -> Path:
    """A folder of ``root`` last used ``age_s`` before ``now``."""
    path = root / name
    (path / "share").mkdir(parents=True)
    (path / "share" / "file").write_text("x")
    os.utime(path, (now - age_s, now - age_s))
    return path


def test_keys_beyond_the_most_recent_are_pruned_unless_used_within_a_day(tmp_path: Path) -> None:
    now = 1_900_000_000.0
    kept = interface_cache.KEPT_KEYS
    # kept + 3 keys, all unused for over a day, distinct ages (the first the newest)
    keys = [folder(tmp_path, f"{k:016x}", 2 * DAY_S + k, now) for k in range(kept + 3)]
    recent = folder(tmp_path, "abcdef0123456789", 0.0, now)  # in use: kept beyond the count
    keys = [recent, *keys]
    others = [
        folder(tmp_path, "not_a_key", 10 * DAY_S, now),  # not ours: never deleted
        folder(tmp_path, "0123456789abcdef0123", 10 * DAY_S, now),  # a 20-digit name: not a key
        folder(tmp_path, ".tmp.running", 60.0, now),  # a build in progress
    ]
    interrupted = folder(tmp_path, ".tmp.killed", 2 * DAY_S, now)
    (tmp_path / "a_file").write_text("")
    deleted = interface_cache.prune(tmp_path, now=now)
    assert sorted(deleted) == sorted([*keys[kept:], interrupted])
    left = set(tmp_path.iterdir())
    assert left == {*keys[:kept], *others, tmp_path / "a_file"}
    # three keys used now: the old keys beyond the most recent ``kept`` go
    new = [folder(tmp_path, f"{k:015x}f", 0.0, now) for k in range(3)]
    assert sorted(interface_cache.prune(tmp_path, now=now)) == sorted(keys[kept - 3 : kept])
    # all used within a day: none goes, however many
    for path in [*new, *keys[: kept - 3]]:
        os.utime(path, (now, now))
    folder(tmp_path, "ffffffffffffffff", 0.0, now)
    assert interface_cache.prune(tmp_path, now=now) == []


def test_the_command_build_interfaces_runs(tmp_path: Path) -> None:
    """``python scripts/interface_cache.py CACHE_ROOT`` as build_interfaces.sh calls it (and
    the call is there): a missing root is no error; a stale key is pruned and named."""
    script = SCRIPTS / "interface_cache.py"
    assert (
        '"$PY" "$ROOT/scripts/interface_cache.py" "$CACHE_ROOT"'
        in (SCRIPTS / "build_interfaces.sh").read_text()
    )
    run = [sys.executable, str(script)]
    missing = subprocess.run([*run, str(tmp_path / "none")], capture_output=True, text=True)
    assert missing.returncode == 0 and missing.stdout == "", missing.stderr
    now = time.time()
    stale = [folder(tmp_path, f"{k:016x}", 2 * DAY_S + k, now) for k in range(7)]
    done = subprocess.run([*run, str(tmp_path)], capture_output=True, text=True, check=True)
    assert done.stdout == f"upstream interfaces: pruned the unused cache {stale[-1]}\n"
    assert subprocess.run(run, capture_output=True).returncode == 2  # usage
