"""What a ranking command loads (issue 30: start-up), counted, not timed: with its kernels in
numba's cache, ``grasp-safety rank`` imports neither scipy.linalg, scipy.interpolate nor
numba's lowering registries (``numba.np.arraymath`` and the rest of the implementations a
compilation needs: about a second), and the demo runs on the Pinocchio path."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from grasp_safety_ros.core.method.ranking import GraspSafetyEvaluator
from grasp_safety_ros.paths import config_file

RANK_AND_LIST_MODULES = """
import json, sys
from grasp_safety_ros.cli.main import main
status = main(["rank", sys.argv[1], "--json", sys.argv[2]])
print(json.dumps({"status": status, "modules": sorted(sys.modules)}))
"""


def rank_in_fresh_process(scenario: Path, out: Path) -> list[str]:
    done = subprocess.run(
        [sys.executable, "-c", RANK_AND_LIST_MODULES, str(scenario), str(out)],
        capture_output=True,
        text=True,
        check=True,
        timeout=1800,
    )
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["status"] == 0
    return result["modules"]


def test_rank_with_cached_kernels_imports_no_scipy_and_no_lowering_registries(
    tmp_path: Path,
) -> None:
    data = yaml.safe_load(config_file("book_baxter.yaml").read_text())
    data["grasps"] = data["grasps"][:1]
    scenario = tmp_path / "one.yaml"
    scenario.write_text(yaml.safe_dump(data))
    rank_in_fresh_process(scenario, tmp_path / "first.json")  # compiles what is not cached
    modules = rank_in_fresh_process(scenario, tmp_path / "second.json")
    # numba's own import checks scipy's version (``import scipy``, a few ms): nothing more
    assert not [m for m in modules if m.startswith(("scipy.linalg", "scipy.interpolate"))]
    assert "numba.np.arraymath" not in modules
    assert (tmp_path / "first.json").read_bytes() == (tmp_path / "second.json").read_bytes()


def test_a_bundled_robot_name_resolves_without_listing_example_robot_data() -> None:
    """``example-robot-data:baxter`` (a bundled name) is found without walking the installed
    tree for every URDF; another name still is, and both resolve to the files they did."""
    from grasp_safety_ros.core.model import description

    if not description.example_robot_data_dirs():
        pytest.skip("example-robot-data is not installed")
    description._urdfs_in.cache_clear()
    baxter = description.example_robot_data_urdf("baxter")
    assert description._urdfs_in.cache_info().misses == 0
    names = description.example_robot_data_names()
    assert baxter.relative_to(baxter.parents[2]).as_posix() == names["baxter"]
    other = next(name for name in names if name not in description.EXAMPLE_ROBOT_DATA_URDFS)
    assert description.example_robot_data_urdf(other).as_posix().endswith(names[other])


def test_demo_ranks_on_the_pinocchio_path(tmp_path: Path, monkeypatch) -> None:
    from grasp_safety_ros.cli import main as cli

    backends = []
    real_init = GraspSafetyEvaluator.__init__

    def recording_init(self, robot, config=None) -> None:
        real_init(self, robot, config)
        backends.append(self.ik.backend_used)

    monkeypatch.setattr(GraspSafetyEvaluator, "__init__", recording_init)
    assert cli.main(["demo", "--out", str(tmp_path)]) == 0
    assert len(backends) == 1 and backends[0].startswith("python")


def test_console_script_exits_with_mains_status_and_complete_outputs(tmp_path: Path) -> None:
    """``run`` ends rank's process without Python's teardown: the table, the JSON and the exit
    status are all there; a bad input still exits 2 with its one-line error."""
    data = yaml.safe_load(config_file("book_baxter.yaml").read_text())
    data["grasps"] = data["grasps"][:1]
    data["trajectory"]["dt_s"] = 0.1
    scenario = tmp_path / "one.yaml"
    scenario.write_text(yaml.safe_dump(data))
    out = tmp_path / "out.json"
    command = [sys.executable, "-m", "grasp_safety_ros.cli", "rank", str(scenario)]
    done = subprocess.run(
        [*command, "--json", str(out)], capture_output=True, text=True, timeout=1800
    )
    assert done.returncode == 0, done.stderr
    assert "spine_minus_0.1" in done.stdout and done.stdout.endswith(f"wrote {out}\n")
    assert json.loads(out.read_text())["ranking"] == [0]
    bad = subprocess.run(
        [*command, "--metric", "mean", "--json", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert bad.returncode == 2 and bad.stderr.startswith("grasp-safety: error: --json")


ANNOUNCED = """
import sys
import numba
from grasp_safety_ros.core.method.warm_up import announce_compiles

@numba.njit
def helper(x):
    return x * 2.0

@numba.njit
def kernel(x):
    return helper(x) + 1.0

announce_compiles(sys.stdout)
print(kernel(1.0), kernel(2.0))
"""


def test_each_kernel_compiled_is_announced_once_without_its_helpers() -> None:
    pytest.importorskip("numba")
    done = subprocess.run(
        [sys.executable, "-c", ANNOUNCED], capture_output=True, text=True, check=True, timeout=600
    )
    lines = done.stdout.splitlines()
    assert len(lines) == 2, done.stdout
    announced = r"compiling kernel __main__\.kernel \(first use on this machine\) \.\.\. \d+\.\d s"
    assert re.fullmatch(announced, lines[0])
    assert lines[1] == "3.0 5.0"


def test_numba_is_imported_without_coverage_which_stays_importable() -> None:
    pytest.importorskip("numba")
    code = (
        "import sys\n"
        "import grasp_safety_ros.core.kernels._jit as jit\n"
        "print(jit.numba is not None, 'coverage' in sys.modules)\n"
        "import importlib.util\n"
        "print(importlib.util.find_spec('coverage') is not None)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=600
    )
    loaded, installed = done.stdout.splitlines()
    assert loaded == "True False"
    if installed == "True":  # the hidden entry is gone: coverage imports as usual
        again = subprocess.run(
            [sys.executable, "-c", code + "import coverage\n"],
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert again.returncode == 0, again.stderr


def test_a_closed_announcement_stream_never_fails_a_compilation() -> None:
    pytest.importorskip("numba")
    code = ANNOUNCED.replace(
        "announce_compiles(sys.stdout)",
        "import io\nclosed = io.StringIO()\nclosed.close()\nannounce_compiles(closed)",
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=600
    )
    assert done.stdout == "3.0 5.0\n"


def test_call_kernel_keeps_the_overload_its_first_call_ran(monkeypatch) -> None:
    """``call_kernel`` keeps the overload the first call ran: the only one without typing the
    arguments again, else the one of the arguments' types."""
    numba = pytest.importorskip("numba")
    from grasp_safety_ros.core.method import compiled

    monkeypatch.setattr(compiled, "_ENTRY_POINTS", {})

    @numba.njit
    def single(x):
        return 2 * x

    @numba.njit
    def double(x):
        return 2 * x

    assert double(3) == 6  # an integer overload first: two overloads after the next call
    real_typeof = numba.typeof

    def no_second_typing(value):
        raise AssertionError("call_kernel typed the arguments of a single-overload kernel")

    monkeypatch.setattr(numba, "typeof", no_second_typing)
    assert compiled.call_kernel(single, 1.5) == 3.0
    monkeypatch.setattr(numba, "typeof", real_typeof)
    assert compiled.call_kernel(double, 1.5) == 3.0
    float64 = (numba.float64,)
    assert compiled._ENTRY_POINTS[single] is single.overloads[float64].entry_point
    assert compiled._ENTRY_POINTS[double] is double.overloads[float64].entry_point
    assert len(double.overloads) == 2
