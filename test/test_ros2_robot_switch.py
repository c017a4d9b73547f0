"""Switching the running node to another robot with ``ros2 param load FILE``, through the real
ROS 2 command line (harness of test_ros2_cli.py: own ROS_DOMAIN_ID, no daemon).

``ros2 param load`` sends every parameter of the file in one ``set_parameters`` request, and
rclpy's parameter service applies them one at a time: each robot parameter alone is
inconsistent with the others' old values. The node accepts such a change as pending, the old
model serving, and applies the robot group (urdf, base_frame, tip_frame, ik_seed) once it is
consistent; a file that never makes it consistent leaves the old model serving, with the reason
in the parameter results, the log and /diagnostics.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import test_ros2_cli
import yaml
from conftest import shown_in_docs
from test_ros2_cli import (
    NODE,
    PARAMS,
    ROS2,
    WAIT,
    RunningNode,
    book_request_yaml,
    response_field,
    ros2_all,
)

node = test_ros2_cli.node  # a fixture here too: this module's own node, started by ros2 run
pytestmark = pytest.mark.skipif(not ROS2.exists(), reason=f"no ros2 command line at {ROS2}")

UR5 = {
    "urdf": "example-robot-data:ur5",
    "base_frame": "base_link",
    "tip_frame": "tool0",
    "ik_seed": [0.0, -1.57, 1.57, -1.57, -1.57, 0.0],
}
BAXTER = {
    key: yaml.safe_load(Path(PARAMS).read_text())["grasp_safety"]["ros__parameters"][key]
    for key in ("urdf", "base_frame", "tip_frame", "ik_seed")
}
RANK = ("service", "call", f"{NODE}/rank_grasps", "grasp_safety_msgs/srv/RankGrasps")
DIAGNOSTICS = (
    *("topic", "echo", "--once", "--no-daemon"),
    *("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
)


def _params_file(tmp_path: Path, name: str, values: dict) -> str:
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump({NODE: {"ros__parameters": values}}, sort_keys=False))
    return str(path)


def _load(node: RunningNode, path: str) -> list[str]:
    """``ros2 param load``: one line per parameter, in the file's order."""
    (completed,) = ros2_all(
        node.env, ("param", "load", "--no-daemon", "--timeout", "20", NODE, path)
    )
    assert completed.returncode == 0, completed.stdout + completed.stderr
    return (completed.stdout + completed.stderr).strip().splitlines()


def test_param_load_of_another_robot_applies_the_group(node: RunningNode, tmp_path: Path) -> None:
    # 1. a file that never becomes consistent: the old model (Baxter) serves; the parameter
    # that completes the group is refused with the reason (rclpy drops a success's reason)
    broken = _params_file(tmp_path, "broken", {**UR5, "tip_frame": "tool"})
    lines = _load(node, broken)
    assert lines[:3] == [f"Set parameter {name} successful" for name in UR5][:3], lines
    assert lines[3].startswith("Set parameter ik_seed failed: ik_seed: robot parameters "), lines
    assert "frame 'tool' not found; did you mean 'tool0'?" in lines[3], lines[3]
    assert "model from urdf (base -> right_gripper) serves" in lines[3], lines[3]
    served, diagnostics = ros2_all(
        node.env, (*RANK, book_request_yaml(integers=False)), DIAGNOSTICS
    )
    assert "success=True" in served.stdout, served.stdout[:2000]
    assert response_field(served.stdout, "order") == [0, 1, 2]  # still Baxter's book ranking
    assert "robot parameters base_frame, ik_seed, tip_frame, urdf are not consistent" in (
        diagnostics.stdout
    ), diagnostics.stdout
    # the first of the file, logged as docs/ros/quickstart.md quotes it
    assert shown_in_docs("ros/quickstart.md", "robot parameters pending").search(node.output())
    got = ros2_all(node.env, ("param", "get", *WAIT, NODE, "tip_frame"))[0]
    assert got.stdout == "String value is: tool\n"  # accepted, pending

    # 2. the consistent UR5 file: applied as a group once its last parameter arrives
    lines = _load(node, _params_file(tmp_path, "ur5", UR5))
    assert all(" successful" in line for line in lines), lines
    assert shown_in_docs("ros/quickstart.md", "robot from urdf: base_link").search(node.output())
    got, diagnostics = ros2_all(node.env, ("param", "get", *WAIT, NODE, "tip_frame"), DIAGNOSTICS)
    assert got.stdout == "String value is: tool0\n"
    assert "robot parameters" not in diagnostics.stdout, diagnostics.stdout

    # 3. back to Baxter with the shipped file's robot group: the book ranking again
    lines = _load(node, _params_file(tmp_path, "baxter", BAXTER))
    assert all(" successful" in line for line in lines), lines
    (served,) = ros2_all(node.env, (*RANK, book_request_yaml(integers=False)))
    assert response_field(served.stdout, "order") == [0, 1, 2], served.stdout[:2000]
    assert node.output().count("robot from urdf: base -> right_gripper, 7 joints") == 2
