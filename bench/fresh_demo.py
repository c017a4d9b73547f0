"""Benchmark section: a newcomer's first table (issue 30), ``make demo`` in a fresh clone.

The repository's committed HEAD is cloned into a temporary folder and ``make demo`` runs there
with an empty pip cache (``PIP_CACHE_DIR``) and an empty kernel cache
(``GRASP_SAFETY_NUMBA_CACHE``): the venv, the core's packages, the package, then the demo.
Each output line is timestamped as it arrives; measured: the wall time to the ranking table's
header (``rank  index``), when each step began (the venv, pip's downloads, pip's unpacking,
the package, the demo) and the longest time without a new line (the issue's "visible
progress"). What pip reads from the machine's own indexes or wheel folders (pip.conf,
``PIP_FIND_LINKS``) it reads there as a new machine would: those are the machine's, not a
cache of this project.

Run alone: .venv/bin/python bench/run.py --only fresh_demo --merge --json bench/results.json
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPOSITORY = Path(__file__).resolve().parents[1]
TABLE_HEADER = "rank  index"
"""The start of the demo's ranking table's header line: the table is on screen."""
STEPS = (
    ("venv", "-m venv"),
    ("downloads", "Looking in indexes"),
    ("unpacking", "Installing collected packages"),
    ("package", "pip install --no-deps -e ."),
    ("demo", "grasp-safety demo"),
)
"""Each step of ``make demo`` and a piece of its first output line."""
TIMEOUT_S = 1800.0


def _clean_environment(pip_cache: str, kernel_cache: str) -> dict[str, str]:
    """This process's environment without its venv and path, with empty caches."""
    environment = {
        key: value
        for key, value in os.environ.items()
        if key not in {"VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME", "MAKEFLAGS", "MAKELEVEL"}
    }
    venv_bin = str(Path(sys.executable).parent)
    environment["PATH"] = os.pathsep.join(
        part for part in environment.get("PATH", "").split(os.pathsep) if part != venv_bin
    )
    environment["PIP_CACHE_DIR"] = pip_cache
    environment["GRASP_SAFETY_NUMBA_CACHE"] = kernel_cache
    return environment


def _timed_lines(
    command: list[str], folder: Path, environment: dict[str, str]
) -> list[tuple[float, str]]:
    """(seconds since start, line) of each line ``command`` prints (stdout and stderr)."""
    start = time.perf_counter()
    lines: list[tuple[float, str]] = []
    with subprocess.Popen(
        command,
        cwd=folder,
        env=environment,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        errors="replace",
    ) as process:
        for line in process.stdout or ():
            lines.append((time.perf_counter() - start, line.rstrip("\n")))
            if time.perf_counter() - start > TIMEOUT_S:
                process.kill()
                break
        returncode = process.wait()
    lines.append((time.perf_counter() - start, f"[exit status {returncode}]"))
    return lines


def summarise_lines(lines: list[tuple[float, str]]) -> dict[str, Any]:
    """The time to the table, each step's start and the longest silence, from timed lines."""
    table_s = next((t for t, line in lines if line.startswith(TABLE_HEADER)), None)
    steps = {name: next((t for t, line in lines if piece in line), None) for name, piece in STEPS}
    until = [t for t, _ in lines if table_s is None or t <= table_s]
    gaps = [later - earlier for earlier, later in zip([0.0, *until], until, strict=False)]
    silent_index = max(range(len(gaps)), key=gaps.__getitem__) if gaps else None
    return {
        "to_table_s": table_s,
        "steps_start_s": steps,
        "longest_silence_s": None if silent_index is None else gaps[silent_index],
        "longest_silence_ended_by": None if silent_index is None else lines[silent_index][1],
        "lines": len(lines),
        "exit": lines[-1][1],
    }


def bench_fresh_demo() -> dict[str, Any]:
    """``make demo`` in a fresh clone of HEAD with empty caches (module docstring)."""
    revision = subprocess.run(
        ["git", "-C", str(REPOSITORY), "rev-parse", "--short", "HEAD"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="fresh_demo_") as scratch:
        clone = Path(scratch) / "grasp_safety_ros"
        subprocess.run(["git", "clone", "--quiet", str(REPOSITORY), str(clone)], check=True)
        pip_cache, kernel_cache = Path(scratch) / "pip", Path(scratch) / "numba"
        pip_cache.mkdir()
        kernel_cache.mkdir()
        environment = _clean_environment(str(pip_cache), str(kernel_cache))
        lines = _timed_lines(["make", "demo"], clone, environment)
    return {"revision": revision, **summarise_lines(lines)}


def print_fresh_demo(result: dict[str, Any]) -> None:
    steps = ", ".join(
        f"{name} {'-' if start is None else f'{start:.1f}'} s"
        for name, start in result["steps_start_s"].items()
    )
    table = result["to_table_s"]
    print(
        f"\nfresh clone of {result['revision']}, empty caches: make demo to its table "
        f"{'(no table: ' + result['exit'] + ')' if table is None else f'{table:.1f} s'}; "
        f"steps began at: {steps}; longest silence {result['longest_silence_s']:.1f} s "
        f"(ended by: {result['longest_silence_ended_by'][:60]!r})"
    )
