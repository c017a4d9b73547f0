"""TopicInputs: how candidate sets, grasp qualities and trajectories pair (no rclpy)."""

from __future__ import annotations

from geometry_msgs.msg import Pose, PoseArray
from nav_msgs.msg import Path

from grasp_safety_ros.ros.topics.inputs import PublisherSequences, TopicInputs


def candidates(count: int) -> PoseArray:
    return PoseArray(poses=[Pose() for _ in range(count)])


def test_a_candidate_set_is_ranked_once_when_a_trajectory_is_known() -> None:
    inputs, grasps, path = TopicInputs(), candidates(3), Path()
    assert inputs.set_candidates(grasps) is None
    assert inputs.take() is None  # no trajectory yet
    inputs.set_trajectory(path)
    taken = inputs.take()
    assert taken is not None and taken[0] is grasps and taken[1] is path and taken[2] is None
    assert inputs.take() is None  # ranked: not again
    inputs.retry()
    assert inputs.take() is not None


def test_a_quality_of_the_current_sets_length_pairs_with_it_and_ranks_again() -> None:
    inputs = TopicInputs()
    inputs.set_trajectory(Path())
    inputs.set_candidates(candidates(2))
    assert inputs.take() is not None
    assert inputs.set_quality((0.5, 0.25))
    taken = inputs.take()
    assert taken is not None and taken[2] == (0.5, 0.25)
    assert not inputs.set_quality((1.0, 2.0))  # the set has its quality: waits for the next
    assert inputs.take() is None
    assert inputs.set_candidates(candidates(2)) is None
    taken = inputs.take()
    assert taken is not None and taken[2] == (1.0, 2.0)


def test_a_waiting_quality_of_another_length_is_discarded_by_the_next_set() -> None:
    inputs = TopicInputs()
    inputs.set_candidates(candidates(3))
    assert not inputs.set_quality((0.1, 0.2, 0.3, 0.4))
    assert inputs.set_candidates(candidates(3)) == 4
    inputs.set_trajectory(Path())
    taken = inputs.take()
    assert taken is not None and taken[2] is None


def test_an_empty_quality_clears_a_waiting_one() -> None:
    inputs = TopicInputs()
    inputs.set_candidates(candidates(2))
    inputs.set_quality((0.1, 0.2, 0.3))  # waits
    inputs.set_quality(None)
    assert inputs.set_candidates(candidates(3)) is None
    inputs.set_trajectory(Path())
    taken = inputs.take()
    assert taken is not None and taken[2] is None


def test_a_set_pairs_with_the_trajectory_received_last_before_it() -> None:
    """Reception times, not the order the node takes the messages, pair a set with its
    trajectory: one received before the set but taken after it ranks the set again with it;
    one received after the set does not."""
    inputs, grasps = TopicInputs(), candidates(2)
    first, late, after = Path(), Path(), Path()
    inputs.set_trajectory(first, received_ns=100)
    inputs.set_candidates(grasps, received_ns=300)
    taken = inputs.take()
    assert taken is not None and taken[1] is first
    inputs.set_trajectory(after, received_ns=400)  # after the set: not its trajectory
    assert inputs.take() is None
    inputs.set_trajectory(late, received_ns=200)  # before the set, taken after it
    taken = inputs.take()
    assert taken is not None and taken[1] is late
    assert inputs.take() is None
    inputs.set_candidates(candidates(2), received_ns=500)
    taken = inputs.take()
    assert taken is not None and taken[1] is after


def test_a_set_before_any_trajectory_takes_the_first_then_one_received_before_it() -> None:
    inputs, grasps = TopicInputs(), candidates(2)
    inputs.set_candidates(grasps, received_ns=300)
    after, before = Path(), Path()
    inputs.set_trajectory(after, received_ns=400)
    taken = inputs.take()
    assert taken is not None and taken[1] is after
    inputs.set_trajectory(before, received_ns=200)
    taken = inputs.take()
    assert taken is not None and taken[1] is before


def test_a_reception_time_of_zero_is_none() -> None:
    """An rmw that does not fill received_timestamp gives 0: the time of the call then, not
    the epoch (which put the later trajectory before every other)."""
    inputs, first, second = TopicInputs(), Path(), Path()
    inputs.set_trajectory(first)  # the time of the call
    inputs.set_trajectory(second, received_ns=0)  # no reception time
    assert inputs.latest_trajectory() is second
    inputs.set_candidates(candidates(2), received_ns=0)
    taken = inputs.take()
    assert taken is not None and taken[1] is second  # the one received last before the set


def test_the_latest_trajectory_is_the_one_received_last() -> None:
    """What ~/plan_grasps ranks along: None before any, then the latest by reception time (a
    message received earlier but handed over later does not replace it)."""
    inputs, first, second, late = TopicInputs(), Path(), Path(), Path()
    assert inputs.latest_trajectory() is None
    inputs.set_trajectory(first, received_ns=10)
    assert inputs.latest_trajectory() is first
    inputs.set_trajectory(second, received_ns=30)
    inputs.set_trajectory(late, received_ns=20)
    assert inputs.latest_trajectory() is second


def test_skipped_messages_are_the_gaps_of_each_publishers_numbers() -> None:
    sequences = PublisherSequences()
    assert [sequences.skipped(n) for n in (1, 2, 5, 6)] == [0, 0, 2, 0]
    assert sequences.skipped(1) == 0  # a second publisher starts
    assert [sequences.skipped(n) for n in (2, 7, 4, 10)] == [0, 0, 1, 2]
    assert sequences.skipped(None) == 0 and sequences.skipped(2**64 - 1) == 0  # unsupported


def test_with_one_publisher_a_number_continues_the_last_taken() -> None:
    """A publisher gone (its numbers up to 5) and a new one whose 2..7 were overwritten: with
    one publisher matched the gap is counted from the new one's 1, not the old one's 5."""
    sequences = PublisherSequences()
    assert [sequences.skipped(n, publishers=1) for n in (1, 2, 5)] == [0, 0, 2]
    assert [sequences.skipped(n, publishers=1) for n in (1, 8)] == [0, 6]
