"""The node over real rclpy, shared by the test_ros_node*.py files and test_ros_robot_source.py:
the node in a thread of its NodeExecutor and a client node (NodeUnderTest), the book scenario's
requests, and the core's results they must equal. ``_localhost_only`` is an autouse
fixture a test module imports; ``ros``, ``own_ros``, ``core_evaluator`` and ``core_ranking``
are in conftest.py.

The node runs in-process in a thread of its NodeExecutor with its own rclpy Context; the
test client is a second node in the same context with its own executor. Each context claims
its own ROS_DOMAIN_ID (ros_domains) and uses localhost-only discovery, so parallel runs do not
cross-talk.
"""

from __future__ import annotations

import array
import math
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
import rclpy
import yaml
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose, PoseArray, PoseStamped, Quaternion
from grasp_safety_msgs.msg import GraspRanking
from grasp_safety_msgs.srv import RankGrasps
from nav_msgs.msg import Path
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_domains import claim_ros_domain
from std_msgs.msg import Header

from grasp_safety_ros.core import (
    Grasp,
    GraspSafetyEvaluator,
    ObjectTrajectory,
)
from grasp_safety_ros.core.analyses.exposed_points import box_corners_in_object
from grasp_safety_ros.core.analyses.safety_report import (
    AnalysisOptions,
    analyse,
)
from grasp_safety_ros.core.method.posture import PostureConfig
from grasp_safety_ros.core.pipeline import PipelineRequest, run_pipeline
from grasp_safety_ros.paths import config_file
from grasp_safety_ros.ros.conversions import inertia_msg_from_object
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


@pytest.fixture(scope="module", autouse=True)
def _localhost_only(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        patch.setenv("ROS_LOG_DIR", str(tmp_path_factory.mktemp("ros_log")))
        yield


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
