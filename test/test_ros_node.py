"""ros.node over real rclpy: the service equals the core, bad requests are refused and the node
keeps serving, the input and result topics (harness: ros_node_harness.py)."""

from __future__ import annotations

import copy
import math
import re
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import InertiaStamped, Pose, PoseArray, PoseStamped
from grasp_safety_msgs.msg import GraspRanking
from grasp_safety_msgs.srv import RankGrasps
from nav_msgs.msg import Path
from rcl_interfaces.srv import GetParameters
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from ros_node_harness import (
    BOOK,
    LATCHED,
    MAX_GRASPS,
    NODE_PARAMETERS,
    NodeUnderTest,
    _localhost_only,  # noqa: F401  (autouse fixture)
    assert_matches_core,
    book_path,
    book_request,
    same_messages,
)
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

from grasp_safety_ros.core import (
    solid_box,
)
from grasp_safety_ros.ros.conversions import inertia_msg_from_object, pose_msg_from_transform

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
