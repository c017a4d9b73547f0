"""Robot model: a kinematic chain base_frame -> tip_frame cut out of a URDF with Pinocchio."""

from __future__ import annotations

import importlib.metadata
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..exceptions import FrameNotFoundError, InvalidInputError, RobotModelError
from ..input_checks import finite_array

EXAMPLE_ROBOT_DATA_PREFIX = "example-robot-data:"

EXAMPLE_ROBOT_DATA_URDFS: Mapping[str, str] = {
    "baxter": "baxter_description/urdf/baxter.urdf",
    "panda": "panda_description/urdf/panda.urdf",
    "ur3": "ur_description/urdf/ur3_robot.urdf",
    "ur5": "ur_description/urdf/ur5_robot.urdf",
    "ur10": "ur_description/urdf/ur10_robot.urdf",
    "kinova": "kinova_description/robots/kinova.urdf",
    "xarm7": "xarm_description/urdf/xarm7.urdf",
    "z1": "z1_description/urdf/z1.urdf",
    "so100": "so_arm_description/urdf/so100.urdf",
}
"""Bundled robot names and their URDF paths inside example-robot-data's ``robots/`` folder."""


def example_robot_data_dirs() -> list[Path]:
    """Folders that may hold example-robot-data's ``robots/`` tree (wheel, then ROS install)."""
    dirs: list[Path] = []
    try:
        dist = importlib.metadata.distribution("example-robot-data")
        dirs.append(Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))))
    except importlib.metadata.PackageNotFoundError:
        pass
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share" / "example-robot-data" / "robots")
    return [d for d in dirs if d.is_dir()]


def resolve_urdf(source: str, relative_to: Path | None = None) -> tuple[str, bool]:
    """Resolve a robot description to (text, is_xml).

    Args:
        source: URDF XML, a path to a URDF file, or ``example-robot-data:<name>`` with a
            name from EXAMPLE_ROBOT_DATA_URDFS or a path relative to the ``robots/`` folder.
        relative_to: Folder that relative file paths are taken from.

    Returns:
        The XML text or the file path, and whether it is XML text.
    """
    text = source.strip()
    if text.startswith("<"):
        return text, True
    if text.startswith(EXAMPLE_ROBOT_DATA_PREFIX):
        name = text[len(EXAMPLE_ROBOT_DATA_PREFIX) :]
        relative = EXAMPLE_ROBOT_DATA_URDFS.get(name, name)
        for folder in example_robot_data_dirs():
            candidate = folder / relative
            if candidate.is_file():
                return str(candidate), False
        raise InvalidInputError(
            "robot.urdf",
            f"example-robot-data robot '{name}' not found; bundled names: "
            f"{', '.join(sorted(EXAMPLE_ROBOT_DATA_URDFS))} (is example-robot-data installed?)",
        )
    path = Path(text).expanduser()
    if relative_to is not None and not path.is_absolute():
        path = relative_to / path
    if not path.is_file():
        raise InvalidInputError(
            "robot.urdf",
            f"no URDF file at '{path}'; give a file path, URDF XML or "
            f"'{EXAMPLE_ROBOT_DATA_PREFIX}<name>'",
        )
    return str(path), False


def load_urdf_model(source: str, relative_to: Path | None = None) -> pin.Model:
    """Build the full Pinocchio model (fixed base) of a URDF given as in resolve_urdf."""
    text, is_xml = resolve_urdf(source, relative_to)
    try:
        return pin.buildModelFromXML(text) if is_xml else pin.buildModelFromUrdf(text)
    except (RuntimeError, ValueError) as error:
        where = "URDF XML" if is_xml else f"'{text}'"
        message = str(error).strip().splitlines()[0] if str(error).strip() else "parse error"
        raise InvalidInputError("robot.urdf", f"cannot read {where}: {message}") from None


class RobotModel:
    """The chain base_frame -> tip_frame of a robot; every other joint locked.

    Joint positions ("positions") are one number per chain joint in chain order: angles [rad]
    for revolute and continuous joints, displacements [m] for prismatic ones. Pinocchio's
    configuration vector ``q`` differs for continuous joints (cos, sin); convert with
    ``q_from_positions`` and ``positions_from_q``.

    Attributes:
        model: Reduced Pinocchio model holding only the chain joints.
        base_frame, tip_frame: Frame names.
        tip_frame_id: Id of the tip frame in ``model``.
        transform_base_to_world: Constant pose of the base frame in the model's world frame.
        joint_names: Chain joint names, base to tip.
    """

    def __init__(
        self,
        full_model: pin.Model,
        base_frame: str,
        tip_frame: str,
        locked_positions: Mapping[str, float] | None = None,
    ) -> None:
        frame_names = [frame.name for frame in full_model.frames]
        for field, name in (("robot.base_frame", base_frame), ("robot.tip_frame", tip_frame)):
            if not full_model.existFrame(name):
                raise FrameNotFoundError(field, name, frame_names)
        base_joint = full_model.frames[full_model.getFrameId(base_frame)].parentJoint
        tip_joint = full_model.frames[full_model.getFrameId(tip_frame)].parentJoint
        upstream_of_base = set(full_model.supports[base_joint])
        chain = [j for j in full_model.supports[tip_joint] if j not in upstream_of_base]
        if base_joint not in full_model.supports[tip_joint]:
            raise InvalidInputError(
                "robot.base_frame",
                f"'{base_frame}' is not upstream of tip frame '{tip_frame}' in the kinematic tree",
            )
        if not chain:
            raise InvalidInputError(
                "robot.tip_frame", f"no joint between '{base_frame}' and '{tip_frame}'"
            )
        for joint_id in chain:
            if full_model.joints[joint_id].nv != 1:
                raise RobotModelError(
                    f"joint '{full_model.names[joint_id]}' on the chain has "
                    f"{full_model.joints[joint_id].nv} DOF; only 1-DOF joints are supported"
                )
        reference = pin.neutral(full_model)
        locked_positions = dict(locked_positions or {})
        for name, value in locked_positions.items():
            if not full_model.existJointName(name):
                raise InvalidInputError(
                    "robot.locked_joints",
                    f"unknown joint '{name}'; joints: {', '.join(full_model.names[1:])}",
                )
            joint = full_model.joints[full_model.getJointId(name)]
            if joint.nq != 1:
                raise InvalidInputError(
                    "robot.locked_joints", f"joint '{name}' has nq={joint.nq}; only nq=1 joints"
                )
            reference[joint.idx_q] = float(value)
        to_lock = [j for j in range(1, full_model.njoints) if j not in chain]
        self.model = (
            pin.buildReducedModel(full_model, to_lock, reference) if to_lock else full_model.copy()
        )
        self.base_frame = base_frame
        self.tip_frame = tip_frame
        self.tip_frame_id = self.model.getFrameId(tip_frame)
        self.base_frame_id = self.model.getFrameId(base_frame)
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, pin.neutral(self.model))
        self.transform_base_to_world = pin.SE3(data.oMf[self.base_frame_id])
        self.joint_names: tuple[str, ...] = tuple(self.model.names[1:])
        self._continuous = np.array([j.nq == 2 for j in self.model.joints[1:]])
        self._idx_q = np.array([j.idx_q for j in self.model.joints[1:]])
        lower, upper = self.model.lowerPositionLimit, self.model.upperPositionLimit
        self.lower_limits = np.where(self._continuous, -np.inf, lower[self._idx_q])
        self.upper_limits = np.where(self._continuous, np.inf, upper[self._idx_q])
        self.velocity_limits = np.array(self.model.velocityLimit)
        for array in (self.lower_limits, self.upper_limits, self.velocity_limits):
            array.setflags(write=False)

    @classmethod
    def from_urdf(
        cls,
        source: str,
        base_frame: str,
        tip_frame: str,
        locked_positions: Mapping[str, float] | None = None,
        relative_to: Path | None = None,
    ) -> RobotModel:
        """Load from a URDF path, URDF XML or ``example-robot-data:<name>``."""
        return cls(load_urdf_model(source, relative_to), base_frame, tip_frame, locked_positions)

    @property
    def num_joints(self) -> int:
        """Number of chain joints."""
        return len(self.joint_names)

    def q_from_positions(self, positions: Sequence[float] | np.ndarray) -> np.ndarray:
        """Pinocchio configuration of chain joint positions (chain order)."""
        positions = np.asarray(positions, dtype=float)
        if not self._continuous.any():
            return positions.copy()
        q = np.empty(self.model.nq)
        for k, idx in enumerate(self._idx_q):
            if self._continuous[k]:
                q[idx], q[idx + 1] = np.cos(positions[k]), np.sin(positions[k])
            else:
                q[idx] = positions[k]
        return q

    def positions_from_q(self, q: np.ndarray) -> np.ndarray:
        """Chain joint positions (chain order) of a Pinocchio configuration."""
        if not self._continuous.any():
            return np.array(q, dtype=float)
        positions = np.array(q[self._idx_q], dtype=float)
        for k in np.flatnonzero(self._continuous):
            idx = self._idx_q[k]
            positions[k] = np.arctan2(q[idx + 1], q[idx])
        return positions

    def default_seed_positions(self) -> np.ndarray:
        """Middle of the joint ranges (0 for unlimited joints)."""
        lower = np.where(np.isfinite(self.lower_limits), self.lower_limits, 0.0)
        upper = np.where(np.isfinite(self.upper_limits), self.upper_limits, 0.0)
        return 0.5 * (lower + upper)

    def check_positions(self, positions: Sequence[float] | np.ndarray, field: str) -> np.ndarray:
        """Validate chain joint positions: count, finiteness and limits."""
        values = finite_array(positions, field, (self.num_joints,))
        outside = (values < self.lower_limits - 1e-9) | (values > self.upper_limits + 1e-9)
        if outside.any():
            k = int(np.flatnonzero(outside)[0])
            raise InvalidInputError(
                field,
                f"joint '{self.joint_names[k]}' = {values[k]:g} is outside its limits "
                f"[{self.lower_limits[k]:g}, {self.upper_limits[k]:g}]",
            )
        return values

    def transform_tip_to_base(self, positions: Sequence[float] | np.ndarray) -> pin.SE3:
        """Forward kinematics: pose of the tip frame in the base frame."""
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, self.q_from_positions(positions))
        return self.transform_base_to_world.actInv(data.oMf[self.tip_frame_id])
