"""``~/plan_grasps`` through the real ``ros2`` command line, as a MoveIt user reaches it: the
node started with ``ros2 run`` and the shipped params file (the book on Baxter), the object's
goal set with ``ros2 param set``, then ``ros2 service call /grasp_safety/plan_grasps
moveit_msgs/srv/GraspPlanning`` with the book's spine grasps as ``candidate_grasps`` (no
upstream planner). The answer must list them in the CLI's order for the book scenario.
Harness (domains, process groups, timeouts): test_ros2_cli.py.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from typing import Any

import pytest
import test_ros2_cli as ros2_cli
from ros_domains import claim_ros_domain
from test_ros2_cli import NODE, PARAMS, WAIT, RunningNode, pose_yaml, ros2_ok, ros_env

from grasp_safety_ros.cli.main import main as cli_main
from grasp_safety_ros.paths import config_file

pytestmark = ros2_cli.pytestmark  # skipped without the ros2 command line
pytest.importorskip("moveit_msgs.msg", reason="moveit_msgs not built (make setup)")

IDS = ("spine_plus_0.1", "spine_0.0", "spine_minus_0.1")
"""The book's grasps (config/book_baxter.yaml), given in reverse: y = +0.1, 0, -0.1 m."""
HALF = (0.5, 0.5, 0.5, 0.5)


@pytest.fixture(scope="module")
def running(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningNode]:
    log_dir = tmp_path_factory.mktemp("ros2_moveit")
    with claim_ros_domain() as claim:
        node = RunningNode(ros_env(log_dir, claim.domain_id), PARAMS, log_dir / "node.log")
        yield node
        node.close()
    assert "Traceback" not in node.output(), node.output()


@pytest.fixture(scope="module")
def book_cli_ranking(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The CLI's result for the book scenario (same robot, object, seed, dt as the params)."""
    out = tmp_path_factory.mktemp("cli") / "book.json"
    assert cli_main(["rank", str(config_file("book_baxter.yaml")), "--json", str(out)]) == 0
    return json.loads(out.read_text())


def plan_request_yaml() -> str:
    grasps = ", ".join(
        f"{{id: {name}, grasp_pose: {{header: {{frame_id: object}}, "
        f"pose: {pose_yaml((-0.075, y, 0.0), (0, 0, 0, 1), False)}}}}}"
        for name, y in zip(IDS, (0.1, 0.0, -0.1), strict=True)
    )
    start = pose_yaml((1.0, 0.0, 0.03), HALF, False)
    target = f"{{id: book, header: {{frame_id: base}}, pose: {start}}}"
    return f"{{group_name: right_arm, target: {target}, candidate_grasps: [{grasps}]}}"


def test_service_call_answers_the_grasps_in_the_cli_order(
    running: RunningNode, book_cli_ranking: dict
) -> None:
    goal = "[1.1, -0.38, 0.16, 0.5, 0.5, 0.5, 0.5]"
    assert "Set parameter successful" in ros2_ok(
        running.env, "param", "set", *WAIT, NODE, "moveit.object_goal", goal
    )
    text = ros2_ok(
        running.env,
        "service",
        "call",
        f"{NODE}/plan_grasps",
        "moveit_msgs/srv/GraspPlanning",
        plan_request_yaml(),
        timeout_s=120.0,
    )
    text = text.partition("response:")[2]  # after the echo of the request
    assert "MoveItErrorCodes(val=1," in text, text[:3000]
    ids = re.findall(r"moveit_msgs\.msg\.Grasp\(id='([^']+)'", text)
    names = [g["name"] for g in book_cli_ranking["grasps"]]
    assert ids == [names[k] for k in book_cli_ranking["ranking"]]
    assert ids == list(reversed(IDS))  # the book: the spine's -0.1 m grasp is the safest
    qualities = [float(q) for q in re.findall(r"grasp_quality=([-0-9.e+]+)", text)]
    assert qualities == sorted(qualities, reverse=True) and len(qualities) == 3
