"""Robot descriptions: URDF and MJCF files or text, ``example-robot-data:<name>``, read into a
full Pinocchio model (``robot.RobotModel`` cuts a chain out of it)."""

from __future__ import annotations

import contextlib
import difflib
import functools
import importlib.metadata
import os
import re
import sys
import tempfile
import threading
import xml.etree.ElementTree as ElementTree
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import pinocchio as pin

from ..exceptions import InvalidInputError
from .bundled_robots import BUNDLED_ROBOTS, EXAMPLE_ROBOT_DATA_PREFIX
from .mjcf_frames import place_frames_as_mujoco

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

MAX_URDF_BYTES = 16_000_000
"""Largest robot description accepted (file or XML text) [bytes]."""


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


@functools.lru_cache(maxsize=4)
def _urdfs_in(folder: Path) -> tuple[str, ...]:
    """Paths of the ``*.urdf`` files under ``folder``, relative to it, sorted."""
    return tuple(sorted(str(path.relative_to(folder)) for path in folder.rglob("*.urdf")))


def example_robot_data_names() -> dict[str, str]:
    """Every name ``example-robot-data:<name>`` accepts, with its URDF path relative to the
    ``robots/`` folder: the names of EXAMPLE_ROBOT_DATA_URDFS, then the file name (without
    ``.urdf``) of every URDF of the installed data that no other URDF shares."""
    names = dict(EXAMPLE_ROBOT_DATA_URDFS)
    stems: dict[str, list[str]] = {}
    for folder in example_robot_data_dirs():
        for relative in _urdfs_in(folder):
            stems.setdefault(Path(relative).stem, []).append(relative)
    for stem, paths in sorted(stems.items()):
        if len(set(paths)) == 1:
            names.setdefault(stem, paths[0])
    return names


def example_robot_data_urdf(name: str) -> Path:
    """The URDF file of ``example-robot-data:<name>``: a name of example_robot_data_names or a
    path relative to the ``robots/`` folder (e.g. ``talos_data/robots/talos_left_arm.urdf``).

    Raises:
        InvalidInputError: no such robot; the message says the closest names and the path form.
    """
    folders = example_robot_data_dirs()
    # a name of EXAMPLE_ROBOT_DATA_URDFS wins over every other (example_robot_data_names): no
    # need to list the installed URDFs (a walk of example-robot-data's tree, 5-25 ms of a
    # command's start-up); the other names (tiago, pr2, ...) still walk it
    relative = EXAMPLE_ROBOT_DATA_URDFS.get(name)
    names = {name: relative} if relative else example_robot_data_names()
    for folder in folders:
        candidate = folder / names.get(name, name)
        if candidate.is_file():
            return candidate
    names = example_robot_data_names()
    if not folders:
        raise InvalidInputError(
            "robot.urdf",
            f"example-robot-data robot '{name}' not found: example-robot-data is not installed "
            "(pip install example-robot-data)",
        )
    shared = sorted(
        {rel for folder in folders for rel in _urdfs_in(folder) if Path(rel).stem == name}
    )
    if shared:
        forms = " or ".join(f"'{EXAMPLE_ROBOT_DATA_PREFIX}{rel}'" for rel in shared)
        raise InvalidInputError(
            "robot.urdf",
            f"example-robot-data robot '{name}' names {len(shared)} URDFs; give the path form: "
            f"{forms}",
        )
    close = difflib.get_close_matches(name, list(names), n=3, cutoff=0.5)
    hint = f"did you mean {' or '.join(repr(n) for n in close)}? " if close else ""
    raise InvalidInputError(
        "robot.urdf",
        f"example-robot-data robot '{name}' not found; {hint}bundled names: "
        f"{', '.join(robot.name for robot in BUNDLED_ROBOTS)}; `grasp-safety robots` lists "
        f"every name; or give a path relative to {folders[0]}: "
        f"'{EXAMPLE_ROBOT_DATA_PREFIX}<path>'",
    )


def resolve_urdf(source: str, relative_to: Path | None = None) -> tuple[str, bool]:
    """Resolve a robot description to (text, is_xml).

    Args:
        source: URDF XML, a path to a URDF file, or ``example-robot-data:<name>`` with a
            name from example_robot_data_names or a path relative to the ``robots/`` folder.
        relative_to: Folder that relative file paths are taken from.

    Returns:
        The XML text or the file path, and whether it is XML text.
    """
    text = source.strip()
    if len(text) > MAX_URDF_BYTES:
        raise InvalidInputError(
            "robot.urdf", f"has {len(text)} characters; at most {MAX_URDF_BYTES} are allowed"
        )
    if text.startswith("<"):
        return text, True
    if text.startswith(EXAMPLE_ROBOT_DATA_PREFIX):
        return str(example_robot_data_urdf(text[len(EXAMPLE_ROBOT_DATA_PREFIX) :])), False
    path = Path(text).expanduser()
    if relative_to is not None and not path.is_absolute():
        path = relative_to / path
    try:
        is_file = path.is_file()
    except (OSError, ValueError):  # a name too long, or with a NUL byte
        is_file = False
    if not is_file:
        shown = str(path) if len(str(path)) <= 200 else f"{str(path)[:197]}..."
        raise InvalidInputError(
            "robot.urdf",
            f"no URDF file at {shown!r}; give a file path, URDF XML or "
            f"'{EXAMPLE_ROBOT_DATA_PREFIX}<name>'",
        )
    if path.stat().st_size > MAX_URDF_BYTES:
        raise InvalidInputError(
            "robot.urdf",
            f"'{path}' has {path.stat().st_size} bytes; at most {MAX_URDF_BYTES} are allowed",
        )
    return str(path), False


_NATIVE_STDERR_LOCK = threading.Lock()


@contextlib.contextmanager
def _native_stderr_captured(captured: list[str]) -> Iterator[None]:
    """Capture what native code (urdfdom's console_bridge) writes to file descriptor 2; the
    text is appended to ``captured`` on exit."""
    with _NATIVE_STDERR_LOCK, tempfile.TemporaryFile() as sink:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(sink.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            captured.append(sink.read().decode("utf-8", errors="replace"))


def _urdf_parser_errors(output: str) -> tuple[list[str], str]:
    """Split urdfdom's output into its error messages and the other lines (kept as text)."""
    errors, other = [], []
    lines = output.splitlines()
    for k, line in enumerate(lines):
        if line.startswith("Error:"):
            errors.append(" ".join(line[len("Error:") :].split()))
        elif not (
            line.startswith("         at line ") and k and lines[k - 1].startswith("Error:")
        ):
            other.append(line)
    return errors, "".join(f"{line}\n" for line in other)


def load_urdf_model(source: str, relative_to: Path | None = None) -> pin.Model:
    """Build the full Pinocchio model (fixed base) of a URDF given as in resolve_urdf.

    A description the URDF parser reports errors for is refused even when Pinocchio builds a
    model from it (a malformed ``<inertial>`` would otherwise become a massless link).
    """
    text, is_xml = resolve_urdf(source, relative_to)
    if is_mjcf(text, is_xml):
        return load_mjcf_model(text, is_xml)
    where = "URDF XML" if is_xml else f"'{text}'"
    captured: list[str] = []
    try:
        with _native_stderr_captured(captured):
            model = pin.buildModelFromXML(text) if is_xml else pin.buildModelFromUrdf(text)
    except (RuntimeError, ValueError) as error:
        parser_errors, other = _urdf_parser_errors("".join(captured))
        sys.stderr.write(other)
        message = " ".join(str(error).split()) or "parse error"
        details = f" ({'; '.join(parser_errors)})" if parser_errors else ""
        raise InvalidInputError("robot.urdf", f"cannot read {where}: {message}{details}") from None
    parser_errors, other = _urdf_parser_errors("".join(captured))
    sys.stderr.write(other)
    if parser_errors:
        raise InvalidInputError("robot.urdf", f"cannot read {where}: {'; '.join(parser_errors)}")
    return model


def is_mjcf(text: str, is_xml: bool) -> bool:
    """Whether a description (XML text, or a file path) is MJCF: its root element <mujoco>."""
    if not is_xml:
        try:
            with open(text, "rb") as file:
                text = file.read(4096).decode("utf-8", errors="replace")
        except OSError:
            return False
    match = re.search(
        r"<\s*([A-Za-z_][\w.-]*)", re.sub(r"<(\?|!--).*?(\?|--)>", "", text, flags=re.S)
    )
    return match is not None and match.group(1) == "mujoco"


def _mjcf_bodies_without_inertial(root: ElementTree.Element) -> list[str]:
    """Bodies whose inertia MuJoCo would compute from their geoms (no <inertial>, or
    inertiafromgeom="true"): Pinocchio's MJCF reader does not, so they are refused."""
    compiler = root.find("compiler")
    from_geom = compiler.get("inertiafromgeom", "auto") if compiler is not None else "auto"
    if from_geom == "false":
        return []
    return [
        body.get("name", "(unnamed)")
        for body in root.iter("body")
        if body.find("geom") is not None and (from_geom == "true" or body.find("inertial") is None)
    ]


def load_mjcf_model(text: str, is_xml: bool) -> pin.Model:
    """Build the Pinocchio model (fixed base) of an MJCF (MuJoCo XML) file or text with
    Pinocchio's MJCF reader; joint ``armature`` comes with it (``model.armature``).

    Meshes are not read: every body with geoms needs an explicit ``<inertial>`` (MuJoCo's
    ``mj_saveLastXML`` writes a model's compiled inertials), else it is refused. Body and site
    frames are placed where MuJoCo places them (``mjcf_frames``: Pinocchio's reader misplaces
    sites below jointless bodies).
    """
    where = "MJCF XML" if is_xml else f"'{text}'"
    try:
        root = ElementTree.fromstring(text) if is_xml else ElementTree.parse(text).getroot()
    except (ElementTree.ParseError, OSError) as error:
        raise InvalidInputError("robot.urdf", f"cannot read {where}: {error}") from None
    missing = _mjcf_bodies_without_inertial(root)
    if missing:
        raise InvalidInputError(
            "robot.urdf",
            f"MJCF bodies {', '.join(missing[:8])} have geoms but no <inertial> (or "
            "inertiafromgeom='true'): Pinocchio does not compute inertia from geoms; add "
            "<inertial> elements (mujoco's mj_saveLastXML writes them)",
        )
    try:
        if is_xml:
            with tempfile.TemporaryDirectory() as folder:
                path = Path(folder) / "robot.xml"
                path.write_text(text)
                model = pin.buildModelFromMJCF(str(path))
        else:
            model = pin.buildModelFromMJCF(text)
    except (RuntimeError, ValueError) as error:
        message = " ".join(str(error).split()) or "parse error"
        raise InvalidInputError("robot.urdf", f"cannot read {where}: {message}") from None
    place_frames_as_mujoco(model, text, is_xml)
    return model


@dataclass(frozen=True)
class MimicJoint:
    """A URDF ``<mimic>``: the joint's position is ``multiplier * leader + offset``."""

    leader: str
    multiplier: float = 1.0
    offset: float = 0.0


def load_urdf_mimic_joints(source: str, relative_to: Path | None = None) -> dict[str, MimicJoint]:
    """The ``<mimic>`` joints of a URDF given as in resolve_urdf, by follower joint name."""
    text, is_xml = resolve_urdf(source, relative_to)
    try:
        root = ElementTree.fromstring(text) if is_xml else ElementTree.parse(text).getroot()
    except (ElementTree.ParseError, OSError) as error:
        where = "URDF XML" if is_xml else f"'{text}'"
        raise InvalidInputError("robot.urdf", f"cannot read {where}: {error}") from None
    mimic_joints = {}
    for joint in root.findall("joint"):
        mimic = joint.find("mimic")
        if mimic is None:
            continue
        try:
            mimic_joints[joint.get("name", "")] = MimicJoint(
                mimic.get("joint", ""),
                float(mimic.get("multiplier", 1.0)),
                float(mimic.get("offset", 0.0)),
            )
        except ValueError:
            raise InvalidInputError(
                "robot.urdf",
                f"joint '{joint.get('name')}': <mimic> multiplier and offset must be numbers",
            ) from None
    return mimic_joints
