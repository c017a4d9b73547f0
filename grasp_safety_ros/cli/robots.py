"""``grasp-safety robots`` (the bundled chains) and ``grasp-safety frames`` (a model's frames)."""

from __future__ import annotations

import difflib
from pathlib import Path

import pinocchio as pin

from ..core.exceptions import InvalidInputError
from ..core.model.bundled_robots import BUNDLED_ROBOTS, EXAMPLE_ROBOT_DATA_PREFIX
from ..core.model.description import (
    example_robot_data_names,
    is_mjcf,
    load_urdf_model,
    resolve_urdf,
)
from ..core.model.robot import frames_by_kind

_JOINT_TYPES = {"RUB": "continuous", "R": "revolute", "P": "prismatic", "FreeFlyer": "floating"}


def robots_text() -> str:
    """The bundled chains (name, DOF, base -> tip, seed), then the other nameable URDFs."""
    rows = [("name", "DOF", "base_frame -> tip_frame", "ik_seed [rad or m]")]
    for robot in BUNDLED_ROBOTS:
        seed = "[" + ", ".join(f"{x:g}" for x in robot.seed) + "]"
        rows.append(
            (robot.name, str(len(robot.seed)), f"{robot.base_frame} -> {robot.tip_frame}", seed)
        )
    widths = [max(len(row[k]) for row in rows) for k in range(3)]
    lines = [
        f"{name:<{widths[0]}}  {dof:>{widths[1]}}  {chain:<{widths[2]}}  {seed}".rstrip()
        for name, dof, chain, seed in rows
    ]
    lines.insert(1, "-" * len(lines[0]))
    listed = {robot.name for robot in BUNDLED_ROBOTS}
    others = sorted(set(example_robot_data_names()) - listed)
    lines += [
        "",
        f"use as robot.urdf: {EXAMPLE_ROBOT_DATA_PREFIX}<name> (node parameter urdf: the same)",
        "also nameable (choose a chain with `grasp-safety frames <name>`): " + ", ".join(others),
        f"any other URDF of the data: {EXAMPLE_ROBOT_DATA_PREFIX}<path relative to its robots/ "
        "folder>, or a URDF file path",
    ]
    return "\n".join(lines)


def load_any_model(source: str) -> tuple[pin.Model, str]:
    """The full Pinocchio model of a URDF or MJCF file, URDF XML, ``example-robot-data:<name>``
    or a bare example-robot-data name; and how to name it in ``robot.urdf``."""
    text = source.strip()
    if not text.startswith(("<", EXAMPLE_ROBOT_DATA_PREFIX)) and not Path(text).exists():
        names = example_robot_data_names()
        if text in names:
            text = EXAMPLE_ROBOT_DATA_PREFIX + text
        else:
            close = difflib.get_close_matches(text, list(names), n=3, cutoff=0.5)
            hint = f"did you mean {' or '.join(repr(n) for n in close)}? " if close else ""
            raise InvalidInputError(
                "frames",
                f"no file '{text}' and no example-robot-data robot of that name; {hint}"
                "`grasp-safety robots` lists the names",
            )
    resolved, is_xml = resolve_urdf(text)
    if not is_xml and is_mjcf(resolved, is_xml):
        try:
            return pin.buildModelFromMJCF(resolved), f"{resolved} (MJCF)"
        except (RuntimeError, ValueError) as error:
            message = " ".join(str(error).split())
            raise InvalidInputError(
                "frames", f"cannot read MJCF '{resolved}': {message}"
            ) from None
    return load_urdf_model(text), text if not is_xml else "(URDF XML)"


def _joint_type(model: pin.Model, joint_id: int) -> str:
    short: str = model.joints[joint_id].shortname().removeprefix("JointModel")
    for prefix, name in _JOINT_TYPES.items():
        if short.startswith(prefix) and (prefix != "R" or not short.startswith("RUB")):
            return name
    return short


def frames_text(source: str) -> str:
    """The frames of a model by kind, then the tree of its links from the root: each link with
    the joint that attaches it and the movable joints (DOF) counted from the root."""
    model, where = load_any_model(source)
    kinds = frames_by_kind(model)
    lines = [
        f"{where}: {len(model.frames)} frames, {model.nv} DOF in "
        f"{model.njoints - 1} movable joints",
        "",
    ]
    for kind, names in kinds.items():
        if not names:
            continue
        if kind == "joints":
            names = [f"{name} ({_joint_type(model, model.getJointId(name))})" for name in names]
        lines.append(f"{kind} ({len(names)}): {', '.join(names)}")
    lines += ["", "tree of links from the root (the joint attaching each; DOF from the root):"]
    children: dict[int, list[int]] = {}
    for i, frame in enumerate(model.frames):
        if frame.type == pin.FrameType.BODY:
            joint_frame = frame.parentFrame
            parent = model.frames[joint_frame].parentFrame if joint_frame else -1
            children.setdefault(parent, []).append(i)

    def walk(link: int, depth: int, dof: int) -> None:
        frame = model.frames[link]
        joint = model.frames[frame.parentFrame] if frame.parentFrame else None
        if joint is not None and joint.type == pin.FrameType.JOINT:
            joint_id = model.getJointId(joint.name)
            dof += model.joints[joint_id].nv
            how = f"{_joint_type(model, joint_id)} '{joint.name}', {dof} DOF"
        else:
            how = f"fixed '{joint.name}'" if joint is not None else "root"
        leaf = "" if children.get(link) else ", leaf"
        lines.append(f"{'  ' * depth}{frame.name}  [{how}{leaf}]")
        for child in children.get(link, []):
            walk(child, depth + 1, dof)

    for root in children.get(-1, []) + children.get(0, []):
        walk(root, 0, 0)
    lines += [
        "",
        "a chain is base_frame -> tip_frame along this tree (tip below base); a name shared by "
        "a link and a joint means the link unless given as NAME@JOINT",
    ]
    return "\n".join(lines)
