"""Scenario files with timed waypoints and planned joint trajectories: ranked by the CLI; every
bad input exits 2 with one line naming the field."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
import yaml

from grasp_safety_ros.cli.main import main
from grasp_safety_ros.paths import config_file

WAYPOINTS = yaml.safe_load(config_file("book_baxter_waypoints.yaml").read_text())
START_GOAL = yaml.safe_load(config_file("book_baxter.yaml").read_text())


def _rank(tmp_path: Path, data: dict, name: str) -> dict:
    scenario = tmp_path / f"{name}.yaml"
    scenario.write_text(yaml.safe_dump(data))
    out = tmp_path / f"{name}.json"
    assert main(["rank", str(scenario), "--json", str(out)]) == 0
    return json.loads(out.read_text())


def test_waypoint_scenario_ranks_and_samples_the_waypoints(tmp_path: Path) -> None:
    result = _rank(tmp_path, WAYPOINTS, "waypoints")
    waypoint_times = [w["time_s"] for w in WAYPOINTS["trajectory"]["waypoints"]]
    planned = WAYPOINTS["grasps"][3]["joint_trajectory"]
    assert sorted(result["ranking"]) == [0, 1, 2, 3]
    for grasp in result["grasps"][:3]:
        times = grasp["samples"]["t_s"]
        assert set(waypoint_times) <= set(times)
        assert len(times) == 126  # 0..2.5 s every 0.02 s; 1.2 s is on that grid
        assert grasp["samples"]["tip_speed_m_s"][0] == 0.0
    samples = result["grasps"][3]["samples"]
    assert samples["t_s"] == [p["time_s"] for p in planned["points"]]
    assert samples["q"] == [p["positions"] for p in planned["points"]]
    assert all(iterations == 0 for iterations in samples["ik_iterations"])


def test_two_waypoints_rank_exactly_as_start_goal(tmp_path: Path) -> None:
    pair = copy.deepcopy(START_GOAL)
    trajectory = pair.pop("trajectory")
    pair["trajectory"] = {
        "waypoints": [
            {"time_s": 0.0, **trajectory["start"]},
            {"time_s": trajectory["duration_s"], **trajectory["goal"]},
        ],
        "dt_s": trajectory["dt_s"],
    }
    assert _rank(tmp_path, pair, "pair") == _rank(tmp_path, START_GOAL, "start_goal")


def _mutate(path: str, value: object) -> dict:
    data = copy.deepcopy(WAYPOINTS)
    node = data
    *parents, leaf = path.split(".")
    for key in parents:
        node = node[int(key)] if isinstance(node, list) else node[key]
    key = int(leaf) if isinstance(node, list) else leaf
    if value is _DELETE:
        del node[key]
    else:
        node[key] = value
    return data


_DELETE = object()
_WP = "trajectory.waypoints"
_JT = "grasps.3.joint_trajectory"

BAD_INPUTS = [
    (f"{_WP}.2.time_s", 1.2, "trajectory.waypoints[2].time_s: must be > waypoints[1].time_s"),
    (f"{_WP}.1.time_s", 3.0, "trajectory.waypoints[2].time_s: must be > waypoints[1].time_s"),
    (f"{_WP}.0.time_s", 0.5, "trajectory.waypoints[0].time_s: must be 0"),
    (f"{_WP}.1.time_s", float("nan"), "trajectory.waypoints[1].time_s: must be finite"),
    (f"{_WP}.1.time_s", _DELETE, "trajectory.waypoints[1].time_s: is required"),
    (f"{_WP}.1.position_m", [1.0, float("inf"), 0.0], "trajectory.waypoints[1].position_m"),
    (f"{_WP}.2.quat_xyzw", [0, 0, 0, 0], "trajectory.waypoints[2].quat_xyzw: must be a unit"),
    (f"{_WP}.2.speed", 1.0, "trajectory.waypoints[2].speed: unknown field"),
    (_WP, [{"time_s": 0.0, "position_m": [1, 0, 0], "quat_xyzw": [0, 0, 0, 1]}], "at least 2"),
    (_WP, "fast", "trajectory.waypoints: must be a list"),
    ("trajectory.dt_s", 1e-7, "trajectory.dt_s: gives"),
    ("trajectory.duration_s", 2.0, "trajectory.duration_s: unknown field"),
    (f"{_JT}.points.3.time_s", 0.5, f"{_JT.replace('.3', '[3]')}.points[3].time_s: must be >"),
    (f"{_JT}.points.3.time_s", 1.0, "grasps[3].joint_trajectory.points[4].time_s: must be >"),
    (f"{_JT}.points.2.positions", [0.1, 0.2], "grasps[3].joint_trajectory.points[2].positions"),
    (f"{_JT}.points.2.positions.1", 9.0, "joint 'right_s1' = 9 is outside its limits"),
    (f"{_JT}.points.2.positions.1", float("inf"), "points[2].positions: must be finite"),
    (f"{_JT}.joint_names.6", "head_pan", "grasps[3].joint_trajectory.joint_names: missing"),
    (f"{_JT}.joint_names", "right_s0", "grasps[3].joint_trajectory.joint_names: must be a list"),
    (f"{_JT}.points.1.time_s", _DELETE, "joint_trajectory.points[1].time_s: is required"),
    (f"{_JT}.points.1.velocities", [0.0] * 7, "velocities for every point or for none"),
    (f"{_JT}.points", [], "grasps[3].joint_trajectory.points: needs at least 2 points"),
]


@pytest.mark.parametrize(("path", "value", "message"), BAD_INPUTS)
def test_bad_motion_input_exits_2_naming_the_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], path: str, value: object, message: str
) -> None:
    scenario = tmp_path / "bad.yaml"
    scenario.write_text(yaml.safe_dump(_mutate(path, value)))
    assert main(["rank", str(scenario)]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
