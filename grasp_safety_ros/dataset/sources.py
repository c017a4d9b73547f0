"""Grasp dataset readers: ACRONYM HDF5, GraspGen ``isaac_grasp`` YAML, scenario files.

``discover`` finds and checks the files of a SPEC (a bad file becomes a Failure naming the
file and the key, the others go on); ``load_block`` reads grasps [start, stop) of one file
as a Scenario of the valid grasps plus the dataset's labels and each bad grasp's error.
"""

from __future__ import annotations

import functools
import glob
import hashlib
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from ..core.exceptions import GraspSafetyError, InvalidInputError, field_and_reason
from ..core.input_checks import finite_array, finite_float, pose_from_position_quat
from ..core.method.ranking import Grasp
from ..core.model.inertia import ObjectInertia
from ..scenario.fields import load_yaml, mapping
from ..scenario.schema import MAX_OBJECT_MASS_KG, Scenario, load_scenario
from .spec import BatchSpec

if TYPE_CHECKING:
    import h5py  # imported when an ACRONYM file is read

MAX_YAML_SOURCE_BYTES = 256_000_000
"""Largest GraspGen YAML file read [bytes]."""

RIGID_TOLERANCE = 1e-6
"""Largest |RᵀR − I|, |det R − 1| and bottom-row deviation of an ACRONYM transform."""

LABELS = {
    "acronym": "label_object_in_gripper",
    "graspgen": "label_confidence",
    "scenarios": "label_quality",
}
"""The column of each format's own grasp label."""


@dataclass(frozen=True)
class Failure:
    """An input that could not be used: the file, the key in it, and why."""

    file: str
    key: str
    reason: str


@dataclass(frozen=True)
class SourceFile:
    """One checked input file.

    Attributes:
        name: Path relative to the SPEC's folder (POSIX), as written in the output.
        sha256: Hash of the file's bytes (part of each chunk's content hash).
    """

    format: str
    path: Path
    name: str
    sha256: str
    num_grasps: int


@dataclass(frozen=True)
class GraspBlock:
    """Grasps [start, start + len(grasp_ids)) of one file.

    Attributes:
        grasp_ids: Each grasp's id in the file (ACRONYM: its index; GraspGen, scenarios: name).
        labels: The dataset's own label per grasp (None where absent).
        errors: (key, reason) of each grasp that could not be read, None for the others.
        scenario: The valid grasps, in file order, with robot, object and motion; None when
            no grasp is valid.
        object_file, object_scale: ACRONYM's mesh file and scale; None otherwise.
    """

    source: SourceFile
    start: int
    grasp_ids: tuple[str, ...]
    labels: tuple[float | None, ...]
    errors: tuple[tuple[str, str] | None, ...]
    scenario: Scenario | None
    object_file: str | None = None
    object_scale: float | None = None


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def discover(spec: BatchSpec) -> tuple[list[SourceFile], list[Failure]]:
    """The SPEC's source files in order (sources in SPEC order, each glob sorted), checked;
    the files that fail and the globs that match nothing as Failures."""
    files: list[SourceFile] = []
    failures: list[Failure] = []
    for i, source in enumerate(spec.sources):
        pattern = str(spec.base_dir / source.pattern)
        matches = sorted(p for p in glob.glob(pattern, recursive=True) if Path(p).is_file())
        if not matches:
            failures.append(Failure(source.pattern, f"sources[{i}].path", "matches no file"))
        for match in matches:
            path = Path(match)
            name = Path(os.path.relpath(path.resolve(), spec.base_dir)).as_posix()
            try:
                count = _count_grasps(spec, source.format, path)
                files.append(SourceFile(source.format, path, name, _sha256(path), count))
            except GraspSafetyError as error:
                failures.append(Failure(name, *field_and_reason(error)))
            except OSError as error:
                failures.append(Failure(name, "/", f"cannot read: {error.strerror or error}"))
    return files, failures


def _count_grasps(spec: BatchSpec, fmt: str, path: Path) -> int:
    """Number of grasps in a file, after the file-level checks (readable, keys, inertia)."""
    if fmt == "acronym":
        with _open_hdf5(path) as h5:
            _acronym_inertia(h5, spec)
            return len(_acronym_transforms(h5))
    if fmt == "graspgen":
        return len(_graspgen_grasps(path, _sha256(path)))
    return len(_scenario(path, _sha256(path)).grasps)


def load_block(spec: BatchSpec, source: SourceFile, start: int, stop: int) -> GraspBlock:
    """Read grasps [start, stop) of ``source`` (file-level errors raise InvalidInputError
    naming the key)."""
    if source.format == "acronym":
        return _acronym_block(spec, source, start, stop)
    if source.format == "graspgen":
        return _graspgen_block(spec, source, start, stop)
    return _scenario_block(source, start, stop)


def _dataset_scenario(spec: BatchSpec, inertia: ObjectInertia, grasps: list[Grasp]) -> Scenario:
    """The scenario of a dataset's grasps: the SPEC's robot and motion (parse_spec requires
    both when an ACRONYM or GraspGen source is given)."""
    if spec.robot is None or spec.trajectory is None:
        raise InvalidInputError("robot", "and motion are required by acronym and graspgen sources")
    return Scenario(
        robot=spec.robot,
        object_inertia=inertia,
        trajectory=spec.trajectory,
        grasps=tuple(grasps),
        metric=spec.metric,
        base_dir=spec.base_dir,
        options=spec.options,
        posture=spec.posture,
        ik=spec.ik,
    )


def _block(
    spec: BatchSpec,
    source: SourceFile,
    start: int,
    inertia: ObjectInertia,
    entries: list[tuple[str, pin.SE3 | None, str, str]],
    labels: list[float | None],
    **extra: Any,
) -> GraspBlock:
    """A block from (grasp id, T_object_gripper or None, error key, error reason) entries."""
    grasps = [
        Grasp(pose * spec.transform_tip_to_gripper, grasp_id)
        for grasp_id, pose, _, _ in entries
        if pose is not None
    ]
    return GraspBlock(
        source=source,
        start=start,
        grasp_ids=tuple(e[0] for e in entries),
        labels=tuple(labels),
        errors=tuple(None if e[1] is not None else (e[2], e[3]) for e in entries),
        scenario=_dataset_scenario(spec, inertia, grasps) if grasps else None,
        **extra,
    )


# ACRONYM -----------------------------------------------------------------------------------


def _open_hdf5(path: Path) -> h5py.File:
    import h5py

    try:
        return h5py.File(path, "r")
    except OSError as error:
        raise InvalidInputError("/", f"not a readable HDF5 file: {error}") from None


def _acronym_transforms(h5: h5py.File) -> h5py.Dataset:
    if "grasps/transforms" not in h5:
        raise InvalidInputError("grasps/transforms", "is required (N x 4 x 4 gripper poses)")
    transforms = h5["grasps/transforms"]
    if transforms.ndim != 3 or transforms.shape[1:] != (4, 4):
        raise InvalidInputError(
            "grasps/transforms", f"must have shape [N, 4, 4], got {list(transforms.shape)}"
        )
    return transforms


def _acronym_inertia(h5: h5py.File, spec: BatchSpec) -> ObjectInertia:
    """The file's object/mass and object/inertia (about the CoM; both or neither) and
    object/com (default the origin); the SPEC's object where the file has none of the three;
    neither: refused naming object/mass. A mass alone does not say how it is distributed, and
    the SPEC's shape is not the file's object: refused naming object/inertia."""
    if "object/mass" not in h5:
        given = [key for key in ("object/inertia", "object/com") if key in h5]
        if given:
            raise InvalidInputError("object/mass", f"is required when {given[0]} is given")
        if spec.object_defaults is None:
            raise InvalidInputError(
                "object/mass", "is missing and the SPEC gives no object defaults"
            )
        return spec.object_defaults
    mass = finite_float(
        h5["object/mass"][()], "object/mass", 0.0, MAX_OBJECT_MASS_KG, strict_minimum=True
    )
    if "object/inertia" not in h5:
        raise InvalidInputError("object/inertia", "is required when object/mass is given")
    com = h5["object/com"][()] if "object/com" in h5 else np.zeros(3)
    com = finite_array(com, "object/com", (3,))
    tensor = finite_array(h5["object/inertia"][()], "object/inertia", (3, 3))
    try:
        return ObjectInertia(mass, com, tensor)
    except InvalidInputError as error:
        raise InvalidInputError("object/inertia", error.reason) from None


def _acronym_pose(matrix: np.ndarray, key: str) -> pin.SE3:
    """A 4 x 4 gripper pose checked to be a rigid transform."""
    if not np.all(np.isfinite(matrix)):
        raise InvalidInputError(key, "must be finite")
    rotation = matrix[:3, :3]
    errors = (
        float(np.max(np.abs(rotation.T @ rotation - np.eye(3)))),
        abs(float(np.linalg.det(rotation)) - 1.0),
        float(np.max(np.abs(matrix[3] - [0.0, 0.0, 0.0, 1.0]))),
    )
    if max(errors) > RIGID_TOLERANCE:
        raise InvalidInputError(
            key, f"must be a rigid transform (rotation, bottom row 0 0 0 1) to {RIGID_TOLERANCE:g}"
        )
    return pin.SE3(np.array(rotation), np.array(matrix[:3, 3]))


def _acronym_block(spec: BatchSpec, source: SourceFile, start: int, stop: int) -> GraspBlock:
    with _open_hdf5(source.path) as h5:
        inertia = _acronym_inertia(h5, spec)
        matrices = np.asarray(_acronym_transforms(h5)[start:stop], dtype=float)
        label_key = "grasps/qualities/flex/object_in_gripper"
        labels: list[float | None] = (
            [float(v) for v in np.asarray(h5[label_key][start:stop]).ravel()]
            if label_key in h5
            else [None] * len(matrices)
        )
        object_file = h5["object/file"][()] if "object/file" in h5 else None
        if isinstance(object_file, bytes):
            object_file = object_file.decode("utf-8", "replace")
        scale = float(h5["object/scale"][()]) if "object/scale" in h5 else None
    entries = []
    for k, matrix in enumerate(matrices):
        key = f"grasps/transforms[{start + k}]"
        try:
            entries.append((str(start + k), _acronym_pose(matrix, key), "", ""))
        except InvalidInputError as error:
            entries.append((str(start + k), None, error.field, error.reason))
    extra = {"object_file": None if object_file is None else str(object_file)}
    return _block(spec, source, start, inertia, entries, labels, object_scale=scale, **extra)


# GraspGen ----------------------------------------------------------------------------------


@functools.lru_cache(maxsize=4)
def _graspgen_grasps(path: Path, sha256: str) -> tuple[tuple[str, Any], ...]:
    """The (name, entry) pairs of an isaac_grasp file, in file order (cached per content)."""
    del sha256  # the cache key: a changed file is read again
    with path.open("rb") as stream:
        raw = stream.read(MAX_YAML_SOURCE_BYTES + 1)
    if len(raw) > MAX_YAML_SOURCE_BYTES:
        raise InvalidInputError("/", f"larger than {MAX_YAML_SOURCE_BYTES} bytes, the limit")
    try:
        data = load_yaml(raw.decode("utf-8"), f"'{path.name}'")
    except UnicodeDecodeError as error:
        raise InvalidInputError("/", f"not UTF-8 text (byte {error.start})") from None
    except InvalidInputError as error:
        raise InvalidInputError("/", error.reason) from None
    root = mapping(data, "/")
    if root.get("format") != "isaac_grasp":
        raise InvalidInputError("format", f"must be isaac_grasp, got {root.get('format')!r}")
    grasps = root.get("grasps")
    if not isinstance(grasps, dict) or not grasps:
        raise InvalidInputError("grasps", "must be a non-empty mapping of name -> grasp")
    return tuple((str(name), entry) for name, entry in grasps.items())


def _graspgen_pose(entry: Any, key: str) -> tuple[pin.SE3, float | None]:
    grasp = mapping(entry, key)
    orientation = mapping(grasp.get("orientation"), f"{key}.orientation")
    xyz = finite_array(orientation.get("xyz"), f"{key}.orientation.xyz", (3,))
    w = finite_float(orientation.get("w"), f"{key}.orientation.w")
    position: Any = grasp.get("position")  # checked by pose_from_position_quat
    pose = pose_from_position_quat(position, [*xyz, w], key)
    confidence = grasp.get("confidence")
    return pose, None if confidence is None else finite_float(confidence, f"{key}.confidence")


def _graspgen_block(spec: BatchSpec, source: SourceFile, start: int, stop: int) -> GraspBlock:
    entries, labels = [], []
    for name, entry in _graspgen_grasps(source.path, source.sha256)[start:stop]:
        try:
            pose, confidence = _graspgen_pose(entry, f"grasps.{name}")
            entries.append((name, pose, "", ""))
            labels.append(confidence)
        except InvalidInputError as error:
            field = error.field.replace(".quat_xyzw", ".orientation")
            field = field.replace(".position_m", ".position")
            entries.append((name, None, field, error.reason))
            labels.append(None)
    if spec.object_defaults is None:  # parse_spec requires it for graspgen sources
        raise InvalidInputError("object", "is required for graspgen sources (they carry no mass)")
    return _block(spec, source, start, spec.object_defaults, entries, labels)


# Scenario files ----------------------------------------------------------------------------


@functools.lru_cache(maxsize=4)
def _scenario(path: Path, sha256: str) -> Scenario:
    del sha256  # the cache key: a changed file is read again
    return load_scenario(path)


def scenario_of(source: SourceFile) -> Scenario:
    """The scenario of a scenario-format source file (parsed once per content)."""
    return _scenario(source.path, source.sha256)


def _scenario_block(source: SourceFile, start: int, stop: int) -> GraspBlock:
    scenario = _scenario(source.path, source.sha256)
    quality = scenario.options.grasp_quality
    options = replace(
        scenario.options,
        uncertainty=None,  # over the whole candidate set: no per-grasp column
        grasp_quality=None if quality is None else quality[start:stop],
    )
    grasps = scenario.grasps[start:stop]
    return GraspBlock(
        source=source,
        start=start,
        grasp_ids=tuple(g.name for g in grasps),
        labels=tuple(quality[start:stop]) if quality is not None else (None,) * len(grasps),
        errors=(None,) * len(grasps),
        scenario=replace(scenario, grasps=grasps, options=options),
    )
