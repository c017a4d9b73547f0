"""Robot model: a kinematic chain base_frame -> tip_frame cut out of a URDF with Pinocchio
(the description is read by ``description``)."""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from ..exceptions import FrameNotFoundError, InvalidInputError
from ..input_checks import finite_array
from .description import MAX_URDF_BYTES as MAX_URDF_BYTES
from .description import MimicJoint, load_urdf_mimic_joints
from .description import load_urdf_model as load_urdf_model
from .description import resolve_urdf as resolve_urdf

# MAX_URDF_BYTES, load_urdf_model and resolve_urdf are re-exported for their callers that import
# them from here (dataset/batch.py, bench/run.py, test_mjcf.py).

FRAME_TYPES: Mapping[str, pin.FrameType] = dict(pin.FrameType.names)
"""Frame types a frame name can be qualified with: ``name@TYPE``, e.g. ``gripper@JOINT``."""

MASS_MATRIX_RELATIVE_TOLERANCE = 1e-12
"""Smallest accepted eigenvalue ratio of the chain's mass matrix with an object at the tip."""

ARMATURE_FIELD = "robot.armature_kgm2"
"""Name of the armature input in messages."""

NO_ARMATURE_NOTE = "rotor inertia not given: effective masses are the links' only (a lower bound)"
"""Said once per result when the chain has no armature (reflected rotor inertia)."""


def armature_from_input(
    value: Sequence[float] | Mapping[str, float] | np.ndarray,
    joint_names: Sequence[str],
    field: str = ARMATURE_FIELD,
    base: np.ndarray | None = None,
) -> np.ndarray:
    """Armature (reflected rotor inertia, I_rotor N^2) per chain joint, chain order: [kg m^2]
    for a revolute or continuous joint, [kg] for a prismatic one.

    Args:
        value: One value per chain joint in chain order, or ``{joint_name: value}`` (joints
            not named keep ``base``).
        joint_names: The chain joints, base to tip.
        base: The armature a mapping overrides, chain order (the description's own); None: 0.

    Raises:
        InvalidInputError: a wrong count, an unknown joint, or a value not finite and >= 0
            (the message names the joint).
    """
    return per_joint_values(
        value,
        joint_names,
        field,
        _armature_value,
        np.zeros(len(joint_names)) if base is None else base,
    )


def per_joint_values(
    value: Any,
    joint_names: Sequence[str],
    field: str,
    read_one: Callable[[Any, str], float],
    base: np.ndarray,
) -> np.ndarray:
    """One value per chain joint, chain order, read-only: ``value`` is a list in chain order or
    ``{joint_name: value}`` (joints not named keep ``base``); ``read_one(entry, field)`` checks
    one entry and names it (``field[k] (joint 'name')`` or ``field.name``).

    Raises:
        InvalidInputError: a wrong count, an unknown joint, neither a list nor a mapping, or
            what ``read_one`` refuses.
    """
    names = list(joint_names)
    if isinstance(value, Mapping):
        values = np.array(base, dtype=float)
        for name, entry in value.items():
            if name not in names:
                raise InvalidInputError(
                    field, f"unknown chain joint '{name}'; chain joints: {', '.join(names)}"
                )
            values[names.index(name)] = read_one(entry, f"{field}.{name}")
    elif isinstance(value, (Sequence, np.ndarray)) and not isinstance(value, (str, bytes)):
        if len(value) != len(names):
            raise InvalidInputError(
                field,
                f"must have one value per chain joint ({len(names)}: {', '.join(names)}), "
                f"got {len(value)}",
            )
        values = np.array(
            [read_one(v, f"{field}[{k}] (joint '{names[k]}')") for k, v in enumerate(value)],
            dtype=float,
        )
    else:
        raise InvalidInputError(
            field,
            f"must be a list of {len(names)} values (chain order) or a mapping "
            f"{{joint_name: value}}, got {value!r}",
        )
    values.setflags(write=False)
    return values


def _armature_value(value: object, field: str) -> float:
    """One armature value: finite and >= 0 [kg m^2 or kg]."""
    if isinstance(value, bool):
        raise InvalidInputError(field, f"must be a number >= 0, got {value!r}")
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InvalidInputError(field, f"must be a number >= 0, got {value!r}") from None
    if not np.isfinite(number) or number < 0.0:
        raise InvalidInputError(
            field, f"must be finite and >= 0 [kg m^2, kg if prismatic], got {number:g}"
        )
    return number


def _describe_frame(model: pin.Model, frame_id: int) -> str:
    frame = model.frames[frame_id]
    return f"{frame.name}@{frame.type.name} (on joint '{model.names[frame.parentJoint]}')"


FRAME_KINDS: Mapping[str, tuple[pin.FrameType, ...]] = {
    "links": (pin.FrameType.BODY,),
    "joints": (pin.FrameType.JOINT,),
    "fixed joints": (pin.FrameType.FIXED_JOINT,),
    "other frames": (pin.FrameType.OP_FRAME, pin.FrameType.SENSOR),
}
"""Frame kinds as listed to a user, by the Pinocchio frame types they hold."""


def frames_by_kind(model: pin.Model) -> dict[str, list[str]]:
    """The model's frame names by kind (FRAME_KINDS), in model order."""
    return {
        kind: [frame.name for frame in model.frames if frame.type in types]
        for kind, types in FRAME_KINDS.items()
    }


def find_frame(model: pin.Model, name: str, field: str) -> int:
    """Id of the frame ``name`` or ``name@TYPE`` (TYPE one of FRAME_TYPES).

    A name shared by several frames (a link and a joint of the same name) picks the BODY (link)
    frame when exactly one matches; otherwise ``name@TYPE`` must say which.

    Raises:
        FrameNotFoundError: no frame of that name.
        InvalidInputError: the name is ambiguous, or has no frame of the given type.
    """
    base_name, at, type_name = name.rpartition("@")
    if not at or type_name.upper() not in FRAME_TYPES or model.existFrame(name):
        base_name, type_name = name, ""
    matches = [i for i, frame in enumerate(model.frames) if frame.name == base_name]
    if not matches:
        kinds = frames_by_kind(model)
        kinds["joints"] += kinds.pop("fixed joints")  # as URDF has them: links and joints
        raise FrameNotFoundError(field, base_name, kinds)
    listed = ", ".join(_describe_frame(model, i) for i in matches)
    if type_name:
        wanted = FRAME_TYPES[type_name.upper()]
        matches = [i for i in matches if model.frames[i].type == wanted]
        if not matches:
            raise InvalidInputError(
                field, f"frame '{base_name}' has no {type_name.upper()} frame; frames: {listed}"
            )
    elif len(matches) > 1:
        bodies = [i for i in matches if model.frames[i].type == pin.FrameType.BODY]
        matches = bodies if len(bodies) == 1 else matches
    if len(matches) > 1:
        raise InvalidInputError(
            field,
            f"'{name}' names {len(matches)} frames: {listed}; pick one as '{base_name}@TYPE' "
            f"(TYPE: {', '.join(FRAME_TYPES)})",
        )
    return matches[0]


def _reduced_model(
    full_model: pin.Model, to_lock: Sequence[int], reference: np.ndarray, frame_ids: Sequence[int]
) -> tuple[pin.Model, list[int]]:
    """buildReducedModel, and the ids in it of the frames ``frame_ids`` of ``full_model``.

    Pinocchio's reduction looks frames up by name, which fails for a name shared by several
    frames: such frames (but a joint's own frame) are renamed for the reduction, then back.
    """
    names = [frame.name for frame in full_model.frames]
    shared = {
        i
        for i, name in enumerate(names)
        if names.count(name) > 1 and full_model.frames[i].type != pin.FrameType.JOINT
    }  # a joint's frame keeps the joint's name: the reduction finds it by that name
    model = full_model.copy()
    for i in shared:
        model.frames[i].name = f"{names[i]}@{model.frames[i].type.name}#{i}"
    renamed = {model.frames[i].name: names[i] for i in shared}
    wanted = [model.frames[i].name for i in frame_ids]
    if to_lock:
        model = pin.buildReducedModel(model, list(to_lock), reference)
    ids = [model.getFrameId(name) for name in wanted]
    for frame in model.frames:
        frame.name = renamed.get(frame.name, frame.name)
    return model, ids


def _chain_joints(full_model: pin.Model, base_id: int, tip_id: int) -> list[int]:
    """Ids of the joints between frames ``base_id`` and ``tip_id``, base to tip;
    InvalidInputError unless the base is upstream of the tip and they are 1-DOF joints."""
    base_frame, tip_frame = full_model.frames[base_id].name, full_model.frames[tip_id].name
    base_joint = full_model.frames[base_id].parentJoint
    tip_joint = full_model.frames[tip_id].parentJoint
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
        joint = full_model.joints[joint_id]
        if joint.nv != 1:
            raise InvalidInputError(
                "robot.tip_frame",
                f"joint '{full_model.names[joint_id]}' ({joint.shortname()}) on the chain "
                f"'{base_frame}' -> '{tip_frame}' has {joint.nv} DOF; only 1-DOF joints "
                "(revolute, continuous, prismatic) are supported",
            )
    return chain


def _set_locked_positions(
    full_model: pin.Model, locked_positions: Mapping[str, float], reference: np.ndarray
) -> None:
    """Write each locked joint's position into the configuration ``reference`` (in place);
    InvalidInputError for an unknown joint, one with nq != 1 or a position outside its
    limits."""
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
        lower = full_model.lowerPositionLimit[joint.idx_q]
        upper = full_model.upperPositionLimit[joint.idx_q]
        if not lower - 1e-9 <= float(value) <= upper + 1e-9:
            raise InvalidInputError(
                f"robot.locked_joints.{name}",
                f"{float(value):g} is outside the joint's limits [{lower:g}, {upper:g}]",
            )
        reference[joint.idx_q] = float(value)


def _apply_mimic_joints(
    full_model: pin.Model,
    chain: Sequence[int],
    mimic_joints: Mapping[str, MimicJoint],
    reference: np.ndarray,
    locked_positions: Mapping[str, float],
    tip_frame: str,
) -> None:
    """Refuse a chain holding a mimic joint or its leader (the chain would be a different
    robot); set each locked mimic joint from its locked leader in ``reference``."""
    names = list(full_model.names)
    for follower, mimic in mimic_joints.items():
        if follower not in names or mimic.leader not in names:
            continue
        follower_id, leader_id = names.index(follower), names.index(mimic.leader)
        if follower_id in chain or leader_id in chain:
            relation = (
                f"joint '{follower}' on the chain to '{tip_frame}' mimics joint '{mimic.leader}'"
                if follower_id in chain
                else f"joint '{mimic.leader}' on the chain to '{tip_frame}' is mimicked by joint "
                f"'{follower}'"
            )
            raise InvalidInputError(
                "robot.tip_frame",
                f"{relation} (URDF <mimic>); chains with mimic joints are not supported: "
                "choose a tip frame upstream of both",
            )
        if follower in locked_positions:
            raise InvalidInputError(
                "robot.locked_joints",
                f"joint '{follower}' mimics joint '{mimic.leader}'; lock '{mimic.leader}' instead",
            )
        follower_joint, leader_joint = full_model.joints[follower_id], full_model.joints[leader_id]
        if follower_joint.nq == 1 and leader_joint.nq == 1:
            reference[follower_joint.idx_q] = (
                mimic.multiplier * reference[leader_joint.idx_q] + mimic.offset
            )


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
        armature_kgm2: Reflected rotor inertia per chain joint, chain order [kg m^2, kg for
            prismatic joints]; written to ``model.armature``, so every Pinocchio call on the
            model or a copy of it (crba, rnea, aba, computeMinverse) includes it.
        armature_given: Whether the armature was given: explicitly (zeros included: a
            direct-drive arm's rotor inertia is known to be nil), or non-zero in the
            description (an MJCF's); False: not given, the effective masses are the links'
            only and a lower bound (NO_ARMATURE_NOTE).
    """

    def __init__(
        self,
        full_model: pin.Model,
        base_frame: str,
        tip_frame: str,
        locked_positions: Mapping[str, float] | None = None,
        mimic_joints: Mapping[str, MimicJoint] | None = None,
        armature_kgm2: Sequence[float] | Mapping[str, float] | np.ndarray | None = None,
    ) -> None:
        base_id = find_frame(full_model, base_frame, "robot.base_frame")
        tip_id = find_frame(full_model, tip_frame, "robot.tip_frame")
        base_frame, tip_frame = full_model.frames[base_id].name, full_model.frames[tip_id].name
        chain = _chain_joints(full_model, base_id, tip_id)
        reference = pin.neutral(full_model)
        locked_positions = dict(locked_positions or {})
        _set_locked_positions(full_model, locked_positions, reference)
        _apply_mimic_joints(
            full_model, chain, mimic_joints or {}, reference, locked_positions, tip_frame
        )
        to_lock = [j for j in range(1, full_model.njoints) if j not in chain]
        self.model, (self.tip_frame_id, self.base_frame_id) = _reduced_model(
            full_model, to_lock, reference, (tip_id, base_id)
        )
        self.base_frame = base_frame
        self.tip_frame = tip_frame
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, pin.neutral(self.model))
        self.transform_base_to_world = pin.SE3(data.oMf[self.base_frame_id])
        self.joint_names: tuple[str, ...] = tuple(self.model.names[1:])
        own = armature_from_input(  # the description's own (an MJCF's; a URDF has none)
            np.array(self.model.armature), self.joint_names, "robot.urdf armature"
        )
        self.armature_kgm2 = armature_from_input(
            own if armature_kgm2 is None else armature_kgm2, self.joint_names, base=own
        )
        self.armature_given = armature_kgm2 is not None or bool(np.any(own > 0.0))
        self.model.armature = np.array(self.armature_kgm2)
        self._links_only: RobotModel | None = None
        self._continuous = np.array([j.nq == 2 for j in self.model.joints[1:]])
        self._idx_q = np.array([j.idx_q for j in self.model.joints[1:]])
        lower, upper = self.model.lowerPositionLimit, self.model.upperPositionLimit
        self.lower_limits = np.where(self._continuous, -np.inf, lower[self._idx_q])
        self.upper_limits = np.where(self._continuous, np.inf, upper[self._idx_q])
        self.velocity_limits = np.array(self.model.velocityLimit)
        for array in (self.lower_limits, self.upper_limits, self.velocity_limits):
            array.setflags(write=False)
        self._check_mass_matrix()

    def _check_mass_matrix(self) -> None:
        """Refuse a chain whose joint-space mass matrix is singular even with an object (1 kg,
        inertia 1e-3 kg m^2 about each axis) at the tip: joints moving no mass or inertia."""
        model = self.model.copy()
        tip = model.frames[self.tip_frame_id]
        model.inertias[tip.parentJoint] = model.inertias[tip.parentJoint] + tip.placement.act(
            pin.Inertia(1.0, np.zeros(3), 1e-3 * np.eye(3))
        )
        data = model.createData()
        rng = np.random.default_rng(0)
        lower = np.where(np.isfinite(self.lower_limits), self.lower_limits, -np.pi)
        upper = np.where(np.isfinite(self.upper_limits), self.upper_limits, np.pi)
        for _ in range(3):  # singular at one generic configuration is singular everywhere
            mass_matrix = pin.crba(model, data, self.q_from_positions(rng.uniform(lower, upper)))
            mass_matrix = np.triu(mass_matrix) + np.triu(mass_matrix, 1).T
            eigenvalues = np.linalg.eigvalsh(mass_matrix)
            if eigenvalues[0] > MASS_MATRIX_RELATIVE_TOLERANCE * abs(eigenvalues[-1]):
                return
        massless = [
            name
            for name, inertia in zip(self.joint_names, self.model.inertias[1:], strict=True)
            if inertia.mass <= 0.0
        ]
        raise InvalidInputError(
            "robot.urdf",
            f"the mass matrix of the chain '{self.base_frame}' -> '{self.tip_frame}' is not "
            "positive definite even with an object at the tip (links moved by "
            f"{', '.join(massless) or 'the chain joints'} have no mass); give the chain's "
            "links a positive <inertial> mass and inertia",
        )

    @classmethod
    def from_urdf(
        cls,
        source: str,
        base_frame: str,
        tip_frame: str,
        locked_positions: Mapping[str, float] | None = None,
        relative_to: Path | None = None,
        armature_kgm2: Sequence[float] | Mapping[str, float] | np.ndarray | None = None,
    ) -> RobotModel:
        """Load from a URDF or MJCF path, URDF or MJCF XML, or ``example-robot-data:<name>``;
        an explicit ``armature_kgm2`` replaces an MJCF's joint armature (a mapping: of the
        joints it names)."""
        full_model = load_urdf_model(source, relative_to)
        mimic_joints = load_urdf_mimic_joints(source, relative_to)
        return cls(
            full_model, base_frame, tip_frame, locked_positions, mimic_joints, armature_kgm2
        )

    def with_armature(
        self, armature_kgm2: Sequence[float] | Mapping[str, float] | np.ndarray
    ) -> RobotModel:
        """This chain with another armature, given (validated as in the constructor; a mapping
        changes the joints it names, the others keep this chain's)."""
        values = armature_from_input(armature_kgm2, self.joint_names, base=self.armature_kgm2)
        robot = copy.copy(self)
        robot.model = self.model.copy()
        robot.model.armature = np.array(values)
        robot.armature_kgm2 = values
        robot.armature_given = True
        robot._links_only = None
        return robot

    def links_only(self) -> RobotModel:
        """This chain without armature (the links' inertia only): itself when it has none."""
        if not np.any(self.armature_kgm2 > 0.0):
            return self
        if self._links_only is None:
            self._links_only = self.with_armature(np.zeros(self.num_joints))
            self._links_only.armature_given = False
        return self._links_only

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
