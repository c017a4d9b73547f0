"""TopicInputs: how candidate sets, grasp qualities and trajectories pair (no rclpy)."""

from __future__ import annotations

from geometry_msgs.msg import Pose, PoseArray
from nav_msgs.msg import Path

from grasp_safety_ros.ros.topic_inputs import TopicInputs


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
