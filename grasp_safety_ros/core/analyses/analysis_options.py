"""The options of the analyses beyond the paper's tip ranking (``AnalysisOptions``: what
``safety_report.analyse`` computes) and what may order the final ranking (``RANK_BY``); their
defaults are core.options.OPTIONS'."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from ..exceptions import InvalidInputError
from .body_regions import BODY_REGIONS, select_regions
from .effort import check_effort_criterion
from .exposed_points import (
    check_metric_point,
    check_metric_point_has_points,
    check_points_in_object,
)
from .redundancy import RedundancyConfig
from .safe_duration import RetimeOptions
from .uncertainty import InertiaUncertainty
from .whole_arm import DEFAULT_RANK_REGION, check_exposed_points_m

RANK_BY = ("safety", "effort", "whole_arm", "safe_duration")
"""What orders the final ranking: the safety score (with quality, when given), the effort,
the whole arm's worst predicted force for ``whole_arm_region``, or the retimed duration."""


@dataclass(frozen=True)
class AnalysisOptions:
    """What to compute beyond the tip effective mass (ISO/TS 15066 and effort by default; the
    defaults are core.options.OPTIONS', checked by test/test_options.py).

    Attributes:
        metric_point: ``tip`` (the paper), ``leading_point`` or ``worst_point`` of the object.
        points_in_object_m: (K, 3) exposed points of the object [m], object frame; needed for
            the point metrics (the CLI derives them from the object's primitive shape).
        iso_regions: ISO/TS 15066 body regions to assess; None: all; empty: no assessment.
        uncertainty: Bounds on the object-inertia error; None: no uncertainty analysis.
        grasp_quality: Quality per candidate (higher is better); None: pure safety ranking.
        safety_weight: w of the weighted sum w·safety + (1 − w)·quality, in [0, 1].
        redundancy: Null-space optimisation of the effective mass (arms with > 6 joints);
            when on, the tip score uses the optimised effective mass.
        effort: Compute joint torques along the trajectory.
        rank_by: ``safety``, ``effort`` (then ``effort_criterion`` orders the grasps) or
            ``whole_arm`` (the worst predicted force over the arm's sites for
            ``whole_arm_region``; turns ``whole_arm`` on).
        effort_criterion: ``peak_fraction`` or ``rms_fraction`` of the torque limits.
        whole_arm: Assess the arm's own sites (core.analyses.whole_arm).
        arm_points_m: Extra sites ``{link_name: (P, 3) points [m], link frame}``; giving any
            turns ``whole_arm`` on.
        whole_arm_region: Body region ``rank_by: whole_arm`` uses (DEFAULT_RANK_REGION).
        retime: Retime each feasible grasp to the site speed limits (core.analyses.
            safe_duration); required by ``rank_by: safe_duration``.
        redundancy_settings: The null-space optimisation's settings when ``redundancy`` is on
            (its ``metric`` and ``max_joint_step`` are the evaluator's).
    """

    metric_point: str = "tip"
    points_in_object_m: np.ndarray | None = None
    iso_regions: tuple[str, ...] | None = None
    uncertainty: InertiaUncertainty | None = None
    grasp_quality: tuple[float, ...] | None = None
    safety_weight: float = 0.5
    redundancy: bool = False
    effort: bool = True
    rank_by: str = "safety"
    effort_criterion: str = "peak_fraction"
    whole_arm: bool = False
    arm_points_m: Mapping[str, Any] | None = None
    whole_arm_region: str = DEFAULT_RANK_REGION
    retime: RetimeOptions | None = None
    redundancy_settings: RedundancyConfig = field(default_factory=RedundancyConfig)

    def __post_init__(self) -> None:
        check_metric_point(self.metric_point)
        if self.points_in_object_m is not None:
            object.__setattr__(
                self,
                "points_in_object_m",
                check_points_in_object(self.points_in_object_m, "object.points_m"),
            )
        check_metric_point_has_points(
            self.metric_point,
            self.points_in_object_m,
            "a box or cylinder shape, or object.points_m",
        )
        if self.iso_regions:
            select_regions(list(self.iso_regions))  # raises on unknown names
        if self.rank_by not in RANK_BY:
            raise InvalidInputError(
                "rank_by", f"must be one of {', '.join(RANK_BY)}, got {self.rank_by!r}"
            )
        check_effort_criterion(self.effort_criterion, "effort.criterion")
        if self.rank_by == "effort" and not self.effort:
            object.__setattr__(self, "effort", True)
        if self.arm_points_m is not None:
            points = check_exposed_points_m(self.arm_points_m)
            object.__setattr__(self, "arm_points_m", MappingProxyType(points))
        if not isinstance(self.whole_arm_region, str):
            raise InvalidInputError(
                "whole_arm.region",
                f"must be one body region name, got {self.whole_arm_region!r}; regions: "
                f"{', '.join(BODY_REGIONS)}",
            )
        if self.whole_arm_region not in BODY_REGIONS:
            raise InvalidInputError(
                "whole_arm.region",
                f"unknown body region {self.whole_arm_region!r}; regions: "
                f"{', '.join(BODY_REGIONS)}",
            )
        assessed = self.iso_regions
        if self.rank_by == "whole_arm" and assessed and self.whole_arm_region not in assessed:
            raise InvalidInputError(
                "whole_arm.region",
                f"rank_by whole_arm ranks by {self.whole_arm_region!r}, which is not among the "
                f"assessed iso_ts_15066.regions ({', '.join(assessed)}); add it there or set "
                "whole_arm.region to one of them",
            )
        if self.rank_by == "whole_arm" or self.arm_points_m:
            object.__setattr__(self, "whole_arm", True)
        if self.retime is None and self.rank_by == "safe_duration":
            raise InvalidInputError(
                "retime.joint_acceleration_limits",
                "rank_by safe_duration needs a retime section with the joint acceleration limits",
            )
        if self.retime is not None and self.iso_regions == ():
            raise InvalidInputError(
                "iso_ts_15066.regions", "a retiming needs at least one region (none: all)"
            )
