"""``ros2 launch grasp_safety_ros grasp_safety.launch.py`` (the package form, with and without
``params_file:=``) and the ways docs/ros/quickstart.md gives to stop the node from a script,
each as a user runs them (harness of test_ros2_cli.py: own ROS_DOMAIN_ID, no daemon).

Needs ``ros2 launch`` in the venv: ``make setup`` installs it when
``../shared/tools/ros2launch/install`` is beside the checkout.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest
import yaml
from ros_domains import claim_ros_domain
from test_ros2_cli import (
    NODE,
    PREFIX,
    ROOT,
    ROS2,
    WAIT,
    book_request_yaml,
    response_field,
    ros2_all,
    ros2_ok,
    ros_env,
)

HAS_LAUNCH = (PREFIX / "bin" / "ros2").exists() and any(
    (path / "ros2launch").is_dir() for path in (PREFIX / "lib").glob("python3*/site-packages")
)
pytestmark = pytest.mark.skipif(
    not HAS_LAUNCH,
    reason="no ros2 launch in the venv (make setup installs it when "
    "../shared/tools/ros2launch/install exists beside the checkout)",
)

LAUNCH = (str(ROS2), "launch", "grasp_safety_ros", "grasp_safety.launch.py")
RANK = ("service", "call", f"{NODE}/rank_grasps", "grasp_safety_msgs/srv/RankGrasps")
READY = "robot from urdf"  # logged once the node serves
QUICKSTART = ROOT / "docs" / "ros" / "quickstart.md"


def _start(command: list[str], env: dict[str, str], log: Path) -> subprocess.Popen:
    """``command`` in a session of its own, output to ``log``, once the node serves."""
    with log.open("w") as out:
        process = subprocess.Popen(
            command, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
        )
    deadline = time.monotonic() + 90.0
    while READY not in log.read_text():
        if process.poll() is not None or time.monotonic() > deadline:
            _kill(process)
            pytest.fail(f"{' '.join(command)} did not start the node:\n{log.read_text()}")
        time.sleep(0.2)
    return process


def _kill(process: subprocess.Popen) -> None:
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=10.0)


def _interrupt(process: subprocess.Popen, log: Path) -> int:
    """SIGINT to the process alone (not its group), as ``kill -INT PID`` from a script."""
    process.send_signal(signal.SIGINT)
    try:
        return process.wait(timeout=30.0)
    except subprocess.TimeoutExpired:
        _kill(process)
        pytest.fail(f"SIGINT did not stop {process.args}:\n{log.read_text()}")


def test_launch_package_form_with_and_without_params_file(tmp_path: Path) -> None:
    with claim_ros_domain() as claim:
        env = ros_env(tmp_path, claim.domain_id)
        log = tmp_path / "default.log"
        process = _start([*LAUNCH], env, log)
        try:
            answered, dumped = ros2_all(
                env, (*RANK, book_request_yaml(integers=False)), ("param", "dump", *WAIT, NODE)
            )
        finally:
            code = _interrupt(process, log)
        assert code == 0, log.read_text()
        assert "process has finished cleanly" in log.read_text(), log.read_text()
        assert "success=True" in answered.stdout, answered.stdout[:2000]
        order = response_field(answered.stdout, "order")
        assert order == [0, 1, 2]

        # the dump, changed in one value that the answer shows, as params_file:=
        values = yaml.safe_load(dumped.stdout)
        values[NODE]["ros__parameters"]["metric"] = "max"
        params_file = tmp_path / "dump.yaml"
        params_file.write_text(yaml.safe_dump(values))
        log = tmp_path / "dump.log"
        process = _start([*LAUNCH, f"params_file:={params_file}"], env, log)
        try:
            (answered,) = ros2_all(env, (*RANK, book_request_yaml(integers=False)))
        finally:
            code = _interrupt(process, log)
    assert code == 0, log.read_text()
    assert "success=True" in answered.stdout and "metric='max'" in answered.stdout


def _documented_script(name: str) -> str:
    """The bash block after ``<!-- script: NAME ...-->`` in docs/ros/quickstart.md."""
    match = re.search(
        rf"<!-- script: {name}\b[^>]*-->\n```bash\n(.*?)```", QUICKSTART.read_text(), re.S
    )
    assert match, f"no script {name} in {QUICKSTART}"
    return match.group(1)


@pytest.mark.parametrize("name", ["stop-direct", "stop-group"])
def test_documented_ways_to_stop_the_node_from_a_script(name: str, tmp_path: Path) -> None:
    script = _documented_script(name)
    with claim_ros_domain() as claim:
        env = ros_env(tmp_path, claim.domain_id)
        completed = subprocess.run(
            ["bash", "-c", script],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=180,
            start_new_session=True,
            check=False,
        )
    output = completed.stdout + completed.stderr
    assert completed.returncode == 0, output
    assert "String value is: mean" in completed.stdout, output  # the node served
    assert completed.stdout.strip().endswith("node exited with 0"), output


def test_ros2_pkg_finds_the_launch_file(tmp_path: Path) -> None:
    """The share folder's launch/ is a real folder (os.walk enters it), its files links."""
    launch = PREFIX / "share" / "grasp_safety_ros" / "launch"
    assert launch.is_dir() and not launch.is_symlink()
    assert (
        launch / "grasp_safety.launch.py"
    ).resolve() == ROOT / "launch" / "grasp_safety.launch.py"
    with claim_ros_domain() as claim:
        shown = ros2_ok(
            ros_env(tmp_path, claim.domain_id),
            "launch",
            "--show-args",
            "grasp_safety_ros",
            "grasp_safety.launch.py",
        )
    assert "params_file" in shown


def test_sigint_to_ros2_run_alone_does_not_stop_the_node(tmp_path: Path) -> None:
    """Why the doc's scripts signal the node or the group: ``ros2 run`` catches the
    KeyboardInterrupt and waits for its child, which never got the signal."""
    with claim_ros_domain() as claim:
        env = ros_env(tmp_path, claim.domain_id)
        log = tmp_path / "run.log"
        params = str(ROOT / "config" / "grasp_safety_node.yaml")
        command = [str(ROS2), "run", "grasp_safety_ros", "grasp_safety_node"]
        process = _start([*command, "--ros-args", "--params-file", params], env, log)
        try:
            process.send_signal(signal.SIGINT)
            time.sleep(5.0)
            assert process.poll() is None, log.read_text()
            got = ros2_ok(env, "param", "get", *WAIT, NODE, "metric")
            assert got == "String value is: mean\n"  # the node still serves
        finally:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGINT)  # the group, as the doc's second script
            try:
                code = process.wait(timeout=30.0)
            except subprocess.TimeoutExpired:
                _kill(process)
                raise
    assert code == 0, log.read_text()
