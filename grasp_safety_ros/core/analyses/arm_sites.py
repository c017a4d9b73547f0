"""Sites of the whole-arm analysis (``whole_arm``): points fixed on the chain's links,
resolved once per robot.

A *site* is a point fixed on one link: a chain joint id j (the body it rides on) and the point
in joint j's frame. By default the origin of every chain joint frame from the third joint on
(elbow, wrist) and the tip; the user adds points per link (``robot.exposed_points_m: {link:
[[x, y, z], ...]}``, link frame [m]). Sites on links welded to the base never move and are
dropped (mink's collision-avoidance pattern: pairs resolved once, fixed rows).
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError
from ..input_checks import check_within_reach, finite_array, read_only
from ..model.robot import RobotModel

FIRST_DEFAULT_JOINT = 3
"""Default sites: the origins of chain joints FIRST_DEFAULT_JOINT.. (1-based), and the tip."""

MAX_SITES = 1000
"""Largest number of sites (default plus user points) accepted."""


@dataclass(frozen=True)
class ArmSites:
    """Points on the chain's links, resolved once per robot (K sites, n chain joints).

    Attributes:
        names: Site names, e.g. ``panda_joint4`` (a joint origin), the tip frame's name, or
            ``panda_link5[0]`` (the first user point on that link).
        links: Name of the link carrying each site.
        joint_ids: (K,) Pinocchio joint id of the body carrying each site (1..n).
        points_in_joint_m: (K, 3) the point in that joint's frame [m].
        support: (K, n) True where chain joint i moves the site's body.
        dropped: Names of user sites dropped because their link is welded to the base.
    """

    names: tuple[str, ...]
    links: tuple[str, ...]
    joint_ids: np.ndarray
    points_in_joint_m: np.ndarray
    support: np.ndarray
    dropped: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.names)


def check_exposed_points_m(
    value: Any, field: str = "robot.exposed_points_m"
) -> dict[str, np.ndarray]:
    """Validate ``{link_name: [[x, y, z], ...]}`` (link frame [m], each coordinate within
    +/- MAX_ABS_POSITION_M); returns (P, 3) arrays."""
    if not isinstance(value, Mapping):
        raise InvalidInputError(
            field, f"must be a mapping {{link_name: [[x, y, z], ...]}}, got {value!r}"
        )
    checked: dict[str, np.ndarray] = {}
    for link, points in value.items():
        if not isinstance(link, str) or not link:
            raise InvalidInputError(field, f"link names must be non-empty strings, got {link!r}")
        array = finite_array(points, f"{field}.{link}")
        if array.ndim == 1 and array.shape == (3,):
            array = array[None]
        if array.ndim != 2 or array.shape[1] != 3 or len(array) < 1:
            raise InvalidInputError(
                f"{field}.{link}", f"must be a list of [x, y, z] points, got {list(array.shape)}"
            )
        check_within_reach(array, f"{field}.{link}")  # 1e300 m: every ranking LinAlgError
        checked[link] = read_only(array, copy=True)
    total = sum(len(points) for points in checked.values())
    if total > MAX_SITES:
        raise InvalidInputError(field, f"has {total} points; at most {MAX_SITES} are allowed")
    return checked


def _link_frame(model: pin.Model, link: str, field: str) -> int:
    """Id of the BODY (link) frame called ``link``; refused with close names suggested."""
    bodies = [frame.name for frame in model.frames if frame.type == pin.FrameType.BODY]
    for i, frame in enumerate(model.frames):
        if frame.type == pin.FrameType.BODY and frame.name == link:
            return i
    close = difflib.get_close_matches(link, bodies, n=3, cutoff=0.5)
    hint = f"did you mean {', '.join(close)}?" if close else f"links: {', '.join(bodies)}"
    raise InvalidInputError(f"{field}.{link}", f"unknown link '{link}'; {hint}")


def _child_link(model: pin.Model, joint_id: int) -> str:
    """The first link (BODY frame) carried by joint ``joint_id``, or the joint's name."""
    for frame in model.frames:
        if frame.type == pin.FrameType.BODY and frame.parentJoint == joint_id:
            return frame.name
    return model.names[joint_id]


def resolve_arm_sites(
    robot: RobotModel,
    exposed_points_m: Mapping[str, Any] | None = None,
    defaults: bool = True,
    field: str = "robot.exposed_points_m",
) -> ArmSites:
    """The sites of ``robot`` (module docstring): the defaults (unless ``defaults`` is False),
    then each user link's points in the order given."""
    model = robot.model
    names: list[str] = []
    links: list[str] = []
    joint_ids: list[int] = []
    points: list[np.ndarray] = []
    if defaults:
        for joint_id in range(FIRST_DEFAULT_JOINT, model.njoints):
            names.append(model.names[joint_id])
            links.append(_child_link(model, joint_id))
            joint_ids.append(joint_id)
            points.append(np.zeros(3))
        tip = model.frames[robot.tip_frame_id]
        names.append(robot.tip_frame)
        links.append(
            robot.tip_frame
            if tip.type == pin.FrameType.BODY
            else _child_link(model, tip.parentJoint)
        )
        joint_ids.append(tip.parentJoint)
        points.append(np.array(tip.placement.translation))
    dropped: list[str] = []
    for link, link_points in check_exposed_points_m(exposed_points_m or {}, field).items():
        frame = model.frames[_link_frame(model, link, field)]
        for p, point in enumerate(link_points):
            name = f"{link}[{p}]"
            if frame.parentJoint == 0:
                dropped.append(name)
                continue
            names.append(name)
            links.append(link)
            joint_ids.append(frame.parentJoint)
            points.append(frame.placement.act(point))
    ids = np.array(joint_ids, dtype=int)
    support = np.zeros((len(ids), model.nv), dtype=bool)
    for k, joint_id in enumerate(ids):
        for i in model.supports[int(joint_id)][1:]:
            support[k, model.joints[i].idx_v] = True
    return ArmSites(
        names=tuple(names),
        links=tuple(links),
        joint_ids=read_only(ids),
        points_in_joint_m=read_only(np.array(points, dtype=float).reshape(-1, 3)),
        support=read_only(support),
        dropped=tuple(dropped),
    )
