"""``~/plan_grasps`` (moveit_msgs/srv/GraspPlanning) against a fake upstream planner in its own
process (test/fake_grasp_planner.py), and the grasp-list helpers of grasp_safety_ros.ros.moveit.

The order oracle is the CLI (``grasp-safety rank``) on the same scenario: robot, object, motion
and grasps; the quality oracle the documented maps of moveit.grasps (1 / (1 + safety_score) of
the CLI's scores; the core's rank_with_quality for the planner-quality weighting).
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rclpy
import yaml
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, Pose, PoseStamped, Quaternion, Transform, Vector3
from grasp_safety_msgs.msg import GraspEvaluation, GraspRanking
from nav_msgs.msg import Path as PathMsg
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from ros_domains import claim_ros_domain
from std_msgs.msg import Header
from test_ros_node_process import PARAMS as NODE_PARAMS
from test_ros_node_process import command as node_command

from grasp_safety_ros.cli.main import main as cli_main
from grasp_safety_ros.core.analyses.multi_objective import rank_with_quality
from grasp_safety_ros.core.exceptions import InvalidInputError
from grasp_safety_ros.ros.node import EXECUTOR_THREADS, GraspSafetyNode
from grasp_safety_ros.ros.runtime.rclpy_private import NodeExecutor, join_callbacks
from grasp_safety_ros.ros.topics.qos import subscription_qos
from grasp_safety_ros.scenario.schema import load_scenario

pytest.importorskip("moveit_msgs.msg", reason="moveit_msgs not built (make setup)")
from moveit_msgs.msg import CollisionObject, Grasp, MoveItErrorCodes
from moveit_msgs.srv import GraspPlanning
from trajectory_msgs.msg import MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint

from grasp_safety_ros.ros.moveit import offer_plan_grasps
from grasp_safety_ros.ros.moveit.grasps import (
    planner_qualities,
    pose_array_of_grasps,
    ranked_grasps,
    trajectory_goal,
)

FAKE_PLANNER = Path(__file__).with_name("fake_grasp_planner.py")
START = {"position_m": [1.0, 0.0, 0.03], "quat_xyzw": [0.5, 0.5, 0.5, 0.5]}
GOAL = {"position_m": [1.1, -0.38, 0.16], "quat_xyzw": [0.5, 0.5, 0.5, 0.5]}
SEED = [0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0]
GRASPS = [  # the book's spine grasps (object frame) and one out of reach; one quality NaN
    {"id": "spine_minus", "position_m": [-0.075, -0.1, 0.0], "quality": 0.9},
    {"id": "out_of_reach", "position_m": [-3.0, 0.0, 0.0], "quality": 0.8},
    {"id": "spine_mid", "position_m": [-0.075, 0.0, 0.0], "quality": float("nan")},
    {"id": "spine_plus", "position_m": [-0.075, 0.1, 0.0], "quality": 0.2},
]
for _grasp in GRASPS:
    _grasp.update(frame="object", quat_xyzw=[0.0, 0.0, 0.0, 1.0])
SCENARIO = {
    "robot": {
        "urdf": "example-robot-data:baxter",
        "base_frame": "base",
        "tip_frame": "right_gripper",
        "seed": SEED,
    },
    "object": {
        "mass_kg": 0.34,
        "com_in_object_m": [0.0, 0.0, 0.0],
        "box_size_m": [0.15, 0.22, 0.015],
    },
    "trajectory": {"start": START, "goal": GOAL, "duration_s": 2.0, "dt_s": 0.1},
    "posture": {"restarts": 0},
    "grasps": [
        {"name": g["id"], "position_m": g["position_m"], "quat_xyzw": g["quat_xyzw"]}
        for g in GRASPS
    ],
    "metric": "mean",
}
PLANNERS = {
    "/fake/good": {"grasps": GRASPS},
    "/fake/slow": {"grasps": GRASPS, "delay_s": 6.0},
    "/fake/delayed": {"grasps": GRASPS, "delay_s": 1.0},
    "/fake/fails": {"error_code": MoveItErrorCodes.PLANNING_FAILED, "message": "no grasps found"},
    "/fake/empty": {"grasps": []},
    "/fake/camera_frame": {"grasps": [{**g, "frame": "camera"} for g in GRASPS]},
    "/fake/zero_quaternion": {"grasps": [GRASPS[0], {**GRASPS[2], "quat_xyzw": [0, 0, 0, 0]}]},
}
TIMEOUT_S = 1.5


@pytest.fixture(scope="module")
def cli_result(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The CLI's JSON for the scenario (its order: ``ranking``)."""
    folder = tmp_path_factory.mktemp("cli")
    (folder / "scenario.yaml").write_text(yaml.safe_dump(SCENARIO))
    assert (
        cli_main(
            [
                "rank",
                str(folder / "scenario.yaml"),
                "--json",
                str(folder / "out.json"),
                "--no-per-sample",
            ]
        )
        == 0
    )
    result = json.loads((folder / "out.json").read_text())
    result["object_inertia"] = load_scenario(folder / "scenario.yaml").object_inertia
    return result


def pose(item: dict[str, Any]) -> Pose:
    x, y, z = (float(v) for v in item["position_m"])
    qx, qy, qz, qw = (float(v) for v in item["quat_xyzw"])
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def grasp_msg(item: dict[str, Any]) -> Grasp:
    return Grasp(
        id=item["id"],
        grasp_quality=float(item["quality"]),
        grasp_pose=PoseStamped(header=Header(frame_id=item["frame"]), pose=pose(item)),
    )


def request(**fields: Any) -> GraspPlanning.Request:
    target = CollisionObject(id="book", header=Header(frame_id="base"), pose=pose(START))
    return GraspPlanning.Request(group_name="right_arm", target=target, **fields)


class Harness:
    """The node (in this process, NodeExecutor in a thread), the fake planner process and a
    client, on one claimed ROS domain."""

    def __init__(self, cli_result: dict[str, Any]) -> None:
        self.claim = claim_ros_domain()
        env = {**os.environ, "ROS_DOMAIN_ID": str(self.claim.domain_id)}
        self.planner = subprocess.Popen(
            [sys.executable, str(FAKE_PLANNER), json.dumps(PLANNERS)],
            env=env,
            stdout=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        try:
            self._start(cli_result)
        except BaseException:
            self._stop_planner()
            raise

    def _start(self, cli_result: dict[str, Any]) -> None:
        watchdog = threading.Timer(120.0, self.planner.kill)
        watchdog.start()
        assert self.planner.stdout.readline().strip() == "ready"
        watchdog.cancel()
        self.context = Context()
        rclpy.init(context=self.context, domain_id=self.claim.domain_id)
        tensor = cli_result["object_inertia"].inertia_about_com_kgm2
        parameters = {
            "urdf": "example-robot-data:baxter",
            "base_frame": "base",
            "tip_frame": "right_gripper",
            "ik_seed": SEED,
            "use_joint_states_seed": False,
            "object.mass_kg": 0.34,
            "object.inertia_about_com_kgm2": [
                float(tensor[i, j]) for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
            ],
            "trajectory.dt_s": 0.1,
            "trajectory.duration_s": 2.0,
            "posture.restarts": 0,
            "max_compute_time_s": 60.0,
            "service_busy_timeout_s": 60.0,
            "moveit.grasp_planner_service": "/fake/good",
            "moveit.planner_timeout_s": 30.0,
            "moveit.object_goal": [*GOAL["position_m"], *GOAL["quat_xyzw"]],
        }
        self.node = GraspSafetyNode(
            context=self.context,
            parameter_overrides=[Parameter(k, value=v) for k, v in parameters.items()],
        )
        self.executor = NodeExecutor(num_threads=EXECUTOR_THREADS, context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        self.client_node = rclpy.create_node("plan_grasps_client", context=self.context)
        self.client_executor = SingleThreadedExecutor(context=self.context)
        self.client_executor.add_node(self.client_node)
        self.client = self.client_node.create_client(GraspPlanning, "/grasp_safety/plan_grasps")
        assert self.client.wait_for_service(timeout_sec=30.0)

    def set(self, **values: Any) -> None:
        results = self.node.set_parameters(
            [Parameter(f"moveit.{k}", value=v) for k, v in values.items()]
        )
        assert all(r.successful for r in results), [r.reason for r in results]

    def call(self, req: GraspPlanning.Request) -> GraspPlanning.Response:
        future = self.client.call_async(req)
        self.client_executor.spin_until_future_complete(future, timeout_sec=120.0)
        assert future.done(), "no answer"
        return future.result()

    def close(self) -> None:
        self.executor.shutdown()
        self.thread.join(timeout=10.0)
        join_callbacks(self.executor)
        self.node.destroy_node()
        self.client_node.destroy_node()
        rclpy.shutdown(context=self.context)
        self._stop_planner()

    def _stop_planner(self) -> None:
        if self.planner.poll() is None:
            os.killpg(self.planner.pid, signal.SIGTERM)
            self.planner.wait(timeout=10.0)
        self.claim.release()


@pytest.fixture(scope="module")
def ros(cli_result: dict[str, Any]) -> Iterator[Harness]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        harness = Harness(cli_result)
        yield harness
        harness.close()


@pytest.fixture()
def defaults(ros: Harness) -> Iterator[Harness]:
    """Restores the moveit.* parameters a test changes."""
    yield ros
    ros.set(
        grasp_planner_service="/fake/good",
        planner_timeout_s=30.0,
        infeasible="append",
        planner_quality=False,
    )


def assert_refused(answer: GraspPlanning.Response, code: int, *parts: str) -> None:
    assert answer.error_code.val == code, answer.error_code
    assert not answer.grasps
    for part in parts:
        assert part in answer.error_code.message, answer.error_code.message


# --- Through the node ---------------------------------------------------------------------------


def test_planner_grasps_come_back_in_the_cli_order(ros: Harness, cli_result: dict) -> None:
    answer = ros.call(request())
    assert answer.error_code.val == MoveItErrorCodes.SUCCESS, answer.error_code.message
    order = cli_result["ranking"]
    assert order == [0, 3, 2]  # the scenario: out_of_reach infeasible
    ids = [g.id for g in answer.grasps]
    assert ids == [GRASPS[k]["id"] for k in order] + ["out_of_reach"]  # appended last
    scores = {g["name"]: g["safety_score"] for g in cli_result["grasps"]}
    qualities = [g.grasp_quality for g in answer.grasps]
    # 1 / (1 + safety_score) of the CLI's scores; rtol: the same computation, ~1e-15 apart
    np.testing.assert_allclose(
        qualities[:3], [1.0 / (1.0 + scores[i]) for i in ids[:3]], rtol=1e-12
    )
    assert qualities[3] == 0.0
    assert qualities == sorted(qualities, reverse=True)
    for grasp in answer.grasps:  # the request reached the planner as sent
        assert list(grasp.allowed_touch_objects) == ["right_arm", "book"]


def test_infeasible_grasps_dropped_by_parameter(defaults: Harness, cli_result: dict) -> None:
    defaults.set(infeasible="drop")
    answer = defaults.call(request())
    assert [g.id for g in answer.grasps] == [GRASPS[k]["id"] for k in cli_result["ranking"]]


def test_planner_quality_weighting_gives_the_combined_score(
    defaults: Harness, cli_result: dict
) -> None:
    defaults.set(planner_quality=True)
    answer = defaults.call(request())
    scores = [
        math.nan if g["safety_score"] is None else g["safety_score"] for g in cli_result["grasps"]
    ]
    quality = [g["quality"] for g in GRASPS]
    quality[2] = min(q for q in quality if math.isfinite(q))  # NaN: the lowest of the set
    expected = rank_with_quality(scores, quality, 0.5)
    assert [g.id for g in answer.grasps] == [GRASPS[k]["id"] for k in expected.order] + [
        "out_of_reach"
    ]
    np.testing.assert_allclose(
        [g.grasp_quality for g in answer.grasps[:3]],
        [expected.combined[k] for k in expected.order],
        rtol=1e-12,
    )


def test_planner_failure_is_passed_through(defaults: Harness) -> None:
    defaults.set(grasp_planner_service="/fake/fails")
    assert_refused(defaults.call(request()), MoveItErrorCodes.PLANNING_FAILED, "no grasps found")


def test_planner_down_is_an_error_within_the_timeout(defaults: Harness) -> None:
    defaults.set(grasp_planner_service="/fake/nobody_serves_this", planner_timeout_s=TIMEOUT_S)
    started = time.monotonic()
    answer = defaults.call(request())
    assert time.monotonic() - started >= TIMEOUT_S  # it waited for the service, then answered
    assert_refused(
        answer, MoveItErrorCodes.COMMUNICATION_FAILURE, "/fake/nobody_serves_this", "not available"
    )


def test_slow_planner_times_out(defaults: Harness) -> None:
    defaults.set(grasp_planner_service="/fake/slow", planner_timeout_s=TIMEOUT_S)
    assert_refused(
        defaults.call(request()), MoveItErrorCodes.TIMED_OUT, "/fake/slow", "did not answer"
    )
    defaults.set(grasp_planner_service="/fake/good", planner_timeout_s=30.0)
    assert defaults.call(request()).error_code.val == MoveItErrorCodes.SUCCESS  # still serving


def test_concurrent_requests_beyond_the_executor_threads_are_all_answered(
    defaults: Harness, cli_result: dict
) -> None:
    """EXECUTOR_THREADS + 1 requests wait for the planner at once (it answers each after 1 s):
    a request waiting for the planner holds no executor thread, so the planner's answers are
    taken and every request is ranked (a request that slept on its thread until the answer
    came left no thread to take it: all timed out)."""
    defaults.set(grasp_planner_service="/fake/delayed")
    futures = [defaults.client.call_async(request()) for _ in range(EXECUTOR_THREADS + 1)]
    deadline = time.monotonic() + 120.0
    while not all(f.done() for f in futures) and time.monotonic() < deadline:
        defaults.client_executor.spin_once(timeout_sec=0.1)
    assert all(f.done() for f in futures), "not every request was answered"
    expected = [GRASPS[k]["id"] for k in cli_result["ranking"]] + ["out_of_reach"]
    for future in futures:
        answer = future.result()
        assert answer.error_code.val == MoveItErrorCodes.SUCCESS, answer.error_code.message
        assert [g.id for g in answer.grasps] == expected


@pytest.mark.parametrize(
    ("service", "parts"),
    [
        ("/fake/empty", ("grasps: is empty",)),
        ("/fake/camera_frame", ("grasps[0].grasp_pose.header.frame_id", "camera")),
        ("/fake/zero_quaternion", ("grasps[1].grasp_pose.pose",)),
    ],
)
def test_planner_garbage_is_refused_with_the_reason(
    defaults: Harness, service: str, parts: tuple[str, ...]
) -> None:
    defaults.set(grasp_planner_service=service)
    assert_refused(defaults.call(request()), MoveItErrorCodes.FAILURE, *parts)
    status = defaults.node.diagnostics_status()  # the reason on /diagnostics too
    assert parts[0] in status.message, status.message


def test_target_in_another_frame_is_refused(ros: Harness) -> None:
    bad = request()
    bad.target.header.frame_id = "camera"
    assert_refused(ros.call(bad), MoveItErrorCodes.FAILURE, "target.header.frame_id", "camera")


def test_candidate_grasps_without_a_planner(defaults: Harness, cli_result: dict) -> None:
    defaults.set(grasp_planner_service="")
    answer = defaults.call(request(candidate_grasps=[grasp_msg(g) for g in GRASPS]))
    assert answer.error_code.val == MoveItErrorCodes.SUCCESS, answer.error_code.message
    assert [g.id for g in answer.grasps] == [GRASPS[k]["id"] for k in cli_result["ranking"]] + [
        "out_of_reach"
    ]
    assert_refused(
        defaults.call(request()),
        MoveItErrorCodes.FAILURE,
        "candidate_grasps",
        "moveit.grasp_planner_service",
    )


def test_goal_from_the_object_trajectory_topic(defaults: Harness, cli_result: dict) -> None:
    """moveit.object_goal empty: the goal and duration are the latest ~/object_trajectory's
    (2 s, the CLI's; trajectory.duration_s set to 4 s meanwhile must not be used)."""
    defaults.set(object_goal=[])
    defaults.node.set_parameters([Parameter("trajectory.duration_s", value=4.0)])
    try:
        assert_refused(
            defaults.call(request()),
            MoveItErrorCodes.FAILURE,
            "moveit.object_goal",
            "~/object_trajectory",
        )
        header = Header(frame_id="base")
        path = PathMsg(
            header=header,
            poses=[
                PoseStamped(header=header, pose=pose(START)),
                PoseStamped(header=Header(frame_id="base", stamp=Time(sec=2)), pose=pose(GOAL)),
            ],
        )
        publisher = defaults.client_node.create_publisher(
            PathMsg, "/grasp_safety/object_trajectory", subscription_qos("object_trajectory")
        )
        deadline = time.monotonic() + 30.0
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)  # matched: the message is not sent before the node reads
        publisher.publish(path)
        answer = defaults.call(request())
        while answer.error_code.val != MoveItErrorCodes.SUCCESS and time.monotonic() < deadline:
            time.sleep(0.2)  # until the node has taken the trajectory
            answer = defaults.call(request())
    finally:
        defaults.node.set_parameters([Parameter("trajectory.duration_s", value=2.0)])
        defaults.set(object_goal=[*GOAL["position_m"], *GOAL["quat_xyzw"]])
    assert answer.error_code.val == MoveItErrorCodes.SUCCESS, answer.error_code.message
    scores = {g["name"]: g["safety_score"] for g in cli_result["grasps"]}
    ids = [g.id for g in answer.grasps]
    assert ids[:3] == [GRASPS[k]["id"] for k in cli_result["ranking"]]
    np.testing.assert_allclose(
        [g.grasp_quality for g in answer.grasps[:3]],
        [1.0 / (1.0 + scores[i]) for i in ids[:3]],
        rtol=1e-12,
    )


def test_object_goal_parameter_is_checked(ros: Harness) -> None:
    results = ros.node.set_parameters([Parameter("moveit.object_goal", value=[1.0, 2.0])])
    assert not results[0].successful
    assert "moveit.object_goal" in results[0].reason and "7 numbers" in results[0].reason


def test_shutdown_answers_a_request_waiting_for_the_planner(ros: Harness) -> None:
    """Last test of the node: it starts the node's shut-down (abandon_rankings)."""
    ros.set(grasp_planner_service="/fake/slow", planner_timeout_s=60.0)
    future = ros.client.call_async(request())
    ros.client_executor.spin_until_future_complete(future, timeout_sec=1.0)  # it waits
    ros.node.abandon_rankings()
    ros.client_executor.spin_until_future_complete(future, timeout_sec=30.0)
    assert future.done(), "no answer after the shut-down began"
    assert_refused(future.result(), MoveItErrorCodes.PREEMPTED, "shutting down")


def test_node_process_answers_a_waiting_request_at_sigint() -> None:
    """The console script, SIGINT while a request waits (suspended) for the slow planner: the
    executor spins until it has answered PREEMPTED (process.settle), then the node stops."""
    with claim_ros_domain() as claim, pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        env = {
            **os.environ,
            "ROS_DOMAIN_ID": str(claim.domain_id),
            "RCUTILS_COLORIZED_OUTPUT": "0",
        }
        planner = subprocess.Popen(
            [
                sys.executable,
                str(FAKE_PLANNER),
                json.dumps({"/fake/slow": PLANNERS["/fake/slow"]}),
            ],
            env=env,
            stdout=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        goal = ",".join(str(v) for v in [*GOAL["position_m"], *GOAL["quat_xyzw"]])
        node = subprocess.Popen(
            node_command(
                "--params-file",
                NODE_PARAMS,
                "-p",
                "moveit.grasp_planner_service:=/fake/slow",
                "-p",
                "moveit.planner_timeout_s:=60.0",
                "-p",
                f"moveit.object_goal:=[{goal}]",
            ),
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        context = Context()
        rclpy.init(context=context, domain_id=claim.domain_id)
        try:
            client_node = rclpy.create_node("plan_grasps_sigint_client", context=context)
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(client_node)
            client = client_node.create_client(GraspPlanning, "/grasp_safety/plan_grasps")
            assert client.wait_for_service(timeout_sec=60.0), "service did not appear"
            watchdog = threading.Timer(120.0, planner.kill)
            watchdog.start()
            assert planner.stdout.readline().strip() == "ready"
            future = client.call_async(request())
            # the node has forwarded the request: it waits for the planner (6 s)
            assert planner.stdout.readline().strip() == "request /fake/slow"
            watchdog.cancel()
            assert not future.done(), future.result()
            node.send_signal(signal.SIGINT)
            executor.spin_until_future_complete(future, timeout_sec=20.0)
            assert future.done(), (
                "no answer after SIGINT; the node's log:\n" + node.communicate(timeout=30.0)[1]
            )
            assert_refused(future.result(), MoveItErrorCodes.PREEMPTED, "shutting down")
            _, stderr = node.communicate(timeout=30.0)
        finally:
            rclpy.shutdown(context=context)
            for process in (node, planner):
                if process.poll() is None:
                    os.killpg(process.pid, signal.SIGKILL)
                    process.wait(timeout=10.0)
    assert node.returncode == 0, stderr
    assert "Traceback" not in stderr, stderr


# --- Grasp lists (no ROS graph) -----------------------------------------------------------------


def test_grasps_in_several_frames_are_refused() -> None:
    grasps = [grasp_msg(GRASPS[0]), grasp_msg({**GRASPS[2], "frame": "base"})]
    with pytest.raises(InvalidInputError, match=r"grasps\[1\]\.grasp_pose\.header\.frame_id"):
        pose_array_of_grasps(grasps, "grasps")


def test_non_finite_planner_quality_counts_as_the_lowest() -> None:
    grasps = [grasp_msg(g) for g in GRASPS]
    assert planner_qualities(grasps) == (0.9, 0.8, 0.2, 0.2)
    assert planner_qualities([grasp_msg({**GRASPS[0], "quality": math.inf})]) is None


def test_goal_of_a_trajectory_in_another_frame_or_without_a_transform_is_refused() -> None:
    header = Header(frame_id="base")
    path = PathMsg(
        header=header,
        poses=[
            PoseStamped(header=header, pose=pose(START)),
            PoseStamped(header=Header(frame_id="base", stamp=Time(sec=2)), pose=pose(GOAL)),
        ],
    )
    goal, duration_s = trajectory_goal(path, "base")
    assert goal == pose(GOAL) and duration_s == 2.0
    with pytest.raises(InvalidInputError) as error:
        trajectory_goal(path, "world")
    assert error.value.field == "object_trajectory.header.frame_id"
    end = Transform(translation=Vector3(x=1.1, y=-0.38, z=0.16), rotation=pose(GOAL).orientation)
    points = [
        MultiDOFJointTrajectoryPoint(transforms=[end]),
        MultiDOFJointTrajectoryPoint(transforms=[end], time_from_start=Duration(sec=3)),
    ]
    trajectory = MultiDOFJointTrajectory(header=header, joint_names=["book"], points=points)
    assert trajectory_goal(trajectory, "base") == (pose(GOAL), 3.0)
    trajectory.header.frame_id = "camera"
    with pytest.raises(InvalidInputError) as error:
        trajectory_goal(trajectory, "base")
    assert error.value.field == "object_multi_dof_trajectory.header.frame_id"
    trajectory.header.frame_id = "base"
    points[1].transforms = []
    with pytest.raises(InvalidInputError) as error:  # was an IndexError: "internal error"
        trajectory_goal(trajectory, "base")
    assert error.value.field == "object_multi_dof_trajectory.points[1].transforms"


class _Logger:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, line: str) -> None:
        self.lines.append(line)


class _Node:
    def __init__(self) -> None:
        self.logger = _Logger()

    def get_logger(self) -> _Logger:
        return self.logger


def test_plan_grasps_is_left_out_only_for_a_missing_moveit_msgs(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    server = "grasp_safety_ros.ros.moveit.server"
    node = _Node()
    with monkeypatch.context() as patch:  # a bug in server.py's imports is not hidden
        patch.setitem(sys.modules, server, None)
        with pytest.raises(ModuleNotFoundError):
            offer_plan_grasps(node)
    with monkeypatch.context() as patch:  # moveit_msgs not built: the node runs without it
        patch.delitem(sys.modules, server, raising=False)
        patch.setitem(sys.modules, "moveit_msgs.msg", None)
        assert offer_plan_grasps(node) is None
    assert len(node.logger.lines) == 1 and "moveit_msgs" in node.logger.lines[0]


def synthetic_ranking(rank_by: str, order: list[int], **keys: list[float]) -> GraspRanking:
    """A GraspRanking of len(values) grasps whose evaluations hold ``keys`` (field: values)."""
    count = len(next(iter(keys.values())))
    evaluations = [
        GraspEvaluation(index=k, **{f: v[k] for f, v in keys.items()}) for k in range(count)
    ]
    return GraspRanking(
        rank_by=rank_by, order=order, evaluations=evaluations, safety_weight=math.nan
    )


@pytest.mark.parametrize(
    ("rank_by", "field"),
    [
        ("safety", "safety_score"),
        ("effort", "effort_score"),
        ("whole_arm", "whole_arm_rank_force_n"),
    ],
)
def test_quality_is_one_over_one_plus_the_ordering_key(rank_by: str, field: str) -> None:
    grasps = [grasp_msg(g) for g in GRASPS]
    ranking = synthetic_ranking(rank_by, [2, 0, 3], **{field: [0.5, math.nan, 0.25, math.nan]})
    answer = ranked_grasps(grasps, ranking, "append")
    assert [g.id for g in answer] == ["spine_mid", "spine_minus", "spine_plus", "out_of_reach"]
    # 1/(1+0.25), 1/(1+0.5), a key not computed (NaN): 0, the infeasible one appended: 0
    assert [g.grasp_quality for g in answer] == [0.8, 1.0 / 1.5, 0.0, 0.0]
    assert [g.id for g in ranked_grasps(grasps, ranking, "drop")] == [
        "spine_mid",
        "spine_minus",
        "spine_plus",
    ]
    assert grasps[0].grasp_quality == 0.9  # the given messages are left as they were


def test_an_unknown_order_gives_qualities_by_position() -> None:
    grasps = [grasp_msg(g) for g in GRASPS]
    ranking = synthetic_ranking("safe_duration", [3, 1, 0, 2], safety_score=[1.0] * 4)
    answer = ranked_grasps(grasps, ranking, "append")
    assert [g.grasp_quality for g in answer] == [1.0, 0.75, 0.5, 0.25]
