"""What a GraspRanking message carries beyond the scores (parameters ``response.*``): a value
record the result conversions take and the parameters build."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

MAX_COUNT = 1_000_000_000
"""Upper bound of the node's unbounded count parameters (a seed, the joint trajectories)."""


@dataclass(frozen=True)
class ResponseContent:
    """What a GraspRanking message carries beyond the scores (parameters ``response.*``).

    Attributes:
        joint_trajectories: How many grasps get their ``joint_trajectory``: the first of the
            final order, then the grasps outside it in index order (infeasible grasps have
            none to give); 0: none. The default, all, is what a message built without node
            parameters carries.
        per_sample: Whether each evaluation's per-sample arrays are filled; false leaves them
            empty (scores, aggregates and per-grasp fields are kept).
    """

    joint_trajectories: int = MAX_COUNT
    per_sample: bool = True

    def with_joint_trajectory(self, order: Sequence[int], count: int) -> frozenset[int]:
        """The grasp indices (of ``count`` grasps) that carry their joint trajectory."""
        if self.joint_trajectories >= count:
            return frozenset(range(count))
        ranked = set(order)
        first = [*order, *(i for i in range(count) if i not in ranked)]
        return frozenset(first[: self.joint_trajectories])
