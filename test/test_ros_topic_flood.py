"""The node's input topics under a flood of malformed messages (issue 27, finding 4): the
queues are bounded (keep the last INPUT_DEPTHS[topic]), what they overwrite is counted on
/diagnostics, and a candidate set is ranked with the trajectory received last before it even
when the node takes that trajectory after the set (the topics are served in turn)."""

from __future__ import annotations

import copy
from collections.abc import Iterator

import pytest
from geometry_msgs.msg import PoseArray, PoseStamped
from grasp_safety_msgs.msg import GraspRanking
from nav_msgs.msg import Path
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_node_harness import (
    LATCHED,
    NODE_PARAMETERS,
    NodeUnderTest,
    _localhost_only,  # noqa: F401  (autouse fixture)
    book_path,
    book_request,
)
from std_msgs.msg import Header

from grasp_safety_ros.ros.runtime.memory import memory_kib
from grasp_safety_ros.ros.topics.qos import INPUT_DEPTHS

KEEP_ALL = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture()
def ros() -> Iterator[NodeUnderTest]:
    """A node of its own: no candidate set or trajectory left by other tests."""
    harness = NodeUnderTest(NODE_PARAMETERS)
    yield harness
    harness.close()


def diagnostics(harness: NodeUnderTest) -> dict[str, str]:
    return {kv.key: kv.value for kv in harness.node.diagnostics_status().values}


def count(harness: NodeUnderTest, key: str) -> int:
    return int(diagnostics(harness).get(key, "0"))


def malformed_path(poses: int) -> Path:
    """A Path the node refuses at once (frame_id), of ``poses`` poses."""
    return Path(header=Header(frame_id="nowhere"), poses=[PoseStamped()] * poses)


def test_a_set_after_a_flood_is_ranked_with_the_trajectory_received_before_it(
    ros: NodeUnderTest,
) -> None:
    """Good trajectory T1 and a set, then 600 malformed trajectories, then T2 and the set
    again: the last ranking published is the service's ranking with T2 (it was T1's: the set,
    alone on its topic, was taken while T2 still queued behind the flood)."""
    rankings: list[GraspRanking] = []
    subscription = ros.client.create_subscription(
        GraspRanking, "/grasp_safety/ranking", rankings.append, LATCHED
    )
    grasps_pub = ros.client.create_publisher(PoseArray, "/grasp_safety/candidate_grasps", KEEP_ALL)
    path_pub = ros.client.create_publisher(Path, "/grasp_safety/object_trajectory", KEEP_ALL)
    try:
        assert ros.spin_until(
            lambda: grasps_pub.get_subscription_count() > 0 and path_pub.get_subscription_count()
        )
        request = book_request()
        want = {}
        for duration_s in (2.0, 3.0):
            timed = copy.deepcopy(request)
            timed.object_trajectory = book_path(duration_s)
            answer = ros.rank(timed)
            assert answer.success, answer.message
            want[duration_s] = answer.ranking
        assert scores(want[2.0]) != scores(want[3.0])  # tells them apart

        def last_is(ranking: GraspRanking) -> bool:
            return bool(rankings) and same_scores(rankings[-1], ranking)

        path_pub.publish(book_path(2.0))
        grasps_pub.publish(request.grasps)
        assert ros.spin_until(lambda: last_is(want[2.0]), 60.0)
        before = count(ros, "refused.object_trajectory") + count(ros, "skipped.object_trajectory")
        bad = malformed_path(2)
        for _ in range(600):
            path_pub.publish(bad)
        path_pub.publish(book_path(3.0))
        grasps_pub.publish(request.grasps)

        def flood_taken() -> bool:
            taken = count(ros, "refused.object_trajectory") + count(
                ros, "skipped.object_trajectory"
            )
            return taken - before >= 600

        assert ros.spin_until(flood_taken, 120.0)
        assert ros.spin_until(lambda: last_is(want[3.0]), 60.0), [scores(r) for r in rankings[-3:]]
    finally:
        ros.client.destroy_subscription(subscription)
        ros.client.destroy_publisher(grasps_pub)
        ros.client.destroy_publisher(path_pub)


def scores(ranking: GraspRanking) -> list[float]:
    """The candidates' effective-mass scores [kg], candidate order."""
    return [e.score for e in ranking.evaluations]


def same_scores(got: GraspRanking, want: GraspRanking) -> bool:
    return list(got.order) == list(want.order) and scores(got) == scores(want)


def test_a_flood_of_large_messages_queues_at_most_the_depth(ros: NodeUnderTest) -> None:
    """300 malformed trajectories of 10,000 poses (about 1 MB each serialised, more as
    Python objects) published faster than the node takes them: every one is refused or
    counted as skipped, and the process grows by less than a bound far below what keeping them
    all would take. Bound: the queue (INPUT_DEPTHS x 1 MB), the publisher's history (10 x
    1 MB), the messages as Python objects being refused (a few x 10,000 PoseStamped of about
    0.5 kB: 5 MB each), plus 150 MB for the allocator's slack; keeping them all (as before)
    held 300 MB serialised alone."""
    publisher = ros.client.create_publisher(
        Path, "/grasp_safety/object_trajectory", QoSProfile(depth=10)
    )
    try:
        assert ros.spin_until(lambda: publisher.get_subscription_count() > 0)
        bad = malformed_path(10_000)
        publisher.publish(bad)  # one first: the sizes of a taken message in the baseline
        assert ros.spin_until(lambda: count(ros, "refused.object_trajectory") >= 1, 30.0)
        rss_before_kib = memory_kib()["rss_kib"]
        for _ in range(300):
            publisher.publish(bad)

        def taken() -> int:
            return count(ros, "refused.object_trajectory") + count(
                ros, "skipped.object_trajectory"
            )

        assert ros.spin_until(lambda: taken() >= 301, 180.0), diagnostics(ros)
        assert taken() == 301  # refused or skipped (how many of each: the machine's speed)
        grown_mb = (memory_kib()["rss_kib"] - rss_before_kib) / 1024
        bound_mb = INPUT_DEPTHS["object_trajectory"] * 1 + 10 * 1 + 4 * 5 + 150
        assert grown_mb < bound_mb, (grown_mb, bound_mb)
    finally:
        ros.client.destroy_publisher(publisher)


def test_a_burst_of_bad_messages_is_counted_in_full(ros: NodeUnderTest) -> None:
    """Every message of a burst from one publisher is refused or, overwritten in the node's
    queue before it took it, counted as skipped on /diagnostics (exact with one publisher,
    from the first message the node took of it: topic_inputs.PublisherSequences)."""
    burst = 300
    publisher = ros.client.create_publisher(PoseArray, "/grasp_safety/candidate_grasps", KEEP_ALL)
    try:
        assert ros.spin_until(lambda: publisher.get_subscription_count() > 0)
        bad = PoseArray(header=Header(frame_id="nowhere"), poses=book_request().grasps.poses)

        def handled() -> int:
            return count(ros, "refused.candidate_grasps") + count(ros, "skipped.candidate_grasps")

        publisher.publish(bad)  # the first the node takes of this publisher
        assert ros.spin_until(lambda: handled() == 1, 30.0)
        for _ in range(burst):
            publisher.publish(bad)
        assert ros.spin_until(lambda: handled() >= 1 + burst, 60.0), diagnostics(ros)
        assert handled() == 1 + burst
        assert count(ros, "lost.candidate_grasps") == 0
    finally:
        ros.client.destroy_publisher(publisher)
