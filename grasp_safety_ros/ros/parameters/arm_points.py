"""The whole arm's extra points as node parameters (pure functions, no rclpy).

ROS parameters have no maps: the scenario's ``robot.exposed_points_m: {link: [[x, y, z], ...]}``
(link frame [m]) is the pair ``whole_arm.point_links`` (one link name per point; a link may
repeat) and ``whole_arm.points_m`` (flat x y z per entry), checked together and against the
robot's links, each refusal naming the parameter.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...core.analyses.whole_arm import MAX_SITES, resolve_arm_sites
from ...core.exceptions import InvalidInputError
from ...core.model.robot import RobotModel
from .values import show, string_list

LINKS = "whole_arm.point_links"
POINTS = "whole_arm.points_m"


def check_point_links(value: Any) -> tuple[str, ...]:
    """``whole_arm.point_links`` on its own: non-empty names, at most MAX_SITES."""
    names = string_list(LINKS, value, "link names")
    if not names:
        return ()
    if not all(isinstance(link, str) and link for link in names):
        raise InvalidInputError(LINKS, f"must be a list of link names, got {show(names)}")
    if len(names) > MAX_SITES:
        raise InvalidInputError(LINKS, f"must hold at most {MAX_SITES} links, got {len(names)}")
    return tuple(names)


def arm_points(links: Sequence[str], numbers: Sequence[float]) -> dict[str, np.ndarray] | None:
    """``{link: (P, 3) [m], link frame}`` of checked ``whole_arm.point_links`` and
    ``whole_arm.points_m`` (3 numbers per link entry), links in order of first mention, a
    link's points in the order given; None when there are none."""
    if len(numbers) != 3 * len(links):
        raise InvalidInputError(
            POINTS,
            f"must hold x y z for each of the {len(links)} {LINKS} "
            f"({3 * len(links)} numbers), got {len(numbers)} numbers",
        )
    points: dict[str, list[np.ndarray]] = {}
    for link, point in zip(links, np.reshape(numbers, (-1, 3)), strict=True):
        points.setdefault(link, []).append(point)
    return {link: np.array(p) for link, p in points.items()} or None


def check_arm_point_links(points: Mapping[str, Any] | None, robot: RobotModel) -> None:
    """Refuse extra points on links ``robot`` does not have (naming ``whole_arm.point_links``,
    with close link names)."""
    if not points:
        return
    try:
        resolve_arm_sites(robot, points, defaults=False, field=LINKS)
    except InvalidInputError as error:
        raise InvalidInputError(LINKS, error.reason) from None
