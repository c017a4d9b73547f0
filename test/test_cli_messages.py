"""What the command line says about bad input: each scenario section lists its own keys,
and the unknown-robot message names the robots ``grasp-safety robots`` lists."""

from __future__ import annotations

import copy
import re
from pathlib import Path
from typing import Any

import pytest
import yaml

from grasp_safety_ros.cli.robots import robots_text
from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.core.model.description import example_robot_data_urdf
from grasp_safety_ros.paths import config_file
from grasp_safety_ros.scenario.schema import parse_scenario

BOOK = yaml.safe_load(config_file("book_baxter.yaml").read_text())
POSE = {"position_m": [0, 0, 0], "quat_xyzw": [0, 0, 0, 1]}
PLANNED = {"joint_names": ["j1"], "points": [{"time_s": 0.0, "positions": [0.0]}]}

SECTIONS: dict[str, tuple[set[str], dict[str, Any]]] = {
    # section as the message names it: (its own keys as the docs state them, a scenario
    # that has the section)
    "robot": (
        {"urdf", "base_frame", "tip_frame", "seed", "locked_joints", "armature_kgm2"}
        | {"exposed_points_m"},
        BOOK,
    ),
    "object": (
        {"mass_kg", "com_in_object_m", "points_m", "inertia_about_com_kgm2", "box_size_m"}
        | {"cylinder", "sphere"},
        BOOK,
    ),
    "object.sphere": (
        {"radius_m"},
        {**BOOK, "object": {"mass_kg": 0.3, "sphere": {"radius_m": 0.05}}},
    ),
    "object.cylinder": (
        {"radius_m", "length_m"},
        {**BOOK, "object": {"mass_kg": 0.3, "cylinder": {"radius_m": 0.05, "length_m": 0.1}}},
    ),
    "trajectory": ({"start", "goal", "duration_s", "dt_s"}, BOOK),
    "trajectory.start": ({"position_m", "quat_xyzw"}, BOOK),
    "trajectory.goal": ({"position_m", "quat_xyzw"}, BOOK),
    "trajectory.waypoints[0]": (
        {"time_s", "position_m", "quat_xyzw"},
        {**BOOK, "trajectory": {"waypoints": [{"time_s": 0.0, **POSE}], "dt_s": 0.1}},
    ),
    "grasps[0]": ({"name", "quality", "joint_trajectory", "position_m", "quat_xyzw"}, BOOK),
    "grasps[0].joint_trajectory": (
        {"joint_names", "points"},
        {**BOOK, "grasps": [{**POSE, "joint_trajectory": PLANNED}]},
    ),
    "grasps[0].joint_trajectory.points[0]": (
        {"time_s", "positions", "velocities"},
        {**BOOK, "grasps": [{**POSE, "joint_trajectory": PLANNED}]},
    ),
    "posture": ({"restarts", "seed"}, {**BOOK, "posture": {}}),
    "iso_ts_15066": ({"regions"}, {**BOOK, "iso_ts_15066": {}}),
    "uncertainty": (
        {"mass_fraction", "com_offset_m", "inertia_fraction", "samples", "percentile", "seed"},
        {**BOOK, "uncertainty": {}},
    ),
    "effort": ({"enabled", "criterion"}, {**BOOK, "effort": {}}),
    "whole_arm": ({"enabled", "region"}, {**BOOK, "whole_arm": {}}),
}
ALL_KEYS = sorted(set().union(*(keys for keys, _ in SECTIONS.values())))


def _section(data: dict[str, Any], path: str) -> dict[str, Any]:
    node: Any = data
    for part in path.split("."):
        name, _, index = part.partition("[")
        node = node[name]
        if index:
            node = node[int(index.rstrip("]"))]
    return node


@pytest.mark.parametrize("section", SECTIONS)
def test_each_section_refuses_the_keys_of_the_others_listing_its_own(section: str) -> None:
    own, scenario = SECTIONS[section]
    foreign = [key for key in ALL_KEYS if key not in own]
    assert foreign
    for key in foreign:
        data = copy.deepcopy(scenario)
        _section(data, section)[key] = 1
        with pytest.raises(InvalidInputError) as error:
            parse_scenario(data, Path("."))
        assert (error.value.field, error.value.reason) == (
            f"{section}.{key}",
            f"unknown field; allowed: {', '.join(sorted(own))}",
        ), key


def test_a_grasp_name_in_the_trajectory_start_is_refused() -> None:
    """The case found: trajectory.start accepted (and ignored) a grasp's name and quality."""
    data = copy.deepcopy(BOOK)
    data["trajectory"]["start"]["name"] = "start"
    with pytest.raises(InvalidInputError, match=r"allowed: position_m, quat_xyzw$"):
        parse_scenario(data, Path("."))


def test_unknown_robot_names_the_robots_that_robots_lists() -> None:
    listed = []
    for line in robots_text().split("\n\n")[0].splitlines()[2:]:  # the table's rows
        listed.append(line.split()[0])
    with pytest.raises(InvalidInputError) as error:
        example_robot_data_urdf("no_such_robot")
    named = re.search(r"bundled names: ([^;]+);", error.value.reason)
    assert named is not None, error.value.reason
    assert named.group(1).split(", ") == listed
    assert {"tiago", "pr2", "icub"} <= set(listed) and "so100" not in listed
