"""Command line: the demo runs; every class of bad input gives exit 2 and names the field."""

from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from grasp_safety_ros.cli.main import main
from grasp_safety_ros.paths import config_file

GOOD = yaml.safe_load(config_file("book_baxter.yaml").read_text())


def test_demo_runs_and_writes_outputs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--out", str(tmp_path)]) == 0
    table = capsys.readouterr().out
    assert "spine_0.0" in table and "rank" in table
    result = json.loads((tmp_path / "ranking.json").read_text())
    assert sorted(result["ranking"]) == [0, 1, 2]
    assert len(result["joint_names"]) == 7
    scores = [result["grasps"][i]["score"] for i in result["ranking"]]
    assert scores == sorted(scores)
    assert result["schema_version"] == 2
    samples = result["grasps"][0]["samples"]  # columnar: one array per field
    assert set(samples) >= {"t_s", "q", "direction_in_base", "effective_mass_kg"}
    assert all(len(column) == len(samples["t_s"]) for column in samples.values())
    assert len(samples["q"][0]) == 7
    assert (tmp_path / "ranking.png").stat().st_size > 10_000


def test_rank_json_round_trip(tmp_path: Path) -> None:
    scenario = tmp_path / "s.yaml"
    data = {**GOOD, "trajectory": {**GOOD["trajectory"], "dt_s": 0.1}, "metric": "integral"}
    scenario.write_text(yaml.safe_dump(data))
    out = tmp_path / "out.json"
    assert main(["rank", str(scenario), "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["metric"] == "integral"
    for grasp in result["grasps"]:
        times = grasp["samples"]["t_s"]
        masses = grasp["samples"]["effective_mass_kg"]
        trapezoid = sum(
            0.5 * (masses[i] + masses[i + 1]) * (times[i + 1] - times[i])
            for i in range(len(times) - 1)
        )
        assert grasp["score"] == pytest.approx(trapezoid, rel=1e-12)


def _mutate(path: str, value: object) -> dict:
    data = json.loads(json.dumps(GOOD))
    *parents, leaf = path.split(".")
    node = data
    for key in parents:
        node = node[int(key)] if isinstance(node, list) else node[key]
    if value is _DELETE:
        del node[leaf]
    else:
        node[int(leaf) if isinstance(node, list) else leaf] = value
    return data


_DELETE = object()

BAD_INPUTS = [
    ("object.mass_kg", _DELETE, "object.mass_kg: is required"),
    ("trajectory.duration_s", _DELETE, "trajectory.duration_s: is required"),
    ("object.mass_kg", "heavy", "object.mass_kg: must be numeric"),
    ("trajectory.dt_s", [0.1], "trajectory.dt_s: must have a number"),
    ("object.mass_kg", -0.3, "object.mass_kg: must be in (0"),
    ("trajectory.duration_s", float("nan"), "trajectory.duration_s: must be finite"),
    ("trajectory.start.position_m", [1.0, float("inf"), 0.0], "trajectory.start.position_m"),
    (
        "trajectory.goal.quat_xyzw",
        [0.0, 0.0, 0.0, 0.0],
        "trajectory.goal.quat_xyzw: must be a unit",
    ),
    ("robot.tip_frame", "no_such_frame", "robot.tip_frame: frame 'no_such_frame' not found"),
    ("robot.urdf", "/nonexistent/robot.urdf", "robot.urdf: no URDF file"),
    ("robot.urdf", "<robot name='x'><link></robot>", "robot.urdf: cannot read URDF XML"),
    ("robot.urdf", "example-robot-data:nosuchbot", "robot.urdf: example-robot-data robot"),
    ("robot.seed", [0.0, 0.0], "robot.seed: must have shape [7]"),
    ("metric", "median", "metric: must be one of mean, max, integral"),
    ("grasps", [], "grasps: must be a non-empty list"),
    ("object.box_size_m", [0.1, -0.2, 0.3], "object.box_size_m: edges must be > 0"),
]


@pytest.mark.parametrize(("path", "value", "message"), BAD_INPUTS)
def test_bad_input_exits_2_naming_the_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], path: str, value: object, message: str
) -> None:
    scenario = tmp_path / "bad.yaml"
    scenario.write_text(yaml.safe_dump(_mutate(path, value)))
    assert main(["rank", str(scenario)]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_unreadable_and_invalid_yaml_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["rank", str(tmp_path / "missing.yaml")]) == 2
    (tmp_path / "broken.yaml").write_text("robot: [unclosed")
    assert main(["rank", str(tmp_path / "broken.yaml")]) == 2
    err = capsys.readouterr().err
    assert "cannot read" in err and "not valid YAML" in err


def test_console_script_has_no_traceback_on_bad_input(tmp_path: Path) -> None:
    scenario = tmp_path / "bad.yaml"
    scenario.write_text(yaml.safe_dump(_mutate("object.mass_kg", -1.0)))
    completed = subprocess.run(
        [sys.executable, "-m", "grasp_safety_ros.cli", "rank", str(scenario)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert completed.returncode == 2
    assert completed.stderr.startswith("grasp-safety: error: object.mass_kg")


def test_json_without_per_sample_keeps_every_per_grasp_result(tmp_path: Path) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text(
        yaml.safe_dump({**GOOD, "trajectory": {**GOOD["trajectory"], "dt_s": 0.1}})
    )
    full, lean = tmp_path / "full.json", tmp_path / "lean.json"
    assert main(["rank", str(scenario), "--json", str(full)]) == 0
    assert main(["rank", str(scenario), "--json", str(lean), "--no-per-sample"]) == 0
    expected = json.loads(full.read_text())
    for grasp in expected["grasps"]:
        assert len(grasp.pop("samples")["t_s"]) == 21
    assert json.loads(lean.read_text()) == expected


def test_help_loads_neither_the_core_nor_heavy_libraries() -> None:
    code = (
        "import sys\n"
        "from grasp_safety_ros.cli.main import build_parser\n"
        "build_parser()\n"
        "heavy = {'pinocchio', 'scipy', 'matplotlib', 'mujoco', 'numba', 'yaml', 'rclpy'}\n"
        "print(sorted(heavy & {name.split('.')[0] for name in sys.modules}))\n"
    )
    loaded = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    )
    assert loaded.stdout.strip() == "[]"


def test_json_writer_round_trips_every_double_and_writes_non_finite_as_null() -> None:
    from grasp_safety_ros.cli.report import json_bytes

    rng = np.random.default_rng(7)
    doubles = np.concatenate(
        [
            rng.standard_normal(500) * 10.0 ** rng.integers(-300, 300, 500),
            [5e-324, -0.0, 0.1 + 0.2, 1e16, 1e-5, np.finfo(float).max, 123456789.0],
        ]
    )
    tree = {
        "floats": doubles,
        "strided": np.arange(12.0).reshape(3, 4)[:, ::2],  # not C-contiguous
        "fortran": np.asfortranarray(np.arange(6.0).reshape(2, 3)),
        "scalar_array": np.array(2.5),
        "non_finite": np.array([1.0, np.nan, np.inf, -np.inf]),
        "ints_and_flags": (np.arange(3), np.array([True, False]), np.float64(1.5)),
        "python": [float("nan"), 1, None, "a"],
    }
    back = json.loads(json_bytes(tree))  # the standard library reads it (strict JSON)
    assert np.array_equal(np.array(back["floats"]), doubles)  # bit for bit, -0.0 aside
    assert np.signbit(back["floats"][501])
    assert back["strided"] == [[0.0, 2.0], [4.0, 6.0], [8.0, 10.0]]
    assert back["fortran"] == [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]
    assert back["scalar_array"] == 2.5
    assert back["non_finite"] == [1.0, None, None, None]
    assert back["ints_and_flags"] == [[0, 1, 2], [True, False], 1.5]
    assert back["python"] == [None, 1, None, "a"]


def test_json_file_holds_the_evaluations_arrays_exactly(tmp_path: Path) -> None:
    from grasp_safety_ros.cli.main import rank_scenario
    from grasp_safety_ros.scenario.schema import parse_scenario

    data = {**GOOD, "trajectory": {**GOOD["trajectory"], "dt_s": 0.1}}
    scenario = tmp_path / "s.yaml"
    scenario.write_text(yaml.safe_dump(data))
    out = tmp_path / "out.json"
    assert main(["rank", str(scenario), "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    report = rank_scenario(parse_scenario(data, tmp_path))
    for grasp, evaluation in zip(result["grasps"], report.ranking.evaluations, strict=True):
        if not evaluation.feasible:
            continue
        samples = grasp["samples"]
        assert np.array_equal(np.array(samples["q"]), evaluation.joint_positions)
        assert np.array_equal(np.array(samples["effective_mass_kg"]), evaluation.effective_mass_kg)
        assert grasp["score"] == evaluation.score


class _ClosedPipe(io.TextIOBase):
    """A stdout whose reader has gone (``| head`` after its bytes): every write fails."""

    def write(self, text: str) -> int:
        raise BrokenPipeError(32, "Broken pipe")


def test_outputs_are_written_even_when_the_reader_stops_early(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "out.json"
    monkeypatch.setattr(sys, "stdout", _ClosedPipe())
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # main closes it on a broken pipe
    scenario = str(config_file("book_baxter.yaml"))
    assert main(["rank", scenario, "--json", str(out), "--no-per-sample"]) == 0
    assert sorted(json.loads(out.read_text())["ranking"]) == [0, 1, 2]
