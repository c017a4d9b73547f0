"""The ``grasp_safety_node`` console script as a process: it serves with the bundled params
file and stops cleanly on SIGINT; start-up errors give one clear log line and exit status 1.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest
import rclpy
from conftest import ARM6_AXES, serial_arm_urdf
from grasp_safety_msgs.srv import RankGrasps
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_domains import claim_ros_domain
from ros_node_harness import book_request
from std_msgs.msg import String

from grasp_safety_ros.paths import config_file

SCRIPT = Path(sys.executable).parent / "grasp_safety_node"
PARAMS = str(config_file("grasp_safety_node.yaml"))
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def command(*ros_args: str) -> list[str]:
    if SCRIPT.exists():
        return [str(SCRIPT), "--ros-args", *ros_args]
    return [sys.executable, "-m", "grasp_safety_ros.ros.node", "--ros-args", *ros_args]


FIRST_CALL_ATTEMPTS = 3
FIRST_CALL_TIMEOUT_S = 30.0


def first_answer(
    executor: SingleThreadedExecutor,
    client: Any,
    request: RankGrasps.Request,
    process: subprocess.Popen[str],
) -> RankGrasps.Response:
    """The answer to the first request to a node process, re-sent when none comes.

    Right after ``wait_for_service`` the node may not have matched the client's response
    reader yet; Fast DDS then drops the response (the node logs "failed to send response
    (timeout)", ros2/rmw_fastrtps#706), which slow discovery on a loaded machine allows. No
    answer to any attempt fails the test with the node's log.
    """
    for _ in range(FIRST_CALL_ATTEMPTS):
        future = client.call_async(request)
        executor.spin_until_future_complete(future, timeout_sec=FIRST_CALL_TIMEOUT_S)
        if future.done():
            return future.result()
        client.remove_pending_request(future)
    process.kill()
    _, stderr = process.communicate()
    pytest.fail(f"no answer to {FIRST_CALL_ATTEMPTS} requests; the node's log:\n{stderr}")


@pytest.fixture()
def ros_env(tmp_path: Path) -> Iterator[dict[str, str]]:
    with claim_ros_domain() as claim:
        yield from _ros_env(tmp_path, claim.domain_id)


def _ros_env(tmp_path: Path, domain_id: int) -> Iterator[dict[str, str]]:
    env = {
        **os.environ,
        "ROS_DOMAIN_ID": str(domain_id),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "ROS_LOG_DIR": str(tmp_path),
        "RCUTILS_COLORIZED_OUTPUT": "0",
    }
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        yield env


def test_console_script_serves_with_the_params_file(ros_env: dict[str, str]) -> None:
    process = subprocess.Popen(
        command("--params-file", PARAMS),
        env=ros_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    context = rclpy.context.Context()
    rclpy.init(context=context, domain_id=int(ros_env["ROS_DOMAIN_ID"]))
    try:
        node = rclpy.create_node("process_test_client", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        client = node.create_client(RankGrasps, "/grasp_safety/rank_grasps")
        assert client.wait_for_service(timeout_sec=20.0), "service did not appear"
        response = first_answer(executor, client, book_request(with_inertia=False), process)
        assert response is not None and response.success, response
        assert sorted(response.ranking.order) == [0, 1, 2]
        assert len(response.ranking.evaluations[0].effective_mass_kg) == 101  # dt_s 0.02
        node.destroy_node()
        run_examples(ros_env, response.ranking.order)
    finally:
        rclpy.shutdown(context=context)
        process.send_signal(signal.SIGINT)
        try:
            _, stderr = process.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            raise
    assert process.returncode == 0, stderr
    assert "Traceback" not in stderr, stderr


def run_example(env: dict[str, str], name: str, *args: str) -> str:
    completed = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert completed.returncode == 0, completed.stdout + completed.stderr
    return completed.stdout


def run_examples(env: dict[str, str], order: Sequence[int]) -> None:
    """The scripts in examples/ work against the running node."""
    table = run_example(env, "rank_grasps_client.py")
    first = table.splitlines()[2].split()
    assert first[:2] == ["1", str(order[0])], table
    echoed = run_example(env, "echo_ranking.py", "--count", "1", "--timeout", "20")
    assert f"#1 candidate {order[0]}:" in echoed, echoed
    assert "published" in run_example(env, "publish_candidates.py")


def test_bad_robot_description_topic_at_start_up(ros_env: dict[str, str]) -> None:
    context = rclpy.context.Context()
    rclpy.init(context=context, domain_id=int(ros_env["ROS_DOMAIN_ID"]))
    try:
        node = rclpy.create_node("robot_state_publisher_stand_in", context=context)
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        publisher = node.create_publisher(String, "/robot_description", latched)
        publisher.publish(String(data=serial_arm_urdf(ARM6_AXES)))  # has no frame 'flange'
        args = ["-p", "base_frame:=base_link", "-p", "tip_frame:=flange"]
        completed = subprocess.run(
            command(*args, "-p", "robot_description_timeout_s:=30.0"),
            env=ros_env,
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    output = completed.stdout + completed.stderr
    assert completed.returncode == 1, output
    failures = [line for line in output.splitlines() if "start-up failed" in line]
    assert len(failures) == 1 and "Traceback" not in output, output
    assert (
        "start-up failed: robot from /robot_description: tip_frame: frame 'flange' not found"
        in (failures[0])
    )


STARTUP_ERRORS = {
    "no_robot_description": (
        [
            *("-p", "base_frame:=base", "-p", "tip_frame:=right_gripper"),
            *("-p", "robot_description_timeout_s:=0.5"),
        ],
        r"start-up failed: no robot description: parameters robot_description and urdf are "
        r"empty and nothing arrived on /robot_description within 0.5 s",
    ),
    "unknown_tip_frame": (
        ["--params-file", PARAMS, "-p", "tip_frame:=right_flange"],
        r"start-up failed: tip_frame: frame 'right_flange' not found; did you mean .*"
        r"'right_gripper'.*\? links: .*; joints: ",
    ),
    "invalid_parameter": (
        ["--params-file", PARAMS, "-p", "object.mass_kg:=-2.0"],
        r"start-up failed: object\.mass_kg: must be in \[0, inf\], got -2",
    ),
    "wrong_parameter_type": (
        ["--params-file", PARAMS, "-p", "max_grasps:=lots"],
        r"start-up failed: max_grasps: must be an integer, got 'lots'",
    ),
    "inconsistent_parameters": (
        ["--params-file", PARAMS, "-p", "trajectory.dt_s:=5.0"],
        r"start-up failed: trajectory\.dt_s: must be at most trajectory\.duration_s=2",
    ),
    "bad_seed": (
        ["--params-file", PARAMS, "-p", "ik_seed:=[0.0, 1.0]"],
        r"start-up failed: ik_seed: must have shape \[7\]",
    ),
    "missing_params_file": (
        ["--params-file", "/nonexistent/grasp_safety.yaml"],
        r"start-up failed: .*Couldn't parse params file",
    ),
}


@pytest.mark.parametrize("case", sorted(STARTUP_ERRORS))
def test_startup_error_is_one_log_line_and_exit_1(ros_env: dict[str, str], case: str) -> None:
    args, pattern = STARTUP_ERRORS[case]
    completed = subprocess.run(
        command(*args), env=ros_env, capture_output=True, text=True, timeout=60, check=False
    )
    output = completed.stdout + completed.stderr
    assert completed.returncode == 1, output
    assert "Traceback" not in output, output
    failures = [line for line in output.splitlines() if "start-up failed" in line]
    assert len(failures) == 1, output
    assert failures[0].startswith("[ERROR]") and "[grasp_safety]" in failures[0]
    assert re.search(pattern, failures[0]), failures[0]


STOPS = 8


def test_repeated_sigint_stops_exit_0_without_an_abort(ros_env: dict[str, str]) -> None:
    """The node process, started and stopped by SIGINT again and again, exits 0 every time,
    its last line the node's own (the signal may come while the node is still starting): the
    interpreter's teardown after it ended in std::terminate ("terminate called without an
    active exception", SIGABRT) about one stop in two."""
    for stop in range(STOPS):
        process = subprocess.Popen(
            command("--params-file", PARAMS, "-p", "use_joint_states_seed:=false"),
            env=ros_env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        lines: list[str] = []
        assert process.stdout is not None
        for line in process.stdout:  # until the robot is loaded
            lines.append(line)
            if "robot from" in line:
                break
        process.send_signal(signal.SIGINT)
        rest, _ = process.communicate(timeout=60)
        log = "".join(lines) + rest
        assert process.returncode == 0, f"stop {stop}: exit {process.returncode}\n{log}"
        assert "terminate called" not in log, log
        assert log.strip().splitlines()[-1].endswith("their requests answered"), log
