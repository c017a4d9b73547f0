"""MuJoCo scenes built from the same URDF as the core's RobotModel.

The URDF is read as text, stripped of visual and collision elements (MuJoCo cannot read the
Baxter's COLLADA meshes), and every joint outside the core's chain is made fixed at its
neutral position (0), which is how ``RobotModel`` locks them; joint damping and friction are
dropped and each chain joint's armature (``dof_armature``) is the core's
(``RobotModel.armature_kgm2``), so the engine's joint-space inertia is the core's (a test checks
it against ``pinocchio.crba``, armature included). ``mujoco.MjSpec`` then adds, by code:

- a sphere at the tip frame's origin, the only robot geometry that collides (see
  ``tip_sphere_radius_m``): a sphere centred on the tip makes the contact normal the face
  normal of whatever it hits, and every point on the line tip + λ·n has the tip's velocity
  component along n, so the contact sees the effective mass *at the tip* along n;
- the grasped object as a child body of the tip body at the grasp, with the object's exact
  mass, centre of mass and inertia tensor, and simple shapes (boxes, capsules) that do not
  collide (the paper's impacts are between the end-effector and the sensor);
- an obstacle: a flat plate whose face is perpendicular to a given direction, either mounted on
  a stiff spring along its normal (a load cell on a rigid pillar) or welded to the world.

Only this subpackage imports mujoco; the core never does.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import pinocchio as pin

from ..core.exceptions import InvalidInputError, RobotModelError
from ..core.model.description import resolve_urdf
from ..core.model.inertia import ObjectInertia
from ..core.model.robot import RobotModel

CONTACT_BIT = 2
"""Collision bit shared by the tip sphere (contype) and the obstacle (conaffinity) only."""

MOVABLE_URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "floating", "planar")


@dataclass(frozen=True)
class ContactConfig:
    """Contact between the tip sphere and the obstacle.

    Attributes:
        friction: Sliding friction coefficient; 0 gives a frictionless contact (condim 1).
        timeconst_s: MuJoCo solref time constant [s]: stiffness of the (mass-normalised)
            soft contact; must be at least 2 timesteps.
        dampratio: MuJoCo solref damping ratio (1 = critical).
        impedance: solimp d0 = dwidth: constant impedance, close to 1 = hard contact.
    """

    friction: float = 0.5
    timeconst_s: float = 3e-4
    dampratio: float = 1.0
    impedance: float = 0.99

    def __post_init__(self) -> None:
        if not (np.isfinite(self.friction) and self.friction >= 0.0):
            raise InvalidInputError("contact.friction", f"must be >= 0, got {self.friction!r}")
        if not (np.isfinite(self.timeconst_s) and self.timeconst_s > 0.0):
            raise InvalidInputError(
                "contact.timeconst_s", f"must be > 0, got {self.timeconst_s!r}"
            )
        if not (np.isfinite(self.dampratio) and self.dampratio > 0.0):
            raise InvalidInputError("contact.dampratio", f"must be > 0, got {self.dampratio!r}")
        if not (0.0 < self.impedance < 1.0):
            raise InvalidInputError(
                "contact.impedance", f"must be in (0, 1), got {self.impedance!r}"
            )


@dataclass(frozen=True)
class SensorConfig:
    """Force sensor plate on the pillar: a plate on a slide joint along its normal.

    The sensor reading is the spring + damper force that the plate transmits to the pillar,
    i.e. what a load cell between them measures. ``stiffness_n_m = None`` welds the plate to
    the pillar (a rigid obstacle; the reading is then the contact normal force).

    Attributes:
        stiffness_n_m: Load-cell stiffness [N/m], or None for a rigid plate.
        damping_n_s_m: Load-cell damping [N s/m].
        plate_mass_kg: Mass of the moving plate [kg].
        plate_half_size_m: Half edge of the square plate face [m].
        plate_half_thickness_m: Half thickness of the plate [m].
    """

    stiffness_n_m: float | None = 2.0e5
    damping_n_s_m: float = 80.0
    plate_mass_kg: float = 0.2
    plate_half_size_m: float = 0.1
    plate_half_thickness_m: float = 0.005

    def __post_init__(self) -> None:
        if self.stiffness_n_m is not None and not (
            np.isfinite(self.stiffness_n_m) and self.stiffness_n_m > 0.0
        ):
            raise InvalidInputError(
                "sensor.stiffness_n_m", f"must be > 0 or None, got {self.stiffness_n_m!r}"
            )
        for name in ("damping_n_s_m", "plate_mass_kg", "plate_half_size_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise InvalidInputError(f"sensor.{name}", f"must be >= 0, got {value!r}")
        if self.plate_mass_kg <= 0.0 or self.plate_half_thickness_m <= 0.0:
            raise InvalidInputError(
                "sensor.plate_mass_kg", "plate mass and half thickness must be > 0"
            )


def arm_urdf_for_mujoco(robot: RobotModel, urdf_source: str) -> str:
    """The URDF text with meshes stripped and every joint off the robot's chain fixed.

    Args:
        robot: The core's chain model; its chain joints stay movable, every other movable
            joint becomes fixed at position 0 (Pinocchio's neutral, which RobotModel locks).
        urdf_source: The same description RobotModel was built from (see resolve_urdf).
    """
    text, is_xml = resolve_urdf(urdf_source)
    try:
        root = ET.fromstring(text) if is_xml else ET.parse(text).getroot()
    except ET.ParseError as error:
        raise InvalidInputError("robot.urdf", f"cannot parse URDF XML: {error}") from None
    chain = set(robot.joint_names)
    found = set()
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
    for joint in root.iter("joint"):
        name = joint.get("name", "")
        kind = joint.get("type", "")
        if name in chain:
            found.add(name)
            if kind == "continuous":
                raise RobotModelError(
                    f"chain joint '{name}' is continuous; the MuJoCo validation supports "
                    "revolute and prismatic chain joints only"
                )
        elif kind in MOVABLE_URDF_JOINT_TYPES:
            joint.set("type", "fixed")
            for tag in ("limit", "mimic", "axis", "safety_controller", "calibration"):
                for element in joint.findall(tag):
                    joint.remove(element)
        for element in joint.findall("dynamics"):  # no damping or friction: rigid-body model
            joint.remove(element)
    missing = chain - found
    if missing:
        raise RobotModelError(f"chain joints {sorted(missing)} are not joints of the URDF")
    for element in root.findall("mujoco"):
        root.remove(element)
    extension = ET.SubElement(root, "mujoco")
    ET.SubElement(
        extension,
        "compiler",
        discardvisual="true",
        fusestatic="false",
        balanceinertia="false",
        strippath="true",
    )
    return ET.tostring(root, encoding="unicode")


def _quat_wxyz(rotation: np.ndarray) -> np.ndarray:
    quat = pin.Quaternion(np.asarray(rotation, dtype=float))
    return np.array([quat.w, quat.x, quat.y, quat.z])


def rotation_z_onto(direction: Sequence[float] | np.ndarray) -> np.ndarray:
    """A rotation matrix whose z axis is the unit vector along ``direction``."""
    unit = np.asarray(direction, dtype=float)
    unit = unit / np.linalg.norm(unit)
    quat = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), unit)
    rotation: np.ndarray = quat.toRotationMatrix()
    return rotation


@dataclass(frozen=True)
class ObjectShape:
    """Simple, non-colliding shapes of the grasped object, in the object frame.

    Attributes:
        boxes: (centre [m], half sizes [m]) per box.
        capsules: (from [m], to [m], radius [m]) per capsule.
    """

    boxes: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = ()
    capsules: tuple[tuple[tuple[float, float, float], tuple[float, float, float], float], ...] = ()


def add_object(
    spec: mujoco.MjSpec,
    tip_body_name: str,
    object_inertia: ObjectInertia,
    transform_tip_to_object: pin.SE3,
    shape: ObjectShape | None = None,
) -> mujoco.MjsBody:
    """Attach the object rigidly to the tip body at the grasp, with its exact inertia."""
    tip = spec.body(tip_body_name)
    if tip is None:
        raise RobotModelError(f"no body '{tip_body_name}' in the MuJoCo model")
    transform_object_to_tip = pin.SE3(transform_tip_to_object).inverse()
    body = tip.add_body(name="grasped_object")
    body.pos = transform_object_to_tip.translation
    body.quat = _quat_wxyz(transform_object_to_tip.rotation)
    body.explicitinertial = True
    body.mass = object_inertia.mass_kg
    body.ipos = np.array(object_inertia.com_in_object_m)
    tensor = np.array(object_inertia.inertia_about_com_kgm2)
    body.fullinertia = [
        tensor[0, 0],
        tensor[1, 1],
        tensor[2, 2],
        tensor[0, 1],
        tensor[0, 2],
        tensor[1, 2],
    ]
    for centre, half in (shape or ObjectShape()).boxes:
        body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=centre,
            size=half,
            contype=0,
            conaffinity=0,
            density=0.0,
            rgba=[0.2, 0.4, 0.8, 1.0],
        )
    for start, end, radius in (shape or ObjectShape()).capsules:
        body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[*start, *end],
            size=[radius, 0.0, 0.0],
            contype=0,
            conaffinity=0,
            density=0.0,
            rgba=[0.8, 0.4, 0.2, 1.0],
        )
    return body


def add_tip_sphere(
    spec: mujoco.MjSpec, tip_body_name: str, radius_m: float, contact: ContactConfig
) -> mujoco.MjsGeom:
    """The colliding sphere centred on the tip frame (massless)."""
    geom = spec.body(tip_body_name).add_geom(
        name="tip_sphere",
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[radius_m, 0.0, 0.0],
        contype=CONTACT_BIT,
        conaffinity=0,
        density=0.0,
        rgba=[0.9, 0.1, 0.1, 1.0],
    )
    _set_contact(geom, contact)
    return geom


def _set_contact(geom: mujoco.MjsGeom, contact: ContactConfig) -> None:
    geom.condim = 1 if contact.friction == 0.0 else 3
    geom.friction = [max(contact.friction, 0.0), 0.005, 0.0001]
    geom.solref = [contact.timeconst_s, contact.dampratio]
    geom.solimp = [contact.impedance, contact.impedance, 0.001, 0.5, 2.0]


def add_obstacle(
    spec: mujoco.MjSpec,
    face_centre_in_world_m: np.ndarray,
    approach_direction_in_world: np.ndarray,
    contact: ContactConfig,
    sensor: SensorConfig,
) -> None:
    """A plate whose face (centre given) is perpendicular to the approach direction u.

    The plate body's z axis is u (pointing into the pillar); its origin is the face centre.
    With a sensor stiffness, the plate slides along z on a spring-damper (joint
    ``sensor_slide``, positive = compressed); otherwise it is welded to the world.
    """
    rotation = rotation_z_onto(approach_direction_in_world)
    pillar = spec.worldbody.add_body(
        name="pillar", pos=np.asarray(face_centre_in_world_m, dtype=float)
    )
    pillar.quat = _quat_wxyz(rotation)
    plate = pillar.add_body(name="sensor_plate")
    if sensor.stiffness_n_m is not None:
        plate.add_joint(
            name="sensor_slide",
            type=mujoco.mjtJoint.mjJNT_SLIDE,
            axis=[0.0, 0.0, 1.0],
            stiffness=[sensor.stiffness_n_m, 0.0, 0.0],
            damping=[sensor.damping_n_s_m, 0.0, 0.0],
            springref=0.0,
        )
    half = sensor.plate_half_size_m
    thickness = sensor.plate_half_thickness_m
    plate.explicitinertial = True
    plate.mass = sensor.plate_mass_kg
    plate.ipos = [0.0, 0.0, thickness]
    side = sensor.plate_mass_kg * (half**2 + thickness**2) / 3.0
    plate.inertia = [side, side, 2.0 * sensor.plate_mass_kg * half**2 / 3.0]
    geom = plate.add_geom(
        name="sensor_face",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        pos=[0.0, 0.0, thickness],
        size=[half, half, thickness],
        contype=0,
        conaffinity=CONTACT_BIT,
        density=0.0,
        rgba=[0.8, 0.1, 0.1, 1.0],
    )
    _set_contact(geom, contact)


def base_spec(
    robot: RobotModel,
    urdf_source: str,
    timestep_s: float,
    gravity: bool = True,
) -> mujoco.MjSpec:
    """The robot alone: URDF without meshes, only the chain joints movable, fixed base, the
    chain joints' armature the core's."""
    spec = mujoco.MjSpec.from_string(arm_urdf_for_mujoco(robot, urdf_source))
    for name, armature in zip(robot.joint_names, robot.armature_kgm2, strict=True):
        spec.joint(name).armature = float(armature)
    spec.option.timestep = timestep_s
    spec.option.gravity = [0.0, 0.0, -9.81] if gravity else [0.0, 0.0, 0.0]
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    return spec


@dataclass
class Scene:
    """A compiled MuJoCo scene and the indices the experiments need.

    Attributes:
        model, data: The MuJoCo model and its data.
        arm_qpos, arm_dof: qpos / qvel indices of the chain joints, in the core's chain order.
        tip_body: Id of the tip body.
        sphere_geom: Id of the tip sphere (or -1).
        face_geom: Id of the obstacle face (or -1).
        sensor_dof: qvel index of the sensor slide joint (or -1).
        sensor_qpos: qpos index of the sensor slide joint (or -1).
        transform_base_to_world: The robot base pose in the MuJoCo world.
    """

    model: mujoco.MjModel
    data: mujoco.MjData
    arm_qpos: np.ndarray
    arm_dof: np.ndarray
    tip_body: int
    sphere_geom: int
    face_geom: int
    sensor_dof: int
    sensor_qpos: int
    transform_base_to_world: pin.SE3


def compile_scene(spec: mujoco.MjSpec, robot: RobotModel) -> Scene:
    """Compile a spec built by the functions above and look up the indices."""
    try:
        model = spec.compile()
    except ValueError as error:
        raise RobotModelError(f"MuJoCo cannot compile the scene: {error}") from None
    data = mujoco.MjData(model)
    arm_qpos = np.array([model.joint(name).qposadr[0] for name in robot.joint_names])
    arm_dof = np.array([model.joint(name).dofadr[0] for name in robot.joint_names])

    def lookup(kind: mujoco.mjtObj, name: str) -> int:
        return int(mujoco.mj_name2id(model, kind, name))

    sensor_joint = lookup(mujoco.mjtObj.mjOBJ_JOINT, "sensor_slide")
    return Scene(
        model=model,
        data=data,
        arm_qpos=arm_qpos,
        arm_dof=arm_dof,
        tip_body=lookup(mujoco.mjtObj.mjOBJ_BODY, robot.tip_frame),
        sphere_geom=lookup(mujoco.mjtObj.mjOBJ_GEOM, "tip_sphere"),
        face_geom=lookup(mujoco.mjtObj.mjOBJ_GEOM, "sensor_face"),
        sensor_dof=int(model.jnt_dofadr[sensor_joint]) if sensor_joint >= 0 else -1,
        sensor_qpos=int(model.jnt_qposadr[sensor_joint]) if sensor_joint >= 0 else -1,
        transform_base_to_world=pin.SE3(robot.transform_base_to_world),
    )


def joint_space_inertia(scene: Scene, positions: np.ndarray) -> np.ndarray:
    """MuJoCo's joint-space inertia of the chain joints (chain order) at chain positions."""
    model, data = scene.model, scene.data
    data.qpos[:] = model.qpos0
    data.qpos[scene.arm_qpos] = positions
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    inertia: np.ndarray = full[np.ix_(scene.arm_dof, scene.arm_dof)]
    return inertia


def tip_translational_jacobian(scene: Scene) -> np.ndarray:
    """3 x nv Jacobian of the tip body origin's velocity (world axes) at the current state."""
    jacobian = np.zeros((3, scene.model.nv))
    mujoco.mj_jacBody(scene.model, scene.data, jacobian, None, scene.tip_body)
    return jacobian


def engine_effective_mass(scene: Scene, direction_in_world: np.ndarray) -> float:
    """1 / (uᵀ J M⁻¹ Jᵀ u) from MuJoCo's own M and J at the current state [kg]."""
    unit = np.asarray(direction_in_world, dtype=float)
    unit = unit / np.linalg.norm(unit)
    row = (unit @ tip_translational_jacobian(scene)).reshape(1, -1)
    solved = np.zeros_like(row)
    mujoco.mj_solveM(scene.model, scene.data, solved, row)
    return float(1.0 / (row @ solved.T)[0, 0])
