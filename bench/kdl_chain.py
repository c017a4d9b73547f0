"""PyKDL for the peer pipeline (bench/pykdl_peer.py): the module, and a KDL chain built from a
URDF as kdl_parser builds it (parsed with xml.etree: joints base -> tip, origins rpy/xyz, axes,
link inertials)."""

from __future__ import annotations

import importlib.util
import math
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

DIST_PACKAGES = Path("/usr/lib/python3/dist-packages")


def load_pykdl(install: bool = True) -> tuple[ModuleType | None, str]:
    """Import PyKDL (Debian's python3-pykdl), installing it with apt-get when root.

    Only the PyKDL extension module is loaded from the system dist-packages (by file), so
    nothing else from the system Python shadows the venv's packages.

    Returns:
        The module, or None and the reason it is unavailable.
    """
    try:
        import PyKDL  # type: ignore[import-not-found]

        return PyKDL, ""
    except ImportError:
        pass
    pattern = f"PyKDL.{sys.implementation.cache_tag}-*.so"  # e.g. cpython-311

    def find() -> Path | None:
        matches = sorted(DIST_PACKAGES.glob(pattern))
        return matches[0] if matches else None

    path = find()
    if path is None and install:
        if shutil.which("apt-get") is None:
            return None, "PyKDL missing and apt-get unavailable (install python3-pykdl)"
        if hasattr(os, "geteuid") and os.geteuid() != 0:
            return None, "PyKDL missing: run 'sudo apt-get install -y python3-pykdl'"
        print("bench: installing python3-pykdl with apt-get ...", file=sys.stderr)
        for command in (
            ["apt-get", "update", "-qq"],
            ["apt-get", "install", "-y", "-qq", "python3-pykdl"],
        ):
            done = subprocess.run(command, capture_output=True, text=True, check=False)
            if done.returncode != 0:
                return None, f"'{' '.join(command)}' failed: {done.stderr.strip()[-300:]}"
        path = find()
    if path is None:
        return None, (
            f"no {pattern} in {DIST_PACKAGES} (python3-pykdl is built for the system Python "
            f"{'.'.join(map(str, sys.version_info[:2]))}?)"
        )
    spec = importlib.util.spec_from_file_location("PyKDL", path)
    if spec is None or spec.loader is None:
        return None, f"cannot load {path}"
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except ImportError as error:
        return None, f"cannot import {path}: {error}"
    sys.modules["PyKDL"] = module
    return module, ""


# ----------------------------------------------------------------------------- URDF -> KDL
def _floats(text: str | None, default: tuple[float, ...]) -> tuple[float, ...]:
    return tuple(float(x) for x in text.split()) if text else default


def _rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll),
        math.sin(roll),
        math.cos(pitch),
        math.sin(pitch),
        math.cos(yaw),
        math.sin(yaw),
    )
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


@dataclass
class KDLChain:
    """A KDL chain with its solvers and joint limits (chain order)."""

    chain: Any
    joint_names: list[str]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray


def build_chain(kdl: ModuleType, urdf_text: str, base_link: str, tip_link: str) -> KDLChain:
    """The chain base_link -> tip_link of a URDF, as kdl_parser builds it.

    kdl_parser's tree keeps side branches (fingers, sensors) that a chain extracted from it
    drops; here each chain link also carries the inertia of everything rigidly hanging off it
    (side branches with their joints at zero, links beyond the tip), as the Pinocchio model
    (locked joints at their neutral position) does, so both describe the same rigid bodies.
    """
    root = ET.fromstring(urdf_text)
    links = {link.get("name"): link for link in root.findall("link")}
    joints = root.findall("joint")
    joint_of_child = {joint.find("child").get("link"): joint for joint in joints}
    children: dict[str, list[ET.Element]] = {}
    for joint in joints:
        children.setdefault(joint.find("parent").get("link"), []).append(joint)
    path = []
    link = tip_link
    while link != base_link:
        if link not in joint_of_child:
            raise ValueError(f"'{base_link}' is not upstream of '{tip_link}'")
        joint = joint_of_child[link]
        path.append(joint)
        link = joint.find("parent").get("link")
    path.reverse()
    on_path = {id(joint) for joint in path}
    chain = kdl.Chain()
    names, lower, upper, velocity = [], [], [], []
    for joint in path:
        rotation, translation = _origin(joint)
        frame = kdl.Frame(kdl.Rotation(*rotation.reshape(-1)), kdl.Vector(*translation))
        kind = joint.get("type")
        name = joint.get("name")
        if kind in ("revolute", "continuous", "prismatic"):
            axis_element = joint.find("axis")
            axis = _floats(
                axis_element.get("xyz") if axis_element is not None else None, (1.0, 0.0, 0.0)
            )
            axis_in_parent = frame.M * kdl.Vector(*axis)
            joint_type = kdl.Joint.TransAxis if kind == "prismatic" else kdl.Joint.RotAxis
            kdl_joint = kdl.Joint(name, frame.p, axis_in_parent, joint_type)
            limit = joint.find("limit")
            if kind == "continuous" or limit is None:
                lo, hi = -math.inf, math.inf
            else:
                lo, hi = float(limit.get("lower", 0.0)), float(limit.get("upper", 0.0))
            names.append(name)
            lower.append(lo)
            upper.append(hi)
            velocity.append(float(limit.get("velocity", 0.0)) if limit is not None else 0.0)
        elif kind == "fixed":
            kdl_joint = kdl.Joint(name, kdl.Joint.Fixed)
        else:
            raise ValueError(f"joint '{name}' of type '{kind}' is not supported by the peer")
        child = joint.find("child").get("link")
        body = _Body()
        _add_subtree(body, child, np.eye(3), np.zeros(3), links, children, on_path)
        chain.addSegment(kdl.Segment(child, kdl_joint, frame, body.kdl(kdl)))
    return KDLChain(chain, names, np.array(lower), np.array(upper), np.array(velocity))


def _origin(element: ET.Element) -> tuple[np.ndarray, np.ndarray]:
    origin = element.find("origin")
    xyz = _floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0))
    rpy = _floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0))
    return _rpy_matrix(*rpy), np.array(xyz)


class _Body:
    """Sum of rigid-body inertias in one frame: mass, first moment, inertia about the origin."""

    def __init__(self) -> None:
        self.mass = 0.0
        self.moment = np.zeros(3)
        self.inertia_origin = np.zeros((3, 3))

    def add(self, mass: float, com: np.ndarray, inertia_com: np.ndarray) -> None:
        self.mass += mass
        self.moment += mass * com
        shift = float(com @ com) * np.eye(3) - np.outer(com, com)
        self.inertia_origin += inertia_com + mass * shift

    def kdl(self, kdl: ModuleType) -> Any:
        if self.mass <= 0.0:
            return kdl.RigidBodyInertia()
        com = self.moment / self.mass
        shift = float(com @ com) * np.eye(3) - np.outer(com, com)
        about_com = self.inertia_origin - self.mass * shift
        rotational = kdl.RotationalInertia(
            about_com[0, 0],
            about_com[1, 1],
            about_com[2, 2],
            about_com[0, 1],
            about_com[0, 2],
            about_com[1, 2],
        )
        return kdl.RigidBodyInertia(self.mass, kdl.Vector(*com), rotational)


def _add_subtree(
    body: _Body,
    link: str,
    rotation: np.ndarray,
    translation: np.ndarray,
    links: dict[str, ET.Element],
    children: dict[str, list[ET.Element]],
    on_path: set[int],
) -> None:
    """Add link's inertial and every off-path subtree below it (joints at zero) to body."""
    inertial = links[link].find("inertial")
    if inertial is not None:
        frame_r, frame_p = _origin(inertial)
        element = inertial.find("inertia")
        values = {key: float(element.get(key, 0.0)) for key in element.keys()}
        tensor = np.array(
            [
                [values.get("ixx", 0.0), values.get("ixy", 0.0), values.get("ixz", 0.0)],
                [values.get("ixy", 0.0), values.get("iyy", 0.0), values.get("iyz", 0.0)],
                [values.get("ixz", 0.0), values.get("iyz", 0.0), values.get("izz", 0.0)],
            ]
        )
        r = rotation @ frame_r
        mass = float(inertial.find("mass").get("value"))
        body.add(mass, rotation @ frame_p + translation, r @ tensor @ r.T)
    for joint in children.get(link, []):
        if id(joint) in on_path:
            continue
        joint_r, joint_p = _origin(joint)
        child = joint.find("child").get("link")
        _add_subtree(
            body,
            child,
            rotation @ joint_r,
            rotation @ joint_p + translation,
            links,
            children,
            on_path,
        )
