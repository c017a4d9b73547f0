"""The node's topic inputs: the latest candidate set, its grasp quality and the object
trajectory, with their pairing rules (plain Python, no rclpy)."""

from __future__ import annotations

import threading
from collections.abc import Sequence

import numpy as np
from geometry_msgs.msg import PoseArray
from nav_msgs.msg import Path
from trajectory_msgs.msg import MultiDOFJointTrajectory

from ..core.exceptions import InvalidInputError
from ..core.input_checks import finite_array

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


class TopicInputs:
    """The latest candidate set (with its quality, and whether it was ranked), a quality
    vector waiting for the next set, and the latest object trajectory (thread-safe).

    A new candidate set takes the waiting quality vector if the lengths match (else that
    vector is discarded). A quality vector pairs with the current set if it has the same
    length and no quality yet (the set is then ranked again, with the quality); otherwise it
    waits for the next candidate set. An empty vector (None) clears a waiting one.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._candidates: PoseArray | None = None
        self._candidates_pending = False  # not ranked yet
        self._candidates_quality: tuple[float, ...] | None = None  # paired with _candidates
        self._pending_quality: tuple[float, ...] | None = None  # waits for the next set
        self._trajectory: Path | MultiDOFJointTrajectory | None = None

    def set_candidates(self, msg: PoseArray) -> int | None:
        """Make ``msg`` the current set, to be ranked; the length of the waiting quality
        vector if it was discarded (lengths differ), else None."""
        with self._lock:
            quality, self._pending_quality = self._pending_quality, None
            if quality is not None and len(quality) != len(msg.poses):
                discarded, quality = len(quality), None
            else:
                discarded = None
            self._candidates, self._candidates_pending = msg, True
            self._candidates_quality = quality
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

    def set_trajectory(self, msg: Path | MultiDOFJointTrajectory) -> None:
        with self._lock:
            self._trajectory = msg

    def latest_trajectory(self) -> Path | MultiDOFJointTrajectory | None:
        """The latest object trajectory (None before the first)."""
        with self._lock:
            return self._trajectory

    def take(
        self,
    ) -> tuple[PoseArray, Path | MultiDOFJointTrajectory, tuple[float, ...] | None] | None:
        """The candidate set, trajectory and quality to rank, if the set is new (not ranked
        yet) and a trajectory is known; the set then counts as ranked."""
        with self._lock:
            grasps, path = self._candidates, self._trajectory
            if grasps is None or path is None or not self._candidates_pending:
                return None
            self._candidates_pending = False
            return grasps, path, self._candidates_quality

    def retry(self) -> None:
        """Rank the current set again with the next trajectory (its ranking could not run)."""
        with self._lock:
            self._candidates_pending = True
