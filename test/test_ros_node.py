"""The node over real rclpy: service, topics, bad inputs, parameters, robot from a topic.

The node runs in-process in a MultiThreadedExecutor thread with its own rclpy Context; the
test client is a second node in the same context with its own executor. Each context uses a
random ROS_DOMAIN_ID and localhost-only discovery, so parallel runs do not cross-talk.
"""

from __future__ import annotations

import copy
import math
import random
import re
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
import rclpy
import yaml
from builtin_interfaces.msg import Time
from conftest import ARM6_AXES, serial_arm_urdf
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import InertiaStamped, Point, Pose, PoseArray, PoseStamped, Quaternion
from grasp_safety_msgs.msg import GraspRanking
from grasp_safety_msgs.srv import RankGrasps
from nav_msgs.msg import Path
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.context import Context
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Header, String
from visualization_msgs.msg import Marker, MarkerArray

from grasp_safety_ros.core import GraspSafetyEvaluator, ObjectTrajectory, RobotModel, solid_box
from grasp_safety_ros.paths import config_file
from grasp_safety_ros.ros.conversions import inertia_msg_from_object, pose_msg_from_transform
from grasp_safety_ros.ros.node import EXECUTOR_THREADS, GraspSafetyNode
from grasp_safety_ros.scenario import load_scenario

BOOK = load_scenario(config_file("book_baxter.yaml"))
BOOK_YAML = yaml.safe_load(config_file("book_baxter.yaml").read_text())
DT_S = 0.1
MAX_GRASPS = 40
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
NODE_PARAMETERS = {
    "urdf": "example-robot-data:baxter",
    "base_frame": "base",
    "tip_frame": "right_gripper",
    "ik_seed": list(BOOK.robot.seed),
    "use_joint_states_seed": False,
    "object.mass_kg": 0.34,
    "object.inertia_about_com_kgm2": [
        float(BOOK.object_inertia.inertia_about_com_kgm2[i, j])
        for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
    ],
    "trajectory.dt_s": DT_S,
    "max_grasps": MAX_GRASPS,
    "max_total_samples": 100_000,
    "max_compute_time_s": 1.5,
    "service_busy_timeout_s": 0.3,
    "diagnostics_period_s": 0.5,
}


def start_context() -> Context:
    """A fresh rclpy context on a random domain, discovery limited to this host."""
    domain_id = random.SystemRandom().randint(0, 101)
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    return context


@pytest.fixture(scope="module", autouse=True)
def _localhost_only(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        patch.setenv("ROS_LOG_DIR", str(tmp_path_factory.mktemp("ros_log")))
        yield


class NodeUnderTest:
    """The node spinning in a background thread, plus a client node."""

    def __init__(self, parameters: dict[str, Any]) -> None:
        self.context = start_context()
        overrides = [Parameter(name, value=value) for name, value in parameters.items()]
        self.node = GraspSafetyNode(context=self.context, parameter_overrides=overrides)
        self.executor = MultiThreadedExecutor(num_threads=EXECUTOR_THREADS, context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        self.client = rclpy.create_node("grasp_safety_test_client", context=self.context)
        self.client_executor = SingleThreadedExecutor(context=self.context)
        self.client_executor.add_node(self.client)
        self.rank_client = self.client.create_client(RankGrasps, "/grasp_safety/rank_grasps")
        self.set_client = self.client.create_client(SetParameters, "/grasp_safety/set_parameters")
        self.get_client = self.client.create_client(GetParameters, "/grasp_safety/get_parameters")
        assert self.rank_client.wait_for_service(timeout_sec=10.0)
        assert self.set_client.wait_for_service(timeout_sec=10.0)

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.client.destroy_node()
        rclpy.shutdown(context=self.context)
        self.thread.join(timeout=5.0)

    def wait(self, future: rclpy.task.Future, timeout_s: float = 30.0) -> Any:
        self.client_executor.spin_until_future_complete(future, timeout_sec=timeout_s)
        assert future.done(), "no answer in time"
        return future.result()

    def rank(self, request: RankGrasps.Request) -> RankGrasps.Response:
        return self.wait(self.rank_client.call_async(request))

    def set_parameters(self, **values: Any) -> list[Any]:
        request = SetParameters.Request(
            parameters=[
                Parameter(name.replace("__", "."), value=value).to_parameter_msg()
                for name, value in values.items()
            ]
        )
        return self.wait(self.set_client.call_async(request)).results

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while not predicate() and time.monotonic() < deadline:
            self.client_executor.spin_once(timeout_sec=0.05)
        return predicate()


@pytest.fixture(scope="module")
def ros() -> Iterator[NodeUnderTest]:
    harness = NodeUnderTest(NODE_PARAMETERS)
    yield harness
    harness.close()


# --- Requests ----------------------------------------------------------------------------------


def pose_from_yaml(item: dict[str, Any]) -> Pose:
    """A Pose built straight from the scenario file's numbers (x, y, z, w order).

    float() matters: rclpy accepts an int in a float64 field but serialises it wrongly (as 0).
    """
    x, y, z = (float(v) for v in item["position_m"])
    qx, qy, qz, qw = (float(v) for v in item["quat_xyzw"])
    return Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def book_path(duration_s: float = 2.0) -> Path:
    trajectory = BOOK_YAML["trajectory"]
    sec = int(duration_s)
    stamps = [Time(sec=0), Time(sec=sec, nanosec=round((duration_s - sec) * 1e9))]
    return Path(
        header=Header(frame_id="base"),
        poses=[
            PoseStamped(header=Header(stamp=stamp), pose=pose_from_yaml(trajectory[key]))
            for stamp, key in zip(stamps, ("start", "goal"), strict=True)
        ],
    )


def book_request(with_inertia: bool = True) -> RankGrasps.Request:
    request = RankGrasps.Request()
    request.grasps = PoseArray(
        header=Header(frame_id="object"), poses=[pose_from_yaml(g) for g in BOOK_YAML["grasps"]]
    )
    request.object_trajectory = book_path()
    if with_inertia:
        request.object_inertia = inertia_msg_from_object(BOOK.object_inertia)
    return request


@pytest.fixture(scope="module")
def core_ranking() -> Any:
    robot = RobotModel.from_urdf("example-robot-data:baxter", "base", "right_gripper")
    trajectory = ObjectTrajectory(
        BOOK.trajectory.transform_object_to_base_start,
        BOOK.trajectory.transform_object_to_base_goal,
        2.0,
        DT_S,
    )
    return GraspSafetyEvaluator(robot).rank(
        BOOK.grasps, BOOK.object_inertia, trajectory, BOOK.robot.seed, "mean"
    )


def assert_matches_core(ranking: GraspRanking, expected: Any) -> None:
    assert tuple(ranking.order) == expected.order
    assert ranking.metric == expected.metric
    assert tuple(ranking.joint_names) == expected.joint_names
    assert len(ranking.evaluations) == len(expected.evaluations)
    for got, want in zip(ranking.evaluations, expected.evaluations, strict=True):
        assert got.index == want.index
        assert got.feasible == want.feasible
        assert got.score == pytest.approx(want.score, rel=1e-9, abs=1e-9)
        assert got.peak_effective_mass_kg == pytest.approx(want.peak_effective_mass_kg, rel=1e-9)
        assert got.mean_effective_mass_kg == pytest.approx(want.mean_effective_mass_kg, rel=1e-9)
        np.testing.assert_allclose(got.time_from_start_s, want.times_s, rtol=0, atol=1e-12)
        np.testing.assert_allclose(
            got.effective_mass_kg, want.effective_mass_kg, rtol=1e-9, atol=1e-9
        )
        directions = np.array([[d.x, d.y, d.z] for d in got.direction])
        np.testing.assert_allclose(directions, want.directions_in_base, rtol=0, atol=1e-9)
        assert list(got.direction_is_worst_case) == want.direction_is_worst_case.tolist()


# --- Service -----------------------------------------------------------------------------------


def test_service_book_scenario_equals_core(ros: NodeUnderTest, core_ranking: Any) -> None:
    response = ros.rank(book_request())
    assert response.success, response.message
    ranking = response.ranking
    assert_matches_core(ranking, core_ranking)
    assert len(core_ranking.order) == 3
    assert ranking.header.frame_id == "base"
    assert ranking.compute_time_s > 0.0
    ranked = ranking.ranked_grasps
    assert ranked.header.frame_id == "object"
    request = book_request()
    assert list(ranked.poses) == [request.grasps.poses[i] for i in core_ranking.order]


def test_default_object_is_used_when_mass_is_zero(ros: NodeUnderTest, core_ranking: Any) -> None:
    response = ros.rank(book_request(with_inertia=False))
    assert response.success, response.message
    assert_matches_core(response.ranking, core_ranking)


def test_service_is_deterministic(ros: NodeUnderTest) -> None:
    first, second = ros.rank(book_request()), ros.rank(book_request())
    assert first.success and second.success
    assert first.ranking.evaluations == second.ranking.evaluations
    assert first.ranking.order == second.ranking.order


def test_grasps_in_base_frame_equal_grasps_in_object_frame(
    ros: NodeUnderTest, core_ranking: Any
) -> None:
    request = book_request()
    start = BOOK.trajectory.transform_object_to_base_start
    request.grasps = PoseArray(
        header=Header(frame_id="base"),
        poses=[pose_msg_from_transform(start * g.transform_tip_to_object) for g in BOOK.grasps],
    )
    response = ros.rank(request)
    assert response.success, response.message
    assert_matches_core(response.ranking, core_ranking)
    assert response.ranking.ranked_grasps.header.frame_id == "base"


def test_metric_in_request(ros: NodeUnderTest) -> None:
    request = book_request()
    request.metric = "integral"
    response = ros.rank(request)
    assert response.success, response.message
    assert response.ranking.metric == "integral"
    for evaluation in response.ranking.evaluations:
        expected = np.trapezoid(evaluation.effective_mass_kg, evaluation.time_from_start_s)
        assert evaluation.score == pytest.approx(expected, rel=1e-12)


# --- Bad input ---------------------------------------------------------------------------------


def _grasp(request: RankGrasps.Request, i: int = 0) -> Pose:
    return request.grasps.poses[i]


def _stamped(request: RankGrasps.Request, i: int) -> PoseStamped:
    return request.object_trajectory.poses[i]


def _set(obj: Any, **values: Any) -> None:
    for key, value in values.items():
        setattr(obj, key, value)


BAD_REQUESTS: dict[str, tuple[Callable[[RankGrasps.Request], None], str]] = {
    "nan_grasp_position": (
        lambda r: _set(_grasp(r).position, x=math.nan),
        r"grasps\.poses\[0\]\.position: must be finite",
    ),
    "inf_path_position": (
        lambda r: _set(_stamped(r, 1).pose.position, z=math.inf),
        r"object_trajectory\.poses\[1\]\.pose\.position: must be finite",
    ),
    "nan_quaternion": (
        lambda r: _set(_grasp(r, 2).orientation, w=math.nan),
        r"grasps\.poses\[2\]\.orientation: must be finite",
    ),
    "zero_quaternion": (
        lambda r: _set(_grasp(r, 1).orientation, w=0.0),
        r"grasps\.poses\[1\]\.orientation: must be a unit quaternion .* got norm 0",
    ),
    "non_unit_quaternion": (
        lambda r: _set(_stamped(r, 0).pose.orientation, x=1.0, y=1.0, z=1.0, w=1.0),
        r"object_trajectory\.poses\[0\]\.pose\.orientation: must be a unit quaternion",
    ),
    "empty_grasps": (lambda r: _set(r.grasps, poses=[]), r"grasps\.poses: is empty"),
    "too_many_grasps": (
        lambda r: _set(r.grasps, poses=[r.grasps.poses[0]] * (MAX_GRASPS + 1)),
        rf"grasps\.poses: has {MAX_GRASPS + 1} grasps; at most max_grasps={MAX_GRASPS}",
    ),
    "path_with_one_pose": (
        lambda r: _set(r.object_trajectory, poses=r.object_trajectory.poses[:1]),
        r"object_trajectory\.poses: has 1 pose; exactly 2",
    ),
    "path_with_three_poses": (
        lambda r: _set(r.object_trajectory, poses=r.object_trajectory.poses * 2 + []),
        r"object_trajectory\.poses: has 4 poses; exactly 2",
    ),
    "unordered_stamps": (
        lambda r: _set(_stamped(r, 0).header, stamp=Time(sec=5)),
        r"object_trajectory\.poses: stamps are not in order",
    ),
    "too_many_samples": (
        lambda r: _set(_stamped(r, 1).header, stamp=Time(sec=100_000)),
        r"object_trajectory\.poses: .* at most max_samples=20000",
    ),
    "unknown_grasp_frame": (
        lambda r: _set(r.grasps.header, frame_id="world"),
        r"grasps\.header\.frame_id: unknown frame_id 'world'; accepted: 'object' or 'base'",
    ),
    "unknown_path_frame": (
        lambda r: _set(r.object_trajectory.header, frame_id="map"),
        r"object_trajectory\.header\.frame_id: unknown frame_id 'map'; accepted: 'base'",
    ),
    "unknown_pose_frame": (
        lambda r: _set(_stamped(r, 1).header, frame_id="map"),
        r"object_trajectory\.poses\[1\]\.header: unknown frame_id 'map'",
    ),
    "negative_mass": (
        lambda r: _set(r.object_inertia, m=-0.34),
        r"object_inertia\.m: must be in \(0, inf\], got -0\.34",
    ),
    "absurd_mass": (
        lambda r: _set(r.object_inertia, m=1e6),
        r"object_inertia\.m: must be at most max_mass_kg=1000",
    ),
    "nan_mass": (lambda r: _set(r.object_inertia, m=math.nan), r"object_inertia\.m: must be"),
    "inf_inertia": (
        lambda r: _set(r.object_inertia, iyy=math.inf),
        r"object_inertia\.ixx\.\.izz: must be finite",
    ),
    "indefinite_inertia": (
        lambda r: _set(r.object_inertia, ixx=-1.0),
        r"object_inertia\.ixx\.\.izz: must be positive definite",
    ),
    "unknown_metric": (
        lambda r: _set(r, metric="median"),
        r"metric: must be one of mean, max, integral, got 'median'",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_REQUESTS))
def test_bad_request_is_refused_then_good_request_succeeds(
    ros: NodeUnderTest, core_ranking: Any, case: str
) -> None:
    mutate, pattern = BAD_REQUESTS[case]
    request = book_request()
    mutate(request)
    response = ros.rank(request)
    assert not response.success
    assert response.message
    assert re.search(pattern, response.message), response.message
    assert response.ranking.evaluations == []
    good = ros.rank(book_request())
    assert good.success, good.message
    assert tuple(good.ranking.order) == core_ranking.order


def test_too_many_samples_in_total_are_refused(ros: NodeUnderTest) -> None:
    request = book_request()
    request.grasps.poses = [request.grasps.poses[0]] * MAX_GRASPS
    request.object_trajectory = book_path(duration_s=1000.0)  # 10001 samples per grasp
    response = ros.rank(request)
    assert not response.success
    assert re.search(
        r"40 grasps x 10001 samples = 400040 samples; at most max_total_samples=100000",
        response.message,
    )


def test_slow_request_does_not_block_the_next_for_ever(ros: NodeUnderTest) -> None:
    # Bounds raised for this test only: 1000 grasps x 20001 samples take far longer than
    # max_compute_time_s, however fast the core is.
    results = ros.set_parameters(
        max_grasps=1000, max_samples=20001, max_total_samples=30_000_000, max_compute_time_s=1.0
    )
    assert all(r.successful for r in results), results
    try:
        slow = book_request()
        slow.grasps.poses = [copy.deepcopy(slow.grasps.poses[i % 3]) for i in range(1000)]
        slow.object_trajectory = book_path(duration_s=2000.0)
        slow_future = ros.rank_client.call_async(slow)
        time.sleep(0.3)  # the slow ranking holds the compute lock by now
        started = time.monotonic()
        busy = ros.rank(book_request())
        assert not busy.success
        assert busy.message.startswith("busy:"), busy.message
        assert time.monotonic() - started < 1.5  # answered after service_busy_timeout_s=0.3
        # parameters still answer while the ranking runs
        get = ros.wait(ros.get_client.call_async(GetParameters.Request(names=["metric"])), 2.0)
        assert get.values[0].string_value == "mean"
        abandoned = ros.wait(slow_future, 20.0)
        assert not abandoned.success
        assert "max_compute_time_s=1" in abandoned.message, abandoned.message
    finally:
        results = ros.set_parameters(
            max_compute_time_s=NODE_PARAMETERS["max_compute_time_s"],
            max_total_samples=NODE_PARAMETERS["max_total_samples"],
            max_grasps=MAX_GRASPS,
            max_samples=20000,
        )
        assert all(r.successful for r in results), results
    good = ros.rank(book_request())
    assert good.success, good.message


# --- Topics ------------------------------------------------------------------------------------


def test_topics_rank_and_publish(ros: NodeUnderTest, core_ranking: Any) -> None:
    received: dict[str, list[Any]] = {"ranking": [], "ranked": [], "markers": [], "diag": []}
    sub = ros.client.create_subscription
    subs = [
        sub(GraspRanking, "/grasp_safety/ranking", received["ranking"].append, LATCHED),
        sub(PoseArray, "/grasp_safety/ranked_grasps", received["ranked"].append, LATCHED),
        sub(MarkerArray, "/grasp_safety/markers", received["markers"].append, LATCHED),
        sub(DiagnosticArray, "/diagnostics", received["diag"].append, 10),
    ]
    grasps_pub = ros.client.create_publisher(PoseArray, "/grasp_safety/candidate_grasps", 10)
    path_pub = ros.client.create_publisher(Path, "/grasp_safety/object_trajectory", 10)
    try:
        assert ros.spin_until(
            lambda: grasps_pub.get_subscription_count() > 0 and path_pub.get_subscription_count()
        )
        # Only the first two book grasps, in reverse: a ranking no earlier test published.
        request = book_request()
        candidates = PoseArray(header=request.grasps.header, poses=request.grasps.poses[1::-1])
        path_pub.publish(request.object_trajectory)
        grasps_pub.publish(candidates)

        def new_ranking() -> GraspRanking | None:
            found = [r for r in received["ranking"] if len(r.evaluations) == 2]
            return found[-1] if found else None

        assert ros.spin_until(lambda: new_ranking() is not None)
        ranking = new_ranking()
        assert ranking is not None

        def its_markers() -> list[Marker]:  # published with the ranking's stamp
            found = [
                a.markers for a in received["markers"] if a.markers[0].header == ranking.header
            ]
            return found[-1] if found else []

        assert ros.spin_until(lambda: bool(its_markers()))
        # candidate i is book grasp 1 - i
        assert [1 - i for i in ranking.order] == [i for i in core_ranking.order if i < 2]
        for evaluation in ranking.evaluations:
            want = core_ranking.evaluations[1 - evaluation.index]
            np.testing.assert_allclose(evaluation.effective_mass_kg, want.effective_mass_kg, 1e-9)
        assert ros.spin_until(lambda: any(len(p.poses) == 2 for p in received["ranked"]))
        ranked = next(p for p in reversed(received["ranked"]) if len(p.poses) == 2)
        assert ranked.header.frame_id == "object"
        assert list(ranked.poses) == [candidates.poses[i] for i in ranking.order]
        markers = its_markers()
        assert markers[0].action == Marker.DELETEALL
        added = [m for m in markers if m.action == Marker.ADD]
        arrows = [m for m in added if m.type == Marker.ARROW]
        labels = [m for m in added if m.type == Marker.TEXT_VIEW_FACING]
        assert len(arrows) == len(labels) == 2
        safest = next(m for m in arrows if m.id == ranking.order[0])
        assert (safest.color.r, safest.color.g) == (0.0, 1.0)
        assert any(t.text.startswith("#1 ") for t in labels)

        # A bad candidate set is logged and reported on /diagnostics; the node keeps going.
        grasps_pub.publish(PoseArray(header=Header(frame_id="world"), poses=candidates.poses))

        def warned() -> bool:
            return any(
                s.level == DiagnosticStatus.WARN
                and "candidate_grasps.header.frame_id" in s.message
                for array in received["diag"]
                for s in array.status
            )

        assert ros.spin_until(warned)
        status = received["diag"][-1].status[0]
        values = {kv.key: kv.value for kv in status.values}
        assert int(values["refused_inputs"]) >= 1 and int(values["rankings"]) >= 1
        assert {"last_compute_time_s", "last_feasible_grasps", "last_infeasible_grasps"} <= set(
            values
        )
        count = len(received["ranking"])
        grasps_pub.publish(candidates)  # a new (good) candidate set is ranked again
        assert ros.spin_until(lambda: len(received["ranking"]) > count)
    finally:
        for subscription in subs:
            ros.client.destroy_subscription(subscription)
        ros.client.destroy_publisher(grasps_pub)
        ros.client.destroy_publisher(path_pub)


def test_object_inertia_topic_overrides_the_default(ros: NodeUnderTest) -> None:
    received: list[GraspRanking] = []
    subscription = ros.client.create_subscription(
        GraspRanking, "/grasp_safety/ranking", received.append, LATCHED
    )
    inertia_pub = ros.client.create_publisher(InertiaStamped, "/grasp_safety/object_inertia", 10)
    grasps_pub = ros.client.create_publisher(PoseArray, "/grasp_safety/candidate_grasps", 10)
    path_pub = ros.client.create_publisher(Path, "/grasp_safety/object_trajectory", 10)
    heavy = solid_box(3.4, [0.15, 0.22, 0.015])
    try:
        assert ros.spin_until(
            lambda: (
                min(p.get_subscription_count() for p in (inertia_pub, grasps_pub, path_pub)) > 0
            )
        )
        wrong_frame = InertiaStamped(header=Header(frame_id="base"))
        wrong_frame.inertia = inertia_msg_from_object(heavy)
        inertia_pub.publish(wrong_frame)
        inertia_pub.publish(
            InertiaStamped(
                header=Header(frame_id="object"), inertia=inertia_msg_from_object(heavy)
            )
        )

        def override() -> Any:
            return ros.node._snapshot().inertia_override

        assert ros.spin_until(lambda: override() is not None)
        assert ros.node.diagnostics_status().values  # still reporting
        request = book_request()
        path_pub.publish(request.object_trajectory)
        grasps_pub.publish(PoseArray(header=request.grasps.header, poses=request.grasps.poses[:1]))

        def single() -> list[GraspRanking]:
            return [r for r in received if len(r.evaluations) == 1]

        assert ros.spin_until(lambda: bool(single()))
        light = ros.rank(book_request()).ranking.evaluations[0]  # the service's own inertia
        assert single()[-1].evaluations[0].mean_effective_mass_kg > light.mean_effective_mass_kg
        inertia_pub.publish(InertiaStamped(header=Header(frame_id="object")))  # m = 0: clear
        assert ros.spin_until(lambda: override() is None)
    finally:
        ros.client.destroy_subscription(subscription)
        for publisher in (inertia_pub, grasps_pub, path_pub):
            ros.client.destroy_publisher(publisher)


def test_internal_error_is_answered_not_dropped(
    ros: NodeUnderTest, monkeypatch: pytest.MonkeyPatch
) -> None:
    bundle = ros.node._snapshot().bundle
    assert bundle is not None

    def broken_rank(*args: Any, **kwargs: Any) -> None:
        raise RuntimeError("simulated bug")

    monkeypatch.setattr(bundle.evaluator, "rank", broken_rank)
    response = ros.rank(book_request())
    assert not response.success
    assert response.message == "internal error: RuntimeError: simulated bug"
    monkeypatch.undo()
    assert ros.rank(book_request()).success


# --- Parameters at run time --------------------------------------------------------------------


def test_invalid_parameters_are_refused_with_a_reason(ros: NodeUnderTest) -> None:
    (result,) = ros.set_parameters(object__mass_kg=-1.0)
    assert not result.successful and "object.mass_kg" in result.reason
    (result,) = ros.set_parameters(tip_frame="no_such_frame")
    assert not result.successful
    assert "tip_frame: frame 'no_such_frame' not found" in result.reason
    (result,) = ros.set_parameters(ik_seed=[0.0, 1.0])
    assert not result.successful and "ik_seed" in result.reason
    (result,) = ros.set_parameters(metric="median")
    assert not result.successful and "metric" in result.reason
    (result,) = ros.set_parameters(trajectory__dt_s="fast")
    assert not result.successful and "trajectory.dt_s" in result.reason
    response = ros.rank(book_request())  # nothing changed
    assert response.success and response.ranking.metric == "mean"


def test_valid_parameter_change_applies(ros: NodeUnderTest) -> None:
    try:
        (result,) = ros.set_parameters(metric="max")
        assert result.successful, result.reason
        response = ros.rank(book_request())
        assert response.success and response.ranking.metric == "max"
        for evaluation in response.ranking.evaluations:
            assert evaluation.score == max(evaluation.effective_mass_kg)
        (result,) = ros.set_parameters(tip_frame="right_wrist")  # rebuilds the robot model
        assert result.successful, result.reason
        assert ros.rank(book_request()).success
    finally:
        ros.set_parameters(metric="mean", tip_frame="right_gripper")


# --- Robot from /robot_description -------------------------------------------------------------


def test_robot_from_robot_description_topic() -> None:
    harness = NodeUnderTest(
        {"base_frame": "base_link", "tip_frame": "tool", "object.mass_kg": 0.0}
    )
    publisher = harness.client.create_publisher(String, "/robot_description", LATCHED)
    try:
        request = book_request()
        request.object_trajectory.header.frame_id = "base_link"
        not_ready = harness.rank(request)
        assert not not_ready.success
        assert not_ready.message.startswith("no robot description yet")

        bad = serial_arm_urdf(ARM6_AXES).replace('"tool"', '"flange"')
        publisher.publish(String(data=bad))  # no tip frame 'tool': refused, still no robot
        time.sleep(0.3)
        assert not harness.node.has_robot
        publisher.publish(String(data=serial_arm_urdf(ARM6_AXES)))
        assert harness.spin_until(lambda: harness.node.has_robot)
        response = harness.rank(request)
        assert response.success, response.message
        assert len(response.ranking.evaluations) == 3
        assert len(response.ranking.joint_names) == 6

        publisher.publish(String(data=bad))  # a bad update keeps the current robot
        time.sleep(0.3)
        assert harness.node.has_robot
        assert harness.rank(request).success
    finally:
        harness.client.destroy_publisher(publisher)
        harness.close()
