"""The node over real rclpy: service, topics, bad inputs, parameters, robot from a topic.

The node runs in-process in a thread of its NodeExecutor with its own rclpy Context; the
test client is a second node in the same context with its own executor. Each context claims
its own ROS_DOMAIN_ID (ros_domains) and uses localhost-only discovery, so parallel runs do not
cross-talk.
"""

from __future__ import annotations

import array
import copy
import math
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
from rcl_interfaces.srv import GetParameters, SetParameters, SetParametersAtomically
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_domains import claim_ros_domain
from std_msgs.msg import Float64MultiArray, Header, String
from visualization_msgs.msg import Marker, MarkerArray

from grasp_safety_ros.core import (
    Grasp,
    GraspSafetyEvaluator,
    ObjectTrajectory,
    RobotModel,
    solid_box,
)
from grasp_safety_ros.core.analyses.exposed_points import box_corners_in_object
from grasp_safety_ros.core.analyses.iso15066 import assess_grasp
from grasp_safety_ros.core.analyses.multi_objective import rank_with_quality
from grasp_safety_ros.core.analyses.safety_report import (
    AnalysisOptions,
    analyse,
)
from grasp_safety_ros.core.analyses.uncertainty import InertiaUncertainty
from grasp_safety_ros.core.method.executable import joint_velocities_accelerations
from grasp_safety_ros.core.method.posture import PostureConfig
from grasp_safety_ros.core.pipeline import PipelineRequest, run_pipeline
from grasp_safety_ros.paths import config_file
from grasp_safety_ros.ros.conversions import inertia_msg_from_object, pose_msg_from_transform
from grasp_safety_ros.ros.node import EXECUTOR_THREADS, GraspSafetyNode
from grasp_safety_ros.ros.runtime.rclpy_private import NodeExecutor, join_callbacks
from grasp_safety_ros.scenario.schema import load_scenario

BOOK = load_scenario(config_file("book_baxter.yaml"))
BOOK_GRASPS = [Grasp(g.transform_tip_to_object, f"grasp_{i}") for i, g in enumerate(BOOK.grasps)]
"""The book's grasps named as the node names candidates."""
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
    "object.box_size_m": [0.15, 0.22, 0.015],  # the book: exposed points for metric_point
    "trajectory.dt_s": DT_S,
    "max_grasps": MAX_GRASPS,
    "max_total_samples": 100_000,
    "max_compute_time_s": 10.0,  # known-good requests must finish on a loaded machine too
    "service_busy_timeout_s": 0.3,
    "diagnostics_period_s": 0.5,
    "posture.restarts": 0,  # the paper's single IK; posture selection: its own tests below
    "response.joint_trajectories": MAX_GRASPS,  # every grasp's; the default (1): tests below
}


def start_context() -> Context:
    """A fresh rclpy context on a domain claimed for it (ros_domains; released when the
    context shuts down), discovery limited to this host."""
    claim = claim_ros_domain()
    context = Context()
    try:
        rclpy.init(context=context, domain_id=claim.domain_id)
    except BaseException:
        claim.release()
        raise
    context.on_shutdown(claim.release)
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
        self.executor = NodeExecutor(num_threads=EXECUTOR_THREADS, context=self.context)
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
        """Stop spinning, then destroy: the spin thread and the callbacks end first, as in
        the node's main (a spin still taking an event's data from a destroyed publisher
        raised InvalidHandle in that thread)."""
        self.executor.shutdown()
        self.thread.join(timeout=10.0)
        join_callbacks(self.executor)
        self.node.destroy_node()
        self.client.destroy_node()
        rclpy.shutdown(context=self.context)

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


@pytest.fixture()
def own_ros() -> Iterator[NodeUnderTest]:
    """A node of its own (own ROS domain): no candidate set, trajectory or quality left by
    earlier tests, which the topic-pairing rules would otherwise act on."""
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


def book_trajectory(duration_s: float = 2.0) -> ObjectTrajectory:
    return ObjectTrajectory(
        BOOK.trajectory.transform_object_to_base_start,
        BOOK.trajectory.transform_object_to_base_goal,
        duration_s,
        DT_S,
    )


@pytest.fixture(scope="module")
def core_evaluator() -> GraspSafetyEvaluator:
    robot = RobotModel.from_urdf("example-robot-data:baxter", "base", "right_gripper")
    return GraspSafetyEvaluator(robot)


@pytest.fixture(scope="module")
def core_ranking(core_evaluator: GraspSafetyEvaluator) -> Any:
    return core_evaluator.rank(
        BOOK_GRASPS, BOOK.object_inertia, book_trajectory(), BOOK.robot.seed, "mean"
    )


def core_report(
    evaluator: GraspSafetyEvaluator, ranking: Any, duration_s: float = 2.0, **options: Any
) -> Any:
    """The core's SafetyReport of the book scenario with the node's box points."""
    points = box_corners_in_object(NODE_PARAMETERS["object.box_size_m"])
    return analyse(
        evaluator,
        BOOK_GRASPS[: len(ranking.evaluations)],
        BOOK.object_inertia,
        book_trajectory(duration_s),
        AnalysisOptions(points_in_object_m=points, **options),
        ranking=ranking,
    )


def core_pipeline(evaluator: GraspSafetyEvaluator, posture: PostureConfig, **options: Any) -> Any:
    """The core pipeline's SafetyReport of the book scenario with the node's box points."""
    points = box_corners_in_object(NODE_PARAMETERS["object.box_size_m"])
    request = PipelineRequest(
        tuple(BOOK_GRASPS),
        BOOK.object_inertia,
        book_trajectory(),
        "mean",
        AnalysisOptions(points_in_object_m=points, **options),
        posture,
        BOOK.robot.seed,
    )
    return run_pipeline(evaluator, request)


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
        directions = np.reshape(got.direction_xyz, (-1, 3))
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


def same_messages(first: Any, second: Any) -> bool:
    """Field-by-field equality of messages (or sequences of them) where NaN equals NaN.

    Message ``==`` says NaN != NaN, and serialised bytes differ in their padding.
    """
    if hasattr(first, "get_fields_and_field_types"):
        return type(first) is type(second) and all(
            same_messages(getattr(first, f), getattr(second, f))
            for f in first.get_fields_and_field_types()
        )
    if isinstance(first, float) and isinstance(second, float):
        return first == second or (math.isnan(first) and math.isnan(second))
    if isinstance(first, (list, tuple, array.array, np.ndarray)):
        return len(first) == len(second) and all(
            same_messages(a, b) for a, b in zip(first, second, strict=True)
        )
    return bool(first == second)


def test_service_is_deterministic(ros: NodeUnderTest) -> None:
    first, second = ros.rank(book_request()), ros.rank(book_request())
    assert first.success and second.success
    assert same_messages(first.ranking.evaluations, second.ranking.evaluations)
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
        r"object_trajectory\.poses: has 1 pose; at least 2",
    ),
    "path_with_repeated_poses": (
        lambda r: _set(r.object_trajectory, poses=r.object_trajectory.poses * 2 + []),
        r"object_trajectory\.poses\[2\]\.header\.stamp: times must increase strictly",
    ),
    "unordered_stamps": (
        lambda r: _set(_stamped(r, 0).header, stamp=Time(sec=5)),
        r"object_trajectory\.poses\[1\]\.header\.stamp: times must increase strictly",
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
    "quality_of_wrong_length": (
        lambda r: _set(r, grasp_quality=[0.5, 0.7]),
        r"^grasp_quality: must have one value per grasp \(3\), got 2$",
    ),
    "quality_not_finite": (
        lambda r: _set(r, grasp_quality=[0.5, math.nan, 0.7]),
        r"^grasp_quality: must be finite",
    ),
    "unknown_metric_point": (
        lambda r: _set(r, metric_point="centre"),
        r"^metric_point: must be one of tip, leading_point, worst_point, got 'centre'",
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
    # Bounds raised for this test only: 1000 grasps x 9991 samples take far longer than
    # max_compute_time_s, however fast the core is. No speed is assumed: the test waits for
    # the node to hold the compute lock, and the time bounds are generous (the deadline is
    # checked after every grasp, also on the worker pool: test_performance_paths).
    max_compute_time_s = 5.0  # the small request below must arrive within it
    results = ros.set_parameters(
        max_grasps=1000,
        max_samples=20001,
        max_total_samples=10_000_000,
        max_compute_time_s=max_compute_time_s,
        service_busy_timeout_s=max_compute_time_s,  # a slice ends after a batch of grasps
    )
    assert all(r.successful for r in results), results
    try:
        slow = book_request()
        slow.grasps.poses = [copy.deepcopy(slow.grasps.poses[i % 3]) for i in range(1000)]
        slow.object_trajectory = book_path(duration_s=999.0)
        slow_future = ros.rank_client.call_async(slow)
        # the slow ranking holds the compute lock (until abandoned, checked after each grasp)
        assert ros.spin_until(ros.node._compute_lock.locked, 60.0), "slow ranking never started"
        # a small request is ranked meanwhile: the slow one hands the lock over after a slice
        # (it was answered busy after service_busy_timeout_s before)
        small = ros.rank(book_request())
        assert small.success, small.message
        assert not slow_future.done()
        # parameters still answer while the ranking runs
        get = ros.wait(ros.get_client.call_async(GetParameters.Request(names=["metric"])), 10.0)
        assert get.values[0].string_value == "mean"
        abandoned = ros.wait(slow_future, 120.0)
        assert not abandoned.success
        assert "max_compute_time_s=5" in abandoned.message, abandoned.message
    finally:
        results = ros.set_parameters(
            max_compute_time_s=NODE_PARAMETERS["max_compute_time_s"],
            max_total_samples=NODE_PARAMETERS["max_total_samples"],
            max_grasps=MAX_GRASPS,
            max_samples=20000,
            service_busy_timeout_s=NODE_PARAMETERS["service_busy_timeout_s"],
        )
        assert all(r.successful for r in results), results
    good = ros.rank(book_request())
    assert good.success, good.message


# --- Topics ------------------------------------------------------------------------------------


def test_result_topics_are_built_for_subscribers_only(
    own_ros: NodeUnderTest, monkeypatch: pytest.MonkeyPatch
) -> None:
    """No subscriber: no markers are built and the ranking is not published (serialised)
    during the call. A late volatile subscriber is not sent them (it asked for later messages
    only); nor is a transient-local one while the volatile one stays (a publication reaches
    both). A transient-local subscriber alone, or left alone, gets the last ones."""
    from rclpy.publisher import Publisher

    import grasp_safety_ros.ros.service.ranking_inputs as node_module  # builds the markers

    ros = own_ros
    built: list[int] = []
    original = node_module.markers_msg

    def counting_markers_msg(*args: Any, **kwargs: Any) -> MarkerArray:
        built.append(1)
        return original(*args, **kwargs)

    published: list[str] = []
    original_publish = Publisher.publish

    def recording_publish(self: Publisher, msg: Any) -> None:
        published.append(type(msg).__name__)
        original_publish(self, msg)

    monkeypatch.setattr(node_module, "markers_msg", counting_markers_msg)
    monkeypatch.setattr(Publisher, "publish", recording_publish)
    response = ros.rank(book_request())
    assert response.success, response.message
    assert built == []
    assert "GraspRanking" not in published
    assert "MarkerArray" not in published
    received: dict[str, list[Any]] = {"volatile": [], "ranking": [], "markers": []}
    volatile = QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE
    )
    ranking_pub = ros.node._ranking_pub.publisher
    volatile_sub = ros.client.create_subscription(
        GraspRanking, "/grasp_safety/ranking", received["volatile"].append, volatile
    )
    assert ros.spin_until(lambda: ranking_pub.get_subscription_count() == 1)
    ros.spin_until(lambda: bool(received["volatile"]), 1.0)
    assert received["volatile"] == [] and built == []
    subscriptions = [
        ros.client.create_subscription(
            GraspRanking, "/grasp_safety/ranking", received["ranking"].append, LATCHED
        ),
        ros.client.create_subscription(
            MarkerArray, "/grasp_safety/markers", received["markers"].append, LATCHED
        ),
    ]
    try:
        assert ros.spin_until(lambda: ranking_pub.get_subscription_count() == 2)
        # the markers' only subscriber is transient-local: sent; the ranking's are not all
        assert ros.spin_until(lambda: bool(received["markers"]), 30.0)
        ros.spin_until(lambda: bool(received["ranking"] or received["volatile"]), 1.0)
        assert received["ranking"] == [] and received["volatile"] == []
        assert published.count("GraspRanking") == 0 and built == [1]
        ros.client.destroy_subscription(volatile_sub)
        assert ros.spin_until(lambda: bool(received["ranking"]), 30.0)
        assert published.count("GraspRanking") == 1 and received["volatile"] == []
        ranking = received["ranking"][-1]
        assert ranking.header.stamp == response.ranking.header.stamp
        assert list(ranking.order) == list(response.ranking.order)
        arrows = [m for m in received["markers"][-1].markers if m.ns == "grasps"]
        assert sorted(m.id for m in arrows) == [0, 1, 2]
    finally:
        for subscription in subscriptions:
            ros.client.destroy_subscription(subscription)


def test_late_subscriber_gets_the_latest_ranking_only(ros: NodeUnderTest) -> None:
    """A ranking published to a subscriber that has left is not what a later subscriber
    receives once a newer ranking was computed with nobody listening: it gets the newer one
    alone (published at once, since the history held the older), even while the publisher's
    lock is held."""
    stamps: list[tuple[int, int]] = []
    first = ros.client.create_subscription(
        GraspRanking,
        "/grasp_safety/ranking",
        lambda m: stamps.append((m.header.stamp.sec, m.header.stamp.nanosec)),
        LATCHED,
    )
    publisher = ros.node._ranking_pub
    assert ros.spin_until(lambda: publisher.publisher.get_subscription_count() > 0)
    older = ros.rank(book_request())
    assert older.success, older.message
    older_stamp = (older.ranking.header.stamp.sec, older.ranking.header.stamp.nanosec)
    assert ros.spin_until(lambda: older_stamp in stamps, 30.0)
    ros.client.destroy_subscription(first)
    assert ros.spin_until(lambda: publisher.publisher.get_subscription_count() == 0)
    newer = ros.rank(book_request())
    assert newer.success, newer.message
    newer_stamp = (newer.ranking.header.stamp.sec, newer.ranking.header.stamp.nanosec)
    assert newer_stamp != older_stamp
    late: list[GraspRanking] = []
    keep_ten = QoSProfile(  # keeps every message that arrives, not only the last
        depth=10,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL,
    )
    with publisher._lock:  # the publication on matching waits
        second = ros.client.create_subscription(
            GraspRanking, "/grasp_safety/ranking", late.append, keep_ten
        )
        assert ros.spin_until(lambda: publisher.publisher.get_subscription_count() > 0)
        ros.spin_until(lambda: bool(late), 1.0)
    try:
        assert ros.spin_until(lambda: bool(late), 30.0)
        ros.spin_until(lambda: len(late) > 1, 0.5)  # an older one would have come by now
        assert [(m.header.stamp.sec, m.header.stamp.nanosec) for m in late] == [newer_stamp]
        assert list(late[0].order) == list(newer.ranking.order)
    finally:
        ros.client.destroy_subscription(second)


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
    (result,) = ros.set_parameters(metric="median")
    assert not result.successful and "metric" in result.reason
    (result,) = ros.set_parameters(trajectory__dt_s="fast")  # declared a double
    assert not result.successful and "expected 'Type.DOUBLE' got 'Type.STRING'" in result.reason
    response = ros.rank(book_request())  # nothing changed
    assert response.success and response.ranking.metric == "mean"


def test_robot_parameters_that_do_not_fit_are_pending_until_the_group_is_consistent(
    ros: NodeUnderTest,
) -> None:
    """A frame or seed that does not fit the other robot parameters is accepted as pending
    (another parameter of the group may follow: ros2 param load sets them one at a time), the
    old model serving and /diagnostics saying why; a change that makes the group consistent
    applies it. A complete group (urdf, base_frame, tip_frame, ik_seed) that does not fit is
    refused with the reason."""
    try:
        (result,) = ros.set_parameters(tip_frame="no_such_frame")
        assert result.successful, result.reason
        status = ros.node.diagnostics_status()
        assert status.level == DiagnosticStatus.WARN
        assert "robot parameters pending (tip_frame)" in status.message
        assert "tip_frame: frame 'no_such_frame' not found" in status.message
        assert status.hardware_id == "base->right_gripper"  # the model that serves
        assert ros.rank(book_request()).success
        (result,) = ros.set_parameters(ik_seed=[0.0, 1.0])
        assert result.successful, result.reason
        (result,) = ros.set_parameters(base_frame="base")
        assert result.successful, result.reason
        (result,) = ros.set_parameters(urdf="example-robot-data:baxter")  # completes the group
        assert not result.successful
        pending = "base_frame, ik_seed, tip_frame, urdf"
        assert f"robot parameters {pending} are not consistent" in result.reason
        assert "the model from urdf (base -> right_gripper) serves" in result.reason
        (result,) = ros.set_parameters(tip_frame="right_gripper")  # the seed is still wrong
        assert result.successful
        assert "ik_seed: must have shape [7]" in ros.node.diagnostics_status().message
        (result,) = ros.set_parameters(ik_seed=list(BOOK.robot.seed))  # consistent: applied
        assert result.successful, result.reason
        assert "robot parameters" not in ros.node.diagnostics_status().message
    finally:
        ros.set_parameters(tip_frame="right_gripper", ik_seed=list(BOOK.robot.seed))


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
        request.metric_point = "leading_point"  # this node has no object points
        refused = harness.rank(request)
        assert not refused.success
        assert refused.message.startswith(
            "metric_point: 'leading_point' needs the object's points: set the node parameter "
            "object.points_in_object_m"
        ), refused.message
        request.metric_point = ""

        publisher.publish(String(data=bad))  # a bad update keeps the current robot
        time.sleep(0.3)
        assert harness.node.has_robot
        assert harness.rank(request).success
    finally:
        harness.client.destroy_publisher(publisher)
        harness.close()


# --- Analyses beyond the paper (issue #6) ------------------------------------------------------


def nan_equal(got: float, want: float) -> bool:
    return (math.isnan(got) and math.isnan(want)) or got == pytest.approx(want, rel=1e-9, abs=1e-9)


def test_default_analyses_leave_the_paper_fields_and_order(
    ros: NodeUnderTest, core_ranking: Any
) -> None:
    response = ros.rank(book_request())
    assert response.success, response.message
    ranking = response.ranking
    assert_matches_core(ranking, core_ranking)  # the old fields, order included
    assert tuple(ranking.safety_order) == tuple(ranking.paper_order) == core_ranking.order
    assert (ranking.metric_point, ranking.rank_by) == ("tip", "safety")
    assert list(ranking.pareto_set) == [] and math.isnan(ranking.safety_weight)
    assert ranking.uncertainty_message == "" and math.isnan(ranking.order_stability)
    for evaluation in ranking.evaluations:
        assert evaluation.safety_score == evaluation.score
        assert math.isnan(evaluation.grasp_quality) and math.isnan(evaluation.combined_score)
        assert math.isnan(evaluation.worst_case_score) and not evaluation.redundancy_applied
        # effort is on by default (core.options): its torques, the order unchanged
        assert len(evaluation.peak_abs_torque) == len(ranking.joint_names)
        # the box gives the exposed points; they do not change the tip score
        count = len(evaluation.effective_mass_kg)
        assert len(evaluation.leading_point_effective_mass_kg) == count
        assert len(evaluation.worst_point_effective_mass_kg) == count


def test_iso_fields_equal_the_core_assessment(ros: NodeUnderTest, core_ranking: Any) -> None:
    response = ros.rank(book_request())
    assert response.success, response.message
    for got, evaluation in zip(
        response.ranking.evaluations, core_ranking.evaluations, strict=True
    ):
        want = assess_grasp(evaluation)  # tip, every region
        assert got.iso_admissible == want.admissible_where_permitted
        assert got.iso_limiting_region == want.limiting_region
        assert got.iso_min_duration_s == pytest.approx(want.min_duration_s, rel=1e-9)
        assert [r.region for r in got.iso_ts_15066] == [r.region.name for r in want.regions]
        for region, expected in zip(got.iso_ts_15066, want.regions, strict=True):
            permitted = expected.transient_contact_permitted
            assert region.transient_contact_permitted == permitted
            assert region.admissible == expected.admissible
            limit = expected.region.max_transient_force_n
            assert nan_equal(region.max_transient_force_n, math.nan if limit is None else limit)
            ratio = expected.worst_force_ratio if permitted else math.nan
            assert nan_equal(region.worst_force_ratio, ratio)
            assert nan_equal(region.peak_contact_force_n, expected.peak_contact_force_n)
            speed = float(np.min(expected.max_permissible_speed_m_s))
            assert nan_equal(region.min_max_permissible_speed_m_s, speed)
            assert region.min_duration_s == pytest.approx(expected.min_duration_s, rel=1e-9)


def test_too_fast_motion_is_not_iso_admissible_and_labelled(ros: NodeUnderTest) -> None:
    markers: list[MarkerArray] = []
    subscription = ros.client.create_subscription(
        MarkerArray, "/grasp_safety/markers", markers.append, LATCHED
    )
    try:
        request = book_request()
        # a book ten times heavier, in 1 s: contact forces above the ISO/TS 15066 limits
        request.object_inertia = inertia_msg_from_object(solid_box(3.4, [0.15, 0.22, 0.015]))
        request.object_trajectory = book_path(duration_s=1.0)
        response = ros.rank(request)
        assert response.success, response.message
        stamp = response.ranking.header.stamp
        assert ros.spin_until(lambda: any(a.markers[0].header.stamp == stamp for a in markers))
        array = next(a for a in markers if a.markers[0].header.stamp == stamp)
        labels = [m.text for m in array.markers if m.type == Marker.TEXT_VIEW_FACING]
        for evaluation in response.ranking.evaluations:
            assert evaluation.feasible, evaluation.reason
            assert not evaluation.iso_admissible
            assert evaluation.iso_min_duration_s > 1.0
        assert len(labels) == 3
        assert all(text.endswith(", ISO/TS 15066: not admissible") for text in labels)
    finally:
        ros.client.destroy_subscription(subscription)


def test_grasp_quality_gives_the_core_combination_and_pareto_set(
    ros: NodeUnderTest, core_ranking: Any
) -> None:
    quality = [0.1, 1.0, 0.0]  # grasp 1 (least safe) has the best quality
    request = book_request()
    request.grasp_quality = quality
    response = ros.rank(request)
    assert response.success, response.message
    ranking = response.ranking
    scores = [e.score for e in core_ranking.evaluations]
    expected = rank_with_quality(scores, quality, 0.5)
    assert tuple(ranking.order) == expected.order
    assert tuple(ranking.pareto_set) == expected.pareto_set == (0, 1)
    assert tuple(ranking.order) != core_ranking.order  # quality changed the order
    assert tuple(ranking.safety_order) == tuple(ranking.paper_order) == core_ranking.order
    assert ranking.safety_weight == 0.5
    request_poses = book_request().grasps.poses
    assert list(ranking.ranked_grasps.poses) == [request_poses[i] for i in expected.order]
    for k, evaluation in enumerate(ranking.evaluations):
        assert evaluation.grasp_quality == quality[k]
        assert evaluation.combined_score == pytest.approx(expected.combined[k], rel=1e-9)
        assert evaluation.pareto_optimal == (k in expected.pareto_set)


def test_leading_point_metric_scores_the_leading_point(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator, core_ranking: Any
) -> None:
    request = book_request()
    request.metric_point = "leading_point"
    response = ros.rank(request)
    assert response.success, response.message
    ranking = response.ranking
    want = core_report(core_evaluator, core_ranking, metric_point="leading_point")
    assert ranking.metric_point == "leading_point"
    assert tuple(ranking.order) == tuple(ranking.safety_order) == want.order
    assert tuple(ranking.paper_order) == core_ranking.order
    for k, evaluation in enumerate(ranking.evaluations):
        masses = evaluation.leading_point_effective_mass_kg
        assert evaluation.safety_score == pytest.approx(np.mean(masses), rel=1e-12)
        assert evaluation.safety_score == pytest.approx(want.scores[k], rel=1e-9)
        np.testing.assert_allclose(masses, want.exposed[k].leading_effective_mass_kg, rtol=1e-9)
        np.testing.assert_allclose(
            evaluation.worst_point_effective_mass_kg,
            want.exposed[k].worst_effective_mass_kg,
            rtol=1e-9,
        )
        assert evaluation.iso_min_duration_s == pytest.approx(want.iso[k].min_duration_s, 1e-9)
    scores = [ranking.evaluations[i].safety_score for i in ranking.order]
    assert scores == sorted(scores)


def test_analyses_switched_on_by_parameters(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator, core_ranking: Any
) -> None:
    results = ros.set_parameters(
        uncertainty__mass_fraction=0.3,
        uncertainty__samples=4,
        effort__enabled=True,
        iso_ts_15066__regions=["chest", "face"],
        rank_by="effort",
    )
    assert all(r.successful for r in results), results
    try:
        response = ros.rank(book_request())
    finally:
        results = ros.set_parameters(
            uncertainty__mass_fraction=0.0,
            uncertainty__samples=64,
            effort__enabled=False,
            iso_ts_15066__regions=[],  # all regions
            rank_by="safety",
        )
        assert all(r.successful for r in results), results
    assert response.success, response.message
    ranking = response.ranking
    want = core_report(
        core_evaluator,
        core_ranking,
        uncertainty=InertiaUncertainty(mass_fraction=0.3, num_random_samples=4),
        effort=True,
        iso_regions=("chest", "face"),
        rank_by="effort",
    )
    assert ranking.rank_by == "effort" and ranking.effort_criterion == "peak_fraction"
    assert tuple(ranking.order) == want.order
    assert tuple(ranking.safety_order) == core_ranking.order
    uncertainty = want.uncertainty
    assert ranking.uncertainty_message == uncertainty.message
    assert ranking.ranking_flips == uncertainty.ranking_flips
    assert ranking.order_stability == pytest.approx(uncertainty.order_stability)
    assert tuple(ranking.worst_case_order) == uncertainty.worst_case_order
    for k, evaluation in enumerate(ranking.evaluations):
        spread, effort = uncertainty.grasps[k], want.effort[k]
        assert evaluation.worst_case_score == pytest.approx(spread.worst_case_score, rel=1e-9)
        assert evaluation.percentile_score == pytest.approx(spread.percentile_score, rel=1e-9)
        assert evaluation.probability_safest == spread.probability_safest
        np.testing.assert_allclose(evaluation.peak_abs_torque, effort.peak_abs_torque, 1e-9)
        np.testing.assert_allclose(evaluation.rms_torque, effort.rms_torque, 1e-9)
        assert evaluation.effort_score == pytest.approx(effort.score("peak_fraction"), 1e-9)
        assert [r.region for r in evaluation.iso_ts_15066] == ["chest", "face"]
    efforts = [ranking.evaluations[i].effort_score for i in ranking.order]
    assert efforts == sorted(efforts)


def test_redundancy_resolution(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator, core_ranking: Any
) -> None:
    (result,) = ros.set_parameters(redundancy__enabled=True)
    assert result.successful, result.reason
    try:
        request = book_request()
        request.grasps.poses = request.grasps.poses[:1]  # ~0.4 s per grasp
        response = ros.rank(request)
    finally:
        (result,) = ros.set_parameters(redundancy__enabled=False)
        assert result.successful, result.reason
    assert response.success, response.message
    (evaluation,) = response.ranking.evaluations
    first = GraspSafetyEvaluator(core_evaluator.robot).rank(
        BOOK_GRASPS[:1], BOOK.object_inertia, book_trajectory(), BOOK.robot.seed, "mean"
    )
    (resolution,) = core_report(core_evaluator, first, redundancy=True).redundancy
    assert evaluation.redundancy_applied and resolution.applied  # Baxter's arm: 7 joints
    assert evaluation.score_without_redundancy == pytest.approx(evaluation.score, rel=1e-12)
    assert evaluation.safety_score == pytest.approx(resolution.score, rel=1e-9)
    assert evaluation.safety_score < evaluation.score
    np.testing.assert_allclose(
        evaluation.effective_mass_with_redundancy_kg, resolution.effective_mass_kg, rtol=1e-9
    )


def test_quality_topic_pairs_with_candidate_sets(own_ros: NodeUnderTest) -> None:
    received: list[GraspRanking] = []
    diagnostics: list[DiagnosticArray] = []
    subs = [
        own_ros.client.create_subscription(
            GraspRanking, "/grasp_safety/ranking", received.append, LATCHED
        ),
        own_ros.client.create_subscription(
            DiagnosticArray, "/diagnostics", diagnostics.append, 10
        ),
    ]
    quality_pub = own_ros.client.create_publisher(
        Float64MultiArray, "/grasp_safety/candidate_grasp_quality", 10
    )
    grasps_pub = own_ros.client.create_publisher(PoseArray, "/grasp_safety/candidate_grasps", 10)
    path_pub = own_ros.client.create_publisher(Path, "/grasp_safety/object_trajectory", 10)
    publishers = (quality_pub, grasps_pub, path_pub)
    request = book_request()
    two = PoseArray(header=request.grasps.header, poses=request.grasps.poses[:2])
    three = request.grasps

    def next_ranking() -> GraspRanking:
        """The first ranking computed after now (not the latched one of an earlier test)."""
        now = own_ros.node.get_clock().now().nanoseconds

        def new() -> list[GraspRanking]:
            stamps = [(r.header.stamp.sec * 10**9 + r.header.stamp.nanosec, r) for r in received]
            return [r for t, r in stamps if t > now]

        assert own_ros.spin_until(lambda: bool(new()))
        time.sleep(0.1)  # a second ranking would have come by now
        own_ros.client_executor.spin_once(timeout_sec=0.05)
        assert len(new()) == 1
        return new()[0]

    try:
        assert own_ros.spin_until(lambda: min(p.get_subscription_count() for p in publishers) > 0)
        path_pub.publish(request.object_trajectory)
        # 1. quality first, then its set: ranked with the quality
        quality_pub.publish(Float64MultiArray(data=[0.0, 1.0]))
        time.sleep(0.2)  # one publisher per topic: let the quality arrive first
        grasps_pub.publish(two)
        ranking = next_ranking()
        assert [e.grasp_quality for e in ranking.evaluations] == [0.0, 1.0]
        assert len(ranking.pareto_set) > 0
        # 2. a new set alone: the used quality is not reused
        grasps_pub.publish(two)
        ranking = next_ranking()
        assert all(math.isnan(e.grasp_quality) for e in ranking.evaluations)
        # 3. the quality after its set: the set is ranked again, with it
        quality_pub.publish(Float64MultiArray(data=[0.5, 0.25]))
        ranking = next_ranking()
        assert [e.grasp_quality for e in ranking.evaluations] == [0.5, 0.25]
        # 4. a waiting quality of another length is discarded by the next set, with a warning
        quality_pub.publish(Float64MultiArray(data=[1.0, 2.0, 3.0, 4.0]))
        time.sleep(0.2)
        grasps_pub.publish(three)
        ranking = next_ranking()
        assert len(ranking.evaluations) == 3
        assert all(math.isnan(e.grasp_quality) for e in ranking.evaluations)

        def warned() -> bool:
            return any(
                "candidate_grasp_quality.data: has 4 values but the new candidate set has 3"
                in s.message
                for array in diagnostics
                for s in array.status
            )

        assert own_ros.spin_until(warned)
    finally:
        for subscription in subs:
            own_ros.client.destroy_subscription(subscription)
        for publisher in publishers:
            own_ros.client.destroy_publisher(publisher)


# --- Posture selection and the executable joint trajectory -----------------------------------


def _seconds(duration: Any) -> float:
    return duration.sec + 1e-9 * duration.nanosec


def assert_joint_trajectory(evaluation: Any, joint_names: Any, times: Any, positions: Any) -> None:
    trajectory = evaluation.joint_trajectory
    assert list(trajectory.joint_names) == list(joint_names)
    assert len(trajectory.points) == len(times)
    velocities, accelerations = joint_velocities_accelerations(times, positions)
    for point, t, q, qd, qdd in zip(
        trajectory.points, times, positions, velocities, accelerations, strict=True
    ):
        assert _seconds(point.time_from_start) == pytest.approx(t, abs=1e-9)
        np.testing.assert_allclose(point.positions, q, rtol=0, atol=1e-12)
        np.testing.assert_allclose(point.velocities, qd, rtol=0, atol=1e-12)
        np.testing.assert_allclose(point.accelerations, qdd, rtol=0, atol=1e-12)


def test_single_ik_posture_fields_and_joint_trajectory(
    ros: NodeUnderTest, core_ranking: Any
) -> None:
    response = ros.rank(book_request())
    assert response.success, response.message
    ranking = response.ranking
    for got, want in zip(ranking.evaluations, core_ranking.evaluations, strict=True):
        assert got.score_single_ik == got.score == got.score_range_min == got.score_range_max
        assert (got.postures_tried, got.postures_feasible) == (1, 1)
        np.testing.assert_allclose(got.start_positions, want.joint_positions[0], atol=1e-12)
        assert_joint_trajectory(got, ranking.joint_names, want.times_s, want.joint_positions)
        header = got.joint_trajectory.header
        assert header.frame_id == "base" and (header.stamp.sec, header.stamp.nanosec) == (0, 0)


def test_posture_selection_by_parameter_equals_the_core(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator
) -> None:
    (result,) = ros.set_parameters(posture__restarts=6)
    assert result.successful, result.reason
    try:
        response = ros.rank(book_request())
    finally:
        (result,) = ros.set_parameters(posture__restarts=0)
        assert result.successful, result.reason
    assert response.success, response.message
    expected = core_pipeline(core_evaluator, PostureConfig(restarts=6), iso_regions=()).ranking
    assert_matches_core(response.ranking, expected)
    for got, want, posture in zip(
        response.ranking.evaluations, expected.evaluations, expected.postures, strict=True
    ):
        assert got.score_single_ik == pytest.approx(posture.score_single_ik, rel=1e-12)
        assert got.score_range_min == pytest.approx(posture.score_range[0], rel=1e-12)
        assert got.score_range_max == pytest.approx(posture.score_range[1], rel=1e-12)
        assert got.score <= got.score_single_ik
        assert (got.postures_tried, got.postures_feasible) == (
            posture.postures_tried,
            posture.postures_feasible,
        )
        np.testing.assert_allclose(got.start_positions, posture.start_positions, atol=1e-12)
        assert_joint_trajectory(
            got, response.ranking.joint_names, want.times_s, want.joint_positions
        )


def test_posture_restarts_parameter_is_typed_and_bounded(ros: NodeUnderTest) -> None:
    (result,) = ros.set_parameters(posture__restarts=-1)
    assert not result.successful and result.reason
    (result,) = ros.set_parameters(posture__restarts=1.5)
    assert not result.successful and result.reason
    future = ros.get_client.call_async(GetParameters.Request(names=["posture.restarts"]))
    (value,) = ros.wait(future).values
    assert value.integer_value == 0
    descriptor = ros.node.describe_parameter("posture.restarts")
    assert descriptor.integer_range[0].from_value == 0
    assert descriptor.integer_range[0].to_value >= 100
    assert "restarts" in descriptor.description


# --- What the response carries (parameters response.*) ----------------------------------------

PER_SAMPLE_FIELDS = (
    "time_from_start_s",
    "effective_mass_kg",
    "direction_xyz",
    "direction_is_worst_case",
    "leading_point_effective_mass_kg",
    "worst_point_effective_mass_kg",
    "links_only_effective_mass_kg",
)


def _with_trajectory(ranking: GraspRanking) -> list[int]:
    return [e.index for e in ranking.evaluations if e.joint_trajectory.points]


def test_response_joint_trajectories_counts_grasps_of_the_final_order(ros: NodeUnderTest) -> None:
    request = book_request()
    request.grasp_quality = [0.9, 0.1, 0.5]  # a final order that is not the index order
    full = ros.rank(request)
    assert full.success, full.message
    order = list(full.ranking.order)
    assert len(order) == 3 and order != sorted(order)
    assert _with_trajectory(full.ranking) == [0, 1, 2]  # the tests' setting: all
    try:
        for count, expected in ((1, order[:1]), (2, order[:2]), (0, []), (3, order)):
            (result,) = ros.set_parameters(response__joint_trajectories=count)
            assert result.successful, result.reason
            response = ros.rank(request)
            assert response.success, response.message
            assert sorted(_with_trajectory(response.ranking)) == sorted(expected), count
            assert list(response.ranking.order) == order
            for got, want in zip(
                response.ranking.evaluations, full.ranking.evaluations, strict=True
            ):
                if got.joint_trajectory.points:  # the same motion as in the full response
                    assert got.joint_trajectory == want.joint_trajectory
                else:
                    assert got.joint_trajectory.points == []
    finally:
        (result,) = ros.set_parameters(response__joint_trajectories=MAX_GRASPS)
        assert result.successful, result.reason


def test_response_per_sample_false_leaves_the_arrays_empty_and_keeps_the_scores(
    ros: NodeUnderTest,
) -> None:
    request = book_request()
    request.metric_point = "leading_point"  # fills the exposed-point arrays too
    full = ros.rank(request)
    assert full.success, full.message
    (result,) = ros.set_parameters(response__per_sample=False)
    assert result.successful, result.reason
    try:
        response = ros.rank(request)
    finally:
        (result,) = ros.set_parameters(response__per_sample=True)
        assert result.successful, result.reason
    assert response.success, response.message
    assert list(response.ranking.order) == list(full.ranking.order)
    for got, want in zip(response.ranking.evaluations, full.ranking.evaluations, strict=True):
        assert want.feasible and len(want.leading_point_effective_mass_kg) > 0
        for field in PER_SAMPLE_FIELDS:
            assert len(getattr(got, field)) == 0, field
        for field in ("score", "safety_score", "peak_effective_mass_kg", "iso_min_duration_s"):
            assert getattr(got, field) == getattr(want, field), field
        assert got.mean_effective_mass_kg == pytest.approx(np.mean(want.effective_mass_kg))
        assert repr(got.iso_ts_15066) == repr(want.iso_ts_15066)  # NaN where not permitted
        assert got.joint_trajectory == want.joint_trajectory  # governed by the other parameter


def test_response_parameters_are_typed_bounded_and_refused_by_name(ros: NodeUnderTest) -> None:
    (result,) = ros.set_parameters(response__joint_trajectories=-1)
    assert not result.successful
    # rclpy checks the declared range first: "Parameter response.joint_trajectories out of
    # range. Min: 0, Max: 1000000000, value: -1"
    assert re.search(r"response\.joint_trajectories\b.*\b0\b.*\b1000000000\b.*-1", result.reason)
    (result,) = ros.set_parameters(response__joint_trajectories=1.0)  # declared an integer
    assert not result.successful
    assert "expected 'Type.INTEGER' got 'Type.DOUBLE'" in result.reason
    (result,) = ros.set_parameters(response__per_sample="no")  # declared a bool
    assert not result.successful and "expected 'Type.BOOL'" in result.reason
    names = ["response.joint_trajectories", "response.per_sample"]
    values = ros.wait(ros.get_client.call_async(GetParameters.Request(names=names))).values
    assert (values[0].integer_value, values[1].bool_value) == (MAX_GRASPS, True)
    descriptor = ros.node.describe_parameter("response.joint_trajectories")
    assert (descriptor.integer_range[0].from_value, descriptor.integer_range[0].to_value) == (
        0,
        1_000_000_000,
    )
    response = ros.rank(book_request())  # still serving, with the settings it had
    assert response.success, response.message
    assert _with_trajectory(response.ranking) == [0, 1, 2]


def test_response_defaults_send_the_first_grasps_trajectory_and_every_sample() -> None:
    parameters = {k: v for k, v in NODE_PARAMETERS.items() if k != "response.joint_trajectories"}
    harness = NodeUnderTest(parameters)
    try:
        response = harness.rank(book_request())
    finally:
        harness.close()
    assert response.success, response.message
    ranking = response.ranking
    assert _with_trajectory(ranking) == [ranking.order[0]]
    for evaluation in ranking.evaluations:
        assert len(evaluation.effective_mass_kg) == 21  # 2 s / 0.1
        assert len(evaluation.direction_xyz) == 3 * 21


def test_rank_by_whole_arm_through_the_service(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator, core_ranking: Any
) -> None:
    """The node's rank_by whole_arm: default sites and region (chest), the core's order, the
    response's whole_arm_* fields equal the core's."""
    results = ros.set_parameters(rank_by="whole_arm")
    assert all(r.successful for r in results), results
    try:
        response = ros.rank(book_request())
    finally:
        results = ros.set_parameters(rank_by="safety")
        assert all(r.successful for r in results), results
    assert response.success, response.message
    ranking = response.ranking
    want = core_report(core_evaluator, core_ranking, rank_by="whole_arm")
    assert ranking.rank_by == "whole_arm" and ranking.whole_arm_region == "chest"
    assert want.arm_sites is not None
    assert tuple(ranking.whole_arm_sites) == want.arm_sites.names
    assert tuple(ranking.order) == want.order
    assert tuple(ranking.paper_order) == core_ranking.order
    for k, evaluation in enumerate(ranking.evaluations):
        whole = want.whole_arm[k]
        chest = whole.region("chest")
        assert evaluation.whole_arm_rank_force_n == pytest.approx(chest.peak_contact_force_n, 1e-9)
        assert evaluation.whole_arm_limiting_region == whole.limiting_region
        assert evaluation.whole_arm_min_duration_s == pytest.approx(whole.min_duration_s, 1e-9)
    forces = [ranking.evaluations[i].whole_arm_rank_force_n for i in ranking.order]
    assert forces == sorted(forces)


def set_parameters_atomically(ros: NodeUnderTest, **values: Any) -> Any:
    """All of ``values`` in one change (``~/set_parameters_atomically``): the SetParameters
    service applies its parameters one by one, so a pair validated together (e.g.
    whole_arm.point_links with whole_arm.points_m) must change at once."""
    client = ros.client.create_client(
        SetParametersAtomically, "/grasp_safety/set_parameters_atomically"
    )
    try:
        assert client.wait_for_service(timeout_sec=10.0)
        request = SetParametersAtomically.Request(
            parameters=[
                Parameter(name.replace("__", "."), value=value).to_parameter_msg()
                for name, value in values.items()
            ]
        )
        return ros.wait(client.call_async(request)).result
    finally:
        ros.client.destroy_client(client)


FOREARM_POINT_M = [0.0, 0.0, 0.1]


def test_whole_arm_parameters_through_the_service(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator, core_ranking: Any
) -> None:
    """whole_arm.region, the extra points (whole_arm.point_links + whole_arm.points_m) and
    iso_ts_15066.regions reach the analysis: the response equals the core's report with the
    same options (the scenario's whole_arm section and robot.exposed_points_m)."""
    results = ros.set_parameters(
        iso_ts_15066__regions=["chest", "upper_arm_elbow"],
        whole_arm__region="upper_arm_elbow",
        rank_by="whole_arm",
    )
    assert all(r.successful for r in results), results
    try:
        # one at a time, the pair is refused naming the parameter; together it is taken
        (result,) = ros.set_parameters(whole_arm__point_links=["right_lower_forearm"])
        assert not result.successful
        assert result.reason.startswith(
            "whole_arm.points_m: must hold x y z for each of the 1 whole_arm.point_links"
        )
        points = {"whole_arm__point_links": ["right_lower_forearm"]}
        result = set_parameters_atomically(ros, **points, whole_arm__points_m=FOREARM_POINT_M)
        assert result.successful, result.reason
        response = ros.rank(book_request())
    finally:
        result = set_parameters_atomically(
            ros,
            whole_arm__point_links=[],
            whole_arm__points_m=[],
            rank_by="safety",
            whole_arm__region="chest",
            iso_ts_15066__regions=[],
        )
        assert result.successful, result.reason
    assert response.success, response.message
    ranking = response.ranking
    want = core_report(
        core_evaluator,
        core_ranking,
        iso_regions=("chest", "upper_arm_elbow"),
        rank_by="whole_arm",
        whole_arm_region="upper_arm_elbow",
        arm_points_m={"right_lower_forearm": [FOREARM_POINT_M]},
    )
    assert want.arm_sites is not None and want.arm_sites.names[-1] == "right_lower_forearm[0]"
    assert ranking.rank_by == "whole_arm" and ranking.whole_arm_region == "upper_arm_elbow"
    assert tuple(ranking.whole_arm_sites) == want.arm_sites.names
    assert tuple(ranking.order) == want.order
    for k, evaluation in enumerate(ranking.evaluations):
        whole = want.whole_arm[k]
        elbow = whole.region("upper_arm_elbow")
        assert evaluation.whole_arm_rank_force_n == pytest.approx(elbow.peak_contact_force_n, 1e-9)
        assert evaluation.whole_arm_limiting_region == whole.limiting_region
        limiting = whole.region(whole.limiting_region)
        assert evaluation.whole_arm_worst_site == whole.site_names[limiting.worst_site]
        assert [r.region for r in evaluation.iso_ts_15066] == ["chest", "upper_arm_elbow"]
    forces = [ranking.evaluations[i].whole_arm_rank_force_n for i in ranking.order]
    assert forces == sorted(forces)


def test_whole_arm_enabled_without_ranking_by_it(ros: NodeUnderTest) -> None:
    """whole_arm.enabled fills the whole_arm_* fields and keeps the paper's order."""
    (result,) = ros.set_parameters(whole_arm__enabled=True)
    assert result.successful, result.reason
    try:
        response = ros.rank(book_request())
    finally:
        (result,) = ros.set_parameters(whole_arm__enabled=False)
        assert result.successful, result.reason
    assert response.success, response.message
    ranking = response.ranking
    assert ranking.rank_by == "safety" and tuple(ranking.order) == tuple(ranking.safety_order)
    assert ranking.whole_arm_region == "chest" and len(ranking.whole_arm_sites) == 6
    assert all(math.isfinite(e.whole_arm_rank_force_n) for e in ranking.evaluations if e.feasible)
    response = ros.rank(book_request())  # off again: not computed
    assert response.success and not response.ranking.whole_arm_sites


def test_whole_arm_parameters_are_refused_naming_them(ros: NodeUnderTest) -> None:
    result = set_parameters_atomically(
        ros, whole_arm__point_links=["right_lower_forarm"], whole_arm__points_m=FOREARM_POINT_M
    )
    assert not result.successful
    assert result.reason.startswith(
        "whole_arm.point_links: unknown link 'right_lower_forarm'; did you mean "
        "right_lower_forearm, "
    )
    (result,) = ros.set_parameters(whole_arm__region="elbow")
    assert not result.successful and result.reason.startswith("whole_arm.region: must be one of")
    (result,) = ros.set_parameters(rank_by="whole_arm")
    assert result.successful, result.reason
    try:
        # rank_by whole_arm orders by chest (whole_arm.region), which must stay assessed
        (result,) = ros.set_parameters(iso_ts_15066__regions=["face", "hand_fingers"])
        assert not result.successful
        assert result.reason == (
            "whole_arm.region: rank_by whole_arm ranks by 'chest', which is not among the "
            "assessed iso_ts_15066.regions (face, hand_fingers); add it there or set "
            "whole_arm.region to one of them"
        )
    finally:
        (result,) = ros.set_parameters(rank_by="safety")
        assert result.successful, result.reason
    response = ros.rank(book_request())  # nothing of the refused changes applied
    assert response.success and response.ranking.rank_by == "safety"
    assert not response.ranking.whole_arm_sites


def test_rank_by_whole_arm_selects_postures_by_it(
    ros: NodeUnderTest, core_evaluator: GraspSafetyEvaluator
) -> None:
    """With rank_by whole_arm and posture.restarts, the node keeps the postures the core's
    whole-arm criterion keeps, and each grasp's ranking force is its kept posture's value."""
    results = ros.set_parameters(
        whole_arm__region="upper_arm_elbow", rank_by="whole_arm", posture__restarts=6
    )
    assert all(r.successful for r in results), results
    try:
        response = ros.rank(book_request())
    finally:
        results = ros.set_parameters(
            posture__restarts=0, rank_by="safety", whole_arm__region="chest"
        )
        assert all(r.successful for r in results), results
    assert response.success, response.message
    want = core_pipeline(
        core_evaluator,
        PostureConfig(restarts=6),
        rank_by="whole_arm",
        whole_arm_region="upper_arm_elbow",
    )
    expected = want.ranking
    ranking = response.ranking
    assert tuple(ranking.order) == want.order
    for got, posture in zip(ranking.evaluations, expected.postures, strict=True):
        assert posture.criterion == "whole_arm:upper_arm_elbow"
        np.testing.assert_allclose(got.start_positions, posture.start_positions, atol=1e-12)
        assert got.whole_arm_rank_force_n == pytest.approx(posture.criterion_value, rel=1e-9)
        assert posture.criterion_value <= posture.criterion_single_ik
