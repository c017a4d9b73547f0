"""The node's topic inputs: the latest candidate set, its grasp quality and the object
trajectory, with their pairing rules (plain Python, no rclpy)."""

from __future__ import annotations

import bisect
import threading
import time
from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import PoseArray
from nav_msgs.msg import Path
from trajectory_msgs.msg import MultiDOFJointTrajectory

from ...core.exceptions import InvalidInputError
from ...core.input_checks import finite_array

MAX_ABS_GRASP_QUALITY = 1e9
"""Grasp qualities beyond +/-1e9 are refused: the min-max normalisation of the combined score
overflowed (1.8e308 and -1.8e308 gave a NaN combined score, ranked first)."""


def check_quality(values: Sequence[float], field: str) -> tuple[float, ...] | None:
    """Grasp qualities of a message array (finite, |q| <= MAX_ABS_GRASP_QUALITY); None when
    empty (pure safety ranking)."""
    if len(values) == 0:
        return None
    checked = finite_array(np.asarray(values, dtype=float), field)
    largest = float(np.max(np.abs(checked)))
    if largest > MAX_ABS_GRASP_QUALITY:
        raise InvalidInputError(
            field,
            f"must be within +/-{MAX_ABS_GRASP_QUALITY:g} (any unit, higher is better), got "
            f"a value of magnitude {largest:g}",
        )
    return tuple(float(v) for v in checked)


TRAJECTORY_HISTORY = 32
"""Accepted trajectories kept with their reception times, to pair a candidate set with the one
received last before it (at least the trajectory topics' queue depths together)."""
PUBLISHER_STREAMS = 16
"""Publishers per topic whose sequence numbers PublisherSequences follows."""


class PublisherSequences:
    """Messages of a topic that its publishers sent and the node never took (overwritten in
    its keep-last queue, or lost), from gaps in the publishers' sequence numbers.

    rmw gives each message its publisher's sequence number but not the publisher. With one
    publisher matched, a number continues the last one taken (a smaller one: a new
    publisher). With several, it continues the followed publisher whose last number is the
    largest below it (a number below all of them starts another): an estimate, as publishers
    whose numbers cross can swap. Counted from the first message taken of each publisher.
    """

    def __init__(self) -> None:
        self._last: list[int] = []  # the last number of each followed publisher, latest last

    def skipped(self, sequence: int | None, publishers: int = 0) -> int:
        """Messages skipped before the one numbered ``sequence`` (0 when rmw gives none), with
        ``publishers`` matched (0: unknown)."""
        if sequence is None or not 0 < sequence < 2**63:
            return 0
        if publishers == 1:
            self._last = self._last[-1:]
        below = [last for last in self._last if last < sequence]
        previous = max(below) if below else None
        if previous is not None:
            self._last.remove(previous)
        self._last = [*self._last, sequence][-PUBLISHER_STREAMS:]
        return 0 if previous is None else sequence - previous - 1


class TopicInputs:
    """The latest candidate set (with its quality, and whether it was ranked), a quality
    vector waiting for the next set, and the accepted object trajectories with their reception
    times (thread-safe).

    A candidate set pairs with the trajectory received last before it, whatever the order in
    which the node takes its topics' messages (the executor serves them in turn, so under a
    flood a set can be taken before a trajectory received earlier); with none received before
    it, with the first received after it. A trajectory received before the current set but
    taken after the set was ranked (with an older one) ranks the set again.

    A new candidate set takes the waiting quality vector if the lengths match (else that
    vector is discarded). A quality vector pairs with the current set if it has the same
    length and no quality yet (the set is then ranked again, with the quality); otherwise it
    waits for the next candidate set. An empty vector (None) clears a waiting one.

    Reception times are the middleware's [ns]; without one (None, or 0: an rmw that does not
    fill it), the time of the call.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._candidates: PoseArray | None = None
        self._candidates_received_ns = 0
        self._candidates_pending = False  # not ranked yet
        self._candidates_quality: tuple[float, ...] | None = None  # paired with _candidates
        self._pending_quality: tuple[float, ...] | None = None  # waits for the next set
        self._ranked_with_ns: int | None = None  # reception of the trajectory last ranked with
        self._trajectories: list[tuple[int, Path | MultiDOFJointTrajectory]] = []  # by time

    def set_candidates(self, msg: PoseArray, received_ns: int | None = None) -> int | None:
        """Make ``msg`` the current set, to be ranked; the length of the waiting quality
        vector if it was discarded (lengths differ), else None."""
        with self._lock:
            quality, self._pending_quality = self._pending_quality, None
            if quality is not None and len(quality) != len(msg.poses):
                discarded, quality = len(quality), None
            else:
                discarded = None
            self._candidates, self._candidates_pending = msg, True
            self._candidates_received_ns = _received(received_ns)
            self._candidates_quality = quality
            self._ranked_with_ns = None
        return discarded

    def set_quality(self, quality: tuple[float, ...] | None) -> bool:
        """Pair ``quality`` with the current set (True: rank it again) or keep it waiting."""
        with self._lock:
            current = self._candidates
            if (
                quality is not None
                and current is not None
                and self._candidates_quality is None
                and len(current.poses) == len(quality)
            ):
                self._candidates_quality, self._candidates_pending = quality, True
                self._pending_quality = None
                return True
            self._pending_quality = quality
            return False

    def set_trajectory(
        self, msg: Path | MultiDOFJointTrajectory, received_ns: int | None = None
    ) -> None:
        """Keep an accepted trajectory; the current set is ranked again if this one was
        received before it and after the trajectory it was ranked with."""
        received = _received(received_ns)
        with self._lock:
            times = [t for t, _ in self._trajectories]
            self._trajectories.insert(bisect.bisect_right(times, received), (received, msg))
            del self._trajectories[:-TRAJECTORY_HISTORY]
            ranked_with = self._ranked_with_ns
            if ranked_with is not None and ranked_with < received <= self._candidates_received_ns:
                self._candidates_pending = True

    def latest_trajectory(self) -> Path | MultiDOFJointTrajectory | None:
        """The latest object trajectory (None before the first)."""
        with self._lock:
            return self._trajectories[-1][1] if self._trajectories else None

    def take(
        self,
    ) -> tuple[PoseArray, Path | MultiDOFJointTrajectory, tuple[float, ...] | None] | None:
        """The candidate set, its trajectory (class docstring) and quality to rank, if the set
        is new (not ranked yet) and a trajectory is known; the set then counts as ranked."""
        with self._lock:
            grasps = self._candidates
            if grasps is None or not self._trajectories or not self._candidates_pending:
                return None
            before = [
                item for item in self._trajectories if item[0] <= self._candidates_received_ns
            ]
            received, path = before[-1] if before else self._trajectories[0]
            self._candidates_pending = False
            self._ranked_with_ns = received if before else -1  # none current: any before it
            return grasps, path, self._candidates_quality

    def retry(self) -> None:
        """Rank the current set again at the next input (its ranking could not run)."""
        with self._lock:
            self._candidates_pending = True


def _received(received_ns: int | None) -> int:
    """The reception time [ns]: the middleware's, or the time of the call when it gave none
    (None, or 0 from an rmw that does not fill it)."""
    return int(received_ns) if received_ns else time.time_ns()
