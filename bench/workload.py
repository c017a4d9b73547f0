"""Benchmark workloads: an arm (Panda, Baxter; Kinova with continuous joints), a box, 100 grasps
around it, a 2 s quintic trajectory."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from grasp_safety_ros.core import Grasp, ObjectInertia, ObjectTrajectory, RobotModel, solid_box
from grasp_safety_ros.core.input_checks import pose_from_position_quat

BOX_SIZE_M = (0.08, 0.12, 0.20)
"""Edges of the box along the object x, y, z axes [m]."""
BOX_MASS_KG = 0.8


@dataclass(frozen=True)
class ArmWorkload:
    """One arm with its IK seed and the object trajectory in its base frame."""

    name: str
    urdf: str
    base_frame: str
    tip_frame: str
    seed_positions: tuple[float, ...]
    start_position_m: tuple[float, float, float]
    goal_position_m: tuple[float, float, float]
    start_quat_xyzw: tuple[float, float, float, float]
    goal_quat_xyzw: tuple[float, float, float, float]
    approach_from: tuple[float, float, float]
    """Unit vector (object axes, object at start) towards which the grasp approaches come from."""

    def robot(self) -> RobotModel:
        return RobotModel.from_urdf(self.urdf, self.base_frame, self.tip_frame)

    def trajectory(self, duration_s: float = 2.0, dt_s: float = 0.01) -> ObjectTrajectory:
        return ObjectTrajectory(
            pose_from_position_quat(self.start_position_m, self.start_quat_xyzw, "start"),
            pose_from_position_quat(self.goal_position_m, self.goal_quat_xyzw, "goal"),
            duration_s,
            dt_s,
        )


_YAW_10 = (0.0, 0.0, float(np.sin(np.pi / 36)), float(np.cos(np.pi / 36)))

ARMS: dict[str, ArmWorkload] = {
    "panda": ArmWorkload(
        name="panda",
        urdf="example-robot-data:panda",
        base_frame="panda_link0",
        tip_frame="panda_hand",
        seed_positions=(0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.785),
        start_position_m=(0.5, 0.1, 0.25),
        goal_position_m=(0.5, -0.1, 0.35),
        start_quat_xyzw=(0.0, 0.0, 0.0, 1.0),
        goal_quat_xyzw=_YAW_10,
        approach_from=(0.0, 0.0, 1.0),
    ),
    "baxter": ArmWorkload(
        name="baxter",
        urdf="example-robot-data:baxter",
        base_frame="base",
        tip_frame="right_gripper",
        seed_positions=(0.0, -0.55, 0.0, 0.75, 0.0, 1.26, 0.0),
        start_position_m=(0.8, -0.3, 0.0),
        goal_position_m=(0.8, -0.45, 0.1),
        start_quat_xyzw=(0.0, 0.0, 0.0, 1.0),
        goal_quat_xyzw=_YAW_10,
        approach_from=(-0.4, 0.0, 1.0),
    ),
    # Continuous joints 1, 4 and 6 (Pinocchio's (cos, sin)): the compiled path must not fall
    # back for them. The box starts 6 cm ahead of the tip at the seed, the tip z axis
    # pointing into it.
    "kinova": ArmWorkload(
        name="kinova",
        urdf="example-robot-data:kinova",
        base_frame="j2s6s200_link_base",
        tip_frame="j2s6s200_end_effector",
        seed_positions=(0.0, 2.9, 1.3, -2.07, 1.4, 0.0),
        start_position_m=(-0.105, 0.209, 0.548),
        goal_position_m=(-0.105, 0.159, 0.588),
        start_quat_xyzw=(0.0, 0.0, 0.0, 1.0),
        goal_quat_xyzw=_YAW_10,
        approach_from=(-0.983, 0.149, -0.11),
    ),
}


def box_object() -> ObjectInertia:
    """The box, with its CoM a little off centre."""
    return solid_box(BOX_MASS_KG, BOX_SIZE_M, (0.0, 0.01, -0.02))


def grasps_around_box(approach_from: np.ndarray, count: int = 100) -> list[Grasp]:
    """``count`` deterministic grasps on the box, approaching from a cone around a direction.

    The tip z axis points into the box (approach); the tip sits 2 cm inside the face the
    approach line crosses; the roll about the approach axis and the contact point vary.
    """
    rng = np.random.default_rng(12345)
    axis = np.asarray(approach_from, dtype=float)
    axis /= np.linalg.norm(axis)
    half = 0.5 * np.asarray(BOX_SIZE_M)
    grasps = []
    for k in range(count):
        # Direction from the box towards the gripper: within 35 degrees of ``axis``.
        while True:
            direction = axis + rng.normal(scale=0.6, size=3)
            direction /= np.linalg.norm(direction)
            if direction @ axis > np.cos(np.radians(35)):
                break
        approach = -direction  # tip z axis, into the box
        offset = rng.uniform(-0.5, 0.5, 3) * half  # contact point spread over the box
        offset -= (offset @ direction) * direction
        scale = np.min(half / np.maximum(np.abs(direction), 1e-9))
        position = offset + direction * (scale - 0.02)
        helper = np.array([1.0, 0.0, 0.0]) if abs(approach[0]) < 0.9 else np.array([0, 1.0, 0])
        x_axis = np.cross(helper, approach)
        x_axis /= np.linalg.norm(x_axis)
        y_axis = np.cross(approach, x_axis)
        roll = rng.uniform(-np.pi / 2, np.pi / 2)
        rotation = np.column_stack([x_axis, y_axis, approach]) @ pin.rpy.rpyToMatrix(0, 0, roll)
        grasps.append(Grasp(pin.SE3(rotation, position), f"grasp_{k:03d}"))
    return grasps
