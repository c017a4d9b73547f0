"""Armature (reflected rotor inertia) input: values, ranges and the published table.

A scenario gives ``robot.armature_kgm2`` as a list in chain joint order or a mapping
``{joint_name: value}``; each value is a number or a range ``[lo, hi]`` [kg m^2, kg for a
prismatic joint]; or ``published`` (``published:<entry>``) for the values of
``data/armature_published.yaml``. With ranges, the chain takes the upper ends (the effective
mass grows with the armature, so this is the conservative end) and the uncertainty analysis
reports the effective mass at both ends (``ArmatureRange``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from importlib import resources
from typing import Any

import numpy as np
import yaml

from ..exceptions import InvalidInputError
from .robot import ARMATURE_FIELD, armature_from_input

PUBLISHED = "published"
"""The ``robot.armature_kgm2`` value that takes the published table's values."""

PUBLISHED_FILE = "armature_published.yaml"


@dataclass(frozen=True)
class PublishedArmature:
    """One entry of the published table (see the data file's header)."""

    name: str
    source: str
    date: str
    status: str
    values_kgm2: tuple[float, ...]
    joint_names: Mapping[str, tuple[str, ...]]
    robots: Mapping[str, str]


@cache
def published_armatures() -> dict[str, PublishedArmature]:
    """The entries of ``data/armature_published.yaml`` by name."""
    text = resources.files("grasp_safety_ros").joinpath("data", PUBLISHED_FILE).read_text()
    arms = yaml.safe_load(text)["arms"]
    return {
        name: PublishedArmature(
            name=name,
            source=" ".join(str(entry["source"]).split()),
            date=str(entry["date"]),
            status=str(entry["status"]),
            values_kgm2=tuple(float(v) for v in entry["values_kgm2"]),
            joint_names={k: tuple(v) for k, v in entry["joint_names"].items()},
            robots=dict(entry.get("robots") or {}),
        )
        for name, entry in arms.items()
    }


def published_for(value: str, urdf: str, joint_names: Sequence[str]) -> PublishedArmature:
    """The published entry ``value`` (``published`` or ``published:<entry>``) names for a
    robot loaded from ``urdf`` with chain ``joint_names``.

    ``published`` picks the entry listing the bundled robot (``example-robot-data:<name>``).
    """
    table = published_armatures()
    _, _, wanted = value.partition(":")
    if wanted:
        if wanted not in table:
            raise InvalidInputError(
                ARMATURE_FIELD, f"no published entry '{wanted}'; entries: {', '.join(table)}"
            )
        return table[wanted]
    robot = urdf.strip().removeprefix("example-robot-data:")
    for entry in table.values():
        if robot in entry.robots:
            return entry
    raise InvalidInputError(
        ARMATURE_FIELD,
        f"no published armature for '{urdf.strip()[:80]}'; name an entry as "
        f"'published:<entry>' (entries: {', '.join(table)}) or give the values",
    )


def published_values(entry: PublishedArmature, joint_names: Sequence[str]) -> dict[str, float]:
    """``{joint_name: value}`` of a published entry for the chain joints it names."""
    chain = set(joint_names)
    for names in entry.joint_names.values():
        if chain & set(names):
            return {n: v for n, v in zip(names, entry.values_kgm2, strict=True) if n in chain}
    listed = "; ".join(", ".join(names) for names in entry.joint_names.values())
    raise InvalidInputError(
        ARMATURE_FIELD,
        f"published entry '{entry.name}' names none of the chain joints "
        f"({', '.join(joint_names)}); it names: {listed}",
    )


@dataclass(frozen=True)
class ArmatureRange:
    """Armature bounds per chain joint, chain order [kg m^2, kg for prismatic joints].

    Attributes:
        lower_kgm2, upper_kgm2: (n,) bounds; equal where a single value was given.
    """

    lower_kgm2: np.ndarray
    upper_kgm2: np.ndarray

    @property
    def is_range(self) -> bool:
        """Whether some joint has lower < upper."""
        return bool(np.any(self.lower_kgm2 < self.upper_kgm2))


def armature_range(
    value: Any, joint_names: Sequence[str], base: np.ndarray | None = None
) -> ArmatureRange:
    """Bounds of a ``robot.armature_kgm2`` list or mapping whose entries are numbers or
    ``[lo, hi]`` ranges (0 <= lo <= hi, finite); refused naming the joint. The joints a
    mapping does not name keep ``base`` (the description's own armature; None: 0)."""
    names = list(joint_names)
    if isinstance(value, Mapping):
        pairs = {name: _bounds(v, f"{ARMATURE_FIELD}.{name}") for name, v in value.items()}
        lows, highs = ({k: p[i] for k, p in pairs.items()} for i in (0, 1))
        lower = armature_from_input(lows, names, base=base)
        upper = armature_from_input(highs, names, base=base)
    else:
        if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
            refused = armature_from_input(value, names)  # type: ignore[arg-type]  # raises
            return ArmatureRange(refused, refused)
        if len(value) != len(names):
            armature_from_input(value, names)  # refused with the count
        pairs_list = [
            _bounds(v, f"{ARMATURE_FIELD}[{k}] (joint '{names[k]}')") for k, v in enumerate(value)
        ]
        lower = armature_from_input([lo for lo, _ in pairs_list], names)
        upper = armature_from_input([hi for _, hi in pairs_list], names)
    return ArmatureRange(lower, upper)


def _bounds(value: Any, field: str) -> tuple[Any, Any]:
    """A value or a [lo, hi] pair as (lo, hi); a pair with lo > hi is refused."""
    if isinstance(value, (list, tuple)):
        if len(value) != 2:
            raise InvalidInputError(field, f"a range must be [lo, hi], got {list(value)!r}")
        lo, hi = value
        try:
            reversed_range = float(lo) > float(hi)
        except (TypeError, ValueError):
            reversed_range = False  # not numbers: refused with the joint by armature_from_input
        if reversed_range:
            raise InvalidInputError(field, f"range [lo, hi] needs lo <= hi, got {list(value)!r}")
        return lo, hi
    return value, value


@dataclass(frozen=True)
class ArmatureRatio:
    """Effective mass with armature over links only, over every feasible sample.

    Attributes:
        median, p10, p90, minimum, maximum: Of the per-sample ratio (>= 1); NaN when no sample.
        samples: Number of samples.
    """

    median: float
    p10: float
    p90: float
    minimum: float
    maximum: float
    samples: int


def armature_ratio(
    with_armature_kg: Sequence[np.ndarray], links_only_kg: Sequence[np.ndarray]
) -> ArmatureRatio:
    """ArmatureRatio of per-grasp effective masses with armature and of the links only [kg]."""
    ratios = np.concatenate(
        [np.empty(0)]
        + [
            np.asarray(a) / np.asarray(b)
            for a, b in zip(with_armature_kg, links_only_kg, strict=True)
        ]
    )
    if not len(ratios):
        nan = float("nan")
        return ArmatureRatio(nan, nan, nan, nan, nan, 0)
    p10, median, p90 = np.percentile(ratios, [10.0, 50.0, 90.0])
    return ArmatureRatio(
        float(median),
        float(p10),
        float(p90),
        float(ratios.min()),
        float(ratios.max()),
        len(ratios),
    )
