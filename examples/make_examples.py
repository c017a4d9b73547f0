"""Write the example inputs under examples/ (committed; run again after changing this file).

- ``mjcf/arm.xml``: a 6-DOF arm in MJCF (explicit inertials, an armature per joint, a site
  ``tool`` as the tip) and ``mjcf/scenario.yaml``, a scenario ranking three grasps with it
  (docs/arms.md).
- ``dataset/``: a tiny grasp dataset for ``grasp-safety batch`` (docs/batch.md): an
  ACRONYM-format HDF5 file, a GraspGen ``isaac_grasp`` YAML file, the SPEC that labels both
  on the bundled Panda, and a SPEC that also asks for a file the batch refuses (an object
  mass without its inertia) and a glob that matches nothing.
- ``whole_arm/book.yaml``: the paper's book on Baxter (config/book_baxter.yaml) with a point
  on the forearm, three body regions, and grasps ranked (and postures chosen) by the whole
  arm's chest force (docs/whole_arm.md).

The object starts at the tip's pose at the robot's IK seed, so every grasp (a small offset
from it) is reachable. Usage, from the repository root::

    .venv/bin/python examples/make_examples.py
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import yaml

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT.parent))

from grasp_safety_ros.core import RobotModel  # noqa: E402
from grasp_safety_ros.core.input_checks import quat_xyzw_from_rotation  # noqa: E402
from grasp_safety_ros.core.model.bundled_robots import BUNDLED_ROBOTS  # noqa: E402
from grasp_safety_ros.core.model.inertia import solid_box  # noqa: E402

LINKS = (  # position in parent [m], joint axis, mass [kg], CoM [m], diagonal inertia, armature
    ((0.0, 0.0, 0.1), (0, 0, 1), 4.0, (0.0, 0.0, 0.08), (0.03, 0.03, 0.01), 0.3),
    ((0.0, 0.0, 0.15), (0, 1, 0), 3.0, (0.0, 0.0, 0.15), (0.04, 0.04, 0.008), 0.3),
    ((0.0, 0.0, 0.3), (0, 1, 0), 2.0, (0.0, 0.0, 0.12), (0.02, 0.02, 0.004), 0.15),
    ((0.0, 0.0, 0.25), (0, 0, 1), 1.0, (0.0, 0.0, 0.05), (0.004, 0.004, 0.002), 0.05),
    ((0.0, 0.0, 0.1), (0, 1, 0), 0.8, (0.0, 0.0, 0.04), (0.002, 0.002, 0.001), 0.05),
    ((0.0, 0.0, 0.08), (0, 0, 1), 0.4, (0.0, 0.0, 0.02), (0.0008, 0.0008, 0.0005), 0.02),
)
EFFORT_NM = (150, 150, 80, 30, 30, 10)
"""Each joint's torque limit [N m] (MJCF ``actuatorfrcrange``)."""
TOOL_M = (0.0, 0.0, 0.1)
"""The site ``tool`` in the last link's frame [m]."""
ARM_SEED = (0.0, 0.6, 1.2, 0.0, 0.9, 0.0)
"""IK seed of the MJCF arm [rad]: bent, the tool pointing forward and down."""
DIGITS = 4
"""Decimals of the poses written (the object's start is near, not at, the seed's tip)."""


def _vector(values: Any) -> str:
    return " ".join(f"{v:g}" for v in values)


def arm_mjcf() -> str:
    """The 6-DOF arm in MJCF (radians; each body with a joint, so the site is on one)."""
    lines = [
        '<mujoco model="example_arm">',
        '  <compiler angle="radian"/>',
        "  <worldbody>",
        '    <body name="base_link">',
        '      <inertial pos="0 0 0.05" mass="5" diaginertia="0.02 0.02 0.02"/>',
    ]
    indent = "      "
    for k, (position, axis, mass, com, inertia, armature) in enumerate(LINKS):
        lines += [
            f'{indent}<body name="link{k + 1}" pos="{_vector(position)}">',
            f'{indent}  <joint name="joint{k + 1}" type="hinge" axis="{_vector(axis)}" '
            f'range="-2.9 2.9" actuatorfrcrange="-{EFFORT_NM[k]:g} {EFFORT_NM[k]:g}" '
            f'armature="{armature:g}"/>',
            f'{indent}  <inertial pos="{_vector(com)}" mass="{mass:g}" '
            f'diaginertia="{_vector(inertia)}"/>',
        ]
        indent += "  "
    lines.append(f'{indent}<site name="tool" pos="{_vector(TOOL_M)}"/>')
    for k in range(len(LINKS), 0, -1):
        lines.append(" " * (4 + 2 * k) + "</body>")
    lines += ["    </body>", "  </worldbody>", "</mujoco>"]
    return "\n".join(lines) + "\n"


def _round(values: Any, digits: int = DIGITS) -> list[float]:
    return [round(float(x), digits) + 0.0 for x in values]  # + 0.0: no -0.0


def _pose(pose: pin.SE3) -> dict[str, list[float]]:
    return {
        "position_m": _round(pose.translation),
        "quat_xyzw": _round(quat_xyzw_from_rotation(pose.rotation)),
    }


def _flow(data: Any) -> str:
    """YAML with each pose on one line (block style for the rest)."""

    class Dumper(yaml.SafeDumper):
        pass

    def flat(value: Any) -> bool:
        return not isinstance(value, (dict, list)) or (
            isinstance(value, list) and all(not isinstance(v, (dict, list)) for v in value)
        )

    def mapping(dumper: yaml.SafeDumper, value: dict) -> Any:
        flow = all(flat(v) for v in value.values()) and len(value) <= 4
        return dumper.represent_mapping("tag:yaml.org,2002:map", value, flow_style=flow)

    def sequence(dumper: yaml.SafeDumper, value: list) -> Any:
        return dumper.represent_sequence("tag:yaml.org,2002:seq", value, flow_style=flat(value))

    Dumper.add_representer(dict, mapping)
    Dumper.add_representer(list, sequence)
    return yaml.dump(data, Dumper=Dumper, sort_keys=False, width=200)


def _tip_pose(robot: RobotModel, seed: tuple[float, ...]) -> pin.SE3:
    """The tip's pose at ``seed``, rounded as written."""
    written = _pose(robot.transform_tip_to_base(np.array(seed)))
    x, y, z, w = written["quat_xyzw"]
    rotation = pin.Quaternion(w, x, y, z).normalized().matrix()
    return pin.SE3(rotation, np.array(written["position_m"]))


def _offsets(count: int) -> list[pin.SE3]:
    """Grasps T_object_tip a little off the identity: turns about the tip's z, shifts in x."""
    return [
        pin.SE3(pin.exp3(np.array([0.0, 0.0, 0.4 * k - 0.6])), np.array([0.02 * k - 0.03, 0, 0]))
        for k in range(count)
    ]


def mjcf_scenario(start: pin.SE3) -> dict[str, Any]:
    lift = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.15]))
    return {
        "robot": {
            "urdf": "arm.xml",
            "base_frame": "base_link",
            "tip_frame": "tool",
            "seed": list(ARM_SEED),
        },
        "object": {"mass_kg": 0.5, "box_size_m": [0.08, 0.08, 0.12]},
        "trajectory": {
            "start": _pose(start),
            "goal": _pose(lift * start),
            "duration_s": 1.0,
            "dt_s": 0.05,
        },
        "grasps": [{"name": f"turn_{k}", **_pose(offset)} for k, offset in enumerate(_offsets(3))],
        "metric": "mean",
    }


BOX = solid_box(0.3, [0.06, 0.06, 0.1])
"""The dataset's object (its inertia is in the ACRONYM file)."""


def _write_acronym(path: Path, grippers: list[pin.SE3], with_inertia: bool = True) -> None:
    import h5py

    path.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(path, "w") as h5:
        h5["grasps/transforms"] = np.array([g.homogeneous for g in grippers])
        h5["grasps/qualities/flex/object_in_gripper"] = np.arange(len(grippers)) % 2
        h5["object/file"] = "meshes/box.obj"
        h5["object/scale"] = 1.0
        h5["object/mass"] = BOX.mass_kg
        h5["object/com"] = BOX.com_in_object_m
        if with_inertia:
            h5["object/inertia"] = BOX.inertia_about_com_kgm2


def _graspgen(grippers: list[pin.SE3]) -> dict[str, Any]:
    grasps = {}
    for k, gripper in enumerate(grippers):
        x, y, z, w = _round(quat_xyzw_from_rotation(gripper.rotation), 6)
        grasps[f"grasp_{k}"] = {
            "confidence": round(0.9 - 0.1 * k, 2),
            "position": _round(gripper.translation, 6),
            "orientation": {"w": w, "xyz": [x, y, z]},
        }
    return {"format": "isaac_grasp", "format_version": 1.0, "grasps": grasps}


def dataset_spec(start: pin.SE3, sources: list[dict[str, str]]) -> dict[str, Any]:
    panda = next(robot for robot in BUNDLED_ROBOTS if robot.name == "panda")
    return {
        "robot": {
            "urdf": panda.urdf,
            "base_frame": panda.base_frame,
            "tip_frame": panda.tip_frame,
            "seed": list(panda.seed),
        },
        "gripper_to_tip": {"position_m": [0, 0, 0], "quat_xyzw": [0, 0, 0, 1]},
        "object_start_in_base": _pose(start),
        "motion": {
            "waypoints": [
                {"time_s": 0.0, "position_m": [0, 0, 0], "quat_xyzw": [0, 0, 0, 1]},
                {"time_s": 0.5, "position_m": [0, 0, 0.1], "quat_xyzw": [0, 0, 0, 1]},
            ],
            "dt_s": 0.05,
        },
        "object": {"mass_kg": 0.3, "box_size_m": [0.06, 0.06, 0.1]},
        "metric": "mean",
        "posture": {"restarts": 0},
        "chunk_grasps": 4,
        "sources": sources,
    }


def whole_arm_book() -> dict[str, Any]:
    """The bundled book scenario, ranked by the whole arm."""
    book = yaml.safe_load((ROOT.parent / "config" / "book_baxter.yaml").read_text())
    book["robot"]["exposed_points_m"] = {"right_lower_forearm": [[0.0, 0.0, 0.1]]}
    book["iso_ts_15066"] = {"regions": ["chest", "upper_arm_elbow", "hand_fingers"]}
    book["whole_arm"] = {"enabled": True, "region": "chest"}
    book["rank_by"] = "whole_arm"
    return book


def write_examples(root: Path = ROOT) -> list[Path]:
    """Write every example below ``root``; the paths written."""
    written = []

    def text(relative: str, content: str) -> None:
        path = root / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(content)
        written.append(path)

    text("mjcf/arm.xml", arm_mjcf())
    arm = RobotModel.from_urdf(str(root / "mjcf" / "arm.xml"), "base_link", "tool")
    header = "# Written by examples/make_examples.py.\n"
    text("mjcf/scenario.yaml", header + _flow(mjcf_scenario(_tip_pose(arm, ARM_SEED))))
    panda = next(robot for robot in BUNDLED_ROBOTS if robot.name == "panda")
    panda_model = RobotModel.from_urdf(panda.urdf, panda.base_frame, panda.tip_frame)
    start = _tip_pose(panda_model, panda.seed)
    grippers = _offsets(6)  # T_object_gripper; the gripper is the tip (gripper_to_tip identity)
    _write_acronym(root / "dataset" / "acronym" / "box.h5", grippers)
    written.append(root / "dataset" / "acronym" / "box.h5")
    _write_acronym(root / "dataset" / "refused" / "mass_only.h5", grippers[:2], False)
    written.append(root / "dataset" / "refused" / "mass_only.h5")
    text("dataset/graspgen/box.yaml", header + _flow(_graspgen(grippers[:4])))
    sources = [
        {"format": "acronym", "path": "acronym/*.h5"},
        {"format": "graspgen", "path": "graspgen/*.yaml"},
    ]
    text("dataset/spec.yaml", header + _flow(dataset_spec(start, sources)))
    refused = [*sources, {"format": "acronym", "path": "refused/*.h5"}]
    refused.append({"format": "graspgen", "path": "missing/*.yaml"})
    text("dataset/spec_refused.yaml", header + _flow(dataset_spec(start, refused)))
    text("whole_arm/book.yaml", header + _flow(whole_arm_book()))
    return written


if __name__ == "__main__":
    for path in write_examples():
        print(f"wrote {path.relative_to(ROOT.parent)}")
