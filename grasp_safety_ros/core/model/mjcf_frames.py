"""MJCF frames placed where MuJoCo places them.

Pinocchio's MJCF reader (4.1) drops the offsets of jointless bodies above a site: a site on a
body that hangs below one or more jointless bodies lands at its own ``pos`` composed with the
last body only (a hinge body, a jointless body at x 0.5, a body at x 0.2 turned 90° about z,
a site at x 0.1: Pinocchio puts the site at (0.2, 0.1, 0), MuJoCo at (0.7, 0.1, 0)).
``place_frames_as_mujoco`` compiles the same description with MuJoCo (imported here only, for
MJCF) and compares every body and site frame with MuJoCo's forward kinematics at the zero and a
generic configuration: a frame that differs is moved onto MuJoCo's placement (relative to its
Pinocchio parent joint, found at the zero configuration) and must then agree at the generic one,
else the description is refused naming the frame.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin

from ..exceptions import InvalidInputError

PLACEMENT_TOLERANCE_M = 1e-9
"""A frame agrees with MuJoCo's when its origin is within this distance [m] and its axes within
this angle [rad] of MuJoCo's."""
MESH_TAGS = ("mesh", "hfield", "skin")
"""Assets (and geom types) dropped when MuJoCo cannot read their files: frames need none."""


def _compile_with_mujoco(text: str, is_xml: bool) -> Any:
    """MuJoCo's model of the description (XML text or a file path); where MuJoCo cannot read
    its meshes (the ranking reads none), the same description without them."""
    try:
        import mujoco
    except ImportError:
        raise InvalidInputError(
            "robot.urdf", "MJCF needs the mujoco package to place its frames (pip install mujoco)"
        ) from None
    try:
        return (
            mujoco.MjModel.from_xml_string(text) if is_xml else mujoco.MjModel.from_xml_path(text)
        )
    except (ValueError, RuntimeError):
        pass
    root = ElementTree.fromstring(text) if is_xml else ElementTree.parse(text).getroot()
    for parent in list(root.iter()):
        for child in list(parent):
            if child.tag in MESH_TAGS or (child.tag == "geom" and child.get("type") in MESH_TAGS):
                parent.remove(child)
    try:
        return mujoco.MjModel.from_xml_string(ElementTree.tostring(root, encoding="unicode"))
    except (ValueError, RuntimeError) as error:
        message = " ".join(str(error).split())
        raise InvalidInputError(
            "robot.urdf", f"MuJoCo cannot compile the MJCF (needed to place its frames): {message}"
        ) from None


def _configurations(model: pin.Model) -> Iterator[np.ndarray]:
    """Pinocchio's zero configuration, then a generic one: each one-degree-of-freedom joint at
    a fixed fraction of its range (0.3 + 0.2 k rad or m where unbounded); ball and free joints
    stay at their zero (MuJoCo's qpos0)."""
    zero = pin.neutral(model)
    yield zero
    step = np.zeros(model.nv)
    for k, joint in enumerate(model.joints[1:]):
        if joint.nv != 1:
            continue
        lower = model.lowerPositionLimit[joint.idx_q]
        upper = model.upperPositionLimit[joint.idx_q]
        fraction = 0.35 + 0.1 * (k % 4)
        bounded = joint.nq == 1 and np.isfinite(lower) and np.isfinite(upper)
        bounded = bounded and upper - lower < 1e3
        step[joint.idx_v] = fraction * (upper - lower) + lower if bounded else 0.3 + 0.2 * k
    yield pin.integrate(model, zero, step)


def _mujoco_positions(model: pin.Model, mj_model: Any, q: np.ndarray) -> np.ndarray:
    """MuJoCo's qpos of Pinocchio's configuration q: one-degree-of-freedom joints matched by
    name, measured from their ``ref`` (MuJoCo's qpos0); the others at qpos0."""
    import mujoco

    qpos: np.ndarray = mj_model.qpos0.copy()
    step = pin.difference(model, pin.neutral(model), q)
    for joint_id in range(1, model.njoints):
        joint, name = model.joints[joint_id], model.names[joint_id]
        if joint.nv != 1:
            continue
        mj_joint = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if mj_joint < 0:
            raise InvalidInputError(
                "robot.urdf", f"MJCF joint '{name}': MuJoCo has no joint of that name"
            )
        qpos[mj_model.jnt_qposadr[mj_joint]] += step[joint.idx_v]
    return qpos


def _mujoco_placements(model: pin.Model, mj_model: Any, q: np.ndarray) -> dict[int, pin.SE3]:
    """MuJoCo's world placement of every Pinocchio BODY and OP_FRAME frame that names a MuJoCo
    body or site, at Pinocchio's configuration q."""
    import mujoco

    data = mujoco.MjData(mj_model)
    data.qpos[:] = _mujoco_positions(model, mj_model, q)
    mujoco.mj_kinematics(mj_model, data)
    placements = {}
    for frame_id, frame in enumerate(model.frames):
        if frame.type == pin.FrameType.BODY:
            index = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_BODY, frame.name)
            if index >= 0:
                rotation, origin = data.xmat[index], data.xpos[index]
                placements[frame_id] = pin.SE3(rotation.reshape(3, 3).copy(), origin.copy())
        elif frame.type == pin.FrameType.OP_FRAME:
            index = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_SITE, frame.name)
            if index >= 0:
                rotation, origin = data.site_xmat[index], data.site_xpos[index]
                placements[frame_id] = pin.SE3(rotation.reshape(3, 3).copy(), origin.copy())
    return placements


def _agrees(a: pin.SE3, b: pin.SE3) -> bool:
    distance = np.linalg.norm(a.translation - b.translation)
    angle = np.linalg.norm(pin.log3(a.rotation.T @ b.rotation))
    return bool(distance <= PLACEMENT_TOLERANCE_M and angle <= PLACEMENT_TOLERANCE_M)


def place_frames_as_mujoco(model: pin.Model, text: str, is_xml: bool) -> list[str]:
    """Move ``model``'s MJCF body and site frames (in place) onto MuJoCo's placements of the
    same description (XML text or a file path); return the names of the frames moved.

    InvalidInputError (``robot.urdf``) naming the frame where a moved frame still differs from
    MuJoCo at the generic configuration, naming the joint where MuJoCo has none of its name.
    """
    mj_model = _compile_with_mujoco(text, is_xml)
    data = model.createData()
    moved = []
    for check, q in enumerate(_configurations(model)):
        pin.framesForwardKinematics(model, data, q)
        for frame_id, expected in _mujoco_placements(model, mj_model, q).items():
            if _agrees(data.oMf[frame_id], expected):
                continue
            frame = model.frames[frame_id]
            if check:
                raise InvalidInputError(
                    "robot.urdf",
                    f"MJCF frame '{frame.name}': Pinocchio and MuJoCo place it differently "
                    "as the joints move (it cannot be corrected)",
                )
            frame.placement = data.oMi[frame.parentJoint].actInv(expected)
            model.frames[frame_id] = frame
            moved.append(frame.name)
    return moved
